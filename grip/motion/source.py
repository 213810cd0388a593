"""The common in-memory type for imported motion-capture clips, plus small shared helpers.

Every importer in :mod:`grip.motion` (BVH, ASF/AMC, DeepMimic, AMASS, poselib) returns a
:class:`SourceMotion`: the clip as the capture rig describes it, in the source's world axes but
already converted to metres, with world (global) joint rotations and positions for every frame.
Retargeting onto the project's body model happens later and is not this module's business.

Conventions: rotation matrices act on column vectors (``v_world = R @ v_local``); a joint's
"local" rotation is relative to its parent joint's frame; shapes use T frames and J joints.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from grip.core.limits import InputLimits, LimitExceeded, check_file_size

SOURCE_FORMATS = ("bvh", "asf_amc", "deepmimic", "amass", "poselib")
"""Values allowed in :attr:`SourceMotion.fmt`."""


class MotionImportError(ValueError):
    """A motion file could not be read. The message always names the file and the problem.

    Example message: ``"clip.bvh: line 57: expected 132 channel values, got 130"``.

    Attributes:
        path: The offending file, as given by the caller.
        problem: What is wrong, without the location prefix.
        line: 1-based line number in the file, when known.
        frame: Frame number (as numbered by the file, or 0-based index), when known.
        key: Key / field name (npz key, JSON key, ASF keyword), when relevant.
    """

    def __init__(
        self,
        path: str | Path,
        problem: str,
        line: int | None = None,
        frame: int | None = None,
        key: str | None = None,
    ) -> None:
        self.path = str(path)
        self.problem = problem
        self.line = line
        self.frame = frame
        self.key = key
        where = [self.path]
        if line is not None:
            where.append(f"line {line}")
        if frame is not None:
            where.append(f"frame {frame}")
        if key is not None:
            where.append(f"key {key!r}")
        super().__init__(": ".join([*where, problem]))

    def __reduce__(self):  # keep picklable (multiprocessing) despite the custom signature
        return (type(self), (self.path, self.problem, self.line, self.frame, self.key))


@dataclass(frozen=True)
class SourceMotion:
    """A clip as the capture rig describes it, before retargeting. Source world axes, metres.

    Attributes:
        name: Clip id, e.g. ``"cmu/02_01"``.
        path: File the motion came from.
        fmt: ``"bvh" | "asf_amc" | "deepmimic" | "amass" | "poselib"``.
        rig: Joint-map key: ``"bandai"``, ``"cmu_daz"``, ``"asf"``, ``"deepmimic"``, ``"ase"``,
            ``"smpl"`` or ``"unknown"``.
        joint_names: J names. BVH/ASF end sites are included as extra joints named
            ``"<parent>_end"``.
        parents: (J,) int, -1 for the root; ``parents[j] < j``.
        times_s: (T,) seconds from the first frame (DeepMimic's dt varies, so no fixed fps here).
        global_rot: (T, J, 3, 3) world rotation of each joint's frame (end sites: their parent's).
        global_pos: (T, J, 3) world joint positions in metres.
        rest_rot: (J, 3, 3) global rotations of the zero pose (all channels zero; ASF: the ASF
            rest pose).
        rest_pos: (J, 3) global joint positions of the zero pose, metres, root at its offset.
        up_axis: Index of the world's up axis (1 = y for BVH, ASF/AMC and DeepMimic; 2 = z for
            AMASS and poselib).
        unit_m: Metres per file unit that was applied (BVH cm -> 0.01; ASF length 0.45 ->
            0.05644; DeepMimic 1.0).
        rest_is_tpose: True where the zero pose is an anatomical T-pose or standing pose.
        category: Motion category (``"walk"``, ``"run"``, ``"jump"``, ...) or ``"unknown"``.
    """

    name: str
    path: str
    fmt: str
    rig: str
    joint_names: tuple[str, ...]
    parents: np.ndarray
    times_s: np.ndarray
    global_rot: np.ndarray
    global_pos: np.ndarray
    rest_rot: np.ndarray
    rest_pos: np.ndarray
    up_axis: int
    unit_m: float
    rest_is_tpose: bool
    category: str

    def __post_init__(self) -> None:
        j = len(self.joint_names)
        t = self.times_s.shape[0] if self.times_s.ndim == 1 else -1
        expected = {
            "parents": (self.parents, (j,)),
            "times_s": (self.times_s, (t,)),
            "global_rot": (self.global_rot, (t, j, 3, 3)),
            "global_pos": (self.global_pos, (t, j, 3)),
            "rest_rot": (self.rest_rot, (j, 3, 3)),
            "rest_pos": (self.rest_pos, (j, 3)),
        }
        for field, (arr, shape) in expected.items():
            if not isinstance(arr, np.ndarray) or arr.shape != shape:
                got = getattr(arr, "shape", type(arr).__name__)
                raise ValueError(
                    f"SourceMotion {self.name!r}: {field} has shape {got}, expected {shape}"
                )
        if np.any(self.parents >= np.arange(j)) or np.any(self.parents < -1):
            raise ValueError(
                f"SourceMotion {self.name!r}: parents must satisfy -1 <= parents[j] < j"
            )
        if self.fmt not in SOURCE_FORMATS:
            raise ValueError(f"SourceMotion {self.name!r}: unknown fmt {self.fmt!r}")
        if self.up_axis not in (0, 1, 2):
            raise ValueError(f"SourceMotion {self.name!r}: up_axis must be 0, 1 or 2")

    @property
    def num_frames(self) -> int:
        """T, the number of frames."""
        return int(self.times_s.shape[0])

    @property
    def num_joints(self) -> int:
        """J, the number of joints (end sites included)."""
        return len(self.joint_names)

    @property
    def duration_s(self) -> float:
        """Time of the last frame, seconds (0 for a single frame)."""
        return float(self.times_s[-1]) if self.num_frames else 0.0

    def joint_index(self, name: str) -> int:
        """Index of the joint called ``name``; raises ``KeyError`` naming the clip if absent."""
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise KeyError(f"{self.name}: no joint named {name!r}") from None

    def rest_height_m(self) -> float:
        """Extent of the rest skeleton along the up axis (max - min), metres."""
        up = self.rest_pos[:, self.up_axis]
        return float(up.max() - up.min())


def source_fk(
    parents: np.ndarray, local_rot: np.ndarray, local_pos: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Batched forward kinematics of a joint tree.

    Joint j's frame is ``parent_frame @ (local_rot[j], local_pos[j])``: its world rotation is
    ``global_rot[parent] @ local_rot[j]`` and its world position is
    ``global_pos[parent] + global_rot[parent] @ local_pos[j]``. The root (parent -1) takes its
    local values as world values. Vectorised over the leading dimensions; loops over joints only.

    Args:
        parents: (J,) int parent indices, -1 for roots, ``parents[j] < j``.
        local_rot: (..., J, 3, 3) rotation of each joint relative to its parent's frame.
        local_pos: (..., J, 3) joint offset from the parent joint in the parent's frame (the root's
            entry is its world position). Any unit; the output uses the same one. Leading
            dimensions broadcast against ``local_rot``'s.

    Returns:
        ``(global_rot, global_pos)``: (..., J, 3, 3) world rotations and (..., J, 3) world
        positions, with the broadcast leading shape of the inputs.
    """
    parents = np.asarray(parents, dtype=np.int64)
    local_rot = np.asarray(local_rot, dtype=np.float64)
    local_pos = np.asarray(local_pos, dtype=np.float64)
    num_joints = parents.shape[0]
    if local_rot.shape[-3:] != (num_joints, 3, 3) or local_pos.shape[-2:] != (num_joints, 3):
        raise ValueError(
            f"source_fk: expected (..., {num_joints}, 3, 3) and (..., {num_joints}, 3), got "
            f"{local_rot.shape} and {local_pos.shape}"
        )
    lead = np.broadcast_shapes(local_rot.shape[:-3], local_pos.shape[:-2])
    local_rot = np.broadcast_to(local_rot, (*lead, num_joints, 3, 3))
    local_pos = np.broadcast_to(local_pos, (*lead, num_joints, 3))
    global_rot = np.empty((*lead, num_joints, 3, 3))
    global_pos = np.empty((*lead, num_joints, 3))
    for j in range(num_joints):
        p = int(parents[j])
        if p < 0:
            global_rot[..., j, :, :] = local_rot[..., j, :, :]
            global_pos[..., j, :] = local_pos[..., j, :]
        else:
            if p >= j:
                raise ValueError(f"source_fk: parents[{j}] = {p} is not < {j}")
            global_rot[..., j, :, :] = global_rot[..., p, :, :] @ local_rot[..., j, :, :]
            global_pos[..., j, :] = global_pos[..., p, :] + np.einsum(
                "...ab,...b->...a", global_rot[..., p, :, :], local_pos[..., j, :]
            )
    return global_rot, global_pos


def rest_fk(parents: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Positions of a skeleton whose joints all have identity rotation.

    Args:
        parents: (J,) parent indices, -1 for the root.
        offsets: (J, 3) offset of each joint from its parent (root: its position).

    Returns:
        (J, 3) joint positions in the units of ``offsets``.
    """
    pos = np.zeros_like(np.asarray(offsets, dtype=np.float64))
    for j, p in enumerate(np.asarray(parents)):
        pos[j] = offsets[j] if p < 0 else pos[p] + offsets[j]
    return pos


def identity_rotations(*shape: int) -> np.ndarray:
    """Identity rotation matrices of shape ``(*shape, 3, 3)``."""
    return np.broadcast_to(np.eye(3), (*shape, 3, 3)).copy()


def check_finite(path: str | Path, what: str, arr: np.ndarray) -> None:
    """Raise :class:`MotionImportError` if ``arr`` has NaN/inf, naming the first bad frame.

    Args:
        path: File the values came from (for the message).
        what: Name of the quantity (key or field), used in the message.
        arr: (T, ...) array; the first axis is reported as the frame index.
    """
    bad = ~np.isfinite(arr)
    if bad.any():
        frame = int(np.argwhere(bad)[0][0]) if arr.ndim else None
        raise MotionImportError(
            path, f"{int(bad.sum())} non-finite (NaN/inf) value(s) in {what}", frame=frame
        )


_F = TypeVar("_F", bound=Callable[..., Any])


def clean_import_errors(func: _F) -> _F:
    """Decorates a loader ``func(path, ...)`` so that every failure is a MotionImportError.

    A :class:`~grip.core.limits.LimitExceeded` keeps its message; any other unexpected exception
    of the parsers (``RecursionError``, ``LookupError``, ``zlib.error``, ...) becomes
    ``MotionImportError(path, "cannot read (<type>: <message>)")``.
    """

    @functools.wraps(func)
    def wrapper(path: Any, *args: Any, **kwargs: Any) -> Any:
        try:
            return func(path, *args, **kwargs)
        except MotionImportError:
            raise
        except LimitExceeded as exc:
            raise MotionImportError(path, str(exc)) from None
        except OSError as exc:
            raise MotionImportError(path, f"cannot read file ({exc.strerror or exc})") from None
        except Exception as exc:  # a malformed or hostile file: never a traceback
            text = str(exc)
            text = text if len(text) <= 300 else text[:300] + "..."
            raise MotionImportError(path, f"cannot read ({type(exc).__name__}: {text})") from None

    return wrapper  # type: ignore[return-value]


def read_text_bounded(path: str | Path, limits: InputLimits) -> str:
    """The text of ``path`` (UTF-8, BOM stripped, bad bytes replaced), size checked first.

    Raises:
        MotionImportError: The file cannot be read or is above ``limits.max_file_bytes``.
    """
    try:
        check_file_size(path, limits)
        return Path(path).read_text(encoding="utf-8-sig", errors="replace")
    except LimitExceeded as exc:
        raise MotionImportError(path, str(exc)) from None
    except OSError as exc:
        raise MotionImportError(path, f"cannot read file ({exc.strerror or exc})") from exc
