"""A tiny DynamicsNet run on the bundled sample (``conftest.run``): train, checkpoint, resume,
warm starts, evaluation. The run's policy files (export, averages, ensembles): test_run_exports.py.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from envs.factory import make_tracking_env
from envs.tracking_env import SAMPLE_REFERENCE, GripTrackingEnv
from grip.core.reference_sets import select_clips
from policies.config import AmpConfig, PolicyRunConfig, PPOConfig, StageConfig
from policies.runner import PolicyRunner, export_policy
from policies.train import PolicyTrainer, run_config_dict


def _tiny() -> PolicyRunConfig:
    return PolicyRunConfig(
        ppo=PPOConfig(n_envs=2, vec_env="dummy", n_steps=32, batch_size=64, n_epochs=1,
                      net_arch=(32, 32)),
        amp=AmpConfig(window=3, hidden=(32,), batch_size=32, updates_per_rollout=1,
                      replay_size=500),
        stage1=StageConfig(timesteps=128, max_episode_frames=40, categories=("walk*",),
                           termination_start_m=0.6, termination_anneal_steps=64),
        stage2=StageConfig(timesteps=64, termination_dist_m=0.0, fall_height_m=0.3,
                           max_episode_frames=50),
        checkpoint_every=1,
    )  # fmt: skip


def test_training_runs_both_stages_and_logs_every_term(run):
    path, tr = run
    assert tr.total_done() >= 192
    stages = [h["stage"] for h in tr.history]
    assert stages[0] == "stage1" and stages[-1] == "stage2"
    for key in ("reward/imit_pos", "reward/amp", "reward/energy", "amp/acc_real", "amp/loss"):
        assert all(np.isfinite(h[key]) for h in tr.history), key
    state = json.loads((path / "checkpoint" / "state.json").read_text())
    assert state["stage_index"] == 1 and state["stage_done"] == 64
    assert (path / "tb").is_dir()
    # the termination curriculum: 0.6 m tightening to 0.25 m within stage 1, off in stage 2
    tau = [h["termination_m"] for h in tr.history]
    s1 = tau[: stages.count("stage1")]
    assert s1[0] == pytest.approx(0.6) and s1[-1] == pytest.approx(0.25)
    assert tau[-1] == 0.0
    ended = [h for h in tr.history if "ep_len" in h]
    assert ended and all(1 <= h["ep_len"] <= 50 for h in ended)  # episodes of at most 50 frames


def test_learning_curves_png(run, tmp_path):
    from policies.report import plot_curves

    _, tr = run
    out = tmp_path / "curves.png"
    plot_curves(tr.history, out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    plot_curves([], tmp_path / "empty.png")  # a run without a rollout yet still gets a figure
    assert (tmp_path / "empty.png").stat().st_size > 0


def test_termination_schedule_and_env_setting():
    st = StageConfig(termination_dist_m=0.25, termination_start_m=0.65,
                     termination_anneal_steps=1000)  # fmt: skip
    assert st.termination_at(0) == pytest.approx(0.65)
    assert st.termination_at(500) == pytest.approx(0.45)
    assert st.termination_at(5000) == pytest.approx(0.25)
    assert StageConfig(termination_dist_m=0.25).termination_at(0) == 0.25
    env = GripTrackingEnv()
    env.set_termination_dist(1e-6)  # any motion at all is "too far": ends at the first step
    env.reset(seed=0)
    assert env.step(np.zeros(env.action_space.shape))[2]
    env.set_termination_dist(0.0)  # off
    env.reset(seed=0)
    assert not env.step(np.zeros(env.action_space.shape))[2]
    with pytest.raises(ValueError, match="termination"):
        env.set_termination_dist(-1.0)


def test_resume_extends_the_last_stage(run, tmp_path):
    path, tr = run
    import shutil

    copy = tmp_path / "resumed"
    shutil.copytree(path, copy)
    cfg = _tiny()
    longer = dataclasses.replace(cfg, stage2=dataclasses.replace(cfg.stage2, timesteps=128))
    tr2 = PolicyTrainer(longer, copy, SAMPLE_REFERENCE, make_tracking_env)
    tr2.train()
    assert tr2.total_done() == 128 + 128
    assert len(tr2.history) > len(tr.history)
    # a resumed run takes its optimiser settings from the config, not from the checkpoint
    assert tr2.model.learning_rate == cfg.ppo.learning_rate
    copy2 = tmp_path / "resumed_lr"
    shutil.copytree(path, copy2)
    slower = dataclasses.replace(
        longer, ppo=dataclasses.replace(cfg.ppo, learning_rate=1e-5, n_epochs=2, clip_range=0.1)
    )
    tr3 = PolicyTrainer(slower, copy2, SAMPLE_REFERENCE, make_tracking_env)
    tr3.train()
    assert tr3.model.learning_rate == 1e-5 and tr3.model.n_epochs == 2
    assert tr3.model.clip_range(1.0) == pytest.approx(0.1)
    assert tr3.model.policy.optimizer.param_groups[0]["lr"] == pytest.approx(1e-5)
    # and its rollout's layout (environments x steps) and root-speed and lean augmentations
    copy3 = tmp_path / "resumed_layout"
    shutil.copytree(path, copy3)
    wider = dataclasses.replace(longer, ppo=dataclasses.replace(cfg.ppo, n_envs=4, n_steps=16),
                                env=dataclasses.replace(cfg.env, root_speed_range=(0.9, 1.1),
                                                        lean_range_deg=(-5.0, 5.0)))
    tr4 = PolicyTrainer(wider, copy3, SAMPLE_REFERENCE, make_tracking_env)
    tr4.train()
    assert tr4.model.n_envs == 4 and tr4.model.n_steps == 16
    assert tr4.cfg.env.root_speed_range == (0.9, 1.1)
    assert tr4.cfg.env.lean_range_deg == (-5.0, 5.0)
    assert tr4.total_done() == 128 + 128
    assert tr4.history[len(tr.history)]["timesteps"] == tr.history[-1]["timesteps"] + 64


def test_learning_rate_decays_over_the_end_of_the_last_stage(run, tmp_path):
    """Resumed with stage 2 extended to 192 decisions and a decay over its last 128: the
    updates after the rollouts ending at 128 and 192 use half and none of the rate."""
    path, tr = run
    import shutil

    copy = tmp_path / "decay"
    shutil.copytree(path, copy)
    cfg = _tiny()
    ppo = dataclasses.replace(cfg.ppo, learning_rate_decay_steps=128, learning_rate_final=0.0)
    longer = dataclasses.replace(cfg, ppo=ppo,
                                 stage2=dataclasses.replace(cfg.stage2, timesteps=192))  # fmt: skip
    tr2 = PolicyTrainer(longer, copy, SAMPLE_REFERENCE, make_tracking_env)
    tr2.train()
    new = tr2.history[len(tr.history) :]
    assert [h["timesteps"] for h in new] == [128 + 128, 128 + 192]
    lr0 = cfg.ppo.learning_rate
    assert [h["learning_rate"] for h in new] == pytest.approx([lr0 / 2, 0.0])
    assert tr2.model.policy.optimizer.param_groups[0]["lr"] == pytest.approx(0.0)
    # stage 1 and runs without the setting keep the constant rate
    assert all(h["learning_rate"] == pytest.approx(lr0) for h in tr.history)
    with pytest.raises(ValueError, match="learning_rate_decay_steps"):
        dataclasses.replace(cfg, ppo=dataclasses.replace(cfg.ppo, learning_rate_decay_steps=-1))


def test_category_selection_and_config_checks():
    from grip.core.reference import ReferenceSet

    ref = ReferenceSet.load(SAMPLE_REFERENCE)
    assert {c.category for c in select_clips(ref, ("run*",)).clips} == {"run"}
    with pytest.raises(ValueError, match="categories present"):
        select_clips(ref, ("swim",))
    with pytest.raises(ValueError, match="batch_size"):
        PolicyRunConfig(ppo=PPOConfig(n_envs=1, n_steps=8, batch_size=64))
    with pytest.raises(ValueError, match=r"amp\.loss"):
        PolicyRunConfig(amp=AmpConfig(loss="wgan"))
    from grip.config import apply_dict

    with pytest.raises(ValueError, match=r"categories: expected a list, got 'walk'"):
        apply_dict(PolicyRunConfig(), {"stage2": {"categories": "walk"}}, "x")  # letter by letter
    with pytest.raises(ValueError, match="expected a list of strings"):
        apply_dict(PolicyRunConfig(), {"stage2": {"categories": ["walk", 3]}}, "x")
    assert apply_dict(PolicyRunConfig(), {"stage2": {"categories": ["walk"]}},
                      "x").stage2.categories == ("walk",)  # fmt: skip


def test_eval_policy_rows_summary_and_files(run, tmp_path):
    from grip.cli.recordings import kin_checkpoint
    from grip.eval.policy import evaluate_policy, markdown_table, summarize_rows, write_rows
    from grip.kinematics.inference import KinematicsEstimator
    from prism_tools.synthetic import make_recording

    path, _ = run
    export_policy(path, tmp_path / "p.pt")
    runner = PolicyRunner.load(tmp_path / "p.pt")
    est = KinematicsEstimator.from_checkpoint(kin_checkpoint(None))
    recs = [make_recording(120, seed=s) for s in (0, 1)]
    rows = evaluate_policy(runner, est, recs)
    assert len(rows) == 2
    for r in rows:
        assert 2 <= r["frames"] <= 120
        assert r["fell"] == (r["frames"] < 120)
        for k in ("MPJPE_mm", "PA_MPJPE_mm", "kin_MPJPE_mm", "FP_mm", "root_err_m",
                  "kin_root_err_m"):  # fmt: skip
            assert np.isfinite(r[k]) and r[k] >= 0, k
        assert "travel_ratio" in r and "kin_travel_ratio" in r
    s = summarize_rows(rows)
    assert s["overall"]["segments"] == 2
    assert s["overall"]["success_rate"] == 100.0 * np.mean([not r["fell"] for r in rows])
    assert all(0 < r["pelvis_min_m"] < 2 for r in rows)
    low = [dict(r, fell=False, pelvis_min_m=0.1) for r in rows[:1]] + rows[1:]
    assert summarize_rows(low)["overall"]["success_rate_height"] == 100.0 * np.mean(
        [False] + [not r["fell"] and r["pelvis_min_m"] >= 0.3 for r in rows[1:]])  # fmt: skip
    assert summarize_rows(low)["overall"]["success_rate"] == 100.0 * np.mean(
        [True] + [not r["fell"] for r in rows[1:]])  # a low pelvis the detector let pass
    assert "| **all** |" in markdown_table(s)
    write_rows(rows, s, tmp_path / "out")
    assert (tmp_path / "out" / "segments.csv").read_text().count("\n") == 3
    # Following the ground truth: the reference error is zero, the estimate's is not.
    truth = evaluate_policy(runner, est, recs, reference="truth")
    for r, t in zip(rows, truth, strict=True):
        assert t["kin_MPJPE_mm"] < 1.0 < r["kin_MPJPE_mm"]
        assert t["kin_root_err_m"] < 1e-3 < r["kin_root_err_m"]
    with pytest.raises(ValueError, match="reference must be"):
        evaluate_policy(runner, est, recs, reference="oracle")


def test_action_repeat_training_counts_frames_and_the_export_keeps_it(tmp_path):
    base = _tiny()
    cfg = dataclasses.replace(
        base, env=dataclasses.replace(base.env, action_repeat=3),
        stage1=dataclasses.replace(base.stage1, timesteps=64, max_episode_frames=45),
        stage2=dataclasses.replace(base.stage2, timesteps=0),
    )  # fmt: skip
    (tmp_path / "config.json").write_text(json.dumps({"config": run_config_dict(cfg)}))
    tr = PolicyTrainer(cfg, tmp_path, SAMPLE_REFERENCE, make_tracking_env)
    tr.train()
    assert tr.total_done() == 64  # decisions
    ended = [h["ep_len"] for h in tr.history if "ep_len" in h]
    # 64 decisions x 3 frames over 2 envs: episodes truncated at 45 frames = 15 decisions
    assert ended and max(ended) <= 45 and max(ended) > 15
    assert all(h["frames"] == 3 * h["timesteps"] for h in tr.history)
    export_policy(tmp_path, tmp_path / "p.pt")
    assert PolicyRunner.load(tmp_path / "p.pt").env_cfg.action_repeat == 3


def _linears(seq) -> list:
    from policies.runner import linear_layers

    return linear_layers(seq)


def _warm_cfg(warmup: int) -> PolicyRunConfig:
    base = _tiny()
    return dataclasses.replace(
        base, ppo=dataclasses.replace(base.ppo, critic_warmup_steps=warmup),
        stage1=dataclasses.replace(base.stage1, timesteps=0),
        stage2=dataclasses.replace(base.stage2, timesteps=128),
    )  # fmt: skip


def test_warm_start_takes_the_exported_networks_and_warmup_trains_only_the_critic(run, tmp_path):
    import torch

    path, _ = run
    exported = tmp_path / "p.pt"
    export_policy(path, exported, half=False)
    src = PolicyRunner.load(exported)
    assert src.critic is not None and src.log_std is not None and src.obs_count > 0

    # warm-up covering the whole run: the policy stays exactly the exported one
    frozen = PolicyTrainer(_warm_cfg(10_000), tmp_path / "frozen", SAMPLE_REFERENCE,
                           make_tracking_env, init=exported)  # fmt: skip
    frozen.train()
    pol = frozen.model.policy
    ours = [*_linears(pol.mlp_extractor.policy_net), pol.action_net]
    for a, b in zip(ours, _linears(src.actor), strict=True):
        assert torch.equal(a.weight, b.weight) and torch.equal(a.bias, b.bias)
    assert torch.equal(pol.log_std, src.log_std)
    vf = [*_linears(pol.mlp_extractor.value_net), pol.value_net]
    moved = [not torch.equal(a.weight, b.weight) for a, b in zip(vf, _linears(src.critic),
                                                                   strict=True)]  # fmt: skip
    assert any(moved)  # the critic learned
    h = [r for r in frozen.history if r["stage"] == "stage2"]
    assert h and h[0]["timesteps"] == 64  # stage 1 of 0 steps is skipped
    # before any update: the discriminator and the observation normaliser are the file's
    fresh = PolicyTrainer(_warm_cfg(0), tmp_path / "fresh", SAMPLE_REFERENCE, make_tracking_env,
                          init=exported)
    fresh.venv = fresh._build_env(fresh.cfg.stage2)
    fresh.model = fresh._new_model(fresh.venv)
    fresh.warm_start(src)
    for k, v in src.disc.state_dict().items():
        assert torch.equal(fresh.amp.disc.state_dict()[k], v), k
    for k, rms in fresh.venv.obs_rms.items():
        np.testing.assert_array_equal(rms.mean, src.obs_mean[k])
        np.testing.assert_array_equal(rms.var, src.obs_var[k])
        assert rms.count == src.obs_count
    fresh.venv.close()
    # no warm-up: the policy trains from the exported weights
    (tmp_path / "free").mkdir()
    (tmp_path / "free" / "config.json").write_text(
        json.dumps({"config": run_config_dict(_warm_cfg(0))}))
    free = PolicyTrainer(_warm_cfg(0), tmp_path / "free", SAMPLE_REFERENCE, make_tracking_env,
                         init=exported)
    free.train()
    pol = free.model.policy
    ours = [*_linears(pol.mlp_extractor.policy_net), pol.action_net]
    assert any(not torch.equal(a.weight, b.weight) for a, b in zip(ours, _linears(src.actor),
                                                                     strict=True))  # fmt: skip
    # the new run's export is close to the one it started from (a few small updates)
    export_policy(tmp_path / "free", tmp_path / "free.pt", half=False)
    env = GripTrackingEnv(src.env_cfg)
    obs, _ = env.reset(seed=5)
    a0, a1 = src.act(obs), PolicyRunner.load(tmp_path / "free.pt").act(obs)
    assert np.abs(a0 - a1).max() < 0.5


def test_warm_start_refuses_a_policy_of_another_size(run, tmp_path):
    path, _ = run
    exported = tmp_path / "p.pt"
    export_policy(path, exported)
    cfg = _warm_cfg(0)
    wider = dataclasses.replace(cfg, ppo=dataclasses.replace(cfg.ppo, net_arch=(64, 32)))
    tr = PolicyTrainer(wider, tmp_path / "wider", SAMPLE_REFERENCE, make_tracking_env,
                       init=exported)
    with pytest.raises(ValueError, match=r"p\.pt: its policy network has layers"):
        tr.train()
    with pytest.raises(ValueError, match=r"junk\.pt"):
        (tmp_path / "junk.pt").write_bytes(b"junk")
        PolicyTrainer(cfg, tmp_path / "j", SAMPLE_REFERENCE, make_tracking_env,
                      init=tmp_path / "junk.pt")


def test_warm_start_refuses_another_observation_variant(run, tmp_path):
    path, _ = run
    exported = tmp_path / "p.pt"
    export_policy(path, exported, half=False)
    assert PolicyRunner.load(exported).env_cfg.kinematic_obs == "OAV_Jrel"
    cfg = _warm_cfg(0)
    glo = dataclasses.replace(cfg, env=dataclasses.replace(cfg.env, kinematic_obs="OAV_Jglo"))
    tr = PolicyTrainer(glo, tmp_path / "jglo", SAMPLE_REFERENCE, make_tracking_env, init=exported)
    with pytest.raises(ValueError, match=r"p\.pt: trained with env.kinematic_obs='OAV_Jrel'"):
        tr.train()


def test_warm_start_grows_the_observation_by_the_root_gap(run, tmp_path):
    """An ``OAV_Jrel`` policy starts an ``OAV_Jrel_root`` run (issue 46): the new inputs get
    weights 0, so the run's first policy acts exactly as the file did, whatever the gap."""
    import torch

    path, _ = run
    exported = tmp_path / "p.pt"
    export_policy(path, exported, half=False)
    src = PolicyRunner.load(exported)
    cfg = _warm_cfg(0)
    cfg = dataclasses.replace(cfg, env=dataclasses.replace(cfg.env, kinematic_obs="OAV_Jrel_root"))
    tr = PolicyTrainer(cfg, tmp_path / "root", SAMPLE_REFERENCE, make_tracking_env, init=exported)
    tr.venv = tr._build_env(tr.cfg.stage2)
    tr.model = tr._new_model(tr.venv)
    tr.warm_start(src)
    rms = tr.venv.obs_rms["kinematic"]
    n = src.obs_mean["kinematic"].shape[0]
    np.testing.assert_array_equal(rms.mean[:n], src.obs_mean["kinematic"])
    np.testing.assert_array_equal(rms.mean[n:], 0.0)
    assert rms.mean.shape == (n + 2,) and (rms.var[n:] > 0).all()
    env = GripTrackingEnv(cfg.env)
    obs, _ = env.reset(seed=5)
    old = {k: (v[:n] if k == "kinematic" else v) for k, v in obs.items()}
    want = src.act(old)
    for gap in ((0.0, 0.0), (0.7, -0.4)):
        obs["kinematic"][-2:] = gap
        x = tr.venv.normalize_obs({k: v[None] for k, v in obs.items()})
        with torch.no_grad():
            got = tr.model.policy.predict(x, deterministic=True)[0][0]
        np.testing.assert_allclose(got, want, atol=1e-5)
    tr.venv.close()


def test_stored_configs_with_removed_settings():
    from grip.config import ConfigError
    from policies.config import REMOVED_IN, policy_config_from_dict

    d = run_config_dict(PolicyRunConfig())
    old = {**d, "push_force_n": 0.0, "push_every_s": 3.0, "reverse_categories": [],
           "ppo": {**d["ppo"], "fixed_std": False, "target_kl": 0.0},
           "amp": {**d["amp"], "from_init": True}}  # the removed settings at their "off" values
    assert policy_config_from_dict(old, "x", training=True) == PolicyRunConfig()
    on = {**d, "push_force_n": 150.0, "ppo": {**d["ppo"], "target_kl": 0.05}}
    with pytest.raises(ConfigError, match=f"ppo.target_kl = 0.05 turns on PPO's KL early stop.*"
                                          f"{REMOVED_IN}"):  # fmt: skip
        policy_config_from_dict(on, "run/config.json", training=True)
    # playing a file needs none of them: how it was trained does not change what it does
    assert policy_config_from_dict(on, "x") == PolicyRunConfig()
    jhor = {**d, "env": {**d["env"], "kinematic_obs": "OAV_Jhor"}}
    with pytest.raises(ConfigError, match=f"kinematic_obs = 'OAV_Jhor' was removed.*{REMOVED_IN}"):
        policy_config_from_dict(jhor, "x")
    with pytest.raises(ConfigError, match="unknown key 'no_such_knob'"):
        policy_config_from_dict({**d, "no_such_knob": 1}, "x")


def test_batched_vec_env_trains_the_same_policy_as_dummy(tmp_path):
    """``ppo.vec_env = "batched"`` gives the transitions of ``"dummy"``, so the same seed trains
    the same networks (the layouts are interchangeable)."""
    import torch

    base = _tiny()
    runs = {}
    for kind in ("dummy", "batched"):
        cfg = dataclasses.replace(
            base, env=dataclasses.replace(base.env, action_repeat=3),
            ppo=dataclasses.replace(base.ppo, vec_env=kind, env_threads=2),
            stage1=dataclasses.replace(base.stage1, timesteps=128, max_episode_frames=45),
            stage2=dataclasses.replace(base.stage2, timesteps=0), checkpoint_every=100,
        )  # fmt: skip
        d = tmp_path / kind
        d.mkdir()
        (d / "config.json").write_text(json.dumps({"config": run_config_dict(cfg)}))
        torch.manual_seed(0)  # (the discriminator's initial weights come from torch's RNG)
        tr = PolicyTrainer(cfg, d, SAMPLE_REFERENCE, make_tracking_env)
        tr.train()
        runs[kind] = tr
    a, b = runs["dummy"], runs["batched"]
    drop = {"wall_s"}
    assert [{k: v for k, v in h.items() if k not in drop} for h in b.history] == [
        {k: v for k, v in h.items() if k not in drop} for h in a.history
    ]
    for p, q in zip(a.model.policy.parameters(), b.model.policy.parameters(), strict=True):
        torch.testing.assert_close(q, p, rtol=0, atol=0)


def test_rows_count_the_episodes_of_each_category(run):
    """Each rollout's row counts its ended episodes and failures per category: the per-category
    learning curves of benchmarks/teacher_curve.py."""
    _, tr = run
    rows = [h for h in tr.history if h["episodes"]]
    assert rows
    cats = set(tr.clip_categories.values())
    for h in rows:
        by_cat = h["by_category"]
        assert set(by_cat) <= cats, by_cat
        assert sum(n for n, _ in by_cat.values()) == h["episodes"]
        fails = sum(f for _, f in by_cat.values())
        assert fails == round(h["episodes"] * (1.0 - h["success_rate"]))


def test_teacher_curve_projects_rising_categories_only(tmp_path, capsys):
    from tests.cli.test_data_cli import _benchmark

    tc = _benchmark("teacher_curve")
    hist = []
    for r in range(40):  # 40 rollouts of 50 k decisions: "walk" rises, "dance" stays flat
        t = r * 50_000 + 1
        ok_walk = min(30, 5 + r)
        hist.append({"timesteps": t, "stage": "stage2", "episodes": 60, "success_rate": 0.5,
                     "mpjpe_mm": 90.0, "ep_len": 200.0,
                     "by_category": {"walk": [30, 30 - ok_walk], "dance": [30, 24]}})  # fmt: skip
    curves = tc._category_curves(hist, 250_000, 0.95, 20)
    assert list(curves) == ["walk", "dance"] or list(curves) == ["dance", "walk"]
    assert curves["dance"]["success"] == pytest.approx([0.2] * 8)
    assert curves["dance"]["decisions_to_target"] is None
    walk = curves["walk"]
    assert walk["episodes"] == [150] * 8 and walk["success"] == sorted(walk["success"])
    assert walk["decisions_to_target"] > 1e6
    run = tmp_path / "run"
    (run / "checkpoint").mkdir(parents=True)
    (run / "checkpoint" / "state.json").write_text(json.dumps({"history": hist, "wall_s": 3600}))
    assert tc.main(["--run", str(run), "--json", str(tmp_path / "c.json"),
                    "--png", str(tmp_path / "c.png")]) == 0  # fmt: skip
    assert "dance" in capsys.readouterr().out
    assert json.loads((tmp_path / "c.json").read_text())["category_curves"]["walk"]["success"]
    assert (tmp_path / "c.png").read_bytes()[:4] == b"\x89PNG"


def test_teacher_curve_groups_categories_by_source(tmp_path):
    from tests.cli.test_data_cli import _benchmark

    tc = _benchmark("teacher_curve")
    clips = [{"clip_id": "bandai_namco/dataset-1_walk_x_001", "category": "walk",
              "group": "bandai_namco/dataset-1/x"},
             {"clip_id": "cmu/14_01", "category": "walk", "group": "cmu/14"},
             {"clip_id": "cmu/14_02", "category": None, "group": None}]  # fmt: skip
    (tmp_path / "manifest.json").write_text(json.dumps({"clips": clips}))
    assert tc._categories(tmp_path) == {"bandai_namco/dataset-1_walk_x_001": "walk",
                                        "cmu/14_01": "walk", "cmu/14_02": "unknown"}
    assert tc._categories(tmp_path, by_source=True) == {
        "bandai_namco/dataset-1_walk_x_001": "walk bandai_namco/dataset-1",
        "cmu/14_01": "walk cmu", "cmu/14_02": "unknown cmu"}  # fmt: skip
    # a training walk played faster (speed_factors) is its clip's
    for name in ("synthetic_bandai_namco/dataset-1_walk_x_001@x1.5_seq000",
                 "synthetic_bandai_namco/dataset-1_walk_x_001_seq000#1"):  # fmt: skip
        assert tc._clip_id(name) == "bandai_namco/dataset-1_walk_x_001"
