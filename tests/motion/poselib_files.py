"""Synthetic poselib ``SkeletonMotion`` files for tests (nothing derived from ASE's motion data).

The skeleton is ASE's sword-and-shield humanoid as poselib stores it: DeepMimic's humanoid3d
bones (``grip.motion.deepmimic.HUMANOID3D_JOINTS``, MIT) turned from y-up to z-up, plus a sword
and a shield at made-up offsets. The file layout is what ``SkeletonMotion.to_file`` writes:
``np.save`` of a dict of ``{"arr": ndarray, "context": {...}}`` entries.
"""

from __future__ import annotations

from collections import OrderedDict
from pathlib import Path

import numpy as np

from grip.motion.deepmimic import HUMANOID3D_JOINTS
from grip.motion.poselib import ASE_BODIES

ASE_PARENTS = np.array([-1, 0, 1, 1, 3, 4, 5, 1, 7, 8, 8, 0, 11, 12, 0, 14, 15])
_FROM_DEEPMIMIC = {
    "pelvis": "root", "torso": "chest", "head": "neck", "right_upper_arm": "right_shoulder",
    "right_lower_arm": "right_elbow", "right_hand": "right_wrist",
    "left_upper_arm": "left_shoulder", "left_lower_arm": "left_elbow", "left_hand": "left_wrist",
    "right_thigh": "right_hip", "right_shin": "right_knee", "right_foot": "right_ankle",
    "left_thigh": "left_hip", "left_shin": "left_knee", "left_foot": "left_ankle",
}  # fmt: skip


def ase_offsets() -> np.ndarray:
    """``(17, 3)`` body offsets in the parent frame, z-up, m (pelvis 1 m up, as poselib's)."""
    dm = {name: np.array(off) for name, _, _, off in HUMANOID3D_JOINTS}
    out = np.zeros((len(ASE_BODIES), 3))
    for j, body in enumerate(ASE_BODIES):
        if body in _FROM_DEEPMIMIC:
            x, y, z = dm[_FROM_DEEPMIMIC[body]]
            out[j] = (x, -z, y)  # DeepMimic: x forward, y up, z right; poselib: z up, y left
    out[0] = (0.0, 0.0, 1.0)
    out[ASE_BODIES.index("sword")] = (0.7, 0.0, 0.0)
    out[ASE_BODIES.index("shield")] = (0.0, 0.05, -0.1)
    return out


def _tensor(arr: np.ndarray) -> dict:
    return {"arr": arr, "context": {"dtype": str(arr.dtype)}}


def poselib_dict(quat_xyzw: np.ndarray, root: np.ndarray, fps: float = 30.0,
                 offsets: np.ndarray | None = None, is_local: bool = True,
                 names: list[str] | None = None,
                 parents: np.ndarray | None = None) -> dict:  # fmt: skip
    """A ``SkeletonMotion`` dict, by default of the ASE humanoid.

    Args:
        quat_xyzw: ``(T, J, 4)`` body rotations, (x, y, z, w).
        root: ``(T, 3)`` pelvis positions, z-up, m.
        fps: Frame rate, Hz.
        offsets: ``(J, 3)`` bone offsets; default :func:`ase_offsets`.
        is_local: Whether ``quat_xyzw`` are local rotations.
        names: ``J`` body names; default ``ASE_BODIES``.
        parents: ``(J,)`` parent indices; default ``ASE_PARENTS``.
    """
    offsets = ase_offsets() if offsets is None else offsets
    names = list(ASE_BODIES) if names is None else names
    parents = ASE_PARENTS.copy() if parents is None else parents
    zeros = np.zeros((quat_xyzw.shape[0], len(names), 3))
    tree = OrderedDict(node_names=names, parent_indices=_tensor(parents),
                       local_translation=_tensor(offsets.astype(np.float32)))  # fmt: skip
    return OrderedDict(
        rotation=_tensor(np.asarray(quat_xyzw, dtype=np.float64)),
        root_translation=_tensor(np.asarray(root, dtype=np.float64)),
        global_velocity=_tensor(zeros), global_angular_velocity=_tensor(zeros),
        skeleton_tree=tree, is_local=is_local, fps=np.float64(fps), __name__="SkeletonMotion",
    )  # fmt: skip


def standing_quats(n_frames: int) -> np.ndarray:
    """``(T, 17, 4)`` identity rotations (x, y, z, w): the rest pose, standing, arms down."""
    q = np.zeros((n_frames, len(ASE_BODIES), 4))
    q[..., 3] = 1.0
    return q


def write_poselib(path: Path, d: object) -> Path:
    """Write ``d`` as ``SkeletonMotion.to_file`` writes its dict (a pickled 0-d object array)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    arr = np.empty((), dtype=object)
    arr[()] = d
    np.save(path, arr, allow_pickle=True)  # writing: nothing is loaded
    return path


def write_standing_clip(path: Path, n_frames: int = 12, fps: float = 30.0) -> Path:
    """A standing ASE clip: pelvis 0.89 m up, soles about 1 cm above z = 0."""
    root = np.tile([0.0, 0.0, 0.89], (n_frames, 1))
    return write_poselib(path, poselib_dict(standing_quats(n_frames), root, fps))
