"""``grip kin eval``: KinematicsNet alone on :mod:`grip.eval.segments`, its own metrics
(:func:`grip.kinematics.evaluate.segment_metrics`), frame-weighted per category and overall.

The segments are scored in this process (:func:`evaluate_segments`) or, with ``--workers K`` or
``--ray``, in a pool (:func:`evaluate_in_pool`): each unit of work is a run of consecutive
segments, scored by a worker that loads the checkpoint once."""

from __future__ import annotations

from collections.abc import Callable, Sequence

from grip.core.runs import CallPool
from grip.eval.report import category_summary, weighted_means
from grip.eval.report import markdown_table as table
from grip.eval.runner import play_segments
from grip.eval.segments import BenchError, Segment
from grip.kinematics.evaluate import METRIC_KEYS, segment_metrics

__all__ = ["MIN_SEGMENT_FRAMES", "aggregate", "evaluate_in_pool", "evaluate_segments",
           "markdown_table"]

MIN_SEGMENT_FRAMES = 10
"""Shortest segment ``grip kin eval`` keeps: a recording's tail down to this length counts."""


def evaluate_segments(
    est, segments: Sequence[Segment], batch: int = 32,
    progress: Callable[[int], object] | None = None, joints: str = "pose", init: str = "truth",
) -> list[dict]:  # fmt: skip
    """KinematicsNet (a :class:`~grip.kinematics.inference.KinematicsEstimator`) on segments,
    ``batch`` per forward pass, each from its first frame's ground truth (the GRIP protocol) or,
    with ``init="standing"``, from the standing pose at the sensors' heading.

    Returns:
        One row per segment: its segment keys and the metrics of ``joints`` (``frames`` the
        segment's length).
    """

    def score(recs: list) -> list[dict]:
        return [segment_metrics(out, rec, joints)
                for rec, out in zip(recs, est.predict(recs, init), strict=True)]  # fmt: skip

    return play_segments(segments, score, batch, progress)


_WORKER_MODEL: dict = {}


def _worker_unit(model: str, tta: str, segments: Sequence[Segment], batch: int, joints: str,
                 init: str) -> list[dict]:  # fmt: skip
    """:func:`evaluate_segments` in a worker process (a local one or Ray's): the checkpoint is
    loaded on the first call (torch on one thread) and kept."""
    est = _WORKER_MODEL.get((model, tta))
    if est is None:
        import torch

        from grip.kinematics.inference import KinematicsEstimator

        torch.set_num_threads(1)
        _WORKER_MODEL.clear()
        est = _WORKER_MODEL[model, tta] = KinematicsEstimator.from_checkpoint(model, tta=tta)
    return evaluate_segments(est, segments, batch, joints=joints, init=init)


def evaluate_in_pool(
    model: str, segments: Sequence[Segment], pool: CallPool, batch: int = 32,
    progress: Callable[[int], object] | None = None, joints: str = "pose", init: str = "truth",
    tta: str = "none",
) -> list[dict]:  # fmt: skip
    """:func:`evaluate_segments` of the checkpoint ``model`` in ``pool``'s workers: units of
    ``batch`` consecutive segments (fewer when a worker would otherwise wait).

    Args:
        model: KinematicsNet checkpoint (a path the workers can read).
        segments: What to score, in order.
        pool: Worker processes (:class:`grip.eval.pool.WorkerPool`) or Ray tasks
            (:class:`grip.cluster.RayPool`).
        batch, joints, init: As :func:`evaluate_segments`.
        progress: Called with the number of segments of each finished unit.
        tta: KinematicsNet's test-time augmentation.

    Returns:
        The rows of :func:`evaluate_segments`, in segment order.

    Raises:
        The exception a unit raised (the worker's traceback its cause). BenchError: a worker
        process died.
    """
    size = max(1, min(batch, -(-len(segments) // max(pool.workers, 1))))
    parts = [list(segments[i : i + size]) for i in range(0, len(segments), size)]
    calls = [(_worker_unit, (model, tta, part, batch, joints, init)) for part in parts]
    got: dict[int, list[dict]] = {}

    def done(k: int, rows) -> None:
        if isinstance(rows, BaseException):
            raise rows
        got[k] = rows
        if progress is not None:
            progress(len(parts[k]))

    lost = pool.run(calls, done)
    if lost:
        first = [parts[k][0].id for k in lost]
        raise BenchError(f"a worker process died (a crash or out of memory) while scoring "
                         f"{len(lost)} run(s) of segments (starting at "
                         f"{', '.join(first[:4])}{', ...' if len(first) > 4 else ''}); run "
                         "without --workers and --ray to see the error")  # fmt: skip
    return [r for k in range(len(parts)) for r in got[k]]


def _mean(rows: list[dict]) -> dict:
    out = weighted_means(rows, METRIC_KEYS, skip_nan=False)
    settled = [r for r in rows if r.get("settled_frames", 0) > 0]
    out["PEL_MPJPE_settled_mm"] = (weighted_means(settled, ("PEL_MPJPE_settled_mm",),
                                                  "settled_frames")["PEL_MPJPE_settled_mm"]
                                   if settled else float("nan"))  # fmt: skip
    out["frames"] = int(sum(r["frames"] for r in rows))
    out["segments"] = len(rows)
    return out


def aggregate(rows: list[dict], key: str = "category") -> dict:
    """Frame-weighted means overall and per category (or per another row key, e.g.
    ``"source"``).

    Returns:
        ``{"overall": {...}, "categories": {category: {...}}}``.
    """
    return category_summary(rows, _mean, key)


def markdown_table(agg: dict, key: str = "category") -> str:
    """The per-category (or per-``key``) table and the overall row in Markdown."""
    head = [key, "segments", "frames", "PEL-MPJPE (mm)", "after 1 s (mm)", "MPJRE (deg)",
            "leaf vel. (m/s)", "root transl. (m)"]  # fmt: skip
    items = [*agg["categories"].items(), ("**all**", agg["overall"])]
    body = [[name, str(m["segments"]), str(m["frames"]), f"{m['PEL_MPJPE_mm']:.1f}",
             f"{m.get('PEL_MPJPE_settled_mm', float('nan')):.1f}", f"{m['MPJRE_deg']:.2f}",
             f"{m['leaf_vel_err_mps']:.3f}", f"{m['trans_err_m']:.3f}"]
            for name, m in items]  # fmt: skip
    return table(head, body)
