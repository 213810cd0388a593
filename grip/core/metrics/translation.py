"""Root translation metrics: horizontal error, travel ratio and cumulative error curves."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from grip.core.metrics._checks import _as_float


# ------------------------------------------------------------------------- translation
@dataclass(frozen=True)
class TranslationErrorCurve:
    """A cumulative translation error curve.

    Attributes:
        x: ``(K,)`` abscissa: horizon in s (TransPose variant) or GT path window in m (PIP).
        error_m: ``(K,)`` mean root translation error at each abscissa, m; NaN where the segment
            is too short (no start frame or no window pair).
        mean_m: Mean of the finite values of ``error_m`` at ``x > 0``, m (NaN if none).
    """

    x: np.ndarray
    error_m: np.ndarray
    mean_m: float


def _curve(x: np.ndarray, err: np.ndarray) -> TranslationErrorCurve:
    use = (x > 0) & np.isfinite(err)
    mean = float(err[use].mean()) if use.any() else float("nan")
    return TranslationErrorCurve(x, err, mean)


def _check_roots(pred_root: np.ndarray, gt_root: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    p, g = _as_float(pred_root), _as_float(gt_root)
    if p.shape != g.shape or p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"expected two (T, 3) root tracks, got {p.shape} and {g.shape}")
    return p, g


def root_error_xy(pred_root: np.ndarray, gt_root: np.ndarray) -> float:
    """Mean horizontal distance between two ``(T, 3)`` root (pelvis) tracks, m (z up)."""
    p, g = _check_roots(pred_root, gt_root)
    return float(np.linalg.norm(p[:, :2] - g[:, :2], axis=1).mean())


def travel_ratio(pred_root: np.ndarray, gt_root: np.ndarray, fps: float,
                 every_s: float = 1.0) -> float:  # fmt: skip
    """Ground covered by a root track over the ground truth's (1 = the same distance), -.

    The horizontal path length of each ``(T, 3)`` track sampled every ``every_s`` seconds (so
    that the sway of the pelvis within a stride does not count as ground covered), predicted
    over true. NaN when the true track covers no ground (< 1 mm) or is shorter than
    ``every_s``.
    """
    p, g = _check_roots(pred_root, gt_root)
    step = max(round(every_s * fps), 1)
    if p.shape[0] <= step:
        return float("nan")

    def path(x: np.ndarray) -> float:
        return float(np.linalg.norm(np.diff(x[::step, :2], axis=0), axis=1).sum())

    ref = path(g)
    return path(p) / ref if ref > 1e-3 else float("nan")


def translation_error_by_time(
    pred_root: np.ndarray,
    gt_root: np.ndarray,
    fps: float,
    max_horizon_s: float = 10.0,
    step_s: float = 1.0,
) -> TranslationErrorCurve:
    """TransPose cumulative translation error against time.

    For every start frame ``s`` both root tracks are aligned at ``s`` and the distance error
    after a horizon of ``k`` frames is ``|(p_hat_{s+k} - p_hat_s) - (p_{s+k} - p_s)|``; it is
    averaged over all start frames with ``s + k < T``. Horizons ``0, step_s, ..., max_horizon_s``.

    Args:
        pred_root: ``(T, 3)`` predicted root positions, world, m.
        gt_root: ``(T, 3)`` ground-truth root positions, world, m.
        fps: Frame rate, Hz.
        max_horizon_s: Largest horizon, s.
        step_s: Horizon spacing, s.

    Returns:
        The curve over horizons in s (NaN for horizons of ``T`` frames or more); ``mean_m``
        averages the horizons ``> 0``.
    """
    p, g = _check_roots(pred_root, gt_root)
    d = p - g  # error relative to GT; aligning both at s subtracts d_s
    horizons = np.arange(0.0, max_horizon_s + 1e-9 * step_s, step_s)
    err = np.full(horizons.shape, np.nan)
    for i, h in enumerate(horizons):
        k = round(h * fps)
        if k < d.shape[0]:
            err[i] = np.linalg.norm(d[k:] - d[: d.shape[0] - k], axis=-1).mean()
    return _curve(horizons, err)


def translation_error_by_distance(
    pred_root: np.ndarray,
    gt_root: np.ndarray,
    windows_m: Sequence[float] = (1, 2, 3, 4, 5, 6, 7),
) -> TranslationErrorCurve:
    """PIP cumulative translation error against travelled distance [C-PIP].

    ``D_t`` is the ground-truth path length (sum of 3D root steps) up to frame ``t``. For a
    window ``w``, each start frame ``s`` pairs with the first end frame ``e`` where
    ``D_e - D_s >= w``; when several starts share an end only the earliest start is kept, and
    starts without such an end are dropped (as PIP's two-pointer scan does). Each pair scores
    ``|(p_hat_e - p_hat_s) - (p_e - p_s)| * w / (D_e - D_s)`` (the error normalised to exactly
    ``w`` m of travel); the window's value is the mean over its pairs.

    Args:
        pred_root: ``(T, 3)`` predicted root positions, world, m.
        gt_root: ``(T, 3)`` ground-truth root positions, world, m.
        windows_m: Path-length windows, m.

    Returns:
        The curve over windows in m (NaN where the GT path is shorter than the window).
    """
    p, g = _check_roots(pred_root, gt_root)
    dist = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(g, axis=0), axis=-1))])
    d = p - g
    windows = np.asarray(windows_m, dtype=np.float64)
    if np.any(windows <= 0.0):
        raise ValueError(f"path windows must be positive, got {windows_m}")
    err = np.full(windows.shape, np.nan)
    n = dist.shape[0]
    for i, w in enumerate(windows):
        end = np.searchsorted(dist, dist + w, side="left")
        valid = np.flatnonzero(end < n)
        if valid.size == 0:
            continue
        # searchsorted keeps the order, so the first occurrence of each end is its earliest start
        _, first = np.unique(end[valid], return_index=True)
        s = valid[first]
        e = end[s]
        e_err = np.linalg.norm(d[e] - d[s], axis=-1) * w / (dist[e] - dist[s])
        err[i] = e_err.mean()
    return _curve(windows, err)


def cumulative_translation_error(
    pred_root: np.ndarray,
    gt_root: np.ndarray,
    fps: float,
    variant: str = "transpose",
    **kwargs: float | Sequence[float],
) -> TranslationErrorCurve:
    """Cumulative root translation error, m, in one of the two published variants.

    Args:
        pred_root: ``(T, 3)`` predicted root positions, world, m.
        gt_root: ``(T, 3)`` ground-truth root positions, world, m.
        fps: Frame rate, Hz (used by the TransPose variant).
        variant: ``"transpose"`` (error after 0..10 s, :func:`translation_error_by_time`) or
            ``"pip"`` (error per 1..7 m of GT path, :func:`translation_error_by_distance`).
        **kwargs: Passed to the chosen function (``max_horizon_s``, ``step_s`` or ``windows_m``).

    Returns:
        The :class:`TranslationErrorCurve`.
    """
    if variant == "transpose":
        return translation_error_by_time(pred_root, gt_root, fps, **kwargs)
    if variant == "pip":
        return translation_error_by_distance(pred_root, gt_root, **kwargs)
    raise ValueError(f"unknown variant {variant!r}; use 'transpose' or 'pip'")
