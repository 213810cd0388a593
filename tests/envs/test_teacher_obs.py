"""A privileged teacher's inputs (``TrackingEnvConfig.teacher_obs``): the observation a policy
trained on the ground truth (``follow = "truth"``) would see in the same state, and the shift
that turns its action into the student's, in the single and the batched environment."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
from stable_baselines3.common.vec_env import DummyVecEnv

from envs.batched import BatchedTrackingEnv
from envs.tracking_env import GripTrackingEnv
from grip.core.reference import ReferenceClip, ReferenceSet
from grip.core.rotations import axis_angle_to_matrix, matrix_to_6d
from grip.task.config import TrackingEnvConfig
from policies.vec_env import BatchedVecEnv

CFG = TrackingEnvConfig(termination_dist_m=0.0, max_episode_frames=30, min_episode_frames=30)


@pytest.fixture(scope="module")
def estimated(reference) -> ReferenceSet:
    """The reference clip with an estimate that is not the truth: joints off by a few
    centimetres, rotations by a few degrees, velocities 10 % fast."""
    c = reference.clip(0)
    rng = np.random.default_rng(5)
    t = c.n_frames
    drift = np.cumsum(rng.normal(0.0, 0.002, (t, 24, 3)), axis=0)
    tilt = axis_angle_to_matrix(0.05 * np.sin(np.linspace(0, 6, t))[:, None, None]
                                * rng.normal(0.0, 1.0, (1, 24, 3)))  # fmt: skip
    clip = ReferenceClip(
        name=c.name, category=c.category, fps=c.fps, body=c.body, gt_qpos=c.gt_qpos.copy(),
        est_pos=c.est_pos + np.clip(drift, -0.04, 0.04), est_rot6d=matrix_to_6d(c.est_rot @ tilt),
        est_vel=1.1 * c.est_vel, sensor=c.sensor, objects=c.objects,
    )  # fmt: skip
    return ReferenceSet([clip], reference.sensor_sites, reference.insoles)


def test_the_teacher_sees_what_it_saw_following_the_truth(estimated) -> None:
    """Student env (the estimate, teacher_obs on) played with ``a + teacher_shift`` and an env
    on the oracle clip played with ``a``: the same PD targets, so the same motion, and the
    student env's ``teacher_kinematic`` is the oracle env's ``kinematic``; the other keys are
    those of the env without teacher_obs."""
    student = GripTrackingEnv(dataclasses.replace(CFG, teacher_obs=True), estimated)
    plain = GripTrackingEnv(CFG, estimated)
    oracle = GripTrackingEnv(CFG, ReferenceSet([estimated.clip(0).oracle()],
                                               estimated.sensor_sites, estimated.insoles))
    assert set(student.observation_space) == {*plain.observation_space, "teacher_kinematic",
                                              "teacher_shift"}  # fmt: skip
    os_, _ = student.reset(seed=3)
    op, _ = plain.reset(seed=3)
    oo, _ = oracle.reset(seed=3)
    rng = np.random.default_rng(0)
    shifts = []
    for step in range(25):
        np.testing.assert_allclose(os_["teacher_kinematic"], oo["kinematic"], atol=2e-4,
                                   err_msg=f"step {step}")  # fmt: skip
        a = rng.uniform(-0.3, 0.3, 69)
        shift = os_["teacher_shift"].astype(np.float64)
        shifts.append(np.abs(shift).max())
        assert np.all(np.abs(a + shift) <= 1.0)  # (no clipping: the targets are the same)
        op, *_ = plain.step(a + shift)
        os_, *_ = student.step(a + shift)
        oo, *_ = oracle.step(a)
        for k in op:
            np.testing.assert_array_equal(os_[k], op[k])
    assert 0.01 < max(shifts) < 0.7  # the estimate is off, and the shift says by how much
    np.testing.assert_allclose(student.data.qpos, oracle.data.qpos, atol=1e-4)


def test_batched_teacher_inputs_match_separate_envs(estimated) -> None:
    cfg = dataclasses.replace(CFG, teacher_obs=True, action_repeat=3, max_episode_frames=12,
                              min_episode_frames=12)  # fmt: skip
    seeds = [11, 12]

    def single(seed):
        from envs.wrappers import ActionRepeat

        env = ActionRepeat(GripTrackingEnv(cfg, estimated), cfg.action_repeat)
        env.reset(seed=seed)
        return env

    ref = DummyVecEnv([functools.partial(single, s) for s in seeds])
    envs = []
    for s in seeds:
        e = GripTrackingEnv(cfg, estimated)
        e.reset(seed=s)
        envs.append(e)
    bat = BatchedVecEnv(BatchedTrackingEnv(envs, 1))
    ref.seed(4)
    bat.seed(4)
    o1, o2 = ref.reset(), bat.reset()
    rng = np.random.default_rng(1)
    for _ in range(10):  # (episodes end and restart within these steps)
        for k in o1:
            np.testing.assert_allclose(o2[k], o1[k], rtol=1e-6, atol=1e-6, err_msg=k)
        a = rng.uniform(-0.5, 0.5, (2, 69)).astype(np.float32)
        o1, *_ = ref.step(a)
        o2, *_ = bat.step(a)
    bat.close()


def test_a_teacher_can_follow_the_students_pelvis(estimated) -> None:
    """``teacher_root = "estimate"``: the teacher's pelvis gap (the last two values of
    ``OAV_Jrel_root``) is the student's, to the estimate's integrated root (10 % fast here, so it
    pulls away from the truth's), while the rest of its observation is still the truth's; the
    batched environments give the same."""
    base = dataclasses.replace(CFG, teacher_obs=True, kinematic_obs="OAV_Jrel_root")
    by_root = {}
    for root in ("truth", "estimate"):
        env = GripTrackingEnv(dataclasses.replace(base, teacher_root=root), estimated)
        o, _ = env.reset(seed=3)
        rows = []
        for _ in range(25):
            rows.append({k: o[k].copy() for k in ("kinematic", "teacher_kinematic")})
            o, *_ = env.step(np.zeros(69))
        by_root[root] = rows
    for tr, es in zip(by_root["truth"], by_root["estimate"], strict=True):
        np.testing.assert_array_equal(es["teacher_kinematic"][-2:], es["kinematic"][-2:])
        np.testing.assert_array_equal(es["teacher_kinematic"][:-2], tr["teacher_kinematic"][:-2])
    last_t, last_e = by_root["truth"][-1], by_root["estimate"][-1]
    assert np.abs(last_t["teacher_kinematic"][-2:] - last_e["teacher_kinematic"][-2:]).max() > 0.01
    cfg = dataclasses.replace(base, teacher_root="estimate", max_episode_frames=12,
                              min_episode_frames=12)  # fmt: skip
    seeds = [11, 12]
    ref = DummyVecEnv([functools.partial(_reset, cfg, estimated, s) for s in seeds])
    envs = [_reset(cfg, estimated, s) for s in seeds]
    bat = BatchedVecEnv(BatchedTrackingEnv(envs, 1))
    ref.seed(4)
    bat.seed(4)
    o1, o2 = ref.reset(), bat.reset()
    rng = np.random.default_rng(1)
    for _ in range(15):
        np.testing.assert_allclose(o2["teacher_kinematic"], o1["teacher_kinematic"], rtol=1e-6,
                                   atol=1e-6)  # fmt: skip
        a = rng.uniform(-0.5, 0.5, (2, 69)).astype(np.float32)
        o1, *_ = ref.step(a)
        o2, *_ = bat.step(a)
    bat.close()


def _reset(cfg, reference, seed) -> GripTrackingEnv:
    env = GripTrackingEnv(cfg, reference)
    env.reset(seed=seed)
    return env
