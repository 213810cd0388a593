"""Issue 47's curricula: failure-weighted starts within clips, per-category termination, the
real windows' clip probabilities and training without AMP; pure parts, env hooks, and tiny
training runs on the bundled sample (a walk and a run clip of 250 frames)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch

from envs.factory import make_tracking_env
from envs.tracking_env import SAMPLE_REFERENCE, GripTrackingEnv
from grip.core.reference_sets import start_bin_probabilities, start_bin_table
from grip.task import amp as A
from policies.config import StageConfig
from policies.curriculum import TERMINATION_MIN_EPISODES, CategoryTermination
from policies.mining import MIN_BIN_DECAY, StartBinStats
from policies.train import PolicyTrainer, run_config_dict
from tests.policies.test_train import _tiny


# ------------------------------------------------------------------ pure parts
def test_start_bin_probabilities_weigh_each_bins_start_frames():
    # starts 0..249 in bins of 100: 100, 100 and 50 start frames
    np.testing.assert_allclose(start_bin_probabilities(249, 100, [1, 1, 1, 7]), [0.4, 0.4, 0.2])
    np.testing.assert_allclose(start_bin_probabilities(249, 100, [0, 1, 2]), [0, 0.5, 0.5])
    np.testing.assert_allclose(start_bin_probabilities(0, 100, [3.0]), [1.0])
    for bad in ([1, 1], [1, np.nan, 1], [1, -1, 1]):
        with pytest.raises(ValueError, match="start bin weights"):
            start_bin_probabilities(249, 100, bad)
    with pytest.raises(ValueError, match="all zero"):
        start_bin_probabilities(249, 100, [0, 0, 0])
    table = start_bin_table(np.array([249, 99]), 100, [None, [5.0]])
    np.testing.assert_allclose(table, [[0.4, 0.4, 0.2], [1.0, 0.0, 0.0]])


def test_start_bins_count_episodes_through_each_bin_and_failures_where_they_end():
    st = StartBinStats(["a", "b"], [250, 100], bin_frames=100, mix=1.0, memory=4.0, prior=1.0)
    assert st.n_bins.tolist() == [3, 1]
    assert [w.tolist() for w in st.weights()] == [[1, 1, 1], [1]]  # nothing seen yet
    st.add(0, 10, 230, failed=True)  # through bins 0, 1, 2; fails in 2
    st.add([0, 1], [120, 0], [180, 60], [False, False])  # bin 1 of a; bin 0 of b
    np.testing.assert_allclose(st.episodes, [1, 2, 1, 1])
    np.testing.assert_allclose(st.fails, [0, 0, 1, 0])
    f = 1 / 5  # overall: one failure in five episode-bins
    fa, fb = (1 + f) / (4 + 1), (0 + f) / (1 + 1)  # the clips', shrunk to f
    np.testing.assert_allclose(st.clip_rates(), [fa, fb])
    bins_a = np.array([(0 + fa) / 2, (0 + fa) / 3, (1 + fa) / 2])
    np.testing.assert_allclose(st.weights()[0], bins_a / fa)  # mix 1: proportional
    assert st.weights()[0].argmax() == 2  # (the bin where the episode failed)
    half = StartBinStats(["a", "b"], [250, 100], 100, mix=0.5, memory=4.0, prior=1.0)
    half.load_state_dict(st.state_dict())
    np.testing.assert_allclose(half.weights()[0], 0.5 + 0.5 * bins_a / fa)
    # the decay follows the data: 5 episode-bins over 4 bins, memory 4 -> 1 - 1.25 / 4
    assert st.end_rollout() == pytest.approx(0.6875)
    np.testing.assert_allclose(st.episodes, 0.6875 * np.array([1, 2, 1, 1]))
    assert st.end_rollout() == 1.0  # (nothing added: no decay)
    for _ in range(10):
        st.add(0, 0, 249, False)
    assert st.end_rollout() == MIN_BIN_DECAY  # (bounded)


def test_start_bins_state_maps_by_name_and_drops_what_changed():
    st = StartBinStats(["a", "b"], [250, 100], 100, mix=1.0)
    st.add([0, 1], [0, 0], [249, 99], [True, False])
    other = StartBinStats(["b", "new", "a"], [100, 300, 150], 100, mix=1.0)
    other.load_state_dict(st.state_dict())
    # b kept; a has 2 bins now instead of 3: dropped; new starts at zero
    assert other.episodes.tolist() == [1, 0, 0, 0, 0, 0] and other.fails.sum() == 0
    coarse = StartBinStats(["a", "b"], [250, 100], 50, mix=1.0)
    coarse.load_state_dict(st.state_dict())
    assert coarse.episodes.sum() == 0  # (other bins: nothing applies)
    for kwargs in ({"mix": 1.5}, {"mix": 0.5, "memory": 0.0}, {"mix": 0.5, "prior": 0.0}):
        with pytest.raises(ValueError):
            StartBinStats(["a"], [100], 100, **kwargs)


def test_category_termination_tightens_loosens_and_stays_in_bounds():
    ct = CategoryTermination(["walk", "run", "walk", "dance"], start_m=0.5, min_m=0.2,
                             max_m=0.6, band=(0.5, 0.8), step=0.1, memory=1e9)  # fmt: skip
    assert ct.categories == ["walk", "run", "dance"]
    np.testing.assert_allclose(ct.clip_dists(), [0.5, 0.5, 0.5, 0.5])

    def rollout():
        ct.add([0, 2, 0, 2, 0], [True] * 5)  # walk: 5 of 5 reach their limit
        ct.add([1] * 4, [False, False, False, True])  # run: 1 of 4
        ct.end_rollout()

    ct.add([3] * 3, [False] * 3)  # dance: too few episodes to judge
    assert 3 < TERMINATION_MIN_EPISODES <= 4
    rollout()
    np.testing.assert_allclose(ct.dist_m, [0.45, 0.55, 0.5])
    np.testing.assert_allclose(ct.clip_dists(), [0.45, 0.55, 0.45, 0.5])
    for _ in range(20):
        rollout()
    np.testing.assert_allclose(ct.dist_m, [0.2, 0.6, 0.5])
    ct.end_rollout()  # (no new episodes: nothing moves, nothing decays)
    np.testing.assert_allclose(ct.dist_m, [0.2, 0.6, 0.5])
    # the counts decay by each category's new episodes: memory 10, 4 new -> x 0.6
    mid = CategoryTermination(["walk"], 0.3, 0.1, 1.0, (0.5, 0.8), 0.1, memory=10.0)
    mid.add([0] * 4, [True] * 3 + [False])  # 0.75: in the band, no change
    mid.end_rollout()
    assert mid.dist_m.tolist() == [0.3]
    np.testing.assert_allclose([mid.episodes[0], mid.reached[0]], [2.4, 1.8])
    mid.add([0] * 30, [True] * 30)
    mid.end_rollout()  # (a decay of at most one half a rollout)
    assert mid.dist_m[0] == pytest.approx(0.27) and mid.episodes[0] == pytest.approx(16.2)
    fresh = CategoryTermination(["run", "walk", "jump"], 0.5, 0.3, 0.6, (0.5, 0.8), 0.1)
    fresh.load_state_dict(ct.state_dict())
    np.testing.assert_allclose(fresh.dist_m, [0.6, 0.3, 0.5])  # clamped; jump keeps its start
    assert CategoryTermination(["a"], 5.0, 0.2, 0.6, (0.5, 0.8), 0.1).dist_m.tolist() == [0.6]
    with pytest.raises(ValueError):
        CategoryTermination(["a"], 0.5, 0.0, 0.6, (0.5, 0.8), 0.1)


def test_stage_settings_are_checked():
    for kwargs, match in (({"mining_bins_mix": 1.5}, "mining_bins_mix"),
                          ({"mining_bins_memory": 0.0}, "mining_bins_memory"),
                          ({"termination_category_min_m": -1.0}, "termination_category_min_m"),
                          ({"termination_category_min_m": 0.5,
                            "termination_category_max_m": 0.4}, "max_m"),
                          ({"termination_category_band": (0.8, 0.5)}, "band"),
                          ({"termination_category_step": 1.0}, "step")):  # fmt: skip
        with pytest.raises(ValueError, match=match):
            StageConfig(**kwargs)


# ------------------------------------------------------------------ env hooks
def test_env_start_bins_steer_random_starts_and_none_restores_the_uniform_draw():
    env = GripTrackingEnv()  # two clips of 250 frames; starts 0..239 (min_episode_frames 10)
    uniform = [env.reset(seed=s)[1]["frame"] for s in range(10)]
    env.set_start_bin_weights(100, [np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])])
    for s in range(40):
        _, info = env.reset(seed=s)
        lo = 100 if info["clip_index"] == 0 else 200
        assert lo <= info["frame"] < lo + 100 and info["frame"] <= 239
    env.set_start_bin_weights(100, None)
    assert [env.reset(seed=s)[1]["frame"] for s in range(10)] == uniform
    with pytest.raises(ValueError, match="one entry per clip"):
        env.set_start_bin_weights(100, [np.ones(3)])


def test_env_clip_termination_distances_apply_per_episode():
    env = GripTrackingEnv()
    env.set_clip_weights([1.0, 0.0])
    env.reset(seed=0)
    env.set_clip_termination_dists([1e-6, 0.0])  # clip 0: any motion ends the episode
    assert env.termination_dist_m == 1e-6  # (from now on, the current episode too)
    assert env.step(np.zeros(env.action_space.shape))[2]
    env.set_clip_weights([0.0, 1.0])
    env.reset(seed=1)
    assert env.termination_dist_m == 0.0
    assert not env.step(np.zeros(env.action_space.shape))[2]
    with pytest.raises(ValueError, match="clip termination"):
        env.set_clip_termination_dists([0.1])


# ------------------------------------------------------------------ training runs
def _stage2_run(tmp_path, name="run", amp_weight=None, **stage2):
    """A tiny run of stage 2 only (its settings ``stage2``), returned with its config."""
    cfg = _tiny()
    cfg = dataclasses.replace(
        cfg, stage1=dataclasses.replace(cfg.stage1, timesteps=0),
        stage2=dataclasses.replace(cfg.stage2, **{"timesteps": 192, "categories": (),
                                                  **stage2}))  # fmt: skip
    if amp_weight is not None:
        w = dataclasses.replace(cfg.env.reward.weights, amp=amp_weight)
        reward = dataclasses.replace(cfg.env.reward, weights=w)
        cfg = dataclasses.replace(cfg, env=dataclasses.replace(cfg.env, reward=reward))
    run = tmp_path / name
    run.mkdir()
    (run / "config.json").write_text(json.dumps({"config": run_config_dict(cfg)}))
    return cfg, run


def _spying_maker(calls: list):
    """``make_tracking_env``, recording every curriculum call to its environments."""

    def make(env_cfg, categories, seed):
        env = make_tracking_env(env_cfg, categories, seed)
        base = env.unwrapped
        for method in ("set_start_bin_weights", "set_clip_termination_dists"):
            orig = getattr(base, method)

            def spy(*args, _orig=orig, _name=method):
                calls.append((_name, args))
                return _orig(*args)

            setattr(base, method, spy)
        return env

    return make


def test_real_windows_come_only_from_the_stages_category(tmp_path):
    """Two clips of different categories, stage 2 on ``walk*``: with ``"episodes"`` every real
    window the discriminator trains on is one of the walk clip's (with ``"frames"``, the
    default, about half are the run clip's), and the sampler holds the envs' probabilities."""
    cfg, run = _stage2_run(tmp_path, categories=("walk*",))
    cfg = dataclasses.replace(cfg, amp=dataclasses.replace(cfg.amp, real_sampling="episodes"))
    (run / "config.json").write_text(json.dumps({"config": run_config_dict(cfg)}))
    tr = PolicyTrainer(cfg, run, SAMPLE_REFERENCE, make_tracking_env)
    drawn = []
    sample = tr.amp.real.sample
    tr.amp.real.sample = lambda n, rng: drawn.append(sample(n, rng)) or drawn[-1]
    tr.train()
    from grip.core.reference import ReferenceSet

    ref = ReferenceSet.load(SAMPLE_REFERENCE, compact=True)  # (as the trainer holds it)
    assert [c.category for c in ref.clips] == ["walk", "run"]
    frames = [{r.tobytes() for r in A.reference_amp_features(c).astype(np.float32)}
              for c in ref.clips]  # fmt: skip
    last = np.concatenate(drawn)[:, -A.FRAME_DIM :]
    assert len(last) >= 3 * cfg.amp.batch_size  # (one update per rollout)
    assert all(r.tobytes() in frames[0] and r.tobytes() not in frames[1] for r in last)
    np.testing.assert_allclose(tr.amp.real.clip_p, [1.0, 0.0])
    np.testing.assert_allclose(tr.amp.real.clip_p, tr.curriculum.real_probabilities())


def test_real_windows_follow_the_miners_weights(tmp_path):
    """All categories with hard-clip mining: after every rollout the real windows' clip
    probabilities are the environments' (length x mining weight, normalised)."""
    cfg, run = _stage2_run(tmp_path, termination_dist_m=0.12, max_episode_frames=20,
                           mining_mix=1.0, mining_decay=0.9)  # fmt: skip
    cfg = dataclasses.replace(cfg, amp=dataclasses.replace(cfg.amp, real_sampling="episodes"))
    (run / "config.json").write_text(json.dumps({"config": run_config_dict(cfg)}))
    tr = PolicyTrainer(cfg, run, SAMPLE_REFERENCE, make_tracking_env)
    tr.train()
    assert tr.mining.weights().std() > 0  # (the clips failed differently)
    for p in tr.venv.get_attr("_clip_p"):
        np.testing.assert_allclose(tr.amp.real.clip_p, p)


def test_amp_weight_zero_skips_the_discriminator(tmp_path):
    """``env.reward.weights.amp = 0``: the discriminator is never run or trained (weights and
    optimiser as built, rows' AMP statistics and style reward 0), and the exported file's
    discriminator says 0.5 on any window: under the fall threshold (0.7), so GRIP's fall
    detector falls back to the pelvis height."""
    from policies.runner import PolicyRunner, export_policy

    cfg, run = _stage2_run(tmp_path, amp_weight=0.0)
    tr = PolicyTrainer(cfg, run, SAMPLE_REFERENCE, make_tracking_env)
    before = {k: v.clone() for k, v in tr.amp.disc.state_dict().items()}
    calls = []
    score = tr.amp.disc.forward
    tr.amp.disc.forward = lambda x: calls.append(len(x)) or score(x)
    tr.train()
    assert not calls and not tr.amp.opt.state and len(tr.amp.replay) == 0
    for k, v in tr.amp.disc.state_dict().items():
        assert torch.equal(v, before[k]), k
    for h in tr.history:
        assert h["reward/amp"] == 0.0 and h["amp/loss"] == 0.0 and h["amp/acc_real"] == 0.0
    out = tmp_path / "policy.pt"
    export_policy(run, out)
    runner = PolicyRunner.load(out)
    windows = np.random.default_rng(0).normal(size=(20, cfg.amp.window * A.FRAME_DIM))
    np.testing.assert_array_equal(runner.fall_probability(windows), 0.5)


def test_start_bins_in_training_push_weights_checkpoint_and_resume(tmp_path):
    """``mining_bins_mix``: the trainer counts each ended episode's bins, hands the envs the
    weights after every rollout, saves the counts with the stage, and a resumed run first
    pushes the weights of the saved counts (a fresh start would push all ones)."""
    calls: list = []
    cfg, run = _stage2_run(tmp_path, termination_dist_m=0.12, max_episode_frames=20,
                           mining_bins_mix=1.0, mining_bins_memory=4.0)  # fmt: skip
    tr = PolicyTrainer(cfg, run, SAMPLE_REFERENCE, _spying_maker(calls))
    tr.train()
    bins = tr.curriculum.bins
    assert bins is not None and bins.bin_frames == 100 and bins.n_bins.tolist() == [3, 3]
    assert bins.episodes.sum() > 0 and 0 < bins.fails.sum()
    assert np.concatenate(bins.weights()).std() > 0
    pushed = [args for name, args in calls if name == "set_start_bin_weights"]
    assert len(pushed) == 2 * (1 + len(tr.history))  # (2 envs: at the start, every rollout)
    f, last = pushed[-1]
    assert f == 100
    for got, want in zip(last, bins.weights(), strict=True):
        np.testing.assert_allclose(got, want)
    for env in tr.venv.venv.venv.venv.envs:  # (VecNormalize, VecMonitor, AmpReward, Dummy)
        assert env.unwrapped._start_bins[0] == 100
    state = json.loads((run / "checkpoint" / "state.json").read_text())
    assert state["start_bins"]["stage_index"] == 1
    np.testing.assert_allclose(np.concatenate(state["start_bins"]["episodes"]), bins.episodes)
    saved = StartBinStats(bins.names, [250, 250], 100, 1.0, 4.0)
    saved.load_state_dict(state["start_bins"])
    longer = dataclasses.replace(cfg, stage2=dataclasses.replace(cfg.stage2, timesteps=256))
    again: list = []
    tr2 = PolicyTrainer(longer, run, SAMPLE_REFERENCE, _spying_maker(again))
    tr2.train()
    first = next(args for name, args in again if name == "set_start_bin_weights")[1]
    for got, want in zip(first, saved.weights(), strict=True):
        np.testing.assert_allclose(got, want)
    assert any(w.std() > 0 for w in first)
    assert len(tr2.history) == len(tr.history) + 1


def test_category_termination_in_training_sets_each_clips_distance_and_resumes(tmp_path):
    """``termination_category_min_m``: every env ends its episode at its clip's category's
    distance; the distances start at the stage's (here its max: stage 2 has none), move by
    how episodes end (short episodes at a loose distance mostly reach their limit: they
    tighten), are logged per category, saved and restored."""
    calls: list = []
    cfg, run = _stage2_run(tmp_path, timesteps=256, max_episode_frames=8,
                           termination_category_min_m=0.1, termination_category_max_m=0.6,
                           termination_category_step=0.2)  # fmt: skip
    tr = PolicyTrainer(cfg, run, SAMPLE_REFERENCE, _spying_maker(calls))
    tr.train()
    term = tr.curriculum.termination
    assert term.categories == ["walk", "run"]
    rows = tr.history
    assert rows[0]["termination_by_category"] == {"walk": 0.6, "run": 0.6}
    assert rows[0]["termination_m"] == pytest.approx(0.6)
    assert min(term.dist_m) < 0.6  # (it moved)
    last = rows[-1]["termination_by_category"]
    assert rows[-1]["termination_m"] == pytest.approx(np.mean(list(last.values())))
    for env in tr.venv.venv.venv.venv.envs:
        e = env.unwrapped
        assert e.termination_dist_m == pytest.approx(term.dist_m[e._clip_i])
    pushed = [args[0] for name, args in calls if name == "set_clip_termination_dists"]
    np.testing.assert_allclose(pushed[-1], term.clip_dists())
    state = json.loads((run / "checkpoint" / "state.json").read_text())
    assert state["termination"]["dist_m"] == term.dist_m.tolist()
    longer = dataclasses.replace(cfg, stage2=dataclasses.replace(cfg.stage2, timesteps=320))
    again: list = []
    tr2 = PolicyTrainer(longer, run, SAMPLE_REFERENCE, _spying_maker(again))
    tr2.train()
    first = next(args[0] for name, args in again if name == "set_clip_termination_dists")
    np.testing.assert_allclose(first, term.clip_dists())  # (the saved distances, not 0.6)
    assert tr2.history[: len(rows)] == json.loads(json.dumps(rows))
    assert len(tr2.history) == len(rows) + 1


def test_a_fork_may_change_the_style_reward_and_the_curricula_on_resume():
    """A/B forks of a checkpoint: the real windows' sampler, AMP on or off, the termination
    settings of stage 1, every stage-2 setting and the threads may change; stage 1's start
    bins may not (a stage-1 setting like its mining mix), and a run recorded before these
    settings existed resumes with them at their defaults."""
    from grip.core.runs import changed_settings
    from policies.config import PolicyRunConfig
    from policies.train import RESUMABLE

    base = PolicyRunConfig()
    old, defaults = run_config_dict(base), run_config_dict(PolicyRunConfig())
    w = dataclasses.replace(base.env.reward.weights, amp=0.0)
    fork = dataclasses.replace(
        base, amp=dataclasses.replace(base.amp, real_sampling="episodes"),
        env=dataclasses.replace(base.env, reward=dataclasses.replace(base.env.reward, weights=w)),
        stage1=dataclasses.replace(base.stage1, termination_category_min_m=0.2),
        stage2=dataclasses.replace(base.stage2, mining_bins_mix=0.5),
        ppo=dataclasses.replace(base.ppo, threads=2, env_threads=2))  # fmt: skip
    assert changed_settings(old, run_config_dict(fork), defaults, RESUMABLE) == []
    bins1 = dataclasses.replace(base, stage1=dataclasses.replace(base.stage1,
                                                                 mining_bins_mix=0.5))  # fmt: skip
    assert changed_settings(old, run_config_dict(bins1), defaults, RESUMABLE) == [
        "stage1.mining_bins_mix"]  # fmt: skip
    older = run_config_dict(base)
    del older["amp"]["real_sampling"], older["stage2"]["mining_bins_mix"]
    assert changed_settings(older, run_config_dict(base), defaults, RESUMABLE) == []
