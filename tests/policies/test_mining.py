"""Hard-clip mining: failure counts -> clip weights -> the environments' clip sampling."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from envs.factory import make_tracking_env
from envs.tracking_env import SAMPLE_REFERENCE, GripTrackingEnv
from policies.mining import ClipFailureStats
from policies.train import PolicyTrainer, run_config_dict


def test_weights_follow_the_shrunk_failure_rates():
    st = ClipFailureStats(["a", "b", "c"], mix=1.0, decay=0.5, prior=2.0)
    assert st.weights().tolist() == [1.0, 1.0, 1.0]  # nothing seen yet
    for _ in range(3):
        st.add(0, failed=True)
    st.add(1, failed=False)
    st.add(1, failed=True)
    # overall 4 fails in 5 episodes: f = 0.8; clip c (unseen) gets exactly f
    f = 0.8
    rates = [(3 + 2 * f) / (3 + 2), (1 + 2 * f) / (2 + 2), f]
    np.testing.assert_allclose(st.failure_rates(), rates)
    np.testing.assert_allclose(st.weights(), np.array(rates) / f)
    half = ClipFailureStats(["a", "b", "c"], mix=0.5, decay=0.5, prior=2.0)
    half.load_state_dict(st.state_dict())
    np.testing.assert_allclose(half.weights(), 0.5 + 0.5 * np.array(rates) / f)
    assert ClipFailureStats(["a", "b", "c"], mix=0.0).weights().tolist() == [1, 1, 1]
    # decay scales every count (the overall rate stays), so the prior weighs more
    st.end_rollout()
    np.testing.assert_allclose(st.episodes, [1.5, 1.0, 0.0])
    np.testing.assert_allclose(st.failure_rates(), [(1.5 + 1.6) / 3.5, (0.5 + 1.6) / 3.0, f])
    assert st.hardest(1)[0][0] == "a"


def test_no_failures_keeps_uniform_weights_and_state_maps_by_name():
    st = ClipFailureStats(["a", "b"], mix=1.0)
    st.add(0, failed=False)
    assert st.weights().tolist() == [1.0, 1.0]
    st.add(1, failed=True)
    other = ClipFailureStats(["b", "new", "a"], mix=1.0)
    other.load_state_dict(st.state_dict())
    assert other.episodes.tolist() == [1.0, 0.0, 1.0] and other.fails.tolist() == [1.0, 0, 0]
    for kwargs, match in (({"mix": 1.5}, "mix"), ({"mix": 0.5, "decay": 0.0}, "decay"),
                          ({"mix": 0.5, "prior": 0.0}, "prior")):  # fmt: skip
        with pytest.raises(ValueError, match=match):
            ClipFailureStats(["a"], **kwargs)
    with pytest.raises(ValueError, match="unique"):
        ClipFailureStats(["a", "a"], mix=0.5)


def test_env_clip_weights_steer_random_starts():
    env = GripTrackingEnv()
    assert len(env.reference) == 2
    env.set_clip_weights([0.0, 1.0])
    picks = {env.reset(seed=s)[1]["clip_index"] for s in range(20)}
    assert picks == {1}
    env.set_clip_weights([1.0, 0.0])
    assert {env.reset(seed=s)[1]["clip_index"] for s in range(20)} == {0}
    for bad in ([1.0], [np.nan, 1.0], [-1.0, 1.0]):
        with pytest.raises(ValueError, match="clip weights"):
            env.set_clip_weights(bad)
    with pytest.raises(ValueError, match="all zero"):
        env.set_clip_weights([0.0, 0.0])


def test_training_with_mining_counts_episodes_pushes_weights_and_resumes(tmp_path):
    from tests.policies.test_train import _tiny

    cfg = _tiny()
    cfg = dataclasses.replace(
        cfg,
        stage1=dataclasses.replace(cfg.stage1, timesteps=0),
        stage2=dataclasses.replace(cfg.stage2, timesteps=256, max_episode_frames=20,
                                   termination_dist_m=0.12, categories=(), mining_mix=1.0,
                                   mining_decay=0.9),  # (a tight distance: some episodes fail)
    )  # fmt: skip
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_text(json.dumps({"config": run_config_dict(cfg)}))
    tr = PolicyTrainer(cfg, run, SAMPLE_REFERENCE, make_tracking_env)
    tr.train()
    mining = tr.mining
    assert mining is not None and mining.episodes.sum() > 0
    assert 0 < mining.fails.sum() < mining.episodes.sum()
    assert mining.weights().std() > 0
    state = json.loads((run / "checkpoint" / "state.json").read_text())
    assert state["mining"]["stage_index"] == 1
    np.testing.assert_allclose(state["mining"]["episodes"], mining.episodes)
    # every environment samples clips by length x the mining weights
    lengths = np.array([c.n_frames for c in tr.venv.get_attr("reference")[0].clips], float)
    want = lengths * mining.weights()
    for p in tr.venv.get_attr("_clip_p"):
        np.testing.assert_allclose(p, want / want.sum())
    # a resumed run starts from the saved counts: one more rollout adds its episodes, then
    # decays everything once
    longer = dataclasses.replace(cfg, stage2=dataclasses.replace(cfg.stage2, timesteps=320))
    tr2 = PolicyTrainer(longer, run, SAMPLE_REFERENCE, make_tracking_env)
    tr2.train()
    assert len(tr2.history) == len(tr.history) + 1
    new = tr2.history[-1]["episodes"]
    saved = sum(state["mining"]["episodes"])
    assert tr2.mining.episodes.sum() == pytest.approx((saved + new) * 0.9)
