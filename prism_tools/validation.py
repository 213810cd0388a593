"""Structural validation of a :class:`~prism_tools.schema.Recording`: shapes, dtypes, finite
values, rotation matrices, frame rate and size limits (:func:`validate`).

Limits (:class:`grip.core.limits.InputLimits`): :func:`validate` refuses a frame rate outside
``[min_fps, max_fps]``, more than ``max_frames`` frames or ``max_duration_s`` seconds, and checks
every rotation matrix of every frame; reading a PRISM dict
(:func:`prism_tools.prism_dict.recording_from_prism_dict`) also refuses physically absurd values
(accelerations, insole forces, positions above the ``max_*`` limits,
:func:`prism_tools.plausibility.check_plausible`) with a message saying which unit was probably
meant.

This module imports numpy and :mod:`grip.core.limits` only.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from grip.core.limits import InputLimits, LimitExceeded, active_limits
from prism_tools.errors import RecordingError
from prism_tools.plausibility import check_plausible
from prism_tools.schema import Recording
from prism_tools.streams import (
    _SPECS,
    FEET,
    IMU_PARTS,
    DataInfo,
    ImuGt,
    ImuStream,
    InsoleCombined,
    InsoleStream,
    SceneObject,
    Slam,
    SmplParams,
    SubjectInfo,
    _ArraySpec,
)

__all__ = ["ROTATION_TOL", "validate"]

ROTATION_TOL = 1e-3
"""Largest accepted ``max |R R^T - I|`` for a rotation matrix."""

_ROTATION_CHUNK = 65536
"""Frames checked per vectorised step of the rotation check (bounds its temporaries)."""


_KIND_CODES = {"float": "f", "bool": "b", "int": "iu"}


def _shape_str(shape: tuple[int | str, ...]) -> str:
    inner = ", ".join(str(s) for s in shape)
    return f"({inner},)" if len(shape) == 1 else f"({inner})"


def _check_array(arr: Any, path: str, spec: _ArraySpec, n_frames: int) -> None:
    if not isinstance(arr, np.ndarray):
        raise RecordingError(f"{path}: expected a numpy array, got {type(arr).__name__}")
    expected = spec.shape
    ok = arr.ndim == len(expected) and all(
        (e == "F" and s == n_frames) or (isinstance(e, str) and e != "F") or s == e
        for e, s in zip(expected, arr.shape, strict=False)
    )
    if not ok:
        with_f = f" with F={n_frames}" if "F" in expected else ""
        raise RecordingError(
            f"{path}: expected shape {_shape_str(expected)}{with_f}, got {tuple(arr.shape)}"
        )
    if arr.dtype.kind not in _KIND_CODES[spec.kind]:
        raise RecordingError(f"{path}: expected {spec.kind} dtype, got {arr.dtype}")
    if spec.kind == "float":
        finite = np.isfinite(arr)
        if not finite.all():
            bad = np.flatnonzero(~finite.reshape(-1))
            where = np.unravel_index(int(bad[0]), arr.shape)
            at = f"frame {where[0]}" if spec.per_frame else f"index {tuple(int(i) for i in where)}"
            raise RecordingError(f"{path}: {bad.size} non-finite value(s) (NaN/inf), first at {at}")
    if spec.rotation and arr.shape[0] > 0:
        _check_rotations(arr, path)


def _check_rotations(rot: np.ndarray, path: str) -> None:
    """Checks that every frame's matrix is a rotation (vectorised, in chunks of frames)."""
    n = rot.shape[0]
    eye = np.eye(3)
    for start in range(0, n, _ROTATION_CHUNK):
        sub = np.asarray(rot[start : start + _ROTATION_CHUNK], dtype=np.float64)
        err = np.abs(np.einsum("nij,nkj->nik", sub, sub) - eye).max(axis=(-2, -1))
        det = np.linalg.det(sub)
        bad = np.flatnonzero((err > ROTATION_TOL) | (det <= 0.0) | ~np.isfinite(err))
        if bad.size:
            i = int(bad[0])
            raise RecordingError(
                f"{path}: not a rotation matrix at frame {start + i} of {n} ({bad.size} bad "
                f"frame(s) among frames {start}-{start + len(sub) - 1}; max |R R^T - I| = "
                f"{err[i]:.3g}, det = {det[i]:.3g}, tolerance {ROTATION_TOL:g})"
            )


def _check_fields(obj: Any, cls: type, path: str, n_frames: int) -> None:
    if not isinstance(obj, cls):
        raise RecordingError(f"{path}: expected {cls.__name__}, got {type(obj).__name__}")
    for name, spec in _SPECS[cls].items():
        arr = getattr(obj, name)
        if arr is None:
            if spec.optional:
                continue
            raise RecordingError(f"{path}.{name}: missing (None)")
        _check_array(arr, f"{path}.{name}", spec, n_frames)


def _check_parts(streams: Any, cls: type, path: str, allowed: tuple[str, ...], n: int) -> None:
    if not isinstance(streams, dict):
        raise RecordingError(f"{path}: expected a dict, got {type(streams).__name__}")
    for part, stream in streams.items():
        if part not in allowed:
            raise RecordingError(f"{path}.{part}: unknown part (expected one of {allowed})")
        _check_fields(stream, cls, f"{path}.{part}", n)


def _check_number(value: Any, path: str, *, positive: bool = False, none_ok: bool = True) -> None:
    if value is None and none_ok:
        return
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise RecordingError(f"{path}: expected a number, got {type(value).__name__}")
    if not math.isfinite(value) or (positive and value <= 0):
        raise RecordingError(
            f"{path}: expected a finite{' positive' if positive else ''} number, got {value}"
        )


def _frame_source(rec: Recording) -> str:
    """Key path of the array that defines the frame count ``F`` (``""`` when there is none)."""
    if rec.smpl_params is not None:
        return "smpl_params.poses"
    imu = rec.imu if isinstance(rec.imu, dict) else {}
    insole = rec.insole if isinstance(rec.insole, dict) else {}
    for part in IMU_PARTS:
        if part in imu:
            return f"imu.{part}.acc_world_raw"
    for foot in FEET:
        if foot in insole:
            return f"insole.{foot}.force"
    return ""


def _frame_count(rec: Recording) -> int:
    """``F`` from the array :func:`_frame_source` names, checked to hold at least one frame."""
    path = _frame_source(rec)
    if not path:
        raise RecordingError("no smpl_params and no imu or insole stream: no frames to read")
    if rec.smpl_params is not None and not isinstance(rec.smpl_params, SmplParams):
        raise RecordingError(
            f"smpl_params: expected SmplParams or None, got {type(rec.smpl_params).__name__}"
        )
    group, *part, name = path.split(".")
    owner = rec.smpl_params if group == "smpl_params" else getattr(rec, group)[part[0]]
    arr = getattr(owner, name, None)
    if not isinstance(arr, np.ndarray) or arr.ndim < 1 or arr.shape[0] < 1:
        shape = getattr(arr, "shape", type(arr).__name__)
        want = "(F, 72)" if group == "smpl_params" else "(F, ...)"
        raise RecordingError(f"{path}: expected shape {want} with F >= 1, got {shape}")
    if group == "smpl_params" and arr.ndim != 2:
        raise RecordingError(f"{path}: expected shape (F, 72) with F >= 1, got {arr.shape}")
    return int(arr.shape[0])


def validate(
    rec: Recording, limits: InputLimits | None = None, *, plausible: bool = True
) -> None:
    """Checks every array of a recording: shape, dtype kind, finiteness, rotations, and fps.

    All per-frame arrays must share ``F = smpl_params.poses.shape[0]`` (without ground truth:
    the frame count of the first IMU stream in :data:`IMU_PARTS` order, else of the first
    insole, and there must be one); float arrays must be
    finite; rotation matrices (every frame) must satisfy ``max |R R^T - I| <= 1e-3`` with a
    positive determinant; contacts are bool, object faces and synthesised-frame indices are
    integers within range; ``fps`` is finite, within ``[limits.min_fps, limits.max_fps]`` and
    equal to ``data_info.fps``; ``F`` and the duration are within ``limits.max_frames`` and
    ``limits.max_duration_s``. Part names must be in :data:`IMU_PARTS` (insoles: :data:`FEET`).
    With ``plausible``, :func:`check_plausible` follows.

    Args:
        rec: The recording.
        limits: The limits; default :func:`grip.core.limits.active_limits`.
        plausible: Also refuse physically absurd values (:func:`check_plausible`).

    Raises:
        RecordingError: On the first problem found, naming its key path, for example
            ``"imu.L_Wrist.ori_world: expected shape (F, 3, 3) with F=1000, got (999, 3, 3)"``.
            The caller adds the file name.
    """
    if not isinstance(rec, Recording):
        raise RecordingError(f"expected a Recording, got {type(rec).__name__}")
    _check_number(rec.fps, "fps", positive=True, none_ok=False)
    if not isinstance(rec.data_info, DataInfo):
        raise RecordingError(
            f"info.data_info: expected DataInfo, got {type(rec.data_info).__name__}"
        )
    _check_number(rec.data_info.fps, "info.data_info.fps", positive=True, none_ok=False)
    if not math.isclose(rec.fps, rec.data_info.fps, rel_tol=1e-9):
        raise RecordingError(
            f"info.data_info.fps: {rec.data_info.fps} differs from the recording's fps {rec.fps}"
        )
    limits = limits or active_limits()
    try:
        limits.check_fps(float(rec.fps), "info.data_info.fps: frame rate")
    except LimitExceeded as e:
        raise RecordingError(str(e)) from None
    if not isinstance(rec.subject, SubjectInfo):
        raise RecordingError(
            f"info.subj_info: expected SubjectInfo, got {type(rec.subject).__name__}"
        )
    for name in ("age", "height_m", "weight_kg", "arm_length"):
        _check_number(getattr(rec.subject, name), f"info.subj_info.{name}", positive=True)
    if not isinstance(rec.subject.gender, str):
        raise RecordingError("info.subj_info.gender: expected a str")

    smpl = rec.smpl_params
    n = _frame_count(rec)
    try:
        limits.check("max_frames", n, f"{_frame_source(rec)}: frame count")
        limits.check("max_duration_s", n / float(rec.fps),
                     f"duration ({n} frames at {float(rec.fps):g} Hz)", " s")  # fmt: skip
    except LimitExceeded as e:
        raise RecordingError(str(e)) from None
    if smpl is not None:
        _check_fields(smpl, SmplParams, "smpl_params", n)
        if not isinstance(smpl.gender, str):
            raise RecordingError("smpl_params.gender: expected a str")

    for part, idx in rec.data_info.synth_imu_frames.items():
        path = f"info.data_info.synth_imu_frames.{part}"
        if not isinstance(idx, np.ndarray) or idx.ndim != 1 or idx.dtype.kind not in "iu":
            desc = getattr(idx, "dtype", type(idx).__name__)
            raise RecordingError(f"{path}: expected a 1-D integer index array, got {desc}")
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise RecordingError(f"{path}: frame indices outside [0, {n})")

    _check_parts(rec.imu, ImuStream, "imu", IMU_PARTS, n)
    _check_parts(rec.imu_gt, ImuGt, "imu_gt", IMU_PARTS, n)
    _check_parts(rec.insole, InsoleStream, "insole", FEET, n)
    if rec.insole_combined is not None:
        _check_fields(rec.insole_combined, InsoleCombined, "insole.combined", n)
    if rec.slam is not None:
        _check_fields(rec.slam, Slam, "slam", n)
    if rec.objects is not None:
        if not isinstance(rec.objects, dict):
            raise RecordingError(
                f"objects: expected a dict or None, got {type(rec.objects).__name__}"
            )
        for name, obj in rec.objects.items():
            path = f"objects.{name}"
            _check_fields(obj, SceneObject, path, n)
            if obj.faces.size and (obj.faces.min() < 0 or obj.faces.max() >= len(obj.vertices)):
                raise RecordingError(
                    f"{path}.faces: vertex indices outside [0, {len(obj.vertices)})"
                )
    if not isinstance(rec.extras, dict) or not all(isinstance(k, str) for k in rec.extras):
        raise RecordingError("extras: expected a dict with str keys")
    if plausible:
        check_plausible(rec, limits)
