"""Loading and saving recordings: the only code in :mod:`prism_tools` that touches pickle or files.

Two formats:

``.pkl``
    Real PRISM pickles (one dict per take). They are read with :class:`RestrictedUnpickler`,
    whose ``find_class`` admits only the globals needed to rebuild numpy arrays, dtypes and
    scalars and builtin containers/scalars; anything else (``os.system``, ``builtins.eval``, any
    class) is refused before it can be called. Written with pickle protocol 4.
``.npz``
    This project's pickle-free variant: every array of the PRISM dict is stored under its
    slash-joined key path (``"imu/L_Wrist/ori_world"``) and everything else (strings, numbers,
    ``None``, empty dicts, the nesting itself) in one JSON document stored as the unicode array
    ``"__meta__.json"``. Loaded with ``allow_pickle=False``.

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
import zipfile
import zlib
from collections import OrderedDict
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any, Literal

import numpy as np

from grip.core.atomic import atomic_write
from prism_tools.errors import RecordingError
from prism_tools.gaps import fill_gaps as _fill_gaps
from prism_tools.schema import EXTRAS_KEY, ForceUnit, Recording, validate

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


def _numpy_globals() -> dict[tuple[str, str], Any]:
    """The globals a pickle of numpy arrays/dtypes/scalars references, old and new spellings."""
    try:
        from numpy._core import multiarray, numeric
    except ImportError:  # numpy < 2
        from numpy.core import multiarray, numeric  # type: ignore[no-redef]

    out: dict[tuple[str, str], Any] = {
        ("numpy", "ndarray"): np.ndarray,
        ("numpy", "dtype"): np.dtype,
    }
    # numpy 2.x writes numpy._core.*, numpy 1.x wrote numpy.core.*: resolve both to the objects
    # above without importing the deprecated numpy.core shim.
    for pkg in ("numpy._core", "numpy.core"):
        out[(f"{pkg}.multiarray", "_reconstruct")] = multiarray._reconstruct
        out[(f"{pkg}.multiarray", "scalar")] = multiarray.scalar
        out[(f"{pkg}.numeric", "_frombuffer")] = numeric._frombuffer
    return out


_BUILTIN_NAMES = (
    "dict", "list", "tuple", "set", "frozenset", "bytearray", "bytes", "str", "int", "float",
    "complex", "bool", "slice", "range",
)  # fmt: skip


def _allowed_globals() -> dict[tuple[str, str], Any]:
    import builtins
    import codecs

    out = _numpy_globals()
    for name in _BUILTIN_NAMES:
        out[("builtins", name)] = getattr(builtins, name)
        out[("__builtin__", name)] = getattr(builtins, name)  # protocol 0-2 spelling
    out[("__builtin__", "xrange")] = range
    out[("collections", "OrderedDict")] = OrderedDict
    # Protocols 0-2 encode bytes (the raw data of arrays) as _codecs.encode(str, "latin1").
    out[("_codecs", "encode")] = codecs.encode
    return out


_ALLOWED_GLOBALS = _allowed_globals()


class _RefusedGlobal(pickle.UnpicklingError):
    """A pickle referenced a global outside the allow-list."""

    def __init__(self, module: str, name: str) -> None:
        super().__init__(f"{module}.{name}")
        self.qualname = f"{module}.{name}"


class RestrictedUnpickler(pickle.Unpickler):
    """An unpickler that can rebuild numpy arrays and builtin containers, and nothing else.

    ``find_class`` looks the requested ``(module, name)`` up in a fixed allow-list of already
    imported objects (it never imports a module); anything else raises before it can be called.
    Persistent ids are refused too.
    """

    def find_class(self, module: str, name: str) -> Any:
        try:
            return _ALLOWED_GLOBALS[(module, name)]
        except KeyError:
            raise _RefusedGlobal(module, name) from None

    def persistent_load(self, pid: Any) -> Any:
        raise pickle.UnpicklingError("persistent ids are not allowed")


# Errors a malformed pickle/npz can raise while being parsed by pickle/numpy/zipfile.
_PARSE_ERRORS = (
    pickle.UnpicklingError,
    EOFError,
    ValueError,
    TypeError,
    AttributeError,
    IndexError,
    KeyError,
    OverflowError,
    MemoryError,
    UnicodeDecodeError,
    zipfile.BadZipFile,
    zlib.error,
    RecursionError,
)


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
def _read_pickle(path: Path) -> Any:
    try:
        with path.open("rb") as f:
            return RestrictedUnpickler(f, encoding="latin1").load()
    except _RefusedGlobal as e:
        raise RecordingError(
            f"{path}: refused to unpickle global {e.qualname!r}: only numpy arrays/dtypes/scalars "
            "and builtin containers are allowed (is this file a PRISM recording?)"
        ) from None
    except _PARSE_ERRORS as e:
        raise RecordingError(
            f"{path}: corrupt or truncated pickle ({type(e).__name__}: {e})"
        ) from None


def _unflatten(tree: Any, arrays: dict[str, np.ndarray], path: Path) -> Any:
    if isinstance(tree, dict):
        if set(tree) == {_ARRAY_MARKER}:
            key = tree[_ARRAY_MARKER]
            if key not in arrays:
                raise RecordingError(f"{path}: npz metadata refers to missing array {key!r}")
            return arrays[key]
        return {k: _unflatten(v, arrays, path) for k, v in tree.items()}
    if isinstance(tree, list):
        return [_unflatten(v, arrays, path) for v in tree]
    return tree


def _read_npz(path: Path) -> Any:
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except _PARSE_ERRORS as e:
        raise RecordingError(
            f"{path}: corrupt or truncated npz ({type(e).__name__}: {e})"
        ) from None
    meta_arr = arrays.pop(_META_KEY, None)
    if meta_arr is None or meta_arr.dtype.kind != "U" or meta_arr.ndim != 0:
        raise RecordingError(f"{path}: not a GRIP PRISM npz (no {_META_KEY!r} entry)")
    try:
        meta = json.loads(str(meta_arr[()]))
    except json.JSONDecodeError as e:
        raise RecordingError(f"{path}: corrupt npz metadata ({e})") from None
    if not isinstance(meta, dict) or meta.get("format") != _NPZ_FORMAT:
        raise RecordingError(f"{path}: not a GRIP PRISM npz (metadata format mismatch)")
    if meta.get("version") != _NPZ_VERSION:
        raise RecordingError(f"{path}: unsupported npz version {meta.get('version')!r}")
    return _unflatten(meta.get("tree"), arrays, path)


def load_prism_dict(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Reads the raw PRISM dict of a ``.pkl`` (restricted unpickler) or ``.npz`` file.

    Args:
        path: File path.

    Returns:
        The nested dict, not validated.

    Raises:
        FileNotFoundError: ``path`` does not exist (the message starts with the path).
        RecordingError: Unknown suffix, refused pickle global, corrupt/truncated file, or the
            content is not a dict; the message starts with the path.
    """
    path = Path(path)
    fmt = _format_of(path, None)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such recording file")
    d = _read_pickle(path) if fmt == "pkl" else _read_npz(path)
    if not isinstance(d, dict):
        raise RecordingError(f"{path}: expected a dict at the top level, got {type(d).__name__}")
    return d


_TAKE_RE = re.compile(r"^(?P<subj>subj\d+)_(?P<take>.+)$")


def take_name_from_path(path: str | os.PathLike[str]) -> str:
    """Take name from a PRISM path: ``<root>/subj001/take002.pkl`` or ``subj001_take002.pkl``.

    Args:
        path: File path.

    Returns:
        ``"subj001_take002"`` for both layouts; the bare file stem when neither pattern matches.
    """
    p = Path(path)
    if _TAKE_RE.match(p.stem):
        return p.stem
    parent = p.parent.name
    if re.fullmatch(r"subj\d+", parent):
        return f"{parent}_{p.stem}"
    return p.stem


def load_recording(
    path: str | os.PathLike[str], *, force_unit: ForceUnit = "auto", fill_gaps: int = 0
) -> Recording:
    """Loads and validates a recording from a ``.pkl`` (PRISM or ours) or ``.npz`` file.

    Accepts both PRISM layouts, ``<root>/<subject>/<take>.pkl`` and flat ``subj001_take002.pkl``.
    For a file without this project's namespace (a real PRISM take), ``extras["take_name"]`` is set
    from the path (``"subj001_take002"``) and the insole force unit is decided from the data (see
    :meth:`Recording.from_prism_dict`).

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

    Returns:
        The validated recording, insole forces in body weights.

    Raises:
        FileNotFoundError: ``path`` does not exist.
        RecordingError: Anything wrong with the file or its content, including non-finite values
            not filled (gaps longer than ``fill_gaps`` frames). Every message starts with the
            file path.
    """
    path = Path(path)
    d = load_prism_dict(path)
    filled: list[dict[str, Any]] = []
    if fill_gaps > 0:
        d, filled = _fill_gaps(d, fill_gaps, source=str(path))
    try:
        rec = Recording.from_prism_dict(d, source=str(path), force_unit=force_unit)
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
