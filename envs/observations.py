"""Observation parts of the tracking task as pure numpy functions (GRIP Sec. 3.3-3.4).

Everything is expressed in the simulated humanoid's *heading frame*: a yaw-only frame at the
pelvis whose x axis points where the body faces (the pelvis' canonical +z axis projected on
the floor), y to its left, z up. World row vectors ``v`` become ``v @ H`` with ``H`` from
:func:`heading_matrix` (``H.T @ v`` for column vectors).

Shapes: J = 24 joints. 6D rotations are the first two matrix columns, ``(c0, c1)``.
"""

from __future__ import annotations

import math

import numpy as np

from grip.core import skeleton as sk

IMU_JOINTS: tuple[int, ...] = (
    sk.IMU_BODY["L_Foot"], sk.IMU_BODY["R_Foot"], sk.IMU_BODY["L_Wrist"], sk.IMU_BODY["R_Wrist"],
)  # fmt: skip
"""Bodies carrying GRIP's four IMUs (ankles, forearms): where D_leaf's rotation terms live."""

SELF_DIM = 1 + 3 * (sk.N_JOINTS - 1) + 6 * sk.N_JOINTS + 3 * sk.N_JOINTS + 3 * sk.N_JOINTS


def kinematic_dim(variant: str) -> int:
    """Length of the state difference for a GRIP Table 4 variant."""
    n = len(IMU_JOINTS) * (6 + 3 + 6)  # d_theta, d_omega, theta_leaf
    if variant != "OA":
        n += 3 * len(sk.VELOCITY_JOINTS)  # d_v
    if variant.startswith("OAV_J"):
        n += 2 * 3 * sk.N_JOINTS  # d_p and p
    return n


_IMU = np.array(IMU_JOINTS)
_VEL = np.array(sk.VELOCITY_JOINTS)
_N_IMU = len(IMU_JOINTS)
_N_SELF_VEC = (sk.N_JOINTS - 1) + 2 * sk.N_JOINTS  # rows of 3-vectors in O^self


def heading_matrix(root_rot: np.ndarray) -> np.ndarray:
    """``(3, 3)`` yaw rotation whose x axis is the pelvis' facing direction on the floor."""
    fx, fy = float(root_rot[0, 2]), float(root_rot[1, 2])  # image of the canonical forward +z
    n = math.hypot(fx, fy)
    c, s = (fx / n, fy / n) if n > 1e-9 else (1.0, 0.0)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def observation_parts(
    variant: str,
    h: np.ndarray,
    sim_pvw: np.ndarray,
    sim_rot: np.ndarray,
    est_pos: np.ndarray,
    est_leaf_rot: np.ndarray,
    est_vel: np.ndarray,
    est_leaf_angvel: np.ndarray,
    est_root_pos: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """O^kin (GRIP's State Difference) and O^self, in the simulated heading frame.

    Both are built together so that every vector is rotated by one matrix product and every
    rotation by another (this runs at every control step).

    Args:
        variant: ``"OA"``, ``"OAV"``, ``"OAV_Jglo"`` or ``"OAV_Jrel"`` (GRIP Table 4), or
            ``"OAV_Jhor"`` (not GRIP's: ``J_rel`` plus the horizontal root error, below).
        h: ``(3, 3)`` heading matrix of the simulated pelvis (:func:`heading_matrix`).
        sim_pvw: ``(3, J, 3)`` simulated world joint positions (m), linear (m/s) and angular
            (rad/s) velocities.
        sim_rot: ``(J, 3, 3)`` simulated global joint rotations.
        est_pos: ``(J, 3)`` estimated joints minus the root (world axes), m.
        est_leaf_rot: ``(4, 3, 3)`` estimated global rotations of :data:`IMU_JOINTS`.
        est_vel: ``(6, 3)`` estimated world velocities of the velocity joints
            (:data:`grip.core.skeleton.VELOCITY_JOINTS`), m/s.
        est_leaf_angvel: ``(4, 3)`` estimated world angular velocities of :data:`IMU_JOINTS`,
            rad/s.
        est_root_pos: ``(3,)`` root integrated from the estimated pelvis velocity (J_glo,
            J_hor), m.

    Returns:
        ``kinematic (kinematic_dim(variant),)`` = [d_theta (4x6): rotation from simulated to
        estimated orientation, theta_leaf (4x6): estimated orientation, d_omega (4x3)] at the
        IMU bodies, then [d_v (6x3)] (not in ``OA``), then [d_p (24x3), p (24x3)] (``J``
        variants; d_p root-relative for ``J_rel``, global via the integrated root for
        ``J_glo``; for ``J_hor`` root-relative, except the pelvis row (always 0 in ``J_rel``),
        which holds the horizontal part of ``est_root_pos - root``: the ground the body has
        lost or gained on the integrated root, without the vertical drift of integrating a
        vertical velocity; p = the estimated root-relative joints);
        ``self (SELF_DIM,)`` = [pelvis height (1), joints 1..23 minus the pelvis (69), linear
        velocities (72), angular velocities (72), rotations 6D (144)].
    """
    pos, vel, w = sim_pvw
    rel = pos - pos[0]
    rows = [rel[1:], vel, w, est_leaf_angvel - w[_IMU]]
    if variant != "OA":
        rows.append(est_vel - vel[_VEL])
    if variant == "OAV_Jrel":
        rows += [est_pos - rel, est_pos]
    elif variant == "OAV_Jglo":
        rows += [(est_root_pos + est_pos) - pos, est_pos]
    elif variant == "OAV_Jhor":
        d_p = est_pos - rel
        d_p[0] = (est_root_pos[0] - pos[0, 0], est_root_pos[1] - pos[0, 1], 0.0)
        rows += [d_p, est_pos]
    vecs = np.concatenate(rows) @ h
    e_leaf = est_leaf_rot
    d_rot = e_leaf @ np.swapaxes(sim_rot[_IMU], -1, -2)
    # Only the first two columns of each rotation are needed (6D). H.T @ R[:, :2] for every R
    # is one (2M x 3) @ (3 x 3) product on the transposed columns; d_theta = H.T d_rot H.
    cols = np.concatenate([sim_rot[..., :2], e_leaf[..., :2], d_rot @ h[:, :2]])
    six = (np.swapaxes(cols, 1, 2).reshape(-1, 3) @ h).reshape(-1, 6)
    n = sk.N_JOINTS
    self_vec = np.concatenate([pos[0, 2:3], vecs[:_N_SELF_VEC].ravel(), six[:n].ravel()])
    kin = np.concatenate([six[n + _N_IMU :].ravel(), six[n : n + _N_IMU].ravel(),
                          vecs[_N_SELF_VEC:].ravel()])  # fmt: skip
    return kin, self_vec
