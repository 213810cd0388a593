"""ActionRepeat: one decision played for k frames, rewards kept at their per-frame scale."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from envs.tracking_env import GripTrackingEnv
from envs.wrappers import ActionRepeat
from grip.task.config import TrackingEnvConfig


def _env(reference, **kw) -> GripTrackingEnv:
    cfg = dataclasses.replace(TrackingEnvConfig(), random_start=False, clip_index=0, **kw)
    return GripTrackingEnv(cfg, reference)


def test_one_step_plays_k_frames_like_k_steps_of_the_same_action(reference) -> None:
    rng = np.random.default_rng(0)
    actions = rng.uniform(-0.3, 0.3, (4, 69))
    plain, wrapped = _env(reference), ActionRepeat(_env(reference), 3)
    plain.reset(seed=0)
    wrapped.reset(seed=0)
    for a in actions:
        rewards, infos = [], []
        for _ in range(3):
            obs_p, r, term, trunc, info_p = plain.step(a)
            rewards.append(r)
            infos.append(info_p)
            assert not (term or trunc)
        obs_w, r_w, term_w, trunc_w, info_w = wrapped.step(a)
        assert not (term_w or trunc_w) and info_w["frames"] == 3
        assert info_w["frame"] == info_p["frame"]
        for k in obs_p:
            np.testing.assert_array_equal(obs_w[k], obs_p[k])  # same trajectory, bit for bit
        assert r_w == pytest.approx(np.mean(rewards))
        for key in ("reward/imit_pos", "reward/energy"):
            assert info_w[key] == pytest.approx(np.mean([i[key] for i in infos]))
        assert info_w["mpjpe_m"] == info_p["mpjpe_m"]  # the last frame's


def test_a_termination_inside_the_repeat_ends_the_step_there(reference) -> None:
    env = ActionRepeat(_env(reference, termination_dist_m=0.25), 50)
    env.reset(seed=0)
    _, _, terminated, _, info = env.step(-np.ones(69))  # collapse: far off within 50 frames
    assert terminated and 1 <= info["frames"] < 50 and info["frame"] == info["frames"]


def test_the_repeat_must_be_a_positive_integer(reference) -> None:
    for k in (0, -1, 1.5):
        with pytest.raises(ValueError, match="action repeat"):
            ActionRepeat(_env(reference), k)
    with pytest.raises(ValueError, match="action_repeat"):
        TrackingEnvConfig(action_repeat=0)
