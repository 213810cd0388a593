"""Pace: how far a simulated body falls behind the pelvis it follows (issue 46).

A physics tracker (GRIP's humanoid) follows a kinematic estimate whose pelvis is integrated from
estimated velocities. If it walks slower than that estimate it ends metres behind it, which no
pose metric shows once the pelvis is aligned (PEL-MPJPE, PA-MPJPE). These functions measure the
horizontal (xy) distance between two pelvis tracks: the body's and the one it follows (the
"pace" gap), or the body's and the ground truth's.

Conventions: ``(T, 3)`` pelvis (root) positions, world frame, z up, metres; ``fps`` in Hz. Only
x and y count: height differences (crouching, a lower pelvis) are not lost ground.

Times: the value "at ``s`` seconds" is the distance at the last frame of the segment's first
``s`` seconds, frame index ``round(s * fps) - 1`` (at 100 Hz: frame 99 for 1 s, frame 499 for
5 s, so a 500-frame segment has a 5 s value), and NaN when the track has fewer frames than
that. "At the end" is the last frame.

Drift rate: the least-squares slope of the distance over time (frame ``k`` at ``k / fps`` s),
m/s. A body that keeps a constant distance (a fixed offset, or sway around the reference) has a
rate of 0 whatever the offset; one that covers ground at a speed ``v`` slower than its reference
has a rate of ``v``. Chosen over "distance at the end / duration" because that ratio counts the
start offset and the sway of the pelvis as drift.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grip.core.metrics._checks import _as_float

__all__ = [
    "PACE_KEYS",
    "PACE_TIMES_S",
    "ROOT_GT_KEYS",
    "Gap",
    "Pace",
    "distance_at",
    "drift_rate",
    "horizontal_distance",
    "horizontal_gap",
    "measure_pace",
]

PACE_TIMES_S: tuple[float, float] = (1.0, 5.0)
"""The times (s from the first frame) at which :class:`Gap` reports the distance."""
PACE_KEYS: tuple[str, ...] = ("pace_1s_m", "pace_5s_m", "pace_end_m", "drift_mps")
""":meth:`Pace.metrics` keys of the body-to-reference gap (m, m, m, m/s)."""
ROOT_GT_KEYS: tuple[str, ...] = ("root_gt_1s_m", "root_gt_5s_m", "root_gt_end_m")
""":meth:`Pace.metrics` / :meth:`Gap.root_gt_metrics` keys of the body-to-truth distance, m."""


def _check_track(x: np.ndarray, what: str) -> np.ndarray:
    a = _as_float(x)
    if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] < 1:
        raise ValueError(f"{what}: expected a (T >= 1, 3) pelvis track, got {a.shape}")
    return a


def horizontal_distance(a_root_world: np.ndarray, b_root_world: np.ndarray) -> np.ndarray:
    """Per-frame horizontal distance between two pelvis tracks.

    Args:
        a_root_world: ``(T, 3)`` pelvis positions, world (z up), m.
        b_root_world: ``(T, 3)`` pelvis positions, world (z up), m.

    Returns:
        ``(T,)`` the xy distance at every frame, m.

    Raises:
        ValueError: The tracks are not two ``(T, 3)`` arrays of the same length.
    """
    a = _check_track(a_root_world, "first track")
    b = _check_track(b_root_world, "second track")
    if a.shape != b.shape:
        raise ValueError(f"pelvis tracks of {a.shape[0]} and {b.shape[0]} frames differ")
    return np.linalg.norm(a[:, :2] - b[:, :2], axis=1)


def distance_at(distance_m: np.ndarray, fps: float, seconds: float | None) -> float:
    """A per-frame distance at a time (see the module docstring for which frame).

    Args:
        distance_m: ``(T,)`` distance per frame, m.
        fps: Frame rate, Hz.
        seconds: Time from the first frame, s; ``None``: the last frame.

    Returns:
        The distance at that frame, m; NaN when the series is shorter than ``seconds``.
    """
    d = np.asarray(distance_m, dtype=np.float64).reshape(-1)
    if d.size == 0:
        return float("nan")
    if seconds is None:
        return float(d[-1])
    k = max(round(seconds * fps), 1) - 1
    return float(d[k]) if k < d.size else float("nan")


def drift_rate(distance_m: np.ndarray, fps: float) -> float:
    """Least-squares slope of a per-frame distance over time, m/s (NaN under 2 frames).

    Args:
        distance_m: ``(T,)`` distance per frame, m (frame ``k`` at ``k / fps`` s).
        fps: Frame rate, Hz.
    """
    d = np.asarray(distance_m, dtype=np.float64).reshape(-1)
    if d.size < 2:
        return float("nan")
    t = np.arange(d.size) / float(fps)
    tc = t - t.mean()
    return float(tc @ (d - d.mean()) / (tc @ tc))


@dataclass(frozen=True)
class Gap:
    """The horizontal distance between two pelvis tracks over a segment.

    Attributes:
        distance_m: ``(T,)`` xy distance per frame, m.
        at_1s_m: The distance after the first second (frame ``fps - 1``), m; NaN if shorter.
        at_5s_m: The distance after the first 5 s (frame ``5 fps - 1``), m; NaN if shorter.
        at_end_m: The distance at the last frame, m.
        drift_mps: :func:`drift_rate` of ``distance_m``, m/s (NaN for one frame).
    """

    distance_m: np.ndarray
    at_1s_m: float
    at_5s_m: float
    at_end_m: float
    drift_mps: float

    def root_gt_metrics(self) -> dict[str, float]:
        """``{root_gt_1s_m, root_gt_5s_m, root_gt_end_m}``: this gap read as a body's distance
        to the ground truth, m."""
        return dict(zip(ROOT_GT_KEYS, (self.at_1s_m, self.at_5s_m, self.at_end_m), strict=True))


def horizontal_gap(a_root_world: np.ndarray, b_root_world: np.ndarray, fps: float) -> Gap:
    """The :class:`Gap` between two ``(T, 3)`` world pelvis tracks (m) at ``fps`` Hz.

    Raises:
        ValueError: Tracks of other shapes, or ``fps`` not positive.
    """
    if not fps > 0:
        raise ValueError(f"fps must be positive, got {fps}")
    d = horizontal_distance(a_root_world, b_root_world)
    one, five = PACE_TIMES_S
    return Gap(d, distance_at(d, fps, one), distance_at(d, fps, five), distance_at(d, fps, None),
               drift_rate(d, fps))  # fmt: skip


@dataclass(frozen=True)
class Pace:
    """How a simulated body kept pace with its reference (:func:`measure_pace`).

    Attributes:
        to_ref: The body's pelvis against the reference pelvis it followed.
        to_gt: The body's pelvis against the ground truth's, or ``None`` without a truth.
    """

    to_ref: Gap
    to_gt: Gap | None = None

    def metrics(self) -> dict[str, float]:
        """:data:`PACE_KEYS` (``pace_1s_m``, ``pace_5s_m``, ``pace_end_m`` in m, ``drift_mps``
        in m/s) and :data:`ROOT_GT_KEYS` (m; NaN without a ground truth)."""
        r = self.to_ref
        out = dict(zip(PACE_KEYS, (r.at_1s_m, r.at_5s_m, r.at_end_m, r.drift_mps), strict=True))
        if self.to_gt is None:
            return out | dict.fromkeys(ROOT_GT_KEYS, float("nan"))
        return out | self.to_gt.root_gt_metrics()


def measure_pace(
    sim_root_world: np.ndarray,
    ref_root_world: np.ndarray,
    fps: float,
    gt_root_world: np.ndarray | None = None,
) -> Pace:
    """How far a simulated body's pelvis is from the pelvis it follows, and from the truth.

    Args:
        sim_root_world: ``(T, 3)`` the simulated body's pelvis, world, m.
        ref_root_world: ``(T, 3)`` the pelvis it follows (GRIP: the kinematic estimate's,
            integrated from its estimated velocity), world, m.
        fps: Frame rate, Hz.
        gt_root_world: ``(T, 3)`` the ground truth's pelvis, world, m, or ``None``.

    Returns:
        The :class:`Pace` (per-frame distances, the distances at 1 s, 5 s and the end, the
        drift rate).

    Raises:
        ValueError: Tracks of other shapes or lengths, or ``fps`` not positive.
    """
    to_gt = None if gt_root_world is None else horizontal_gap(sim_root_world, gt_root_world, fps)
    return Pace(horizontal_gap(sim_root_world, ref_root_world, fps), to_gt)
