"""PIP's physics optimiser (Yi et al., CVPR 2022, section 3.2) on the project's MuJoCo humanoid.

This is BASELINES_AND_METRICS.md section 1: a per-frame quadratic programme that turns a
kinematic estimate (local pose, joint velocities, foot contact probabilities) into a motion that
obeys the equation of motion of a floating-base humanoid with ground contacts, plus the ground
reaction forces, joint torques and a residual root wrench that produce it. Where PIP's paper and
its public code disagree, the code produced the published numbers, so the code is the default
and the paper is a flag of :class:`~grip.baselines.pip_config.PipConfig`:

================  =============================================  =================================
flag              default (code)                                 variant (paper)
================  =============================================  =================================
friction          ``"inner"``: ``|lambda_x|, |lambda_y| <=``     ``"outer"``: ``<= mu lambda_z``
                  ``mu / sqrt(2) lambda_z``
velocity_bounds   ``"code"``: feet always within                 ``"paper"``: contact joints
                  ``th = -ln(min(c, .85) / .85)`` m/s, other     slide at most ``sigma`` = 0.01
                  contact joints within 0.1 m/s                  m/s and never move down
integrator        ``"semi_implicit"``: ``qd += qdd dt``, then    ``"explicit"`` (eq. 13): ``q``
                  ``q`` moves with the new ``qd``                moves with the old ``qd``
pd_joints         ``"code"``: 20 joints (no feet 10/11)          ``"all"``: 24 joints
weight_form       ``"code"``: weights inside the norm            ``"paper"``: outside the norm
contact_rule      ``"code"``: foot ``c > .5 and d <= 3 cm`` or   ``"paper"``: foot ``d < .5 cm``
                  ``d <= 0``; other joints ``d <= 0``            or ``d < 3 cm and c > .5``;
                                                                 other joints ``d < .5 cm``
================  =============================================  =================================

MuJoCo serves only as a rigid-body-dynamics library here (``mj_step`` is never called): the
model is :func:`grip.core.mjcf.build_mjcf`'s humanoid of the subject (total mass = subject
mass) with joint armature and damping set to 0, so that ``M`` is the pure rigid-body inertia,
and with contacts, constraints (joint limits: PIP has none), actuation, passive forces and
sensors disabled in ``opt.disableflags``.

Per frame (state ``q, qd``; inputs pose ``phi``, joint velocities ``v``, contact probabilities
``c``):

1. ``M`` (``mj_fullM``) and ``h = qfrc_bias`` at the current state.
2. Contact joints: the foot joints (SMPL 10/11) and 14 other candidates, by their height ``d``
   above the *joint floor* ``z_floor + h_foot``, where ``h_foot`` is the foot joint's height
   above the sole in the subject's rest pose (PIP's floor is the plane the foot joints rest on).
   Each contact joint contributes the 4 corners of a horizontal ``L x L`` square centred on it,
   rigidly attached to its body.
3. Dual PD: ``qdd_theta = kp_theta e - kd_theta qd[3:]`` (``e`` from ``mj_differentiatePos``
   towards the reference, hinge entries wrapped to [-pi, pi)); for each PD joint
   ``rdd = kp_r v dt - kd_r J qd``.
4. The QP over ``y = [qdd (75), lambda (3 n_c)]``, with ``tau = M qdd + h - J_c^T lambda``
   substituted (PIP's equality constraint eliminated, so only inequalities remain):
   ``min |qdd[3:] - qdd_theta|^2 + |J qdd + Jd qd - rdd|^2 + sum_c (10 max(d_c, .005))^2
   |lambda_c|^2 + .01 |tau[:6]|^2 + 1e-4 |tau[6:]|^2`` (code weights, inside the norm) subject
   to the friction pyramid and the bounds on next-step joint velocities ``J (qd + qdd dt)``.
5. ``qd <- qd + qdd dt``, ``q <- integratePos(q, qd, dt)`` (semi-implicit).

The QP is solved with quadprog (the solver PIP used) or daqp, through ``qpsolvers``. A failed
solve (no solution, a non-finite one, or ``|[qdd, lambda, tau]| > 1e4`` as in PIP's code) is
retried with the other solver (section 1.6 names proxqp for the retry; it is not installed
here); if that fails too, the QP is solved again with softer PD terms
(:attr:`~grip.baselines.pip_config.PipConfig.soften_on_failure`, not in PIP), and only when
those fail too the frame has ``qdd = 0`` and, by default, the body stops there
(:attr:`~grip.baselines.pip_config.PipConfig.on_failure`); failures and softened frames are
counted in the notes.

Frame 0 of :meth:`PipPhysics.reconstruct` outputs the reference pose unchanged at the given
initial root position, with the state at rest unless an initial velocity is given (PIP's code).

Arrays: world frame z up, floor at ``cfg.floor_z_m``; m, s, N, N m, rad. ``qpos`` (76,) and
``qvel`` (75,) are in MuJoCo's order (free root first, then hinges depth-first); torques leave in
:func:`grip.core.mjcf.hinge_names` order.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict

import mujoco
import numpy as np
import qpsolvers

from grip.baselines.pip_config import (
    CONTACT_CANDIDATES,
    PD_JOINTS_CODE,
    SOFTEN_FACTORS,
    SOLVERS,
    PipConfig,
    PipFrame,
    PipInputError,
    _check,
)
from grip.baselines.pip_dynamics import _skew, _solve_qp, foot_joint_height
from grip.core import skeleton as sk
from grip.core.body import BodyModel, BodyParams
from grip.core.mjcf import SIM_TEXTURE_PX, MjcfConfig, as_body_model, build_mjcf
from grip.core.reconstruction import Reconstruction
from grip.core.reference import pose_vector
from grip.sim.model import HumanoidIndex, write_pose_vector

__all__ = ["PipPhysics"]

_FOOT_PROB_CAP = 0.85  # PIP code: th = -ln(min(c, 0.84999) / 0.85), ~0 for c >= 0.85
_FOOT_Z_SLACK = 1e-6  # PIP code: upper bound of the foot's vertical speed is max(th, th_z) + 1e-6
_COP_MIN_FORCE_N = 1.0  # below this vertical force a foot's centre of pressure is undefined (NaN)


class PipPhysics:
    """PIP's per-frame physics optimiser for one subject.

    Args:
        body: The subject's body model or parameters (``None``: 1.70 m, 70 kg).
        cfg: Settings (``None``: :class:`PipConfig` defaults).

    Raises:
        ValueError: The configured solver is not installed.
    """

    def __init__(self, body: BodyModel | BodyParams | None = None,
                 cfg: PipConfig | None = None) -> None:  # fmt: skip
        self.cfg = cfg or PipConfig()
        self.body = as_body_model(body)
        installed = set(qpsolvers.available_solvers)
        fallback = self.cfg.fallback_solver
        if fallback == "auto":
            fallback = next(s for s in SOLVERS if s != self.cfg.solver)
            fallback = fallback if fallback in installed else None
        for s in (self.cfg.solver, fallback):
            if s is not None and s not in installed:
                raise ValueError(f"QP solver {s!r} is not installed (qpsolvers has "
                                 f"{sorted(installed)}); pip install {s}")  # fmt: skip
        self.fallback_solver = fallback

        mjcf = MjcfConfig(armature=0.0, joint_damping=0.0, floor=False, self_collision=False,
                          sole_pads=False, insole_sensors=False, imu_sensors=False,
                          texture_px=SIM_TEXTURE_PX)  # fmt: skip
        self.model = mujoco.MjModel.from_xml_string(build_mjcf(self.body, mjcf))
        off = mujoco.mjtDisableBit
        self.model.opt.disableflags |= int(
            off.mjDSBL_CONTACT | off.mjDSBL_CONSTRAINT | off.mjDSBL_ACTUATION
            | off.mjDSBL_SPRING | off.mjDSBL_DAMPER | off.mjDSBL_SENSOR
        )  # fmt: skip
        self.data = mujoco.MjData(self.model)
        self.index = HumanoidIndex.from_model(self.model)
        nv = self.nv = int(self.model.nv)

        cfg = self.cfg
        self.foot_height_m = foot_joint_height(self.body)
        self.joint_floor_z = cfg.floor_z_m + self.foot_height_m
        self._bid = self.index.body_ids
        self._pd = np.array(PD_JOINTS_CODE if cfg.pd_joints == "code" else range(sk.N_JOINTS))
        self._feet = np.array(sk.FOOT_JOINTS)
        self._nonfoot = np.array(CONTACT_CANDIDATES)
        half = 0.5 * cfg.contact_square_m
        self._corner_off = np.array([[-half, -half, 0.0], [half, -half, 0.0],
                                     [half, half, 0.0], [-half, half, 0.0]])  # fmt: skip
        self._corner_skew = _skew(self._corner_off)  # (4, 3, 3)
        self._hinge_dofs = self.index.hinge_dof_adr
        s2 = math.sqrt(2.0) if cfg.friction == "inner" else 1.0
        self._cone = np.array([[s2, 0, -cfg.mu], [-s2, 0, -cfg.mu],
                               [0, s2, -cfg.mu], [0, -s2, -cfg.mu]])  # fmt: skip

        def weight(w: float) -> float:  # factor of the squared residual
            return w * w if cfg.weight_form == "code" else w

        self._s_theta, self._s_r = weight(cfg.w_theta), weight(cfg.w_r)
        self._tau_w = np.concatenate([np.full(6, weight(cfg.w_residual)),
                                      np.full(nv - 6, weight(cfg.w_torque))])  # fmt: skip

        self._M = np.zeros((nv, nv))
        self._jp = np.zeros((sk.N_JOINTS, 3, nv))
        self._jr = np.zeros((sk.N_JOINTS, 3, nv))
        self._jdot = np.zeros((3, nv))
        self._err = np.zeros(nv)
        self._qref = np.zeros(self.model.nq)
        self.qp_failures = 0
        self.qp_retries = 0
        self.qp_softened = 0
        self.reset(self.model.qpos0)

    # ------------------------------------------------------------------ state
    def pose_qpos(self, local_rot: np.ndarray, root_pos: np.ndarray) -> np.ndarray:
        """MuJoCo ``qpos`` ``(76,)`` of a pose.

        Args:
            local_rot: ``(24, 3, 3)`` rotations relative to the parent; row 0 = root world
                rotation.
            root_pos: ``(3,)`` pelvis position, world, m.
        """
        local_rot = _check("local_rot", local_rot, (sk.N_JOINTS, 3, 3))
        root_pos = _check("root_pos", root_pos, (3,))
        qpos = self.model.qpos0.copy()
        write_pose_vector(pose_vector(local_rot, root_pos), self.index, qpos)
        return qpos

    def reset(self, qpos: np.ndarray, qvel: np.ndarray | None = None) -> None:
        """Set the state.

        Args:
            qpos: ``(76,)`` MuJoCo ``qpos`` (e.g. from :meth:`pose_qpos`).
            qvel: ``(75,)`` MuJoCo ``qvel``; ``None``: at rest (PIP's start).
        """
        qpos = _check("qpos", qpos, (self.model.nq,))
        qvel = np.zeros(self.nv) if qvel is None else _check("qvel", qvel, (self.nv,))
        norm = float(np.linalg.norm(qpos[3:7]))
        if norm < 1e-6:
            raise PipInputError(f"qpos has a zero root quaternion {qpos[3:7].tolist()}")
        self.data.qpos[:] = qpos
        self.data.qpos[3:7] /= norm
        self.data.qvel[:] = qvel
        mujoco.mj_kinematics(self.model, self.data)

    @property
    def qpos(self) -> np.ndarray:
        """``(76,)`` current MuJoCo ``qpos`` (a copy)."""
        return self.data.qpos.copy()

    @property
    def qvel(self) -> np.ndarray:
        """``(75,)`` current MuJoCo ``qvel`` (a copy)."""
        return self.data.qvel.copy()

    # ------------------------------------------------------------------ one frame
    def step(self, local_rot: np.ndarray, joint_vel: np.ndarray,
             contact_prob: np.ndarray) -> PipFrame:  # fmt: skip
        """Optimise one frame and advance the state by ``1 / fps``.

        Args:
            local_rot: ``(24, 3, 3)`` reference pose: rotations relative to the parent, row 0 =
                root world rotation.
            joint_vel: ``(24, 3)`` reference joint velocities, world, m/s.
            contact_prob: ``(2,)`` left, right foot contact probabilities in [0, 1].

        Returns:
            The state after the update with the forces that produced it.

        Raises:
            PipInputError: A wrong shape, a non-finite value or a probability outside [0, 1].
        """
        local_rot = _check("local_rot", local_rot, (sk.N_JOINTS, 3, 3))
        joint_vel = _check("joint_vel", joint_vel, (sk.N_JOINTS, 3))
        contact_prob = self._check_prob(_check("contact_prob", contact_prob, (2,)))
        pose = pose_vector(local_rot, np.zeros(3))
        return self._advance(pose, joint_vel, contact_prob, integrate=True)

    @staticmethod
    def _check_prob(c: np.ndarray) -> np.ndarray:
        if (c < 0.0).any() or (c > 1.0).any():
            bad = np.argwhere((c < 0.0) | (c > 1.0))[0]
            raise PipInputError(f"contact_prob must lie in [0, 1], got {c[tuple(bad)]} "
                                f"at index {tuple(int(i) for i in bad)}")  # fmt: skip
        return c

    def _advance(self, pose: np.ndarray, joint_vel: np.ndarray, contact_prob: np.ndarray,
                 integrate: bool) -> PipFrame:  # fmt: skip
        """Solve the QP at the current state for a ``(76,)`` pose vector and, with
        ``integrate``, update the state."""
        m, d, cfg, nv = self.model, self.data, self.cfg, self.nv
        dt = cfg.dt
        mujoco.mj_fwdPosition(m, d)
        mujoco.mj_fwdVelocity(m, d)
        mujoco.mj_fullM(m, d, self._M)
        M, h, qvel = self._M, d.qfrc_bias.copy(), d.qvel.copy()
        xpos = d.xpos[self._bid]  # (24, 3)
        jp, jr = self._jp, self._jr
        for j, b in enumerate(self._bid):
            mujoco.mj_jacBody(m, d, jp[j], jr[j], b)

        # contact joints and their corner points
        height = xpos[:, 2] - self.joint_floor_z
        d_feet, d_other = height[self._feet], height[self._nonfoot]
        if cfg.contact_rule == "code":
            foot_in = ((contact_prob > 0.5) & (d_feet <= cfg.foot_contact_height_m)) | (d_feet <= 0)
            other_in = d_other <= 0.0
        else:
            foot_in = (d_feet < cfg.touch_height_m) | (
                (d_feet < cfg.foot_contact_height_m) & (contact_prob > 0.5))  # fmt: skip
            other_in = d_other < cfg.touch_height_m
        cj = np.concatenate([self._feet[foot_in], self._nonfoot[other_in]])
        nc = 4 * len(cj)
        # corner velocity = v_joint + w x r = (Jp - [r]_x Jr) qd
        jc = (jp[cj][:, None] - self._corner_skew[None] @ jr[cj][:, None]).reshape(3 * nc, nv)
        corners = (xpos[cj][:, None, :] + self._corner_off[None]).reshape(nc, 3)
        d_corner = np.repeat(height[cj], 4)

        # dual PD targets
        mujoco.mj_differentiatePos(m, self._err, 1.0, d.qpos, self._reference_qpos(pose))
        e = self._err
        e[self._hinge_dofs] = np.mod(e[self._hinge_dofs] + np.pi, 2.0 * np.pi) - np.pi
        qdd_theta = cfg.kp_theta * e[3:] - cfg.kd_theta * qvel[3:]
        pd = self._pd
        j_pd = jp[pd].reshape(-1, nv)
        jdq = np.empty((len(pd), 3))
        for k, j in enumerate(pd):
            mujoco.mj_jacDot(m, d, self._jdot, None, xpos[j], int(self._bid[j]))
            jdq[k] = self._jdot @ qvel
        rdd = cfg.kp_r * dt * joint_vel[pd] - cfg.kd_r * (j_pd @ qvel).reshape(-1, 3)
        b_r = (rdd - jdq).reshape(-1)

        # objective 1/2 y^T P y - a^T y over y = [qdd, lambda]; tau = K y + h
        n = nv + 3 * nc
        k_mat = np.empty((nv, n))
        k_mat[:, :nv] = M
        k_mat[:, nv:] = -jc.T
        # The two Gram products go through einsum, not BLAS: at this size OpenBLAS runs them
        # multi-threaded, which made a frame 3-15x slower on a loaded 2-core machine.
        kw = k_mat * self._tau_w[:, None]
        hess = np.einsum("ij,ik->jk", kw, k_mat)
        lin = -(kw.T @ h)
        hess[:nv, :nv] += self._s_r * np.einsum("ij,ik->jk", j_pd, j_pd)
        lin_pd = np.zeros(n)  # the PD terms' part of the linear term (softened on a failure)
        lin_pd[:nv] = self._s_r * (j_pd.T @ b_r)
        idx = np.arange(3, nv)
        hess[idx, idx] += self._s_theta
        lin_pd[3:nv] += self._s_theta * qdd_theta
        dc = np.maximum(d_corner, cfg.signorini_min_height_m) * cfg.w_signorini
        sig = dc * dc if cfg.weight_form == "code" else dc
        lam_idx = np.arange(nv, n)
        hess[lam_idx, lam_idx] += np.repeat(sig, 3)
        hess[np.arange(n), np.arange(n)] += cfg.regularization

        g, hb = self._constraints(jp, height, contact_prob, foot_in, cj, qvel, nc)
        y, failed, retried = self._solve(hess, lin + lin_pd, g, hb, k_mat, h)
        if failed and cfg.soften_on_failure:
            for f in SOFTEN_FACTORS:
                y, failed, _ = self._solve(hess, lin + f * lin_pd, g, hb, k_mat, h)
                if not failed:
                    self.qp_softened += 1
                    break
        if failed:
            self.qp_failures += 1
        qdd, lam = y[:nv], y[nv:].reshape(nc, 3)
        tau = k_mat @ y + h

        if failed and cfg.on_failure == "stop":
            qvel = np.zeros_like(qvel)
        if integrate:
            if cfg.integrator == "semi_implicit":
                d.qvel[:] = qvel + qdd * dt
                mujoco.mj_integratePos(m, d.qpos, d.qvel, dt)
            else:
                mujoco.mj_integratePos(m, d.qpos, qvel, dt)
                d.qvel[:] = qvel + qdd * dt
            mujoco.mj_kinematics(m, d)
        grf, cop = self._foot_forces(cj, corners, lam)
        return PipFrame(
            qpos=d.qpos.copy(), qvel=d.qvel.copy(), joint_pos=d.xpos[self._bid].copy(),
            global_rot=d.xmat[self._bid].reshape(sk.N_JOINTS, 3, 3).copy(), grf=grf, cop=cop,
            torques=tau[self._hinge_dofs].copy(), contacts=foot_in.copy(), residual=tau[:6].copy(),
            qp_failed=failed, qp_retried=retried,
        )  # fmt: skip

    def _reference_qpos(self, pose: np.ndarray) -> np.ndarray:
        """MuJoCo ``qpos`` of a ``(76,)`` pose vector (the root position is irrelevant: the
        rotation PD uses only the rotational part of the difference)."""
        write_pose_vector(pose, self.index, self._qref)
        return self._qref

    def _constraints(self, jp: np.ndarray, height: np.ndarray, prob: np.ndarray,
                     foot_in: np.ndarray, cj: np.ndarray, qvel: np.ndarray,
                     nc: int) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
        """Inequalities ``g y <= h``: friction pyramid per corner, bounds on the next-step
        velocity ``J (qd + qdd dt)`` of joint centres. Rows with an infinite bound are left out."""
        cfg, nv, dt = self.cfg, self.nv, self.cfg.dt
        inf = np.inf
        if cfg.velocity_bounds == "code":
            with np.errstate(divide="ignore"):
                th = -np.log(np.minimum(prob, _FOOT_PROB_CAP - 1e-5) / _FOOT_PROB_CAP)
            th_z = -height[self._feet] / dt  # cannot pass the joint floor within one step
            lo = np.stack([-th, -th, th_z], axis=1)
            hi = np.stack([th, th, np.maximum(th, th_z) + _FOOT_Z_SLACK], axis=1)
            others = cj[~np.isin(cj, self._feet)]
            s, up = cfg.nonfoot_slide_mps, cfg.nonfoot_max_up_mps
            joints = np.concatenate([self._feet, others])
            lo = np.concatenate([lo, np.tile([-s, -s, 0.0], (len(others), 1))])
            hi = np.concatenate([hi, np.tile([s, s, up], (len(others), 1))])
        else:
            s = cfg.sigma_mps
            joints = cj
            lo = np.tile([-s, -s, 0.0], (len(cj), 1))
            hi = np.tile([s, s, inf], (len(cj), 1))
        jv = jp[joints].reshape(-1, nv)  # (3 nb, nv)
        v_now = jv @ qvel
        lo, hi = lo.reshape(-1), hi.reshape(-1)
        up_rows, lo_rows = np.isfinite(hi), np.isfinite(lo)
        n = nv + 3 * nc
        n_fric = 4 * nc
        rows = n_fric + int(up_rows.sum()) + int(lo_rows.sum())
        g = np.zeros((rows, n))
        hb = np.zeros(rows)
        if nc:
            g[:n_fric, nv:] = np.kron(np.eye(nc), self._cone)
        r = n_fric
        k = int(up_rows.sum())
        g[r : r + k, :nv] = dt * jv[up_rows]
        hb[r : r + k] = hi[up_rows] - v_now[up_rows]
        r += k
        g[r:, :nv] = -dt * jv[lo_rows]
        hb[r:] = v_now[lo_rows] - lo[lo_rows]
        return g, hb

    def _solve(self, hess: np.ndarray, lin: np.ndarray, g: np.ndarray, hb: np.ndarray,
               k_mat: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, bool, bool]:  # fmt: skip
        """``(y, failed, retried)``; a failed frame gets ``y = 0`` (``qdd = 0``, no forces)."""

        def ok(y: np.ndarray | None) -> bool:
            if y is None or not np.isfinite(y).all():
                return False
            z = np.concatenate([y, k_mat @ y + h])
            return bool(np.linalg.norm(z) <= self.cfg.max_solution_norm)

        y = _solve_qp(hess, lin, g, hb, self.cfg.solver)
        if ok(y):
            return y, False, False
        if self.fallback_solver is not None:
            self.qp_retries += 1
            y = _solve_qp(hess, lin, g, hb, self.fallback_solver)
            if ok(y):
                return y, False, True
        return np.zeros(hess.shape[0]), True, self.fallback_solver is not None

    def _foot_forces(self, cj: np.ndarray, corners: np.ndarray,
                     lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
        """Per-foot force ``(2, 3)`` N and centre of pressure ``(2, 3)`` m on the floor plane."""
        grf = np.zeros((2, 3))
        cop = np.full((2, 3), np.nan)
        z0 = self.cfg.floor_z_m
        for f, joint in enumerate(sk.FOOT_JOINTS):
            rows = np.flatnonzero(np.repeat(cj == joint, 4))
            if rows.size == 0:
                continue
            fl, p = lam[rows], corners[rows]
            grf[f] = fl.sum(axis=0)
            if grf[f, 2] >= _COP_MIN_FORCE_N:
                # point on z = z0 about which the corner forces have no horizontal moment
                lever = p[:, 2] - z0
                cop[f, 0] = (fl[:, 2] @ p[:, 0] - lever @ fl[:, 0]) / grf[f, 2]
                cop[f, 1] = (fl[:, 2] @ p[:, 1] - lever @ fl[:, 1]) / grf[f, 2]
                cop[f, 2] = z0
        return grf, cop

    # ------------------------------------------------------------------ sequences
    def reconstruct(
        self,
        local_rot: np.ndarray,
        joint_vel: np.ndarray,
        contact_prob: np.ndarray,
        root_pos0: np.ndarray,
        qvel0: np.ndarray | None = None,
        name: str = "pip",
    ) -> Reconstruction:
        """Run the optimiser over a sequence.

        Frame 0 initialises the state with the reference pose at ``root_pos0`` (the ground-truth
        initial state of the GRIP protocol) and outputs that pose unchanged; its forces are the
        QP's at the initial state (the state is not advanced). Frames 1.. are optimised.

        Args:
            local_rot: ``(T, 24, 3, 3)`` reference local rotations (row 0 = root world rotation).
            joint_vel: ``(T, 24, 3)`` reference joint velocities, world, m/s.
            contact_prob: ``(T, 2)`` left, right foot contact probabilities in [0, 1].
            root_pos0: ``(3,)`` initial pelvis position, world, m.
            qvel0: ``(75,)`` initial MuJoCo ``qvel``; ``None``: at rest (PIP).
            name: Recording (segment) name.

        Returns:
            A :class:`Reconstruction` with method ``"pip"``; ``notes`` hold the number of QP
            failures and retries and the mean residual force/torque norms.

        Raises:
            PipInputError: Inputs of the wrong shape or with non-finite values (the message
                names the array and the first bad frame).
        """
        local_rot = np.asarray(local_rot, dtype=np.float64)
        t = local_rot.shape[0] if local_rot.ndim == 4 else -1
        if t < 1:
            raise PipInputError(f"local_rot must have shape (T, 24, 3, 3) with T >= 1, "
                                f"got {local_rot.shape}")  # fmt: skip
        local_rot = _check("local_rot", local_rot, (t, sk.N_JOINTS, 3, 3))
        joint_vel = _check("joint_vel", joint_vel, (t, sk.N_JOINTS, 3))
        prob = self._check_prob(_check("contact_prob", contact_prob, (t, 2)))
        root_pos0 = _check("root_pos0", root_pos0, (3,))
        poses = pose_vector(local_rot, np.zeros((t, 3)))
        poses[0, :3] = root_pos0
        qpos0 = self.model.qpos0.copy()
        write_pose_vector(poses[0], self.index, qpos0)
        self.reset(qpos0, qvel0)
        self.qp_failures = self.qp_retries = self.qp_softened = 0

        out = {k: np.empty((t, *s)) for k, s in (("joint_pos", (sk.N_JOINTS, 3)),
               ("global_rot", (sk.N_JOINTS, 3, 3)), ("grf", (2, 3)), ("cop", (2, 3)),
               ("torques", (self.nv - 6,)), ("residual", (6,)))}  # fmt: skip
        contacts = np.zeros((t, 2), dtype=bool)
        start = time.perf_counter()
        for i in range(t):
            fr = self._advance(poses[i], joint_vel[i], prob[i], integrate=i > 0)
            for k, arr in out.items():
                arr[i] = getattr(fr, k)
            contacts[i] = fr.contacts
        ms = (time.perf_counter() - start) * 1000.0 / t
        notes = {
            "qp_failures": int(self.qp_failures),
            "qp_retries": int(self.qp_retries),
            "qp_softened": int(self.qp_softened),
            "residual_force_mean_n": float(np.linalg.norm(out["residual"][:, :3], axis=1).mean()),
            "residual_torque_mean_nm": float(np.linalg.norm(out["residual"][:, 3:], axis=1).mean()),
            "solver": self.cfg.solver,
            "fallback_solver": self.fallback_solver,
            "joint_floor_m": float(self.joint_floor_z),
            "config": asdict(self.cfg),
        }
        return Reconstruction(name=name, method="pip", fps=float(self.cfg.fps), contacts=contacts,
                              ms_per_frame=ms, notes=notes, **out)  # fmt: skip
