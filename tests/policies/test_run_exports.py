"""The policy files of a tiny DynamicsNet run (``conftest.run``): export against the SB3 policy,
averages and ensembles (``combine``), action noise, refused and shipped files. The training
itself: test_train.py."""

from __future__ import annotations

import json

import numpy as np
import pytest

from envs.factory import make_tracking_env
from envs.tracking_env import SAMPLE_REFERENCE, GripTrackingEnv
from policies.controller import Controller, combine, load_controller
from policies.runner import PolicyRunner, export_policy, read_policy_file
from policies.train import PolicyTrainer
from tests.policies.test_train import _tiny


def _save_v1(payload: dict, path) -> None:
    """Write one policy's payload in the layout of files exported before version 2 (the policy
    at the top level), which must keep loading."""
    import torch

    torch.save({**payload, "format": "grip-policy", "version": 1}, path)


def _two_policies(run, tmp_path, actor_noise: float, info: dict | None = None):
    """The run's export ``a.pt`` and ``b.pt`` (written in the layout before version 2): its
    actor plus noise, its normaliser shifted by 0.3 of the spread and the variance times 1.3
    (so that neither file clips a test input near the means); returns both paths and a's
    payload."""
    import torch

    path, _ = run
    a = tmp_path / "a.pt"
    export_policy(path, a, half=False)
    [ck], _ = read_policy_file(a)
    gen = torch.Generator().manual_seed(0)
    other = dict(ck)
    other["actor"] = {k: v + actor_noise * torch.randn(v.shape, generator=gen, dtype=v.dtype)
                      for k, v in ck["actor"].items()}  # fmt: skip
    other["obs_mean"] = {k: v + 0.3 * (ck["obs_var"][k] + 1e-8).sqrt()
                         for k, v in ck["obs_mean"].items()}  # fmt: skip
    other["obs_var"] = {k: v * 1.3 for k, v in ck["obs_var"].items()}
    if info is not None:
        other["info"] = json.dumps(info)
    b = tmp_path / "b.pt"
    _save_v1(other, b)
    return a, b, ck


def test_policy_average_rewrites_first_layers_for_one_normaliser(run, tmp_path):
    import torch

    a, b, ck = _two_policies(run, tmp_path, actor_noise=0.05)
    avg = tmp_path / "avg.pt"
    assert combine([a, b], avg, how="average")[1] == 1
    ra, rb, rv = (PolicyRunner.load(f) for f in (a, b, avg))
    np.testing.assert_allclose(rv._mean, rb._mean)  # the last file's normaliser
    # the first layer's pre-activation is the mean of the two files' on the same raw input
    x = rb._mean + 0.5 * rb._std * np.random.default_rng(1).standard_normal(rb._mean.shape)

    def pre(r):
        z = torch.from_numpy(np.clip((x - r._mean) / r._std, -r.clip_obs, r.clip_obs)).float()
        return r.actor[0](z).detach().numpy()

    np.testing.assert_allclose(pre(rv), (pre(ra) + pre(rb)) / 2, atol=1e-4)
    assert np.abs(pre(ra) - pre(rb)).max() > 0.05  # (the two files do differ)
    # deeper layers: the plain mean
    np.testing.assert_allclose(rv.actor[2].weight.detach(),
                               (ra.actor[2].weight + rb.actor[2].weight).detach() / 2,
                               atol=1e-6)  # fmt: skip
    # a file averaged with itself acts as it does
    self_avg = tmp_path / "self.pt"
    combine([a, a], self_avg, how="average")
    obs = {k: np.asarray(v, np.float64) for k, v in ra.obs_mean.items()}
    np.testing.assert_allclose(PolicyRunner.load(self_avg).act(obs), ra.act(obs), atol=1e-5)
    # other networks, and single files, are refused with the file's name
    bad = dict(ck)
    bad["actor_sizes"] = [*ck["actor_sizes"][:-1], 7]
    _save_v1(bad, tmp_path / "bad.pt")
    with pytest.raises(ValueError, match=r"bad\.pt: actor_sizes .* does not fit the weights"):
        combine([tmp_path / "bad.pt", a], tmp_path / "x.pt", how="average")
    with pytest.raises(ValueError, match="at least two"):
        combine([a], tmp_path / "x.pt", how="average")
    assert not (tmp_path / "x.pt").exists()


def test_policy_ensemble_plays_the_mean_action_and_round_trips_a_file(run, tmp_path):
    import dataclasses as dc

    import torch

    from policies.ensemble import PolicyEnsemble

    # another network with its own normaliser and held-out clips: a policy trained apart
    a, b, ck = _two_policies(run, tmp_path, actor_noise=0.2, info={"holdout": ["x", "y"]})
    ra, rb = PolicyRunner.load(a), PolicyRunner.load(b)
    obs, info = GripTrackingEnv(ra.env_cfg).reset(seed=3)
    assert np.abs(ra.act(obs) - rb.act(obs)).max() > 0.01  # (the two do differ)
    ens = load_controller([a, b])
    assert isinstance(ens, PolicyEnsemble) and isinstance(ens, Controller)
    np.testing.assert_allclose(ens.act(obs), (ra.act(obs) + rb.act(obs)) / 2, atol=1e-5)
    batch = {k: np.stack([v, v]) for k, v in obs.items()}
    assert ens.act(batch).shape == (2, ra.act(obs).size)
    assert ens.fall_probability(info["amp_obs"]) == pytest.approx(ra.fall_probability(
        info["amp_obs"]))  # the first member's discriminator  # fmt: skip
    assert ens.info["holdout"] == []  # a clip only b held out trained a
    # one file: actors and normalisers of both, one discriminator, no value networks
    f = tmp_path / "ens.pt"
    size, n = combine([a, b], f)
    assert n == 2 and size == f.stat().st_size
    loaded = load_controller(f)
    assert isinstance(loaded, PolicyEnsemble) and len(loaded.members) == 2
    err = np.abs(loaded.act(obs) - ens.act(obs)).max()  # int8 actors by default
    assert 0 < err < 0.1, err  # (a tiny noisy test network; the shipped one: README)
    exact = tmp_path / "exact.pt"
    assert combine([a, b], exact, precision="fp32")[0] > size
    np.testing.assert_allclose(load_controller(exact).act(obs), ens.act(obs), atol=1e-5)
    assert loaded.members[0].disc is not None and loaded.members[1].disc is None
    # the fall detector is stored int8 too and gives the same probability within 0.05
    stored = torch.load(f, weights_only=True)["members"][0]["disc"]
    assert any(v.dtype == torch.int8 for v in stored.values())
    p_ref, p_int8 = ra.fall_probability(info["amp_obs"]), loaded.fall_probability(info["amp_obs"])
    assert np.abs(p_int8 - p_ref).max() < 0.05
    p_exact = load_controller(exact).fall_probability(info["amp_obs"])
    assert p_exact == pytest.approx(p_ref, abs=1e-5)
    assert all(m.critic is None for m in loaded.members)
    assert isinstance(load_controller(a), PolicyRunner)
    # an ensemble file joins another file as its members
    assert combine([f, a], tmp_path / "three.pt")[1] == 3
    assert len(load_controller([f, a]).members) == 3
    # refusals name the file: one policy alone, a member that drives the body otherwise, a
    # corrupt ensemble, and an ensemble where one policy is needed (fine-tuning)
    with pytest.raises(ValueError, match="at least two"):
        combine([a], tmp_path / "x.pt")
    cfg = json.loads(ck["config"])
    cfg["env"]["action_scale"] = 0.25
    odd = dict(ck, config=json.dumps(cfg))
    _save_v1(odd, tmp_path / "odd.pt")
    with pytest.raises(ValueError, match=r"odd\.pt: environment settings differ .*action_scale"):
        combine([a, tmp_path / "odd.pt"], tmp_path / "x.pt")
    assert not (tmp_path / "x.pt").exists()
    wide = dict(ck, obs_mean=dict(ck["obs_mean"]), obs_var=dict(ck["obs_var"]))
    key = ck["obs_keys"][0]  # a policy of another sensor set: a longer first part
    wide["obs_mean"][key] = torch.cat([ck["obs_mean"][key], ck["obs_mean"][key][:3]])
    wide["obs_var"][key] = torch.cat([ck["obs_var"][key], ck["obs_var"][key][:3]])
    wide["actor"] = dict(ck["actor"])
    w0 = sorted(k for k in ck["actor"] if k.endswith(".weight"))[0]
    wide["actor"][w0] = torch.cat([ck["actor"][w0], ck["actor"][w0][:, :3]], 1)
    wide["actor_sizes"] = [ck["actor_sizes"][0] + 3, *ck["actor_sizes"][1:]]
    _save_v1(wide, tmp_path / "wide.pt")
    with pytest.raises(ValueError, match=r"wide\.pt: observation .* of \d+ values"):
        load_controller([a, tmp_path / "wide.pt"])
    rb.env_cfg = dc.replace(ra.env_cfg, reward=dc.replace(ra.env_cfg.reward, k_pos=1.0))
    PolicyEnsemble([ra, rb])  # reward settings may differ: inference computes no reward
    broken = torch.load(f, weights_only=True)
    broken["members"][1] = {"format": "grip-policy"}
    torch.save(broken, tmp_path / "broken.pt")
    with pytest.raises(ValueError, match=r"broken\.pt \(member 1.*lacks"):
        load_controller(tmp_path / "broken.pt")
    with pytest.raises(ValueError, match=r"ens\.pt: an ensemble of 2 policies"):
        PolicyRunner.load(f)
    with pytest.raises(ValueError, match=r"ens\.pt \[0\]: critic_sizes None differs"):
        combine([f, a], tmp_path / "x.pt", how="average")  # (an ensemble keeps no critics)
    # one member alone: its actor as stored, the file's fall detector, no value network
    assert combine([f], tmp_path / "m1.pt", member=1)[1] == 1
    m1 = load_controller(tmp_path / "m1.pt")
    assert isinstance(m1, PolicyRunner) and m1.critic is None and m1.disc is not None
    np.testing.assert_allclose(m1.act(obs), loaded.members[1].act(obs), atol=1e-6)
    with pytest.raises(ValueError, match="no member 2"):
        combine([f], tmp_path / "m2.pt", member=2)
    # a warm start from an ensemble file begins from its first member (no value network)
    tr = PolicyTrainer(_tiny(), tmp_path / "ft", SAMPLE_REFERENCE, make_tracking_env, init=exact)
    assert tr.init_members == 2 and tr._init_runner.critic is None
    np.testing.assert_allclose(tr._init_runner.act(obs), ra.act(obs), atol=1e-6)
    # or from a later member, which takes the file's discriminator (it stores one)
    tr = PolicyTrainer(_tiny(), tmp_path / "ft1", SAMPLE_REFERENCE, make_tracking_env,
                       init=exact, init_member=1)  # fmt: skip
    np.testing.assert_allclose(tr._init_runner.act(obs), rb.act(obs), atol=1e-6)
    assert tr._init_runner.disc is not None and "member 1" in tr.init_name
    assert tr._init_runner.fall_probability(info["amp_obs"]) == pytest.approx(
        ra.fall_probability(info["amp_obs"]), abs=1e-5)  # fmt: skip
    with pytest.raises(ValueError, match=r"exact\.pt: no member 2 \(the file holds 2 policies"):
        PolicyTrainer(_tiny(), tmp_path / "ft2", SAMPLE_REFERENCE, make_tracking_env,
                      init=exact, init_member=2)  # fmt: skip
    with pytest.raises(ValueError, match=r"\.pt: no member 1 \(the file holds 1 policy"):
        PolicyTrainer(_tiny(), tmp_path / "ft3", SAMPLE_REFERENCE, make_tracking_env,
                      init=a, init_member=1)  # fmt: skip


def test_export_matches_the_sb3_policy_and_loads_safely(run, tmp_path):
    path, _ = run
    import torch
    from stable_baselines3 import PPO

    out = tmp_path / "policy.pt"
    export_policy(path, out, half=False)
    runner = PolicyRunner.load(out)
    env = GripTrackingEnv(runner.env_cfg)
    obs, info = env.reset(seed=3)
    model = PPO.load(path / "checkpoint" / "model.zip", device="cpu")  # (trusted: the oracle)
    with np.load(path / "checkpoint" / "vecnorm.npz") as z:
        norm = dict(z)
    nobs = {k: np.clip((v - norm[f"obs/{k}/mean"]) / np.sqrt(norm[f"obs/{k}/var"] + 1e-8),
                       -10, 10).astype(np.float32) for k, v in obs.items()}  # fmt: skip
    expected, _ = model.predict(nobs, deterministic=True)
    np.testing.assert_allclose(runner.act(obs), expected, atol=1e-5)
    p = runner.fall_probability(info["amp_obs"])
    assert p.shape == (1,) and 0 <= p[0] <= 1
    half = tmp_path / "half.pt"
    assert export_policy(path, half) < out.stat().st_size
    np.testing.assert_allclose(PolicyRunner.load(half).act(obs), expected, atol=2e-2)
    # int8 (a scale per row) for all three networks: smaller still, and it acts, values and
    # judges nearly as the fp32 file does (the tiny test network; the shipped one: README)
    small = tmp_path / "int8.pt"
    assert export_policy(path, small, precision="int8") < half.stat().st_size
    [stored], _ = read_policy_file(small)
    for part in ("actor", "critic", "disc"):
        assert any(v.dtype == torch.int8 for v in stored[part].values()), part
    q = PolicyRunner.load(small)
    assert 0 < np.abs(q.act(obs) - expected).max() < 0.1
    x = torch.randn(4, runner.critic[0].in_features)
    assert torch.allclose(q.critic(x), runner.critic(x), rtol=0.05, atol=0.05)
    assert np.abs(q.fall_probability(info["amp_obs"]) - p).max() < 0.05


def test_action_noise_samples_the_trained_gaussian_and_clips(run, tmp_path):
    import torch

    path, _ = run
    export_policy(path, tmp_path / "p.pt", half=False)
    runner = PolicyRunner.load(tmp_path / "p.pt")
    obs, _ = GripTrackingEnv(runner.env_cfg).reset(seed=3)
    mean = runner.act(obs)
    runner.log_std = torch.full_like(runner.log_std, -3.0)  # std 0.05: few samples clipped
    std = np.exp(-3.0)
    batch = {k: np.repeat(np.asarray(v)[None], 4000, axis=0) for k, v in obs.items()}
    runner.use_action_noise(1.0, seed=5)
    a = runner.act(batch)
    assert a.shape == (4000, mean.size) and np.abs(a).max() <= 1.0
    inside = np.abs(mean) < 1 - 4 * std
    assert inside.sum() >= 3
    np.testing.assert_allclose(a.mean(0)[inside], mean[inside], atol=0.1 * std)
    np.testing.assert_allclose(a.std(0)[inside], std, rtol=0.05)
    runner.use_action_noise(2.0, seed=5)
    np.testing.assert_allclose(runner.act(batch).std(0)[inside], 2 * std, rtol=0.05)
    runner.use_action_noise(1.0, seed=5)
    np.testing.assert_array_equal(runner.act(batch), a)  # the seed repeats the draw
    runner.use_action_noise(0.0)
    np.testing.assert_array_equal(runner.act(obs), mean)
    with pytest.raises(ValueError, match=">= 0"):
        runner.use_action_noise(-1.0)
    runner.log_std = None
    with pytest.raises(ValueError, match="no log_std"):
        runner.use_action_noise(1.0)


def test_bad_policy_files_are_refused(tmp_path):
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match=r"junk\.pt: not a policy file: corrupt"):
        PolicyRunner.load(junk)
    import torch

    other = tmp_path / "other.pt"
    torch.save({"format": "something-else"}, other)
    with pytest.raises(ValueError, match="not a GRIP policy"):
        PolicyRunner.load(other)


def test_the_shipped_policy_file_loads():
    from grip.assets import SHIPPED_POLICY
    from policies.config import policy_config_from_dict
    from policies.runner import read_policy_file

    members, _ = read_policy_file(SHIPPED_POLICY)
    for m in members:  # (the shipped controller reads the gap to the followed pelvis: the pace
        # keeper's lead reaches it, docs/pace.md)
        cfg = policy_config_from_dict(json.loads(m["config"]), "member", training=True)
        assert cfg.env.kinematic_obs == "OAV_Jrel_root"
