"""Orientation transfer of :func:`grip.motion.retarget.retarget` (steps 1-3 and 5 of its
method): source world and body bases, bone definitions, the neutral reference frame, the
per-segment offsets ``K`` and the sharing of the spine bend."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from grip.core import skeleton as sk
from grip.core.body import CANONICAL_TO_WORLD, BodyModel, build_body
from grip.core.rotations import axis_angle_to_matrix, matrix_to_axis_angle, rotation_between
from grip.motion.source import SourceMotion

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

#: Source bones shorter than this (m) count as degenerate (zero-length end sites).
_MIN_BONE_M = 0.01
_DOWN = np.array([0.0, -1.0, 0.0])


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
    """Bone definition of every mapped segment (see :mod:`grip.motion.retarget`, step 3)."""
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
