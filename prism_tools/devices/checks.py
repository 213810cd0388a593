"""What gravity and stillness say about an IMU export, checked before it is imported.

A device export carries no statement of its own units beyond its column names, and a generic
CSV's units and quaternion order are what the user claims (:class:`~prism_tools.devices.imu_csv.
ImuCsvOptions`). A wrong claim used to be imported without a word, with 12-47 degrees of
orientation error. Gravity gives the claims away:

* accelerations with gravity (specific force) read about 1 g while the sensor turns slowly;
  values near 1 m/s^2 are in g, near 96 g in m/s^2, near 0 without gravity
  (:func:`check_acceleration`); accelerations without gravity that read 1 g hold it;
* the angular rate of the gyroscope matches the rate of the sensor's own orientation track;
  57 times it is deg/s read as rad/s (:func:`check_gyroscope`);
* a sensor at rest measures gravity along its reference frame's vertical whatever its
  attitude: rotated to the reference frame by the exported orientation, the specific force of
  every quiet sample points up (z, in every format's reference frame); with the quaternion's
  components in another order it does not (:func:`check_orientation`).

Each check raises :class:`~prism_tools.devices.common.DeviceFileError` naming the file, the part,
what was measured and the option that probably fixes it. numpy and :mod:`grip.core` only.
"""

from __future__ import annotations

import math

import numpy as np

from grip.core.rotations import matrix_to_axis_angle, quat_to_matrix
from prism_tools.devices.common import DeviceFileError
from prism_tools.streams import GRAVITY

__all__ = [
    "QUIET_RATE_RAD_S",
    "TILT_MAX_DEG",
    "check_acceleration",
    "check_gyroscope",
    "check_imu_export",
    "check_orientation",
    "sample_rates",
    "unit_fixes",
]

QUIET_RATE_RAD_S = math.radians(20.0)
"""Angular rate below which a sample counts as quiet (as the importer's still test)."""
MIN_QUIET = 10
"""Fewest quiet samples a check of gravity needs (else it is skipped)."""
GRAVITY_SPREAD_DEG = 15.0
"""Largest median angle of a quiet sample's gravity direction (reference frame) from their
mean: a sensor's attitude error is a few degrees; a wrong component order gives tens."""
TILT_MAX_DEG = 20.0
"""Largest tilt of the mean gravity direction from the reference frame's vertical (every
format's reference frame is z up; a sensor's attitude error is a few degrees)."""
XYZW_TO_WXYZ = np.array([3, 0, 1, 2])
"""Columns of an ``xyzw`` quaternion in ``wxyz`` order (its own inverse is ``[1, 2, 3, 0]``)."""


def sample_rates(time_s: np.ndarray, quat_wxyz: np.ndarray) -> np.ndarray:
    """``(N,)`` angular rate of an orientation track, rad/s (the step to the next sample; the
    last sample repeats the one before)."""
    rot = quat_to_matrix(np.asarray(quat_wxyz, dtype=np.float64))
    rel = np.swapaxes(rot[:-1], -1, -2) @ rot[1:]
    dt = np.diff(np.asarray(time_s, dtype=np.float64))
    rate = np.linalg.norm(matrix_to_axis_angle(rel), axis=-1) / np.maximum(dt, 1e-9)
    return np.append(rate, rate[-1:]) if len(rate) else np.zeros(len(time_s))


_FIXED = "the format fixes its units: is it a {kind} export?"
_OPTION = {"g": ("acc_unit", "g"), "mps2": ("acc_unit", "mps2"),
           "gravity": ("acc_has_gravity", True), "no_gravity": ("acc_has_gravity", False),
           "deg": ("gyro_unit", "deg"), "rad": ("gyro_unit", "rad"),
           "wxyz": ("quat_order", "wxyz"), "xyzw": ("quat_order", "xyzw")}  # fmt: skip


def unit_fixes(fmt: str) -> dict[str, str]:
    """What sets each claim the checks test, for their messages: for a generic CSV the option
    (``"--acc-unit g, ImuCsvOptions(acc_unit='g')"``), for a format with fixed units
    (``"movella_dot"``, ``"moticon"``) a question about the file."""
    if fmt != "generic":
        kind = {"movella_dot": "Movella DOT", "moticon": "Moticon OpenGo"}.get(fmt, fmt)
        return dict.fromkeys(_OPTION, _FIXED.format(kind=kind))
    out = {}
    for key, (name, value) in _OPTION.items():
        flag = (f"--{name.replace('_', '-')} {value}" if not isinstance(value, bool)
                else f"--{'' if value else 'no-'}{name.replace('_', '-')}")  # fmt: skip
        out[key] = f"{flag}; ImuCsvOptions({name}={value!r})"
    return out


def _where(file: str, part: str) -> str:
    return f"{file}: {part}" if file else part


def check_acceleration(acc: np.ndarray, kind: str, quiet: np.ndarray, file: str, part: str,
                       fix: dict[str, str]) -> None:  # fmt: skip
    """Refuse accelerations whose magnitude while the sensor turns slowly is not what their
    claimed unit and kind give (about 1 g with gravity, well below it without).

    Args:
        acc: ``(N, 3)`` accelerations as read, m/s^2 (the claimed unit applied).
        kind: ``"specific_force"``, ``"free_sensor"`` or ``"free_earth"``.
        quiet: ``(N,)`` bool, the samples turning slowly (all, when nothing tells).
        file, part: For the message.
        fix: The option that sets each claim, for the message: keys ``"g"`` (the values are in
            g), ``"mps2"`` (in m/s^2), ``"gravity"`` (they hold gravity), ``"no_gravity"``.

    Raises:
        DeviceFileError: Naming what was measured and the option that probably fixes it.
    """
    mag = np.linalg.norm(np.asarray(acc, dtype=np.float64), axis=1)
    mag = mag[quiet] if quiet.sum() >= MIN_QUIET else mag
    if mag.size < MIN_QUIET:
        return
    med = float(np.median(mag))
    said = (f"{_where(file, part)}: the accelerations read {med:.3g} m/s^2 in magnitude while the "
            "sensor turns slowly")  # fmt: skip
    if kind == "specific_force":
        if 0.6 * GRAVITY <= med <= 1.6 * GRAVITY:
            return
        if 0.6 <= med <= 1.6:
            guess = f"the values are in g, not m/s^2 ({fix['g']})"
        elif 0.6 * GRAVITY**2 <= med <= 1.6 * GRAVITY**2:
            guess = f"the values are in m/s^2, not g ({fix['mps2']})"
        elif med < 0.3 * GRAVITY:
            guess = f"gravity is removed from them ({fix['no_gravity']})"
        else:
            guess = "the unit is neither g nor m/s^2 (milli-g? mm/s^2?)"
        raise DeviceFileError(f"{said}, where gravity alone gives {GRAVITY:.2f} m/s^2 (1 g): "
                              f"{guess}")  # fmt: skip
    if 0.8 * GRAVITY <= med <= 1.2 * GRAVITY:
        raise DeviceFileError(f"{said}, about 1 g, but they are read as acceleration without "
                              f"gravity: they hold gravity ({fix['gravity']})")  # fmt: skip


def check_gyroscope(gyr: np.ndarray, rates: np.ndarray, file: str, part: str,
                    fix: dict[str, str]) -> None:  # fmt: skip
    """Refuse angular rates that differ from the rate of the sensor's own orientation track
    (samples turning faster than 30 deg/s; skipped with fewer than 20 of them).

    Args:
        gyr: ``(N, 3)`` angular rates as read, rad/s.
        rates: ``(N,)`` rate of the orientation track, rad/s (:func:`sample_rates`).
        file, part: For the message.
        fix: The option setting the unit: keys ``"deg"`` (the values are deg/s), ``"rad"``.

    Raises:
        DeviceFileError: The median ratio is not within 0.5-2.
    """
    moving = rates > math.radians(30.0)
    if moving.sum() < 20:
        return
    ratio = float(np.median(np.linalg.norm(gyr[moving], axis=1) / rates[moving]))
    if 0.5 <= ratio <= 2.0:
        return
    if 25.0 <= ratio <= 130.0:
        guess = f"the gyroscope reads deg/s, not rad/s ({fix['deg']})"
    elif 1 / 130.0 <= ratio <= 1 / 25.0:
        guess = f"the gyroscope reads rad/s, not deg/s ({fix['rad']})"
    else:
        guess = "the gyroscope and the orientation are not the same sensor's"
    raise DeviceFileError(f"{_where(file, part)}: the gyroscope turns {ratio:.3g} times as fast "
                          f"as the exported orientation: {guess}")  # fmt: skip


def _gravity_spread(acc: np.ndarray, quat_wxyz: np.ndarray) -> tuple[float, float]:
    """Median angle of the quiet samples' gravity directions (reference frame) from their
    mean, and the mean's tilt from the reference vertical, deg."""
    up = np.einsum("nij,nj->ni", quat_to_matrix(quat_wxyz), acc)
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    mean = up.mean(axis=0)
    mean /= np.linalg.norm(mean)
    spread = np.degrees(np.arccos(np.clip(up @ mean, -1.0, 1.0)))
    return float(np.median(spread)), float(np.degrees(np.arccos(np.clip(mean[2], -1.0, 1.0))))


def check_orientation(acc: np.ndarray, quat_wxyz: np.ndarray, quiet: np.ndarray, file: str,
                      part: str, claimed: str | None, fix: dict[str, str]) -> None:  # fmt: skip
    """Refuse an orientation track that does not carry gravity to one direction of its
    reference frame over the samples where the sensor rests (turning slowly, its specific
    force within 0.1 g of 1 g).

    Args:
        acc: ``(N, 3)`` specific force in the sensor frame, m/s^2.
        quat_wxyz: ``(N, 4)`` sensor -> reference orientations as read.
        quiet: ``(N,)`` bool, the samples turning slowly.
        file, part: For the message.
        claimed: The order positional quaternion columns were read in (``"wxyz"``,
            ``"xyzw"``), ``None`` when the columns name their components: with an order, the
            other one is tried and named when it agrees.
        fix: Keys ``"wxyz"`` and ``"xyzw"``: the option naming each order.

    Raises:
        DeviceFileError: The directions spread more than :data:`GRAVITY_SPREAD_DEG`, or their
            mean tilts more than :data:`TILT_MAX_DEG` from the reference vertical.
    """
    acc = np.asarray(acc, dtype=np.float64)
    rest = quiet & (np.abs(np.linalg.norm(acc, axis=1) - GRAVITY) < 0.1 * GRAVITY)
    if rest.sum() < MIN_QUIET:
        return
    q = np.asarray(quat_wxyz, dtype=np.float64)[rest]
    spread, tilt = _gravity_spread(acc[rest], q)
    if spread <= GRAVITY_SPREAD_DEG and tilt <= TILT_MAX_DEG:
        return
    msg = (f"{_where(file, part)}: rotated by the exported orientation, gravity points "
           f"{spread:.0f} deg apart (median) and {tilt:.0f} deg from the reference frame's "
           "vertical over the samples where the sensor rests, where one direction, up, is "
           "expected")  # fmt: skip
    if claimed in ("wxyz", "xyzw"):
        other = "xyzw" if claimed == "wxyz" else "wxyz"
        # the columns read as `claimed` but written as `other`: their true wxyz order
        order = XYZW_TO_WXYZ if claimed == "wxyz" else np.array([1, 2, 3, 0])
        alt, alt_tilt = _gravity_spread(acc[rest], q[:, order])
        if alt <= GRAVITY_SPREAD_DEG / 3 and alt_tilt <= TILT_MAX_DEG / 4:
            raise DeviceFileError(f"{msg}; read in the order {other}, {alt:.1f} and "
                                  f"{alt_tilt:.1f} deg: the quaternion columns are {other}, not "
                                  f"{claimed} ({fix[other]})")  # fmt: skip
    raise DeviceFileError(f"{msg}: a wrong quaternion order or an orientation of another "
                          "sensor frame")  # fmt: skip


def check_imu_export(time_s: np.ndarray, acc: np.ndarray, kind: str, gyr: np.ndarray | None,
                     quat_wxyz: np.ndarray | None, file: str, part: str,
                     fix: dict[str, str], quat_order: str | None = None) -> None:  # fmt: skip
    """:func:`check_acceleration`, :func:`check_gyroscope` and :func:`check_orientation` of one
    IMU's samples, with the quiet samples taken from the orientation track (else the
    gyroscope).

    Args:
        time_s: ``(N,)`` sample times, s.
        acc: ``(N, 3)`` accelerations, m/s^2, of ``kind``.
        kind: One of :data:`prism_tools.devices.imu_csv.ACC_KINDS`.
        gyr: ``(N, 3)`` angular rates, rad/s, or ``None``.
        quat_wxyz: ``(N, 4)`` orientations, or ``None``.
        file, part: For the messages.
        fix: The options that set each claim (see the checks; an export whose format fixes
            its units says so instead).
        quat_order: The order positional quaternion columns were read in (see
            :func:`check_orientation`).

    Raises:
        DeviceFileError: The first check that fails.
    """
    n = len(time_s)
    rates = None if quat_wxyz is None or n < 2 else sample_rates(time_s, quat_wxyz)
    if rates is not None:
        quiet = rates < QUIET_RATE_RAD_S
    elif gyr is not None:
        quiet = np.linalg.norm(gyr, axis=1) < QUIET_RATE_RAD_S
    else:
        quiet = np.ones(n, dtype=bool)
    check_acceleration(acc, kind, quiet, file, part, fix)
    if gyr is not None and rates is not None:
        check_gyroscope(gyr, rates, file, part, fix)
    if quat_wxyz is not None and kind == "specific_force":
        check_orientation(acc, quat_wxyz, quiet, file, part, quat_order, fix)
