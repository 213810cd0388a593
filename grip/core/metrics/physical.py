"""Physical plausibility metrics: foot sliding, contacts, penetration, GRF error and ZMP."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import signal

from grip.core import skeleton as sk
from grip.core.body import GRAVITY, BodyModel
from grip.core.fk import segment_com
from grip.core.metrics._checks import _MM, _as_float, _require_frames
from grip.core.rotations import angular_velocity

_G_WORLD = np.array([0.0, 0.0, -GRAVITY])


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
