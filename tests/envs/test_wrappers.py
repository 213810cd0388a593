"""ActionRepeat: one decision played for k frames, rewards kept at their per-frame scale;
RandomPushes: training perturbations on the pelvis."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from envs.config import TrackingEnvConfig
from envs.tracking_env import GripTrackingEnv
from envs.wrappers import ActionRepeat, RandomPushes


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


def test_a_push_moves_the_pelvis_along_its_force_by_its_impulse(reference) -> None:
    plain = _env(reference, termination_dist_m=0.0)
    pushed = RandomPushes(_env(reference, termination_dist_m=0.0), force_n=300.0, every_s=1e-9,
                          duration_s=0.1, seed=3)  # fmt: skip
    plain.reset(seed=0)
    pushed.reset(seed=0)
    m, d = plain.model, plain.data
    pelvis = plain.humanoid.pelvis_body
    mass = float(m.body_subtreemass[pelvis])
    forces = []
    for _ in range(10):  # 0.1 s at 100 Hz: the whole first push
        plain.step(np.zeros(69))
        _, _, _, _, info = pushed.step(np.zeros(69))
        forces.append(pushed.unwrapped.data.xfrc_applied[pelvis, :3].copy())
        assert info["push_n"] == pytest.approx(np.linalg.norm(forces[-1]))
    f = forces[0]
    assert 150.0 <= np.linalg.norm(f) <= 300.0 and f[2] == 0.0
    np.testing.assert_array_equal(forces, np.tile(f, (10, 1)))  # one constant push
    # the whole body's momentum changes by the push's impulse (contacts act on both twins)
    d2 = pushed.unwrapped.data
    for data in (d, d2):
        mujoco.mj_subtreeVel(m, data)  # the whole body's centre-of-mass velocity
    dv = d2.subtree_linvel[pelvis] - d.subtree_linvel[pelvis]
    expected = f * 0.1 / mass
    assert np.dot(dv[:2], expected[:2]) / np.dot(expected[:2], expected[:2]) == (
        pytest.approx(1.0, abs=0.35))


def test_between_pushes_the_environment_is_untouched(reference) -> None:
    plain = _env(reference)
    rare = RandomPushes(_env(reference), force_n=300.0, every_s=1e6, duration_s=0.2, seed=0)
    plain.reset(seed=0)
    rare.reset(seed=0)
    rng = np.random.default_rng(1)
    for _ in range(20):
        a = rng.uniform(-0.3, 0.3, 69)
        obs_p, *_ = plain.step(a)
        obs_r, _, _, _, info = rare.step(a)
        assert info["push_n"] == 0.0
        for k in obs_p:
            np.testing.assert_array_equal(obs_r[k], obs_p[k])


def test_pushes_need_positive_settings_and_zero_force_is_off(reference) -> None:
    with pytest.raises(ValueError, match="force_n, every_s and duration_s must be > 0"):
        RandomPushes(_env(reference), force_n=0.0, every_s=1.0, duration_s=0.2)
    from policies.config import PolicyRunConfig

    with pytest.raises(ValueError, match="push_force_n must be >= 0"):
        PolicyRunConfig(push_force_n=-1.0)
    with pytest.raises(ValueError, match="push_every_s and push_duration_s > 0"):
        PolicyRunConfig(push_force_n=100.0, push_every_s=0.0)
