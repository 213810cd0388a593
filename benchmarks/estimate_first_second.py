"""How a KinematicsNet's estimate of the locomotion test walks differs in its first second from
the rest (issue 46: the humanoid loses its pace to the estimate in the first second,
docs/pace.md): per walk, the root-relative joint error, the feet's root-relative horizontal
speed over the truth's and the integrated root's speed over the truth's, over frames 0-1 s and
1 s-end, and the walker's own speed over 0-0.3 s, 0.3-1 s and after (``setting_off``: the first
0.3 s below 70 % of the speed after 1 s); medians (and the share setting off) printed and
written with the rows to --json.

    python benchmarks/estimate_first_second.py --data DATA [--kin CKPT] --json F
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

FEET = (10, 11)  # (grip.core.skeleton: L_Foot, R_Foot)


def window_ratios(est, truth, first_s: float = 1.0) -> dict[str, float]:
    """The figures of one walk from its estimate and its truth as reference clips (``est_pos``
    root-relative joints, ``est_root_pos`` integrated roots; same frames)."""
    fps = float(est.fps)
    k = round(first_s * fps)
    err = np.linalg.norm(est.est_pos - truth.est_pos, axis=-1).mean(-1)

    def speed(x: np.ndarray) -> np.ndarray:
        return np.linalg.norm(np.gradient(x, axis=0), axis=-1) * fps

    feet_e = speed(est.est_pos[:, FEET, :2]).mean(-1)
    feet_t = speed(truth.est_pos[:, FEET, :2]).mean(-1)
    root_e, root_t = speed(est.est_root_pos[:, :2]), speed(truth.est_root_pos[:, :2])

    def ratio(a: np.ndarray, b: np.ndarray) -> float:  # (NaN where the truth stands still)
        return float(a.mean() / b.mean()) if b.mean() > 1e-6 else float("nan")

    k3 = round(0.3 * fps)
    out = {"truth_speed_0_0.3s_mps": float(root_t[:k3].mean()),
           "truth_speed_0.3_1s_mps": float(root_t[k3:k].mean()),
           "truth_speed_after_1s_mps": float(root_t[k:].mean())}  # fmt: skip
    out["setting_off"] = float(out["truth_speed_0_0.3s_mps"]
                               < 0.7 * out["truth_speed_after_1s_mps"])  # fmt: skip
    for name, sl in (("first", slice(0, k)), ("rest", slice(k, None))):
        out[f"joint_err_{name}_m"] = float(err[sl].mean())
        out[f"feet_speed_ratio_{name}"] = ratio(feet_e[sl], feet_t[sl])
        out[f"root_speed_ratio_{name}"] = ratio(root_e[sl], root_t[sl])
    return out


def main(argv: list[str] | None = None) -> None:
    from grip.assets import SHIPPED_KIN

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--kin", default=str(SHIPPED_KIN))
    ap.add_argument("--categories", default="walk*,run*")
    ap.add_argument("--segment-frames", type=int, default=500)
    ap.add_argument("--json", required=True)
    args = ap.parse_args(argv)
    if not Path(args.kin).is_file():
        ap.error(f"--kin {args.kin}: no such file")

    from grip.eval.policy import _estimates
    from grip.eval.segments import SegmentReader, list_segments, split_files
    from grip.kinematics.inference import KinematicsEstimator

    est = KinematicsEstimator.from_checkpoint(args.kin)
    segs = list_segments(split_files(args.data, "test"), args.segment_frames,
                         args.categories.split(","))  # fmt: skip
    read = SegmentReader()
    rows = []
    for seg in segs:
        rec = read(seg)
        e, t = (_estimates(est, [rec], 1, ref, "truth")[0] for ref in ("estimate", "truth"))
        rows.append({"segment": seg.id, **window_ratios(e, t)})
    med = {k: float(np.nanmedian([r[k] for r in rows])) for k in rows[0]
           if k not in ("segment", "setting_off")}  # fmt: skip
    med["share_setting_off"] = float(np.mean([r["setting_off"] for r in rows]))
    print(json.dumps(med, indent=1))
    Path(args.json).write_text(json.dumps({"kin": args.kin, "walks": len(rows), "median": med,
                                           "rows": rows}, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
