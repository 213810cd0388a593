"""Moticon OpenGo text export (``.txt``): reading and writing, our own implementation of the
layout that Moticon's OpenGo software writes (documented by Moticon's ``moticon-opengo``
package and its test exports).

Layout::

    # Start time: 27.09.2023 10:21:14.922
    # Duration: 00:17.496
    # Sensor insoles: Left SN5968, Right SN9171
    # Size: 7
    # Recording type: normal
    # Name: 230927_10:21:14
    # time<TAB>left pressure 1[N/cm²]<TAB>...<TAB>left pressure 16[N/cm²]
      <TAB>left acceleration X[g]...<TAB>left angular X[dps]...<TAB>left total force[N]
      <TAB>left center of pressure X[-0.5...+0.5]<TAB>left center of pressure Y[-0.5...+0.5]
      <TAB>right ... (the same 25 channels)<TAB>right steps[]<TAB>left steps[]   (one line)
    0.00<TAB><TAB>...<TAB>6.50<TAB>6.50<TAB>...

Header lines start with ``#``; the last one names the tab-separated channels. Every data row
has one field per channel. Left and right share the time column (s); a side without a sample in a
row leaves its fields empty (the sides start, stop and drop samples independently). Optional
channels (the IMU, total force, CoP, step events, CoP velocity, user event columns ``<group>
label[]`` + ``<group>[]``) may be absent; the 16 pressures of a side are required for that side.

Units and frames (as exported, and what :func:`read_moticon` returns):

* pressure: N/cm^2 per cell (cells 1-16; :data:`CELL_MAP`);
* total force: N (Moticon's own sum, with its cell-area factors that cover the gaps between the
  cells: it exceeds the sum of pressure x cell area);
* centre of pressure: normalised insole coordinates in ``[-0.5, 0.5]``, X along the insole
  (heel -0.5 -> toe +0.5), Y across it (lateral -0.5 -> medial +0.5), the same on both feet
  (Moticon: "size and side agnostic"); ``(0, 0)`` while unloaded;
* acceleration: g (specific force, gravity included: about +1 g along z at rest);
* angular rate: deg/s;
* IMU frame: x towards the toes, y medial, z up (out of the insole's top). The right insole's
  frame is right-handed (y = the subject's left); the left insole's is its mirror image (y =
  the subject's right, left-handed), as the GRIP supplement describes (its eq. 3). The reader
  returns both in the right-handed frame x toes, y subject's left, z up: the left insole's
  acceleration times (1, -1, 1) and angular rate times (-1, 1, -1) (a mirrored axial vector),
  in m/s^2 and rad/s; the writer does the reverse.
* step events (``left steps[]``/``right steps[]``): 11/21 heel strike, 15/25 toe off
  (left/right).

The axis conventions were checked on Moticon's published test exports: at rest both insoles read
about (-0.2, +0.04, +0.97) g (x forward with the shoe's heel drop, z up, the same y sign on both
feet: mirrored frames), the angular-rate distributions of the two feet agree axis by axis, and a
least-squares fit of the CoP to the pressures puts each cell where :data:`CELL_MAP` says. Which
insole is right-handed is the GRIP supplement's statement (IMU data cannot tell a motion from its
mirror image).

This module imports numpy and :mod:`grip.core.limits` only.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from grip.core.limits import InputLimits
from prism_tools.devices.common import (
    DeviceFileError,
    parse_column,
    read_text_lines,
    require_increasing,
)
from prism_tools.streams import FEET, GRAVITY, N_INSOLE_CELLS

__all__ = [
    "CELL_MAP",
    "LEFT_ACC_SIGN",
    "LEFT_GYR_SIGN",
    "MoticonExport",
    "MoticonSide",
    "read_moticon",
    "write_moticon",
]

CELL_MAP: tuple[int, ...] = tuple(range(N_INSOLE_CELLS))
"""Our insole cell (index) of each Moticon cell ``pressure k`` (``k = 1..16`` -> ``k - 1``).

PRISM recorded Moticon OpenGo insoles and lists the 16 cells in Moticon's order, zero-based
(PRISM_FORMAT.md: 0-1 rear heel, 2-3 front heel, 4-5 rear midfoot, 6 medial arch, 7 lateral arch,
8-12 metatarsal heads from the first, 13 hallux, 14-15 lesser toes); the body model's layout
(:data:`grip.core.skeleton.INSOLE_CELL_UV`) follows it. Fitted on Moticon's test exports, the CoP
puts Moticon's cells 1-16 at (X along, Y medial): 1-2 (-0.41, +0.11/-0.16), 3-4 (-0.28,
+0.09/-0.23), 5-6 (-0.2/-0.1, +0.03/-0.27), 7 (0.0, +0.25), 8 (-0.1, -0.52), 9-13 (0.15-0.3,
+0.38 ... -0.41), 14 (0.38, +0.15), 15 (0.5, -0.06), 16 (0.33, -0.21): the same order."""

LEFT_ACC_SIGN = np.array([1.0, -1.0, 1.0])
"""Left insole: raw acceleration x this = the right-handed frame's (and back)."""
LEFT_GYR_SIGN = np.array([-1.0, 1.0, -1.0])
"""Left insole: raw angular rate x this = the right-handed frame's (and back)."""

_SIDE_FOOT = {"left": "L_Foot", "right": "R_Foot"}
_FOOT_SIDE = {v: k for k, v in _SIDE_FOOT.items()}
_STEP_CODES = {"L_Foot": (11, 15), "R_Foot": (21, 25)}  # heel strike, toe off
_CHANNEL = re.compile(
    r"^(?P<side>left|right) (?P<group>[a-zA-Z ]+?)(?: (?P<index>[XYZ]|\d+))?\s*"
    r"\[(?P<unit>[^\]]*)\]$"
)
_UNITS: dict[str, dict[str, float]] = {  # group -> accepted unit -> factor to SI
    "pressure": {"n/cm²": 1.0, "n/cm2": 1.0, "n/cm^2": 1.0},
    "acceleration": {"g": GRAVITY, "m/s²": 1.0, "m/s2": 1.0, "m/s^2": 1.0},
    "angular": {"dps": math.pi / 180.0, "deg/s": math.pi / 180.0, "°/s": math.pi / 180.0,
                "rad/s": 1.0},
    "total force": {"n": 1.0},
    "center of pressure": {"-0.5...+0.5": 1.0},
    "steps": {"": 1.0},
}  # fmt: skip
_WIDTH = {"pressure": N_INSOLE_CELLS, "acceleration": 3, "angular": 3, "center of pressure": 2}


@dataclass(frozen=True, eq=False)
class MoticonSide:
    """One insole's channels on the export's rows (``N`` rows; NaN where the side has none).

    Attributes:
        valid: ``(N,)`` bool, rows holding this side's sample (all 16 pressures present).
        pressure_n_cm2: ``(N, 16)`` cell pressures, N/cm^2, Moticon's cell order (= ours).
        acc_mps2: ``(N, 3)`` specific force (gravity included), m/s^2, right-handed insole
            frame (x toes, y subject's left, z up), or ``None`` when not exported.
        gyr_rad_s: ``(N, 3)`` angular rate, rad/s, the same frame, or ``None``.
        total_force_n: ``(N,)`` total force, N, or ``None``.
        cop_norm: ``(N, 2)`` centre of pressure (X along heel -> toe, Y lateral -> medial), in
            ``[-0.5, 0.5]``, or ``None``.
        heel_strike_rows: ``(K,)`` rows of heel-strike events (empty without a steps channel).
        toe_off_rows: ``(K,)`` rows of toe-off events.
    """

    valid: np.ndarray
    pressure_n_cm2: np.ndarray
    acc_mps2: np.ndarray | None = None
    gyr_rad_s: np.ndarray | None = None
    total_force_n: np.ndarray | None = None
    cop_norm: np.ndarray | None = None
    heel_strike_rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    toe_off_rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


@dataclass(frozen=True, eq=False)
class MoticonExport:
    """A Moticon OpenGo text export.

    Attributes:
        time_s: ``(N,)`` row times, s, strictly increasing (the insoles' clock).
        sides: ``"L_Foot"``/``"R_Foot"`` -> :class:`MoticonSide` (the sides exported).
        meta: Header fields (``"Start time"``, ``"Size"``, ``"Sensor insoles"``, ...).
        source: The file read (``""`` when built in memory).
    """

    time_s: np.ndarray
    sides: dict[str, MoticonSide]
    meta: dict[str, str] = field(default_factory=dict)
    source: str = ""

    @property
    def insole_size(self) -> str | None:
        """The ``Size`` header field (Moticon's insole size), or ``None``."""
        return self.meta.get("Size") or None


@dataclass
class _Column:
    index: int
    foot: str
    group: str
    slot: int
    factor: float


def _parse_channels(names: list[str], source: str, line: int) -> tuple[int, list[_Column]]:
    """The time column and the channels this reader uses (others are skipped)."""
    clean = [n.strip() for n in names]
    time_cols = [i for i, n in enumerate(clean) if n.lower() in ("time", "time[s]", "time [s]")]
    if not time_cols:
        raise DeviceFileError(f"{source}: line {line}: no 'time' channel in the header "
                              f"(channels: {_list(clean)}); is this a Moticon text export?")
    cols: list[_Column] = []
    seen: dict[tuple[str, str, int], int] = {}
    for i, name in enumerate(clean):
        m = _CHANNEL.match(name)
        if not m or m["group"] not in _UNITS:
            continue  # user events, COP velocity, ...: not read
        group, unit = m["group"], m["unit"].strip()
        factor = _UNITS[group].get(unit.lower())
        if factor is None:
            raise DeviceFileError(
                f"{source}: line {line}: channel {name!r}: unit [{unit}] is not one of "
                f"{sorted(_UNITS[group])}"
            )
        width = _WIDTH.get(group, 1)
        idx = m["index"]
        if width == 1:
            slot = 0
        elif idx is None:
            raise DeviceFileError(f"{source}: line {line}: channel {name!r} has no index")
        elif idx.isdigit():
            slot = int(idx) - 1
        else:
            slot = "XYZ".index(idx)
        if not 0 <= slot < width:
            raise DeviceFileError(f"{source}: line {line}: channel {name!r}: index out of range "
                                  f"(1-{width})")  # fmt: skip
        key = (m["side"], group, slot)
        if key in seen:
            raise DeviceFileError(f"{source}: line {line}: channel {name!r} appears twice "
                                  f"(columns {seen[key] + 1} and {i + 1})")  # fmt: skip
        seen[key] = i
        cols.append(_Column(i, _SIDE_FOOT[m["side"]], group, slot, factor))
    for side in ("left", "right"):
        groups = {c.group: 0 for c in cols if c.foot == _SIDE_FOOT[side]}
        for g in groups:
            have = sorted(c.slot for c in cols if c.foot == _SIDE_FOOT[side] and c.group == g)
            need = list(range(_WIDTH.get(g, 1)))
            if have != need:
                raise DeviceFileError(
                    f"{source}: line {line}: {side} {g}: expected {len(need)} channels, got "
                    f"{len(have)}"
                )
        if groups and "pressure" not in groups:
            raise DeviceFileError(f"{source}: line {line}: {side} insole channels without its 16 "
                                  "'pressure' channels")  # fmt: skip
    if not cols:
        raise DeviceFileError(f"{source}: line {line}: no 'left ...' or 'right ...' insole "
                              f"channels (channels: {_list(clean)})")  # fmt: skip
    return time_cols[0], cols


def _list(names: list[str]) -> str:
    shown = ", ".join(repr(n) for n in names[:8])
    return shown + (f", ... ({len(names)} in all)" if len(names) > 8 else "")


def read_moticon(path: str | os.PathLike[str], limits: InputLimits | None = None) -> MoticonExport:
    """Reads a Moticon OpenGo text export.

    Args:
        path: The ``.txt`` file.
        limits: Input limits (file size, line count); default the active ones.

    Returns:
        The export in SI units and right-handed insole frames (module docstring).

    Raises:
        FileNotFoundError: ``path`` does not exist.
        DeviceFileError: A malformed file, naming the file and the line: no channel header, a
            row with a wrong field count, a non-numeric value in a channel read, a time that
            does not increase, a side with some but not all of its pressures in a row, an
            unknown unit, no sample at all.
    """
    source = str(path)
    lines = read_text_lines(path, limits)
    meta: dict[str, str] = {}
    header: tuple[int, list[str]] | None = None
    first_data = len(lines)
    for n, raw in enumerate(lines):
        if not raw.startswith("#"):
            if raw.strip():
                first_data = n
                break
            continue
        body = raw[1:].strip()
        if "\t" in body or body.lower().startswith("time"):
            header = (n + 1, body.split("\t"))
        elif ":" in body:
            key, value = body.split(":", 1)
            meta[key.strip()] = value.strip()
    if header is None:
        raise DeviceFileError(f"{source}: no channel header (a '# time<TAB>left pressure 1[N/cm²]"
                              "...' line); is this a Moticon OpenGo text export?")  # fmt: skip
    header_line, names = header
    time_col, cols = _parse_channels(names, source, header_line)
    rows, line_no = [], []
    for n in range(first_data, len(lines)):
        raw = lines[n]
        if not raw.strip():
            continue
        if raw.startswith("#"):
            raise DeviceFileError(f"{source}: line {n + 1}: a '#' header line after the data")
        fields = raw.split("\t")
        if len(fields) != len(names):
            raise DeviceFileError(
                f"{source}: line {n + 1}: {len(fields)} tab-separated fields, the header names "
                f"{len(names)} channels (wrong column count)"
            )
        rows.append(fields)
        line_no.append(n + 1)
    if not rows:
        raise DeviceFileError(f"{source}: no data rows after the header")
    lines_arr = np.asarray(line_no)
    time_s = parse_column([r[time_col] for r in rows], lines_arr,
                          lambda ln: f"{source}: line {ln}: column 'time'")  # fmt: skip
    require_increasing(time_s, lines_arr, source)
    sides: dict[str, MoticonSide] = {}
    for foot in FEET:
        mine = [c for c in cols if c.foot == foot]
        if mine:
            sides[foot] = _read_side(foot, mine, rows, lines_arr, names, source)
    return MoticonExport(time_s=time_s, sides=sides, meta=meta, source=source)


def _read_side(foot: str, cols: list[_Column], rows: list[list[str]], lines: np.ndarray,
               names: list[str], source: str) -> MoticonSide:  # fmt: skip
    n = len(rows)
    arrays: dict[str, np.ndarray] = {}
    for c in cols:
        a = arrays.setdefault(c.group, np.full((n, _WIDTH.get(c.group, 1)), np.nan))
        name = names[c.index].strip()
        a[:, c.slot] = parse_column([r[c.index] for r in rows], lines,
                                    lambda ln, name=name: f"{source}: line {ln}: column {name!r}"
                                    ) * c.factor  # fmt: skip
    p = arrays["pressure"]
    present = np.isfinite(p)
    partial = np.flatnonzero(present.any(axis=1) & ~present.all(axis=1))
    if partial.size:
        i = int(partial[0])
        raise DeviceFileError(
            f"{source}: line {lines[i]}: {int(present[i].sum())} of the 16 "
            f"{_FOOT_SIDE[foot]} pressures present (a side's row has all or none)"
        )
    valid = present.all(axis=1)
    acc = arrays.get("acceleration")
    gyr = arrays.get("angular")
    if foot == "L_Foot":
        acc = None if acc is None else acc * LEFT_ACC_SIGN
        gyr = None if gyr is None else gyr * LEFT_GYR_SIGN
    hs = to = np.zeros(0, dtype=np.int64)
    if "steps" in arrays:
        codes = arrays["steps"][:, 0]
        hs_code, to_code = _STEP_CODES[foot]
        hs = np.flatnonzero(codes == hs_code).astype(np.int64)
        to = np.flatnonzero(codes == to_code).astype(np.int64)
    force = arrays.get("total force")
    return MoticonSide(
        valid=valid,
        pressure_n_cm2=p,
        acc_mps2=acc,
        gyr_rad_s=gyr,
        total_force_n=None if force is None else force[:, 0],
        cop_norm=arrays.get("center of pressure"),
        heel_strike_rows=hs,
        toe_off_rows=to,
    )


# ------------------------------------------------------------------------------------- writing
def _fmt(values: np.ndarray, spec: str) -> list[str]:
    """Numbers as text, ``""`` for NaN, ``-0.00`` printed ``0.00``."""
    out = []
    for v in values:
        text = "" if not np.isfinite(v) else format(float(v), spec)
        out.append(text[1:] if text.startswith("-") and float(text) == 0.0 else text)
    return out


def write_moticon(path: str | os.PathLike[str], export: MoticonExport) -> None:
    """Writes an export in Moticon OpenGo's text layout (the reverse of :func:`read_moticon`).

    Numbers as the OpenGo software prints them: time with 2 decimals (more where the times need
    them), pressures and total force with 2, acceleration (g), angular rate (deg/s) and CoP
    with 6; a side's fields are empty in rows where it has no sample. The left insole's IMU is
    written in its mirrored frame.

    Args:
        path: Destination ``.txt`` (written atomically; its folder is created).
        export: What to write; ``meta`` gives the header fields (defaults fill the usual ones).
    """
    from grip.core.atomic import atomic_write_text

    t = np.asarray(export.time_s, dtype=np.float64)
    t_spec = ".2f" if np.allclose(np.round(t, 2), t, atol=1e-9) else ".5f"
    columns: list[tuple[str, list[str]]] = [("time", _fmt(t, t_spec))]
    steps: list[tuple[str, list[str]]] = []
    for foot in FEET:
        s = export.sides.get(foot)
        if s is None:
            continue
        side = _FOOT_SIDE[foot]
        keep = np.asarray(s.valid, dtype=bool)

        def masked(a: np.ndarray, keep: np.ndarray = keep) -> np.ndarray:
            a = np.asarray(a, dtype=np.float64).copy()
            a[~keep] = np.nan
            return a

        p = masked(s.pressure_n_cm2)
        columns += [(f"{side} pressure {k + 1}[N/cm²]", _fmt(p[:, k], ".2f"))
                    for k in range(N_INSOLE_CELLS)]  # fmt: skip
        if s.acc_mps2 is not None:
            acc = masked(s.acc_mps2) / GRAVITY * (LEFT_ACC_SIGN if foot == "L_Foot" else 1.0)
            columns += [(f"{side} acceleration {a}[g]", _fmt(acc[:, i], ".6f"))
                        for i, a in enumerate("XYZ")]  # fmt: skip
        if s.gyr_rad_s is not None:
            gyr = np.degrees(masked(s.gyr_rad_s)) * (LEFT_GYR_SIGN if foot == "L_Foot" else 1.0)
            columns += [(f"{side} angular {a}[dps]", _fmt(gyr[:, i], ".6f"))
                        for i, a in enumerate("XYZ")]  # fmt: skip
        if s.total_force_n is not None:
            columns.append((f"{side} total force[N]", _fmt(masked(s.total_force_n), ".2f")))
        if s.cop_norm is not None:
            cop = masked(s.cop_norm)
            columns += [(f"{side} center of pressure {a}[-0.5...+0.5]", _fmt(cop[:, i], ".6f"))
                        for i, a in enumerate("XY")]  # fmt: skip
        codes = np.full(len(t), np.nan)
        hs_code, to_code = _STEP_CODES[foot]
        codes[np.asarray(s.heel_strike_rows, dtype=np.int64)] = hs_code
        codes[np.asarray(s.toe_off_rows, dtype=np.int64)] = to_code
        steps.append((f"{side} steps[]", _fmt(codes, ".0f")))
    columns += steps[::-1]  # Moticon writes "right steps[]" before "left steps[]"
    duration = float(t[-1] - t[0]) if len(t) else 0.0
    meta = {
        "Start time": "01.01.2024 00:00:00.000",
        "Duration": f"{int(duration // 60):02d}:{duration % 60:06.3f}",
        "Sensor insoles": ", ".join(f"{_FOOT_SIDE[f].capitalize()} SN0000" for f in export.sides),
        "Size": "7",
        "Recording type": "normal",
        "Name": Path(path).stem,
        **export.meta,
    }
    out = [f"# {k}: {v}" for k, v in meta.items()]
    out.append("# " + "\t".join(name for name, _ in columns))
    for i in range(len(t)):
        out.append("\t".join(vals[i] for _, vals in columns))
    atomic_write_text(path, "\n".join(out) + "\n")
