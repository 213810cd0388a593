"""Evaluation metrics of BASELINES_AND_METRICS.md section 4.2 as pure numpy functions.

Conventions: world frame z-up with the floor at ``z = 0``; positions in m, rotations as
``(..., 3, 3)`` matrices acting on column vectors; ``T`` frames, ``J`` joints (24 SMPL joints in
SMPL order unless stated). Each function returns the unit given in its docstring (mm for position
errors, deg for angles, SI otherwise).

Protocol (section 4.1): every metric is computed per 500-frame segment (values averaged over the
frames and joints of the segment), then :func:`summarize` averages the segment values.

Not implemented here: "Mesh err" (needs the 6,890-vertex SMPL mesh, which the project does not
ship); foot penetration is measured on the body model's sole corner points instead of SMPL foot
vertices (:func:`grip.core.fk.sole_points`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import signal

from grip.core import skeleton as sk
from grip.core.body import GRAVITY, BodyModel
from grip.core.fk import forward_kinematics, segment_com
from grip.core.rotations import angular_velocity

__all__ = [
    "SIP_EVAL_JOINTS",
    "SIP_MASKED_JOINTS",
    "TranslationErrorCurve",
    "acceleration_error",
    "angular_error_masked",
    "contacts_from_motion",
    "cumulative_translation_error",
    "foot_penetration",
    "foot_sliding",
    "global_to_local_rot",
    "jitter",
    "local_to_global_rot",
    "mpjpe",
    "mpjre",
    "mpjre_local",
    "net_external_wrench",
    "pa_mpjpe",
    "pel_mpjpe",
    "position_error_masked",
    "procrustes",
    "procrustes_align",
    "sip_error",
    "sip_masked_joint_positions",
    "sip_masked_pose",
    "success_rate",
    "summarize",
    "translation_error_by_distance",
    "translation_error_by_time",
    "vgrf_error",
    "zero_moment_point",
    "zmp_distance",
    "zmp_distances",
]

SIP_MASKED_JOINTS: tuple[int, ...] = (0, 7, 8, 10, 11, 20, 21, 22, 23)
"""Joints whose local rotation is set to identity before the SIP/masked metrics [C-PIP]: root,
ankles, feet, wrists, hands."""

SIP_EVAL_JOINTS: tuple[int, ...] = (1, 2, 16, 17)
"""Joints averaged by the SIP error (hips and shoulders, i.e. upper legs and upper arms)."""

_G_WORLD = np.array([0.0, 0.0, -GRAVITY])
_MM = 1000.0


# ------------------------------------------------------------------------------------ helpers
def _as_float(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=np.float64)


def _check_pair(pred: np.ndarray, gt: np.ndarray, tail: tuple[int, ...], what: str) -> None:
    if pred.shape != gt.shape:
        raise ValueError(f"{what}: prediction {pred.shape} and ground truth {gt.shape} differ")
    if pred.ndim < len(tail) + 1 or pred.shape[-len(tail) :] != tail:
        raise ValueError(f"{what}: expected shape (..., J, {', '.join(map(str, tail))}), "
                         f"got {pred.shape}")  # fmt: skip


def _reduce(err: np.ndarray, per_joint: bool) -> float | np.ndarray:
    """Mean of ``(..., J)`` values over everything, or over everything but ``J``."""
    if per_joint:
        return err.reshape(-1, err.shape[-1]).mean(axis=0)
    return float(err.mean())


def _require_frames(x: np.ndarray, n: int, what: str) -> None:
    if x.shape[0] < n:
        raise ValueError(f"{what} needs at least {n} frames, got {x.shape[0]}")


# ----------------------------------------------------------------------------- positions
def mpjpe(pred_pos: np.ndarray, gt_pos: np.ndarray, per_joint: bool = False) -> float | np.ndarray:
    """Mean per-joint position error, mm.

    ``mean_{t,j} |p_hat_tj - p_tj| * 1000`` in the world frame, with no alignment (both
    sequences share the ground-truth start of the segment).

    Args:
        pred_pos: ``(T, J, 3)`` predicted joint positions, world frame, m (any leading shape).
        gt_pos: ``(T, J, 3)`` ground-truth joint positions, world frame, m.
        per_joint: Return the ``(J,)`` per-joint means instead of the overall mean.

    Returns:
        The error in mm: a float, or ``(J,)`` with ``per_joint``.
    """
    pred_pos, gt_pos = _as_float(pred_pos), _as_float(gt_pos)
    _check_pair(pred_pos, gt_pos, (3,), "mpjpe")
    return _reduce(np.linalg.norm(pred_pos - gt_pos, axis=-1) * _MM, per_joint)


def pel_mpjpe(
    pred_pos: np.ndarray, gt_pos: np.ndarray, per_joint: bool = False, root: int = 0
) -> float | np.ndarray:
    """Pelvis-relative MPJPE, mm.

    Each frame's ``root`` joint (the pelvis, joint 0) is subtracted from all joints of that frame,
    in the prediction and in the ground truth separately; rotation is kept (no alignment).

    Args:
        pred_pos: ``(T, J, 3)`` predicted joint positions, m.
        gt_pos: ``(T, J, 3)`` ground-truth joint positions, m.
        per_joint: Return ``(J,)`` per-joint means.
        root: Index of the joint subtracted.

    Returns:
        The error in mm (float or ``(J,)``).
    """
    pred_pos, gt_pos = _as_float(pred_pos), _as_float(gt_pos)
    _check_pair(pred_pos, gt_pos, (3,), "pel_mpjpe")
    pred_rel = pred_pos - pred_pos[..., root : root + 1, :]
    gt_rel = gt_pos - gt_pos[..., root : root + 1, :]
    return mpjpe(pred_rel, gt_rel, per_joint)


def procrustes(
    pred_pos: np.ndarray, gt_pos: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-frame similarity transform mapping the prediction onto the ground truth (Umeyama).

    For each frame, with centroids ``mu_p, mu_g`` and centred point sets ``X = p_hat - mu_p``,
    ``Y = p - mu_g``: cross-covariance ``C = Y^T X / J`` with SVD ``C = U diag(sigma) V^T``,
    ``S = diag(1, 1, sign det(U V^T))`` (``sign 0 := +1``), ``R = U S V^T`` (a proper rotation,
    never a reflection), ``s = tr(diag(sigma) S) / var(p_hat)`` with
    ``var(p_hat) = mean_j |X_j|^2``, and ``t = mu_g - s R mu_p``.

    Args:
        pred_pos: ``(..., J, 3)`` predicted points.
        gt_pos: ``(..., J, 3)`` target points.

    Returns:
        ``scale (...)``, ``rot (..., 3, 3)`` and ``trans (..., 3)`` such that
        ``s * R @ p_hat + t`` best matches ``p`` in the least-squares sense.
    """
    pred_pos, gt_pos = _as_float(pred_pos), _as_float(gt_pos)
    _check_pair(pred_pos, gt_pos, (3,), "procrustes")
    mu_p = pred_pos.mean(axis=-2)
    mu_g = gt_pos.mean(axis=-2)
    x = pred_pos - mu_p[..., None, :]
    y = gt_pos - mu_g[..., None, :]
    cov = np.einsum("...ji,...jk->...ik", y, x) / pred_pos.shape[-2]
    u, sigma, vt = np.linalg.svd(cov)
    d = np.where(np.linalg.det(u @ vt) < 0.0, -1.0, 1.0)
    s_diag = np.stack([np.ones_like(d), np.ones_like(d), d], axis=-1)
    rot = (u * s_diag[..., None, :]) @ vt
    var_p = np.mean(np.sum(x * x, axis=-1), axis=-1)
    scale = np.sum(sigma * s_diag, axis=-1) / np.maximum(var_p, 1e-300)
    trans = mu_g - scale[..., None] * np.einsum("...ij,...j->...i", rot, mu_p)
    return scale, rot, trans


def procrustes_align(pred_pos: np.ndarray, gt_pos: np.ndarray) -> np.ndarray:
    """``(..., J, 3)`` prediction after the per-frame similarity alignment of :func:`procrustes`."""
    scale, rot, trans = procrustes(pred_pos, gt_pos)
    rotated = np.einsum("...ik,...jk->...ji", rot, _as_float(pred_pos))
    return scale[..., None, None] * rotated + trans[..., None, :]


def pa_mpjpe(
    pred_pos: np.ndarray, gt_pos: np.ndarray, per_joint: bool = False
) -> float | np.ndarray:
    """Procrustes-aligned MPJPE, mm: :func:`mpjpe` after :func:`procrustes_align` per frame.

    Args:
        pred_pos: ``(T, J, 3)`` predicted joint positions, m.
        gt_pos: ``(T, J, 3)`` ground-truth joint positions, m.
        per_joint: Return ``(J,)`` per-joint means.

    Returns:
        The error in mm (float or ``(J,)``).
    """
    return mpjpe(procrustes_align(pred_pos, gt_pos), gt_pos, per_joint)


# ----------------------------------------------------------------------------- rotations
def _angle_deg(pred_rot: np.ndarray, gt_rot: np.ndarray, what: str) -> np.ndarray:
    """Geodesic angle of ``pred^T gt`` in deg, in [0, 180].

    ``atan2(|vee(A - A^T)| / 2, (tr A - 1) / 2)`` equals ``arccos((tr A - 1) / 2)`` (as in
    :func:`rotations.geodesic_angle`) but stays accurate near 0 deg, where the arccos form has a
    ~1e-6 deg floor that would make identical poses report a nonzero error.
    """
    pred_rot, gt_rot = _as_float(pred_rot), _as_float(gt_rot)
    _check_pair(pred_rot, gt_rot, (3, 3), what)
    rel = np.swapaxes(pred_rot, -1, -2) @ gt_rot
    vee = np.stack(
        [rel[..., 2, 1] - rel[..., 1, 2], rel[..., 0, 2] - rel[..., 2, 0],
         rel[..., 1, 0] - rel[..., 0, 1]], axis=-1,
    )  # fmt: skip
    cos = 0.5 * (np.trace(rel, axis1=-2, axis2=-1) - 1.0)
    return np.rad2deg(np.arctan2(0.5 * np.linalg.norm(vee, axis=-1), cos))


def mpjre(pred_rot: np.ndarray, gt_rot: np.ndarray, per_joint: bool = False) -> float | np.ndarray:
    """Mean per-joint rotation error of **global** joint rotations, deg.

    ``mean_{t,j} |log(R_hat_tj^T R_tj)|`` (geodesic angle in [0, 180]), PIP/TransPose's
    "angular error" without masking [D].

    Args:
        pred_rot: ``(T, J, 3, 3)`` predicted global joint rotations.
        gt_rot: ``(T, J, 3, 3)`` ground-truth global joint rotations.
        per_joint: Return ``(J,)`` per-joint means.

    Returns:
        The error in deg (float or ``(J,)``).
    """
    return _reduce(_angle_deg(pred_rot, gt_rot, "mpjre"), per_joint)


def mpjre_local(
    pred_local: np.ndarray, gt_local: np.ndarray, per_joint: bool = False
) -> float | np.ndarray:
    """Mean per-joint rotation error of **local** (parent-relative) rotations, deg.

    Same geodesic angle as :func:`mpjre`, on ``(T, J, 3, 3)`` local rotations (row 0 is the root's
    global rotation). Logged as the local-rotation variant of section 4.2.
    """
    return _reduce(_angle_deg(pred_local, gt_local, "mpjre_local"), per_joint)


# ------------------------------------------------------------------------------ dynamics
def acceleration_error(
    pred_pos: np.ndarray, gt_pos: np.ndarray, fps: float, per_joint: bool = False
) -> float | np.ndarray:
    """Acceleration error, m/s^2.

    ``mean_{t,j} |a_hat_tj - a_tj|`` with ``a_t = (p_{t+1} - 2 p_t + p_{t-1}) fps^2`` in the world
    frame, over the ``T - 2`` interior frames.

    Args:
        pred_pos: ``(T, J, 3)`` predicted joint positions, m.
        gt_pos: ``(T, J, 3)`` ground-truth joint positions, m.
        fps: Frame rate, Hz.
        per_joint: Return ``(J,)`` per-joint means.

    Returns:
        The error in m/s^2 (float or ``(J,)``).
    """
    pred_pos, gt_pos = _as_float(pred_pos), _as_float(gt_pos)
    _check_pair(pred_pos, gt_pos, (3,), "acceleration_error")
    _require_frames(pred_pos, 3, "acceleration_error")
    d = pred_pos - gt_pos
    acc = (d[2:] - 2.0 * d[1:-1] + d[:-2]) * fps**2
    return _reduce(np.linalg.norm(acc, axis=-1), per_joint)


def jitter(pos: np.ndarray, fps: float, per_joint: bool = False) -> float | np.ndarray:
    """Jitter (mean jerk magnitude) of one motion, m/s^3.

    ``mean_{t,j} |p_{t+3} - 3 p_{t+2} + 3 p_{t+1} - p_t| fps^3`` over the ``T - 3`` windows.
    Reporting units differ between papers: PIP prints km/s^3 (divide by 1000) and TransPose
    10^2 m/s^3 (divide by 100). "Jitter (rel.)" is this function on
    :func:`sip_masked_joint_positions` (masked pose, no translation); "Abs. jitter" on the full
    world joint positions.

    Args:
        pos: ``(T, J, 3)`` joint positions, m.
        fps: Frame rate, Hz.
        per_joint: Return ``(J,)`` per-joint means.

    Returns:
        The jitter in m/s^3 (float or ``(J,)``).
    """
    pos = _as_float(pos)
    if pos.ndim < 2 or pos.shape[-1] != 3:
        raise ValueError(f"jitter: expected (T, J, 3), got {pos.shape}")
    _require_frames(pos, 4, "jitter")
    jerk = (pos[3:] - 3.0 * pos[2:-1] + 3.0 * pos[1:-2] - pos[:-3]) * fps**3
    return _reduce(np.linalg.norm(jerk, axis=-1), per_joint)


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


# ------------------------------------------------------------------------------ feet
def _foot_track(foot_pos: np.ndarray, what: str) -> np.ndarray:
    """``(T, 2, 3)`` foot-joint positions from ``(T, 2, 3)`` or a full ``(T, 24, 3)`` pose."""
    foot_pos = _as_float(foot_pos)
    if foot_pos.ndim != 3 or foot_pos.shape[-1] != 3:
        raise ValueError(f"{what}: expected (T, 2, 3) or (T, 24, 3), got {foot_pos.shape}")
    if foot_pos.shape[1] == sk.N_JOINTS:
        return foot_pos[:, list(sk.FOOT_JOINTS)]
    if foot_pos.shape[1] != 2:
        raise ValueError(f"{what}: expected (T, 2, 3) or (T, 24, 3), got {foot_pos.shape}")
    return foot_pos


def foot_sliding(pred_foot_pos: np.ndarray, gt_contact: np.ndarray, fps: float) -> float:
    """Foot sliding (skating), m/s.

    Horizontal speed ``|(p_hat_{t+1} - p_hat_t)_xy| * fps`` of the predicted SMPL foot joints
    10/11, averaged over the frames ``t`` (``0 <= t < T - 1``) where the **ground-truth** foot is
    in contact; both feet are pooled (each (frame, foot) pair with contact counts once) [D].

    Args:
        pred_foot_pos: ``(T, 2, 3)`` predicted foot-joint positions (L, R), world, m; a full
            ``(T, 24, 3)`` pose is also accepted (joints :data:`skeleton.FOOT_JOINTS` are taken).
        gt_contact: ``(T, 2)`` bool ground-truth contact (insole fore or rear, else
            :func:`contacts_from_motion` of the ground truth).
        fps: Frame rate, Hz.

    Returns:
        The mean speed in m/s; NaN when the ground truth has no contact in frames ``0..T-2``.
    """
    p = _foot_track(pred_foot_pos, "foot_sliding")
    contact = np.asarray(gt_contact, dtype=bool)
    if contact.shape != p.shape[:2]:
        raise ValueError(f"foot_sliding: contact {contact.shape} does not match feet {p.shape}")
    _require_frames(p, 2, "foot_sliding")
    speed = np.linalg.norm(np.diff(p[..., :2], axis=0), axis=-1) * fps  # (T-1, 2)
    mask = contact[:-1]
    if not mask.any():
        return float("nan")
    return float(speed[mask].mean())


def contacts_from_motion(foot_pos: np.ndarray, fps: float, speed_mps: float = 0.48) -> np.ndarray:
    """Foot contact labels from motion alone (TransPose rule), for data without insoles.

    A foot is in contact at frame ``t >= 1`` when its 3D displacement since frame ``t - 1`` is
    below ``speed_mps / fps`` (TransPose: 0.008 m per frame at 60 Hz = 0.48 m/s, i.e.
    0.0048 m per frame at 100 Hz). Frame 0 copies frame 1.

    Args:
        foot_pos: ``(T, F, 3)`` foot-joint positions (e.g. ``pos[:, FOOT_JOINTS]``), m.
        fps: Frame rate, Hz.
        speed_mps: Speed threshold, m/s.

    Returns:
        ``(T, F)`` bool.
    """
    foot_pos = _as_float(foot_pos)
    _require_frames(foot_pos, 2, "contacts_from_motion")
    step = np.linalg.norm(np.diff(foot_pos, axis=0), axis=-1)
    contact = step < speed_mps / fps
    return np.concatenate([contact[:1], contact], axis=0)


def foot_penetration(
    sole_pts: np.ndarray,
    floor_height: float | Callable[[np.ndarray], np.ndarray] = 0.0,
) -> float:
    """Foot-floor penetration, mm.

    Per frame and foot, the depth of the deepest sole point below the surface under it,
    ``max(0, max_v (h(x_v, y_v) - z_v))`` (for a flat floor ``max(0, h - min_v z_v)``), times
    1000, averaged over all frames and both feet (frames without penetration count as 0).

    Args:
        sole_pts: ``(T, 2, P, 3)`` world sole points per foot (e.g. :func:`fk.sole_points`), m.
        floor_height: Floor height, m: a scalar, or a height map ``f(xy (..., 2)) -> z (...)``
            evaluated under each point.

    Returns:
        The mean penetration in mm.
    """
    sole_pts = _as_float(sole_pts)
    if sole_pts.ndim != 4 or sole_pts.shape[-1] != 3:
        raise ValueError(f"foot_penetration: expected (T, 2, P, 3), got {sole_pts.shape}")
    if callable(floor_height):
        h = _as_float(floor_height(sole_pts[..., :2]))
        if h.shape != sole_pts.shape[:-1]:
            raise ValueError(f"floor_height returned {h.shape}, expected {sole_pts.shape[:-1]}")
    else:
        h = float(floor_height)
    depth = np.max(h - sole_pts[..., 2], axis=-1)  # (T, 2)
    return float(np.maximum(depth, 0.0).mean() * _MM)


def vgrf_error(pred_force_n: np.ndarray, gt_force_n: np.ndarray) -> float:
    """Vertical ground-reaction-force error, N: ``mean_{t,foot} |F_hat_z - F_z^insole|``.

    Args:
        pred_force_n: ``(T, 2)`` predicted vertical force per foot (L, R), N.
        gt_force_n: ``(T, 2)`` insole vertical force per foot, N.

    Returns:
        The mean absolute error in N over the frames whose prediction is finite (a method may
        have no forces on some frames, e.g. GRIP's fall recovery replaces the frames of a fall
        by the kinematic estimate); NaN if no frame has one.
    """
    p, g = _as_float(pred_force_n), _as_float(gt_force_n)
    if p.shape != g.shape or p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"vgrf_error: expected two (T, 2) arrays, got {p.shape} and {g.shape}")
    ok = np.isfinite(p).all(axis=1)
    if not ok.any():
        return float("nan")
    return float(np.abs(p[ok] - g[ok]).mean())


# ------------------------------------------------------------------------------ success
def success_rate(fell: Sequence[bool] | np.ndarray) -> float:
    """Success rate, %: segments in which the fall detector never fired / all segments.

    Args:
        fell: One flag per segment, True if the fall detector (section 5.4) fired at least once.

    Returns:
        ``100 * (1 - mean(fell))``; the fall rate is ``100 - success_rate``.
    """
    fell = np.asarray(fell, dtype=bool).reshape(-1)
    if fell.size == 0:
        raise ValueError("success_rate needs at least one segment")
    return float(100.0 * (1.0 - fell.mean()))


# ------------------------------------------------------------------------- translation
@dataclass(frozen=True)
class TranslationErrorCurve:
    """A cumulative translation error curve.

    Attributes:
        x: ``(K,)`` abscissa: horizon in s (TransPose variant) or GT path window in m (PIP).
        error_m: ``(K,)`` mean root translation error at each abscissa, m; NaN where the segment
            is too short (no start frame or no window pair).
        mean_m: Mean of the finite values of ``error_m`` at ``x > 0``, m (NaN if none).
    """

    x: np.ndarray
    error_m: np.ndarray
    mean_m: float


def _curve(x: np.ndarray, err: np.ndarray) -> TranslationErrorCurve:
    use = (x > 0) & np.isfinite(err)
    mean = float(err[use].mean()) if use.any() else float("nan")
    return TranslationErrorCurve(x, err, mean)


def _check_roots(pred_root: np.ndarray, gt_root: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    p, g = _as_float(pred_root), _as_float(gt_root)
    if p.shape != g.shape or p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"expected two (T, 3) root tracks, got {p.shape} and {g.shape}")
    return p, g


def root_error_xy(pred_root: np.ndarray, gt_root: np.ndarray) -> float:
    """Mean horizontal distance between two ``(T, 3)`` root (pelvis) tracks, m (z up)."""
    p, g = _check_roots(pred_root, gt_root)
    return float(np.linalg.norm(p[:, :2] - g[:, :2], axis=1).mean())


def travel_ratio(pred_root: np.ndarray, gt_root: np.ndarray, fps: float,
                 every_s: float = 1.0) -> float:  # fmt: skip
    """Ground covered by a root track over the ground truth's (1 = the same distance), -.

    The horizontal path length of each ``(T, 3)`` track sampled every ``every_s`` seconds (so
    that the sway of the pelvis within a stride does not count as ground covered), predicted
    over true. NaN when the true track covers no ground (< 1 mm) or is shorter than
    ``every_s``.
    """
    p, g = _check_roots(pred_root, gt_root)
    step = max(round(every_s * fps), 1)
    if p.shape[0] <= step:
        return float("nan")

    def path(x: np.ndarray) -> float:
        return float(np.linalg.norm(np.diff(x[::step, :2], axis=0), axis=1).sum())

    ref = path(g)
    return path(p) / ref if ref > 1e-3 else float("nan")


def translation_error_by_time(
    pred_root: np.ndarray,
    gt_root: np.ndarray,
    fps: float,
    max_horizon_s: float = 10.0,
    step_s: float = 1.0,
) -> TranslationErrorCurve:
    """TransPose cumulative translation error against time.

    For every start frame ``s`` both root tracks are aligned at ``s`` and the distance error
    after a horizon of ``k`` frames is ``|(p_hat_{s+k} - p_hat_s) - (p_{s+k} - p_s)|``; it is
    averaged over all start frames with ``s + k < T``. Horizons ``0, step_s, ..., max_horizon_s``.

    Args:
        pred_root: ``(T, 3)`` predicted root positions, world, m.
        gt_root: ``(T, 3)`` ground-truth root positions, world, m.
        fps: Frame rate, Hz.
        max_horizon_s: Largest horizon, s.
        step_s: Horizon spacing, s.

    Returns:
        The curve over horizons in s (NaN for horizons of ``T`` frames or more); ``mean_m``
        averages the horizons ``> 0``.
    """
    p, g = _check_roots(pred_root, gt_root)
    d = p - g  # error relative to GT; aligning both at s subtracts d_s
    horizons = np.arange(0.0, max_horizon_s + 1e-9 * step_s, step_s)
    err = np.full(horizons.shape, np.nan)
    for i, h in enumerate(horizons):
        k = round(h * fps)
        if k < d.shape[0]:
            err[i] = np.linalg.norm(d[k:] - d[: d.shape[0] - k], axis=-1).mean()
    return _curve(horizons, err)


def translation_error_by_distance(
    pred_root: np.ndarray,
    gt_root: np.ndarray,
    windows_m: Sequence[float] = (1, 2, 3, 4, 5, 6, 7),
) -> TranslationErrorCurve:
    """PIP cumulative translation error against travelled distance [C-PIP].

    ``D_t`` is the ground-truth path length (sum of 3D root steps) up to frame ``t``. For a
    window ``w``, each start frame ``s`` pairs with the first end frame ``e`` where
    ``D_e - D_s >= w``; when several starts share an end only the earliest start is kept, and
    starts without such an end are dropped (as PIP's two-pointer scan does). Each pair scores
    ``|(p_hat_e - p_hat_s) - (p_e - p_s)| * w / (D_e - D_s)`` (the error normalised to exactly
    ``w`` m of travel); the window's value is the mean over its pairs.

    Args:
        pred_root: ``(T, 3)`` predicted root positions, world, m.
        gt_root: ``(T, 3)`` ground-truth root positions, world, m.
        windows_m: Path-length windows, m.

    Returns:
        The curve over windows in m (NaN where the GT path is shorter than the window).
    """
    p, g = _check_roots(pred_root, gt_root)
    dist = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(g, axis=0), axis=-1))])
    d = p - g
    windows = np.asarray(windows_m, dtype=np.float64)
    if np.any(windows <= 0.0):
        raise ValueError(f"path windows must be positive, got {windows_m}")
    err = np.full(windows.shape, np.nan)
    n = dist.shape[0]
    for i, w in enumerate(windows):
        end = np.searchsorted(dist, dist + w, side="left")
        valid = np.flatnonzero(end < n)
        if valid.size == 0:
            continue
        # searchsorted keeps the order, so the first occurrence of each end is its earliest start
        _, first = np.unique(end[valid], return_index=True)
        s = valid[first]
        e = end[s]
        e_err = np.linalg.norm(d[e] - d[s], axis=-1) * w / (dist[e] - dist[s])
        err[i] = e_err.mean()
    return _curve(windows, err)


def cumulative_translation_error(
    pred_root: np.ndarray,
    gt_root: np.ndarray,
    fps: float,
    variant: str = "transpose",
    **kwargs: float | Sequence[float],
) -> TranslationErrorCurve:
    """Cumulative root translation error, m, in one of the two published variants.

    Args:
        pred_root: ``(T, 3)`` predicted root positions, world, m.
        gt_root: ``(T, 3)`` ground-truth root positions, world, m.
        fps: Frame rate, Hz (used by the TransPose variant).
        variant: ``"transpose"`` (error after 0..10 s, :func:`translation_error_by_time`) or
            ``"pip"`` (error per 1..7 m of GT path, :func:`translation_error_by_distance`).
        **kwargs: Passed to the chosen function (``max_horizon_s``, ``step_s`` or ``windows_m``).

    Returns:
        The :class:`TranslationErrorCurve`.
    """
    if variant == "transpose":
        return translation_error_by_time(pred_root, gt_root, fps, **kwargs)
    if variant == "pip":
        return translation_error_by_distance(pred_root, gt_root, **kwargs)
    raise ValueError(f"unknown variant {variant!r}; use 'transpose' or 'pip'")


# ----------------------------------------------------------------------------------- ZMP
def _second_derivative(x: np.ndarray, fps: float) -> np.ndarray:
    """Central second difference along axis 0; the end frames copy their neighbours."""
    a = np.empty_like(x)
    a[1:-1] = (x[2:] - 2.0 * x[1:-1] + x[:-2]) * fps**2
    a[0], a[-1] = a[1], a[-2]
    return a


def _derivative(
    x: np.ndarray, fps: float, order: int, window_s: float | None, poly: int
) -> np.ndarray:
    """``order``-th time derivative along axis 0 (finite differences or Savitzky-Golay)."""
    if window_s is not None:
        w = max(round(window_s * fps), poly + 1)
        w += 1 - w % 2
        if w > x.shape[0]:
            w = x.shape[0] - (1 - x.shape[0] % 2)
        if w > poly:
            return signal.savgol_filter(x, w, poly, deriv=order, delta=1.0 / fps, axis=0,
                                        mode="interp")  # fmt: skip
    if order == 2:
        return _second_derivative(x, fps)
    return np.gradient(x, 1.0 / fps, axis=0)


def net_external_wrench(
    global_rot: np.ndarray,
    joint_pos: np.ndarray,
    body: BodyModel,
    fps: float,
    smooth_window_s: float | None = None,
    smooth_polyorder: int = 2,
) -> tuple[np.ndarray, np.ndarray]:
    """Net external (gravito-inertial) wrench that produces a motion, by Newton-Euler.

    Over the 24 rigid segments with masses ``m_j``, world COMs ``c_j``, world inertia
    ``I_j = R_j I_local R_j^T`` and world angular velocity ``w_j``:
    ``F = sum_j m_j (c''_j - g)`` and, about the world origin,
    ``N = sum_j c_j x m_j (c''_j - g) + d/dt sum_j I_j w_j`` with ``g = (0, 0, -9.81)``
    (``I_j w_j`` computed as ``R_j I_local w_local``). A body standing still gives
    ``F = (0, 0, M g)``. This is the residual-free wrench PIP reads from inverse dynamics.

    Derivatives: with ``smooth_window_s=None``, central finite differences (second difference
    for ``c''`` with the end frames copied from their neighbours, ``np.gradient`` for the spin,
    :func:`rotations.angular_velocity` for ``w``, which is wrap-safe); otherwise Savitzky-Golay
    derivatives (odd window of ``smooth_window_s`` s, ``smooth_polyorder``, ``mode="interp"``,
    shrunk for short clips).

    Args:
        global_rot: ``(T, 24, 3, 3)`` global segment rotations.
        joint_pos: ``(T, 24, 3)`` joint positions, world frame, m.
        body: Body model (segment masses, COMs and inertias in the body frames).
        fps: Frame rate, Hz.
        smooth_window_s: Savitzky-Golay window, s, or None for plain finite differences.
        smooth_polyorder: Savitzky-Golay polynomial order.

    Returns:
        ``force_world (T, 3)`` in N and ``moment_world (T, 3)`` about the world origin in N m.
    """
    global_rot, joint_pos = _as_float(global_rot), _as_float(joint_pos)
    if global_rot.ndim != 4 or global_rot.shape[1:] != (sk.N_JOINTS, 3, 3):
        raise ValueError(f"global_rot must be (T, 24, 3, 3), got {global_rot.shape}")
    if joint_pos.shape != (global_rot.shape[0], sk.N_JOINTS, 3):
        raise ValueError(f"joint_pos must be (T, 24, 3), got {joint_pos.shape}")
    _require_frames(global_rot, 3, "net_external_wrench")
    c = segment_com(global_rot, joint_pos, body)  # (T, 24, 3)
    acc = _derivative(c, fps, 2, smooth_window_s, smooth_polyorder)
    lin = body.masses[:, None] * (acc - _G_WORLD)  # (T, 24, 3) N
    force = lin.sum(axis=1)
    moment = np.cross(c, lin).sum(axis=1)
    w_local = angular_velocity(global_rot, fps, local=True)  # (T, 24, 3)
    spin = np.einsum("tjab,jbc,tjc->ta", global_rot, body.inertia_local, w_local)
    moment = moment + _derivative(spin, fps, 1, smooth_window_s, smooth_polyorder)
    return force, moment


def zero_moment_point(
    force_world: np.ndarray,
    moment_world: np.ndarray,
    plane_height: float = 0.0,
    min_fz_n: float = 1.0,
) -> np.ndarray:
    """Zero-moment point on the horizontal plane ``z = h``.

    The external moment about ``p = (x, y, h)`` is ``N - p x F``; its horizontal part vanishes
    at ``x = (h F_x - N_y) / F_z`` and ``y = (N_x + h F_y) / F_z``.

    Args:
        force_world: ``(T, 3)`` external force, N.
        moment_world: ``(T, 3)`` external moment about the world origin, N m.
        plane_height: ``h``, m.
        min_fz_n: Frames with ``F_z`` below this (no upward support) get NaN.

    Returns:
        ``(T, 2)`` world x, y of the ZMP, m.
    """
    f, n = _as_float(force_world), _as_float(moment_world)
    fz = f[:, 2]
    ok = fz >= min_fz_n
    safe = np.where(ok, fz, 1.0)
    x = (plane_height * f[:, 0] - n[:, 1]) / safe
    y = (n[:, 0] + plane_height * f[:, 1]) / safe
    zmp = np.stack([x, y], axis=-1)
    zmp[~ok] = np.nan
    return zmp


def _point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(T,)`` distance from points ``p`` to segments ``[a, b]``, all ``(T, 2)``."""
    ab = b - a
    len2 = np.sum(ab * ab, axis=-1)
    r = np.sum((p - a) * ab, axis=-1) / np.where(len2 > 0.0, len2, 1.0)
    r = np.clip(np.where(len2 > 0.0, r, 0.0), 0.0, 1.0)
    return np.linalg.norm(p - (a + r[:, None] * ab), axis=-1)


def zmp_distances(
    global_rot: np.ndarray,
    joint_pos: np.ndarray,
    body: BodyModel,
    fps: float,
    *,
    foot_radius_m: float = 0.10,
    plane_height: float = 0.0,
    foot_joints: tuple[int, int] = sk.FOOT_JOINTS,
    floor_frames: tuple[int, int] = (2, 30),
    floor_margin_m: float = 0.01,
    smooth_window_s: float | None = None,
) -> np.ndarray:
    """Per-frame ZMP distance to the support, m (NaN where the frame is not used).

    PIP's metric [C-PIP, adapted] from the numpy body model instead of MuJoCo/RBDL inverse
    dynamics: the ZMP of :func:`net_external_wrench` on the plane ``z = plane_height`` (the
    world floor through the origin, as PIP's RBDL call). The joint floor is the mean height of
    both foot joints over frames ``floor_frames`` (2..29) plus ``floor_margin_m``; a foot joint
    at or below it is in contact. Support: the xy segment between both foot joints when both are
    in contact, the single contacting foot joint otherwise. Distance:
    ``max(0, dist_xy(ZMP, support) - foot_radius_m)``. Frames with both foot joints above the
    joint floor, or with ``F_z < 1 N`` (ZMP undefined), are not used.

    Differences from PIP's code: central instead of backward finite differences (no one-frame
    lag), and the body model's segment inertias instead of PIP's URDF.

    Args:
        global_rot: ``(T, 24, 3, 3)`` global segment rotations of the output motion.
        joint_pos: ``(T, 24, 3)`` joint positions, world, m.
        body: Body model of the subject.
        fps: Frame rate, Hz.
        foot_radius_m: Support tolerance, m.
        plane_height: Height of the ZMP plane, m.
        foot_joints: (left, right) joints that define the support (SMPL feet 10, 11).
        floor_frames: ``[start, stop)`` frames for the joint floor (clipped to the clip; all
            frames if none remain).
        floor_margin_m: Added to the mean foot-joint height, m.
        smooth_window_s: Optional Savitzky-Golay window for the derivatives, s.

    Returns:
        ``(T,)`` distances in m, NaN for unused frames.
    """
    force, moment = net_external_wrench(global_rot, joint_pos, body, fps, smooth_window_s)
    zmp = zero_moment_point(force, moment, plane_height)
    feet = _as_float(joint_pos)[:, list(foot_joints)]  # (T, 2, 3)
    ref = feet[floor_frames[0] : floor_frames[1]]
    if ref.shape[0] == 0:
        ref = feet
    floor = ref[..., 2].mean() + floor_margin_m
    contact = feet[..., 2] <= floor  # (T, 2)
    left, right = feet[:, 0, :2], feet[:, 1, :2]
    # One foot in contact: a degenerate segment at that foot.
    a = np.where(contact[:, :1], left, right)
    b = np.where(contact[:, 1:], right, left)
    d = np.maximum(_point_segment_distance(zmp, a, b) - foot_radius_m, 0.0)
    used = contact.any(axis=1) & np.isfinite(zmp).all(axis=1)
    return np.where(used, d, np.nan)


def zmp_distance(
    global_rot: np.ndarray,
    joint_pos: np.ndarray,
    body: BodyModel,
    fps: float,
    **kwargs: float | tuple[int, int] | None,
) -> float:
    """ZMP distance, m: mean of :func:`zmp_distances` over the used frames (NaN if none).

    Keyword arguments are passed to :func:`zmp_distances`.
    """
    d = zmp_distances(global_rot, joint_pos, body, fps, **kwargs)
    used = np.isfinite(d)
    return float(d[used].mean()) if used.any() else float("nan")


# ------------------------------------------------------------------------------ summary
def summarize(
    per_segment: Sequence[Mapping[str, float | np.ndarray]],
) -> dict[str, float | np.ndarray]:
    """Average metric dicts over evaluation segments.

    Each key's value is the mean over the segments that report a finite value for it (NaN
    entries, e.g. foot sliding of a segment without contact, are skipped; the result is NaN if
    no segment has one). Array values (e.g. :attr:`TranslationErrorCurve.error_m`) are averaged
    element-wise. For metrics that average every frame and joint of a segment, equal segment
    lengths make this equal to the global per-frame mean (section 4.1); metrics averaged over a
    data-dependent subset of frames (foot sliding, ZMP distance) are segment-weighted, as PIP
    averages per sequence. A per-segment ``success_rate([fell])`` (0 or 100) averages to the
    success rate.

    Args:
        per_segment: One ``{metric name: value}`` mapping per segment.

    Returns:
        ``{metric name: mean}`` in first-appearance key order (floats, or arrays for array
        values).
    """
    keys: list[str] = []
    for seg in per_segment:
        keys.extend(k for k in seg if k not in keys)
    out: dict[str, float | np.ndarray] = {}
    for k in keys:
        vals = np.stack([_as_float(seg[k]) for seg in per_segment if k in seg])
        finite = np.isfinite(vals)
        count = finite.sum(axis=0)
        total = np.where(finite, vals, 0.0).sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(count > 0, total / np.maximum(count, 1), np.nan)
        out[k] = float(mean) if mean.ndim == 0 else mean
    return out
