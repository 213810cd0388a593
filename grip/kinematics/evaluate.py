"""KinematicsNet's metrics per segment (``grip kin eval``; its report over a dataset's segments is
:mod:`grip.eval.kinematics`), and the same on recordings in memory."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np

from grip.core import metrics as M
from grip.kinematics.features import targets
from grip.kinematics.inference import KinematicsEstimator

METRIC_KEYS: tuple[str, ...] = (
    "PEL_MPJPE_mm", "MPJRE_deg", "leaf_vel_err_mps", "trans_err_m", "MPJPE_mm", "PA_MPJPE_mm",
)  # fmt: skip

SETTLE_S = 1.0
"""``PEL_MPJPE_settled_mm`` leaves out each segment's first second: the frames where a start
from the standing pose (``--init standing``) has not yet caught up with the motion."""


JOINTS: tuple[str, ...] = ("pose", "fp")
"""Which joints the position metrics read: the estimated pose (rotations posed on the body,
:attr:`KinematicEstimate.joint_pos`) or the FP stage's own (``fp_joint_pos``)."""


def segment_metrics(est_out, rec, joints: str = "pose") -> dict[str, float]:
    """Metrics of one estimate against its recording's ground truth.

    ``PEL_MPJPE_mm``: root-relative joint error (mm); ``MPJRE_deg``: global joint rotation
    error (deg); ``leaf_vel_err_mps``: mean error of the 6 velocity outputs (m/s);
    ``trans_err_m``: mean distance between the integrated and the true root trajectory (m);
    ``MPJPE_mm``: global joint error with the integrated root trajectory (mm);
    ``PA_MPJPE_mm``: joint error after Procrustes alignment per frame (mm);
    ``PEL_MPJPE_settled_mm``: ``PEL_MPJPE_mm`` after the first :data:`SETTLE_S` (NaN for a
    segment no longer than that), over ``settled_frames`` frames.
    """
    if joints not in JOINTS:
        raise ValueError(f"joints must be one of {list(JOINTS)}, got {joints!r}")
    gt = targets(rec)
    pos = est_out.joint_pos if joints == "pose" else est_out.fp_joint_pos
    est_glob = pos + est_out.root_pos[:, None]
    gt_glob = gt.joint_pos + gt.root_pos[:, None]
    skip = round(SETTLE_S * float(rec.fps))
    settled = (float(M.pel_mpjpe(pos[skip:], gt.joint_pos[skip:])) if rec.n_frames > skip
               else float("nan"))  # fmt: skip
    return {
        "PEL_MPJPE_mm": float(M.pel_mpjpe(pos, gt.joint_pos)),
        "MPJRE_deg": float(M.mpjre(est_out.global_rot, gt.global_rot)),
        "leaf_vel_err_mps": float(np.linalg.norm(est_out.velocity - gt.velocity, axis=-1).mean()),
        "trans_err_m": float(np.linalg.norm(est_out.root_pos - gt.root_pos, axis=-1).mean()),
        "MPJPE_mm": float(M.mpjpe(est_glob, gt_glob)),
        "PA_MPJPE_mm": float(M.pa_mpjpe(pos, gt.joint_pos)),
        "frames": int(rec.n_frames),
        "PEL_MPJPE_settled_mm": settled,
        "settled_frames": max(int(rec.n_frames) - skip, 0),
    }


def predict_segments(
    est: KinematicsEstimator,
    recs: list,
    segment_frames: int = 500,
    batch: int = 32,
    progress: Callable[[int], object] | None = None,
) -> Iterator[tuple[object, object]]:
    """Cut recordings into segments (each initialised from its first frame's ground truth, the
    GRIP protocol), run them in batches and yield ``(segment recording, estimate)`` pairs."""
    from prism_tools.chunking import segments

    segs = [rec.slice_frames(sl.start, sl.stop) for rec in recs
            for sl in segments(rec.n_frames, segment_frames, min_length=10)]  # fmt: skip
    for i in range(0, len(segs), batch):
        part = segs[i : i + batch]
        yield from zip(part, est.predict(part), strict=True)
        if progress is not None:
            progress(len(part))


def evaluate_recordings(
    est: KinematicsEstimator,
    recs: list,
    segment_frames: int = 500,
    batch: int = 32,
    progress: Callable[[int], object] | None = None,
    joints: str = "pose",
) -> list[dict]:
    """:func:`predict_segments` scored: one metrics dict per segment (with ``name`` and
    ``category``), the rows :func:`grip.eval.kinematics.aggregate` takes."""
    pairs = predict_segments(est, recs, segment_frames, batch, progress)
    return [{"name": rec.name, "category": rec.category or "unknown",
             **segment_metrics(out, rec, joints)} for rec, out in pairs]  # fmt: skip
