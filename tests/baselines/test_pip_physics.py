"""PIP's physics optimiser on MuJoCo: standing, tracking a walk, each paper/code flag, the QP
failure path, input checks and the reconstruction it returns.

The walking checks use real mocap (CMU 07_05, a slow walk, 4.3 s) from the shared clips and skip
where the shared data is absent; everything else runs on the rest pose of the body model.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import grip.baselines.pip_physics as pip
from grip.baselines.pip_config import PipConfig, PipInputError
from grip.baselines.pip_dynamics import backward_velocity, foot_joint_height
from grip.core import metrics as mt
from grip.core.body import GRAVITY, BodyParams, build_body
from grip.core.fk import forward_kinematics, integrate_root, rest_pose, sole_points
from grip.core.mjcf import hinge_names
from grip.core.reconstruction import Reconstruction
from grip.core.rotations import axis_angle_to_matrix, geodesic_angle

FEET = list(pip.sk.FOOT_JOINTS)


@pytest.fixture(scope="module")
def body():
    return build_body(BodyParams(1.70, 70.0))


@pytest.fixture(scope="module")
def walk(body, cmu_walk):
    """GT walk on the default body: local rotations, joint positions, rotations, root, fps."""
    motion = cmu_walk
    assert motion.body == body.params
    rot, pos = motion.fk(body)
    return motion.local_rot(), pos, rot, motion.root_pos, motion.fps


def _standing(body, cfg: PipConfig | None = None, lift_m: float = 0.0):
    """Optimiser reset to the rest pose standing on the floor (lifted by ``lift_m``)."""
    phys = pip.PipPhysics(body, cfg)
    rot, root = rest_pose(1)
    root[0, 2] = body.pelvis_height + lift_m
    phys.reset(phys.pose_qpos(rot[0], root[0]))
    return phys, rot[0], root[0]


def _sequence(rot, root, n):
    return np.repeat(rot[None], n, 0), np.zeros((n, 24, 3)), np.ones((n, 2)), root


# ------------------------------------------------------------------ pure parts
def test_gains_at_60_hz_are_pips() -> None:
    cfg = PipConfig.at_rate(60.0)
    assert (cfg.kp_theta, cfg.kd_theta, cfg.kp_r, cfg.kd_r) == pytest.approx((2400, 60, 3600, 60))
    default = PipConfig()
    at100 = PipConfig.at_rate(100.0)
    assert at100.kp_r == default.kp_r and at100.kd_theta == default.kd_theta
    assert at100.kp_theta == pytest.approx(default.kp_theta, abs=0.5)


def test_joint_floor_is_the_foot_joint_height_at_rest(body) -> None:
    # the rest pose stands on the floor (soles at height 0)
    assert foot_joint_height(body) == pytest.approx(body.rest_joint_pos[10, 1], abs=1e-12)
    assert 0.01 < foot_joint_height(body) < 0.05


def test_backward_velocity() -> None:
    p = np.cumsum(np.ones((4, 2, 3)), axis=0) * 0.01  # 1 m/s along every axis at 100 Hz
    v = backward_velocity(p, 100.0)
    np.testing.assert_allclose(v, 1.0, atol=1e-12)
    with pytest.raises(ValueError, match="joint_pos"):
        backward_velocity(np.zeros((4, 3)), 100.0)


# ------------------------------------------------------------------ physics
def test_standing_body_stays_upright_on_its_feet(body) -> None:
    phys, rot, root = _standing(body)
    rec = phys.reconstruct(*_sequence(rot, root, 150))
    mg = body.total_mass * GRAVITY
    feet = rec.joint_pos[:, FEET]
    assert np.abs(feet - feet[0]).max() < 1e-3  # no sliding, no sinking
    assert feet[..., 2].min() > phys.joint_floor_z - 1e-4
    tilt = np.degrees(geodesic_angle(rec.global_rot[:, 0], rec.global_rot[0, 0]))
    assert tilt.max() < 1.0
    assert abs(rec.joint_pos[:, 15, 2] - rec.joint_pos[0, 15, 2]).max() < 0.01
    assert rec.contacts.all() and rec.notes["qp_failures"] == 0
    vgrf = rec.grf[:, :, 2].sum(axis=1)
    # The feet carry the body weight; the residual takes a little: with 8 corners at the minimum
    # Signorini height, 0.01 r^2 + 8 x 0.0025 lambda^2 is least at r = mg / 33.
    assert (vgrf / mg > 0.94).all() and (vgrf / mg < 1.0).all()
    np.testing.assert_allclose(rec.grf[:, 0], rec.grf[:, 1] * [-1, 1, 1], atol=1e-6 * mg)
    assert rec.notes["residual_force_mean_n"] < 0.1 * mg
    # each foot's centre of pressure lies in its contact square, on the floor
    half = 0.5 * phys.cfg.contact_square_m
    assert (np.abs(rec.cop[..., :2] - feet[..., :2]) <= half + 1e-9).all()
    np.testing.assert_allclose(rec.cop[..., 2], 0.0)


def test_forces_satisfy_the_equation_of_motion(body) -> None:
    """With the feet in contact, MuJoCo's inverse dynamics of the chosen acceleration equals the
    joint torques, the residual wrench and the foot forces the optimiser reports."""
    phys, rot, _ = _standing(body)
    q0, qd0 = phys.qpos, phys.qvel
    vel = np.zeros((24, 3))
    vel[:, 0] = 0.4  # push sideways: friction and residual both work
    fr = phys.step(rot, vel, np.ones(2))
    m, d = phys.model, mujoco.MjData(phys.model)
    d.qpos[:], d.qvel[:] = q0, qd0
    mujoco.mj_forward(m, d)
    d.qacc[:] = (fr.qvel - qd0) * phys.cfg.fps
    mujoco.mj_inverse(m, d)
    f = d.qfrc_inverse
    idx = phys.index.hinge_dof_adr
    # hinge rows: tau_j + (J_c^T lambda)_j, where the second term vanishes off the legs
    lower = np.isin(np.arange(69) // 3 + 1, [1, 2, 4, 5, 7, 8, 10, 11])
    np.testing.assert_allclose(fr.torques[~lower], f[idx][~lower], atol=1e-6)
    # root translation rows: residual force + total contact force (world)
    np.testing.assert_allclose(f[:3], fr.residual[:3] + fr.grf.sum(axis=0), atol=1e-6)
    assert fr.grf[:, 2].sum() > 0.5 * body.total_mass * GRAVITY


def test_torques_in_hinge_name_order_match_inverse_dynamics_in_flight(body) -> None:
    phys, rot, _ = _standing(body, lift_m=2.0)
    q0 = phys.qpos
    vel = np.random.default_rng(0).normal(scale=0.3, size=(24, 3))
    fr = phys.step(rot, vel, np.zeros(2))
    assert not fr.contacts.any() and np.all(fr.grf == 0) and np.isnan(fr.cop).all()
    d = mujoco.MjData(phys.model)
    d.qpos[:] = q0
    mujoco.mj_forward(phys.model, d)
    d.qacc[:] = fr.qvel * phys.cfg.fps
    mujoco.mj_inverse(phys.model, d)
    np.testing.assert_allclose(fr.residual, d.qfrc_inverse[:6], atol=1e-6)
    np.testing.assert_allclose(fr.torques, d.qfrc_inverse[phys.index.hinge_dof_adr], atol=1e-6)
    # holding an outstretched arm is a torque about the forward (body z) axis of the shoulder
    names = hinge_names()
    sh = [names.index(f"L_Shoulder_{a}") for a in "xyz"]
    assert np.argmax(np.abs(fr.torques[sh])) == 2 and abs(fr.torques[sh[2]]) > 1.0


def test_walk_with_perfect_input_tracks_the_ground_truth(body, walk) -> None:
    local, pos, rot, root, fps = walk
    contact = mt.contacts_from_motion(pos[:, FEET], fps)
    phys = pip.PipPhysics(body)
    rec = phys.reconstruct(local, backward_velocity(pos, fps), contact.astype(float), root[0])
    assert rec.notes["qp_failures"] == 0
    np.testing.assert_allclose(rec.joint_pos[0], pos[0], atol=1e-9)  # frame 0: the input pose
    assert mt.mpjpe(rec.joint_pos, pos) < 50.0  # mm
    assert mt.mpjre(rec.global_rot, rot) < 5.0  # deg
    assert np.linalg.norm(rec.joint_pos[-1, 0] - pos[-1, 0]) < 0.1  # no drift over 4.3 s
    mean_vgrf = rec.grf[1:, :, 2].sum(axis=1).mean() / (body.total_mass * GRAVITY)
    assert 0.8 < mean_vgrf < 1.1


def test_physics_reduces_sliding_and_penetration_of_a_noisy_estimate(body, walk) -> None:
    """The issue's claim: PIP reduces foot sliding and penetration vs the kinematics alone."""
    local, pos, _, root, fps = walk
    rng = np.random.default_rng(0)
    jitter = rng.normal(scale=np.radians(3), size=(*local.shape[:2], 3))  # 3 deg per joint
    noisy_local = local @ axis_angle_to_matrix(jitter)
    vel = backward_velocity(pos, fps) + rng.normal(scale=0.1, size=pos.shape)
    vel[..., 2] -= 0.05  # a velocity bias: the integrated estimate sinks into the floor
    kin_rot, kin_pos = forward_kinematics(noisy_local, integrate_root(root[0], vel[:, 0], fps),
                                          body.offsets)  # fmt: skip
    contact = mt.contacts_from_motion(pos[:, FEET], fps)
    rec = pip.PipPhysics(body).reconstruct(noisy_local, vel, contact.astype(float), root[0])
    fs_kin, fs_pip = (mt.foot_sliding(p, contact, fps) for p in (kin_pos, rec.joint_pos))
    fp_kin = mt.foot_penetration(sole_points(kin_rot, kin_pos, body))
    fp_pip = mt.foot_penetration(sole_points(rec.global_rot, rec.joint_pos, body))
    assert fs_pip < 0.1 * fs_kin
    assert fp_pip < 0.5 * fp_kin
    assert mt.mpjpe(rec.joint_pos, pos) < mt.mpjpe(kin_pos, pos)


# ------------------------------------------------------------------ flags
@pytest.mark.parametrize("cone", ["inner", "outer"])
def test_friction_pyramid(body, cone: str) -> None:
    phys, rot, _ = _standing(body, PipConfig(friction=cone))
    vel = np.zeros((24, 3))
    vel[:, 0] = 1.0  # a sideways demand far beyond what friction can give
    fr = phys.step(rot, vel, np.ones(2))
    ratio = np.abs(fr.grf[:, 0]) / fr.grf[:, 2]
    mu = phys.cfg.mu
    if cone == "inner":
        assert ratio.max() <= mu / np.sqrt(2) + 1e-6
        np.testing.assert_allclose(ratio, mu / np.sqrt(2), rtol=1e-3)  # saturated
    else:
        assert ratio.max() <= mu + 1e-6
        np.testing.assert_allclose(ratio, mu, rtol=1e-3)  # more tangential force than inner


@pytest.mark.parametrize("bounds", ["code", "paper"])
def test_foot_velocity_bounds(body, bounds: str) -> None:
    phys, rot, _ = _standing(body, PipConfig(velocity_bounds=bounds))
    foot0 = phys.data.xpos[phys.index.body_ids[FEET]].copy()
    vel = np.zeros((24, 3))
    vel[:, 0] = 0.3  # the whole body moves sideways at 0.3 m/s
    fr = phys.step(rot, vel, np.full(2, 0.6))
    speed = np.abs(fr.joint_pos[FEET, 0] - foot0[:, 0]) * phys.cfg.fps
    assert fr.contacts.all()
    if bounds == "code":  # th = -ln(0.6 / 0.85) = 0.35 m/s lets the feet follow
        assert (speed > 0.1).all() and (speed <= -np.log(0.6 / 0.85) + 1e-6).all()
    else:  # contact joints slide at most sigma
        # (the bound holds for the linearised velocity J (qd + qdd dt); the displacement over
        # one step differs from it at second order)
        assert (speed <= phys.cfg.sigma_mps * 1.01).all()


def test_foot_with_low_contact_probability_is_free_but_cannot_pass_the_floor(body) -> None:
    phys, rot, _ = _standing(body)
    vel = np.zeros((24, 3))
    vel[:, 2] = -1.0  # the estimate sinks at 1 m/s
    for _ in range(20):
        fr = phys.step(rot, vel, np.zeros(2))
    assert fr.joint_pos[FEET, 2].min() >= phys.joint_floor_z - 1e-6


def test_explicit_integration_moves_with_the_old_velocity(body) -> None:
    vel = np.zeros((24, 3))
    vel[:, 0] = 0.3
    q = {}
    for integ in ("semi_implicit", "explicit"):
        phys, rot, _ = _standing(body, PipConfig(integrator=integ))
        q0 = phys.qpos
        fr = phys.step(rot, vel, np.full(2, 0.6))
        assert np.abs(fr.qvel).max() > 0.05
        q[integ] = fr.qpos - q0
    np.testing.assert_array_equal(q["explicit"], 0.0)  # from rest: the old velocity is 0
    assert np.abs(q["semi_implicit"]).max() > 1e-4


def test_position_pd_on_all_joints_drives_the_feet(body) -> None:
    vel = np.zeros((24, 3))
    vel[FEET, 0] = 0.5  # only the feet are asked to move
    moved = {}
    for joints in ("code", "all"):
        phys, rot, _ = _standing(body, PipConfig(pd_joints=joints), lift_m=2.0)
        foot0 = phys.data.xpos[phys.index.body_ids[FEET]].copy()
        fr = phys.step(rot, vel, np.zeros(2))
        moved[joints] = (fr.joint_pos[FEET, 0] - foot0[:, 0]) * phys.cfg.fps
    assert np.abs(moved["code"]).max() < 0.01  # code: no position row for the feet
    assert (moved["all"] > 0.1).all()


def test_weight_form_changes_the_residual(body) -> None:
    res = {}
    for form in ("code", "paper"):
        phys, rot, root = _standing(body, PipConfig(weight_form=form))
        res[form] = phys.reconstruct(*_sequence(rot, root, 30)).notes["residual_force_mean_n"]
    # code: 0.01 |r|^2 vs 0.0025 |lambda_c|^2; paper: 0.1 |r|^2 vs 0.05 |lambda_c|^2, so the
    # paper form leans more on the residual
    assert res["paper"] > 1.2 * res["code"]


@pytest.mark.parametrize(("rule", "expected"), [("code", False), ("paper", True)])
def test_contact_rule(body, rule: str, expected: bool) -> None:
    phys, rot, _ = _standing(body, PipConfig(contact_rule=rule), lift_m=0.004)
    fr = phys.step(rot, np.zeros((24, 3)), np.full(2, 0.2))  # 4 mm up, unlikely contact
    assert (fr.contacts == expected).all()
    assert (fr.grf[:, 2] > 100.0).all() == expected


# ------------------------------------------------------------------ failures
def test_failed_qp_keeps_going_and_is_counted(body, monkeypatch) -> None:
    calls = []

    def failing(hess, lin, g, h, solver):
        calls.append(solver)
        return None

    monkeypatch.setattr(pip, "_solve_qp", failing)
    phys, rot, root = _standing(body)
    rec = phys.reconstruct(*_sequence(rot, root, 10))
    # each frame: the full QP and its two softened retries, each with both solvers
    assert rec.notes["qp_failures"] == 10 and rec.notes["qp_retries"] == 30
    assert calls == ["quadprog", "daqp"] * 30 and rec.notes["qp_softened"] == 0
    # qdd = 0 from rest: the body stays put, no forces, torques = bias forces
    np.testing.assert_allclose(rec.joint_pos, rec.joint_pos[:1].repeat(10, 0), atol=1e-12)
    np.testing.assert_array_equal(rec.grf, 0.0)
    assert np.isfinite(rec.torques).all() and np.abs(rec.residual[:, 2]).min() > 100.0


def test_a_reference_far_from_the_state_is_followed_with_a_softer_pd(body) -> None:
    """A start far from the reference (the estimate's first frames when it starts from the
    standing calibration): the full PD asks for more than ``max_solution_norm`` and, without
    softening, the body halts and every frame fails; with it the body moves toward the
    reference and the full QP succeeds again."""
    from grip.core.rotations import rot_x

    far = np.repeat(rest_pose(1)[0], 40, 0)  # local rotations
    for hip, knee in ((1, 4), (2, 5)):  # a deep squat: hips and knees 1.2 rad
        far[:, hip], far[:, knee] = rot_x(np.array(-1.2)), rot_x(np.array(1.2))
    out = {}
    for soften in (False, True):
        phys, rot, root = _standing(body, PipConfig(soften_on_failure=soften))
        local = far.copy()
        local[0] = rot  # frame 0: the state's pose (the rest pose)
        out[soften] = phys.reconstruct(local, np.zeros((40, 24, 3)), np.ones((40, 2)), root)
    halted = out[False]
    assert halted.notes["qp_failures"] == 39  # every frame after the first
    np.testing.assert_allclose(halted.joint_pos, halted.joint_pos[:1].repeat(40, 0), atol=1e-12)
    soft = out[True]
    assert soft.notes["qp_failures"] == 0 and 1 <= soft.notes["qp_softened"] < 20
    want = forward_kinematics(far[-1:], root[None], body.offsets)[0][0, 4]
    cos = (np.trace(soft.global_rot[-1, 4].T @ want) - 1.0) / 2.0
    assert np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))) < 20.0  # the left shank follows


@pytest.mark.parametrize("mode", ["stop", "coast"])
def test_a_failed_frame_stops_or_coasts(body, monkeypatch, mode: str) -> None:
    monkeypatch.setattr(pip, "_solve_qp", lambda *a: None)
    cfg = PipConfig(on_failure=mode, fallback_solver=None)
    phys, rot, root = _standing(body, cfg)
    rot_s, vel, prob, _ = _sequence(rot, root, 6)
    qvel0 = np.zeros(phys.nv)
    qvel0[2] = -2.0  # dropping at 2 m/s, as onto the floor when lying down
    rec = phys.reconstruct(rot_s, vel, prob, root, qvel0=qvel0)
    assert rec.notes["qp_failures"] == 6  # frame 0 solves too (its forces), without advancing
    drop = rec.joint_pos[0, 0, 2] - rec.joint_pos[-1, 0, 2]
    if mode == "stop":  # halts at the first failed frame: no further motion
        assert drop == pytest.approx(0.0, abs=1e-12)
    else:  # keeps 2 m/s for 5 frames, without gravity or forces
        assert drop == pytest.approx(5 * 2.0 / cfg.fps, rel=1e-9)


def test_retry_with_the_fallback_solver(body, monkeypatch) -> None:
    inner = pip._solve_qp
    phys, rot, root = _standing(body)
    ref = phys.reconstruct(*_sequence(rot, root, 10))
    monkeypatch.setattr(pip, "_solve_qp",
                        lambda *a: None if a[-1] == "quadprog" else inner(*a))  # fmt: skip
    rec = phys.reconstruct(*_sequence(rot, root, 10))
    assert rec.notes["qp_failures"] == 0 and rec.notes["qp_retries"] == 10
    np.testing.assert_allclose(rec.joint_pos, ref.joint_pos, atol=1e-8)  # daqp == quadprog
    np.testing.assert_allclose(rec.grf, ref.grf, atol=1e-5)


def test_solution_norm_limit_counts_as_failure(body) -> None:
    phys, rot, root = _standing(body, PipConfig(max_solution_norm=1.0, fallback_solver=None))
    rec = phys.reconstruct(*_sequence(rot, root, 5))
    assert rec.notes["qp_failures"] == 5 and rec.notes["qp_retries"] == 0


# ------------------------------------------------------------------ bad input
def test_bad_inputs_are_refused_with_clear_errors(body) -> None:
    phys, rot, root = _standing(body)
    good = _sequence(rot, root, 6)
    with pytest.raises(PipInputError, match=r"local_rot has shape \(23, 3, 3\)"):
        phys.step(rot[1:], np.zeros((24, 3)), np.ones(2))
    with pytest.raises(PipInputError, match=r"joint_vel has shape"):
        phys.step(rot, np.zeros((24, 2)), np.ones(2))
    with pytest.raises(PipInputError, match=r"contact_prob must lie in \[0, 1\]"):
        phys.step(rot, np.zeros((24, 3)), np.array([0.5, 1.2]))
    vel = good[1].copy()
    vel[4, 7, 1] = np.nan
    with pytest.raises(PipInputError, match=r"joint_vel has non-finite values .*index 4\)"):
        phys.reconstruct(good[0], vel, good[2], root)
    with pytest.raises(PipInputError, match=r"contact_prob has shape \(5, 2\)"):
        phys.reconstruct(good[0], good[1], good[2][:5], root)
    with pytest.raises(PipInputError, match=r"local_rot must have shape \(T, 24, 3, 3\)"):
        phys.reconstruct(rot, good[1], good[2], root)
    with pytest.raises(PipInputError, match="root_pos0 has non-finite"):
        phys.reconstruct(*good[:3], np.array([0.0, np.inf, 1.0]))
    with pytest.raises(PipInputError, match="quaternion"):
        phys.reset(np.zeros(76))


@pytest.mark.parametrize(
    ("kw", "msg"),
    [
        ({"friction": "cone"}, "friction='cone'"),
        ({"solver": "proxqp"}, "solver='proxqp'"),
        ({"fallback_solver": "osqp"}, "fallback_solver='osqp'"),
        ({"fps": 0.0}, "fps=0.0 must be > 0"),
        ({"w_torque": -1.0}, "w_torque=-1.0 must be >= 0"),
        ({"mu": float("nan")}, "mu=nan must be finite"),
    ],
)
def test_bad_config_is_refused(kw: dict, msg: str) -> None:
    with pytest.raises(ValueError, match=msg):
        PipConfig(**kw)


# ------------------------------------------------------------------ output
def test_reconstruction_shapes_and_round_trip(body, tmp_path) -> None:
    phys, rot, root = _standing(body)
    rec = phys.reconstruct(*_sequence(rot, root, 8), name="stand")
    assert isinstance(rec, Reconstruction) and rec.method == "pip" and rec.fps == 100.0
    shapes = {"joint_pos": (24, 3), "global_rot": (24, 3, 3), "grf": (2, 3), "cop": (2, 3),
              "torques": (69,), "contacts": (2,), "residual": (6,)}  # fmt: skip
    for key, shape in shapes.items():
        assert getattr(rec, key).shape == (8, *shape), key
    assert rec.ms_per_frame > 0 and rec.falls.shape == (0, 2)
    # frame 0 is the kinematic input pose
    g_rot, g_pos = forward_kinematics(rot, root, body.offsets)
    np.testing.assert_allclose(rec.joint_pos[0], g_pos, atol=1e-9)
    np.testing.assert_allclose(rec.global_rot[0], g_rot, atol=1e-9)
    path = tmp_path / "stand.npz"
    rec.save(path)
    back = Reconstruction.load(path)
    assert back.notes["qp_failures"] == 0 and back.notes["config"]["friction"] == "inner"
    np.testing.assert_array_equal(back.torques, rec.torques)
