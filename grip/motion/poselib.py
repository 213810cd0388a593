"""poselib ``SkeletonMotion`` clips (NVIDIA ASE, IsaacGymEnvs): ``.npy`` files of a pickled dict.

``SkeletonMotion.to_file`` writes ``np.save(path, dict)``: a 0-d object array whose pickle holds

* ``rotation``: ``{"arr": (T, J, 4)}`` joint rotations as quaternions **(x, y, z, w)**, local
  (relative to the parent body) when ``is_local`` is true (as written by ASE), else global;
* ``root_translation``: ``{"arr": (T, 3)}`` world position of the root body, m;
* ``skeleton_tree``: ``{"node_names": [J names], "parent_indices": {"arr": (J,)},
  "local_translation": {"arr": (J, 3)}}``, each body's offset in its parent's frame, m (the
  root's entry is replaced by ``root_translation``);
* ``fps`` (float), ``is_local``, ``global_velocity``/``global_angular_velocity`` (unused) and
  ``__name__`` = ``"SkeletonMotion"``.

The file is read with the project's restricted unpickler (:func:`grip.core.safe_pickle.
load_object_npy`): numpy arrays, dtypes and builtin containers (and ``OrderedDict``) only, never
``np.load(allow_pickle=True)``; a file that names any other global (a planted ``os.system``) is
refused before anything in it runs, with an error naming the file.

World: **z-up**, metres (poselib's convention; checked: the rest skeleton must stand along z).
Forward kinematics as poselib's: a body's world rotation is its parent's times its local one,
its world position the parent's plus the parent's rotation applied to its offset. The rest pose
(all rotations identity) is the skeleton tree itself: for ASE's humanoids a standing pose with
the arms down, facing +x with the left side at +y.

ASE's sword-and-shield humanoid (``rig="ase"``, 17 bodies) carries a sword on the right hand and
a shield on the left forearm: rigid attachments, not body segments, dropped here with anything
below them. Its bodies match DeepMimic's ``humanoid3d`` (same bone offsets); as for that
importer, end sites from the MJCF shapes of the leaf bodies (``amp_humanoid_sword_shield.xml``)
are added: the top of the head sphere, the tips of the hand spheres and the front bottom edge
of each foot box (the toe tip on the sole).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from grip.core.limits import InputLimits, LimitExceeded, active_limits, check_file_size
from grip.core.safe_pickle import NPY_HEADER_MAX_BYTES, RefusedGlobal, load_object_npy, npy_header
from grip.motion.source import (
    MotionImportError,
    SourceMotion,
    check_finite,
    clean_import_errors,
    identity_rotations,
    rest_fk,
    source_fk,
)

#: Bodies of ASE's sword-and-shield humanoid, in file order (``node_names``).
ASE_BODIES: tuple[str, ...] = (
    "pelvis", "torso", "head", "right_upper_arm", "right_lower_arm", "right_hand", "sword",
    "left_upper_arm", "left_lower_arm", "shield", "left_hand", "right_thigh", "right_shin",
    "right_foot", "left_thigh", "left_shin", "left_foot",
)  # fmt: skip

#: Rigid attachments that are not body segments: dropped with their descendants.
PROPS: frozenset[str] = frozenset({"sword", "shield"})

#: End sites of the ASE humanoid: (body, offset in its frame, m), from the MJCF shapes: head
#: sphere at (0, 0, 0.175), radius 0.095; hand spheres of radius 0.04 at the wrist (tip along
#: the forearm, -z); foot boxes centred at (0.045, 0, -0.0225), half sizes (0.0885, 0.045,
#: 0.0275).
ASE_END_SITES: tuple[tuple[str, tuple[float, float, float]], ...] = (
    ("head", (0.0, 0.0, 0.27)),
    ("right_hand", (0.0, 0.0, -0.04)),
    ("left_hand", (0.0, 0.0, -0.04)),
    ("right_foot", (0.1335, 0.0, -0.05)),
    ("left_foot", (0.1335, 0.0, -0.05)),
)

_REQUIRED_KEYS = ("rotation", "root_translation", "skeleton_tree", "fps")
_TREE_KEYS = ("node_names", "parent_indices", "local_translation")
#: An upright rest skeleton is at least this tall along z compared with its horizontal extent.
_MIN_UPRIGHT_RATIO = 0.5


def _read(path: str | Path, limits: InputLimits) -> Any:
    """The object a ``.npy`` holds, unpickled by the restricted unpickler; errors name the file."""
    path_s = str(path)
    check_file_size(path, limits)
    data = Path(path).read_bytes()
    try:
        return load_object_npy(data, limits)
    except RefusedGlobal as e:
        raise MotionImportError(
            path_s,
            f"refused to unpickle global {e.qualname!r}: a poselib clip holds only numpy arrays "
            "and builtin containers (nothing from this file was run)",
        ) from None
    except LimitExceeded:
        raise
    except Exception as e:  # any failure of the parser: a damaged or hostile file
        text = str(e)[:300]
        raise MotionImportError(path_s, f"not a readable poselib .npy ({type(e).__name__}: "
                                        f"{text})") from None  # fmt: skip


def _is_skeleton_motion(obj: Any) -> bool:
    return isinstance(obj, Mapping) and all(k in obj for k in _REQUIRED_KEYS)


def is_poselib_npy(path: str | Path, *, limits: InputLimits | None = None) -> bool:
    """Whether ``path`` is a poselib ``SkeletonMotion`` ``.npy`` (for the clip search).

    A ``.npy`` of a plain array is not (False, read no further than its header); one of a
    pickled object is read with the restricted unpickler and is a clip when it is a dict with
    ``rotation``, ``root_translation``, ``skeleton_tree`` and ``fps``.

    Raises:
        MotionImportError: A file that is not a readable npy, or a pickled object that cannot
            be read safely: a global outside the allow-list (nothing is run), a damaged pickle,
            a size above ``limits``.
    """
    limits = limits or active_limits()
    try:
        with Path(path).open("rb") as fh:
            header, _ = npy_header(fh.read(NPY_HEADER_MAX_BYTES))
        if header.get("descr") != "|O":
            return False  # a numeric array: not a clip
        return _is_skeleton_motion(_read(path, limits))
    except MotionImportError:
        raise
    except LimitExceeded as e:
        raise MotionImportError(path, str(e)) from None
    except ValueError as e:  # npy_header's
        raise MotionImportError(path, f"not a readable npy ({e})") from None
    except OSError as e:
        raise MotionImportError(path, f"cannot read file ({e.strerror or e})") from None


def _array(path_s: str, entry: Any, key: str, ndim: int) -> np.ndarray:
    """A poselib tensor entry (``{"arr": ndarray, "context": ...}`` or a bare array) as a
    float64 or int64 array of ``ndim`` dimensions."""
    arr = entry.get("arr") if isinstance(entry, Mapping) else entry
    if not isinstance(arr, np.ndarray) or arr.dtype.kind not in "fiu" or arr.ndim != ndim:
        got = (f"{arr.dtype} array of shape {arr.shape}" if isinstance(arr, np.ndarray)
               else type(arr).__name__)  # fmt: skip
        raise MotionImportError(path_s, f"expected a numeric {ndim}-d array, got {got}", key=key)
    return arr.astype(np.int64 if arr.dtype.kind in "iu" else np.float64)


def _skeleton(path_s: str, tree: Any) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Names, parents ``(J,)`` and offsets ``(J, 3)`` of a poselib ``skeleton_tree``."""
    if not isinstance(tree, Mapping) or any(k not in tree for k in _TREE_KEYS):
        raise MotionImportError(path_s, f"skeleton_tree must hold {list(_TREE_KEYS)}",
                                key="skeleton_tree")  # fmt: skip
    names = tree["node_names"]
    if not isinstance(names, list | tuple) or not all(isinstance(n, str) for n in names):
        raise MotionImportError(path_s, "node_names must be a list of names", key="node_names")
    parents = _array(path_s, tree["parent_indices"], "parent_indices", 1)
    offsets = _array(path_s, tree["local_translation"], "local_translation", 2)
    n = len(names)
    if n == 0 or parents.shape != (n,) or offsets.shape != (n, 3):
        raise MotionImportError(path_s, f"{n} node_names, parent_indices of shape "
                                f"{parents.shape} and local_translation of shape "
                                f"{offsets.shape} do not agree", key="skeleton_tree")  # fmt: skip
    if parents[0] != -1 or np.any(parents[1:] < 0) or np.any(parents[1:] >= np.arange(1, n)):
        raise MotionImportError(path_s, "parent_indices must be -1 for the first body and "
                                "name an earlier body for every other",
                                key="parent_indices")  # fmt: skip
    check_finite(path_s, "local_translation", offsets)
    return list(names), parents, offsets


def _keep_bodies(names: list[str], parents: np.ndarray) -> np.ndarray:
    """Indices of the bodies that are neither a prop (:data:`PROPS`) nor below one."""
    dropped = np.zeros(len(names), dtype=bool)
    for j, name in enumerate(names):
        dropped[j] = name in PROPS or (parents[j] >= 0 and dropped[parents[j]])
    return np.flatnonzero(~dropped)


@clean_import_errors
def load_poselib(
    path: str | Path,
    *,
    name: str | None = None,
    category: str = "unknown",
    limits: InputLimits | None = None,
) -> SourceMotion:
    """Read a poselib ``SkeletonMotion`` ``.npy`` into a :class:`SourceMotion` (z-up, metres).

    Args:
        path: The ``.npy`` file.
        name: Clip id to store; default: the file's stem.
        category: Motion category to store.
        limits: Size and rate limits (:class:`grip.core.limits.InputLimits`): the pickle's
            arrays and containers while it is read, then the frame rate, frames, duration and
            frames x joints; default :func:`grip.core.limits.active_limits`.

    Returns:
        The clip with ``fmt="poselib"``, ``rig="ase"`` for ASE's humanoid, with or without
        sword and shield (props dropped, end sites added), ``"unknown"`` for other skeletons,
        ``up_axis=2``, ``unit_m=1``, the skeleton tree (all rotations identity) as rest pose,
        frame k at ``k / fps``.

    Raises:
        MotionImportError: Naming the file: a refused pickle global, a damaged file, missing
            keys, shapes that disagree, non-finite values, zero quaternions, a rest skeleton
            that does not stand along z, or a limit exceeded.
    """
    path_s = str(path)
    limits = limits or active_limits()
    d = _read(path, limits)
    if not _is_skeleton_motion(d):
        what = (f"keys {sorted(map(str, d))[:8]}" if isinstance(d, Mapping)
                else f"a pickled {type(d).__name__}")  # fmt: skip
        raise MotionImportError(path_s, f"not a poselib SkeletonMotion ({what}; needs "
                                        f"{list(_REQUIRED_KEYS)})")  # fmt: skip
    names, parents, offsets = _skeleton(path_s, d["skeleton_tree"])
    quat = _array(path_s, d["rotation"], "rotation", 3)
    root = _array(path_s, d["root_translation"], "root_translation", 2)
    n_frames, n_bodies = quat.shape[0], len(names)
    if quat.shape != (n_frames, n_bodies, 4) or root.shape != (n_frames, 3) or n_frames == 0:
        raise MotionImportError(path_s, f"rotation {quat.shape} and root_translation "
                                f"{root.shape} do not fit {n_bodies} bodies (expected (T, "
                                f"{n_bodies}, 4) and (T, 3), T >= 1)")  # fmt: skip
    fps = d["fps"]
    if isinstance(fps, np.ndarray) and fps.shape == ():
        fps = fps.item()
    if not isinstance(fps, int | float | np.number) or isinstance(fps, bool):
        raise MotionImportError(path_s, f"fps must be a number, got {type(fps).__name__}",
                                key="fps")  # fmt: skip
    is_local = d.get("is_local", True)
    if not isinstance(is_local, bool | np.bool_):
        raise MotionImportError(path_s, "is_local must be true or false", key="is_local")
    keep = _keep_bodies(names, parents)
    rig = "ase" if set(ASE_BODIES) - PROPS <= set(names) else "unknown"  # (with or without props)
    ends = [(names.index(b), np.array(off)) for b, off in ASE_END_SITES] if rig == "ase" else []
    limits.check_take(n_frames, float(fps), len(keep) + len(ends))
    check_finite(path_s, "rotation", quat)
    check_finite(path_s, "root_translation", root)
    with np.errstate(over="ignore"):  # a damaged file's 1e300 is refused below, not warned
        norms = np.linalg.norm(quat, axis=-1)
    bad = ~(norms > 1e-6) | ~np.isfinite(norms)
    if np.any(bad):
        k, j = np.argwhere(bad)[0]
        raise MotionImportError(path_s, f"zero or overflowing quaternion for body {names[j]!r} "
                                f"(norm {norms[k, j]:.3g})", frame=int(k))  # fmt: skip
    # poselib stores (x, y, z, w); SciPy is told the order explicitly (STYLE: w-first elsewhere).
    wxyz = (quat / norms[..., None])[..., [3, 0, 1, 2]]
    rot = Rotation.from_quat(wxyz.reshape(-1, 4), scalar_first=True).as_matrix()
    rot = rot.reshape(n_frames, n_bodies, 3, 3)
    if not is_local:  # global rotations: local = parent^T @ own
        rot[:, 1:] = np.swapaxes(rot[:, parents[1:]], -1, -2) @ rot[:, 1:]

    # Props and their subtrees leave the skeleton; end sites join it.
    new_index = {int(old): new for new, old in enumerate(keep)}
    out_names = [names[j] for j in keep]
    out_parents = [-1 if parents[j] < 0 else new_index[int(parents[j])] for j in keep]
    local_rot = rot[:, keep]
    local_pos = np.broadcast_to(offsets[keep], (n_frames, len(keep), 3)).copy()
    local_pos[:, 0] = root
    rest_offsets = [*offsets[keep]]
    for j, tip in ends:
        out_names.append(f"{names[j]}_end")
        out_parents.append(new_index[j])
        rest_offsets.append(tip)
    if ends:
        tips = np.stack([tip for _, tip in ends])
        local_rot = np.concatenate([local_rot, identity_rotations(n_frames, len(ends))], axis=1)
        local_pos = np.concatenate([local_pos, np.broadcast_to(tips, (n_frames, *tips.shape))],
                                   axis=1)  # fmt: skip
    parents_arr = np.array(out_parents, dtype=np.int64)
    rest_pos = rest_fk(parents_arr, np.array(rest_offsets))
    extent = np.ptp(rest_pos, axis=0)
    if extent[2] < _MIN_UPRIGHT_RATIO * extent[:2].max() or extent[2] <= 0:
        raise MotionImportError(path_s, f"the rest skeleton is {extent[2]:.2f} m tall along z "
                                f"but {extent[:2].max():.2f} m wide: not z-up (poselib clips "
                                "are z-up; convert the file)")  # fmt: skip
    global_rot, global_pos = source_fk(parents_arr, local_rot, local_pos)
    return SourceMotion(
        name=name if name is not None else Path(path).stem,
        path=path_s,
        fmt="poselib",
        rig=rig,
        joint_names=tuple(out_names),
        parents=parents_arr,
        times_s=np.arange(n_frames) / float(fps),
        global_rot=global_rot,
        global_pos=global_pos,
        rest_rot=identity_rotations(len(out_names)),
        rest_pos=rest_pos,
        up_axis=2,
        unit_m=1.0,
        rest_is_tpose=True,
        category=category,
    )
