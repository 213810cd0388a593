"""Feet and floor of :func:`grip.motion.retarget.retarget` (steps 4 and 8 of its method):
planted source feet, sole levelling, floor tilt, foot clearance, flat-foot contacts, the
floor height and the two-bone leg IK."""

from __future__ import annotations

import numpy as np

from grip.core import skeleton as sk
from grip.core.body import BodyModel
from grip.core.fk import forward_kinematics, sole_points
from grip.core.rotations import rotation_between
from grip.motion.retarget_bones import _is_descendant, _normalize

_J = sk.JOINT_INDEX

#: Legs as (hip, knee, ankle, toe) joint indices, left then right.
_LEGS: tuple[tuple[int, int, int, int], ...] = ((1, 4, 7, 10), (2, 5, 8, 11))

#: Source planted-foot rule: ankle within this height of its lowest (m), slower than this (m/s),
#: shank within this angle of vertical (deg).
_PLANT_HEIGHT_M, _PLANT_SPEED_MPS, _PLANT_SHANK_DEG = 0.04, 0.2, 40.0
_PLANT_SPEED_LOOSE_MPS = 1.0
#: Planted source frames needed per foot to calibrate it (3 frames = 0.1 s at 30 Hz).
_MIN_PLANTED_FRAMES = 3
_Y = np.array([0.0, 1.0, 0.0])
_Z = np.array([0.0, 0.0, 1.0])


# --------------------------------------------------------------------------- feet and floor
def _planted_feet(pos_w: np.ndarray, times: np.ndarray, smpl_to_src: dict[int, int]) -> np.ndarray:
    """``(T, 2)`` frames where each source foot (L, R) is planted.

    Planted: the ankle is within 4 cm of its lowest height (2nd percentile), slower than
    0.2 m/s and the shank within 40 deg of vertical (so a lying or kneeling leg is not taken for a
    stance). A foot with fewer than 3 such frames (short runs and hops) is planted where it is
    that low and upright and slower than 1 m/s instead.

    Args:
        pos_w: ``(T, J, 3)`` source joint positions in the z-up world (source size), m.
        times: ``(T,)`` frame times, s.
        smpl_to_src: SMPL joint index -> source joint index.
    """
    out = np.zeros((pos_w.shape[0], 2), dtype=bool)
    if pos_w.shape[0] < 3 or not times[-1] > times[0]:
        return out
    for f, (_, knee, ankle, _) in enumerate(_LEGS):
        p = pos_w[:, smpl_to_src[ankle]]
        speed = np.linalg.norm(np.gradient(p, times, axis=0), axis=-1)
        shank_up = _normalize(pos_w[:, smpl_to_src[knee]] - p)[:, 2]
        low = ((p[:, 2] < np.percentile(p[:, 2], 2) + _PLANT_HEIGHT_M)
               & (shank_up > np.cos(np.radians(_PLANT_SHANK_DEG))))  # fmt: skip
        out[:, f] = low & (speed < _PLANT_SPEED_MPS)
        if out[:, f].sum() < _MIN_PLANTED_FRAMES:
            out[:, f] = low & (speed < _PLANT_SPEED_LOOSE_MPS)
    return out


def _flatten_feet(
    g: np.ndarray, planted: np.ndarray, smpl_to_src: dict[int, int]
) -> dict[str, float]:
    """Level the soles of planted feet: a fixed per-segment offset in the segment's own frame.

    A rig's rest pose says nothing about the sole plane: ASF rest legs are splayed ~20 deg and
    the feet roll with them, a Daz foot rests a few degrees plantar-flexed, and transferring the
    bone direction of a Bandai foot (ankle high above the toes) pitches ours ~20 deg toe-down.
    Mid-stance soles are flat on the floor, so the mean "up" axis of our foot frame over the
    frames where the source foot is planted should be world up; the correction is the minimal
    rotation doing so (pitch and roll, no yaw). A mapped toe segment is levelled the same way.
    A correction is skipped with fewer than 3 planted frames or above 45 deg (90 deg for toes,
    whose reference orientation may come from a clip frame; no reliable stance otherwise);
    outliers more than 20 deg from the mean are dropped once. A foot that is never planted takes
    the mirrored correction of the other foot (rigs are left/right symmetric).

    Args:
        g: ``(T, 24, 3, 3)`` our global rotations at the source rate, z-up world; the foot and
            toe rows are corrected in place.
        planted: ``(T, 2)`` planted frames of the left and right source foot.
        smpl_to_src: SMPL joint index -> source joint index.

    Returns:
        Correction angle per foot (``"L"``, ``"R"``) and toe segment (``"L_toes"``, ``"R_toes"``),
        deg; absent where skipped.
    """
    # Mean world-up direction in each segment's frame over its planted frames.
    means: dict[tuple[int, int], np.ndarray] = {}
    for f, side in enumerate("LR"):
        if planted[:, f].sum() < _MIN_PLANTED_FRAMES:
            continue
        for k, seg in enumerate((_J[f"{side}_Ankle"], _J[f"{side}_Foot"])):
            if seg not in smpl_to_src:
                continue  # unmapped toes follow the corrected foot
            up_local = np.einsum("tba,b->ta", g[planted[:, f], seg], _Z)
            mean = _normalize(up_local.mean(axis=0))
            keep = up_local @ mean > np.cos(np.radians(20))
            if keep.sum() >= _MIN_PLANTED_FRAMES:
                mean = _normalize(up_local[keep].mean(axis=0))
            if np.degrees(np.arccos(np.clip(mean[1], -1.0, 1.0))) <= (45.0, 90.0)[k]:
                means[f, k] = mean
    out: dict[str, float] = {}
    mirror = np.array([-1.0, 1.0, 1.0])
    for f, side in enumerate("LR"):
        for k, (seg, key) in enumerate(((_J[f"{side}_Ankle"], side),
                                        (_J[f"{side}_Foot"], f"{side}_toes"))):  # fmt: skip
            # A foot never planted (a kicking or balancing leg) takes its twin's correction.
            mean = means.get((f, k))
            if mean is None and (1 - f, k) in means and seg in smpl_to_src:
                mean = means[1 - f, k] * mirror
            if mean is None:
                continue
            g[:, seg] = g[:, seg] @ rotation_between(_Y, mean)
            out[key] = float(np.degrees(np.arccos(np.clip(mean[1], -1.0, 1.0))))
    return out


def fit_floor_tilt(
    points: np.ndarray,
    groups: np.ndarray | None = None,
    min_extent_m: float = 1.5,
    max_slope_deg: float = 3.0,
    min_gain: float = 0.3,
) -> np.ndarray | None:
    """Transform that levels a slightly tilted capture floor, or None.

    A plane ``z = a x + b y + c_g`` (one intercept per group, e.g. per foot, so that a left
    ankle sitting higher than the right one is not taken for a slope when walking sideways) is
    fitted robustly (3 rounds of least squares on the points within 3 MADs) to foot-plant points,
    with slopes only along the horizontal principal directions in which the points span at least
    ``min_extent_m`` (a straight walk fixes the tilt along it only). It is accepted when the
    slope is between 0.1 deg and ``max_slope_deg`` (stairs and props give steeper fits) and
    reduces the robust spread (MAD) of the heights, after removing the group offsets, by
    ``min_gain``.

    Args:
        points: ``(N, 3)`` foot-plant points (e.g. planted ankles), z-up world, m.
        groups: ``(N,)`` integer group of each point (default: one group).
        min_extent_m: Least extent of the points along their main horizontal direction, m.
        max_slope_deg: Steepest accepted plane, deg.
        min_gain: Least relative reduction of the height MAD by the slope.

    Returns:
        ``(4, 4)`` homogeneous transform (a rotation about the points' centroid on the plane)
        that makes the plane horizontal, or None.
    """
    if points.shape[0] < 10:
        return None
    xy = points[:, :2] - points[:, :2].mean(axis=0)
    _, _, vt = np.linalg.svd(xy, full_matrices=False)
    extent = np.ptp(xy @ vt.T, axis=0)
    # Slopes only along horizontal directions the plants span (a straight walk says nothing
    # about the sideways tilt, and per-foot offsets would make that fit arbitrary).
    axes = vt[extent >= min_extent_m]
    if len(axes) == 0:
        return None
    z = points[:, 2]
    groups = np.zeros(len(z), dtype=np.int64) if groups is None else np.asarray(groups)
    onehot = (groups[:, None] == np.unique(groups)[None, :]).astype(np.float64)
    design = np.c_[xy @ axes.T, onehot]
    inlier = np.ones(len(points), dtype=bool)
    coef = np.zeros(design.shape[1])
    res = z.copy()
    for _ in range(3):
        coef, *_ = np.linalg.lstsq(design[inlier], z[inlier], rcond=None)
        res = z - design @ coef
        mid = np.median(res[inlier])
        mad = np.median(np.abs(res[inlier] - mid))
        inlier = np.abs(res - mid) < 3.0 * 1.4826 * mad + 0.005
    n_ax = len(axes)
    flat = z - onehot @ coef[n_ax:]  # heights without the group offsets, no slope
    mad_plane = np.median(np.abs(res - np.median(res)))
    mad_const = np.median(np.abs(flat - np.median(flat)))
    grad = coef[:n_ax] @ axes  # (2,) dz/dx, dz/dy
    slope = np.degrees(np.arctan(np.linalg.norm(grad)))
    if not 0.1 <= slope <= max_slope_deg or mad_plane > (1.0 - min_gain) * mad_const:
        return None  # below 0.1 deg (1.7 mm/m) levelling changes nothing worth a rotation
    rot = rotation_between(np.array([-grad[0], -grad[1], 1.0]), _Z)
    centre = np.r_[points[:, :2].mean(axis=0), np.mean(onehot @ coef[n_ax:])]
    out = np.eye(4)
    out[:3, :3] = rot
    out[:3, 3] = centre - rot @ centre
    return out


def foot_clearance(
    pos_w: np.ndarray, planted: np.ndarray, smpl_to_src: dict[int, int], parents: np.ndarray
) -> np.ndarray:
    """Height of each source foot above its own planted posture, ``(T, 2)`` (L, R), m.

    For every point of the source foot (the ankle joint, its descendants: toes, end sites) the
    height above that point's median height in planted frames; the foot's clearance is the
    smallest of those, clipped at 0. It is 0 in flat stance, at heel strike (ankle down) and at
    toe-off (toes down), and the lift of the lowest part of the foot otherwise. Feet without
    planted frames get NaN.

    Args:
        pos_w: ``(T, J, 3)`` source joint positions, z-up world (levelled), source size, m.
        planted: ``(T, 2)`` planted frames.
        smpl_to_src: SMPL joint index -> source joint index.
        parents: ``(J,)`` source parents.
    """
    out = np.full((pos_w.shape[0], 2), np.nan)
    for f, (_, _, ankle, _) in enumerate(_LEGS):
        if planted[:, f].sum() < _MIN_PLANTED_FRAMES:
            continue
        a = smpl_to_src[ankle]
        pts = [a] + [j for j in range(len(parents)) if _is_descendant(parents, j, a)]
        h = pos_w[:, pts, 2]  # (T, P)
        ref = np.median(h[planted[:, f]], axis=0)
        out[:, f] = np.maximum(0.0, (h - ref).min(axis=1))
    return out


def flat_foot_contacts(
    global_rot: np.ndarray, joint_pos: np.ndarray, body: BodyModel, fps: float,
    speed_mps: float, max_tilt_deg: float = 15.0,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Frames where a foot is planted flat (sole level and nearly still), and sole heights.

    Args:
        global_rot: ``(T, 24, 3, 3)`` global rotations, z-up world.
        joint_pos: ``(T, 24, 3)`` joint positions, m.
        body: The body model.
        fps: Frame rate, Hz.
        speed_mps: Mean horizontal speed of the foot's sole points below which it is still.
        max_tilt_deg: Largest angle between the foot's up axis and world up.

    Returns:
        ``(T, 2)`` mask (feet L, R) and ``(T, 2)`` lowest sole point height of each foot, m.
    """
    soles = sole_points(global_rot, joint_pos, body)  # (T, 2, 6, 3)
    up_z = global_rot[:, [_J["L_Ankle"], _J["R_Ankle"]], 2, 1]  # world z of the foot's y axis
    centre = soles[..., :2].mean(axis=2)
    if soles.shape[0] >= 2:
        speed = np.linalg.norm(np.gradient(centre, axis=0), axis=-1) * fps
    else:
        speed = np.zeros(up_z.shape)
    mask = (up_z > np.cos(np.radians(max_tilt_deg))) & (speed < speed_mps)
    return mask, soles[..., 2].min(axis=2)


def floor_offset(
    low_points: np.ndarray, fps: float, stance_speed_mps: float, percentile: float
) -> tuple[float, np.ndarray]:
    """Height of the floor from the lowest body points (any body part).

    Used when the feet are rarely planted flat (floor-lying, crawling, rolling clips).

    Args:
        low_points: ``(T, P, 3)`` candidate lowest points of the body (sole corners and shape
            bottoms, see :func:`grip.motion.quality.body_low_points`), z-up world, m.
        fps: Frame rate, Hz.
        stance_speed_mps: Frames whose lowest point moves horizontally slower than this rest on
            the floor, m/s.
        percentile: Percentile of the lowest-point height over resting frames taken as floor.

    Returns:
        The floor height (m; subtract it from z) and the ``(T,)`` resting-frame mask. Without
        resting frames all frames are used.
    """
    t = low_points.shape[0]
    z = low_points[..., 2]
    k = np.argmin(z, axis=1)
    z_low = z[np.arange(t), k]
    if t >= 2:
        vel = np.gradient(low_points[..., :2], axis=0) * fps  # (T, P, 2)
        speed = np.linalg.norm(vel[np.arange(t), k], axis=-1)
    else:
        speed = np.zeros(t)
    rest = speed < stance_speed_mps
    pool = z_low[rest] if rest.any() else z_low
    return float(np.percentile(pool, percentile)), rest


def leg_ik(
    local_rot: np.ndarray, root: np.ndarray, body: BodyModel, lift: np.ndarray
) -> np.ndarray:
    """Move each ankle by ``lift`` with two-bone IK, keeping the foot's world orientation.

    The knee stays in the plane it bends in (its offset from the hip-ankle line; the thigh's
    forward axis for a straight leg); targets out of reach are clamped to the reachable range
    (along the hip-target line).

    Args:
        local_rot: ``(T, 24, 3, 3)`` local rotations.
        root: ``(T, 3)`` root positions, m.
        body: The body model.
        lift: ``(T, 2)`` vertical ankle displacement of the left and right leg, or ``(T, 2, 3)``
            a displacement in any direction (world frame), m.

    Returns:
        ``(T, 24, 3, 3)`` local rotations with new hip, knee and ankle rows.
    """
    g, p = forward_kinematics(local_rot, root, body.offsets)
    out = local_rot.copy()
    for f, (hip, knee, ankle, _) in enumerate(_LEGS):
        if not np.any(lift[:, f]):
            continue
        l1 = np.linalg.norm(body.offsets[knee])
        l2 = np.linalg.norm(body.offsets[ankle])
        ph, pk, pa = p[:, hip], p[:, knee], p[:, ankle]
        target = pa + (lift[:, f, None] * _Z if lift.ndim == 2 else lift[:, f])
        reach = target - ph
        dist = np.clip(np.linalg.norm(reach, axis=-1), abs(l1 - l2) + 1e-4, l1 + l2 - 1e-6)
        axis = _normalize(reach)
        # Bending direction: the knee's offset from the old hip-ankle line.
        old = _normalize(pa - ph)
        bend = (pk - ph) - np.sum((pk - ph) * old, axis=-1, keepdims=True) * old
        fwd = g[:, hip] @ _Z
        bend = np.where(np.linalg.norm(bend, axis=-1, keepdims=True) < 1e-4, fwd, bend)
        bend = _normalize(bend - np.sum(bend * axis, axis=-1, keepdims=True) * axis)
        along = (l1**2 - l2**2 + dist**2) / (2.0 * dist)
        across = np.sqrt(np.maximum(l1**2 - along**2, 0.0))
        pk_new = ph + along[:, None] * axis + across[:, None] * bend
        pa_new = ph + dist[:, None] * axis
        g_thigh = rotation_between(pk - ph, pk_new - ph) @ g[:, hip]
        g_shank = rotation_between(pa - pk, pa_new - pk_new) @ g[:, knee]
        out[:, hip] = np.swapaxes(g[:, sk.PARENTS[hip]], -1, -2) @ g_thigh
        out[:, knee] = np.swapaxes(g_thigh, -1, -2) @ g_shank
        out[:, ankle] = np.swapaxes(g_shank, -1, -2) @ g[:, ankle]
    return out
