"""Aggregation over evaluation segments: success rate and the segment mean of metric dicts."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from grip.core.metrics._checks import _as_float


# ------------------------------------------------------------------------------ success
def success_rate(fell: Sequence[bool] | np.ndarray) -> float:
    """Success rate, %: segments in which the fall detector never fired / all segments.

    Args:
        fell: One flag per segment, True if the fall detector (section 5.4) fired at least once.

    Returns:
        ``100 * (1 - mean(fell))``; the fall rate is ``100 - success_rate``.
    """
    fell = np.asarray(fell, dtype=bool).reshape(-1)
    if fell.size == 0:
        raise ValueError("success_rate needs at least one segment")
    return float(100.0 * (1.0 - fell.mean()))


# ------------------------------------------------------------------------------ summary
def summarize(
    per_segment: Sequence[Mapping[str, float | np.ndarray]],
) -> dict[str, float | np.ndarray]:
    """Average metric dicts over evaluation segments.

    Each key's value is the mean over the segments that report a finite value for it (NaN
    entries, e.g. foot sliding of a segment without contact, are skipped; the result is NaN if
    no segment has one). Array values (e.g. :attr:`TranslationErrorCurve.error_m`) are averaged
    element-wise. For metrics that average every frame and joint of a segment, equal segment
    lengths make this equal to the global per-frame mean (section 4.1); metrics averaged over a
    data-dependent subset of frames (foot sliding, ZMP distance) are segment-weighted, as PIP
    averages per sequence. A per-segment ``success_rate([fell])`` (0 or 100) averages to the
    success rate.

    Args:
        per_segment: One ``{metric name: value}`` mapping per segment.

    Returns:
        ``{metric name: mean}`` in first-appearance key order (floats, or arrays for array
        values).
    """
    keys: list[str] = []
    for seg in per_segment:
        keys.extend(k for k in seg if k not in keys)
    out: dict[str, float | np.ndarray] = {}
    for k in keys:
        vals = np.stack([_as_float(seg[k]) for seg in per_segment if k in seg])
        finite = np.isfinite(vals)
        count = finite.sum(axis=0)
        total = np.where(finite, vals, 0.0).sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(count > 0, total / np.maximum(count, 1), np.nan)
        out[k] = float(mean) if mean.ndim == 0 else mean
    return out
