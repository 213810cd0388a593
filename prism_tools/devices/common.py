"""What the device readers share: the error type, bounded text reading, number parsing with
line numbers, time checks and the gaps of a sample stream.

This module imports numpy and :mod:`grip.core.limits` only.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from grip.core.limits import InputLimits, LimitExceeded, active_limits, check_file_size
from prism_tools.errors import RecordingError

__all__ = [
    "DeviceFileError",
    "Gap",
    "StreamGaps",
    "find_gaps",
    "parse_column",
    "parse_float",
    "read_text_lines",
    "require_increasing",
]


class DeviceFileError(RecordingError):
    """A device export is malformed. The message starts with the file, then the line where there
    is one (``"L.csv: line 12: column 'Acc_X': 'abc' is not a number"``)."""


def read_text_lines(path: str | os.PathLike[str], limits: InputLimits | None = None) -> list[str]:
    """The lines of a text export, without line ends, bounded by the input limits.

    The file size is checked against ``limits.max_file_bytes`` before it is read; it is then
    read in blocks of 1 MiB, and a line longer than ``max_line_bytes``, more lines than
    ``max_frames`` or more text than ``max_total_bytes`` is refused as soon as it is seen (one
    1 GB line is never held whole). Lines end at ``\n``, ``\r\n`` or ``\r``. UTF-8 (a
    byte-order mark is dropped), with Latin-1 as the fallback for exports written in a Windows
    code page (``N/cm²`` in cp1252).

    Raises:
        FileNotFoundError: ``path`` does not exist (the message names it).
        DeviceFileError: Too large, a line too long (named by its number), unreadable, or with
            a NUL byte (a binary file).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    limits = limits or active_limits()
    try:
        check_file_size(path, limits)
        raw = _read_lines(path, limits)
    except LimitExceeded as e:
        raise DeviceFileError(f"{path}: {e}") from None
    except OSError as e:
        raise DeviceFileError(f"{path}: cannot read ({e.strerror or e})") from None
    if isinstance(raw, tuple):  # (line number, reason)
        raise DeviceFileError(f"{path}: {raw[1]}" if raw[0] == 0 else
                              f"{path}: line {raw[0]}: {raw[1]}")  # fmt: skip
    try:
        lines = [b.decode("utf-8") for b in raw]
        if lines and lines[0].startswith("\ufeff"):
            lines[0] = lines[0][1:]
    except UnicodeDecodeError:
        lines = [b.decode("latin-1") for b in raw]
    return lines


_BLOCK_BYTES = 2**20


def _read_lines(path: Path, limits: InputLimits) -> list[bytes] | tuple[int, str]:
    """The lines of ``path`` as bytes (line ends removed), or ``(line number, reason)`` of the
    first refused one (0: the file as a whole).

    Raises:
        LimitExceeded: More lines than ``max_frames`` or more bytes than ``max_total_bytes``.
    """
    lines: list[bytes] = []
    carry, total = b"", 0

    def add(line: bytes) -> str | None:
        nonlocal total
        if len(line) > limits.max_line_bytes:
            return _line_too_long(len(line), limits)
        lines.append(line)
        total += len(line)
        limits.check("max_frames", len(lines), "lines")
        limits.check("max_total_bytes", total, "text read", " bytes")
        return None

    with path.open("rb") as f:
        while block := f.read(_BLOCK_BYTES):
            if b"\0" in block:
                return 0, "not a text file (it holds NUL bytes)"
            parts = (carry + block).splitlines(keepends=True)
            last = parts[-1]
            # an unfinished line (or a "\r" whose "\n" may start the next block) waits for more
            carry = last if not last.endswith(b"\n") else b""
            for part in parts[:-1] if carry else parts:
                bad = add(part.rstrip(b"\r\n"))
                if bad:
                    return len(lines) + 1, bad
            if len(carry) > limits.max_line_bytes + 1:
                return len(lines) + 1, _line_too_long(len(carry), limits, at_least=True)
    if carry:
        bad = add(carry.rstrip(b"\r\n"))
        if bad:
            return len(lines) + 1, bad
    return lines


def _line_too_long(n: int, limits: InputLimits, at_least: bool = False) -> str:
    """The refusal of a line of ``n`` bytes (``at_least``: read so far)."""
    try:
        limits.check("max_line_bytes", n, "a line of" + (" at least" if at_least else ""),
                     " bytes")  # fmt: skip
    except LimitExceeded as e:
        return str(e)
    return ""


def parse_float(text: str, where: str) -> float:
    """A number of a text export: empty and ``nan`` give NaN (a missing sample); infinities and
    anything else that is not a number are errors.

    Args:
        text: The field.
        where: ``"FILE: line N: column 'NAME'"`` for the message.

    Raises:
        DeviceFileError: ``"<where>: 'abc' is not a number"``.
    """
    s = text.strip()
    if not s or s.lower() == "nan":
        return math.nan
    try:
        value = float(s)
    except ValueError:
        raise DeviceFileError(f"{where}: {_show(s)} is not a number") from None
    if math.isinf(value):
        raise DeviceFileError(f"{where}: {_show(s)} is not a finite number")
    return value


def parse_column(texts: list[str], lines: np.ndarray, where: Callable[[int], str]) -> np.ndarray:
    """A column of a text export as ``(N,)`` float64 (vectorised; :func:`parse_float`'s rules).

    Args:
        texts: The column's fields.
        lines: ``(N,)`` 1-based file line of each field, for the message.
        where: The message prefix of a line, for example
            ``lambda line: f"L.csv: line {line}: column 'Acc_X'"``.

    Raises:
        DeviceFileError: A field that is not a number, or an infinity.
    """
    cleaned = [t.strip() or "nan" for t in texts]
    try:
        values = np.asarray(cleaned, dtype=np.float64)
    except ValueError:
        values = None
    if values is None or np.isinf(values).any():
        for text, line in zip(texts, lines, strict=True):
            parse_float(text, where(int(line)))
    return values if values is not None else np.zeros(0)


def _show(s: str) -> str:
    return repr(s if len(s) <= 40 else s[:40] + "...")


def require_increasing(time_s: np.ndarray, line_of: np.ndarray, source: str) -> None:
    """Refuses a time column that does not increase strictly (a concatenated or re-sorted export).

    Args:
        time_s: ``(N,)`` sample times, s (NaN for rows without a time is an error too).
        line_of: ``(N,)`` 1-based file line of each sample, for the message.
        source: The file, for the message.

    Raises:
        DeviceFileError: ``"FILE: line 57: time 1.2 s is not after the previous sample's 1.3 s
            (line 56): the time column must increase"``.
    """
    if time_s.size == 0:
        return
    bad = np.flatnonzero(~np.isfinite(time_s))
    if bad.size:
        i = int(bad[0])
        raise DeviceFileError(f"{source}: line {int(line_of[i])}: the time is missing")
    steps = np.diff(time_s)
    back = np.flatnonzero(steps <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise DeviceFileError(
            f"{source}: line {int(line_of[i])}: time {time_s[i]:.6g} s is not after the previous "
            f"sample's {time_s[i - 1]:.6g} s (line {int(line_of[i - 1])}): the time column must "
            "increase (non-monotonic time)"
        )


@dataclass(frozen=True)
class Gap:
    """Missing samples between two samples of a stream.

    Attributes:
        start_s: Time of the last sample before the gap, s (the stream's own clock).
        end_s: Time of the first sample after it, s.
        missing: Number of samples the nominal rate expects in between.
    """

    start_s: float
    end_s: float
    missing: int

    @property
    def length_s(self) -> float:
        return self.end_s - self.start_s


@dataclass(frozen=True)
class StreamGaps:
    """The sampling of one stream.

    Attributes:
        rate_hz: Nominal sample rate (the median sample step), Hz.
        samples: Samples present.
        gaps: Steps longer than 1.5 nominal steps, in time order.
    """

    rate_hz: float
    samples: int
    gaps: tuple[Gap, ...]

    @property
    def missing(self) -> int:
        """Samples the nominal rate expects that are absent."""
        return sum(g.missing for g in self.gaps)

    @property
    def longest_s(self) -> float:
        return max((g.length_s for g in self.gaps), default=0.0)


def find_gaps(time_s: np.ndarray) -> StreamGaps:
    """Nominal rate and gaps of a stream's present samples.

    Args:
        time_s: ``(N,)`` strictly increasing times of the samples present, s, ``N >= 2``.

    Returns:
        The rate (1 / median step) and every step above 1.5 median steps as a :class:`Gap`.
    """
    steps = np.diff(np.asarray(time_s, dtype=np.float64))
    if steps.size == 0:
        raise ValueError("find_gaps: a stream needs at least 2 samples")
    dt = float(np.median(steps))
    idx = np.flatnonzero(steps > 1.5 * dt)
    gaps = tuple(
        Gap(float(time_s[i]), float(time_s[i + 1]), max(1, round(steps[i] / dt) - 1)) for i in idx
    )
    return StreamGaps(1.0 / dt, len(time_s), gaps)
