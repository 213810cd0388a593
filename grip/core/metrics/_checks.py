"""Argument checks and reductions shared by the metric modules."""

from __future__ import annotations

import numpy as np

_MM = 1000.0


def _as_float(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=np.float64)


def _check_pair(pred: np.ndarray, gt: np.ndarray, tail: tuple[int, ...], what: str) -> None:
    if pred.shape != gt.shape:
        raise ValueError(f"{what}: prediction {pred.shape} and ground truth {gt.shape} differ")
    if pred.ndim < len(tail) + 1 or pred.shape[-len(tail) :] != tail:
        raise ValueError(f"{what}: expected shape (..., J, {', '.join(map(str, tail))}), "
                         f"got {pred.shape}")  # fmt: skip


def _reduce(err: np.ndarray, per_joint: bool) -> float | np.ndarray:
    """Mean of ``(..., J)`` values over everything, or over everything but ``J``."""
    if per_joint:
        return err.reshape(-1, err.shape[-1]).mean(axis=0)
    return float(err.mean())


def _require_frames(x: np.ndarray, n: int, what: str) -> None:
    if x.shape[0] < n:
        raise ValueError(f"{what} needs at least {n} frames, got {x.shape[0]}")
