"""Metrics of BASELINES_AND_METRICS.md section 4.2 on hand-computed cases."""

import numpy as np
import pytest

from grip.core import fk
from grip.core import metrics as M
from grip.core import skeleton as sk
from grip.core.body import GRAVITY, build_body
from grip.core.rotations import axis_angle_to_matrix, rot_z

FPS = 100.0


@pytest.fixture
def rng():
    return np.random.default_rng(0)


@pytest.fixture(scope="module")
def body():
    return build_body()


def _standing(body, n_frames):
    """Rest pose upright in the world, soles on the floor: ``(T, 24, 3, 3)``, ``(T, 24, 3)``."""
    local, root = fk.rest_pose(n_frames)
    root[:, 2] = body.pelvis_height
    return fk.forward_kinematics(local, root, body.offsets)


# ------------------------------------------------------------------------------ positions
def test_translation_offset(rng):
    gt = rng.normal(size=(5, 24, 3))
    pred = gt + np.array([0.03, -0.04, 0.0])
    assert M.mpjpe(pred, gt) == pytest.approx(50.0)
    np.testing.assert_allclose(M.mpjpe(pred, gt, per_joint=True), np.full(24, 50.0))
    assert M.pel_mpjpe(pred, gt) == pytest.approx(0.0, abs=1e-9)
    assert M.pa_mpjpe(pred, gt) == pytest.approx(0.0, abs=1e-9)


def test_rotation_about_pelvis_two_joints():
    theta = np.deg2rad(60.0)
    gt = np.broadcast_to([[0.5, 0.2, 1.0], [0.8, 0.2, 1.0]], (4, 2, 3)).copy()
    r = rot_z(np.array(theta))
    pred = gt.copy()
    pred[:, 1] = gt[:, 0] + (gt[:, 1] - gt[:, 0]) @ r.T
    # Joint 1 moves on a chord 2 |d| sin(theta / 2) = 0.3 m; the pelvis does not move.
    assert M.pel_mpjpe(pred, gt) == pytest.approx(0.5 * 300.0)
    np.testing.assert_allclose(M.pel_mpjpe(pred, gt, per_joint=True), [0.0, 300.0], atol=1e-9)
    assert M.pa_mpjpe(pred, gt) == pytest.approx(0.0, abs=1e-9)
    gt_rot = np.broadcast_to(np.eye(3), (4, 2, 3, 3))
    pred_rot = np.broadcast_to(r, (4, 2, 3, 3))
    assert M.mpjre(pred_rot, gt_rot) == pytest.approx(60.0)
    assert M.mpjre_local(pred_rot, gt_rot) == pytest.approx(60.0)


def test_scaled_and_similarity_transformed_pose(rng):
    gt = rng.normal(size=(3, 24, 3))
    pred = 1.1 * gt
    expected = 0.1 * np.linalg.norm(gt, axis=-1).mean() * 1000.0
    assert M.mpjpe(pred, gt) == pytest.approx(expected)
    assert M.pa_mpjpe(pred, gt) == pytest.approx(0.0, abs=1e-9)
    # A full similarity transform is recovered exactly.
    r = axis_angle_to_matrix(np.array([0.3, -0.5, 0.9]))
    shift = np.array([1.0, 2.0, 3.0])
    pred = 0.7 * gt @ r.T + shift
    scale, rot, trans = M.procrustes(pred, gt)
    np.testing.assert_allclose(scale, 1 / 0.7)
    np.testing.assert_allclose(trans, np.broadcast_to(-(r.T @ shift) / 0.7, (3, 3)), atol=1e-12)
    np.testing.assert_allclose(rot, np.broadcast_to(r.T, (3, 3, 3)), atol=1e-12)
    np.testing.assert_allclose(M.procrustes_align(pred, gt), gt, atol=1e-12)
    assert M.pa_mpjpe(pred, gt) == pytest.approx(0.0, abs=1e-9)


def test_procrustes_never_returns_a_reflection(rng):
    gt = rng.normal(size=(2, 24, 3))
    mirrored = gt * np.array([-1.0, 1.0, 1.0])
    scale, rot, _ = M.procrustes(mirrored, gt)
    np.testing.assert_allclose(np.linalg.det(rot), 1.0)
    # For that rotation the scale is the least-squares one: sum <y, R x> / sum |x|^2.
    x = mirrored - mirrored.mean(axis=1, keepdims=True)
    y = gt - gt.mean(axis=1, keepdims=True)
    best = np.einsum("tja,tab,tjb->t", y, rot, x) / np.sum(x * x, axis=(1, 2))
    np.testing.assert_allclose(scale, best, rtol=1e-12)
    eye = np.broadcast_to(np.eye(3), rot.shape)
    np.testing.assert_allclose(rot @ np.swapaxes(rot, -1, -2), eye, atol=1e-12)
    # A reflection would fit a mirrored chiral point set exactly; a rotation cannot.
    assert M.pa_mpjpe(mirrored, gt) > 100.0


# ------------------------------------------------------------------------------ dynamics
def test_jitter_of_a_cubic_and_acceleration_error_of_a_parabola():
    t = np.arange(50) / FPS
    direction = np.array([1.0, -2.0, 2.0])  # |direction| = 3
    a = 0.5
    cubic = a * t[:, None, None] ** 3 * direction  # (T, 1, 3)
    assert M.jitter(cubic, FPS) == pytest.approx(6 * a * 3.0, rel=1e-6)
    assert M.jitter(np.zeros((10, 24, 3)), FPS) == 0.0
    gt = np.zeros((50, 2, 3))
    pred = gt + a * t[:, None, None] ** 2 * direction
    assert M.acceleration_error(pred, gt, FPS) == pytest.approx(2 * a * 3.0, rel=1e-9)
    np.testing.assert_allclose(M.acceleration_error(pred, gt, FPS, per_joint=True), [3.0, 3.0])
    with pytest.raises(ValueError):
        M.jitter(cubic[:3], FPS)


# ------------------------------------------------------------------------------ feet
def test_foot_sliding_counts_only_ground_truth_contact_frames():
    n = 21
    t = np.arange(n) / FPS
    feet = np.zeros((n, 2, 3))
    feet[:, 0, 0] = 0.3 * t  # left slides at 0.3 m/s in x
    feet[:, 1, 1] = -0.4 * t  # right slides at 0.4 m/s in y
    feet[:, :, 2] = 0.05 * np.sin(t)[:, None]  # vertical motion is not sliding
    contact = np.ones((n, 2), dtype=bool)
    contact[:, 1] = False
    assert M.foot_sliding(feet, contact, FPS) == pytest.approx(0.3)
    contact[:, 1] = True
    assert M.foot_sliding(feet, contact, FPS) == pytest.approx(0.35)
    # Moving only while in the air: no sliding.
    still = feet.copy()
    still[10:] = feet[10]
    contact = np.zeros((n, 2), dtype=bool)
    contact[10:] = True
    assert M.foot_sliding(still, contact, FPS) == pytest.approx(0.0)
    # A full pose is accepted; joints 10 and 11 are used.
    pose = np.zeros((n, 24, 3))
    pose[:, list(sk.FOOT_JOINTS)] = feet
    assert M.foot_sliding(pose, np.ones((n, 2), bool), FPS) == pytest.approx(0.35)
    assert np.isnan(M.foot_sliding(feet, np.zeros((n, 2), bool), FPS))


def test_contacts_from_motion_threshold():
    t = np.arange(10) / FPS
    feet = np.zeros((10, 2, 3))
    feet[:, 0, 0] = 0.40 * t  # 0.0040 m per frame < 0.0048
    feet[:, 1, 0] = 0.60 * t  # 0.0060 m per frame > 0.0048
    c = M.contacts_from_motion(feet, FPS)
    assert c.shape == (10, 2)
    assert c[:, 0].all() and not c[:, 1].any()
    feet[6:, 1] = feet[5, 1]  # the right foot stops at frame 5
    c = M.contacts_from_motion(feet, FPS)
    np.testing.assert_array_equal(c[:, 1], np.arange(10) >= 6)


def test_foot_penetration_flat_floor_and_height_map():
    sole = np.zeros((4, 2, 6, 3))
    sole[2:, :, 3, 2] = -0.005  # one point of each sole 5 mm under the floor in half the frames
    sole[:, :, 0, 2] = 0.3  # points above the floor do not offset the depth
    assert M.foot_penetration(sole) == pytest.approx(2.5)
    assert M.foot_penetration(sole, floor_height=-0.01) == pytest.approx(0.0)
    # A 1 cm step under the left foot only.
    sole[..., 0] = np.array([1.0, -1.0])[None, :, None]

    def step(xy):
        return np.where(xy[..., 0] > 0.0, 0.01, 0.0)

    # Left: 10 mm (2 frames) and 15 mm (2 frames); right: 0 and 5 mm.
    assert M.foot_penetration(sole, step) == pytest.approx((10 + 10 + 15 + 15 + 5 + 5) / 8)


def test_vgrf_error_and_success_rate():
    pred = np.array([[100.0, 200.0], [300.0, 0.0]])
    gt = np.array([[110.0, 190.0], [300.0, 40.0]])
    assert M.vgrf_error(pred, gt) == pytest.approx(15.0)
    # frames without a predicted force (a recovered fall) are left out
    pred_gap = np.vstack([pred, [[np.nan, np.nan]]])
    assert M.vgrf_error(pred_gap, np.vstack([gt, [[500.0, 500.0]]])) == pytest.approx(15.0)
    assert np.isnan(M.vgrf_error(np.full((2, 2), np.nan), gt))
    assert M.success_rate([False, False, True, False]) == pytest.approx(75.0)
    assert M.success_rate(np.zeros(508, bool)) == 100.0
    assert M.success_rate([True] * 28 + [False] * 480) == pytest.approx(94.488, abs=1e-3)
    with pytest.raises(ValueError):
        M.success_rate([])


# ------------------------------------------------------------------------- translation
def test_cumulative_translation_error_of_a_constant_drift():
    n = 1201  # 12 s at 100 Hz
    t = np.arange(n) / FPS
    gt = np.stack([1.0 * t, np.zeros(n), np.full(n, 0.9)], axis=-1)  # 1 m/s along x
    pred = gt + np.stack([np.zeros(n), 0.1 * t, np.zeros(n)], axis=-1)  # drifts 0.1 m/s in y
    tp = M.cumulative_translation_error(pred, gt, FPS)
    np.testing.assert_allclose(tp.x, np.arange(11.0))
    np.testing.assert_allclose(tp.error_m, 0.1 * np.arange(11.0), atol=1e-9)
    assert tp.mean_m == pytest.approx(0.55)
    pip = M.cumulative_translation_error(pred, gt, FPS, variant="pip")
    np.testing.assert_allclose(pip.x, np.arange(1.0, 8.0))
    np.testing.assert_allclose(pip.error_m, 0.1 * np.arange(1.0, 8.0), atol=1e-9)
    # A 5 s segment has no 5..10 s horizons and no 7 m... it travels 4.99 m.
    short = M.translation_error_by_time(pred[:500], gt[:500], FPS)
    assert np.isfinite(short.error_m[:5]).all() and np.isnan(short.error_m[5:]).all()
    assert np.isnan(M.translation_error_by_distance(pred[:500], gt[:500]).error_m[4:]).all()


def _pip_windows_loop(pred, gt, window):
    """Straightforward two-pointer scan of PIP's window pairs, for comparison."""
    dist = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(gt, axis=0), axis=1))])
    pairs, start, end = [], 0, 1
    while end < len(dist):
        if dist[end] - dist[start] < window:
            end += 1
        else:
            if not pairs or pairs[-1][1] != end:
                pairs.append((start, end))
            start += 1
    errs = [
        np.linalg.norm((gt[e] - gt[s]) - (pred[e] - pred[s])) / (dist[e] - dist[s]) * window
        for s, e in pairs
    ]
    return np.mean(errs) if errs else np.nan


def test_pip_window_pairs_match_a_two_pointer_scan(rng):
    gt = np.cumsum(rng.normal(scale=0.02, size=(400, 3)), axis=0)
    pred = gt + np.cumsum(rng.normal(scale=0.005, size=(400, 3)), axis=0)
    curve = M.translation_error_by_distance(pred, gt, windows_m=(0.5, 1.0, 2.0, 3.0, 50.0))
    expected = [_pip_windows_loop(pred, gt, w) for w in (0.5, 1.0, 2.0, 3.0, 50.0)]
    np.testing.assert_allclose(curve.error_m, expected, rtol=1e-12)
    assert np.isnan(curve.error_m[-1])


# ----------------------------------------------------------------------------------- ZMP
def test_static_standing_wrench_and_zmp(body):
    rot, pos = _standing(body, 40)
    pos = pos + np.array([0.3, -0.2, 0.0])
    force, moment = M.net_external_wrench(rot, pos, body, FPS)
    mg = body.total_mass * GRAVITY
    np.testing.assert_allclose(force, np.broadcast_to([0.0, 0.0, mg], force.shape), atol=1e-9)
    com = fk.center_of_mass(rot, pos, body)
    zmp = M.zero_moment_point(force, moment)
    np.testing.assert_allclose(zmp, com[:, :2], atol=1e-12)
    # The SMPL foot joints are the toe bases, ahead of the COM: the distance is what is left of
    # the COM-to-toe-line gap after the 0.10 m foot radius.
    gap = pos[0, 10, 1] - com[0, 1]
    assert 0.10 < gap < 0.13
    assert M.zmp_distance(rot, pos, body, FPS) == pytest.approx(gap - 0.10, abs=1e-9)
    # With the ankles as support points the standing body is balanced.
    assert M.zmp_distance(rot, pos, body, FPS, foot_joints=(7, 8)) == 0.0
    assert M.zmp_distance(rot, pos, body, FPS, foot_radius_m=0.2) == 0.0


def test_zmp_shifted_by_horizontal_acceleration(body):
    rot, pos = _standing(body, 40)
    a = 3.0  # m/s^2 forward (+y)
    t = np.arange(40) / FPS
    pos = pos + (0.5 * a * t**2)[:, None, None] * np.array([0.0, 1.0, 0.0])
    force, moment = M.net_external_wrench(rot, pos, body, FPS)
    np.testing.assert_allclose(force[:, 1], body.total_mass * a, rtol=1e-6)
    com = fk.center_of_mass(rot, pos, body)
    zmp = M.zero_moment_point(force, moment)
    np.testing.assert_allclose(zmp[:, 1], com[:, 1] - a * com[:, 2] / GRAVITY, atol=1e-6)
    np.testing.assert_allclose(zmp[:, 0], com[:, 0], atol=1e-9)
    # ZMP behind the toe line (feet stay on the floor): distance = gap - radius, every frame.
    expected = pos[:, 10, 1] - zmp[:, 1] - 0.10
    assert expected.min() > 0.3
    d = M.zmp_distances(rot, pos, body, FPS)
    np.testing.assert_allclose(d, expected, atol=1e-6)
    assert M.zmp_distance(rot, pos, body, FPS) == pytest.approx(expected.mean(), abs=1e-6)


def test_wrench_of_a_vertical_spin_includes_segment_inertia(body):
    """Spinning up about the vertical axis: N_z = I_zz alpha (orbital plus segment spin)."""
    rot, pos = _standing(body, 40)
    alpha = 2.0  # rad/s^2
    r = rot_z(0.5 * alpha * (np.arange(40) / FPS) ** 2)  # (T, 3, 3)
    rot = r[:, None] @ rot
    pos = np.einsum("tab,tjb->tja", r, pos)
    _, moment = M.net_external_wrench(rot, pos, body, FPS)
    c = fk.segment_com(rot[:1], pos[:1], body)[0]
    orbital = np.sum(body.masses * np.sum(c[:, :2] ** 2, axis=-1))
    spin = np.einsum("jab,jbc,jdc->jad", rot[0], body.inertia_local, rot[0])[:, 2, 2].sum()
    assert spin > 0.1 * orbital
    np.testing.assert_allclose(moment[5:-5, 2], (orbital + spin) * alpha, rtol=1e-4)


@pytest.mark.parametrize(("lifted", "support"), [((7, 10), 11), ((8, 11), 10)])
def test_zmp_support_is_the_single_contacting_foot(body, lifted, support):
    rot, pos = _standing(body, 50)
    pos[30:, list(lifted), 2] += 0.1  # one foot leaves the floor at frame 30 (and stays up)
    com = fk.center_of_mass(rot, pos, body)
    d = M.zmp_distances(rot, pos, body, FPS)
    expected = np.linalg.norm(com[32:, :2] - pos[32:, support, :2], axis=-1) - 0.10
    np.testing.assert_allclose(d[32:], expected, atol=1e-9)
    np.testing.assert_allclose(d[:28], pos[0, 10, 1] - com[0, 1] - 0.10, atol=1e-9)


def test_zmp_skips_frames_with_both_feet_in_the_air(body):
    rot, pos = _standing(body, 60)
    pos[40:, :, 2] += 0.2
    d = M.zmp_distances(rot, pos, body, FPS, foot_joints=(7, 8))
    assert np.isnan(d[40:]).all()
    np.testing.assert_allclose(d[:38], 0.0)
    assert M.zmp_distance(rot, pos, body, FPS, foot_joints=(7, 8)) == pytest.approx(np.nanmean(d))


# ------------------------------------------------------------------------------ SIP masking
def _pose_with(joint, angle_deg, n=5):
    local = np.broadcast_to(np.eye(3), (n, 24, 3, 3)).copy()
    local[:, 0] = axis_angle_to_matrix(np.array([0.2, 0.1, -0.3]))  # some root orientation
    local[:, 18] = axis_angle_to_matrix(np.array([0.0, 0.4, 0.0]))  # bent elbow
    local[:, joint] = local[:, joint] @ axis_angle_to_matrix(
        np.array([0.0, 0.0, np.deg2rad(angle_deg)])
    )
    return local


def test_local_global_round_trip(rng):
    from scipy.spatial.transform import Rotation

    local = Rotation.random(2 * 24, random_state=rng).as_matrix().reshape(2, 24, 3, 3)
    glob = M.local_to_global_rot(local)
    np.testing.assert_allclose(glob[:, 18], glob[:, 16] @ local[:, 18], atol=1e-12)
    np.testing.assert_allclose(M.global_to_local_rot(glob), local, atol=1e-12)
    g_fk, _ = fk.forward_kinematics(local, np.zeros((2, 3)), build_body().offsets)
    np.testing.assert_allclose(glob, g_fk, atol=1e-12)


def test_sip_masking_ignores_wrists_and_root_but_not_shoulders():
    base = _pose_with(0, 0.0)
    gt = M.local_to_global_rot(base)
    # Wrist (masked): visible without masking, invisible to the masked metrics.
    wrist = M.local_to_global_rot(_pose_with(20, 40.0))
    assert M.mpjre(wrist, gt) == pytest.approx(2 * 40.0 / 24)
    assert M.sip_error(wrist, gt) == pytest.approx(0.0, abs=1e-6)
    assert M.angular_error_masked(wrist, gt) == pytest.approx(0.0, abs=1e-6)
    # Root orientation (masked): every global rotation changes, the masked errors do not.
    root = M.local_to_global_rot(_pose_with(0, 30.0))
    assert M.mpjre(root, gt) == pytest.approx(30.0)
    assert M.sip_error(root, gt) == pytest.approx(0.0, abs=1e-6)
    assert M.angular_error_masked(root, gt) == pytest.approx(0.0, abs=1e-6)
    # Shoulder (evaluated): SIP sees its angle on joint 16; over all joints, 16 and its
    # descendants 18, 20, 22 (masked locally, but they inherit it) are off by 25 deg.
    shoulder_local = _pose_with(16, 25.0)
    shoulder = M.local_to_global_rot(shoulder_local)
    per_joint = M.sip_error(shoulder, gt, per_joint=True)
    np.testing.assert_allclose(per_joint, [0, 0, 25.0, 0], atol=1e-6)
    assert M.sip_error(shoulder, gt) == pytest.approx(25.0 / 4)
    assert M.sip_error(shoulder_local, base, is_local=True) == pytest.approx(25.0 / 4)
    assert M.angular_error_masked(shoulder, gt) == pytest.approx(4 * 25.0 / 24)


def test_masked_positions_and_relative_jitter(body):
    base = _pose_with(0, 0.0)
    pos = M.sip_masked_joint_positions(base, body.offsets, is_local=True)
    assert pos.shape == (5, 24, 3)
    np.testing.assert_allclose(pos[:, 0], 0.0)
    root_turned = M.sip_masked_joint_positions(_pose_with(0, 50.0), body.offsets, is_local=True)
    np.testing.assert_allclose(root_turned, pos, atol=1e-12)
    # Shoulder rotation by 90 deg about the masked root's z: the whole arm chain moves.
    turned = _pose_with(16, 90.0)
    err = M.position_error_masked(turned, base, body.offsets, is_local=True, per_joint=True)
    assert err[[0, 1, 2, 16]] == pytest.approx([0, 0, 0, 0], abs=1e-9)
    assert (err[[18, 20, 22]] > 10.0).all()
    # A root spinning with a cubic angle jitters in the world, not in the masked pose.
    local = np.broadcast_to(np.eye(3), (8, 24, 3, 3)).copy()
    local[:, 16] = axis_angle_to_matrix(np.array([0.0, 0.0, 0.5]))
    local[:, 0] = rot_z(200.0 * (np.arange(8) / FPS) ** 3)
    _, world = fk.forward_kinematics(local, np.zeros((8, 3)), body.offsets)
    assert M.jitter(world, FPS) > 100.0
    relative = M.sip_masked_joint_positions(local, body.offsets, is_local=True)
    assert M.jitter(relative, FPS) == pytest.approx(0.0, abs=1e-6)


# ------------------------------------------------------------------------------ summary
def test_summarize_averages_segments_and_skips_nan():
    segs = [
        {"mpjpe": 10.0, "fs": np.nan, "curve": np.array([0.0, 1.0])},
        {"mpjpe": 20.0, "fs": 0.2, "curve": np.array([0.0, 3.0])},
        {"mpjpe": 30.0, "fs": 0.4, "success": 0.0},
    ]
    out = M.summarize(segs)
    assert list(out) == ["mpjpe", "fs", "curve", "success"]
    assert out["mpjpe"] == pytest.approx(20.0)
    assert out["fs"] == pytest.approx(0.3)
    np.testing.assert_allclose(out["curve"], [0.0, 2.0])
    assert out["success"] == 0.0
    assert np.isnan(M.summarize([{"fs": np.nan}])["fs"])
    # Equal-length segments: the mean of segment means is the global mean.
    rng = np.random.default_rng(1)
    gt, pred = rng.normal(size=(2, 10, 24, 3))
    per_seg = [{"mpjpe": M.mpjpe(pred[i : i + 5], gt[i : i + 5])} for i in (0, 5)]
    assert M.summarize(per_seg)["mpjpe"] == pytest.approx(M.mpjpe(pred, gt))


def test_shape_errors():
    with pytest.raises(ValueError):
        M.mpjpe(np.zeros((2, 24, 3)), np.zeros((2, 23, 3)))
    with pytest.raises(ValueError):
        M.vgrf_error(np.zeros((3, 2)), np.zeros((3, 3)))
    with pytest.raises(ValueError):
        M.cumulative_translation_error(np.zeros((5, 3)), np.zeros((5, 3)), FPS, variant="x")


def test_root_error_and_travel_ratio_on_hand_made_tracks():
    t = np.arange(301) / 100.0  # 3 s at 100 Hz
    gt = np.stack([1.2 * t, np.zeros_like(t), np.full_like(t, 0.9)], axis=1)  # 1.2 m/s along x
    # half the speed, with a 5 cm sway at 2 Hz and a different height: half the ground
    slow = np.stack([0.6 * t, 0.05 * np.sin(2 * np.pi * 2 * t), np.full_like(t, 0.8)], axis=1)
    assert M.travel_ratio(slow, gt, 100.0) == pytest.approx(0.5, abs=1e-9)  # sway sampled at 0
    assert M.travel_ratio(gt, gt, 100.0) == pytest.approx(1.0)
    # the mean horizontal distance of the slow track: 0.6 t along x plus the sway
    want = np.mean(np.hypot(0.6 * t, 0.05 * np.sin(2 * np.pi * 2 * t)))
    assert M.root_error_xy(slow, gt) == pytest.approx(want)
    still = np.tile(gt[:1], (301, 1))
    assert np.isnan(M.travel_ratio(gt, still, 100.0))  # the truth covers no ground
    assert np.isnan(M.travel_ratio(gt[:50], gt[:50], 100.0))  # shorter than one sample step
    with pytest.raises(ValueError, match="root tracks"):
        M.root_error_xy(gt[:, :2], gt[:, :2])
