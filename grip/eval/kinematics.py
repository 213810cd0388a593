"""``grip kin eval``: KinematicsNet alone on :mod:`grip.eval.segments`, its own metrics
(:func:`grip.kinematics.evaluate.segment_metrics`), frame-weighted per category and overall."""

from __future__ import annotations

from collections.abc import Callable, Sequence

from grip.eval.report import category_summary, weighted_means
from grip.eval.report import markdown_table as table
from grip.eval.runner import play_segments
from grip.eval.segments import Segment
from grip.kinematics.evaluate import METRIC_KEYS, segment_metrics

__all__ = ["MIN_SEGMENT_FRAMES", "aggregate", "evaluate_segments", "markdown_table"]

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
