"""SIP-masked pose metrics of PIP/TransPose and the local/global rotation conversions."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from grip.core import skeleton as sk
from grip.core.fk import forward_kinematics
from grip.core.metrics._checks import _as_float, _reduce
from grip.core.metrics.pose import _angle_deg

SIP_MASKED_JOINTS: tuple[int, ...] = (0, 7, 8, 10, 11, 20, 21, 22, 23)
"""Joints whose local rotation is set to identity before the SIP/masked metrics [C-PIP]: root,
ankles, feet, wrists, hands."""

SIP_EVAL_JOINTS: tuple[int, ...] = (1, 2, 16, 17)
"""Joints averaged by the SIP error (hips and shoulders, i.e. upper legs and upper arms)."""


# ------------------------------------------------------------------ SIP / masked pose metrics
def local_to_global_rot(
    local_rot: np.ndarray, parents: Sequence[int] | np.ndarray = sk.PARENTS
) -> np.ndarray:
    """Rotation-only forward kinematics: ``G_j = G_parent(j) @ L_j``, ``G_root = L_root``.

    Args:
        local_rot: ``(..., J, 3, 3)`` parent-relative rotations (row 0: root's global rotation).
        parents: ``(J,)`` parent index of each joint, -1 for the root; parents precede children.

    Returns:
        ``(..., J, 3, 3)`` global rotations.
    """
    local_rot = _as_float(local_rot)
    glob = np.empty_like(local_rot)
    for j, p in enumerate(np.asarray(parents)):
        if p < 0:
            glob[..., j, :, :] = local_rot[..., j, :, :]
        else:
            glob[..., j, :, :] = glob[..., p, :, :] @ local_rot[..., j, :, :]
    return glob


def global_to_local_rot(
    global_rot: np.ndarray, parents: Sequence[int] | np.ndarray = sk.PARENTS
) -> np.ndarray:
    """Inverse of :func:`local_to_global_rot`: ``L_j = G_parent(j)^T @ G_j``.

    Args:
        global_rot: ``(..., J, 3, 3)`` global rotations.
        parents: ``(J,)`` parent index of each joint, -1 for the root.

    Returns:
        ``(..., J, 3, 3)`` parent-relative rotations.
    """
    global_rot = _as_float(global_rot)
    parents = np.asarray(parents)
    local = global_rot.copy()
    has_parent = parents >= 0
    par = global_rot[..., parents[has_parent], :, :]
    local[..., has_parent, :, :] = np.swapaxes(par, -1, -2) @ global_rot[..., has_parent, :, :]
    return local


def _masked_local(
    rot: np.ndarray,
    is_local: bool,
    masked_joints: Sequence[int],
    parents: Sequence[int] | np.ndarray,
) -> np.ndarray:
    """Local rotations with ``masked_joints`` set to identity."""
    local = _as_float(rot).copy() if is_local else global_to_local_rot(rot, parents)
    if local.shape[-2:] != (3, 3):
        raise ValueError(f"expected rotations (..., J, 3, 3), got {local.shape}")
    local[..., list(masked_joints), :, :] = np.eye(3)
    return local


def sip_masked_pose(
    rot: np.ndarray,
    *,
    is_local: bool = False,
    masked_joints: Sequence[int] = SIP_MASKED_JOINTS,
    parents: Sequence[int] | np.ndarray = sk.PARENTS,
) -> np.ndarray:
    """Global rotations after setting the local rotations of ``masked_joints`` to identity.

    This is PIP/TransPose's evaluation preprocessing [C-PIP]: the root orientation, ankles, feet,
    wrists and hands (the joints the sparse IMUs observe directly or cannot observe) are reset in
    the local pose, then the global rotations are recomputed through the kinematic tree.

    Args:
        rot: ``(T, J, 3, 3)`` global rotations, or local ones with ``is_local``.
        is_local: ``rot`` holds parent-relative rotations.
        masked_joints: Joints whose local rotation becomes the identity.
        parents: ``(J,)`` parent of each joint (default :data:`grip.core.skeleton.PARENTS`).

    Returns:
        ``(T, J, 3, 3)`` masked global rotations (root = identity when the root is masked).
    """
    return local_to_global_rot(_masked_local(rot, is_local, masked_joints, parents), parents)


def sip_error(
    pred_rot: np.ndarray,
    gt_rot: np.ndarray,
    *,
    is_local: bool = False,
    per_joint: bool = False,
) -> float | np.ndarray:
    """SIP error, deg: mean global angle error of joints 1, 2, 16, 17 after SIP masking.

    Both poses go through :func:`sip_masked_pose` (local rotations of joints
    0, 7, 8, 10, 11, 20, 21, 22, 23 set to identity, global rotations recomputed), then
    ``mean_{t, j in (1, 2, 16, 17)} angle(R_hat_tj^T R_tj)`` [C-PIP].

    Args:
        pred_rot: ``(T, 24, 3, 3)`` predicted rotations (global; local with ``is_local``).
        gt_rot: ``(T, 24, 3, 3)`` ground-truth rotations, same convention.
        is_local: Inputs are parent-relative rotations.
        per_joint: Return the ``(4,)`` means of joints (1, 2, 16, 17).

    Returns:
        The error in deg (float or ``(4,)``).
    """
    p = sip_masked_pose(pred_rot, is_local=is_local)[..., list(SIP_EVAL_JOINTS), :, :]
    g = sip_masked_pose(gt_rot, is_local=is_local)[..., list(SIP_EVAL_JOINTS), :, :]
    return _reduce(_angle_deg(p, g, "sip_error"), per_joint)


def angular_error_masked(
    pred_rot: np.ndarray,
    gt_rot: np.ndarray,
    *,
    is_local: bool = False,
    per_joint: bool = False,
) -> float | np.ndarray:
    """PIP/TransPose "angular error", deg: SIP masking, then the global angle over all joints.

    Args:
        pred_rot: ``(T, 24, 3, 3)`` predicted rotations (global; local with ``is_local``).
        gt_rot: ``(T, 24, 3, 3)`` ground-truth rotations, same convention.
        is_local: Inputs are parent-relative rotations.
        per_joint: Return ``(24,)`` per-joint means (masked joints whose whole chain is masked
            are 0 by construction).

    Returns:
        The error in deg (float or ``(24,)``).
    """
    p = sip_masked_pose(pred_rot, is_local=is_local)
    g = sip_masked_pose(gt_rot, is_local=is_local)
    return _reduce(_angle_deg(p, g, "angular_error_masked"), per_joint)


def sip_masked_joint_positions(
    rot: np.ndarray, offsets: np.ndarray, *, is_local: bool = False
) -> np.ndarray:
    """Joint positions of the SIP-masked pose with the root at the origin, m.

    Args:
        rot: ``(T, 24, 3, 3)`` rotations (global; local with ``is_local``).
        offsets: ``(24, 3)`` rest offsets (:attr:`BodyModel.offsets`; PIP uses the SMPL mean shape).
        is_local: ``rot`` holds parent-relative rotations.

    Returns:
        ``(T, 24, 3)`` positions in the masked root's frame (no translation), m. Feed to
        :func:`jitter` for "Jitter (rel.)".
    """
    local = _masked_local(rot, is_local, SIP_MASKED_JOINTS, sk.PARENTS)
    _, pos = forward_kinematics(local, np.zeros((*local.shape[:-3], 3)), offsets)
    return pos


def position_error_masked(
    pred_rot: np.ndarray,
    gt_rot: np.ndarray,
    offsets: np.ndarray,
    *,
    is_local: bool = False,
    per_joint: bool = False,
) -> float | np.ndarray:
    """PIP/TransPose "positional error", cm: SIP masking, no translation, root at the origin.

    ``mean_{t,j} |p_hat_tj - p_tj| * 100`` on :func:`sip_masked_joint_positions` of both poses
    (same ``offsets``), all 24 joints.

    Returns:
        The error in cm (float or ``(24,)``).
    """
    p = sip_masked_joint_positions(pred_rot, offsets, is_local=is_local)
    g = sip_masked_joint_positions(gt_rot, offsets, is_local=is_local)
    return _reduce(np.linalg.norm(p - g, axis=-1) * 100.0, per_joint)
