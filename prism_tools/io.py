"""Loading and saving recordings: the only code in :mod:`prism_tools` that touches pickle or files.

Two formats:

``.pkl``
    Real PRISM pickles (one dict per take). They are read with :class:`RestrictedUnpickler`
    (:mod:`grip.core.safe_pickle`), whose ``find_class`` admits only the globals needed to
    rebuild numpy arrays, dtypes and scalars and builtin containers/scalars; anything else
    (``os.system``, ``builtins.eval``, any class) is refused before it can be called. Written
    with pickle protocol 4.
``.npz``
    This project's pickle-free variant: every array of the PRISM dict is stored under its
    slash-joined key path (``"imu/L_Wrist/ori_world"``) and everything else (strings, numbers,
    ``None``, empty dicts, the nesting itself) in one JSON document stored as the unicode array
    ``"__meta__.json"``. Loaded with ``allow_pickle=False``.

Every read is bounded by :class:`grip.core.limits.InputLimits` (the ``limits`` argument, by
default :func:`grip.core.limits.active_limits`): the file size; for pickles the size of every
array, ``bytes``/``bytearray`` and container the pickle asks to build (checked before it is
built), the nesting depth and the total array bytes; for npz the declared size of every member
(zip sizes and npy headers, read before any array is loaded) and the JSON metadata's depth and
integer digits. Any failure of the parsers (``LookupError``, ``RecursionError``, ...) becomes a
:class:`RecordingError` naming the file.

Both are written atomically: to a temporary file in the destination directory, flushed and
fsynced, then moved over the destination with :func:`os.replace`. A failure at any point leaves an
existing file untouched and no temporary file behind.
"""

from __future__ import annotations

import dataclasses
import json
import os
import pickle
import re
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any, Literal

import numpy as np

from grip.core.atomic import atomic_write
from grip.core.limits import (
    InputLimits,
    LimitExceeded,
    active_limits,
    check_file_size,
    check_npz,
    safe_json_loads,
)
from grip.core.safe_pickle import RefusedGlobal, RestrictedUnpickler, restricted_loads
from grip.core.text import clean_strings, clean_text
from prism_tools.errors import RecordingError
from prism_tools.gaps import fill_gaps as _fill_gaps
from prism_tools.prism_dict import recording_from_prism_dict
from prism_tools.schema import Recording
from prism_tools.streams import EXTRAS_KEY, ForceUnit
from prism_tools.validation import validate

__all__ = [
    "RestrictedUnpickler",
    "atomic_write",
    "load_prism_dict",
    "load_recording",
    "save_recording",
    "take_name_from_path",
]

Format = Literal["pkl", "npz"]

_SUFFIX_FORMATS: dict[str, Format] = {".pkl": "pkl", ".pickle": "pkl", ".npz": "npz"}
_META_KEY = "__meta__.json"
_NPZ_FORMAT = "grip-prism-npz"
_NPZ_VERSION = 1
_ARRAY_MARKER = "__ndarray__"
_PICKLE_PROTOCOL = 4


def _format_of(path: Path, fmt: str | None) -> Format:
    suffix_fmt = _SUFFIX_FORMATS.get(path.suffix.lower())
    if fmt is None:
        if suffix_fmt is None:
            raise RecordingError(
                f"{path}: unknown recording format (expected a .pkl or .npz file name)"
            )
        return suffix_fmt
    if fmt not in ("pkl", "npz"):
        raise ValueError(f"fmt must be 'pkl', 'npz' or None, got {fmt!r}")
    if suffix_fmt is not None and suffix_fmt != fmt:
        raise ValueError(f"{path}: fmt={fmt!r} does not match the file suffix {path.suffix!r}")
    return fmt  # type: ignore[return-value]


# ----------------------------------------------------------------------------------- reading
def _read_pickle(path: Path, limits: InputLimits) -> Any:
    try:
        check_file_size(path, limits)
        # Read the (bounded) file first: a length field of a truncated pickle then cannot make
        # the unpickler allocate what the file does not hold.
        return restricted_loads(path.read_bytes(), limits, "pickle")
    except RefusedGlobal as e:
        raise RecordingError(
            f"{path}: refused to unpickle global {e.qualname!r}: only numpy arrays/dtypes/scalars "
            "and builtin containers are allowed (is this file a PRISM recording?)"
        ) from None
    except LimitExceeded as e:
        raise RecordingError(f"{path}: {e}") from None
    except OSError as e:
        raise RecordingError(f"{path}: cannot read ({e.strerror or e})") from None
    except Exception as e:  # any failure of the parser: a corrupt or hostile file
        raise RecordingError(
            f"{path}: corrupt or truncated pickle ({type(e).__name__}: {_short(e)})"
        ) from None


def _short(e: BaseException) -> str:
    text = str(e)
    return text if len(text) <= 300 else text[:300] + "..."


def _unflatten(tree: Any, arrays: dict[str, np.ndarray], path: Path) -> Any:
    """The JSON tree with array markers replaced (iterative: no recursion limit involved)."""
    root: list[Any] = [tree]
    stack: list[tuple[Any, Any]] = [(root, 0)]
    while stack:
        parent, key = stack.pop()
        node = parent[key]
        if isinstance(node, dict):
            if set(node) == {_ARRAY_MARKER}:
                name = node[_ARRAY_MARKER]
                if not isinstance(name, str) or name not in arrays:
                    raise RecordingError(f"{path}: npz metadata refers to missing array {name!r}")
                parent[key] = arrays[name]
                continue
            node = dict(node)
            parent[key] = node
            stack.extend((node, k) for k in node)
        elif isinstance(node, list):
            node = list(node)
            parent[key] = node
            stack.extend((node, i) for i in range(len(node)))
    return root[0]


def _read_npz(path: Path, limits: InputLimits) -> Any:
    try:
        members = check_npz(path, limits)
        meta_info = members.get(_META_KEY.removesuffix(".npy"))
        if meta_info is None or meta_info[1].kind != "U" or meta_info[0] != ():
            raise RecordingError(f"{path}: not a GRIP PRISM npz (no {_META_KEY!r} entry)")
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        meta_arr = arrays.pop(_META_KEY)
        meta = safe_json_loads(str(meta_arr[()]), limits, f"npz metadata {_META_KEY!r}")
    except RecordingError:
        raise
    except LimitExceeded as e:
        raise RecordingError(f"{path}: {e}") from None
    except OSError as e:
        raise RecordingError(f"{path}: cannot read ({e.strerror or e})") from None
    except Exception as e:  # any failure of zipfile/numpy/json: a corrupt or hostile file
        raise RecordingError(
            f"{path}: corrupt or truncated npz ({type(e).__name__}: {_short(e)})"
        ) from None
    if not isinstance(meta, dict) or meta.get("format") != _NPZ_FORMAT:
        raise RecordingError(f"{path}: not a GRIP PRISM npz (metadata format mismatch)")
    if meta.get("version") != _NPZ_VERSION:
        raise RecordingError(f"{path}: unsupported npz version {meta.get('version')!r}")
    return _unflatten(meta.get("tree"), arrays, path)


def load_prism_dict(
    path: str | os.PathLike[str], *, limits: InputLimits | None = None
) -> dict[str, Any]:
    """Reads the raw PRISM dict of a ``.pkl`` (restricted unpickler) or ``.npz`` file.

    Args:
        path: File path.
        limits: Size limits (:class:`grip.core.limits.InputLimits`); default
            :func:`grip.core.limits.active_limits`.

    Returns:
        The nested dict, not validated. Its strings (keys, values, text arrays) are cleaned
        (:func:`grip.core.text.clean_strings`): a code point UTF-8 cannot encode, such as a lone
        surrogate, is U+FFFD, so a category or name never breaks a writer downstream.

    Raises:
        FileNotFoundError: ``path`` does not exist (the message starts with the path).
        RecordingError: Unknown suffix, refused pickle global, corrupt/truncated file, a size
            above ``limits``, the content is not a dict, or two of its keys differ only in
            unencodable characters; the message starts with the path.
    """
    path = Path(path)
    fmt = _format_of(path, None)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such recording file")
    limits = limits or active_limits()
    d = _read_pickle(path, limits) if fmt == "pkl" else _read_npz(path, limits)
    if not isinstance(d, dict):
        raise RecordingError(f"{path}: expected a dict at the top level, got {type(d).__name__}")
    try:
        return clean_strings(d)
    except ValueError as e:
        raise RecordingError(f"{path}: {e}") from None


_TAKE_RE = re.compile(r"^(?P<subj>subj\d+)_(?P<take>.+)$")


def take_name_from_path(path: str | os.PathLike[str]) -> str:
    """Take name from a PRISM path: ``<root>/subj001/take002.pkl`` or ``subj001_take002.pkl``.

    Args:
        path: File path.

    Returns:
        ``"subj001_take002"`` for both layouts; the bare file stem when neither pattern matches;
        cleaned (:func:`grip.core.text.clean_text`: the undecodable bytes of a file name are
        U+FFFD).
    """
    p = Path(path)
    stem = clean_text(p.stem)
    if _TAKE_RE.match(stem):
        return stem
    parent = clean_text(p.parent.name)
    if re.fullmatch(r"subj\d+", parent):
        return f"{parent}_{stem}"
    return stem


def load_recording(
    path: str | os.PathLike[str],
    *,
    force_unit: ForceUnit = "auto",
    fill_gaps: int = 0,
    limits: InputLimits | None = None,
) -> Recording:
    """Loads and validates a recording from a ``.pkl`` (PRISM or ours) or ``.npz`` file.

    Accepts both PRISM layouts, ``<root>/<subject>/<take>.pkl`` and flat ``subj001_take002.pkl``.
    For a file without this project's namespace (a real PRISM take), ``extras["take_name"]`` is set
    from the path (``"subj001_take002"``) and the insole force unit is decided from the data (see
    :func:`prism_tools.prism_dict.recording_from_prism_dict`).

    Degraded mode (``fill_gaps > 0``): short sensor dropouts (runs of at most ``fill_gaps``
    frames holding NaN/inf in the ``imu``, ``imu_gt`` and ``insole`` streams) are filled before
    validation by :func:`prism_tools.gaps.fill_gaps` (linear interpolation, slerp for
    orientations, the nearest valid frame held at the start/end). When anything was filled,
    ``extras["filled_gaps"]`` lists the runs as ``{"key": "imu.L_Wrist.acc_world_filt",
    "first": 10, "last": 12}`` (inclusive frame ranges); it is absent otherwise. Longer gaps are
    left and the file is rejected.

    Args:
        path: File path.
        force_unit: Stored insole force unit, ``"auto"`` to decide from the data (or the file's
            own declaration), ``"body_weight"`` or ``"n_per_kg"``.
        fill_gaps: Longest sensor dropout to fill, frames (5 frames = 50 ms at 100 fps);
            ``0`` (default) fills nothing and any non-finite value rejects the file.
        limits: Limits on sizes, frame rate, duration and physically plausible values
            (:class:`grip.core.limits.InputLimits`); default
            :func:`grip.core.limits.active_limits`.

    Returns:
        The validated recording, insole forces in body weights.

    Raises:
        FileNotFoundError: ``path`` does not exist.
        RecordingError: Anything wrong with the file or its content, including non-finite values
            not filled (gaps longer than ``fill_gaps`` frames), values above ``limits`` and
            any unexpected failure while interpreting the content. Every message starts with
            the file path.
    """
    path = Path(path)
    limits = limits or active_limits()
    d = load_prism_dict(path, limits=limits)
    try:
        return _recording_from_dict(d, path, force_unit, fill_gaps, limits)
    except RecordingError:
        raise
    except Exception as e:  # a content no check foresaw: still a clean error naming the file
        raise RecordingError(
            f"{path}: cannot interpret the recording ({type(e).__name__}: {_short(e)})"
        ) from None


def _recording_from_dict(d: dict[str, Any], path: Path, force_unit: ForceUnit, fill_gaps: int,
                         limits: InputLimits) -> Recording:  # fmt: skip
    filled: list[dict[str, Any]] = []
    if fill_gaps > 0:
        d, filled = _fill_gaps(d, fill_gaps, source=str(path))
    try:
        rec = recording_from_prism_dict(d, source=str(path), force_unit=force_unit, limits=limits)
    except RecordingError as e:
        if fill_gaps > 0 and "non-finite" in str(e):
            raise RecordingError(
                f"{e} (a gap longer than fill_gaps={fill_gaps} frames, or outside the "
                "imu/imu_gt/insole streams, is not filled)"
            ) from None
        raise
    if EXTRAS_KEY not in d and "take_name" not in rec.extras:
        rec = _with_extras(rec, take_name=take_name_from_path(path))
    if filled:
        rec = _with_extras(rec, filled_gaps=filled)
    return rec


def _with_extras(rec: Recording, **extras: Any) -> Recording:
    return dataclasses.replace(rec, extras={**rec.extras, **extras})


# ----------------------------------------------------------------------------------- writing
def _flatten(value: Any, key: str, arrays: dict[str, np.ndarray], dest: Path) -> Any:
    """JSON tree of ``value`` with arrays moved to ``arrays`` under slash-joined key paths."""
    if isinstance(value, np.ndarray):
        if value.dtype.kind in "OV" or value.dtype.hasobject:
            raise RecordingError(f"{dest}: {key}: cannot store dtype {value.dtype} in npz")
        arrays[key] = value
        return {_ARRAY_MARKER: key}
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str) or "/" in k or k == _ARRAY_MARKER or not k:
                raise RecordingError(f"{dest}: {key}: key {k!r} cannot be stored in npz")
            out[k] = _flatten(v, f"{key}/{k}" if key else k, arrays, dest)
        return out
    if isinstance(value, list | tuple):
        return [_flatten(v, f"{key}/{i}", arrays, dest) for i, v in enumerate(value)]
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, str | int | float | bool):
        return value
    raise RecordingError(f"{dest}: {key}: cannot store a {type(value).__name__} in npz")


def _npz_writer(d: dict[str, Any], dest: Path) -> Callable[[IO[bytes]], None]:
    arrays: dict[str, np.ndarray] = {}
    tree = _flatten(d, "", arrays, dest)
    meta = json.dumps({"format": _NPZ_FORMAT, "version": _NPZ_VERSION, "tree": tree})
    payload = {**arrays, _META_KEY: np.array(meta)}

    def write(f: IO[bytes]) -> None:
        np.savez_compressed(f, **payload)

    return write


def _pickle_writer(d: dict[str, Any]) -> Callable[[IO[bytes]], None]:
    def write(f: IO[bytes]) -> None:
        pickle.dump(d, f, protocol=_PICKLE_PROTOCOL)

    return write


def save_recording(
    rec: Recording, path: str | os.PathLike[str], *, fmt: Format | None = None
) -> None:
    """Validates and saves a recording atomically as ``.pkl`` or ``.npz``.

    The content is :meth:`Recording.to_prism_dict` (PRISM layout plus this project's ``grip``
    namespace, which declares the force unit as body weights).

    Args:
        rec: The recording.
        path: Destination; its parent directory is created if missing.
        fmt: ``"pkl"`` or ``"npz"``; ``None`` infers it from the suffix (``.pkl``/``.pickle``,
            ``.npz``). A format that contradicts a known suffix is an error.

    Raises:
        RecordingError: ``rec`` is invalid or holds extras that cannot be stored; the message
            starts with the path. Nothing is written then.
        OSError: The write failed; an existing file at ``path`` is left unchanged.
    """
    path = Path(path)
    fmt_ = _format_of(path, fmt)
    try:
        validate(rec)
    except RecordingError as e:
        raise RecordingError(f"{path}: refusing to save an invalid recording: {e}") from None
    d = rec.to_prism_dict()
    writer = _pickle_writer(d) if fmt_ == "pkl" else _npz_writer(d, path)
    atomic_write(path, writer)
