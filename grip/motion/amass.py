"""AMASS-style ``.npz`` reader (SMPL / SMPL-H / SMPL-X body poses).

AMASS files hold axis-angle joint rotations ``poses`` (T, 72 | 156 | 165) in the SMPL joint tree,
the model translation ``trans`` (T, 3) and ``mocap_framerate`` (or ``mocap_frame_rate``); ``betas``
and ``gender`` are optional and unused here. The world is Z-up (``up_axis = 2``), metres.

No SMPL model file is available to this project, so joint positions come from a fixed *approximate*
neutral rest skeleton (:data:`SMPL_REST_OFFSETS`): the project's own anthropometric estimates in
the SMPL canonical frame (x = subject's left, y = up, z = forward; pelvis about 0.94 m above the
floor). They are close to, but not, SMPL's regressed joints, and ``betas`` are ignored.

Positions follow SMPL's skinning convention: the pelvis joint sits at ``trans + SMPL_PELVIS_M``
(the model-space pelvis location added without rotation), every other joint hangs off it through
the posed rotations. For SMPL-H / SMPL-X files body joints 0-21 are used and the hand joints 22/23
get identity local rotation.

Rest pose: the zero pose stood upright in the Z-up world, i.e. every joint frame rotated by
:data:`SMPL_TO_ZUP` (x -> x, y -> z, z -> -y; the rotation AMASS root orientations carry for a
subject standing upright), the pelvis :data:`SMPL_PELVIS_HEIGHT_M` above the floor ``z = 0``.
``rest_rot`` is therefore ``SMPL_TO_ZUP`` for every joint, so ``global_rot @ rest_rot^T`` is the
world-frame rotation away from the upright T-pose.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from grip.core import skeleton as sk
from grip.core.limits import InputLimits, active_limits, check_npz
from grip.motion.source import MotionImportError, SourceMotion, clean_import_errors, source_fk

SMPL_JOINT_NAMES: tuple[str, ...] = sk.JOINT_NAMES
"""The 24 SMPL joint names (``Pelvis``, ``L_Hip``, ...), shared with :mod:`grip.core.skeleton`."""
SMPL_PARENTS: np.ndarray = sk.PARENTS

#: Approximate neutral SMPL rest offsets (child minus parent), metres, SMPL canonical frame
#: (x left, y up, z forward). Own anthropometric estimates, not SMPL's regressed joints.
SMPL_REST_OFFSETS = np.array(
    [
        [0.000, 0.000, 0.000],  # Pelvis (placed separately)
        [0.070, -0.090, -0.005],  # L_Hip
        [-0.070, -0.090, -0.005],  # R_Hip
        [0.000, 0.110, -0.025],  # Spine1
        [0.040, -0.380, 0.005],  # L_Knee
        [-0.040, -0.380, 0.005],  # R_Knee
        [0.000, 0.135, 0.005],  # Spine2
        [-0.010, -0.400, -0.040],  # L_Ankle
        [0.010, -0.400, -0.040],  # R_Ankle
        [0.000, 0.055, 0.000],  # Spine3
        [0.030, -0.060, 0.120],  # L_Foot
        [-0.030, -0.060, 0.120],  # R_Foot
        [0.000, 0.210, -0.035],  # Neck
        [0.075, 0.115, -0.015],  # L_Collar
        [-0.075, 0.115, -0.015],  # R_Collar
        [0.000, 0.090, 0.050],  # Head
        [0.120, 0.045, -0.010],  # L_Shoulder
        [-0.120, 0.045, -0.010],  # R_Shoulder
        [0.260, -0.015, -0.020],  # L_Elbow
        [-0.260, -0.015, -0.020],  # R_Elbow
        [0.250, 0.010, 0.000],  # L_Wrist
        [-0.250, 0.010, 0.000],  # R_Wrist
        [0.085, -0.010, -0.010],  # L_Hand
        [-0.085, -0.010, -0.010],  # R_Hand
    ]
)

#: Approximate pelvis location in SMPL model space (model origin to pelvis joint), metres.
SMPL_PELVIS_M = np.array([0.0, -0.22, 0.03])
#: Approximate pelvis height above the soles in the rest pose, metres.
SMPL_PELVIS_HEIGHT_M = 0.94
#: Rotation taking the SMPL canonical (y-up) frame to AMASS's z-up world, upright.
SMPL_TO_ZUP = Rotation.from_euler("x", 90.0, degrees=True).as_matrix()

_POSE_WIDTHS = {72: "smpl", 156: "smplh", 165: "smplx"}


def _array(path_s: str, npz: np.lib.npyio.NpzFile, key: str) -> np.ndarray:
    try:
        arr = npz[key]
    except ValueError as exc:  # object arrays need pickle, which is refused
        raise MotionImportError(path_s, f"cannot read without pickle ({exc})", key=key) from None
    if arr.dtype.kind not in "iuf":
        raise MotionImportError(path_s, f"expected numbers, got dtype {arr.dtype}", key=key)
    return np.asarray(arr, dtype=np.float64)


@clean_import_errors
def load_amass_npz(
    path: str | Path,
    *,
    name: str | None = None,
    category: str = "unknown",
    limits: InputLimits | None = None,
) -> SourceMotion:
    """Read an AMASS-style ``.npz`` into a :class:`SourceMotion` (Z-up, metres, 24 SMPL joints).

    Args:
        path: The ``.npz`` file (opened with ``allow_pickle=False``).
        name: Clip id to store; default: the file stem.
        category: Motion category to store.
        limits: Size and rate limits (:class:`grip.core.limits.InputLimits`): member sizes
            are checked from the npy headers before anything is loaded, the frame rate, frames
            and duration before the poses are read; default
            :func:`grip.core.limits.active_limits`.

    Returns:
        The clip with ``rig="smpl"``, ``up_axis=2``, ``unit_m=1``, ``rest_is_tpose=True``,
        ``times_s = k / mocap_framerate``; joint positions from the approximate rest skeleton.

    Raises:
        MotionImportError: Missing keys, wrong shapes, NaN/inf, a non-positive frame rate,
            sizes or a rate outside ``limits``, a corrupt file (the message names the file and
            the key).
    """
    path_s = str(path)
    limits = limits or active_limits()
    try:
        members = check_npz(path, limits)
        npz = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise MotionImportError(path_s, f"cannot open as .npz ({exc})") from None
    with npz:
        keys = set(npz.files)
        for key in ("poses", "trans"):
            if key not in keys:
                raise MotionImportError(path_s, "missing required array", key=key)
        rate_key = next((k for k in ("mocap_framerate", "mocap_frame_rate") if k in keys), None)
        if rate_key is None:
            raise MotionImportError(path_s, "missing frame rate", key="mocap_framerate")
        rate = _array(path_s, npz, rate_key)
        if rate.size == 1 and np.isfinite(rate).all() and float(rate.reshape(())) > 0:
            shape = members["poses"][0]
            limits.check_take(shape[0] if shape else 0, float(rate.reshape(())),
                              len(SMPL_JOINT_NAMES))  # fmt: skip
        poses = _array(path_s, npz, "poses")
        trans = _array(path_s, npz, "trans")
    if poses.ndim != 2 or poses.shape[1] not in _POSE_WIDTHS:
        raise MotionImportError(
            path_s, f"expected shape (T, 72|156|165), got {poses.shape}", key="poses"
        )
    n_frames = poses.shape[0]
    if trans.shape != (n_frames, 3):
        raise MotionImportError(
            path_s, f"expected shape ({n_frames}, 3), got {trans.shape}", key="trans"
        )
    if rate.size != 1 or not np.isfinite(rate).all() or float(rate.reshape(())) <= 0:
        raise MotionImportError(path_s, f"expected one positive number, got {rate!r}", key=rate_key)
    if n_frames == 0:
        raise MotionImportError(path_s, "no frames", key="poses")
    for key, arr in (("poses", poses), ("trans", trans)):
        bad = ~np.isfinite(arr)
        if bad.any():
            frame = int(np.argwhere(bad)[0][0])
            raise MotionImportError(
                path_s, f"{int(bad.sum())} non-finite value(s)", frame=frame, key=key
            )
    fps = float(rate.reshape(()))

    n_joints = len(SMPL_JOINT_NAMES)
    n_pose_joints = n_joints if poses.shape[1] == 72 else 22
    rotvec = np.zeros((n_frames, n_joints, 3))
    rotvec[:, :n_pose_joints] = poses[:, : 3 * n_pose_joints].reshape(n_frames, n_pose_joints, 3)
    local_rot = Rotation.from_rotvec(rotvec.reshape(-1, 3)).as_matrix()
    local_rot = local_rot.reshape(n_frames, n_joints, 3, 3)
    local_pos = np.broadcast_to(SMPL_REST_OFFSETS, (n_frames, n_joints, 3)).copy()
    local_pos[:, 0] = trans + SMPL_PELVIS_M
    global_rot, global_pos = source_fk(SMPL_PARENTS, local_rot, local_pos)

    rest_local = SMPL_REST_OFFSETS.copy()
    rest_local[0] = 0.0
    rest_rot = np.broadcast_to(SMPL_TO_ZUP, (n_joints, 3, 3)).copy()
    rest_rot_root = np.broadcast_to(np.eye(3), (n_joints, 3, 3)).copy()
    rest_rot_root[0] = SMPL_TO_ZUP
    _, rest_pos = source_fk(SMPL_PARENTS, rest_rot_root, rest_local)
    rest_pos[:, 2] += SMPL_PELVIS_HEIGHT_M
    return SourceMotion(
        name=name if name is not None else Path(path).stem,
        path=path_s,
        fmt="amass",
        rig="smpl",
        joint_names=SMPL_JOINT_NAMES,
        parents=SMPL_PARENTS.copy(),
        times_s=np.arange(n_frames, dtype=np.float64) / fps,
        global_rot=global_rot,
        global_pos=global_pos,
        rest_rot=rest_rot,
        rest_pos=rest_pos,
        up_axis=2,
        unit_m=1.0,
        rest_is_tpose=True,
        category=category,
    )
