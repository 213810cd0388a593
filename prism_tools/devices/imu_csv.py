"""IMU CSV exports of wrist and foot sensors: reading and writing.

Two headers are recognised (column names are matched without regard to case, spaces and a
trailing ``[unit]``):

Movella DOT (the DOT app's CSV export, our own reader of its documented layout)::

    sep=,
    DeviceTag:,L_Wrist,,,
    OutputRate:,60Hz,,,
    ...
    PacketCounter,SampleTimeFine,Quat_W,Quat_X,Quat_Y,Quat_Z,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,Gyr_Z
    1,3525983561,0.70710,0.00000,0.00000,0.70710,0.0123,-0.0041,9.8115,0.061,-0.122,0.031

  ``SampleTimeFine``: the sensor's clock, microseconds (it wraps at 2^32 and is unwrapped);
  ``Quat_*``: orientation, sensor -> the local earth frame (x east, y north, z up), w first;
  ``Acc_*``: accelerometer, m/s^2, sensor frame, gravity included; ``FreeAcc_*`` (or
  ``FreeAcc_E/N/U``): acceleration without gravity, m/s^2, earth frame (used when ``Acc_*`` is
  absent); ``Gyr_*``: angular rate, deg/s, sensor frame. The lines before the header
  (``key:,value``) are kept as metadata.

Generic (smartwatch apps, one's own loggers)::

    time,ax,ay,az,gx,gy,gz,qw,qx,qy,qz
    0.000,0.102,-0.031,9.794,0.0012,-0.0021,0.0005,0.7071,0.0,0.0,0.7071

  ``time`` (also ``t``, ``time_s``) in s, ``time_ms`` in ms, ``time_us`` in us; acceleration
  ``ax ay az`` (or ``acc_x ...``) in the sensor frame; angular rate ``gx gy gz`` (or ``gyr_x``,
  ``gyro_x``, ``wx``); orientation sensor -> a z-up reference frame as ``qw qx qy qz`` (named
  components, any column order) or ``q0 q1 q2 q3`` (positional, ordered as
  :attr:`ImuCsvOptions.quat_order`). Units are the options' (:class:`ImuCsvOptions`): by
  default m/s^2 with gravity, rad/s, wxyz.

Required: a time column, the three accelerations, and an orientation quaternion or the three
angular rates (without a quaternion the orientation is estimated from the accelerometer and the
gyroscope, :mod:`prism_tools.devices.orientation`, which needs gravity in the acceleration).
Empty fields and ``nan`` are missing samples (dropped and reported as gaps).

This module imports numpy and :mod:`grip.core` only.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from grip.core.limits import InputLimits
from prism_tools.devices.common import (
    DeviceFileError,
    parse_column,
    read_text_lines,
    require_increasing,
)
from prism_tools.streams import GRAVITY

__all__ = [
    "ACC_KINDS",
    "FORMATS",
    "ImuCsv",
    "ImuCsvOptions",
    "read_imu_csv",
    "write_imu_csv",
]

AccKind = Literal["specific_force", "free_sensor", "free_earth"]
ACC_KINDS: tuple[str, ...] = ("specific_force", "free_sensor", "free_earth")
"""What an acceleration column holds: the accelerometer's specific force (gravity included,
sensor frame), acceleration without gravity in the sensor frame, or without gravity in the
orientation's reference frame (Movella's ``FreeAcc``)."""
FORMATS: tuple[str, ...] = ("movella_dot", "generic")

_DOT_WRAP_US = 2**32


@dataclass(frozen=True)
class ImuCsvOptions:
    """Units of a generic IMU CSV; ``None`` takes the defaults (m/s^2 with gravity, rad/s, wxyz).
    A Movella DOT file has its format's units (``Acc`` m/s^2 with gravity, ``FreeAcc`` m/s^2
    without, ``Gyr`` deg/s, ``Quat`` wxyz) and ignores these.

    Attributes:
        acc_unit: ``"g"`` (x :data:`prism_tools.streams.GRAVITY`) or ``"mps2"``.
        acc_has_gravity: The accelerations include gravity (an accelerometer's reading);
            ``False``: gravity removed, sensor frame.
        gyro_unit: ``"deg"`` (deg/s) or ``"rad"`` (rad/s).
        quat_order: Order of positional quaternion columns ``q0..q3``: ``"wxyz"`` or
            ``"xyzw"`` (named columns ``qw qx qy qz`` need none).
    """

    acc_unit: Literal["g", "mps2"] | None = None
    acc_has_gravity: bool | None = None
    gyro_unit: Literal["deg", "rad"] | None = None
    quat_order: Literal["wxyz", "xyzw"] | None = None

    def __post_init__(self) -> None:
        for name, allowed in (("acc_unit", ("g", "mps2")), ("gyro_unit", ("deg", "rad")),
                              ("quat_order", ("wxyz", "xyzw"))):  # fmt: skip
            value = getattr(self, name)
            if value is not None and value not in allowed:
                raise ValueError(f"ImuCsvOptions.{name} must be one of {allowed}, got {value!r}")


@dataclass(frozen=True, eq=False)
class ImuCsv:
    """An IMU export in SI units (``N`` samples, all channels present).

    Attributes:
        time_s: ``(N,)`` sample times, s, strictly increasing (the device's clock).
        acc_mps2: ``(N, 3)`` acceleration, m/s^2, of kind :attr:`acc_kind`.
        acc_kind: One of :data:`ACC_KINDS`.
        gyr_rad_s: ``(N, 3)`` angular rate, rad/s, sensor frame, or ``None``.
        quat_wxyz: ``(N, 4)`` unit quaternions, sensor -> reference frame (z up), or ``None``.
        fmt: ``"movella_dot"`` or ``"generic"``.
        meta: Metadata lines before the header (Movella: ``DeviceTag``, ``OutputRate``, ...).
        source: The file read (``""`` when built in memory).
        dropped_lines: 1-based lines of rows dropped for missing values.
        quat_order: The order positional quaternion columns ``q0..q3`` were read in
            (``"wxyz"``, ``"xyzw"``), ``None`` for named columns or none.
    """

    time_s: np.ndarray
    acc_mps2: np.ndarray
    acc_kind: AccKind
    gyr_rad_s: np.ndarray | None = None
    quat_wxyz: np.ndarray | None = None
    fmt: str = "generic"
    meta: dict[str, str] = field(default_factory=dict)
    source: str = ""
    dropped_lines: tuple[int, ...] = ()
    quat_order: str | None = None

    def __post_init__(self) -> None:
        if self.acc_kind not in ACC_KINDS:
            raise ValueError(f"ImuCsv.acc_kind must be one of {ACC_KINDS}, got {self.acc_kind!r}")


def _norm(name: str) -> str:
    """``" Acc_X [m/s2]"`` -> ``"acc_x"``."""
    return re.sub(r"\s*\[[^\]]*\]\s*$", "", name).strip().lower().replace(" ", "_")


_TIME_COLUMNS = {"time": 1.0, "t": 1.0, "time_s": 1.0, "time_ms": 1e-3, "time_us": 1e-6}
_GENERIC = {
    "acc": (("ax", "ay", "az"), ("acc_x", "acc_y", "acc_z")),
    "gyr": (("gx", "gy", "gz"), ("gyr_x", "gyr_y", "gyr_z"), ("gyro_x", "gyro_y", "gyro_z"),
            ("wx", "wy", "wz")),
    "quat": (("qw", "qx", "qy", "qz"), ("quat_w", "quat_x", "quat_y", "quat_z")),
    "quat_pos": (("q0", "q1", "q2", "q3"),),
}  # fmt: skip
_DOT = {
    "acc": (("acc_x", "acc_y", "acc_z"),),
    "free": (("freeacc_x", "freeacc_y", "freeacc_z"), ("freeacc_e", "freeacc_n", "freeacc_u")),
    "gyr": (("gyr_x", "gyr_y", "gyr_z"),),
    "quat": (("quat_w", "quat_x", "quat_y", "quat_z"),),
}


def _find(cols: dict[str, int], options: tuple[tuple[str, ...], ...]) -> list[int] | None:
    for names in options:
        if all(n in cols for n in names):
            return [cols[n] for n in names]
    return None


def _is_header(fields: list[str]) -> bool:
    names = {_norm(f) for f in fields}
    return bool(names & ({"packetcounter", "sampletimefine"} | set(_TIME_COLUMNS)))


def read_imu_csv(path: str | os.PathLike[str], options: ImuCsvOptions | None = None,
                 limits: InputLimits | None = None) -> ImuCsv:  # fmt: skip
    """Reads a Movella DOT or generic IMU CSV (module docstring).

    Args:
        path: The ``.csv`` file.
        options: Units of a generic file (a Movella DOT file has its own); ``None``: defaults.
        limits: Input limits (file size, line count); default the active ones.

    Returns:
        The samples in SI units; rows with a missing value are dropped (listed in
        ``dropped_lines``).

    Raises:
        FileNotFoundError: ``path`` does not exist.
        DeviceFileError: Naming the file (and the line where there is one): no header, required
            columns missing, a row with a wrong field count, a non-numeric value, a time that
            does not increase, a quaternion that is not of unit length, fewer than 2 samples.
    """
    options = options or ImuCsvOptions()
    source = str(path)
    lines = read_text_lines(path, limits)
    meta: dict[str, str] = {}
    sep = ","
    header_at = None
    for n, raw in enumerate(lines):
        s = raw.strip()
        if not s or s.startswith("#"):
            continue
        if s.lower().startswith("sep="):
            sep = s[4:5] or ","
            continue
        fields = raw.split(sep)
        if len(fields) == 1 and "\t" in raw:
            sep, fields = "\t", raw.split("\t")
        if _is_header(fields):
            header_at = n
            break
        if any(c.isalpha() for c in s):  # a preamble line (Movella's "DeviceTag:,L_Wrist,,,")
            if fields[0].strip().endswith(":"):
                meta[fields[0].strip()[:-1]] = fields[1].strip() if len(fields) > 1 else ""
            continue
        raise DeviceFileError(
            f"{source}: line {n + 1}: expected a header line naming the columns (a time column "
            f"{sorted(_TIME_COLUMNS)} or Movella's PacketCounter/SampleTimeFine) before the data"
        )
    if header_at is None:
        raise DeviceFileError(f"{source}: no header line naming the columns (a time column "
                              f"{sorted(_TIME_COLUMNS)} or Movella's SampleTimeFine)")  # fmt: skip
    names = lines[header_at].split(sep)
    cols: dict[str, int] = {}
    for i, name in enumerate(names):
        key = _norm(name)
        if key:
            if key in cols:
                raise DeviceFileError(f"{source}: line {header_at + 1}: column {name.strip()!r} "
                                      "appears twice")  # fmt: skip
            cols[key] = i
    dot = "sampletimefine" in cols or "packetcounter" in cols
    rows, line_no = [], []
    for n in range(header_at + 1, len(lines)):
        raw = lines[n]
        if not raw.strip():
            continue
        fields = raw.split(sep)
        if len(fields) != len(names):
            raise DeviceFileError(
                f"{source}: line {n + 1}: {len(fields)} fields, the header has {len(names)} "
                "columns (wrong column count)"
            )
        rows.append(fields)
        line_no.append(n + 1)
    parsed = (_dot_columns if dot else _generic_columns)(cols, options, source, header_at + 1)
    lines_arr = np.asarray(line_no, dtype=np.int64)

    def column(i: int) -> np.ndarray:
        label = names[i].strip()
        return parse_column([r[i] for r in rows], lines_arr,
                            lambda ln: f"{source}: line {ln}: column {label!r}")  # fmt: skip

    time_col, time_scale = parsed["time"]
    t = column(time_col)
    if dot:
        t = _unwrap_us(t) * 1e-6
    else:
        t = t * time_scale
    acc = np.stack([column(i) for i in parsed["acc"]], axis=1) * parsed["acc_scale"]
    gyr = quat = None
    if "gyr" in parsed:
        gyr = np.stack([column(i) for i in parsed["gyr"]], axis=1) * parsed["gyr_scale"]
    if "quat" in parsed:
        quat = np.stack([column(i) for i in parsed["quat"]], axis=1)
    present = np.isfinite(t) & np.isfinite(acc).all(axis=1)
    for extra in (gyr, quat):
        if extra is not None:
            present &= np.isfinite(extra).all(axis=1)
    dropped = tuple(int(x) for x in lines_arr[~present])
    keep = np.flatnonzero(present)
    t, acc, lines_arr = t[keep], acc[keep], lines_arr[keep]
    gyr = None if gyr is None else gyr[keep]
    if quat is not None:
        quat = _unit_quats(quat[keep], lines_arr, source)
    if len(t) < 2:
        raise DeviceFileError(f"{source}: fewer than 2 complete samples")
    require_increasing(t, lines_arr, source)
    return ImuCsv(time_s=t, acc_mps2=acc, acc_kind=parsed["acc_kind"], gyr_rad_s=gyr,
                  quat_wxyz=quat, fmt="movella_dot" if dot else "generic", meta=meta,
                  source=source, dropped_lines=dropped,
                  quat_order=parsed.get("quat_order"))  # fmt: skip


def _missing(source: str, line: int, what: str, cols: dict[str, int]) -> DeviceFileError:
    return DeviceFileError(f"{source}: line {line}: no {what} columns (the header has "
                           f"{sorted(cols)})")  # fmt: skip


def _dot_columns(cols: dict[str, int], o: ImuCsvOptions, source: str, line: int) -> dict:
    """Movella's columns; its units are the format's (the options are for generic files)."""
    if "sampletimefine" not in cols:
        raise _missing(source, line, "SampleTimeFine (the sensor's clock, us)", cols)
    out: dict = {"time": (cols["sampletimefine"], 1e-6)}
    acc = _find(cols, _DOT["acc"])
    if acc is not None:
        out.update(acc=acc, acc_kind="specific_force", acc_scale=1.0)
    else:
        free = _find(cols, _DOT["free"])
        if free is None:
            raise _missing(source, line, "acceleration (Acc_X/Y/Z or FreeAcc_X/Y/Z)", cols)
        out.update(acc=free, acc_kind="free_earth", acc_scale=1.0)
    gyr = _find(cols, _DOT["gyr"])
    if gyr is not None:
        out.update(gyr=gyr, gyr_scale=math.pi / 180.0)
    quat = _find(cols, _DOT["quat"])
    if quat is not None:
        out["quat"] = quat
    if gyr is None and quat is None:
        raise _missing(source, line, "orientation (Quat_W/X/Y/Z) or angular rate (Gyr_X/Y/Z)",
                       cols)  # fmt: skip
    if quat is None and out["acc_kind"] != "specific_force":
        raise DeviceFileError(f"{source}: without Quat_* columns the orientation is estimated "
                              "from Acc_X/Y/Z (with gravity), which this file lacks")  # fmt: skip
    return out


def _generic_columns(cols: dict[str, int], o: ImuCsvOptions, source: str, line: int) -> dict:
    time = next(((cols[k], s) for k, s in _TIME_COLUMNS.items() if k in cols), None)
    if time is None:
        raise _missing(source, line, f"time ({' or '.join(_TIME_COLUMNS)})", cols)
    acc = _find(cols, _GENERIC["acc"])
    if acc is None:
        raise _missing(source, line, "acceleration (ax, ay, az)", cols)
    gravity = True if o.acc_has_gravity is None else o.acc_has_gravity
    out: dict = {"time": time, "acc": acc, "acc_kind": "specific_force" if gravity else
                 "free_sensor", "acc_scale": GRAVITY if o.acc_unit == "g" else 1.0}  # fmt: skip
    gyr = _find(cols, _GENERIC["gyr"])
    if gyr is not None:
        out.update(gyr=gyr, gyr_scale=math.pi / 180.0 if o.gyro_unit == "deg" else 1.0)
    quat = _find(cols, _GENERIC["quat"])
    if quat is None:
        pos = _find(cols, _GENERIC["quat_pos"])
        if pos is not None:
            quat = pos if o.quat_order in (None, "wxyz") else [pos[3], pos[0], pos[1], pos[2]]
            out["quat_order"] = o.quat_order or "wxyz"
    if quat is not None:
        out["quat"] = quat
    if gyr is None and quat is None:
        raise _missing(source, line, "orientation (qw, qx, qy, qz) or angular rate (gx, gy, gz)",
                       cols)  # fmt: skip
    if quat is None and not gravity:
        raise DeviceFileError(f"{source}: without quaternion columns the orientation is "
                              "estimated from accelerations with gravity; the file's have none "
                              "(--no-acc-has-gravity)")  # fmt: skip
    return out


def _unwrap_us(t_us: np.ndarray) -> np.ndarray:
    """Movella's SampleTimeFine (us, wrapping at 2^32) as a continuous clock, us."""
    t = np.asarray(t_us, dtype=np.float64)
    ok = np.isfinite(t)
    steps = np.diff(t[ok])
    wraps = np.zeros_like(t)
    if steps.size:
        jump = np.concatenate([[0.0], np.where(steps < -_DOT_WRAP_US / 2, _DOT_WRAP_US, 0.0)])
        wraps[ok] = np.cumsum(jump)
    return t + wraps


def _unit_quats(q: np.ndarray, lines: np.ndarray, source: str) -> np.ndarray:
    norm = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(np.abs(norm - 1.0) > 0.05)
    if bad.size:
        i = int(bad[0])
        raise DeviceFileError(
            f"{source}: line {int(lines[i])}: quaternion of length {norm[i]:.3g}, not a unit "
            "quaternion (wrong columns, or not an orientation?)"
        )
    q = q / norm[:, None]
    return q * np.where(q[:, :1] < 0.0, -1.0, 1.0)  # w >= 0: one sign per orientation


# ------------------------------------------------------------------------------------- writing
def write_imu_csv(path: str | os.PathLike[str], data: ImuCsv, fmt: str = "generic",
                  options: ImuCsvOptions | None = None) -> None:  # fmt: skip
    """Writes IMU samples as a Movella DOT or generic CSV (the reverse of
    :func:`read_imu_csv`).

    Movella DOT: the app's preamble, ``PacketCounter, SampleTimeFine`` (us, from ``time_s``),
    then ``Quat_*`` (when given), ``Acc_*`` (``specific_force``) or ``FreeAcc_*``
    (``free_earth``), ``Gyr_*`` (deg/s, when given). Generic: ``time`` (s), ``ax ay az``,
    ``gx gy gz`` and the quaternion as named columns in ``options.quat_order``, in the options'
    units. 9 significant digits.

    Args:
        path: Destination (written atomically).
        data: The samples (``meta`` adds Movella preamble fields).
        fmt: ``"movella_dot"`` or ``"generic"``.
        options: Units of a generic file (``acc_has_gravity`` must match ``data.acc_kind``).

    Raises:
        ValueError: An acceleration kind the format cannot hold.
    """
    from grip.core.atomic import atomic_write_text

    if fmt not in FORMATS:
        raise ValueError(f"fmt must be one of {FORMATS}, got {fmt!r}")
    o = options or ImuCsvOptions()
    n = len(data.time_s)
    cols: list[tuple[str, np.ndarray]] = []
    pre: list[str] = []
    if fmt == "movella_dot":
        if data.acc_kind == "free_sensor":
            raise ValueError("a Movella DOT file holds Acc (with gravity) or FreeAcc (earth frame)")
        t_us = np.round(np.asarray(data.time_s) * 1e6).astype(np.int64) % _DOT_WRAP_US
        cols += [("PacketCounter", np.arange(1, n + 1)), ("SampleTimeFine", t_us)]
        if data.quat_wxyz is not None:
            cols += [(f"Quat_{c}", data.quat_wxyz[:, i]) for i, c in enumerate("WXYZ")]
        kind = "Acc" if data.acc_kind == "specific_force" else "FreeAcc"
        cols += [(f"{kind}_{c}", data.acc_mps2[:, i]) for i, c in enumerate("XYZ")]
        if data.gyr_rad_s is not None:
            cols += [(f"Gyr_{c}", np.degrees(data.gyr_rad_s[:, i])) for i, c in enumerate("XYZ")]
        rate = 1.0 / float(np.median(np.diff(data.time_s))) if n > 1 else 60.0
        preamble = {"DeviceTag": "DOT", "FirmwareVersion": "2.6.0", "AppVersion": "2023.6.0",
                    "SyncStatus": "Synced", "OutputRate": f"{rate:.0f}Hz",
                    "FilterProfile": "General", "Measurement Mode": "Custom Mode 5",
                    "StartTime": "2024-01-01 00:00:00.000 +0000", **data.meta}  # fmt: skip
        pad = "," * (len(cols) - 2)
        pre = ["sep=,"] + [f"{k}:,{v}{pad}" for k, v in preamble.items()] + [""]
    else:
        gravity = data.acc_kind == "specific_force"
        if data.acc_kind == "free_earth" or (o.acc_has_gravity is not None
                                              and o.acc_has_gravity != gravity):  # fmt: skip
            raise ValueError(f"a generic CSV with acc_has_gravity={o.acc_has_gravity} cannot "
                             f"hold {data.acc_kind} accelerations")  # fmt: skip
        acc = data.acc_mps2 / (GRAVITY if o.acc_unit == "g" else 1.0)
        cols += [("time", np.asarray(data.time_s))]
        cols += [(f"a{c}", acc[:, i]) for i, c in enumerate("xyz")]
        if data.gyr_rad_s is not None:
            gyr = np.degrees(data.gyr_rad_s) if o.gyro_unit == "deg" else data.gyr_rad_s
            cols += [(f"g{c}", gyr[:, i]) for i, c in enumerate("xyz")]
        if data.quat_wxyz is not None:
            order = "xyzw" if o.quat_order == "xyzw" else "wxyz"
            cols += [(f"q{c}", data.quat_wxyz[:, "wxyz".index(c)]) for c in order]
    body = [",".join(name for name, _ in cols)]
    spec = {"PacketCounter": "d", "SampleTimeFine": "d", "time": ".6f"}
    text_cols = [[format(int(v) if spec.get(name) == "d" else float(v) + 0.0, spec.get(name, ".9g"))
                  for v in vals] for name, vals in cols]  # fmt: skip
    body += [",".join(c[i] for c in text_cols) for i in range(n)]
    atomic_write_text(path, "\n".join(pre + body) + "\n")
