"""Joint position and rotation errors, acceleration error and jitter (mm, deg, m/s^2)."""

from __future__ import annotations

import numpy as np

from grip.core.metrics._checks import _MM, _as_float, _check_pair, _reduce, _require_frames


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
