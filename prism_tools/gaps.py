"""Degraded mode for recordings with short sensor dropouts: filling short runs of NaN frames.

Real recordings sometimes lose a sensor for a few frames; the stored values are then NaN (or
inf) and :func:`~prism_tools.validation.validate` rejects the whole file. :func:`fill_gaps` repairs
short dropouts in the raw PRISM dict (as read by :func:`prism_tools.io.load_prism_dict`) before
it is parsed, and reports every run it filled so that the repair stays visible;
``load_recording(path, fill_gaps=N)`` applies it and stores the report in
``extras["filled_gaps"]``.

What is filled: every per-frame float array (first axis = frames) of the sensor groups
:data:`GAP_GROUPS`, i.e. ``imu.<part>.*``, ``imu_gt.<part>.*`` and ``insole.<foot>.*`` /
``insole.combined.*``, whatever part names are present. A frame is *missing* when any of its
values is non-finite; a run of consecutive missing frames of at most ``max_frames`` frames is
replaced as a whole:

* between two valid frames, vectors are interpolated linearly per component and ``(F, 3, 3)``
  rotation matrices (``ori_world``) spherically (slerp) between the two neighbouring valid
  orientations;
* at the start or end of the recording, the nearest valid frame is held.

Longer runs, streams without any valid frame, bool arrays (``contacts``), ``smpl_params``,
``slam`` and ``objects`` are left untouched (validation then rejects the file and names the key).

numpy at import time; scipy (``scipy.spatial.transform``) is imported on first use.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from prism_tools.errors import RecordingError

__all__ = ["GAP_GROUPS", "fill_gaps", "missing_runs"]

GAP_GROUPS: tuple[str, ...] = ("imu", "imu_gt", "insole")
"""Top-level groups of the PRISM dict whose ``<group>.<part>.<field>`` arrays are gap-filled."""


def missing_runs(arr: np.ndarray) -> list[tuple[int, int]]:
    """Runs of frames holding at least one non-finite value.

    Args:
        arr: ``(F, ...)`` float array, first axis = frames.

    Returns:
        ``[(first, last), ...]`` inclusive frame ranges in increasing order; empty when every
        value is finite.
    """
    n = arr.shape[0]
    if n == 0:
        return []
    bad = ~np.isfinite(arr.reshape(n, -1)).all(axis=1)
    if not bad.any():
        return []
    edges = np.diff(np.concatenate([[False], bad, [False]]).astype(np.int8))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1)  # one past the last missing frame
    return [(int(a), int(b) - 1) for a, b in zip(starts, stops, strict=True)]


def _is_rotation_stream(arr: np.ndarray) -> bool:
    return arr.ndim == 3 and arr.shape[1:] == (3, 3)


def _fill_run(arr: np.ndarray, out: np.ndarray, first: int, last: int, rotation: bool) -> bool:
    """Fills frames ``first..last`` of ``out`` from the valid neighbours in ``arr``.

    Returns:
        ``False`` (``out`` unchanged) when the neighbouring orientations are not rotations.
    """
    n = arr.shape[0]
    before, after = first - 1, last + 1
    if before < 0:  # run touches the start (the stream has valid frames, so after < n)
        out[first : last + 1] = arr[after]
        return True
    if after >= n:
        out[first : last + 1] = arr[before]
        return True
    # fraction of the way from the frame before the run to the frame after it, in (0, 1)
    t = (np.arange(first, last + 1) - before) / (after - before)
    if rotation:
        from scipy.spatial.transform import Rotation, Slerp

        try:
            ends = Rotation.from_matrix(arr[[before, after]].astype(np.float64))
        except ValueError:  # a neighbour is not a rotation matrix (det <= 0)
            return False
        out[first : last + 1] = Slerp([0.0, 1.0], ends)(t).as_matrix()
        return True
    a = arr[before].astype(np.float64)
    b = arr[after].astype(np.float64)
    t = t.reshape((-1,) + (1,) * (arr.ndim - 1))
    out[first : last + 1] = a + t * (b - a)
    return True


def _fill_array(
    arr: np.ndarray, max_frames: int, key: str, report: list[dict[str, Any]]
) -> np.ndarray:
    """``arr`` itself when nothing was filled, else a filled copy; appends filled runs to report."""
    if arr.dtype.kind != "f" or arr.ndim == 0:
        return arr
    runs = missing_runs(arr)
    if not runs:
        return arr
    n = arr.shape[0]
    if sum(b - a + 1 for a, b in runs) == n:  # no valid frame to fill from
        return arr
    rotation = _is_rotation_stream(arr)
    out: np.ndarray | None = None
    for first, last in runs:
        if last - first + 1 > max_frames:
            continue
        if out is None:
            out = arr.copy()
        if _fill_run(arr, out, first, last, rotation):
            report.append({"key": key, "first": first, "last": last})
    return arr if out is None else out


def fill_gaps(
    d: Mapping[str, Any], max_frames: int, source: str = "<dict>"
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Fills short runs of non-finite frames in the sensor streams of a raw PRISM dict.

    See the module docstring for what is filled and how. The input is not modified: the
    returned dict shares every array that was not changed and holds new arrays (same dtype and
    shape) where frames were filled; the dicts along the way are shallow copies.

    Args:
        d: PRISM nested dict as read by :func:`prism_tools.io.load_prism_dict`.
        max_frames: Longest run of missing frames that is filled, frames (at 100 fps, 5 frames
            = 50 ms). ``<= 0`` fills nothing.
        source: Where ``d`` came from (a file path); prefixes error messages.

    Returns:
        ``(filled, report)``: the new dict, and one entry per filled run in stream order then
        frame order, ``{"key": "imu.L_Wrist.acc_world_filt", "first": 10, "last": 12}`` with the
        inclusive frame range. Empty when nothing was filled (``filled`` is then a shallow copy of
        ``d`` sharing all its arrays).

    Raises:
        RecordingError: ``d`` is not a dict; the message starts with ``source``.
    """
    if not isinstance(d, Mapping):
        raise RecordingError(f"{source}: expected a dict at the top level, got {type(d).__name__}")
    out = dict(d)
    report: list[dict[str, Any]] = []
    if max_frames <= 0:
        return out, report
    for group in GAP_GROUPS:
        parts = d.get(group)
        if not isinstance(parts, Mapping):
            continue  # absent or malformed: left to the parser to report
        new_parts: dict[Any, Any] = {}
        for part, fields in parts.items():
            if not isinstance(fields, Mapping):
                new_parts[part] = fields
                continue
            new_fields = dict(fields)
            for name, arr in fields.items():
                if isinstance(arr, np.ndarray):
                    key = f"{group}.{part}.{name}"
                    new_fields[name] = _fill_array(arr, max_frames, key, report)
            new_parts[part] = new_fields
        out[group] = new_parts
    return out, report
