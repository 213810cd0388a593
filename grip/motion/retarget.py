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

import itertools
from dataclasses import asdict, dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d, maximum_filter1d, uniform_filter1d

from grip.core import skeleton as sk
from grip.core.body import CANONICAL_TO_WORLD, BodyModel, BodyParams, build_body
from grip.core.fk import forward_kinematics, sole_points
from grip.core.rotations import (
    axis_angle_to_matrix,
    matrix_to_axis_angle,
    matrix_to_quat,
    quat_to_matrix,
    resample_linear,
    resample_quats,
    rotation_between,
)
from grip.motion.joint_maps import resolve_joint_map
from grip.motion.motion import Motion
from grip.motion.quality import body_low_points
from grip.motion.source import MotionImportError, SourceMotion

_J = sk.JOINT_INDEX

#: Child that defines each segment's bone direction (segment -> joint at its distal end).
MAIN_CHILD: dict[int, int] = {
    0: 3, 1: 4, 2: 5, 3: 6, 4: 7, 5: 8, 6: 9, 7: 10, 8: 11, 9: 12, 12: 15, 13: 16, 14: 17,
    16: 18, 17: 19, 18: 20, 19: 21, 20: 22, 21: 23,
}  # fmt: skip

#: The spine/neck chain, root to head: unmapped joints between two mapped ones share the bend.
SPINE_CHAIN: tuple[int, ...] = (0, 3, 6, 9, 12, 15)

#: Segments without a measurable bone whose reference-pose *world* orientation counts as neutral
#: (feet flat, head level in a standing reference pose); other such segments (hands, a neck
#: without a mapped head) keep their reference-pose rotation *relative to the parent* instead,
#: which is right for hands whether the arms are out (T-pose) or hanging.
ABSOLUTE_SEGMENTS: frozenset[int] = frozenset({7, 8, 10, 11, 15})

#: Segments whose twist is also aligned with a lateral line: segment -> (left joint, right joint).
_LATERAL_PAIRS: dict[int, tuple[int, int]] = {0: (1, 2), 9: (16, 17)}

#: Legs as (hip, knee, ankle, toe) joint indices, left then right.
_LEGS: tuple[tuple[int, int, int, int], ...] = ((1, 4, 7, 10), (2, 5, 8, 11))

#: Source bones shorter than this (m) count as degenerate (zero-length end sites).
_MIN_BONE_M = 0.01
#: Flat foot plants higher than this above the lowest ones (10th percentile) stand on a step or
#: prop and do not define the floor, m.
_FLOOR_BAND_M = 0.03
#: Planted flat foot-frames needed to take the floor height from the feet.
_MIN_FLAT_FOOT_FRAMES = 10
#: Source planted-foot rule: ankle within this height of its lowest (m), slower than this (m/s),
#: shank within this angle of vertical (deg).
_PLANT_HEIGHT_M, _PLANT_SPEED_MPS, _PLANT_SHANK_DEG = 0.04, 0.2, 40.0
_PLANT_SPEED_LOOSE_MPS = 1.0
#: Planted source frames needed per foot to calibrate it (3 frames = 0.1 s at 30 Hz).
_MIN_PLANTED_FRAMES = 3
_DOWN = np.array([0.0, -1.0, 0.0])
_Y = np.array([0.0, 1.0, 0.0])
_Z = np.array([0.0, 0.0, 1.0])


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
            planted source feet (see :func:`fit_floor_tilt`; at most 3 deg, >= 1.5 m of travel).
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


# --------------------------------------------------------------------------- frames and bases
def world_from_source(up_axis: int) -> np.ndarray:
    """Fixed rotation ``(3, 3)`` from a source world with the given up axis to the z-up world.

    y-up: :data:`CANONICAL_TO_WORLD` (x -> -x, y -> z, z -> y), so a source whose rest pose faces
    +z with its left at +x (CMU, HDM05, SMPL) faces +y with its left at -x, exactly as our body.
    z-up: identity. x-up: the cyclic permutation x -> z, y -> x, z -> y.
    """
    if up_axis == 1:
        return CANONICAL_TO_WORLD.copy()
    if up_axis == 2:
        return np.eye(3)
    if up_axis == 0:
        return np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    raise ValueError(f"up_axis must be 0, 1 or 2, got {up_axis!r}")


def body_basis(left_vec: np.ndarray, up_axis: int) -> tuple[np.ndarray, np.ndarray]:
    """Yaw-only body bases ``[left, up, forward]`` (columns) in source world axes.

    Args:
        left_vec: ``(..., 3)`` a vector towards the subject's left (e.g. left hip - right hip),
            source world axes; only its horizontal part is used.
        up_axis: Index of the source's up axis.

    Returns:
        ``(..., 3, 3)`` rotations mapping canonical (x left, y up, z forward) to the source world,
        and ``(...)`` the length of the horizontal part (0 where the heading is undefined).
    """
    up = np.zeros(3)
    up[up_axis] = 1.0
    left = np.asarray(left_vec, dtype=np.float64).copy()
    left[..., up_axis] = 0.0
    norm = np.linalg.norm(left, axis=-1)
    fallback = np.zeros(3)
    fallback[(up_axis + 1) % 3] = 1.0
    left = np.where(norm[..., None] > 1e-9, left / np.maximum(norm, 1e-12)[..., None], fallback)
    fwd = np.cross(left, up)
    return np.stack([left, np.broadcast_to(up, left.shape), fwd], axis=-1), norm


def reference_basis(
    ref_pos: np.ndarray, smpl_to_src: dict[int, int], rest_joint_pos: np.ndarray
) -> np.ndarray | None:
    """Rotation from our canonical axes to the source world axes of the reference pose's body.

    The source body's frame is built from its hip line (left hip - right hip) and trunk (pelvis
    to the highest mapped of neck, chest, head or spine joints, made orthogonal to the hip line),
    and matched to the frame our rest skeleton builds from the same joints. Taking the axes from
    the body rather than the world lets any reference pose work, e.g. the zero pose of an
    SMPL/AMASS rig, which lies along the y axis of a z-up world; matching them to our own trunk
    (which leans ~2 deg) keeps a source identical to our skeleton exact.

    Args:
        ref_pos: ``(J, 3)`` source joint positions of the reference pose.
        smpl_to_src: SMPL joint index -> source joint index.
        rest_joint_pos: ``(24, 3)`` our rest joint positions, canonical frame.

    Returns:
        ``(3, 3)`` rotation ``B`` (columns: where our left, up and forward axes point in the
        source world), or None when the hips coincide or are parallel to the trunk.
    """
    top = next(_J[j] for j in ("Neck", "Spine3", "Head", "Spine2", "Spine1")
               if _J[j] in smpl_to_src)  # fmt: skip
    frames = []
    for pos, idx in ((ref_pos, smpl_to_src), (rest_joint_pos, {j: j for j in range(24)})):
        left = pos[idx[_J["L_Hip"]]] - pos[idx[_J["R_Hip"]]]
        up = pos[idx[top]] - pos[idx[_J["Pelvis"]]]
        if np.linalg.norm(left) < 1e-6 or np.linalg.norm(np.cross(left, up)) < 1e-9:
            return None
        frames.append(_frame_from(left, up))
    return frames[0] @ frames[1].T


# --------------------------------------------------------------------------- helpers
def _is_descendant(parents: np.ndarray, node: int, ancestor: int) -> bool:
    p = int(parents[node])
    while p >= 0:
        if p == ancestor:
            return True
        p = int(parents[p])
    return False


def _normalize(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _frame_from(primary: np.ndarray, secondary: np.ndarray) -> np.ndarray:
    """Orthonormal frame ``(3, 3)`` with columns (primary, secondary made orthogonal, cross)."""
    a = _normalize(primary)
    b = _normalize(secondary - np.dot(secondary, a) * a)
    return np.stack([a, b, np.cross(a, b)], axis=-1)


@dataclass(frozen=True)
class _Bone:
    """How one mapped segment's bone direction is measured (or that it inherits a swing)."""

    smpl: int
    src: int
    src_child: int | None  # source joint at the bone's distal end, None: inherit parent swing
    dir_ours: np.ndarray  # (3,) our rest bone direction, canonical frame


def _segment_bones(
    smpl_to_src: dict[int, int], parents: np.ndarray, rest_pos_src: np.ndarray, body: BodyModel
) -> dict[int, _Bone]:
    """Bone definition of every mapped segment (see the module docstring, step 3)."""
    bones: dict[int, _Bone] = {}
    for j, s in smpl_to_src.items():
        c = MAIN_CHILD.get(j)
        chosen: int | None = None
        while c is not None:
            sc = smpl_to_src.get(c)
            if (
                sc is not None
                and sc != s
                and _is_descendant(parents, sc, s)
                and np.linalg.norm(rest_pos_src[sc] - rest_pos_src[s]) > _MIN_BONE_M
            ):
                chosen = c
                break
            c = MAIN_CHILD.get(c)  # walk on through unmapped or zero-length links
        if chosen is None:
            bones[j] = _Bone(j, s, None, np.zeros(3))
        else:
            d = body.rest_joint_pos[chosen] - body.rest_joint_pos[j]
            bones[j] = _Bone(j, s, smpl_to_src[chosen], _normalize(d))
    return bones


def _neutral_directions(bones: dict[int, _Bone]) -> dict[int, np.ndarray]:
    """Canonical neutral-standing bone direction per measured segment: our rest direction, but
    arms (shoulder, elbow, wrist, hand segments) hanging down."""
    out = {}
    for j, bone in bones.items():
        if bone.src_child is None:
            continue
        out[j] = _DOWN if j >= 16 else bone.dir_ours
    return out


def neutral_frame(
    src: SourceMotion, smpl_to_src: dict[int, int], body: BodyModel | None = None
) -> tuple[int, np.ndarray]:
    """The clip frame closest to neutral standing.

    Score per frame: sum over measured segments of the angle (rad) between the source bone
    direction and its neutral direction (legs and trunk vertical, arms down, feet forward and
    slightly down), expressed in that frame's yaw-only body basis (from the hip line).

    Args:
        src: The clip.
        smpl_to_src: SMPL joint index -> source joint index.
        body: Body model giving our rest bone directions (default body if None).

    Returns:
        The best frame index and the ``(T,)`` scores, rad.
    """
    body = body or build_body()
    bones = _segment_bones(smpl_to_src, src.parents, src.rest_pos, body)
    neutral = _neutral_directions(bones)
    seg = sorted(neutral)
    if not seg:
        return 0, np.zeros(src.num_frames)
    s_idx = np.array([bones[j].src for j in seg])
    c_idx = np.array([bones[j].src_child for j in seg])
    dirs = _normalize(src.global_pos[:, c_idx] - src.global_pos[:, s_idx])  # (T, M, 3)
    lhip, rhip = smpl_to_src[_J["L_Hip"]], smpl_to_src[_J["R_Hip"]]
    basis, hnorm = body_basis(src.global_pos[:, lhip] - src.global_pos[:, rhip], src.up_axis)
    target = np.einsum("tab,mb->tma", basis, np.stack([neutral[j] for j in seg]))
    cos = np.clip(np.sum(dirs * target, axis=-1), -1.0, 1.0)
    score = np.arccos(cos).sum(axis=1)
    score = np.where(hnorm > 1e-6, score, np.inf)
    return int(np.argmin(score)), score


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


def _segment_offsets(
    bones: dict[int, _Bone],
    smpl_to_src: dict[int, int],
    ref_rot: np.ndarray,
    ref_pos: np.ndarray,
    b_src: np.ndarray,
    model: BodyModel,
) -> tuple[list[int], np.ndarray]:
    """Per mapped segment the fixed offset ``K`` with ``G(t) = W @ S(t) @ K`` (step 3).

    Returns:
        The mapped SMPL joints in order and their ``(M, 3, 3)`` offsets.
    """
    swing: dict[int, np.ndarray] = {}
    order = sorted(smpl_to_src)
    k_mats = np.empty((len(order), 3, 3))
    for m, j in enumerate(order):
        bone = bones[j]
        a = int(sk.PARENTS[j])
        while a >= 0 and a not in swing:
            a = int(sk.PARENTS[a])
        q_parent = swing[a] if a >= 0 else np.eye(3)
        if bone.src_child is None:
            q = np.eye(3) if j in ABSOLUTE_SEGMENTS else q_parent
        else:
            b = ref_pos[bone.src_child] - ref_pos[bone.src]
            target = b_src @ bone.dir_ours
            # Swing the bone as its parent was swung, then by the least residual rotation:
            # an unchanged joint (e.g. a straight elbow) keeps its reference twist.
            q = rotation_between(q_parent @ b, target) @ q_parent
            pair = _LATERAL_PAIRS.get(j)
            if pair is not None and pair[0] in smpl_to_src and pair[1] in smpl_to_src:
                lat_src = ref_pos[smpl_to_src[pair[0]]] - ref_pos[smpl_to_src[pair[1]]]
                lat_ours = model.rest_joint_pos[pair[0]] - model.rest_joint_pos[pair[1]]
                if np.linalg.norm(np.cross(_normalize(b), _normalize(lat_src))) > 0.1:
                    q = _frame_from(target, b_src @ lat_ours) @ _frame_from(b, lat_src).T
        swing[j] = q
        k_mats[m] = (q @ ref_rot[bone.src]).T @ b_src
    return order, k_mats


def _leg_length(pos: np.ndarray, smpl_to_src: dict[int, int]) -> float:
    """Mean over both sides of thigh + shank bone length of a pose ``(J, 3)``, m."""
    total = 0.0
    for hip, knee, ankle, _ in _LEGS:
        h, k, a = smpl_to_src[hip], smpl_to_src[knee], smpl_to_src[ankle]
        total += np.linalg.norm(pos[k] - pos[h]) + np.linalg.norm(pos[a] - pos[k])
    return float(total / 2)


def _share_spine(g: np.ndarray, mapped: np.ndarray) -> np.ndarray:
    """Fill unmapped spine-chain joints between two mapped ones by equal slerp fractions.

    Args:
        g: ``(T, 24, 3, 3)`` global rotations; rows of mapped joints are set, the filled ones are
            written in place.
        mapped: ``(24,)`` which joints are mapped.

    Returns:
        ``(24,)`` mask of the joints filled here.
    """
    filled = np.zeros(sk.N_JOINTS, dtype=bool)
    anchors = [k for k, j in enumerate(SPINE_CHAIN) if mapped[j]]
    for a, b in itertools.pairwise(anchors):
        gap = SPINE_CHAIN[a + 1 : b]
        if not gap:
            continue
        ga = g[:, SPINE_CHAIN[a]]
        aa = matrix_to_axis_angle(np.swapaxes(ga, -1, -2) @ g[:, SPINE_CHAIN[b]])  # a's frame
        n = len(gap) + 1
        for k, j in enumerate(gap, start=1):
            g[:, j] = ga @ axis_angle_to_matrix(aa * (k / n))
            filled[j] = True
    return filled


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
    """Move each ankle vertically by ``lift`` with two-bone IK, keeping the foot's orientation.

    The knee stays in the plane it bends in (its offset from the hip-ankle line; the thigh's
    forward axis for a straight leg); targets out of reach are clamped to the reachable range.

    Args:
        local_rot: ``(T, 24, 3, 3)`` local rotations.
        root: ``(T, 3)`` root positions, m.
        body: The body model.
        lift: ``(T, 2)`` vertical ankle displacement of the left and right leg, m.

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
        target = pa + lift[:, f, None] * _Z
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
