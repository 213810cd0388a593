"""One table of limits on every input file, checked before anything large is allocated.

Every loader of the project (PRISM recordings ``.pkl``/``.npz``, motion clips BVH, ASF/AMC,
DeepMimic, AMASS, ``Motion`` files, reconstructions and reference sets) checks the sizes and
rates a file declares against :class:`InputLimits` *before* it builds arrays from them, so a
76-byte pickle, an npz whose header claims a 2 GB array, or a 3-frame BVH with ``Frame Time:
1800`` is refused in milliseconds with a message naming the file, the value and the limit, e.g.
``"clip.bvh: frame rate 0.000556 Hz is below the limit min_fps=10 (a genuine take? raise it with
--input-limit min_fps=VALUE or GRIP_LIMITS=min_fps=VALUE)"``.

Overrides, for genuine long or unusual takes: every command that reads inputs takes a
repeatable ``--input-limit NAME=VALUE`` option (``grip.cli.recordings.add_limit_arguments``), and
the environment variable ``GRIP_LIMITS`` (``"max_duration_s=7200,max_frames=1e6"``) applies to
every process, worker processes included (``--input-limit`` sets it for the command's workers).
``VALUE`` may be ``inf`` to switch a limit off.

numpy and stdlib only.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import os
import re
import zipfile
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from grip.core.checks import check, check_fields

__all__ = [
    "DEFAULT_LIMITS",
    "LIMITS_ENV",
    "InputLimits",
    "LimitExceeded",
    "active_limits",
    "check_file_size",
    "check_npz",
    "check_tree",
    "check_zip",
    "limit_help",
    "safe_json_loads",
    "set_active_limits",
]

LIMITS_ENV = "GRIP_LIMITS"
"""Environment variable holding limit overrides, ``"name=value,name=value"``."""

_GIB = 2**30
_MIB = 2**20


@dataclass(frozen=True)
class InputLimits:
    """Limits on what one input file may declare or hold. ``inf`` switches a limit off.

    Attributes:
        min_fps: Lowest accepted frame rate, Hz (an AMASS file at 0.01 Hz is refused).
        max_fps: Highest accepted frame rate, Hz.
        max_duration_s: Longest accepted take or clip, seconds (20 min).
        max_frames: Most frames in one file (source frames, before resampling).
        max_joints: Most joints (end sites included) of one motion-capture skeleton.
        max_frame_joints: Most frames x joints of one motion clip (its world rotations and
            positions take 96 bytes per frame-joint).
        max_file_bytes: Largest file read, bytes (2 GiB).
        max_array_bytes: Largest single array (npz member, unpickled array or bytes), bytes,
            decompressed (512 MiB).
        max_total_bytes: Largest sum of what one file expands to, bytes, decompressed: its
            arrays, the members of a zip (npz, torch file, ``model.zip``), everything a pickle
            asks to build (1 GiB: a 20-minute PRISM take holds about 0.2 GiB).
        max_elements: Most items of one container (list, tuple, set, dict, range) built while
            unpickling, and most containers walked in one file.
        max_depth: Deepest nesting of containers (pickle) or JSON values.
        max_int_digits: Most digits of an integer in JSON metadata.
        max_acc_mps2: Largest accepted acceleration magnitude of any sample, m/s^2 (10,000 g:
            beyond any sensor; motion capture glitches differentiated twice reach ~1,000 g).
        max_typical_acc_mps2: Largest accepted median acceleration magnitude of a stream, m/s^2
            (20 g: no human motion is typically above it; mm/s^2 values are ~1,000x).
        max_vel_mps: Largest accepted linear velocity of any sample, m/s.
        max_typical_vel_mps: Largest accepted median speed of a stream, m/s (mm/s: ~1,000x).
        max_force_bw: Largest accepted insole force, body weights.
        max_position_m: Largest accepted position magnitude or span of a trajectory, metres.
        max_line_bytes: Longest line of a text export (device CSVs), bytes (1 MiB).
        max_model_params: Most parameters of one network that a model file (KinematicsNet
            checkpoint, baseline, policy file, run folder) may declare (100 M: GRIP's policy at
            full scale has 9.2 M).
    """

    min_fps: float = 1.0
    max_fps: float = 2000.0
    max_duration_s: float = 1200.0
    max_frames: float = 500_000
    max_joints: float = 512
    max_frame_joints: float = 10_000_000
    max_file_bytes: float = 2 * _GIB
    max_array_bytes: float = 512 * _MIB
    max_total_bytes: float = 1 * _GIB
    max_elements: float = 10_000_000
    max_depth: float = 64
    max_int_digits: float = 100
    max_acc_mps2: float = 1e5
    max_typical_acc_mps2: float = 200.0
    max_vel_mps: float = 1000.0
    max_typical_vel_mps: float = 50.0
    max_force_bw: float = 30.0
    max_position_m: float = 1000.0
    max_line_bytes: float = 1 * _MIB
    max_model_params: float = 100_000_000

    def __post_init__(self) -> None:
        check_fields(self, lambda v: (not isinstance(v, bool) and isinstance(v, int | float)
                                      and not math.isnan(v) and v >= 0),
                     "must be a number >= 0 (or inf)")  # fmt: skip
        check(self, (self.min_fps <= self.max_fps,
                     f"min_fps={self.min_fps:g} is above max_fps={self.max_fps:g}"))  # fmt: skip

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The limit names, in table order."""
        return tuple(f.name for f in dataclasses.fields(cls))

    def with_overrides(self, items: Iterable[str] | Mapping[str, float]) -> InputLimits:
        """A copy with some limits replaced.

        Args:
            items: ``"name=value"`` strings (``value`` a number, ``2e9`` or ``inf``), or a mapping
                name -> number.

        Raises:
            ValueError: Unknown name or a bad value (the message lists the names).
        """
        pairs: list[tuple[str, Any]] = []
        if isinstance(items, Mapping):
            pairs = list(items.items())
        else:
            for item in items:
                name, sep, value = str(item).partition("=")
                if not sep:
                    raise ValueError(f"limit {item!r}: expected NAME=VALUE")
                pairs.append((name.strip(), value.strip()))
        changes: dict[str, float] = {}
        for name, value in pairs:
            if name not in self.names():
                raise ValueError(f"unknown limit {name!r}; known: {', '.join(self.names())}")
            try:
                number = float(value)
            except (TypeError, ValueError):
                raise ValueError(f"limit {name}={value!r}: not a number") from None
            changes[name] = int(number) if number.is_integer() and number < 2**63 else number
        return dataclasses.replace(self, **changes)

    def overrides(self) -> dict[str, float]:
        """The limits that differ from :data:`DEFAULT_LIMITS`."""
        return {
            n: getattr(self, n) for n in self.names() if getattr(self, n) != getattr(_DEFAULTS, n)
        }

    # ------------------------------------------------------------------------------ checks
    def check(self, name: str, value: float, what: str, unit: str = "") -> None:
        """Raises :class:`LimitExceeded` when ``value`` is above limit ``name``.

        Args:
            name: A ``max_*`` limit name.
            value: The value the input declares or holds.
            what: What the value is, for the message (``"frames"``, ``"member 'poses'"``).
            unit: Unit of ``value`` for the message.
        """
        limit = getattr(self, name)
        if value > limit:
            raise LimitExceeded(name, value, limit, f"{what} {_fmt(value)}{unit} is above")

    def check_fps(self, fps: float, what: str = "frame rate") -> None:
        """Raises :class:`LimitExceeded` unless ``min_fps <= fps <= max_fps`` (fps finite)."""
        if not math.isfinite(fps) or fps <= 0:
            raise LimitExceeded("min_fps", fps, self.min_fps, f"{what} {fps!r} Hz is not a "
                                "positive number, below")  # fmt: skip
        if fps < self.min_fps:
            raise LimitExceeded("min_fps", fps, self.min_fps, f"{what} {_fmt(fps)} Hz is below")
        self.check("max_fps", fps, what, " Hz")

    def check_take(self, n_frames: int, fps: float, n_joints: int | None = None) -> None:
        """Checks a clip's frame rate, frame count, duration and (with ``n_joints``) size."""
        self.check_fps(fps)
        self.check("max_frames", n_frames, "frame count")
        self.check("max_duration_s", n_frames / fps, f"duration ({n_frames} frames at "
                   f"{_fmt(fps)} Hz)", " s")  # fmt: skip
        if n_joints is not None:
            self.check("max_joints", n_joints, "joint count")
            self.check("max_frame_joints", n_frames * n_joints,
                       f"frames x joints ({n_frames} x {n_joints})")  # fmt: skip


DEFAULT_LIMITS = InputLimits()
"""The limits every loader uses unless told otherwise (see the class for the values)."""
_DEFAULTS = DEFAULT_LIMITS


class LimitExceeded(ValueError):
    """An input declares or holds more than a limit of :class:`InputLimits` allows.

    Attributes:
        name: The limit's name (``"max_duration_s"``).
        value: The offending value.
        limit: The limit in force.
    """

    def __init__(self, name: str, value: float, limit: float, text: str) -> None:
        self.name, self.value, self.limit = name, value, limit
        super().__init__(
            f"{text} the limit {name}={_fmt(limit)} (a genuine input? raise it with "
            f"--input-limit {name}=VALUE or {LIMITS_ENV}={name}=VALUE)"
        )

    def __reduce__(self):  # picklable across worker processes
        return (_rebuild_limit_exceeded, (self.name, self.value, self.limit, str(self)))


def _rebuild_limit_exceeded(name: str, value: float, limit: float, msg: str) -> LimitExceeded:
    e = LimitExceeded.__new__(LimitExceeded)
    ValueError.__init__(e, msg)
    e.name, e.value, e.limit = name, value, limit
    return e


def _fmt(x: float) -> str:
    if isinstance(x, float) and not x.is_integer():
        return f"{x:.3g}"
    if isinstance(x, int | float) and math.isfinite(x):
        return f"{int(x)}"
    return str(x)


# ------------------------------------------------------------------------------ active limits
def active_limits() -> InputLimits:
    """The limits in force: :data:`DEFAULT_LIMITS` with the overrides of ``$GRIP_LIMITS``.

    Raises:
        ValueError: ``$GRIP_LIMITS`` names an unknown limit or holds a bad value.
    """
    text = os.environ.get(LIMITS_ENV, "").strip()
    if not text:
        return DEFAULT_LIMITS
    items = [s for s in re.split(r"[,\s]+", text) if s]
    try:
        return DEFAULT_LIMITS.with_overrides(items)
    except ValueError as e:
        raise ValueError(f"${LIMITS_ENV}: {e}") from None


def set_active_limits(limits: InputLimits) -> None:
    """Makes ``limits`` the limits of this process and of the worker processes it starts.

    Writes their differences from the defaults to ``$GRIP_LIMITS`` (removes it when there are
    none). Called by the command-line tools only (``--input-limit``); library code takes ``limits``
    arguments.
    """
    over = limits.overrides()
    if over:
        os.environ[LIMITS_ENV] = ",".join(f"{k}={v!r}" for k, v in over.items())
    else:
        os.environ.pop(LIMITS_ENV, None)


def limit_help() -> str:
    """One line per limit, ``name=default``, for ``--help`` texts."""
    return ", ".join(f"{n}={_fmt(getattr(DEFAULT_LIMITS, n))}" for n in InputLimits.names())


# --------------------------------------------------------------------------------- files
def check_file_size(path: str | os.PathLike, limits: InputLimits) -> int:
    """Size of ``path`` in bytes; :class:`LimitExceeded` above ``max_file_bytes``.

    Raises:
        OSError: The file cannot be stat'ed.
    """
    size = os.stat(path).st_size
    limits.check("max_file_bytes", size, "file size", " bytes")
    return size


def check_zip(source: str | os.PathLike | bytes | Any, limits: InputLimits,
              what: str = "zip") -> list[zipfile.ZipInfo]:  # fmt: skip
    """The members of a zip (an npz, a torch file, a ``model.zip``) with the sizes they declare
    checked before any is decompressed (a 2 MB zip of deflated zeros expands to gigabytes).

    Python's :mod:`zipfile` never inflates a member beyond its declared size, nor does torch's
    reader (it allocates that size), so the declared sizes bound what the file expands to.

    Args:
        source: A path, the bytes of a zip, or a seekable binary file.
        limits: The limits to apply.
        what: What the zip is, for the messages (``"npz"``, ``"torch file"``).

    Returns:
        The members, in the order of the zip's directory.

    Raises:
        LimitExceeded: More members than ``max_elements``, a member larger than
            ``max_array_bytes`` or all together larger than ``max_total_bytes`` (uncompressed).
        zipfile.BadZipFile: Not a zip.
    """
    if isinstance(source, bytes | bytearray):
        source = io.BytesIO(source)
    with zipfile.ZipFile(source) as zf:
        infos = zf.infolist()
    limits.check("max_elements", len(infos), f"number of {what} members")
    total = 0
    for info in infos:
        limits.check("max_array_bytes", info.file_size,
                     f"{what} member {info.filename!r} (uncompressed size)", " bytes")  # fmt: skip
        total += info.file_size
        limits.check("max_total_bytes", total, f"sum of the {what}'s members up to "
                     f"{info.filename!r} (uncompressed)", " bytes")  # fmt: skip
    return infos


def _npy_header(f: Any) -> tuple[tuple[int, ...], bool, np.dtype]:
    fmt = np.lib.format
    version = fmt.read_magic(f)
    if version == (1, 0):
        return fmt.read_array_header_1_0(f)
    if version == (2, 0):
        return fmt.read_array_header_2_0(f)
    return fmt._read_array_header(f, version)  # (3, 0): utf-8 header


def check_npz(
    path: str | os.PathLike, limits: InputLimits
) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """Inspects an npz's members (zip sizes and npy headers) without loading any array.

    Args:
        path: The ``.npz`` file.
        limits: The limits to apply.

    Returns:
        Member name (without ``.npy``) -> (shape, dtype) as the npy headers declare them.

    Raises:
        LimitExceeded: The file, a member or their sum is above ``max_file_bytes``,
            ``max_array_bytes`` or ``max_total_bytes`` (each member's declared uncompressed size
            and the size its header's shape and dtype imply are both checked).
        ValueError: Not a zip, a member is not an npy array, holds Python objects, or is shorter
            than its header says (truncated): the array would not load.
        OSError: The file cannot be read.
    """
    check_file_size(path, limits)
    out: dict[str, tuple[tuple[int, ...], np.dtype]] = {}
    total = 0
    try:
        check_zip(path, limits, "npz")
        with zipfile.ZipFile(path) as zf:
            for info in zf.infolist():
                name = info.filename.removesuffix(".npy")
                with zf.open(info) as f:
                    shape, _fortran, dtype = _npy_header(f)
                    header_len = f.tell()
                if dtype.hasobject:
                    raise ValueError(f"npz member {name!r} holds Python objects (dtype {dtype})")
                nbytes = math.prod(shape) * dtype.itemsize
                limits.check("max_array_bytes", nbytes,
                             f"npz member {name!r} {tuple(shape)} {dtype}", " bytes")  # fmt: skip
                if header_len + nbytes > info.file_size:
                    raise ValueError(f"npz member {name!r} is truncated: its header declares "
                                     f"{nbytes} bytes of data, the member holds "
                                     f"{info.file_size - header_len}")  # fmt: skip
                total += nbytes
                limits.check("max_total_bytes", total, "sum of the npz's arrays", " bytes")
                out[name] = (tuple(int(s) for s in shape), dtype)
    except zipfile.BadZipFile as e:
        raise ValueError(f"not a readable npz/zip file ({e})") from None
    return out


def load_checked_npz(path: str | os.PathLike, limits: InputLimits, error: type[Exception],
                     what: str = ".npz file") -> tuple[dict[str, np.ndarray], Any]:  # fmt: skip
    """The arrays of an npz checked by :func:`check_npz` first, and its JSON ``"__meta__"``
    member parsed by :func:`safe_json_loads` (removed from the arrays).

    Args:
        path: The ``.npz`` file.
        limits: The limits to apply.
        error: Exception class raised on any problem, with a message naming ``path``.
        what: The kind of file, for the message of an unreadable one.

    Returns:
        ``(arrays, meta)``: member name -> array, and the parsed metadata (not yet checked).
    """
    try:
        check_npz(path, limits)
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except LimitExceeded as e:
        raise error(f"{path}: {e}") from None
    except Exception as e:  # any failure of zipfile/numpy: a corrupt or hostile file
        raise error(f"{path}: not a readable {what} "
                    f"({type(e).__name__}: {str(e)[:300]})") from None  # fmt: skip
    try:
        meta = safe_json_loads(str(data.pop("__meta__")), limits, "'__meta__'")
    except LimitExceeded as e:
        raise error(f"{path}: {e}") from None
    except (KeyError, ValueError) as e:
        raise error(f"{path}: missing or corrupt '__meta__' ({e})") from None
    return data, meta


# ---------------------------------------------------------------------------------- JSON
_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.DOTALL)


def json_depth(text: str) -> int:
    """Deepest nesting of ``[``/``{`` in a JSON text (strings skipped), without recursion."""
    stripped = _JSON_STRING.sub('""', text)
    codes = np.frombuffer(stripped.encode("utf-8", "replace"), dtype=np.uint8)
    step = (np.isin(codes, (ord("["), ord("{"))).astype(np.int64)
            - np.isin(codes, (ord("]"), ord("}"))))  # fmt: skip
    return int(np.cumsum(step).max(initial=0))


def safe_json_loads(text: str, limits: InputLimits, what: str = "JSON") -> Any:
    """``json.loads`` with the nesting depth and integer digits bounded first.

    Raises:
        LimitExceeded: Nesting deeper than ``max_depth`` (checked before parsing, so no
            ``RecursionError``) or an integer longer than ``max_int_digits``.
        ValueError: Not valid JSON (``json.JSONDecodeError``).
    """
    limits.check("max_depth", json_depth(text), f"{what} nesting depth")

    def parse_int(s: str) -> int:
        limits.check("max_int_digits", len(s.lstrip("-")), f"{what} integer of")
        return int(s)

    return json.loads(text, parse_int=parse_int)


def read_json_file(path: str | os.PathLike, what: str = "JSON file",
                   limits: InputLimits | None = None, kind: type = dict) -> Any:  # fmt: skip
    """A JSON file of a run folder or dataset (``config.json``, ``state.json``, ...), bounded.

    Args:
        path: The file.
        what: What it should be, for the messages (``"policy train run config"``).
        limits: Default :func:`active_limits`.
        kind: The type its top level must have (``dict``; ``object`` for any).

    Raises:
        ValueError: ``"{path}: not a {what} (...)"``: unreadable, not UTF-8, not JSON, nested
            too deep, an absurd integer, too large or of another type at its top level.
    """
    limits = limits or active_limits()
    try:
        check_file_size(path, limits)
        with open(path, "rb") as f:
            text = f.read().decode("utf-8")
        obj = safe_json_loads(text, limits, "JSON")
    except (OSError, UnicodeDecodeError, ValueError) as e:
        reason = e.strerror if isinstance(e, OSError) and e.strerror else str(e)[:300]
        raise ValueError(f"{path}: not a {what} ({reason})") from None
    if not isinstance(obj, kind):
        raise ValueError(f"{path}: not a {what} (a JSON {type(obj).__name__}, expected "
                         f"{kind.__name__})")  # fmt: skip
    return obj


# ---------------------------------------------------------------------------------- trees
def check_tree(obj: Any, limits: InputLimits, what: str = "content") -> None:
    """Walks a nested structure (dicts, lists, tuples, sets, numpy arrays, torch tensors)
    without recursion.

    Raises:
        LimitExceeded: Nesting deeper than ``max_depth``, more than ``max_elements`` containers
            and items walked (a structure that shares sub-structures many times counts each
            time: no exponential walk downstream), or arrays (each counted every time it is
            referenced) summing to more than ``max_total_bytes``.
    """
    stack: list[tuple[Any, int]] = [(obj, 1)]
    items = 0
    nbytes = 0
    while stack:
        node, depth = stack.pop()
        if _is_array(node):
            nbytes += int(node.nbytes)
            limits.check("max_total_bytes", nbytes, f"{what}: sum of its arrays", " bytes")
            continue
        if isinstance(node, Mapping):
            children: Iterable[Any] = node.values()
            n = len(node)
        elif isinstance(node, list | tuple | set | frozenset):
            children, n = node, len(node)
        else:
            continue
        limits.check("max_depth", depth, f"{what}: nesting depth")
        items += n + 1
        limits.check("max_elements", items, f"{what}: containers and items walked")
        stack.extend((c, depth + 1) for c in children
                     if isinstance(c, Mapping | list | tuple | set | frozenset)
                     or _is_array(c))  # fmt: skip


def _is_array(node: Any) -> bool:
    """A numpy array, or an array of another library (a torch tensor: ``nbytes``, ``shape``
    and ``dtype``; its ``nbytes`` is its logical size, so a stride-0 view counts in full)."""
    return isinstance(node, np.ndarray) or (
        not isinstance(node, type) and isinstance(getattr(node, "nbytes", None), int)
        and hasattr(node, "shape") and hasattr(node, "dtype"))  # fmt: skip
