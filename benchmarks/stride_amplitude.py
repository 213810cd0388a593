"""Does KinematicsNet shorten the strides of the walks it estimates? (issue 46, docs/pace.md)

For each locomotion segment: the stride amplitude of the estimated pose against the truth's,
where the stride amplitude is the 95th percentile over the segment of the horizontal distance
between the two ankles in the root-relative pose (feet apart at the longest step). A ratio
below 1 means the estimate's legs swing less than the walker's, while its root may move at the
walker's speed: a humanoid imitating those legs steps short. Beside it the legs' speed: the mean
rate at which the ankles part and close along the stride's axis (the principal axis of their
horizontal offset), m/s. A walker's stance foot moves back under the pelvis at the walking
speed while the swing foot moves forward about as fast, so this rate is a multiple of the speed
the pose alone walks at, whatever the root does: the ratio estimate/truth is the pace the legs
set (``legs_ratio``). And the trunk's lean towards the travel, estimate minus truth
(``lean_est_minus_truth_deg``; negative: the estimate leans back), which sets the humanoid's
pace (docs/pace.md, "The trunk's lean sets the pace").

    python benchmarks/stride_amplitude.py --data DATA --json F [--split train --kin-fold F0
        --kin-fold F1 --speed-factor 1.4] [--segments 52] [--shift S]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def _ankle_offset(joint_pos: np.ndarray) -> np.ndarray:
    """``(T, 2)`` the left ankle's horizontal offset from the right's, m."""
    from grip.core.skeleton import ANKLE_JOINTS

    left, right = ANKLE_JOINTS
    return joint_pos[:, left, :2] - joint_pos[:, right, :2]


def stride_amplitude(joint_pos: np.ndarray, q: float = 95.0) -> float:
    """The ``q``-th percentile over frames of the horizontal ankle-to-ankle distance, m, of
    ``(T, 24, 3)`` root-relative joints (world axes, z up)."""
    return float(np.percentile(np.linalg.norm(_ankle_offset(joint_pos), axis=1), q))


def leg_speed(joint_pos: np.ndarray, fps: float) -> float:
    """The mean rate, m/s, at which the ankles part and close along the principal axis of their
    horizontal offset, of ``(T, 24, 3)`` joints (world axes, z up); 0 for fewer than 3 frames."""
    d = _ankle_offset(joint_pos)
    if len(d) < 3:
        return 0.0
    d = d - d.mean(axis=0)
    axis = np.linalg.svd(d, full_matrices=False)[2][0]
    return float(np.abs(np.diff(d @ axis)).mean() * fps)


def trunk_lean_deg(joint_pos: np.ndarray, root_pos: np.ndarray) -> float:
    """The mean angle, deg, of the neck over the pelvis from the vertical towards the segment's
    direction of travel (the mean horizontal velocity of ``root_pos (T, 3)``), of ``(T, 24, 3)``
    root-relative joints; positive: leaning forward. NaN where the root does not travel."""
    v = (root_pos[-1, :2] - root_pos[0, :2]) if len(root_pos) > 1 else np.zeros(2)
    n = float(np.linalg.norm(v))
    if n < 1e-6:
        return float("nan")
    neck = joint_pos[:, 12] - joint_pos[:, 0]
    return float(np.degrees(np.arctan2(neck[:, :2] @ (v / n), neck[:, 2])).mean())


def main(argv: list[str] | None = None) -> None:
    from grip.assets import SHIPPED_KIN
    from grip.eval.segments import SegmentReader
    from grip.kinematics.features import targets
    from grip.kinematics.inference import KinematicsEstimator

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--kin", default=str(SHIPPED_KIN))
    ap.add_argument("--kin-fold", action="append", default=[], metavar="CKPT",
                    help="fold models: each segment estimated by the one that never saw its "
                    "person (pace_cause.py's option)")
    ap.add_argument("--split", default="test", choices=("train", "test"))
    ap.add_argument("--categories", default="walk*,run*")
    ap.add_argument("--segments", type=int, default=0)
    ap.add_argument("--segment-frames", type=int, default=500)
    ap.add_argument("--speed-factor", type=float, default=None)
    ap.add_argument("--shift", type=float, default=0.0, metavar="S",
                    help="each segment S seconds later in its file (pace_cause.py's option)")
    ap.add_argument("--json", required=True)
    args = ap.parse_args(argv)

    import torch
    from pace_cause import fold_chooser, split_segments

    torch.set_num_threads(1)
    segs, _keep = split_segments(args)  # (_keep: the speed-scaled recordings, read below)
    default = KinematicsEstimator.from_checkpoint(args.kin)
    choose = fold_chooser(args.kin_fold, args.data) if args.kin_fold else (lambda rec: default)
    read, rows = SegmentReader(), []
    for seg in segs:
        rec = read(seg)
        est, tgt = choose(rec).predict([rec])[0], targets(rec)
        fps = float(rec.fps)
        stride, legs = stride_amplitude(tgt.joint_pos), leg_speed(tgt.joint_pos, fps)
        row = {"segment": seg.id, "category": seg.category, "stride_truth_m": stride,
               "stride_est_m": stride_amplitude(est.joint_pos), "legs_truth_mps": legs,
               "legs_est_mps": leg_speed(est.joint_pos, fps),
               "lean_est_minus_truth_deg": trunk_lean_deg(est.joint_pos, tgt.root_pos)
               - trunk_lean_deg(tgt.joint_pos, tgt.root_pos)}  # (the walker's travel for both)
        row["ratio"] = row["stride_est_m"] / max(stride, 1e-9)
        row["legs_ratio"] = row["legs_est_mps"] / max(legs, 1e-9)
        rows.append(row)
    ratios = [r["ratio"] for r in rows]
    out = {"data": args.data, "split": args.split, "kin": args.kin_fold or args.kin,
           "speed_factor": args.speed_factor, "segments": len(rows),
           "median_ratio": float(np.median(ratios)) if rows else None,
           "median_legs_ratio": float(np.median([r["legs_ratio"] for r in rows]))
           if rows else None,
           "median_lean_est_minus_truth_deg": float(np.nanmedian(
               [r["lean_est_minus_truth_deg"] for r in rows])) if rows else None,
           "median_stride_truth_m": float(np.median([r["stride_truth_m"] for r in rows]))
           if rows else None, "rows": rows}  # fmt: skip
    Path(args.json).write_text(json.dumps(out, indent=1))
    print(json.dumps({k: v for k, v in out.items() if k != "rows"}))


if __name__ == "__main__":
    main()
