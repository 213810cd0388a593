"""Tests for prism_tools.synth: IMU and insole synthesis from motion, noise, recording assembly."""

from __future__ import annotations

import dataclasses
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import Delaunay

from grip.core import fk
from grip.core import skeleton as sk
from grip.core.body import CANONICAL_TO_WORLD, GRAVITY, BodyModel, BodyParams, build_body
from grip.core.rotations import axis_angle_to_quat, matrix_to_quat, rot_x, rot_z
from grip.motion.motion import Motion
from prism_tools.io import load_recording, save_recording
from prism_tools.synth import (
    ImuKinematics,
    ImuSynthConfig,
    InsoleReadings,
    InsoleSynth,
    InsoleSynthConfig,
    NoiseConfig,
    SynthConfig,
    distribute_force,
    external_wrench,
    measure_imu,
    measure_insoles,
    recording_from_motion,
    synthesize_imu,
    synthesize_insoles,
    synthesize_sensors,
)
from prism_tools.synth.force_distribution import _nnls_distribute
from prism_tools.synth.imu import resolve_acc_smoothing_frames, second_difference
from prism_tools.synth.noise import apply_drops, corrupt_imu, corrupt_insole_cells, drop_mask
from prism_tools.synth.recording import ZMP_OUTSIDE_M
from prism_tools.validation import validate

FPS = 100.0
BODY = build_body()
BW = BODY.total_mass * GRAVITY
PELVIS = sk.IMU_PARTS.index("Pelvis")


# ------------------------------------------------------------------------------------ motions
def _motion(local_rot: np.ndarray, root_pos: np.ndarray, name: str = "test") -> Motion:
    return Motion(
        fps=FPS, root_pos=root_pos, local_quat=matrix_to_quat(local_rot), name=name, category="test"
    )


def _standing(n: int = 200, arms_down_deg: float = 75.0) -> tuple[np.ndarray, np.ndarray]:
    """Rest pose upright (facing +y), arms lowered symmetrically, feet flat on the floor."""
    rot, pos = fk.rest_pose(n)
    a = np.deg2rad(arms_down_deg)
    rot[:, 16] = rot_z(np.array(-a))  # left arm (+x canonical) turns down about the forward axis
    rot[:, 17] = rot_z(np.array(a))
    pos[:, 2] = BODY.pelvis_height
    return rot, pos


def _rot2(v: np.ndarray, th: np.ndarray) -> np.ndarray:
    c, s = np.cos(th), np.sin(th)
    return np.stack([v[..., 0] * c - v[..., 1] * s, v[..., 0] * s + v[..., 1] * c], -1)


def _synthetic_walk(n: int = 660, step_m: float = 0.45, stride_s: float = 1.1) -> Motion:
    """A flat-footed walk along +y: planted stance feet (exact planar leg IK), 40 % swing.

    Each foot is in stance for 60 % of the stride (double support 2 x 10 %); in swing the ankle
    follows a smooth arc 8 cm high. The pelvis moves forward at constant speed with a small
    vertical bob and lateral sway; other joints keep the rest pose.
    """
    t = np.arange(n) / FPS
    v = 2 * step_m / stride_s
    phase = (t / stride_s) % 1.0
    bob = 0.01 * np.cos(4 * np.pi * (phase - 0.3))
    sway = -0.02 * np.cos(2 * np.pi * (phase - 0.3))
    root = np.stack([sway, v * t, BODY.pelvis_height - 0.06 + bob], -1)
    local = np.broadcast_to(np.eye(3), (n, 24, 3, 3)).copy()
    local[:, 0] = CANONICAL_TO_WORLD
    ankle_h = BODY.rest_joint_pos[7, 1]
    for hip, knee, ankle, shift in ((1, 4, 7, 0.0), (2, 5, 8, 0.5)):
        ph = (phase - shift) % 1.0
        y_plant = v * (np.floor(t / stride_s - shift) + shift + 0.3) * stride_s
        foot_y, foot_z = y_plant.copy(), np.full(n, ankle_h)
        sw = ph >= 0.6
        s = (ph[sw] - 0.6) / 0.4
        foot_y[sw] += 2 * step_m * (s - np.sin(2 * np.pi * s) / (2 * np.pi))
        foot_z[sw] += 0.08 * 0.5 * (1 - np.cos(2 * np.pi * s))
        hip_w = root + CANONICAL_TO_WORLD @ BODY.offsets[hip]
        d = np.stack([foot_z - hip_w[:, 2], foot_y - hip_w[:, 1]], -1)  # canonical (y, z)
        u1, u2 = BODY.offsets[knee][1:], BODY.offsets[ankle][1:]
        l1, l2 = np.linalg.norm(u1), np.linalg.norm(u2)
        dist = np.linalg.norm(d, axis=-1)
        assert dist.max() < 0.999 * (l1 + l2)

        def ang(w: np.ndarray) -> np.ndarray:
            return np.arctan2(w[..., 1], w[..., 0])

        phi = np.arccos((dist**2 - l1**2 - l2**2) / (2 * l1 * l2))
        th_k = phi - (ang(u2) - ang(u1))  # knee flexes so that the ankle goes backwards
        th_h = ang(d) - ang(u1 + _rot2(np.broadcast_to(u2, (n, 2)), th_k))
        local[:, hip], local[:, knee] = rot_x(th_h), rot_x(th_k)
        local[:, ankle] = rot_x(-(th_h + th_k))  # foot stays flat
    return _motion(local, root, name="synthetic/walk")


# --------------------------------------------------------------------------------- standing
def test_standing_still_weight_cop_split_contacts() -> None:
    rot, pos = _standing()
    g, p = fk.forward_kinematics(rot, pos, BODY.offsets)
    syn = synthesize_insoles(g, p, BODY, FPS)
    r = measure_insoles(syn, BODY)
    total = r.force_bw.sum(axis=1)
    np.testing.assert_allclose(total, 1.0, atol=0.02)
    np.testing.assert_allclose(syn.wrench.force_world[:, 2] / BW, 1.0, atol=0.02)
    com = fk.center_of_mass(g, p, BODY)
    np.testing.assert_allclose(syn.wrench.zmp_world, com[:, :2], atol=1e-6)
    np.testing.assert_allclose(r.combined_cop_world_m[:, :2], com[:, :2], atol=1e-4)
    hull = Delaunay(fk.sole_points(g[:1], p[:1], BODY).reshape(-1, 3)[:, :2])
    assert np.all(hull.find_simplex(r.combined_cop_world_m[:, :2]) >= 0)
    share = r.force_bw / total[:, None]
    assert np.all((share > 0.4) & (share < 0.6))
    assert r.contacts.all()
    # Bookkeeping: cells sum to the foot, pressures are force / area, CoP lies under the foot.
    np.testing.assert_allclose(r.cell_force_bw.sum(-1), r.force_bw, atol=1e-12)
    np.testing.assert_allclose(
        r.cell_pressure_n_per_cm2 * BODY.insole_area_cm2, r.cell_force_bw * BW, rtol=1e-12
    )
    assert np.all(np.abs(r.cop_insole_m[..., 0]) < BODY.foot_length / 2)
    assert syn.fallback_frames.size == 0 and np.all(syn.unsupported_force_n == 0)


def test_sway_cop_equals_zmp_inside_support() -> None:
    """A slow sway of the whole body: the ZMP stays under the feet and the CoP follows it."""
    rot, pos = _standing(400)
    t = np.arange(400) / FPS
    w = 2 * np.pi * 0.5
    pos[:, 0] += 0.02 * np.sin(w * t)
    pos[:, 1] += 0.02 * np.cos(w * t)
    g, p = fk.forward_kinematics(rot, pos, BODY.offsets)
    syn = synthesize_insoles(g, p, BODY, FPS)
    r = measure_insoles(syn, BODY)
    com = syn.wrench.com_world
    # Pure translation: ZMP = COM - z_com / g * a_com (linear inverted pendulum, exact here).
    acc = -(w**2) * np.stack([0.02 * np.sin(w * t), 0.02 * np.cos(w * t)], -1)
    zmp = com[:, :2] - com[:, 2:] / GRAVITY * acc
    inner = slice(20, -20)
    np.testing.assert_allclose(syn.wrench.zmp_world[inner], zmp[inner], atol=1e-3)
    assert syn.zmp_error_m.max() < 1e-4
    np.testing.assert_allclose(r.combined_cop_world_m[:, :2], syn.wrench.zmp_world, atol=1e-4)
    # The feet share the load by the lateral position of the ZMP (left foot at -x).
    left_share = r.force_bw[:, 0] / r.force_bw.sum(1)
    assert np.corrcoef(left_share, -syn.wrench.zmp_world[:, 0])[0, 1] > 0.95


def test_millimetre_jitter_does_not_move_the_zmp_off_the_feet() -> None:
    """1 mm of 8 Hz jitter (what the retarget's 10 Hz low-pass lets through) is a COM
    acceleration of 2.5 m/s^2: 25 cm of ZMP, which a 0.2 s derivative window takes out (the
    default 0.1 s window passes 14 cm of it); the 0.5 Hz sway above stays exact."""
    rot, pos = _standing(400)
    t = np.arange(400) / FPS
    pos[:, 0] += 0.001 * np.sin(2 * np.pi * 8.0 * t)
    g, p = fk.forward_kinematics(rot, pos, BODY.offsets)
    inner = slice(50, -50)
    dev = {}
    for w in (0.1, 0.2):
        syn = synthesize_insoles(g, p, BODY, FPS, InsoleSynthConfig(smoothing_window_s=w))
        dev[w] = np.abs(syn.wrench.zmp_world - syn.wrench.com_world[:, :2])[inner].max()
    assert dev[0.1] > 0.1 and dev[0.2] < 0.02
    assert syn.zmp_error_m.max() < 1e-4  # under the feet: the cells follow it


def test_moment_matches_rigid_body_dynamics() -> None:
    """A rigid body turning faster and faster about the world vertical, off its COM.

    About the world origin: ``N = w x (I_O w) + I_O dw/dt + sum_j c_j x m_j (0, 0, g)``, where
    ``I_O`` includes the segments' own inertias ``R_j I_j R_j^T`` (the spin term, also checked
    on its own).
    """
    n, omega0, alpha = 200, 0.5, 3.0
    rot, pos = _standing(n)
    t = np.arange(n) / FPS
    yaw = rot_z(omega0 * t + 0.5 * alpha * t**2)
    rot[:, 0] = yaw @ CANONICAL_TO_WORLD
    pos[:] = np.einsum("tij,j->ti", yaw, np.array([0.05, 0.02, BODY.pelvis_height]))
    g, p = fk.forward_kinematics(rot, pos, BODY.offsets)
    # The formula, not the default low-pass, is under test: the short 0.1 s window keeps the
    # smoothing error of this fast spin below 1 %.
    cfg = InsoleSynthConfig(smoothing_window_s=0.1)
    wrench = external_wrench(g, p, BODY, FPS, cfg)
    c = fk.segment_com(g, p, BODY)
    m = BODY.masses
    i_spin = np.einsum("tjab,jbc,tjdc->tad", g, BODY.inertia_local, g)
    cc = np.einsum("j,tjk,tjk->t", m, c, c)
    i_o = i_spin + cc[:, None, None] * np.eye(3) - np.einsum("j,tja,tjb->tab", m, c, c)
    w = np.outer(omega0 + alpha * t, [0.0, 0.0, 1.0])
    dw = np.array([0.0, 0.0, alpha])
    dyn = np.cross(w, np.einsum("tab,tb->ta", i_o, w)) + np.einsum("tab,b->ta", i_o, dw)
    gravity = np.cross(c, m[:, None] * np.array([0.0, 0.0, GRAVITY])).sum(1)
    spin = np.cross(w, np.einsum("tab,tb->ta", i_spin, w)) + np.einsum("tab,b->ta", i_spin, dw)
    inner = slice(20, -20)
    err = np.linalg.norm(wrench.moment_world - dyn - gravity, axis=1)[inner]
    assert np.all(err < 0.01 * np.linalg.norm(dyn, axis=1)[inner])  # smoothing: ~(w W)^2 / 20
    # The spin term alone: the same motion on a body whose segments have no own inertia.
    no_spin = dataclasses.replace(BODY, inertia_local=np.zeros_like(BODY.inertia_local))
    spin_computed = wrench.moment_world - external_wrench(g, p, no_spin, FPS, cfg).moment_world
    spin_norm = np.linalg.norm(spin, axis=1)[inner]
    assert spin_norm.min() > 0.5
    assert np.all(np.linalg.norm(spin_computed - spin, axis=1)[inner] < 0.02 * spin_norm)
    # Force: M times the COM acceleration (centripetal + tangential), plus weight.
    com = wrench.com_world
    r = com[:, :2]
    acc = -(w[:, 2:] ** 2) * r + alpha * np.stack([-r[:, 1], r[:, 0]], -1)
    f_xy = BODY.total_mass * acc[inner]
    err_f = np.linalg.norm(wrench.force_world[inner, :2] - f_xy, axis=1)
    assert np.all(err_f < 0.01 * np.linalg.norm(f_xy, axis=1) + 0.01)
    np.testing.assert_allclose(wrench.force_world[inner, 2], BW, rtol=1e-9)


# ------------------------------------------------------------------------------------ IMUs
def test_pelvis_free_acceleration_matches_analytic_operator() -> None:
    n_frames, amp, freq = 300, 0.1, 1.0
    rot, pos = _standing(n_frames)
    t = np.arange(n_frames) / FPS
    w = 2 * np.pi * freq
    pos[:, 0] += amp * np.sin(w * t)
    g, p = fk.forward_kinematics(rot, pos, BODY.offsets)
    kin = synthesize_imu(g, p, BODY, FPS)
    n = kin.acc_smoothing_frames
    assert n == 7
    acc = kin.acc_world[:, PELVIS, 0]
    dt = 1.0 / FPS
    exact = -amp * w**2 * np.sin(w * t)

    def operator(k: int) -> np.ndarray:  # the k-frame second difference of a sine, exactly
        return exact * (2 - 2 * np.cos(w * k * dt)) / (w * k * dt) ** 2

    np.testing.assert_allclose(acc[n:-n], operator(n)[n:-n], atol=1e-9)
    np.testing.assert_allclose(acc[1:n], operator(1)[1:n], atol=1e-9)
    np.testing.assert_allclose(acc[-n:-1], operator(1)[-n:-1], atol=1e-9)
    assert acc[0] == 0 and acc[-1] == 0
    np.testing.assert_allclose(acc[n:-n], exact[n:-n], atol=0.02 * amp * w**2)
    np.testing.assert_allclose(kin.acc_world[:, PELVIS, 1:], 0.0, atol=1e-9)
    # Ground truth: plain second difference and central-difference velocity.
    np.testing.assert_allclose(kin.acc_world_gt[1:-1, PELVIS, 0], operator(1)[1:-1], atol=1e-9)
    np.testing.assert_allclose(
        kin.vel_world[1:-1, PELVIS, 0],
        amp * w * np.cos(w * t[1:-1]) * np.sin(w * dt) / (w * dt),
        atol=1e-9,
    )


def test_smoothing_frames_and_second_difference_edges() -> None:
    assert resolve_acc_smoothing_frames(ImuSynthConfig(), 100.0) == 7
    assert resolve_acc_smoothing_frames(ImuSynthConfig(), 60.0) == 4
    assert resolve_acc_smoothing_frames(ImuSynthConfig(acc_smoothing_frames=3), 100.0) == 3
    with pytest.raises(ValueError):
        ImuSynthConfig(acc_smoothing_frames=0)
    x = np.arange(10.0) ** 2  # x'' = 2 per frame^2
    np.testing.assert_allclose(second_difference(x, 1.0, 3), [0] + [2.0] * 8 + [0])
    assert np.all(second_difference(np.ones((2, 3)), 100.0, 7) == 0)


def test_gyroscope_and_specific_force() -> None:
    """Turning on the spot at a constant yaw rate: gyro = body-frame rate, accelerometer = g."""
    n, omega = 200, 1.5
    rot, pos = _standing(n)
    rot[:, 0] = rot_z(omega * np.arange(n) / FPS) @ CANONICAL_TO_WORLD
    g, p = fk.forward_kinematics(rot, pos, BODY.offsets)
    kin = synthesize_imu(g, p, BODY, FPS)
    expected_gyr = np.einsum("tsji,j->tsi", kin.ori_world, np.array([0.0, 0.0, omega]))
    np.testing.assert_allclose(kin.gyr_local[1:-1], expected_gyr[1:-1], atol=1e-6)
    # Specific force back in the world = free acceleration + (0, 0, g).
    back = np.einsum("tsij,tsj->tsi", kin.ori_world, kin.acc_local)
    np.testing.assert_allclose(
        back - kin.acc_world, np.broadcast_to([0, 0, GRAVITY], back.shape), atol=1e-9
    )
    # A mounting offset rotates the sensor frame: R_sensor = R_segment @ R_offset.
    cfg = ImuSynthConfig(mount_offsets_rotvec_rad=(("L_Wrist", (0.0, 0.0, np.pi / 2)),))
    kin2 = synthesize_imu(g, p, BODY, FPS, cfg)
    i = sk.IMU_PARTS.index("L_Wrist")
    np.testing.assert_allclose(
        kin2.ori_world[:, i], kin.ori_world[:, i] @ rot_z(np.pi / 2), atol=1e-12
    )
    np.testing.assert_allclose(kin2.acc_world, kin.acc_world)


def test_acc_filter_is_causal_and_passes_constants() -> None:
    rot, pos = _standing(300)
    t = np.arange(300) / FPS
    pos[150:, 0] += 0.05 * (t[150:] - t[150]) ** 2  # starts accelerating at frame 150
    g, p = fk.forward_kinematics(rot, pos, BODY.offsets)
    kin = synthesize_imu(g, p, BODY, FPS)
    r = measure_imu(kin, FPS)
    filt = r.acc_world_filt[:, PELVIS, 0]
    first = int(np.flatnonzero(np.abs(kin.acc_world[:, PELVIS, 0]) > 1e-9)[0])
    assert np.all(filt[:first] == 0.0)  # nothing before the input moves (causal)
    assert abs(filt[-20] - 0.1) < 0.01  # constant acceleration passes the low-pass


# ------------------------------------------------------------------------------- free fall
def test_free_fall_has_no_force_and_no_contact() -> None:
    n = 40
    rot, pos = _standing(n)
    t = np.arange(n) / FPS
    pos[:, 2] = BODY.pelvis_height + 1.5 - 0.5 * GRAVITY * t**2  # feet >= 0.7 m above the floor
    g, p = fk.forward_kinematics(rot, pos, BODY.offsets)
    syn = synthesize_insoles(g, p, BODY, FPS)
    r = measure_insoles(syn, BODY)
    np.testing.assert_allclose(syn.wrench.force_world, 0.0, atol=1e-6 * BW)
    np.testing.assert_allclose(r.force_bw, 0.0, atol=1e-12)
    assert not r.contacts.any()
    assert np.all(syn.support == 0)


# --------------------------------------------------------------------------------- walking
def _single_support_shares(syn: InsoleSynth, r: InsoleReadings) -> list[np.ndarray]:
    """Stance-foot share of the force in frames where the other foot is clearly in the air.

    Clearly in the air: every cell of the swing foot moves faster than 1.5 m/s horizontally
    while the other foot has a cell slower than 1 m/s, or the swing foot's lowest cell is 5 cm
    above the other foot's lowest cell (plain finite differences, independent of the
    synthesis' smoothed contact logic).
    """
    low = syn.cell_pos_world[..., 2].min(axis=-1)  # (T, 2)
    vel = np.gradient(syn.cell_pos_world[..., :2], 1.0 / FPS, axis=0)
    slowest = np.linalg.norm(vel, axis=-1).min(axis=-1)  # (T, 2)
    total = r.force_bw.sum(axis=1)
    out = []
    for swing in (0, 1):
        moving = (slowest[:, swing] > 1.5) & (slowest[:, 1 - swing] < 1.0)
        air = moving | (low[:, swing] > low[:, 1 - swing] + 0.05)
        air &= total > 0.3
        out.append(r.force_bw[air, 1 - swing] / total[air])
    return out


def test_synthetic_walk_force_and_stance_foot() -> None:
    m = _synthetic_walk()
    syn = synthesize_sensors(m, noise=False)
    r = syn.insole_readings
    assert abs(r.force_bw.sum(axis=1).mean() - 1.0) < 0.05
    shares = _single_support_shares(syn.insole, r)
    for share in shares:
        assert share.size > 50
        assert np.all(share > 0.95)
    # Double support: both feet loaded; contacts alternate.
    assert np.any(np.all(r.force_bw > 0.2, axis=1))
    assert r.contacts[:, 0].any(axis=1).mean() > 0.5 and (~r.contacts[:, 0].any(axis=1)).any()


def test_floating_feet_keep_support_and_sliding_feet_carry_nothing() -> None:
    walk = _synthetic_walk(330)
    lifted = dataclasses.replace(walk, root_pos=walk.root_pos + np.array([0.0, 0.0, 0.04]))
    syn = synthesize_sensors(lifted, noise=False)
    assert abs(syn.insole_readings.force_bw.sum(axis=1).mean() - 1.0) < 0.05
    np.testing.assert_allclose(np.median(syn.insole.contact_level_m), 0.04, atol=1e-3)
    high = dataclasses.replace(walk, root_pos=walk.root_pos + np.array([0.0, 0.0, 0.2]))
    syn = synthesize_sensors(high, noise=False)
    assert np.all(syn.insole_readings.force_bw == 0)
    np.testing.assert_allclose(syn.insole.unsupported_force_n, syn.insole.wrench.force_world[:, 2])
    # A standing body gliding at 2 m/s: its sliding soles carry nothing.
    rot, pos = _standing(100)
    pos[:, 1] += 2.0 * np.arange(100) / FPS
    g, p = fk.forward_kinematics(rot, pos, BODY.offsets)
    ins = synthesize_insoles(g, p, BODY, FPS)
    assert np.all(ins.support == 0) and np.all(ins.cell_force_n == 0)
    np.testing.assert_allclose(ins.unsupported_force_n, BW, rtol=1e-6)


_CMU_WALK = Path(__file__).resolve().parents[3] / "shared/data/motions/cmu/bvh/02_01.bvh"
_HAVE_IMPORTERS = all(
    importlib.util.find_spec(f"grip.motion.{m}") is not None for m in ("catalog", "retarget")
)


@pytest.mark.skipif(
    not (_HAVE_IMPORTERS and _CMU_WALK.exists()),
    reason="grip.motion importers or the CMU walk clip are missing",
)
def test_real_walk_clip() -> None:
    from grip.motion.catalog import load_clip
    from grip.motion.retarget import retarget

    m = retarget(load_clip(_CMU_WALK))
    syn = synthesize_sensors(m, noise=False)
    r = syn.insole_readings
    assert abs(r.force_bw.sum(axis=1).mean() - 1.0) < 0.05
    for share in _single_support_shares(syn.insole, r):
        assert share.size > 20
        assert np.all(share > 0.95)


# ----------------------------------------------------------------------------- distribution
def test_distribute_force_matches_nnls_and_constraints() -> None:
    rng = np.random.default_rng(3)
    n, p = 300, 32
    cap = rng.random((n, p)) * (rng.random((n, p)) < 0.6)
    xy = rng.normal(size=(n, p, 2)) * 0.1
    target = rng.normal(size=(n, 2)) * 0.1
    fz = rng.uniform(100, 1500, n)
    forces, fallback = distribute_force(fz, target, xy, cap)
    assert np.all(forces >= 0) and np.all(forces[cap == 0] == 0)
    np.testing.assert_allclose(forces.sum(1), fz, rtol=1e-9)
    centroid = np.einsum("tp,tpk->tk", forces, xy) / fz[:, None]
    inside = np.array([Delaunay(xy[i, cap[i] > 0]).find_simplex(target[i]) >= 0 for i in range(n)])
    assert 20 < inside.sum() < n - 20  # both cases are exercised
    np.testing.assert_allclose(centroid[inside], target[inside], atol=1e-4)
    for i in range(0, n, 10):
        s = cap[i] / cap[i].sum()
        c = s @ xy[i]
        ref = _nnls_distribute(s, xy[i] - c, target[i] - c, 1e8) * fz[i]
        np.testing.assert_allclose(forces[i], ref, atol=1e-3 * fz[i])
    assert fallback.sum() <= 2
    # No capacity or no force: nothing is placed.
    f0, _ = distribute_force(
        np.array([700.0, -5.0]), np.zeros((2, 2)), xy[:2], np.stack([np.zeros(p), cap[1]])
    )
    assert np.all(f0 == 0)


# ----------------------------------------------------------------------------------- noise
def _kin_and_insole(n: int = 300) -> tuple[ImuKinematics, InsoleSynth, BodyModel]:
    m = _synthetic_walk(n)
    body = m.body_model()
    g, p = m.fk(body)
    return synthesize_imu(g, p, body, FPS), synthesize_insoles(g, p, body, FPS), body


def test_noise_seeded_off_exact_and_no_mutation() -> None:
    kin, ins, body = _kin_and_insole()
    before = {k: np.copy(getattr(kin, k)) for k in ("acc_world", "ori_world", "acc_local")}
    cells_before = ins.cell_force_n.copy()
    noise = NoiseConfig(imu_drop_prob=0.02, insole_drop_prob=0.02)
    a = measure_imu(kin, FPS, noise=noise, rng=np.random.default_rng(1))
    b = measure_imu(kin, FPS, noise=noise, rng=np.random.default_rng(1))
    c = measure_imu(kin, FPS, noise=noise, rng=np.random.default_rng(2))
    for f in ("acc_world_raw", "acc_world_filt", "ori_world", "acc_local_raw", "gyr_local_raw"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
        assert not np.array_equal(getattr(a, f), getattr(c, f))
    ia = measure_insoles(ins, body, noise=noise, rng=np.random.default_rng(1))
    ib = measure_insoles(ins, body, noise=noise, rng=np.random.default_rng(1))
    ic = measure_insoles(ins, body, noise=noise, rng=np.random.default_rng(2))
    np.testing.assert_array_equal(ia.cell_force_bw, ib.cell_force_bw)
    assert not np.array_equal(ia.cell_force_bw, ic.cell_force_bw)
    for k, v in before.items():
        np.testing.assert_array_equal(getattr(kin, k), v)
    np.testing.assert_array_equal(ins.cell_force_n, cells_before)
    # Noisy readings stay physically consistent: R_est @ specific force = free acc + g.
    back = np.einsum("tsij,tsj->tsi", a.ori_world, a.acc_local_raw)
    np.testing.assert_allclose(
        back - a.acc_world_raw, np.broadcast_to([0, 0, GRAVITY], back.shape), atol=1e-9
    )
    # Off: exact ground truth.
    off = measure_imu(kin, FPS, noise=NoiseConfig.off(), rng=np.random.default_rng(1))
    np.testing.assert_array_equal(off.acc_world_raw, kin.acc_world)
    np.testing.assert_array_equal(off.ori_world, kin.ori_world)
    np.testing.assert_array_equal(off.acc_local_raw, kin.acc_local)
    np.testing.assert_array_equal(off.gyr_local_raw, kin.gyr_local)
    assert all(v.size == 0 for v in off.dropped.values())
    clean = measure_insoles(ins, body)
    off_ins = measure_insoles(ins, body, noise=NoiseConfig.off(), rng=np.random.default_rng(5))
    np.testing.assert_array_equal(off_ins.cell_force_bw, clean.cell_force_bw)
    np.testing.assert_array_equal(off_ins.cop_world_m, clean.cop_world_m)
    assert NoiseConfig.off().is_off and not NoiseConfig().is_off


def test_dropped_samples_repeat_previous_value() -> None:
    kin, ins, body = _kin_and_insole()
    noise = dataclasses.replace(NoiseConfig.off(), imu_drop_prob=0.1, insole_drop_prob=0.1)
    r = measure_imu(kin, FPS, noise=noise, rng=np.random.default_rng(0))
    for i, part in enumerate(kin.parts):
        idx = r.dropped[part]
        assert idx.size > 5 and idx.min() >= 1
        kept = np.setdiff1d(np.arange(kin.acc_world.shape[0]), idx)
        np.testing.assert_array_equal(r.acc_world_raw[kept, i], kin.acc_world[kept, i])
        np.testing.assert_array_equal(r.acc_world_raw[idx, i], r.acc_world_raw[idx - 1, i])
        np.testing.assert_array_equal(r.ori_world[idx, i], r.ori_world[idx - 1, i])
        np.testing.assert_array_equal(r.gyr_local_raw[idx, i], r.gyr_local_raw[idx - 1, i])
    ri = measure_insoles(ins, body, noise=noise, rng=np.random.default_rng(0))
    for f, foot in enumerate(sk.FEET):
        idx = ri.dropped[foot]
        assert idx.size > 5
        np.testing.assert_array_equal(ri.cell_force_bw[idx, f], ri.cell_force_bw[idx - 1, f])
        np.testing.assert_array_equal(ri.cop_world_m[idx, f], ri.cop_world_m[idx - 1, f])
    # The helpers directly: consecutive drops repeat the last kept sample.
    x = np.arange(6.0)[:, None]
    dropped = np.array([False, True, True, False, True, False])[:, None]
    np.testing.assert_array_equal(apply_drops(x, dropped)[:, 0], [0, 0, 0, 3, 3, 5])
    assert not drop_mask(50, 3, 0.99, np.random.default_rng(0))[0].any()


def test_noise_magnitudes_are_as_configured() -> None:
    n, s = 20000, 2
    rng = np.random.default_rng(0)
    ori = np.broadcast_to(np.eye(3), (n, s, 3, 3))
    zeros = np.zeros((n, s, 3))
    cfg = dataclasses.replace(NoiseConfig.off(), acc_white_m_s2=0.1, gyr_bias_rad_s=0.02)
    still = np.broadcast_to(np.array([0.0, 0.0, GRAVITY]), zeros.shape)
    out = corrupt_imu(zeros, ori, still, zeros, FPS, cfg, rng)
    np.testing.assert_allclose(out.acc_world.std(axis=0), 0.1, rtol=0.05)
    assert np.all(out.gyr_local.std(axis=0) < 1e-12)  # a bias is constant
    cfg = dataclasses.replace(NoiseConfig.off(), ori_drift_yaw_deg_per_sqrt_s=1.0)
    out = corrupt_imu(zeros, ori, zeros, zeros, FPS, cfg, rng)
    yaw = np.rad2deg(np.arctan2(out.ori_world[:, :, 1, 0], out.ori_world[:, :, 0, 0]))
    steps = np.diff(yaw, axis=0)
    np.testing.assert_allclose(steps.std(), 1.0 / np.sqrt(FPS), rtol=0.05)
    np.testing.assert_allclose(out.ori_world[:, :, 2, 2], 1.0)  # yaw only: no tilt
    cells = corrupt_insole_cells(
        np.zeros((10, 2, 16)), BODY.insole_area_cm2, NoiseConfig(), np.random.default_rng(0)
    )
    assert np.all(cells >= 0)


# ------------------------------------------------------------------------------- recording
def test_recording_from_motion(tmp_path: Path) -> None:
    params = BodyParams(height_m=1.8, mass_kg=80.0, arm_length_m=0.55)
    m = dataclasses.replace(_synthetic_walk(300), body=params)
    rec = recording_from_motion(m, seed=3)
    validate(rec)
    n = m.n_frames
    assert rec.n_frames == n and rec.fps == FPS and rec.data_info.take_id == "synthetic/walk"
    assert rec.subject.height_m == 1.8 and rec.subject.weight_kg == 80.0
    assert rec.subject.arm_length == 0.55
    assert set(rec.imu) == set(sk.IMU_PARTS) == set(rec.imu_gt)
    for part, stream in rec.imu.items():
        assert (stream.acc_local_raw is not None) == (part in sk.FEET)
    # Poses are the motion's local rotations (joint 0 = global orientation).
    aa = rec.smpl_params.poses.reshape(n, 24, 3).astype(np.float64)
    dots = np.abs(np.sum(axis_angle_to_quat(aa) * m.local_quat, axis=-1))
    np.testing.assert_allclose(dots, 1.0, atol=1e-6)
    np.testing.assert_array_equal(rec.smpl_params.trans + rec.smpl_params.root_offset, m.root_pos)
    assert rec.smpl_params.betas.shape == (n, 10) and not rec.smpl_params.betas.any()
    total = sum(rec.insole[f].force[:, 0] for f in sk.FEET)
    np.testing.assert_allclose(rec.insole_combined.force_world[:, 2], total, atol=1e-12)
    for foot in sk.FEET:
        np.testing.assert_allclose(
            rec.insole[foot].forces.sum(1), rec.insole[foot].force[:, 0], atol=1e-12
        )
    ex = rec.extras
    assert ex["insole_zmp_outside_threshold_m"] == ZMP_OUTSIDE_M == 0.03
    assert ex["source_clip"] == "synthetic/walk" and ex["noise_seed"] == 3 and ex["noise"]
    cfg = json.loads(ex["synthesis_config"])
    assert cfg["imu"]["acc_smoothing_frames"] == "auto"
    assert set(ex["dropped_frames"]["imu"]) == set(sk.IMU_PARTS)
    # Same seed, same recording; noise off gives the clean signals.
    again = recording_from_motion(m, seed=3)
    np.testing.assert_array_equal(
        again.imu["L_Foot"].acc_world_raw, rec.imu["L_Foot"].acc_world_raw
    )
    clean = recording_from_motion(m, noise=False)
    assert clean.extras["noise_seed"] is None
    assert json.loads(clean.extras["synthesis_config"])["noise"]["acc_white_m_s2"] == 0.0
    np.testing.assert_array_equal(clean.imu["Head"].ori_world, clean.imu_gt["Head"].ori_world)
    # The extras survive the project's writer and reader.
    save_recording(rec, tmp_path / "synth.npz")
    back = load_recording(tmp_path / "synth.npz")
    np.testing.assert_array_equal(back.insole["R_Foot"].forces, rec.insole["R_Foot"].forces)
    assert back.extras["synthesis_config"] == ex["synthesis_config"]
    # A config with other settings is honoured and recorded.
    cfg2 = SynthConfig(insole=InsoleSynthConfig(contact_threshold_n=1e6))
    rec2 = recording_from_motion(m, cfg2, noise=False)
    assert not rec2.insole["L_Foot"].contacts.any()
