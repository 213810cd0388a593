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
import io
import json
import math
import os
import pickle
import re
from collections import OrderedDict
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
    check_tree,
    safe_json_loads,
)
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


def _allowed_globals(limits: InputLimits) -> dict[tuple[str, str], Any]:
    """The allow-list, each callable wrapped so that what it would build is bounded first."""
    import builtins

    out: dict[tuple[str, str], Any] = {}
    for key, obj in _numpy_globals().items():
        if key[1] == "_reconstruct":
            obj = _bounded_reconstruct(limits)
        elif key == ("numpy", "ndarray"):
            obj = _bounded_ndarray(limits)
        out[key] = obj
    for name in _BUILTIN_NAMES:
        wrapped = _bounded_builtin(getattr(builtins, name), limits)
        out[("builtins", name)] = wrapped
        out[("__builtin__", name)] = wrapped  # protocol 0-2 spelling
    out[("__builtin__", "xrange")] = out[("builtins", "range")]
    out[("collections", "OrderedDict")] = _bounded_builtin(OrderedDict, limits)
    # Protocols 0-2 encode bytes (the raw data of arrays) as _codecs.encode(str, "latin1").
    out[("_codecs", "encode")] = _latin1_encode
    return out


def _size_of_arg(arg: Any) -> int:
    """Number of items ``arg`` would produce when iterated (0 for scalars)."""
    if isinstance(arg, range):
        try:
            return len(arg)
        except OverflowError:
            return 2**63
    if isinstance(arg, str | bytes | bytearray | list | tuple | dict | set | frozenset):
        return len(arg)
    return 0


def _bounded_builtin(cls: type, limits: InputLimits) -> Callable[..., Any]:
    """``cls`` wrapped: refuses sizes (``bytearray(10**10)``) and ranges above the limits."""

    def build(*args: Any) -> Any:
        for arg in args:
            if cls in (bytes, bytearray) and isinstance(arg, int) and not isinstance(arg, bool):
                limits.check("max_array_bytes", arg, f"pickled {cls.__name__}({arg})", " bytes")
            limits.check("max_elements", _size_of_arg(arg),
                         f"items of a pickled {cls.__name__}")  # fmt: skip
        return cls(*args)

    build.__name__ = build.__qualname__ = cls.__name__
    return build


def _array_nbytes(shape: Any, dtype: Any) -> int:
    dims = (shape,) if isinstance(shape, int) else tuple(shape)
    if not all(isinstance(d, int | np.integer) and d >= 0 for d in dims):
        raise pickle.UnpicklingError(f"bad array shape {shape!r}")
    return math.prod(int(d) for d in dims) * np.dtype(dtype).itemsize


def _bounded_reconstruct(limits: InputLimits) -> Callable[..., Any]:
    """numpy's ``_reconstruct(ndarray, shape, dtype)`` with the array size bounded."""
    from numpy._core.multiarray import _reconstruct

    def reconstruct(subtype: Any, shape: Any, dtype: Any) -> Any:
        if subtype is not np.ndarray and getattr(subtype, "_grip_ndarray", False) is not True:
            raise pickle.UnpicklingError("numpy _reconstruct of a class other than ndarray")
        limits.check("max_array_bytes", _array_nbytes(shape, dtype),
                     f"pickled array of shape {shape!r}", " bytes")  # fmt: skip
        return _reconstruct(np.ndarray, shape, dtype)

    return reconstruct


def _bounded_ndarray(limits: InputLimits) -> Callable[..., Any]:
    """``numpy.ndarray(shape, dtype=float, ...)`` with the array size bounded."""

    def ndarray(shape: Any, dtype: Any = float, *args: Any) -> np.ndarray:
        limits.check("max_array_bytes", _array_nbytes(shape, dtype),
                     f"pickled ndarray of shape {shape!r}", " bytes")  # fmt: skip
        return np.ndarray(shape, dtype, *args)

    ndarray._grip_ndarray = True  # type: ignore[attr-defined]
    return ndarray


def _latin1_encode(text: Any, encoding: str = "utf-8", errors: str = "strict") -> bytes:
    """``_codecs.encode`` as protocols 0-2 use it (str -> latin-1 bytes), nothing else."""
    if not isinstance(text, str) or str(encoding).lower().replace("_", "-") not in (
        "latin1", "latin-1", "iso-8859-1",
    ):  # fmt: skip
        raise pickle.UnpicklingError(
            f"_codecs.encode with encoding {encoding!r} (only latin1 str -> bytes is allowed)"
        )
    return text.encode("latin-1", errors)


class _RefusedGlobal(pickle.UnpicklingError):
    """A pickle referenced a global outside the allow-list."""

    def __init__(self, module: str, name: str) -> None:
        super().__init__(f"{module}.{name}")
        self.qualname = f"{module}.{name}"


class RestrictedUnpickler(pickle.Unpickler):
    """An unpickler that can rebuild numpy arrays and builtin containers, and nothing else.

    ``find_class`` looks the requested ``(module, name)`` up in a fixed allow-list of already
    imported objects (it never imports a module); anything else raises before it can be called.
    The allowed callables are wrapped so that an array, ``bytes``/``bytearray`` or container
    larger than ``limits`` allows is refused before it is built (a 76-byte pickle cannot ask for
    ``bytearray(5_000_000_000)``), and ``_codecs.encode`` accepts only latin-1. Persistent ids
    are refused too.

    Args:
        file: Binary file object to read from.
        limits: Size limits; default :func:`grip.core.limits.active_limits`.
        **kwargs: Passed to :class:`pickle.Unpickler` (``encoding``, ...).
    """

    def __init__(self, file: IO[bytes], *, limits: InputLimits | None = None,
                 **kwargs: Any) -> None:  # fmt: skip
        super().__init__(file, **kwargs)
        self._allowed = _allowed_globals(limits or active_limits())

    def find_class(self, module: str, name: str) -> Any:
        try:
            return self._allowed[(module, name)]
        except KeyError:
            raise _RefusedGlobal(module, name) from None

    def persistent_load(self, pid: Any) -> Any:
        raise pickle.UnpicklingError("persistent ids are not allowed")


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
        data = path.read_bytes()
        _check_opcodes(data)
        obj = RestrictedUnpickler(io.BytesIO(data), limits=limits, encoding="latin1").load()
        del data
        check_tree(obj, limits, "pickle")
        return obj
    except _RefusedGlobal as e:
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


_MEMO_PUTS = frozenset({"PUT", "BINPUT", "LONG_BINPUT"})


def _check_opcodes(data: bytes) -> None:
    """Scan the pickle's opcodes before running any of them.

    A memo slot is an index into an array the C unpickler grows to that size: one
    ``LONG_BINPUT 499103675`` in a damaged file makes it allocate and clear 4 GB. A well-formed
    pickle never stores to a slot beyond the number of opcodes before it, so such a file is
    refused here. Unknown opcodes (a corrupt file) end the scan with ``ValueError``.
    """
    import pickletools
    import warnings

    with warnings.catch_warnings():  # (protocol-0 strings of a damaged file warn while decoded)
        warnings.simplefilter("ignore")
        for n, (op, arg, _pos) in enumerate(pickletools.genops(data)):
            if op.name in _MEMO_PUTS and isinstance(arg, int) and arg > n:
                raise pickle.UnpicklingError(f"memo slot {arg} at opcode {n} (a damaged pickle)")


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
        The nested dict, not validated.

    Raises:
        FileNotFoundError: ``path`` does not exist (the message starts with the path).
        RecordingError: Unknown suffix, refused pickle global, corrupt/truncated file, a size
            above ``limits``, or the content is not a dict; the message starts with the path.
    """
    path = Path(path)
    fmt = _format_of(path, None)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such recording file")
    limits = limits or active_limits()
    d = _read_pickle(path, limits) if fmt == "pkl" else _read_npz(path, limits)
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
        rec = recording_from_prism_dict(
            d, source=str(path), force_unit=force_unit, limits=limits
        )
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
