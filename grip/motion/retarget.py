"""Retarget an imported clip (:class:`SourceMotion`) onto the body model: a 100 Hz :class:`Motion`.

Method: transfer of global segment orientations through a joint map
(:mod:`grip.motion.joint_maps`), then contact clean-up.

1. The source world is turned into the z-up world by a fixed rotation ``W`` that only moves the
   up axis (y-up sources: ``W = CANONICAL_TO_WORLD``, so a source +z becomes world +y; z-up: the
   identity). Clips keep their own heading.
2. A *reference pose* ties each source joint frame to our segment frame. For rigs whose zero pose
   is an anatomical T-pose/standing pose it is that zero pose; for rigs whose zero pose is not
   (Bandai: bones along local x, rest orientation baked into the channels) it is the clip frame
   closest to neutral standing (legs and trunk vertical, arms hanging, feet forward).
3. In the reference pose, the body basis ``B_src`` (it maps our canonical axes to source world
   axes; from the hip line and the trunk) and, per mapped segment, the minimal swing ``Q`` that
   turns the source bone (towards the source joint mapped to the segment's child), already
   swung like its parent, onto our rest bone direction expressed in ``B_src`` (least change of
   every joint's reference rotation). The pelvis and the chest also align their twist with the
   hip and shoulder lines. Segments without a mapped child keep either their reference *world*
   orientation (feet, toes, head: level in a standing pose) or their reference rotation
   *relative to the parent* (hands). Per segment ``K = (Q @ S_ref)^T @ B_src`` and for every
   frame ``G(t) = W @ S(t) @ K``: our world segment rotation. Hence our world bone
   directions equal ``W`` times the source's at every frame; the reference pose fixes the twist.
   SMPL/AMASS sources instead keep their rotations relative to the rest T-pose joint by joint
   (``K = S_rest^T @ S_rest,pelvis``): PRISM and AMASS poses are defined that way.
4. Feet: each foot (and toe) segment gets a fixed offset that levels its sole, on average, where
   the source foot is planted; rest poses do not define the sole plane (ASF legs rest splayed
   with the feet rolled, Daz feet rest plantar-flexed, Bandai ankles sit high). A slightly tilted
   capture floor (some CMU takes rise ~1 deg) is levelled by rotating the whole clip.
5. Local rotations ``L_j = G_parent^T G_j``. Unmapped spine/neck joints between two mapped ones
   share the rotation between them evenly; other unmapped joints keep the identity.
6. Root: the source hip centre, scaled by our leg length over the source's (thigh + shank bone
   lengths, pose independent) and mapped by ``W``, fixes our hip centre; the pelvis joint follows
   from the pelvis rotation. (Matching hip centres rather than "pelvis" joints removes the
   rig-dependent offset between a rig's pelvis joint and its hips.)
7. Resampling to ``cfg.fps`` from ``src.times_s`` (variable dt allowed): slerp on local
   quaternions, linear on the root; then a zero-phase 10 Hz low-pass (config). It removes the
   marker jitter of the CMU conversions (wrist acceleration in a walk: median 11 -> 5 m/s^2)
   and the kinks that linear upsampling of 30 Hz sources leaves (99th percentile 45 -> 17
   m/s^2), which finite-difference IMU synthesis would otherwise turn into acceleration spikes;
   human motion content lies below it.
8. Floor and contacts: the floor is the height of our flat planted feet (the median of those
   within 3 cm of the lowest, so steps and stools do not count; the lowest body point for clips
   without flat foot plants). Rotations alone put our feet at the wrong height whenever the
   source's foot proportions differ (a Bandai ankle is ~11 cm above the floor, ours 7.6 cm, so a
   rotating foot dips into the floor at toe-off), so a two-bone leg IK moves each ankle
   vertically until our lowest sole point has the source foot's clearance above its own planted
   height, keeping the foot's world orientation. A smooth per-frame lift of the
   root removes whatever still penetrates (e.g. a lying torso thicker than the actor's).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d, maximum_filter1d, uniform_filter1d

from grip.core import skeleton as sk
from grip.core.body import BodyModel, BodyParams, build_body
from grip.core.fk import forward_kinematics
from grip.core.rotations import matrix_to_quat, quat_to_matrix, resample_linear, resample_quats
from grip.motion.joint_maps import resolve_joint_map
from grip.motion.motion import Motion
from grip.motion.quality import body_low_points
from grip.motion.retarget_bones import (
    _segment_bones,
    _segment_offsets,
    _share_spine,
    neutral_frame,
    reference_basis,
    world_from_source,
)
from grip.motion.retarget_feet import (
    _LEGS,
    _flatten_feet,
    _planted_feet,
    fit_floor_tilt,
    flat_foot_contacts,
    floor_offset,
    foot_clearance,
    leg_ik,
)
from grip.motion.source import MotionImportError, SourceMotion

_J = sk.JOINT_INDEX

#: Flat foot plants higher than this above the lowest ones (10th percentile) stand on a step or
#: prop and do not define the floor, m.
_FLOOR_BAND_M = 0.03
#: Planted flat foot-frames needed to take the floor height from the feet.
_MIN_FLAT_FOOT_FRAMES = 10


@dataclass(frozen=True)
class RetargetConfig:
    """Settings of :func:`retarget`.

    Attributes:
        fps: Output frame rate, Hz.
        stance_speed_mps: A foot (or the lowest body point) is still when its horizontal speed is
            below this, m/s; still, level feet define the floor.
        floor_percentile: Percentile (0-100) of the lowest sole height over flat, still foot
            frames (those within 3 cm of the lowest ones: steps and stools excluded) that becomes
            the floor; of the lowest body point over resting frames when there are no flat foot
            plants. Low values trade floating for penetration; with ``foot_ik`` the choice
            matters little.
        flatten_feet: Level each foot's (and toe's) sole on average where the source foot is
            planted (a fixed offset per segment and clip).
        level_floor: Rotate the clip to level a slightly tilted capture floor fitted to the
            planted source feet (see :func:`~grip.motion.retarget_feet.fit_floor_tilt`; at most
            3 deg, >= 1.5 m of travel).
        foot_ik: Two-bone leg IK that gives each foot the source foot's clearance above the floor.
        max_foot_ik_m: Largest vertical ankle correction of the IK, m.
        align_bones: Align bone directions (step 3; True) or copy rotations relative to the rest
            pose joint by joint (False: right for SMPL/AMASS poses, which this body's topology
            is made for; bone directions then follow our skeleton). None: copy for ``"smpl"``
            rigs with a T-pose rest, align otherwise.
        fix_penetration: Raise the root, smoothly, in frames where a body point is still below
            the floor.
        penetration_window_s: Width of the smoothing window of that lift, s.
        smooth_hz: -3 dB cut-off of the zero-phase Gaussian low-pass after resampling (None:
            off), Hz; see step 7 of the module docstring.
        joint_map_path: JSON joint map (SMPL name -> source name) replacing the rig's map.
    """

    fps: float = 100.0
    stance_speed_mps: float = 0.3
    floor_percentile: float = 50.0
    flatten_feet: bool = True
    level_floor: bool = True
    foot_ik: bool = True
    max_foot_ik_m: float = 0.1
    align_bones: bool | None = None
    fix_penetration: bool = True
    penetration_window_s: float = 0.2
    smooth_hz: float | None = 10.0
    joint_map_path: str | None = None

    def __post_init__(self) -> None:
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"RetargetConfig.fps must be > 0, got {self.fps!r}")
        if not 0.0 <= self.floor_percentile <= 100.0:
            raise ValueError(f"RetargetConfig.floor_percentile must lie in [0, 100], "
                             f"got {self.floor_percentile!r}")  # fmt: skip
        if self.stance_speed_mps <= 0 or self.penetration_window_s < 0 or self.max_foot_ik_m < 0:
            raise ValueError("RetargetConfig: stance_speed_mps must be > 0, penetration_window_s "
                             "and max_foot_ik_m >= 0")  # fmt: skip
        if self.smooth_hz is not None and not self.smooth_hz > 0:
            raise ValueError(
                f"RetargetConfig.smooth_hz must be > 0 or None, got {self.smooth_hz!r}"
            )


# --------------------------------------------------------------------------- main entry
def retarget(
    src: SourceMotion, body: BodyParams | None = None, cfg: RetargetConfig | None = None
) -> Motion:
    """Retarget a clip onto the body model (method: module docstring).

    Args:
        src: The imported clip (source world axes, metres).
        body: Subject parameters of the target body; default :class:`BodyParams` ().
        cfg: Settings; default :class:`RetargetConfig` ().

    Returns:
        A :class:`Motion` at ``cfg.fps`` in the z-up world (floor z = 0), named and categorised
        like the source, with ``meta`` holding the source file, format, rig, joint map, scale,
        reference frame, foot and floor corrections and the settings.

    Raises:
        MotionImportError: Required joints cannot be mapped (the message lists them and the
            available source joint names), or the clip is degenerate (no heading, no legs).
    """
    cfg = cfg or RetargetConfig()
    params = body or BodyParams()
    model = build_body(params)
    where = src.path or src.name
    mapping = resolve_joint_map(src.rig, src.joint_names, src.parents,
                                override=cfg.joint_map_path, where=where)  # fmt: skip
    smpl_to_src = {_J[k]: src.joint_names.index(v) for k, v in mapping.items()}
    bones = _segment_bones(smpl_to_src, src.parents, src.rest_pos, model)

    # ------------------------------------------------ reference pose, body basis, offsets K
    if src.rest_is_tpose:
        ref_index = -1
        ref_rot, ref_pos = src.rest_rot, src.rest_pos
    else:
        ref_index, _ = neutral_frame(src, smpl_to_src, model)
        ref_rot, ref_pos = src.global_rot[ref_index], src.global_pos[ref_index]
    lhip, rhip = smpl_to_src[_J["L_Hip"]], smpl_to_src[_J["R_Hip"]]
    b_src = reference_basis(ref_pos, smpl_to_src, model.rest_joint_pos)
    if b_src is None:
        raise MotionImportError(
            where,
            "cannot find the subject's axes in the reference pose: "
            "the hip joints coincide or lie on the spine line",
        )
    align = cfg.align_bones
    if align is None:
        align = not (src.rig == "smpl" and src.rest_is_tpose)
    if align:
        order, k_mats = _segment_offsets(bones, smpl_to_src, ref_rot, ref_pos, b_src, model)
    else:
        # SMPL-topology sources: rotations relative to the rest T-pose apply joint by joint.
        order = sorted(smpl_to_src)
        b_src = ref_rot[smpl_to_src[_J["Pelvis"]]]
        k_mats = np.swapaxes(ref_rot[[smpl_to_src[j] for j in order]], -1, -2) @ b_src
    src_leg = _leg_length(ref_pos, smpl_to_src)
    if not src_leg > 1e-6:
        raise MotionImportError(where, "the source legs have zero length")
    scale = _leg_length(model.rest_joint_pos, {j: j for j in range(sk.N_JOINTS)}) / src_leg

    # ------------------------------------------------ world rotations at the source rate
    w = world_from_source(src.up_axis)
    times = np.asarray(src.times_s, dtype=np.float64)
    pos_w = src.global_pos @ w.T  # (T, J, 3) source joints, z-up world, source size
    g = np.empty((src.num_frames, sk.N_JOINTS, 3, 3))
    g[:, order] = w @ src.global_rot[:, [smpl_to_src[j] for j in order]] @ k_mats
    planted = _planted_feet(pos_w, times, smpl_to_src)
    feet_fix = _flatten_feet(g, planted, smpl_to_src) if cfg.flatten_feet else {}
    tilt_deg = 0.0
    if cfg.level_floor:
        ankles = [smpl_to_src[_J["L_Ankle"]], smpl_to_src[_J["R_Ankle"]]]
        foot_of = np.broadcast_to(np.arange(2), planted.shape)
        level = fit_floor_tilt(pos_w[:, ankles][planted], foot_of[planted])
        if level is not None:
            pos_w = pos_w @ level[:3, :3].T + level[:3, 3]
            g[:, order] = level[:3, :3] @ g[:, order]
            tilt_deg = float(np.degrees(np.arccos(np.clip(level[2, 2], -1.0, 1.0))))
    mapped = np.zeros(sk.N_JOINTS, dtype=bool)
    mapped[order] = True
    shared = _share_spine(g, mapped)
    for j in range(1, sk.N_JOINTS):
        if not mapped[j] and not shared[j]:
            g[:, j] = g[:, sk.PARENTS[j]]
    local = np.empty_like(g)
    local[:, 0] = g[:, 0]
    local[:, 1:] = np.swapaxes(g[:, sk.PARENTS[1:]], -1, -2) @ g[:, 1:]

    # ------------------------------------------------ root from the hip centre
    hip_off = 0.5 * (model.offsets[1] + model.offsets[2])  # hip centre in the pelvis frame
    root = scale * 0.5 * (pos_w[:, lhip] + pos_w[:, rhip]) - g[:, 0] @ hip_off
    clearance = scale * foot_clearance(pos_w, planted, smpl_to_src, src.parents)

    # ------------------------------------------------ resample, smooth
    quat = matrix_to_quat(local)
    if src.num_frames >= 2 and times[-1] > times[0]:
        n_out = int(np.floor((times[-1] - times[0]) * cfg.fps + 1e-6)) + 1
        new_t = times[0] + np.arange(n_out) / cfg.fps
        quat = resample_quats(times, quat, new_t)
        root = resample_linear(times, root, new_t)
        clearance = resample_linear(times, clearance, new_t)
    else:
        quat, root, clearance = quat[:1], root[:1], clearance[:1]
    if cfg.smooth_hz is not None:
        quat, root = smooth_motion(quat, root, cfg.fps, cfg.smooth_hz)

    # ------------------------------------------------ floor and contacts
    quat, root, floor = _floor_and_contacts(quat, root, clearance, model, cfg)
    meta = {
        "source_path": src.path,
        "source_fmt": src.fmt,
        "source_rig": src.rig,
        "source_frames": src.num_frames,
        "source_duration_s": float(times[-1] - times[0]),
        "joint_map": dict(mapping),
        "scale": float(scale),
        "source_leg_length_m": float(src_leg),
        "reference_frame": "rest" if ref_index < 0 else int(ref_index),
        "aligned_bones": bool(align),
        "foot_flatten_deg": feet_fix,
        "floor_tilt_deg": tilt_deg,
        **floor,
        "retarget_config": asdict(cfg),
    }
    return Motion(fps=float(cfg.fps), root_pos=root, local_quat=quat, body=params,
                  name=src.name, category=src.category, meta=meta)  # fmt: skip


def _leg_length(pos: np.ndarray, smpl_to_src: dict[int, int]) -> float:
    """Mean over both sides of thigh + shank bone length of a pose ``(J, 3)``, m."""
    total = 0.0
    for hip, knee, ankle, _ in _LEGS:
        h, k, a = smpl_to_src[hip], smpl_to_src[knee], smpl_to_src[ankle]
        total += np.linalg.norm(pos[k] - pos[h]) + np.linalg.norm(pos[a] - pos[k])
    return float(total / 2)


def smooth_motion(quat: np.ndarray, root: np.ndarray, fps: float, cutoff_hz: float
                  ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Zero-phase Gaussian low-pass of local quaternions and root positions.

    Quaternion tracks are made sign-continuous, filtered per component and renormalised (fine for
    the small frame-to-frame rotations of 100 Hz motion).

    Args:
        quat: ``(T, 24, 4)`` local quaternions (w, x, y, z).
        root: ``(T, 3)`` root positions, m.
        fps: Frame rate, Hz.
        cutoff_hz: -3 dB frequency of the Gaussian, Hz (sigma = 0.1325 / cutoff s).

    Returns:
        Filtered ``(T, 24, 4)`` unit quaternions (w >= 0) and ``(T, 3)`` positions.
    """
    sigma = 0.1325 / cutoff_hz * fps
    if quat.shape[0] < 3 or sigma < 0.3:
        return quat, root
    q = quat.copy()
    flips = np.sum(q[1:] * q[:-1], axis=-1) < 0.0  # (T-1, 24)
    q[1:] *= np.where(np.cumsum(flips, axis=0) % 2 == 1, -1.0, 1.0)[..., None]
    q = gaussian_filter1d(q, sigma, axis=0, mode="nearest")
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q = np.where(q[..., :1] < 0.0, -q, q)
    return q, gaussian_filter1d(root, sigma, axis=0, mode="nearest")


def _floor_and_contacts(
    quat: np.ndarray, root: np.ndarray, clearance: np.ndarray, model: BodyModel,
    cfg: RetargetConfig,
) -> tuple[np.ndarray, np.ndarray, dict]:  # fmt: skip
    """Floor height, foot IK and penetration lift (step 8). Returns quat, root and a report."""
    local = quat_to_matrix(quat)
    g_rot, j_pos = forward_kinematics(local, root, model.offsets)
    flat, foot_low = flat_foot_contacts(g_rot, j_pos, model, cfg.fps, cfg.stance_speed_mps)
    report: dict = {}
    if flat.sum() >= _MIN_FLAT_FOOT_FRAMES:
        # The floor level, not a step or stool: the flat-foot heights near the lowest ones.
        heights = foot_low[flat]
        base = np.percentile(heights, 10)
        floor = float(np.percentile(heights[heights < base + _FLOOR_BAND_M], cfg.floor_percentile))
        report["floor_from"] = "flat_feet"
    else:
        floor, _ = floor_offset(body_low_points(g_rot, j_pos, model), cfg.fps,
                                cfg.stance_speed_mps, cfg.floor_percentile)  # fmt: skip
        report["floor_from"] = "lowest_point"
    ik = np.zeros_like(foot_low)
    if cfg.foot_ik and cfg.max_foot_ik_m > 0:
        wanted = floor + clearance
        ik = np.where(np.isfinite(wanted), wanted - foot_low, 0.0)
        ik = np.clip(ik, -cfg.max_foot_ik_m, cfg.max_foot_ik_m)
        if ik.shape[0] >= 3:
            ik = gaussian_filter1d(ik, 0.02 * cfg.fps, axis=0, mode="nearest")
        if np.any(ik):
            local = leg_ik(local, root, model, ik)
            quat = matrix_to_quat(local)
            g_rot, j_pos = forward_kinematics(local, root, model.offsets)
    root = root.copy()
    root[:, 2] -= floor
    z_low = body_low_points(g_rot, j_pos, model)[..., 2].min(axis=1) - floor
    lift = np.zeros_like(z_low)
    if cfg.fix_penetration and np.any(z_low < 0):
        width = max(1, round(cfg.penetration_window_s * cfg.fps) | 1)
        need = np.maximum(0.0, -z_low)
        # A max filter then a box filter of the same width never falls below `need`.
        lift = uniform_filter1d(maximum_filter1d(need, width, mode="nearest"), width,
                                mode="nearest")  # fmt: skip
        lift = np.maximum(lift, need)
        root[:, 2] += lift
    report.update({
        "floor_offset_m": floor,
        "foot_ik_mean_m": [float(v) for v in np.abs(ik).mean(axis=0)] if ik.size else [0.0, 0.0],
        "penetration_lift_max_m": float(lift.max()) if lift.size else 0.0,
        "penetration_lift_mean_m": float(lift.mean()) if lift.size else 0.0,
    })  # fmt: skip
    return quat, root, report
