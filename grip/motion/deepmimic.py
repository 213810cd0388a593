"""DeepMimic reference-motion reader (``humanoid3d`` character).

A DeepMimic motion file is JSON ``{"Loop": ..., "Frames": [[dt, root_pos(3), root_quat(4), ...]]}``
where, after the root, each non-fixed joint of the character skeleton contributes its local
rotation in skeleton order: a quaternion ``(w, x, y, z)`` for spherical joints, one angle (radians)
for revolute joints. The world is Y-up, metres; ``dt`` is the duration of that frame, so frame k
starts at ``sum(dt[:k])``.

Conventions checked against the data (``humanoid3d_walk``): the character faces +x with its
right side at +z; revolute joints (knees, elbows) turn about their local z axis; knee angles
are <= 0 (joint limits [-pi, 0]) and swing the foot backwards, elbow angles >= 0 swing the hand
forwards. Fixed joints (wrists) become joints with identity local rotation.

End sites (``"<joint>_end"``, with their parent's rotation) are placed from the body shapes of the
leaf joints in the character file: a sphere gives the point of the sphere furthest along the
joint's rest offset direction (head top above the neck, hand tip below the wrist); a box gives the
centre of its front (+x) bottom (-y) edge (the toe tip on the sole). Other shapes give no end site.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from grip.core.limits import InputLimits, LimitExceeded, active_limits, safe_json_loads
from grip.motion.source import (
    MotionImportError,
    SourceMotion,
    clean_import_errors,
    identity_rotations,
    read_text_bounded,
    rest_fk,
    source_fk,
)

SKELETON_FILE = "humanoid3d_character_skeleton.txt"

#: humanoid3d joints (name, type, parent, attach offset in the parent frame, metres), from the
#: DeepMimic character file; used when no character file is found next to a clip.
HUMANOID3D_JOINTS: tuple[tuple[str, str, int, tuple[float, float, float]], ...] = (
    ("root", "none", -1, (0.0, 0.0, 0.0)),
    ("chest", "spherical", 0, (0.0, 0.236151, 0.0)),
    ("neck", "spherical", 1, (0.0, 0.223894, 0.0)),
    ("right_hip", "spherical", 0, (0.0, 0.0, 0.084887)),
    ("right_knee", "revolute", 3, (0.0, -0.421546, 0.0)),
    ("right_ankle", "spherical", 4, (0.0, -0.40987, 0.0)),
    ("right_shoulder", "spherical", 1, (-0.02405, 0.2435, 0.18311)),
    ("right_elbow", "revolute", 6, (0.0, -0.274788, 0.0)),
    ("right_wrist", "fixed", 7, (0.0, -0.258947, 0.0)),
    ("left_hip", "spherical", 0, (0.0, 0.0, -0.084887)),
    ("left_knee", "revolute", 9, (0.0, -0.421546, 0.0)),
    ("left_ankle", "spherical", 10, (0.0, -0.40987, 0.0)),
    ("left_shoulder", "spherical", 1, (-0.02405, 0.2435, -0.18311)),
    ("left_elbow", "revolute", 12, (0.0, -0.274788, 0.0)),
    ("left_wrist", "fixed", 13, (0.0, -0.258947, 0.0)),
)

#: humanoid3d body shapes of the leaf joints (shape, attach offset, Param0..2), from the same file.
HUMANOID3D_LEAF_BODIES: dict[str, tuple[str, tuple[float, float, float], tuple[float, ...]]] = {
    "neck": ("sphere", (0.0, 0.175, 0.0), (0.205, 0.205, 0.205)),
    "right_ankle": ("box", (0.045, -0.0225, 0.0), (0.177, 0.055, 0.09)),
    "right_wrist": ("sphere", (0.0, 0.0, 0.0), (0.08, 0.08, 0.08)),
    "left_ankle": ("box", (0.045, -0.0225, 0.0), (0.177, 0.055, 0.09)),
    "left_wrist": ("sphere", (0.0, 0.0, 0.0), (0.08, 0.08, 0.08)),
}

_DOF_SIZE = {"none": 7, "spherical": 4, "revolute": 1, "fixed": 0}


@dataclass(frozen=True)
class DeepMimicSkeleton:
    """A DeepMimic kinematic character.

    Attributes:
        names: (J,) joint names, skeleton order.
        types: (J,) ``"none"`` (root), ``"spherical"``, ``"revolute"`` or ``"fixed"``.
        parents: (J,) parent index, -1 for the root.
        offsets: (J, 3) joint attach offset in the parent frame, metres.
        end_sites: ``(joint index, (3,) offset in that joint's frame)`` per end site.
    """

    names: tuple[str, ...]
    types: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    end_sites: tuple[tuple[int, np.ndarray], ...]

    @property
    def frame_size(self) -> int:
        """Numbers per motion frame: dt + root (7) + 4 per spherical + 1 per revolute."""
        return 1 + sum(_DOF_SIZE[t] for t in self.types)


def _read_json(path: str | os.PathLike, limits: InputLimits) -> object:
    """Parse a JSON file (size, depth and integer digits bounded by ``limits``); failures
    become :class:`MotionImportError` naming the file."""
    path_s = str(path)
    text = read_text_bounded(path, limits)
    try:
        return safe_json_loads(text, limits, "JSON")
    except LimitExceeded as exc:
        raise MotionImportError(path_s, str(exc)) from None
    except json.JSONDecodeError as exc:
        raise MotionImportError(path_s, f"not valid JSON ({exc.msg})", line=exc.lineno) from None


def _end_site(
    shape: str, attach: np.ndarray, params: np.ndarray, joint_offset: np.ndarray
) -> np.ndarray | None:
    if shape == "sphere":
        norm = np.linalg.norm(joint_offset)
        if norm == 0:
            return None
        return attach + 0.5 * params[0] * joint_offset / norm
    if shape == "box":
        return attach + np.array([0.5 * params[0], -0.5 * params[1], 0.0])
    return None


def _build_skeleton(
    joints: list[tuple[str, str, int, tuple[float, float, float]]],
    leaf_bodies: dict[str, tuple[str, tuple[float, float, float], tuple[float, ...]]],
) -> DeepMimicSkeleton:
    parents = np.array([j[2] for j in joints], dtype=np.int64)
    offsets = np.array([j[3] for j in joints], dtype=np.float64)
    has_child = set(parents.tolist())
    ends = []
    for k, (name, *_rest) in enumerate(joints):
        if k in has_child or name not in leaf_bodies:
            continue
        shape, attach, params = leaf_bodies[name]
        tip = _end_site(shape, np.asarray(attach, float), np.asarray(params, float), offsets[k])
        if tip is not None:
            ends.append((k, tip))
    return DeepMimicSkeleton(
        names=tuple(j[0] for j in joints),
        types=tuple(j[1] for j in joints),
        parents=parents,
        offsets=offsets,
        end_sites=tuple(ends),
    )


def humanoid3d_skeleton() -> DeepMimicSkeleton:
    """The built-in humanoid3d character (used when no character file is available)."""
    return _build_skeleton(list(HUMANOID3D_JOINTS), HUMANOID3D_LEAF_BODIES)


@clean_import_errors
def load_deepmimic_skeleton(
    path: str | Path, *, limits: InputLimits | None = None
) -> DeepMimicSkeleton:
    """Read a DeepMimic character file (``{"Skeleton": {"Joints": [...]}, "BodyDefs": [...]}``).

    Raises:
        MotionImportError: Not JSON, missing keys, unknown joint types, non-zero AttachTheta
            (not supported), parents out of order.
    """
    path_s = str(path)
    limits = limits or active_limits()
    data = _read_json(path, limits)
    try:
        raw_joints = data["Skeleton"]["Joints"]
    except (KeyError, TypeError):
        raise MotionImportError(path_s, "no Skeleton.Joints list", key="Skeleton") from None
    joints: list[tuple[str, str, int, tuple[float, float, float]]] = []
    for k, j in enumerate(sorted(raw_joints, key=lambda j: j.get("ID", 0))):
        try:
            name, jtype, parent = str(j["Name"]), str(j["Type"]).lower(), int(j["Parent"])
            attach = (float(j["AttachX"]), float(j["AttachY"]), float(j["AttachZ"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise MotionImportError(
                path_s, f"joint {k}: missing or bad field ({exc})", key="Joints"
            ) from None
        if jtype not in _DOF_SIZE:
            raise MotionImportError(
                path_s, f"joint {name!r}: unsupported type {jtype!r}", key="Type"
            )
        if (k == 0) != (parent == -1) or parent >= k:
            raise MotionImportError(
                path_s, f"joint {name!r}: parent {parent} out of order", key="Parent"
            )
        thetas = [float(j.get(f"AttachTheta{a}", 0.0)) for a in "XYZ"]
        if any(thetas):
            raise MotionImportError(
                path_s, f"joint {name!r}: non-zero AttachTheta is not supported", key="AttachTheta"
            )
        joints.append((name, jtype if k else "none", parent, attach))
    bodies: dict[str, tuple[str, tuple[float, float, float], tuple[float, ...]]] = {}
    for b in data.get("BodyDefs", []) or []:
        try:
            bodies[str(b["Name"])] = (
                str(b["Shape"]).lower(),
                (float(b["AttachX"]), float(b["AttachY"]), float(b["AttachZ"])),
                (float(b["Param0"]), float(b["Param1"]), float(b["Param2"])),
            )
        except (KeyError, TypeError, ValueError):
            continue  # a body we cannot read only costs its end site
    return _build_skeleton(joints, bodies)


def _load_frames(path_s: str, data: Any, frame_size: int, limits: InputLimits) -> np.ndarray:
    if not isinstance(data, dict) or "Frames" not in data:
        raise MotionImportError(path_s, "no 'Frames' list (not a DeepMimic motion)", key="Frames")
    frames = data["Frames"]
    if not isinstance(frames, list) or not frames:
        raise MotionImportError(path_s, "'Frames' must be a non-empty list", key="Frames")
    limits.check("max_frames", len(frames), "frame count")
    for k, fr in enumerate(frames):
        if not isinstance(fr, list) or len(fr) != frame_size:
            got = len(fr) if isinstance(fr, list) else type(fr).__name__
            raise MotionImportError(
                path_s, f"expected {frame_size} numbers, got {got}", frame=k, key="Frames"
            )
    try:
        arr = np.array(frames, dtype=np.float64)
    except (TypeError, ValueError):
        for k, fr in enumerate(frames):
            if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in fr):
                raise MotionImportError(
                    path_s, "non-numeric value", frame=k, key="Frames"
                ) from None
        raise
    bad = ~np.isfinite(arr)
    if bad.any():
        k, c = np.argwhere(bad)[0]
        raise MotionImportError(
            path_s, f"non-finite value in column {int(c)}", frame=int(k), key="Frames"
        )
    return arr


@clean_import_errors
def load_deepmimic(
    path: str | Path,
    skeleton_path: str | Path | None = None,
    *,
    name: str | None = None,
    category: str = "unknown",
    limits: InputLimits | None = None,
) -> SourceMotion:
    """Read a DeepMimic motion clip into a :class:`SourceMotion` (Y-up, metres).

    Args:
        path: The motion file (JSON with a ``"Frames"`` list; ``.txt`` in the DeepMimic repo).
        skeleton_path: Character file; ``None`` uses ``humanoid3d_character_skeleton.txt`` next
            to the clip, or the built-in humanoid3d constants if that file is absent.
        name: Clip id to store; default: the stem without the ``humanoid3d_`` prefix.
        category: Motion category to store.
        limits: Size and rate limits (:class:`grip.core.limits.InputLimits`): the frame rate
            (from the median ``dt``), frames, duration and frames x joints are checked before
            the clip's arrays are built; default :func:`grip.core.limits.active_limits`.

    Returns:
        The clip with ``rig="deepmimic"``, ``unit_m=1``, root at the origin in the rest pose, the
        character's zero pose (standing, arms down, facing +x) as rest pose, end sites included.

    Raises:
        MotionImportError: Invalid JSON, wrong frame size, non-numeric or non-finite values,
            non-positive dt before the last frame, zero quaternions.
    """
    path_s = str(path)
    limits = limits or active_limits()
    if skeleton_path is None:
        default = Path(path).parent / SKELETON_FILE
        skel = (load_deepmimic_skeleton(default, limits=limits) if default.is_file()
                else humanoid3d_skeleton())  # fmt: skip
    else:
        skel = load_deepmimic_skeleton(skeleton_path, limits=limits)
    data = _read_json(path, limits)
    arr = _load_frames(path_s, data, skel.frame_size, limits)
    n_frames = arr.shape[0]
    dt = arr[:, 0]
    if n_frames > 1 and np.any(dt[:-1] <= 0):
        k = int(np.flatnonzero(dt[:-1] <= 0)[0])
        raise MotionImportError(path_s, f"frame duration dt must be > 0, got {dt[k]}", frame=k)
    times = np.concatenate([[0.0], np.cumsum(dt[:-1])])
    n_all = len(skel.names) + len(skel.end_sites)
    if n_frames > 1:
        limits.check_take(n_frames, 1.0 / float(np.median(dt[:-1])), n_all)
        limits.check("max_duration_s", float(times[-1]), "duration (sum of the frames' dt)", " s")
    else:
        limits.check("max_joints", n_all, "joint count")

    n_joints = len(skel.names)
    local_rot = identity_rotations(n_frames, n_joints)
    local_pos = np.broadcast_to(skel.offsets, (n_frames, n_joints, 3)).copy()
    col = 1
    for j, jtype in enumerate(skel.types):
        if jtype in ("none", "spherical"):
            if jtype == "none":
                local_pos[:, j] = arr[:, col : col + 3]
                col += 3
            quat = arr[:, col : col + 4]
            norms = np.linalg.norm(quat, axis=1)
            if np.any(norms < 1e-6):
                k = int(np.flatnonzero(norms < 1e-6)[0])
                raise MotionImportError(
                    path_s, f"zero quaternion for joint {skel.names[j]!r}", frame=k
                )
            local_rot[:, j] = Rotation.from_quat(quat, scalar_first=True).as_matrix()
            col += 4
        elif jtype == "revolute":
            local_rot[:, j] = Rotation.from_rotvec(
                arr[:, col, None] * np.array([0.0, 0.0, 1.0])
            ).as_matrix()
            col += 1

    names = list(skel.names)
    parents = list(skel.parents.tolist())
    offsets = [*skel.offsets]
    ends_local_pos = []
    for j, tip in skel.end_sites:
        names.append(f"{skel.names[j]}_end")
        parents.append(j)
        offsets.append(tip)
        ends_local_pos.append(np.broadcast_to(tip, (n_frames, 3)))
    if ends_local_pos:
        n_ends = len(ends_local_pos)
        local_rot = np.concatenate([local_rot, identity_rotations(n_frames, n_ends)], axis=1)
        local_pos = np.concatenate([local_pos, np.stack(ends_local_pos, axis=1)], axis=1)
    parents_arr = np.array(parents, dtype=np.int64)
    global_rot, global_pos = source_fk(parents_arr, local_rot, local_pos)
    rest_offsets = np.array(offsets)
    rest_offsets[0] = 0.0
    stem = Path(path).stem
    return SourceMotion(
        name=name if name is not None else stem.removeprefix("humanoid3d_"),
        path=path_s,
        fmt="deepmimic",
        rig="deepmimic",
        joint_names=tuple(names),
        parents=parents_arr,
        times_s=times,
        global_rot=global_rot,
        global_pos=global_pos,
        rest_rot=identity_rotations(len(names)),
        rest_pos=rest_fk(parents_arr, rest_offsets),
        up_axis=1,
        unit_m=1.0,
        rest_is_tpose=True,
        category=category,
    )
