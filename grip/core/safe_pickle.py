"""The restricted unpickler: pickles of numpy arrays and builtin containers, and nothing else.

Every pickle the project reads goes through here: real PRISM recordings
(:func:`prism_tools.io.load_recording`) and poselib ``SkeletonMotion`` clips
(:mod:`grip.motion.poselib`, pickled dicts inside ``.npy`` files). Nothing from a pickle is
executed: :class:`RestrictedUnpickler` looks every global the pickle names up in a fixed
allow-list of already imported objects (numpy's array, dtype and scalar reconstruction helpers,
builtin containers and scalars, ``collections.OrderedDict``, latin-1 ``_codecs.encode``) and
refuses anything else (``os.system``, ``builtins.eval``, any class) before it can be called. The
allowed callables are wrapped so that whatever they would build, each call and the sum of all
calls, is bounded by :class:`grip.core.limits.InputLimits` first, and :func:`check_opcodes`
refuses damaged memo indices before the unpickler runs. :func:`restricted_loads` does all of
it for a byte string; :func:`load_object_npy` reads a ``.npy`` holding a pickled object (what
``np.save(..., allow_pickle=True)`` writes) the same way, never through
``np.load(allow_pickle=True)``.
"""

from __future__ import annotations

import ast
import io
import math
import pickle
from collections import OrderedDict
from collections.abc import Callable
from typing import IO, Any

import numpy as np

from grip.core.limits import InputLimits, active_limits, check_tree

__all__ = [
    "RefusedGlobal",
    "RestrictedUnpickler",
    "check_opcodes",
    "load_object_npy",
    "npy_header",
    "restricted_loads",
]


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


class _Budget:
    """What the callables of one pickle have built so far, bytes, against ``max_total_bytes``:
    each call is bounded by ``max_array_bytes``/``max_elements``, their sum by this (twelve
    ``bytearray(500 MB)`` calls fit in a 146-byte pickle)."""

    def __init__(self, limits: InputLimits) -> None:
        self.limits, self.spent = limits, 0

    def spend(self, nbytes: int, what: str) -> None:
        """Count ``nbytes`` about to be built; refuses before they are."""
        self.spent += int(nbytes)
        self.limits.check("max_total_bytes", self.spent,
                          f"what the pickle builds (with {what})", " bytes")  # fmt: skip


_ITEM_BYTES = 64
"""Bytes counted per item of a container a pickled call builds (a pointer, a new int or float
object, a hash-table slot): an upper estimate."""


def _allowed_globals(limits: InputLimits) -> dict[tuple[str, str], Any]:
    """The allow-list, each callable wrapped so that what it would build is bounded first: by
    itself, and together with what the pickle's other calls built (:class:`_Budget`)."""
    import builtins

    budget = _Budget(limits)
    out: dict[tuple[str, str], Any] = {}
    for key, obj in _numpy_globals().items():
        if key[1] == "_reconstruct":
            obj = _bounded_reconstruct(limits, budget)
        elif key == ("numpy", "ndarray"):
            obj = _bounded_ndarray(limits, budget)
        out[key] = obj
    for name in _BUILTIN_NAMES:
        wrapped = _bounded_builtin(getattr(builtins, name), limits, budget)
        out[("builtins", name)] = wrapped
        out[("__builtin__", name)] = wrapped  # protocol 0-2 spelling
    out[("__builtin__", "xrange")] = out[("builtins", "range")]
    out[("collections", "OrderedDict")] = _bounded_builtin(OrderedDict, limits, budget)
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


def _built_bytes(cls: type, args: tuple) -> int:
    """An upper estimate of the bytes ``cls(*args)`` builds (a ``range`` is lazy)."""
    if cls is range:
        return _ITEM_BYTES
    nbytes = _ITEM_BYTES
    for arg in args:
        if cls in (bytes, bytearray) and isinstance(arg, int) and not isinstance(arg, bool):
            nbytes += max(0, arg)
        elif cls in (bytes, bytearray, str):
            nbytes += 4 * _size_of_arg(arg)  # (the str of bytes is a repr: up to 4 per byte)
        else:
            nbytes += _ITEM_BYTES * _size_of_arg(arg)
    return nbytes


def _bounded_builtin(cls: type, limits: InputLimits, budget: _Budget) -> Callable[..., Any]:
    """``cls`` wrapped: refuses sizes (``bytearray(10**10)``) and ranges above the limits, and
    what would take the pickle's total above ``max_total_bytes``."""

    def build(*args: Any) -> Any:
        for arg in args:
            if cls in (bytes, bytearray) and isinstance(arg, int) and not isinstance(arg, bool):
                limits.check("max_array_bytes", arg, f"pickled {cls.__name__}({arg})", " bytes")
            limits.check("max_elements", _size_of_arg(arg),
                         f"items of a pickled {cls.__name__}")  # fmt: skip
        budget.spend(_built_bytes(cls, args), f"a {cls.__name__}")
        return cls(*args)

    build.__name__ = build.__qualname__ = cls.__name__
    return build


def _array_nbytes(shape: Any, dtype: Any) -> int:
    dims = (shape,) if isinstance(shape, int) else tuple(shape)
    if not all(isinstance(d, int | np.integer) and d >= 0 for d in dims):
        raise pickle.UnpicklingError(f"bad array shape {shape!r}")
    return math.prod(int(d) for d in dims) * np.dtype(dtype).itemsize


def _bounded_reconstruct(limits: InputLimits, budget: _Budget) -> Callable[..., Any]:
    """numpy's ``_reconstruct(ndarray, shape, dtype)`` with the array size bounded."""
    from numpy._core.multiarray import _reconstruct

    def reconstruct(subtype: Any, shape: Any, dtype: Any) -> Any:
        if subtype is not np.ndarray and getattr(subtype, "_grip_ndarray", False) is not True:
            raise pickle.UnpicklingError("numpy _reconstruct of a class other than ndarray")
        nbytes = _array_nbytes(shape, dtype)
        limits.check("max_array_bytes", nbytes, f"pickled array of shape {shape!r}", " bytes")
        budget.spend(nbytes, f"an array of shape {shape!r}")
        return _reconstruct(np.ndarray, shape, dtype)

    return reconstruct


def _bounded_ndarray(limits: InputLimits, budget: _Budget) -> Callable[..., Any]:
    """``numpy.ndarray(shape, dtype=float, ...)`` with the array size bounded."""

    def ndarray(shape: Any, dtype: Any = float, *args: Any) -> np.ndarray:
        nbytes = _array_nbytes(shape, dtype)
        limits.check("max_array_bytes", nbytes, f"pickled ndarray of shape {shape!r}", " bytes")
        budget.spend(nbytes, f"an ndarray of shape {shape!r}")
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


class RefusedGlobal(pickle.UnpicklingError):
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
            raise RefusedGlobal(module, name) from None

    def persistent_load(self, pid: Any) -> Any:
        raise pickle.UnpicklingError("persistent ids are not allowed")


_MEMO_PUTS = frozenset({"PUT", "BINPUT", "LONG_BINPUT"})


def check_opcodes(data: bytes) -> None:
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


def restricted_loads(data: bytes, limits: InputLimits | None = None, what: str = "pickle") -> Any:
    """Unpickle ``data`` with :class:`RestrictedUnpickler` after :func:`check_opcodes`, and
    bound the result's nesting, item count and total array bytes (:func:`check_tree`).

    Args:
        data: The whole pickle (read from a file whose size was checked).
        limits: Size limits; default :func:`grip.core.limits.active_limits`.
        what: What the pickle is, for limit messages.

    Raises:
        RefusedGlobal: The pickle names a global outside the allow-list (nothing was called).
        grip.core.limits.LimitExceeded: Something it asks to build is above ``limits``.
        pickle.UnpicklingError, ValueError, EOFError, ...: A damaged pickle (callers turn every
            failure into their own error naming the file).
    """
    limits = limits or active_limits()
    check_opcodes(data)
    obj = RestrictedUnpickler(io.BytesIO(data), limits=limits, encoding="latin1").load()
    check_tree(obj, limits, what)
    return obj


_NPY_MAGIC = b"\x93NUMPY"
#: Bytes that always hold an npy header: magic, version, a 4-byte length and at most 64 KiB.
NPY_HEADER_MAX_BYTES = 12 + 65535


def npy_header(data: bytes) -> tuple[dict, int]:
    """The header of an ``.npy`` file and where its data starts, read without numpy's loader.

    Args:
        data: The file's first bytes (:data:`NPY_HEADER_MAX_BYTES` always suffice) or all of it.

    Returns:
        ``(header, offset)``: the header dict (``descr``, ``fortran_order``, ``shape``), parsed
        with :func:`ast.literal_eval` (literals only, nothing is called), and the offset of the
        array data (for an object array: the pickle).

    Raises:
        ValueError: Not an npy file, an unknown version, or a header that is cut off or not a
            dict literal.
    """
    if not data.startswith(_NPY_MAGIC) or len(data) < 10:
        raise ValueError("not an npy file (no \\x93NUMPY magic)")
    major = data[6]
    if major == 1:
        size, start = int.from_bytes(data[8:10], "little"), 10
    elif major in (2, 3):
        size, start = int.from_bytes(data[8:12], "little"), 12
    else:
        raise ValueError(f"unsupported npy format version {major}")
    if size > 65535 or start + size > len(data):
        raise ValueError(f"npy header of {size} bytes does not fit the file")
    try:
        text = data[start : start + size].decode("utf-8" if major == 3 else "latin1")
        header = ast.literal_eval(text)
    except (ValueError, SyntaxError, UnicodeDecodeError, MemoryError, RecursionError) as e:
        raise ValueError(f"unreadable npy header ({type(e).__name__})") from None
    if not isinstance(header, dict) or not {"descr", "shape"} <= set(header):
        raise ValueError("unreadable npy header (not a dict with 'descr' and 'shape')")
    return header, start + size


def load_object_npy(data: bytes, limits: InputLimits | None = None) -> Any:
    """The Python object a ``.npy`` file of a pickled object holds, read without running it.

    ``np.save(path, obj, allow_pickle=True)`` writes a 0-d array of dtype object: an npy header
    (:func:`npy_header`) followed by the pickle of that array. The pickle goes through
    :func:`restricted_loads`; the 0-d array's item is returned.

    Args:
        data: The file's bytes.
        limits: Size limits; default :func:`grip.core.limits.active_limits`.

    Raises:
        ValueError: Not an npy file, an unreadable header, or not a 0-d object array.
        RefusedGlobal, grip.core.limits.LimitExceeded, pickle.UnpicklingError, ...: As
            :func:`restricted_loads`.
    """
    header, offset = npy_header(data)
    if header.get("descr") != "|O" or header.get("shape") != ():
        raise ValueError("not a pickled object (the npy header does not declare a 0-d array of "
                         "dtype object)")  # fmt: skip
    arr = restricted_loads(data[offset:], limits, "npy pickle")
    if not isinstance(arr, np.ndarray) or arr.dtype != object or arr.shape != ():
        raise ValueError("the npy pickle is not a 0-d object array")
    return arr[()]
