"""Synchronisation of device clocks by a jump (GRIP supplement Sec. 7.1, "Time
Synchronization"): the landing after a vertical jump is an acceleration peak that every stream
sees at the same instant, so aligning each stream's landing aligns the clocks.

GRIP cross-correlates each IMU's vertical acceleration with the motion capture's; without motion
capture this module finds the landing in each stream directly. A jump shows as a flight phase,
when every accelerometer on a body in free fall reads about 0 g (the insoles about 0 N), followed
by the landing impact, a peak of several g (several body weights). :func:`find_landings` returns
the time of each such peak, refined between samples by a parabola through the highest sample and
its neighbours. Streams sampled at different rates or phases are aligned to a fraction of a
sample; sites land within a few milliseconds of each other on a real body (feet first), which is
the method's floor. Keep the arms still during the jump: swinging arms keep the wrists' readings
away from 0 g in flight.

This module imports numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Landing", "SyncSettings", "find_landings"]


@dataclass(frozen=True)
class SyncSettings:
    """What counts as a jump.

    Attributes:
        flight_below: Flight: the signal below this (g for accelerations, body weights for
            insole force).
        min_flight_s: Shortest flight, s (a 10 cm jump flies 0.29 s).
        peak_above: The landing peak must reach this (same unit).
        peak_within_s: The peak is looked for this long after the flight ends, s.
        search_s: Only jumps landing within this many seconds of a stream's first sample count.
    """

    flight_below: float = 0.4
    min_flight_s: float = 0.08
    peak_above: float = 1.5
    peak_within_s: float = 0.3
    search_s: float = 60.0


@dataclass(frozen=True)
class Landing:
    """A jump's landing in one stream.

    Attributes:
        time_s: The landing peak, s, on the stream's own clock (refined between samples).
        peak: The peak value (g, or body weights).
        flight_s: Duration of the flight before it, s.
    """

    time_s: float
    peak: float
    flight_s: float


def find_landings(time_s: np.ndarray, signal: np.ndarray,
                  settings: SyncSettings = SyncSettings()) -> list[Landing]:  # fmt: skip
    """Every jump landing of a stream, in time order.

    Args:
        time_s: ``(N,)`` strictly increasing sample times, s.
        signal: ``(N,)`` specific-force magnitude in g (or insole force in body weights); NaN
            samples are ignored.
        settings: Thresholds.

    Returns:
        One :class:`Landing` per flight of at least ``min_flight_s`` below ``flight_below``
        followed within ``peak_within_s`` by a peak above ``peak_above``, whose peak lies within
        ``search_s`` of the first sample.
    """
    t = np.asarray(time_s, dtype=np.float64)
    x = np.asarray(signal, dtype=np.float64)
    ok = np.isfinite(x)
    t, x = t[ok], x[ok]
    if len(t) < 3:
        return []
    dt = float(np.median(np.diff(t)))
    low = x < settings.flight_below
    edges = np.diff(np.concatenate([[0], low.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)  # [start, stop)
    out: list[Landing] = []
    for a, b in zip(starts, stops, strict=True):
        flight = t[b - 1] - t[a] + dt
        if flight < settings.min_flight_s or b >= len(t):
            continue
        after = np.flatnonzero((t > t[b - 1]) & (t <= t[b - 1] + settings.peak_within_s))
        if after.size == 0:
            continue
        i = int(after[np.argmax(x[after])])
        if x[i] < settings.peak_above:
            continue
        t_peak = _refine(t, x, i)
        if t_peak - t[0] > settings.search_s:
            break
        out.append(Landing(t_peak, float(x[i]), float(flight)))
    return out


def _refine(t: np.ndarray, x: np.ndarray, i: int) -> float:
    """The vertex of the parabola through samples ``i - 1, i, i + 1`` (``t[i]`` at the ends or
    where the three do not bend down)."""
    if i == 0 or i == len(t) - 1:
        return float(t[i])
    t0, t1, t2 = t[i - 1] - t[i], 0.0, t[i + 1] - t[i]
    a = np.array([[t0 * t0, t0, 1.0], [t1 * t1, t1, 1.0], [t2 * t2, t2, 1.0]])
    c2, c1, _ = np.linalg.solve(a, x[i - 1 : i + 2])
    if c2 >= 0.0:
        return float(t[i])
    return float(t[i] + np.clip(-c1 / (2.0 * c2), t0, t2))
