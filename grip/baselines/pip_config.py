"""Settings, input checks and per-frame output of PIP's physics optimiser
(:class:`grip.baselines.pip_physics.PipPhysics`; the flags are described there)."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from grip.core import skeleton as sk

__all__ = [
    "CONTACT_CANDIDATES",
    "PD_JOINTS_CODE",
    "SOLVERS",
    "PipConfig",
    "PipFrame",
    "PipInputError",
]

PD_JOINTS_CODE: tuple[int, ...] = tuple(j for j in range(22) if j not in sk.FOOT_JOINTS)
"""Joints with a position-PD row in PIP's code: SMPL 0-9 and 12-21 (no feet, no hands)."""

CONTACT_CANDIDATES: tuple[int, ...] = (1, 2, 3, 4, 5, 6, 9, 15, 16, 17, 18, 19, 22, 23)
"""Non-foot joints that may touch the ground in PIP's code: hips, spine1-3, knees, head,
shoulders, elbows, hands. The foot joints :data:`grip.core.skeleton.FOOT_JOINTS` come on top."""

SOLVERS: tuple[str, ...] = ("quadprog", "daqp")
"""Supported QP solvers (both exact dense active-set methods; section 1.6)."""

SOFTEN_FACTORS: tuple[float, ...] = (0.1, 0.01)
"""PD scalings of :attr:`PipConfig.soften_on_failure`'s retries, in order."""

_ENUMS = {
    "friction": ("inner", "outer"),
    "velocity_bounds": ("code", "paper"),
    "integrator": ("semi_implicit", "explicit"),
    "pd_joints": ("code", "all"),
    "weight_form": ("code", "paper"),
    "contact_rule": ("code", "paper"),
    "on_failure": ("stop", "coast"),
    "solver": SOLVERS,
}


class PipInputError(ValueError):
    """An input of the optimiser has the wrong shape or non-finite / out-of-range values."""


@dataclass(frozen=True)
class PipConfig:
    """Settings of the PIP optimiser; defaults are PIP's code converted to 100 Hz (section 1.8).

    Attributes:
        fps: Frame rate of inputs and outputs, Hz (the step is ``1 / fps``).
        kp_theta: Rotation-PD stiffness, 1/s^2 (PIP: 2400 at 60 Hz = (2/3) fps^2).
        kd_theta: Rotation-PD damping, 1/s (fps).
        kp_r: Position-PD stiffness, 1/s^2 (fps^2).
        kd_r: Position-PD damping, 1/s (fps).
        w_theta: Weight of the rotation-PD term.
        w_r: Weight of the position-PD term.
        w_signorini: Weight of the Signorini term (contact force times contact height).
        signorini_min_height_m: Contact heights below this count as this, m.
        w_residual: Weight of the residual root wrench ``tau[:6]``.
        w_torque: Weight of the joint torques ``tau[6:]``.
        weight_form: ``"code"``: each weight multiplies the residual inside the squared norm
            (``(w |x|)^2``); ``"paper"``: it multiplies the squared norm (``w |x|^2``).
        mu: Friction coefficient.
        friction: ``"inner"`` pyramid ``|lambda_x|, |lambda_y| <= mu / sqrt(2) lambda_z`` (code)
            or ``"outer"`` ``<= mu lambda_z`` (paper).
        velocity_bounds: ``"code"`` or ``"paper"`` next-step velocity bounds
            (:mod:`grip.baselines.pip_physics`).
        sigma_mps: Paper's sliding bound of contact joints, m/s.
        nonfoot_slide_mps: Code's horizontal speed bound of non-foot contact joints, m/s.
        nonfoot_max_up_mps: Code's upward speed bound of non-foot contact joints, m/s.
        integrator: ``"semi_implicit"`` (code) or ``"explicit"`` (paper eq. 13).
        pd_joints: ``"code"`` (:data:`PD_JOINTS_CODE`) or ``"all"`` 24 joints (paper).
        contact_rule: ``"code"`` or ``"paper"`` contact tests (:mod:`grip.baselines.pip_physics`).
        foot_contact_height_m: A foot with contact probability > 0.5 this close to the joint
            floor is in contact, m.
        touch_height_m: Paper rule: any candidate this close to the joint floor is in contact, m.
        contact_square_m: Side of the contact square around each contact joint, m.
        floor_z_m: Height of the (flat) floor, m.
        solver: ``"quadprog"`` or ``"daqp"``.
        fallback_solver: Solver of the retry after a failure: ``"auto"`` (the other one),
            a name from :data:`SOLVERS`, or ``None`` (no retry).
        max_solution_norm: A solution ``[qdd, lambda, tau]`` with a larger norm counts as a
            failure (PIP code: 1e4).
        regularization: Added to the QP's Hessian diagonal (quadprog needs strict convexity).
        on_failure: What a frame whose QP failed does (``qdd = 0`` either way): ``"stop"``
            also zeroes the velocity (the body halts, and the next QP starts from rest);
            ``"coast"`` keeps it. Coasting never recovers once the failures chain: without
            gravity or contact forces a body dropping onto the floor keeps its speed and
            sinks through it (a lie-down segment: 323 of 500 frames failed, 1.9 m under
            the floor), while from rest the QP is feasible again.
        soften_on_failure: Before a frame counts as failed, retry its QP with both PD terms
            scaled by each of :data:`SOFTEN_FACTORS` (not in PIP). A reference far from the
            state (a start that no ground truth places: the estimate snaps from the standing
            calibration to the motion in its first frames) asks for accelerations beyond
            ``max_solution_norm``; with ``"stop"`` the body then halts, the next QP asks the
            same, and every later frame fails (a walk started standing: 499 of 499). A softer
            PD moves the body toward the reference until the full one is feasible again.
    """

    fps: float = 100.0
    kp_theta: float = 6667.0
    kd_theta: float = 100.0
    kp_r: float = 10000.0
    kd_r: float = 100.0
    w_theta: float = 1.0
    w_r: float = 1.0
    w_signorini: float = 10.0
    signorini_min_height_m: float = 0.005
    w_residual: float = 0.1
    w_torque: float = 0.01
    weight_form: str = "code"
    mu: float = 0.6
    friction: str = "inner"
    velocity_bounds: str = "code"
    sigma_mps: float = 0.01
    nonfoot_slide_mps: float = 0.1
    nonfoot_max_up_mps: float = 100.0
    integrator: str = "semi_implicit"
    pd_joints: str = "code"
    contact_rule: str = "code"
    foot_contact_height_m: float = 0.03
    touch_height_m: float = 0.005
    contact_square_m: float = 0.20
    floor_z_m: float = 0.0
    solver: str = "quadprog"
    fallback_solver: str | None = "auto"
    max_solution_norm: float = 1e4
    regularization: float = 1e-8
    on_failure: str = "stop"
    soften_on_failure: bool = True

    def __post_init__(self) -> None:
        for name, allowed in _ENUMS.items():
            value = getattr(self, name)
            if value not in allowed:
                raise ValueError(f"PipConfig.{name}={value!r}: use one of {list(allowed)}")
        if self.fallback_solver not in (None, "auto", *SOLVERS):
            raise ValueError(f"PipConfig.fallback_solver={self.fallback_solver!r}: use None, "
                             f"'auto' or one of {list(SOLVERS)}")  # fmt: skip
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, float) and not math.isfinite(value):
                raise ValueError(f"PipConfig.{f.name}={value!r} must be finite")
        positive = ("fps", "signorini_min_height_m", "mu", "sigma_mps", "contact_square_m",
                    "max_solution_norm", "nonfoot_slide_mps", "nonfoot_max_up_mps")  # fmt: skip
        for name in positive:
            if not getattr(self, name) > 0.0:
                raise ValueError(f"PipConfig.{name}={getattr(self, name)!r} must be > 0")
        non_negative = ("kp_theta", "kd_theta", "kp_r", "kd_r", "w_theta", "w_r",
                        "w_signorini", "w_residual", "w_torque", "regularization",
                        "foot_contact_height_m", "touch_height_m")  # fmt: skip
        for name in non_negative:
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"PipConfig.{name}={getattr(self, name)!r} must be >= 0")

    @classmethod
    def at_rate(cls, fps: float, alpha: float = 2.0 / 3.0, **overrides) -> PipConfig:
        """PIP's gain derivation at another frame rate (supplement, eq. 15).

        ``kp = 1 / dt^2`` and ``kd = 1 / dt`` make one step close the error; the rotation gain
        is lowered to ``alpha / dt^2`` for smoother angular accelerations (PIP: alpha = 2/3).

        Args:
            fps: Frame rate, Hz.
            alpha: Fraction of the full rotation stiffness.
            **overrides: Other :class:`PipConfig` fields.
        """
        return cls(fps=fps, kp_theta=alpha * fps**2, kd_theta=fps, kp_r=fps**2, kd_r=fps,
                   **overrides)  # fmt: skip

    @property
    def dt(self) -> float:
        """Time step, s."""
        return 1.0 / self.fps


@dataclass(frozen=True)
class PipFrame:
    """The optimiser's output for one frame (the state after the update).

    Attributes:
        qpos: ``(76,)`` MuJoCo ``qpos`` (root position m, root quaternion wxyz, hinges rad).
        qvel: ``(75,)`` MuJoCo ``qvel`` (root linear velocity world m/s, root angular velocity
            in the root frame rad/s, hinge rates rad/s).
        joint_pos: ``(24, 3)`` world joint positions (SMPL order), m.
        global_rot: ``(24, 3, 3)`` world joint rotations.
        grf: ``(2, 3)`` ground reaction force on the left, right foot (world), N.
        cop: ``(2, 3)`` centre of pressure of each foot on the floor plane (world), m; NaN where
            the foot's vertical force is below 1 N.
        torques: ``(69,)`` joint torques, N m, :func:`grip.core.mjcf.hinge_names` order.
        contacts: ``(2,)`` left, right foot joint in the contact set.
        residual: ``(6,)`` residual root force (N, world) and torque (N m, root frame).
        qp_failed: The QP failed (after the retry); the frame used ``qdd = 0``.
        qp_retried: The first solver failed and the fallback solver was used.
    """

    qpos: np.ndarray
    qvel: np.ndarray
    joint_pos: np.ndarray
    global_rot: np.ndarray
    grf: np.ndarray
    cop: np.ndarray
    torques: np.ndarray
    contacts: np.ndarray
    residual: np.ndarray
    qp_failed: bool
    qp_retried: bool


def _check(name: str, a, shape: tuple[int, ...]) -> np.ndarray:
    """``a`` as float64 of ``shape`` with finite values, else :class:`PipInputError` naming
    ``name`` and the first bad index along the first axis (the frame of a sequence)."""
    a = np.asarray(a, dtype=np.float64)
    if a.shape != shape:
        raise PipInputError(f"{name} has shape {a.shape}, expected {shape}")
    if not np.isfinite(a).all():
        lead = a.reshape(shape[0], -1) if len(shape) > 1 else a.reshape(-1, 1)
        bad = int(np.argwhere(~np.isfinite(lead).all(axis=1))[0, 0])
        raise PipInputError(f"{name} has non-finite values (first at index {bad})")
    return a
