"""Helpers of PIP's physics optimiser: the joint-floor height, backward-difference joint
velocities, the QP call and cross-product matrices."""

from __future__ import annotations

import numpy as np
import qpsolvers

from grip.core import skeleton as sk
from grip.core.body import BodyModel
from grip.core.fk import forward_kinematics, rest_pose, sole_points

__all__ = ["backward_velocity", "foot_joint_height"]


def foot_joint_height(body: BodyModel) -> float:
    """Height of the foot joints (SMPL 10/11) above the soles in the rest pose, m.

    The rest pose stands on the floor, so this is the foot joints' height above the lowest sole
    point (:func:`grip.core.fk.sole_points`), averaged over both feet: PIP's "joint floor" lies
    this far above the real floor.
    """
    rot, root = rest_pose(1)
    root[:, 2] = body.pelvis_height
    g_rot, pos = forward_kinematics(rot, root, body.offsets)
    soles = sole_points(g_rot, pos, body)[0]  # (2, 6, 3)
    feet = pos[0, list(sk.FOOT_JOINTS), 2]
    return float(np.mean(feet - soles[..., 2].min(axis=1)))


def backward_velocity(joint_pos: np.ndarray, fps: float) -> np.ndarray:
    """Joint velocities by backward differences, PIP's ground-truth definition.

    ``v_t = (p_t - p_{t-1}) fps``; frame 0 copies frame 1 (zeros for a single frame).

    Args:
        joint_pos: ``(T, J, 3)`` world joint positions, m.
        fps: Frame rate, Hz.

    Returns:
        ``(T, J, 3)`` velocities, m/s.
    """
    p = np.asarray(joint_pos, dtype=np.float64)
    if p.ndim != 3 or p.shape[-1] != 3 or p.shape[0] < 1:
        raise ValueError(f"joint_pos must have shape (T, J, 3), got {p.shape}")
    v = np.zeros_like(p)
    v[1:] = np.diff(p, axis=0) * fps
    if p.shape[0] > 1:
        v[0] = v[1]
    return v


def _solve_qp(
    hess: np.ndarray, lin: np.ndarray, g: np.ndarray, h: np.ndarray, solver: str
) -> np.ndarray | None:
    """``argmin_y 1/2 y^T hess y - lin^T y`` s.t. ``g y <= h``; ``None`` if the solver fails.

    Through ``qpsolvers.solve_qp``: its conversion added 3-4 % to quadprog's solve time on this
    problem (``benchmarks/pip_speed.py`` times both), so calling quadprog directly is not worth
    a second code path.
    """
    if g.shape[0] == 0:  # no inequality (no contact, paper bounds); quadprog needs one
        try:
            return np.linalg.solve(hess, lin)
        except np.linalg.LinAlgError:
            return None
    try:
        return qpsolvers.solve_qp(hess, -lin, g, h, solver=solver)
    except (ValueError, qpsolvers.QPError):
        return None


def _skew(v: np.ndarray) -> np.ndarray:
    """``(..., 3) -> (..., 3, 3)`` cross-product matrices ``[v]_x``."""
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out
