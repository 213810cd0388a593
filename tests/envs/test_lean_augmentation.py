"""The lean augmentation of training (``TrackingEnvConfig.lean_range_deg``, docs/pace.md,
hypothesis 12 b): each episode's followed upper body leans a drawn angle about the pelvis, in
the observation and in the spine's PD target, while the truth the reward pays stays."""

from __future__ import annotations

import numpy as np
import pytest

from envs.tracking_env import SAMPLE_REFERENCE, GripTrackingEnv
from grip.core import skeleton as sk
from grip.core.reference import ReferenceSet
from grip.task import observations as O
from grip.task.config import TrackingEnvConfig


def _angle_deg(r: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0))))


@pytest.fixture(scope="module")
def clip():
    return ReferenceSet.load(SAMPLE_REFERENCE).clip(0)


def test_forward_lean_turns_the_vertical_towards_the_facing_direction(clip) -> None:
    root = clip.est_rot[::40, 0]
    facing = O.heading_matrices(root)[:, :2, 0]
    for deg in (7.0, -4.0):
        lean = O.forward_lean(root, deg)
        up = lean @ np.array([0.0, 0.0, 1.0])
        along = np.einsum("ni,ni->n", up[:, :2], facing)
        across = up[:, 0] * facing[:, 1] - up[:, 1] * facing[:, 0]
        np.testing.assert_allclose(along, np.sin(np.radians(deg)), atol=1e-12)
        np.testing.assert_allclose(across, 0.0, atol=1e-12)
        assert all(_angle_deg(r) == pytest.approx(abs(deg)) for r in lean)
    per_row = O.forward_lean(root[:3], np.array([1.0, 2.0, 3.0]))
    assert [_angle_deg(r) for r in per_row] == pytest.approx([1.0, 2.0, 3.0])


def test_lean_rows_turn_the_upper_body_as_leaned_does(clip) -> None:
    frames = O.EstimateFrames()
    frames.update(clip, np.zeros(69), False)
    t = np.arange(5, 200, 45)
    rows = frames.obs_rows[t].copy()
    lean = O.forward_lean(clip.est_rot[t, 0], 6.0)
    O.lean_rows(rows, lean)
    pos, rot, vel = O.leaned(clip.est_pos[t], clip.est_rot[t], clip.est_vel[t], lean)
    r = O.OBS_ROW
    np.testing.assert_allclose(rows[:, r["est_pos"]], pos.reshape(len(t), -1), atol=1e-12)
    np.testing.assert_allclose(rows[:, r["est_vel"]], vel.reshape(len(t), -1), atol=1e-12)
    leaf = rows[:, r["leaf_rot"]].reshape(len(t), 4, 3, 3)
    np.testing.assert_allclose(leaf, rot[:, list(O.IMU_JOINTS)], atol=1e-12)
    w = rows[:, r["leaf_angvel"]].reshape(len(t), 4, 3)
    for k, j in enumerate(O.IMU_JOINTS):
        want = clip.est_angvel[t, j]
        if j in O.UPPER_BODY:  # the wrists turn, the feet do not
            want = np.einsum("nij,nj->ni", lean, want)
        np.testing.assert_allclose(w[:, k], want, atol=1e-12)
    # the pelvis, the legs and the root stay
    legs = [j for j in range(sk.N_JOINTS) if j not in O.UPPER_BODY]
    np.testing.assert_array_equal(pos[:, legs], clip.est_pos[t][:, legs])
    np.testing.assert_array_equal(rows[:, r["est_root_pos"]], frames.obs_rows[t, r["est_root_pos"]])


def test_lean_hinges_of_many_frames_is_each_frame_s(clip) -> None:
    t = np.arange(0, 200, 30)
    lean = O.forward_lean(clip.est_rot[t, 0], -5.0)
    many = O.lean_hinges(clip.est_rot[t], lean)
    one = np.stack([O.lean_hinges(clip.est_rot[k], m) for k, m in zip(t, lean, strict=True)])
    np.testing.assert_allclose(many, one, atol=1e-12)
    assert np.count_nonzero(np.abs(many).sum(axis=0)) <= 3  # the first spine joint only


def _torso_lead(deg: float, steps: int = 60) -> tuple[float, float, dict]:
    """With the pelvis pinned to the truth and actions of 0: the mean of the simulated neck's
    horizontal lead over the pelvis along the pelvis' facing direction, m, and the mean
    imitation reward, and the first observation."""
    env = GripTrackingEnv(TrackingEnvConfig(pin_root=True, random_start=False,
                                            termination_dist_m=0.0, amp_window=0,
                                            lean_range_deg=(deg, deg)))  # fmt: skip
    obs0, _ = env.reset(seed=0)
    lead, reward = [], []
    for _ in range(steps):
        *_, info = env.step(np.zeros(69))
        pvw, rot = env.humanoid.state()
        facing = O.heading_matrices(rot[0])[:2, 0]
        lead.append(float((pvw[0, 12, :2] - pvw[0, 0, :2]) @ facing))
        reward.append(info["reward/imit_pos"])
    env.close()
    return float(np.mean(lead[20:])), float(np.mean(reward[20:])), obs0


def test_a_leaned_episode_leans_the_humanoid_and_the_observation() -> None:
    """A followed trunk leaned 10 deg forward tips the humanoid's neck forward (the spine's
    PD target leans: about 0.1 m at a 0.5 m spine), the truth-paid imitation reward falls, and
    the observation differs from the upright episode's; 0 deg is the augmentation off."""
    up, r_up, obs_up = _torso_lead(0.0)
    fwd, r_fwd, obs_fwd = _torso_lead(10.0)
    back, _, _ = _torso_lead(-10.0)
    assert fwd - up > 0.04 and up - back > 0.04
    assert r_fwd < r_up
    assert not np.allclose(obs_fwd["kinematic"], obs_up["kinematic"])
    np.testing.assert_array_equal(obs_fwd["sensor"], obs_up["sensor"])


def test_a_lean_is_drawn_per_episode_and_checked() -> None:
    env = GripTrackingEnv(TrackingEnvConfig(lean_range_deg=(-5.0, 5.0), amp_window=0))
    drawn = set()
    for s in range(6):
        env.reset(seed=s)
        drawn.add(round(env._lean_deg, 6))
    env.close()
    assert len(drawn) == 6 and all(-5.0 <= d <= 5.0 for d in drawn)
    for bad in ((2.0, 1.0), (-20.0, 0.0), (0.0, 16.0)):
        with pytest.raises(ValueError, match="lean_range_deg"):
            TrackingEnvConfig(lean_range_deg=bad)
    with pytest.raises(ValueError, match="teacher_obs"):
        TrackingEnvConfig(lean_range_deg=(-1.0, 1.0), teacher_obs=True)
