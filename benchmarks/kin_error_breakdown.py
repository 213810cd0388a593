"""Where KinematicsNet's root-relative error sits within one motion category: per joint group,
per joint, and on frames with the pelvis lowered (seated, crouched) against upright ones.

The segments are the ones ``grip kin eval`` scores (500 frames, each initialised from its first
frame's ground truth), so the category's overall number equals that table's PEL-MPJPE.
"Lowered" frames have the true pelvis more than ``--lowered`` metres below the highest pelvis
of the category's segments.

    python benchmarks/kin_error_breakdown.py --data DATA --category sit_stand [--split train]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from grip.cli.recordings import kin_checkpoint, load_recordings, split_paths
from grip.core import skeleton as sk
from grip.kinematics.evaluate import predict_segments
from grip.kinematics.features import targets
from grip.kinematics.inference import KinematicsEstimator

GROUPS: dict[str, tuple[str, ...]] = {
    "legs": ("L_Hip", "R_Hip", "L_Knee", "R_Knee", "L_Ankle", "R_Ankle", "L_Foot", "R_Foot"),
    "spine and head": ("Spine1", "Spine2", "Spine3", "Neck", "Head"),
    "arms": ("L_Collar", "R_Collar", "L_Shoulder", "R_Shoulder", "L_Elbow", "R_Elbow",
             "L_Wrist", "R_Wrist", "L_Hand", "R_Hand"),
}  # fmt: skip


def joint_errors(est: KinematicsEstimator, recs: list) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame, per-joint root-relative errors ``(F, 24)`` (m) and true pelvis heights
    ``(F,)`` (m) over the 500-frame segments of ``recs`` (those of ``grip kin eval``)."""
    errs, heights = [], []
    for rec, out in predict_segments(est, recs):
        gt = targets(rec)
        errs.append(np.linalg.norm(out.joint_pos - gt.joint_pos, axis=-1))
        heights.append(gt.root_pos[:, 2])
    if not errs:
        raise SystemExit("no segments: is the category in this split?")
    return np.concatenate(errs), np.concatenate(heights)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    ap.add_argument("--data", required=True, help="dataset folder (grip data build)")
    ap.add_argument("--category", required=True, help="motion category, e.g. sit_stand")
    ap.add_argument("--split", default="test", choices=("train", "test"))
    ap.add_argument("--model", default=None, help="KinematicsNet checkpoint (default: shipped)")
    ap.add_argument("--lowered", type=float, default=0.25,
                    help="metres below the category's highest pelvis that count as lowered")
    args = ap.parse_args()
    recs = [r for r in load_recordings(split_paths(Path(args.data), args.split))
            if r.category == args.category]  # fmt: skip
    est = KinematicsEstimator.from_checkpoint(kin_checkpoint(args.model))
    e, h = joint_errors(est, recs)
    idx = {g: [sk.JOINT_INDEX[n] for n in names] for g, names in GROUPS.items()}
    low = h < h.max() - args.lowered
    print(f"{args.category}, {args.split} split: {e.shape[0]} frames, PEL-MPJPE "
          f"{1000 * e.mean():.1f} mm")
    print("| frames | share | all | " + " | ".join(GROUPS) + " |")
    print("|---|---:|---:|" + "---:|" * len(GROUPS))
    for name, m in (("all", np.ones_like(low)), ("pelvis lowered", low), ("upright", ~low)):
        if m.any():
            cells = " | ".join(f"{1000 * e[m][:, j].mean():.1f}" for j in idx.values())
            print(f"| {name} | {100 * m.mean():.0f} % | {1000 * e[m].mean():.1f} | {cells} |")
    worst = np.argsort(-e.mean(0))[:6]
    print("worst joints (mm): " + ", ".join(f"{sk.JOINT_NAMES[j]} {1000 * e[:, j].mean():.0f}"
                                            for j in worst))  # fmt: skip


if __name__ == "__main__":
    main()
