"""PPO + AMP on the device (:class:`policies.warp.train.WarpPolicyTrainer`) end to end on MuJoCo
Warp's CPU device, on the bundled sample: both stages, the checkpoint resumes, the exported file
plays in the CPU player, a CPU policy warm-starts a device run with the same actions, and the
teacher's recipe (hard-clip mining, ``fall_below_reference_m``) trains and resumes, also on a
data set with a clip that has its own scene objects.

``slow``: MuJoCo Warp compiles its kernels on first use (about a minute on a cold cache); they
skip where the ``gpu`` extra is absent.
"""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest

from envs.warp import warp_available

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not warp_available(), reason="needs mujoco-warp (pip install -e .[gpu])"),
]


def _tiny():
    from policies.config import AmpConfig, PolicyRunConfig, PPOConfig, StageConfig

    return PolicyRunConfig(
        ppo=PPOConfig(n_envs=4, n_steps=8, batch_size=16, n_epochs=2, net_arch=(16,)),
        amp=AmpConfig(window=2, hidden=(16,), batch_size=16, updates_per_rollout=1,
                      replay_size=256),
        stage1=StageConfig(timesteps=64, max_episode_frames=40, termination_start_m=0.6,
                           termination_anneal_steps=32),
        stage2=StageConfig(timesteps=32, termination_dist_m=0.0, fall_height_m=0.3,
                           max_episode_frames=50),
        checkpoint_every=1,
    )  # fmt: skip


def _trainer(cfg, run, make_env=None, **kw):
    import warp as wp

    from envs.tracking_env import SAMPLE_REFERENCE
    from envs.warp.factory import make_warp_tracking_env
    from policies.warp.train import WarpPolicyTrainer

    wp.config.quiet = True
    return WarpPolicyTrainer(cfg, run, SAMPLE_REFERENCE, make_env or make_warp_tracking_env,
                             **kw)  # fmt: skip


def _write_config(run, cfg, **extra) -> None:
    from grip.core.rundir import RunDir
    from policies.warp.train import BACKEND

    RunDir(run).write_config(cfg, **{"backend": BACKEND, **extra})


@pytest.fixture(scope="module")
def warp_run(tmp_path_factory):
    run = tmp_path_factory.mktemp("warp_run")
    cfg = _tiny()
    _write_config(run, cfg)
    tr = _trainer(cfg, run)
    tr.train()
    return run, tr


def test_both_stages_train_on_the_device(warp_run):
    run, tr = warp_run
    assert tr.total_done() == 96
    stages = [h["stage"] for h in tr.history]
    assert stages == ["stage1", "stage1", "stage2"]
    for key in ("reward/imit_pos", "reward/amp", "reward/energy", "amp/acc_real", "amp/loss"):
        assert all(np.isfinite(h[key]) for h in tr.history), key
    assert [h["termination_m"] for h in tr.history] == pytest.approx([0.6, 0.25, 0.0])
    assert all(0.0 < h["reward/amp"] <= 1.0 for h in tr.history)
    state = json.loads((run / "checkpoint" / "state.json").read_text())
    assert state["stage_index"] == 1 and state["stage_done"] == 32
    assert tr.model.num_timesteps == 96
    assert tr.model._n_updates == 3 * 2  # three PPO updates of two epochs each
    assert (run / "tb" / "warp").is_dir()


def test_checkpoint_resumes(warp_run, tmp_path):
    from policies.checkpoint import load_weights

    run, tr = warp_run
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    cfg = dataclasses.replace(tr.cfg, stage2=dataclasses.replace(tr.cfg.stage2, timesteps=64))
    saved = load_weights(copy / "checkpoint" / "amp.pt", "amp")
    again = _trainer(cfg, copy)
    again.train()
    assert [h["timesteps"] for h in again.history] == [32, 64, 96, 128]
    assert again.history[:3] == json.loads(json.dumps(tr.history))
    assert again.model.num_timesteps == 128 and again.model._n_updates == 8
    state = json.loads((copy / "checkpoint" / "state.json").read_text())
    assert state["stage_index"] == 1 and state["stage_done"] == 64
    assert not all(np.array_equal(saved["disc"][k], v.cpu())
                   for k, v in again.amp.disc.state_dict().items())  # (it trained on)  # fmt: skip


def test_a_cpu_run_folder_is_not_resumed_by_the_device_trainer(warp_run, tmp_path):
    run, tr = warp_run
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    data = json.loads((copy / "config.json").read_text())
    del data["backend"]
    (copy / "config.json").write_text(json.dumps(data))
    with pytest.raises(ValueError, match="backend"):
        _trainer(tr.cfg, copy)


def test_exported_policy_plays_in_the_cpu_env(warp_run, tmp_path):
    import torch

    from envs.tracking_env import SAMPLE_REFERENCE, GripTrackingEnv
    from grip.core.reference import ReferenceSet
    from policies.runner import PolicyRunner, export_policy

    run, tr = warp_run
    out = tmp_path / "policy.pt"
    export_policy(run, out, half=False)
    runner = PolicyRunner.load(out)
    env = GripTrackingEnv(runner.env_cfg, ReferenceSet.load(SAMPLE_REFERENCE))
    obs, _ = env.reset(seed=0)
    for _ in range(5):
        a = runner.act(obs)
        assert a.shape == env.action_space.shape and np.all(np.abs(a) <= 1.0)
        obs, r, term, trunc, _ = env.step(a)
        assert np.isfinite(r) and all(np.all(np.isfinite(v)) for v in obs.values())
        if term or trunc:
            obs, _ = env.reset()
    # the same network and normaliser as the trainer's model (exported at full precision)
    o = {k: torch.as_tensor(np.asarray(v)[None], dtype=torch.float32) for k, v in obs.items()}
    np.testing.assert_allclose(runner.act(obs), tr.act(o)[0].numpy(), atol=1e-5)


def test_cpu_policy_warm_starts_a_device_run(tiny_policy_run, tmp_path):
    """A policy file of the CPU trainer starts a device run: the same actions for the same
    observations, the same normaliser and discriminator."""
    import torch

    from policies.config import policy_config_from_dict
    from policies.runner import PolicyRunner
    from policies.vec_env import vecnorm_state

    _, cpu_run = tiny_policy_run
    policy = cpu_run / "policy.pt"
    recorded = json.loads((cpu_run / "config.json").read_text())["config"]
    cfg = policy_config_from_dict(recorded, "cpu run", training=True)
    cfg = dataclasses.replace(cfg, ppo=dataclasses.replace(cfg.ppo, n_envs=3, device="cpu"))
    tr = _trainer(cfg, tmp_path / "run", init=policy)
    tr.prepare_stage(cfg.stage1)
    runner = PolicyRunner.load(policy)
    obs = tr.env.observe()
    want = runner.act({k: v.numpy() for k, v in obs.items()})
    np.testing.assert_allclose(tr.act(obs).numpy(), want, atol=1e-5)
    norm = vecnorm_state(tr.venv)
    for k in runner.obs_keys:
        np.testing.assert_allclose(norm[f"obs/{k}/mean"], runner.obs_mean[k])
    x = torch.as_tensor(np.random.default_rng(0).normal(size=(4, tr.amp.disc.in_dim)),
                        dtype=torch.float32)  # fmt: skip
    np.testing.assert_allclose(tr.amp.disc(x).detach().numpy(),
                               runner.disc(x).detach().numpy(), atol=1e-6)  # fmt: skip
    tr.env.close()


def test_cli_backend_warp_trains_and_policy_eval_plays_it(tiny_policy_settings, walk_takes,
                                                          tmp_path):  # fmt: skip
    """``grip policy train --backend warp --device cpu`` end to end, its file evaluated by
    ``grip policy eval`` unchanged; resuming it with the other backend is refused."""
    from envs.tracking_env import SAMPLE_REFERENCE
    from grip.cli.main import main

    data = tmp_path / "data"
    data.mkdir()
    (data / "split.json").write_text(json.dumps({"train": ["s0"], "test": []}))
    run = tmp_path / "run"
    run.mkdir()
    shutil.copy(SAMPLE_REFERENCE, run / "reference_train.npz")  # (no KinematicsNet pass)
    sets = [*tiny_policy_settings, "--set", "ppo.n_envs=4", "--set", "ppo.n_steps=8",
            "--set", "ppo.batch_size=16", "--set", "stage1.timesteps=32",
            "--set", "stage2.timesteps=32"]  # fmt: skip
    train = ["policy", "train", "--data", str(data), "--out", str(run), *sets]
    assert main([*train, "--backend", "warp", "--device", "cpu"]) == 0
    assert json.loads((run / "config.json").read_text())["backend"] == "warp"
    assert main(["policy", "eval", "--policy", str(run / "policy.pt"), "--data",
                 str(walk_takes), "--segment-frames", "60", "--segments", "2",
                 "--json", str(tmp_path / "eval.json")]) == 0  # fmt: skip
    assert json.loads((tmp_path / "eval.json").read_text())["segments"] == 2
    assert main(train) == 2  # the CPU backend does not resume a warp run
    assert main([*train, "--device", "cpu"]) == 2  # --device without --backend warp


def test_teacher_recipe_trains_on_clips_with_their_own_props(tmp_path):
    """The teacher's recipe (``env.terrain = "auto"``) on a data set with a props clip (the walk
    with a 0.3 m block ahead of its last frames, beside the flat run) trains on the device; the
    env it built shows the block in the height map of the walk's worlds, as the CPU env does,
    and none in the run's."""
    import torch

    from envs.tracking_env import SAMPLE_REFERENCE, GripTrackingEnv
    from envs.warp.factory import make_warp_tracking_env
    from grip.assets import REPO_ROOT
    from grip.config import load_config
    from grip.core.reference import ReferenceSet
    from policies.config import PolicyRunConfig
    from policies.warp.train import WarpPolicyTrainer

    cfg = load_config(REPO_ROOT / "configs" / "policy" / "teacher.toml", PolicyRunConfig(),
                      TEACHER_TINY)  # fmt: skip
    assert cfg.env.terrain == "auto"
    ref = ReferenceSet.load(SAMPLE_REFERENCE)
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.3]])
    f = np.array([[0, 1, 2], [0, 1, 3], [1, 2, 3], [0, 2, 3]])
    clips = [dataclasses.replace(ref.clip(0), objects={"box": (v, f)}), *ref.clips[1:]]
    path = tmp_path / "props.npz"
    props = ReferenceSet(clips, ref.sensor_sites, ref.insoles)
    props.save(path)
    run = tmp_path / "run"
    _write_config(run, cfg)
    import warp as wp

    wp.config.quiet = True
    made = []

    def make(*args, **kwargs):
        made.append(make_warp_tracking_env(*args, **kwargs))
        return made[-1]

    tr = WarpPolicyTrainer(cfg, run, path, make)
    tr.train()
    assert [h["stage"] for h in tr.history] == ["stage1", "stage1", "stage2"]
    assert all(np.isfinite(h["reward/imit_pos"]) and h["episodes"] > 0 for h in tr.history)
    env = made[-1]
    assert not env.overflowed()
    starts = ((0, 240), (0, 230), (1, 240), (1, 230))
    env.reset(torch.ones(env.num_envs, dtype=torch.bool), torch.tensor([c for c, _ in starts]),
              torch.tensor([s for _, s in starts]))  # fmt: skip
    hm = env.observe()["environment"].numpy()
    cpu = GripTrackingEnv(env.cfg, props)
    for w, (c, s) in enumerate(starts):
        obs, _ = cpu.reset(options={"clip": c, "start": s})
        np.testing.assert_allclose(hm[w], obs["environment"], atol=1e-5)
        assert (np.ptp(hm[w]) > 0.1) if c == 0 else (np.ptp(hm[w]) == 0)


TEACHER_TINY = ("ppo.n_envs=4", "ppo.n_steps=8", "ppo.batch_size=16", "ppo.n_epochs=1",
                "ppo.net_arch=[16]", "amp.hidden=[16]", "amp.window=2", "amp.batch_size=16",
                "amp.replay_size=256", "checkpoint_every=1",
                "stage1.timesteps=64", "stage1.termination_dist_m=0.12",
                "stage1.termination_anneal_steps=0", "stage1.max_episode_frames=15",
                "stage1.mining_decay=0.9", "stage2.timesteps=32",
                "stage2.termination_dist_m=0.12", "stage2.max_episode_frames=15",
                "stage2.mining_decay=0.9")  # fmt: skip
"""configs/policy/teacher.toml at the size of :func:`_tiny`: episodes of 5 decisions and a tight
termination distance in both stages, so that some episodes fail and others reach their limit."""


def _spying_maker(pushed: list):
    """The warp env constructor, recording every ``set_clip_weights`` call in ``pushed``."""
    from envs.warp.factory import make_warp_tracking_env

    def make(*args, **kwargs):
        env = make_warp_tracking_env(*args, **kwargs)
        push = env.set_clip_weights

        def spy(w) -> None:
            pushed.append(np.array(w, dtype=np.float64))
            push(w)

        env.set_clip_weights = spy
        return env

    return make


def test_teacher_recipe_mines_hard_clips_checkpoints_and_resumes(tmp_path):
    """The teacher's recipe (hard-clip mining in both stages, ``fall_below_reference_m``; a
    tight termination distance so that episodes fail) trains on the device: per rollout the
    trainer counts the ended and failed episodes of each clip, records them per category in the
    history row, and gives the env the miner's weights (the same weights as a
    :class:`ClipFailureStats` fed with the rows' counts); the checkpoint keeps the miner's
    counts as the CPU trainer's does, and a resumed run goes on from them."""
    from envs.tracking_env import SAMPLE_REFERENCE
    from grip.assets import REPO_ROOT
    from grip.config import load_config
    from grip.core.reference import ReferenceSet
    from policies.config import PolicyRunConfig
    from policies.mining import ClipFailureStats

    cfg = load_config(REPO_ROOT / "configs" / "policy" / "teacher.toml", PolicyRunConfig(),
                      TEACHER_TINY)  # fmt: skip
    assert cfg.stage1.mining_mix > 0 and cfg.stage2.mining_mix > 0
    assert cfg.stage2.fall_below_reference_m > 0 and cfg.env.action_repeat == 3
    clips = ReferenceSet.load(SAMPLE_REFERENCE).clips
    names, cats = [c.name for c in clips], [c.category for c in clips]
    assert len(set(cats)) == len(cats)  # (one clip per category: rows give per-clip counts)
    run = tmp_path / "run"
    _write_config(run, cfg)
    pushed: list[np.ndarray] = []
    tr = _trainer(cfg, run, make_env=_spying_maker(pushed))
    tr.train()
    assert [h["stage"] for h in tr.history] == ["stage1", "stage1", "stage2"]
    for h in tr.history:
        by_cat = h["by_category"]
        assert set(by_cat) <= set(cats), by_cat
        assert sum(n for n, _ in by_cat.values()) == h["episodes"] > 0
        assert sum(f for _, f in by_cat.values()) == round(h["episodes"] * (1 - h["success_rate"]))
    stage1 = [h for h in tr.history if h["stage"] == "stage1"]
    fails = sum(f for h in stage1 for _, f in h["by_category"].values())
    assert 0 < fails < sum(h["episodes"] for h in stage1)  # (mining had something to weigh)
    # each stage: its first weights at the start (a fresh miner: all ones), then one per rollout
    want = []
    for name, stage in cfg.stages():
        miner = ClipFailureStats(names, stage.mining_mix, stage.mining_decay, stage.mining_prior)
        want.append(miner.weights())
        for h in tr.history:
            if h["stage"] == name:
                for i, cat in enumerate(cats):
                    miner.episodes[i] += h["by_category"].get(cat, [0, 0])[0]
                    miner.fails[i] += h["by_category"].get(cat, [0, 0])[1]
                miner.end_rollout()
                want.append(miner.weights())
    assert len(pushed) == len(want) == 5
    for got, w in zip(pushed, want, strict=True):
        np.testing.assert_allclose(got, w, rtol=1e-12)
    assert pushed[2].std() > 0 and pushed[4].std() > 0  # (the failures differ by clip)
    np.testing.assert_allclose(tr.mining.episodes, miner.episodes, rtol=1e-12)
    state = json.loads((run / "checkpoint" / "state.json").read_text())
    assert state["mining"] == json.loads(json.dumps({"stage_index": 1,
                                                     **tr.mining.state_dict()}))  # fmt: skip
    # resumed with a longer stage 2: the saved counts' weights first (a fresh miner's would be
    # all ones), then one rollout more
    copy = tmp_path / "copy"
    shutil.copytree(run, copy)
    longer = dataclasses.replace(cfg, stage2=dataclasses.replace(cfg.stage2, timesteps=64))
    pushed_again: list[np.ndarray] = []
    again = _trainer(longer, copy, make_env=_spying_maker(pushed_again))
    again.train()
    assert again.history[:3] == json.loads(json.dumps(tr.history))
    assert len(again.history) == 4 and len(pushed_again) == 2
    np.testing.assert_allclose(pushed_again[0], pushed[-1], rtol=1e-12)
    new = again.history[-1]["episodes"]
    assert new > 0
    assert again.mining.episodes.sum() == pytest.approx((sum(state["mining"]["episodes"]) + new)
                                                        * cfg.stage2.mining_decay)  # fmt: skip


def _spy_curricula(calls: list):
    """The warp env constructor, recording every curriculum call (name, args) in ``calls``
    (and each env made, as ``("env", env)``)."""
    from envs.warp.factory import make_warp_tracking_env

    def make(*args, **kwargs):
        env = make_warp_tracking_env(*args, **kwargs)
        calls.append(("env", env))
        for method in ("set_start_bin_weights", "set_clip_termination_dists"):
            orig = getattr(env, method)

            def spy(*a, _orig=orig, _name=method):
                calls.append((_name, a))
                return _orig(*a)

            setattr(env, method, spy)
        return env

    return make


def test_issue47_curricula_and_real_sampling_on_the_device(tmp_path):
    """Failure-weighted starts, per-category termination and real windows drawn as the
    episodes, on the device trainer: after every rollout the env gets the bins' weights and
    each clip's distance, the discriminator's real clips follow the stage (``walk*`` only:
    the run clip gets probability 0), all of it is saved and a resumed run starts from it."""
    from policies.mining import StartBinStats

    cfg = _tiny()
    cfg = dataclasses.replace(
        cfg, amp=dataclasses.replace(cfg.amp, real_sampling="episodes"),
        stage1=dataclasses.replace(cfg.stage1, timesteps=0),
        stage2=dataclasses.replace(cfg.stage2, timesteps=64, max_episode_frames=6,
                                   categories=("walk*",), mining_bins_mix=1.0,
                                   termination_category_min_m=0.05,
                                   termination_category_max_m=0.4,
                                   termination_category_step=0.3))  # fmt: skip
    run = tmp_path / "run"
    _write_config(run, cfg)
    calls: list = []
    tr = _trainer(cfg, run, make_env=_spy_curricula(calls))
    tr.train()
    cur = tr.curriculum
    assert cur.bins.episodes.sum() > 0 and cur.termination.categories == ["walk"]
    bins = [a for name, a in calls if name == "set_start_bin_weights"]
    dists = [a[0] for name, a in calls if name == "set_clip_termination_dists"]
    assert len(bins) == len(dists) == 1 + len(tr.history)
    for got, want in zip(bins[-1][1], cur.bins.weights(), strict=True):
        np.testing.assert_allclose(got, want)
    np.testing.assert_allclose(dists[-1], cur.termination.clip_dists())
    env = [a for name, a in calls if name == "env"][-1]
    np.testing.assert_allclose(env.termination_dist_m.numpy(),
                               cur.termination.clip_dists()[env.clip_index.numpy()],
                               rtol=1e-6)  # fmt: skip
    assert tr.history[0]["termination_by_category"] == {"walk": 0.4}
    np.testing.assert_allclose(tr.amp.clip_p.cpu().numpy(), [1.0, 0.0])
    state = json.loads((run / "checkpoint" / "state.json").read_text())
    assert state["start_bins"]["stage_index"] == state["termination"]["stage_index"] == 1
    saved = StartBinStats(cur.bins.names, [250], 100, 1.0)
    saved.load_state_dict(state["start_bins"])
    longer = dataclasses.replace(cfg, stage2=dataclasses.replace(cfg.stage2, timesteps=96))
    again: list = []
    tr2 = _trainer(longer, run, make_env=_spy_curricula(again))
    tr2.train()
    first_bins = next(a for name, a in again if name == "set_start_bin_weights")[1]
    for got, want in zip(first_bins, saved.weights(), strict=True):
        np.testing.assert_allclose(got, want)
    first_dists = next(a[0] for name, a in again if name == "set_clip_termination_dists")
    np.testing.assert_allclose(first_dists, state["termination"]["dist_m"])


def test_amp_weight_zero_skips_the_discriminator_on_the_device(tmp_path):
    """``env.reward.weights.amp = 0`` on the device trainer: no discriminator update, no
    replay, style reward 0 in every row."""
    import torch

    cfg = _tiny()
    weights = dataclasses.replace(cfg.env.reward.weights, amp=0.0)
    env = dataclasses.replace(cfg.env, reward=dataclasses.replace(cfg.env.reward,
                                                                  weights=weights))  # fmt: skip
    cfg = dataclasses.replace(cfg, env=env,
                              stage1=dataclasses.replace(cfg.stage1, timesteps=32),
                              stage2=dataclasses.replace(cfg.stage2, timesteps=0))  # fmt: skip
    run = tmp_path / "run"
    _write_config(run, cfg)
    tr = _trainer(cfg, run)
    before = {k: v.clone() for k, v in tr.amp.disc.state_dict().items()}
    tr.train()
    assert tr.amp.replay_n == 0 and not tr.amp.opt.state
    for k, v in tr.amp.disc.state_dict().items():
        assert torch.equal(v, before[k]), k
    assert all(h["reward/amp"] == 0.0 and h["amp/loss"] == 0.0 for h in tr.history)
