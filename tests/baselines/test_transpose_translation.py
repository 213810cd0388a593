"""TransPose's supporting-foot translation, fusion, gravity term and penetration guard on poses
built by hand."""

from __future__ import annotations

import numpy as np
import pytest

from grip.baselines.transpose_translation import (
    FPS_HZ,
    GRAVITY_VELOCITY_MPS,
    TranslationConfig,
    foot_positions,
    fused_velocity,
    fusion_weight,
    guard_heights,
    joint_floor_height,
    root_translation,
)
from grip.core.body import CANONICAL_TO_WORLD, build_body
from grip.core.fk import forward_kinematics
from grip.core.metrics import local_to_global_rot
from grip.core.rotations import axis_angle_to_matrix, rot_x

BODY = build_body()
NO_GRAVITY = TranslationConfig(gravity_velocity_mps=0.0, penetration_guard=False)


def _walk_pose(n: int, swing_knee_rad: float = 1.4) -> np.ndarray:
    """``(n, 24, 3, 3)`` global rotations: upright body facing +y, left leg swinging from
    front to back (the body vaults over the left foot), right leg the mirror swing with a bent
    knee (so the right foot stays above the left)."""
    theta = np.linspace(0.35, -0.35, n)
    local = np.broadcast_to(np.eye(3), (n, 24, 3, 3)).copy()
    local[:, 0] = CANONICAL_TO_WORLD
    local[:, 1] = rot_x(-theta)  # canonical x = left: negative pitch swings the leg forward
    local[:, 2] = rot_x(theta)
    local[:, 5] = rot_x(np.full(n, swing_knee_rad))
    return local_to_global_rot(local)


def test_constants_are_transposes_converted_to_100_hz():
    assert FPS_HZ == 100.0
    np.testing.assert_allclose(GRAVITY_VELOCITY_MPS / FPS_HZ, 0.0108)  # 0.018 m at 60 Hz
    np.testing.assert_allclose(fusion_weight(np.array([0.2, 0.5, 0.7, 0.9, 1.0])),
                               [0.0, 0.0, 0.5, 1.0, 1.0])  # fmt: skip


def test_foot_positions_match_full_forward_kinematics():
    rng = np.random.default_rng(0)
    local = axis_angle_to_matrix(rng.normal(0, 0.5, (7, 24, 3)))
    g_rot, pos = forward_kinematics(local, np.zeros((7, 3)), BODY.offsets)
    np.testing.assert_allclose(foot_positions(g_rot, BODY.offsets), pos[:, [10, 11]], atol=1e-12)


def test_planted_foot_gives_zero_drift_while_the_body_walks_over_it():
    """Left foot on the joint floor, contact probability 1: gravity pulls the body down every
    frame and the guard puts it back, so the foot stays exactly where it is (no drift in any
    axis) while the pelvis moves forward by the leg's swing; Trans-B2's velocity is ignored."""
    n = 60
    g_rot = _walk_pose(n)
    rel = foot_positions(g_rot, BODY.offsets)
    assert np.all(rel[:, 1, 2] > rel[:, 0, 2] + 0.05), "the swing foot must stay above"
    floor = joint_floor_height(BODY)
    planted = np.array([0.3, -0.2, floor])
    gt_root = planted - rel[:, 0]
    contact = np.tile([1.0, 0.1], (n, 1))
    junk_vel = np.random.default_rng(1).normal(0, 3.0, (n, 3))
    root = root_translation(g_rot, contact, junk_vel, BODY.offsets, gt_root[0], floor)
    np.testing.assert_allclose(root, gt_root, atol=1e-12)
    assert gt_root[-1, 1] - gt_root[0, 1] > 0.3, "the pelvis really travelled forward"
    foot_world = root + rel[:, 0]
    np.testing.assert_allclose(foot_world - planted, 0.0, atol=1e-12)


def test_support_switches_to_the_foot_with_the_higher_probability():
    """Left foot planted for the first half, then the right one: each planted foot stays put
    (kinematic check, gravity and guard off)."""
    n, k = 40, 20
    g_rot = _walk_pose(n, swing_knee_rad=0.0)
    rel = foot_positions(g_rot, BODY.offsets)
    contact = np.where(np.arange(n)[:, None] < k, [0.95, 0.4], [0.3, 0.97])
    root0 = np.array([0.0, 0.0, 1.0])
    root = root_translation(g_rot, contact, np.zeros((n, 3)), BODY.offsets, root0, -10.0,
                            NO_GRAVITY)  # fmt: skip
    left = root[:k] + rel[:k, 0]
    right = root[k - 1 :] + rel[k - 1 :, 1]
    np.testing.assert_allclose(left - left[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(right - right[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(root[0], root0)


@pytest.mark.parametrize(("prob", "w"), [(0.3, 0.0), (0.5, 0.0), (0.7, 0.5), (0.9, 1.0),
                                         (0.97, 1.0)])  # fmt: skip
def test_fusion_weights_between_the_thresholds(prob, w):
    n = 5
    foot_rel = np.zeros((n, 2, 3))
    foot_rel[:, 0, 0] = -0.01 * np.arange(n)  # left foot moves back 1 cm/frame: body +1 cm
    v_e = np.tile([2.0, 0.0, 0.0], (n, 1))  # Trans-B2: 2 m/s = 2 cm/frame
    prob2 = np.tile([prob, prob / 2], (n, 1))
    v = fused_velocity(foot_rel, prob2, v_e, TranslationConfig())
    foot_branch = np.array([0.01, 0.0, -GRAVITY_VELOCITY_MPS / FPS_HZ])
    net_branch = np.array([0.02, 0.0, 0.0])
    np.testing.assert_allclose(v[1:], np.tile((1 - w) * net_branch + w * foot_branch, (n - 1, 1)),
                               atol=1e-15)  # fmt: skip
    np.testing.assert_allclose(v[0], 0.0)


def test_gravity_term_pulls_a_body_in_contact_down_when_nothing_stops_it():
    n = 11
    g_rot = _walk_pose(1).repeat(n, axis=0)  # static pose
    root0 = np.array([0.0, 0.0, 1.2])
    cfg = TranslationConfig(penetration_guard=False)
    root = root_translation(g_rot, np.ones((n, 2)), np.zeros((n, 3)), BODY.offsets, root0, 0.0,
                            cfg)  # fmt: skip
    np.testing.assert_allclose(root[:, 2], 1.2 - 0.0108 * np.arange(n), atol=1e-12)
    np.testing.assert_allclose(root[:, :2], 0.0, atol=1e-12)
    # with the guard and a far floor nothing changes; with the guard and the real floor the
    # body stops when the lower foot reaches the joint floor
    far = root_translation(g_rot, np.ones((n, 2)), np.zeros((n, 3)), BODY.offsets, root0, -5.0)
    np.testing.assert_allclose(far, root, atol=1e-12)
    floor = joint_floor_height(BODY)
    low = foot_positions(g_rot, BODY.offsets)[0, :, 2].min()
    start = np.array([0.0, 0.0, floor - low + 0.03])  # lower foot 3 cm above the joint floor
    held = root_translation(g_rot, np.ones((n, 2)), np.zeros((n, 3)), BODY.offsets, start, floor)
    np.testing.assert_allclose(held[:3, 2], start[2] - 0.0108 * np.arange(3), atol=1e-12)
    np.testing.assert_allclose(held[3:, 2], floor - low, atol=1e-12)


def test_penetration_guard_lands_exactly_on_the_joint_floor_and_never_pushes_down():
    n = 30
    g_rot = _walk_pose(1).repeat(n, axis=0)
    floor = joint_floor_height(BODY, floor_z_m=0.1)
    low = foot_positions(g_rot, BODY.offsets)[0, :, 2].min()
    root0 = np.array([0.0, 0.0, floor - low])  # standing on the floor
    half = np.full((n, 2), 0.5)  # w = 0: Trans-B2 only
    down = np.tile([0.0, 0.0, -1.0], (n, 1))
    guarded = root_translation(g_rot, half, down, BODY.offsets, root0, floor)
    np.testing.assert_allclose(guarded[:, 2], root0[2], atol=1e-12)
    free = root_translation(g_rot, half, down, BODY.offsets, root0, floor,
                            TranslationConfig(penetration_guard=False))  # fmt: skip
    np.testing.assert_allclose(free[:, 2], root0[2] - 0.01 * np.arange(n), atol=1e-12)
    up = np.tile([0.5, 0.0, 1.0], (n, 1))
    np.testing.assert_allclose(root_translation(g_rot, half, up, BODY.offsets, root0, floor),
                               root0 + up * np.arange(n)[:, None] / 100.0, atol=1e-12)  # fmt: skip


def test_vectorised_guard_equals_the_sequential_rule():
    rng = np.random.default_rng(3)
    n = 500
    v_z = rng.normal(0, 0.02, n)
    foot = rng.normal(-0.9, 0.05, n)
    floor = 0.05
    z = np.empty(n)
    z[0] = 0.97
    for t in range(1, n):  # TransPose's loop
        z[t] = z[t - 1] + v_z[t]
        if z[t] + foot[t] < floor:
            z[t] = floor - foot[t]
    np.testing.assert_allclose(guard_heights(0.97, v_z, foot, floor), z, atol=1e-12)


def test_bad_inputs_are_named():
    n = 4
    g_rot = _walk_pose(n)
    ok = {"global_rot": g_rot, "contact_prob": np.ones((n, 2)), "root_vel_world": np.zeros((n, 3)),
          "offsets": BODY.offsets, "root0": np.zeros(3), "joint_floor_z": 0.0}  # fmt: skip
    cases = {
        "global_rot": (g_rot[:, :23], "global_rot"),
        "contact_prob": (np.ones((n, 3)), "contact_prob"),
        "root_vel_world": (np.full((n, 3), np.nan), "non-finite"),
        "offsets": (BODY.offsets[:10], "offsets"),
    }
    for key, (bad, msg) in cases.items():
        with pytest.raises(ValueError, match=msg):
            root_translation(**{**ok, key: bad})
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        root_translation(**{**ok, "contact_prob": np.full((n, 2), 1.5)})
    with pytest.raises(ValueError, match="prob_low"):
        TranslationConfig(prob_low=0.9, prob_high=0.5)
