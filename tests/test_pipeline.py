"""The inference pipeline reads sensors and the calibration frames only, with the numbers of the
recording-based functions it replaces."""

from __future__ import annotations

import numpy as np

from grip.core.reference import Estimate
from grip.kinematics.features import (
    FeatureConfig,
    first_state,
    input_features,
    sensor_stream,
    stream_features,
    targets,
)
from grip.kinematics.reference import oracle_reference_clip
from grip.pipeline import start_from_calibration, start_from_clip
from prism_tools.synthetic import make_recording


def test_sensor_stream_features_equal_the_recordings() -> None:
    rec = make_recording(60, seed=4)
    for cfg in (FeatureConfig(), FeatureConfig(insoles=False, align_first_frame=False)):
        s = sensor_stream(rec, cfg)
        np.testing.assert_array_equal(stream_features(s, cfg), input_features(rec, cfg))
        assert [f.acc.shape for f in list(s.frames())[:1]] == [(len(cfg.sites), 3)]


def test_calibration_gives_the_ground_truths_start() -> None:
    rec = make_recording(60, seed=5)
    s = sensor_stream(rec)
    first = first_state(s.calibration, s.body, s.fps)
    t = targets(rec.slice_frames(0, 2))
    np.testing.assert_array_equal(first["fp"], t.joint_pos[0].reshape(-1).astype(np.float32))
    np.testing.assert_array_equal(first["fa"], t.rot6d[0].reshape(-1).astype(np.float32))
    # a segment cut in motion starts from its first frame's velocities, as a training window
    # does (KinematicsNet learnt to start from them); a standing calibration from zero
    cut = make_recording(200, seed=5).slice_frames(150, 200)  # (still for 100 frames)
    moving = sensor_stream(cut)
    want = targets(cut).velocity[0].reshape(-1).astype(np.float32)
    assert np.abs(want).max() > 0.05
    got = first_state(moving.calibration, moving.body, moving.fps)["lv"]
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
    still = sensor_stream(rec, init="standing")
    assert not first_state(still.calibration, still.body, still.fps)["lv"].any()
    clip = oracle_reference_clip(rec)
    a, b = start_from_calibration(s.calibration, s.body, s.fps), start_from_clip(clip)
    np.testing.assert_array_equal(a.qpos, b.qpos)
    np.testing.assert_allclose(a.qvel, b.qvel, atol=1e-12)
    np.testing.assert_allclose(a.amp, b.amp, atol=1e-9)
    est = Estimate(clip.name, clip.fps, clip.est_pos, clip.est_rot6d, clip.est_vel, clip.sensor,
                   s.calibration.root_pos[0])  # fmt: skip
    for k in ("est_rot", "est_angvel", "est_hinge", "est_hinge_vel", "est_root_pos"):
        np.testing.assert_array_equal(getattr(est, k), getattr(clip, k), err_msg=k)


def test_without_ground_truth_the_start_is_the_standing_pose_at_the_feet_heading() -> None:
    import dataclasses

    from grip.core.body import CANONICAL_TO_WORLD
    from grip.core.mjcf import standing_qpos
    from grip.core.rotations import quat_to_matrix
    from grip.kinematics.features import recording_body, sensor_heading

    psi = 0.6
    yaw = np.array([[np.cos(psi), -np.sin(psi), 0.0], [np.sin(psi), np.cos(psi), 0.0],
                    [0.0, 0.0, 1.0]])  # fmt: skip
    rec = make_recording(60, seed=6)
    imu = {p: dataclasses.replace(s, ori_world=np.array(s.ori_world)) for p, s in rec.imu.items()}
    for foot in ("L_Foot", "R_Foot"):
        imu[foot].ori_world[0] = yaw @ CANONICAL_TO_WORLD
    rec = dataclasses.replace(rec, imu=imu, smpl_params=None, imu_gt={})
    assert np.isclose(sensor_heading(np.stack([imu["L_Foot"].ori_world[0]] * 2)), psi)
    s = sensor_stream(rec)
    assert np.isnan(s.calibration.imu_ori).all()  # no imu_gt: orientations used as recorded
    start = start_from_calibration(s.calibration, s.body, s.fps)
    q = standing_qpos(recording_body(rec))
    np.testing.assert_allclose(start.qpos[:3], q[:3], atol=1e-12)
    np.testing.assert_allclose(quat_to_matrix(start.qpos[3:7]), yaw @ CANONICAL_TO_WORLD,
                               atol=1e-9)  # fmt: skip
    np.testing.assert_allclose(start.qpos[7:], 0.0, atol=1e-9)
    assert not start.qvel.any()
    first = first_state(s.calibration, s.body, s.fps)
    assert all(np.isfinite(v).all() for v in first.values()) and not first["lv"].any()
    np.testing.assert_array_equal(stream_features(s), input_features(rec))
