"""Batched forward kinematics of the body model, numpy only."""

from __future__ import annotations

import numpy as np

from grip.core import skeleton as sk
from grip.core.body import BodyModel


def forward_kinematics(
    local_rot: np.ndarray, root_pos: np.ndarray, offsets: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Global joint rotations and positions.

    Args:
        local_rot: ``(..., 24, 3, 3)`` joint rotations relative to the parent frame; row 0 is the
            root's global rotation.
        root_pos: ``(..., 3)`` pelvis joint position, world frame, m.
        offsets: ``(24, 3)`` rest offsets from :class:`BodyModel` (row 0 is ignored).

    Returns:
        ``global_rot (..., 24, 3, 3)`` and ``joint_pos (..., 24, 3)`` in the world frame.
    """
    local_rot = np.asarray(local_rot, dtype=np.float64)
    root_pos = np.asarray(root_pos, dtype=np.float64)
    if local_rot.shape[-3:] != (sk.N_JOINTS, 3, 3):
        raise ValueError(f"local_rot must have shape (..., 24, 3, 3), got {local_rot.shape}")
    if root_pos.shape != (*local_rot.shape[:-3], 3):
        raise ValueError(
            f"root_pos shape {root_pos.shape} does not match local_rot {local_rot.shape}"
        )
    g_rot = np.empty_like(local_rot)
    g_rot[..., 0, :, :] = local_rot[..., 0, :, :]
    for j in range(1, sk.N_JOINTS):
        g_rot[..., j, :, :] = g_rot[..., sk.PARENTS[j], :, :] @ local_rot[..., j, :, :]
    return g_rot, joints_from_global(g_rot, offsets) + root_pos[..., None, :]


def joints_from_global(global_rot: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Root-relative joint positions of a pose given by its global rotations.

    Args:
        global_rot: ``(..., 24, 3, 3)`` global joint rotations.
        offsets: ``(24, 3)`` rest offsets of the body (row 0 is ignored).

    Returns:
        ``(..., 24, 3)`` joint positions with the root at the origin, world axes, m.
    """
    global_rot = np.asarray(global_rot, dtype=np.float64)
    if global_rot.shape[-3:] != (sk.N_JOINTS, 3, 3):
        raise ValueError(f"global_rot must have shape (..., 24, 3, 3), got {global_rot.shape}")
    pos = np.zeros((*global_rot.shape[:-2], 3), dtype=np.float64)
    for j in range(1, sk.N_JOINTS):
        p = sk.PARENTS[j]
        pos[..., j, :] = pos[..., p, :] + global_rot[..., p, :, :] @ offsets[j]
    return pos


def body_points(
    global_rot: np.ndarray, joint_pos: np.ndarray, bodies: np.ndarray, local_pos: np.ndarray
) -> np.ndarray:
    """World positions of points rigidly attached to bodies.

    Args:
        global_rot: ``(..., 24, 3, 3)`` from :func:`forward_kinematics`.
        joint_pos: ``(..., 24, 3)``.
        bodies: ``(P,)`` body index of each point.
        local_pos: ``(P, 3)`` point in its body's frame, m.

    Returns:
        ``(..., P, 3)`` world positions, m.
    """
    r = global_rot[..., bodies, :, :]
    return joint_pos[..., bodies, :] + np.einsum("...pij,pj->...pi", r, local_pos)


def segment_com(global_rot: np.ndarray, joint_pos: np.ndarray, body: BodyModel) -> np.ndarray:
    """``(..., 24, 3)`` world centre of mass of every segment, m."""
    return body_points(global_rot, joint_pos, np.arange(sk.N_JOINTS), body.com_local)


def center_of_mass(global_rot: np.ndarray, joint_pos: np.ndarray, body: BodyModel) -> np.ndarray:
    """``(..., 3)`` whole-body centre of mass, m."""
    c = segment_com(global_rot, joint_pos, body)
    return np.einsum("...jk,j->...k", c, body.masses) / body.masses.sum()


def sole_points(global_rot: np.ndarray, joint_pos: np.ndarray, body: BodyModel) -> np.ndarray:
    """``(..., 2, 6, 3)`` world positions of the sole corner points of both feet (L, R), m."""
    pts = body_points(global_rot, joint_pos, body.sole_points_body.reshape(-1),
                      body.sole_points_pos.reshape(-1, 3))  # fmt: skip
    return pts.reshape(*pts.shape[:-2], 2, 6, 3)


def grounded_root(global_rot: np.ndarray, root_pos: np.ndarray, body: BodyModel) -> np.ndarray:
    """``root_pos (3,)`` moved vertically so that the pose ``global_rot (24, 3, 3)`` rests its
    lowest sole point on the floor (z = 0), as the standing rest pose does: where a physics
    method starts a pose that no ground truth places (a new ``(3,)`` array)."""
    root = np.array(root_pos, dtype=np.float64).reshape(3)
    joints = joints_from_global(global_rot, body.offsets) + root
    rot = np.asarray(global_rot, dtype=np.float64)
    root[2] -= float(sole_points(rot, joints, body)[..., 2].min())
    return root


def rest_pose(n_frames: int = 1, world: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Identity local rotations; with ``world`` the root stands upright facing +y.

    Returns:
        ``local_rot (T, 24, 3, 3)`` and a zero ``root_pos (T, 3)`` (callers set the height).
    """
    from grip.core.body import CANONICAL_TO_WORLD

    rot = np.broadcast_to(np.eye(3), (n_frames, sk.N_JOINTS, 3, 3)).copy()
    if world:
        rot[:, 0] = CANONICAL_TO_WORLD
    return rot, np.zeros((n_frames, 3))


def integrate_root(root0: np.ndarray, root_vel: np.ndarray, fps: float) -> np.ndarray:
    """Root trajectory from a start position and per-frame world velocities (forward Euler).

    Frame t's position is ``root0`` plus the velocities of frames 0..t-1 over ``fps``: how
    GRIP turns KinematicsNet's pelvis velocity into a global trajectory.

    Args:
        root0: ``(3,)`` position at frame 0, m.
        root_vel: ``(T, 3)`` world velocity per frame, m/s.
        fps: Frame rate, Hz.

    Returns:
        ``(T, 3)`` positions, m.
    """
    root_vel = np.asarray(root_vel, dtype=np.float64)
    pos = np.empty_like(root_vel)
    pos[0] = root0
    np.cumsum(root_vel[:-1] / fps, axis=0, out=pos[1:])
    pos[1:] += root0
    return pos
