"""``grip policy eval`` one segment after another (``--batch 1``) and side by side
(``--batch N``): wall time of each, the speed-up, and how far the per-segment metrics move.

Three passes over the same segments in one process, each with the same torch thread count,
taking turns on ``--rounds`` parts of the segments (a load from other processes that changes
during the run weighs on each pass alike):

- ``sequential``: :meth:`grip.pipeline.GripPipeline.play` per segment (``--batch 1``);
- ``batched``: :class:`grip.pipeline.BatchedPlayer`, one controller forward per frame over the
  rows whose decision is due;
- ``batched_rowwise``: the same, but the controller run on each row alone (what a row's action
  is when played alone): isolates the batched player itself (its numbers must equal the
  sequential ones exactly) from the float32 rounding of a batched forward, which the
  simulation may amplify into another trajectory.

The per-segment metrics of each batched pass are compared with the sequential ones: the largest
absolute difference per metric, the segments whose rows are identical, and those whose fall
outcome or length differ.

    python benchmarks/eval_batch.py --data data/person --segments 64 \\
        --segment-frames 300 --batch 16 --json runs/eval_batch.json
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

_COMPARED = ("MPJPE_mm", "PA_MPJPE_mm", "FS_mps", "FP_mm", "vGRF_N", "kin_MPJPE_mm",
             "root_err_m", "travel_ratio", "pelvis_min_m", "frames")  # fmt: skip


class _RowWise:
    """A controller whose batched ``act`` runs the wrapped one on each row alone."""

    def __init__(self, runner) -> None:
        self.runner = runner
        self.env_cfg, self.obs_keys = runner.env_cfg, runner.obs_keys
        self.disc, self.info = runner.disc, runner.info

    def act(self, obs: dict) -> np.ndarray:
        n = len(next(iter(obs.values())))
        return np.stack([self.runner.act({k: v[i] for k, v in obs.items()}) for i in range(n)])

    def fall_probability(self, amp_obs: np.ndarray) -> np.ndarray:
        return self.runner.fall_probability(amp_obs)


def _same(a: dict, b: dict) -> bool:
    """Rows equal key by key (NaN equals NaN)."""
    return a.keys() == b.keys() and all(
        a[k] == b[k] or (isinstance(a[k], float) and math.isnan(a[k]) and math.isnan(b[k]))
        for k in a
    )


def _compare(seq: list[dict], other: list[dict]) -> dict:
    diff = {}
    for k in _COMPARED:
        d = [abs(float(a[k]) - float(b[k])) for a, b in zip(seq, other, strict=True)
             if math.isfinite(float(a[k])) or math.isfinite(float(b[k]))]  # fmt: skip
        diff[k] = max(d, default=0.0)
    return {
        "max_abs_diff": diff,
        "identical_rows": sum(_same(a, b) for a, b in zip(seq, other, strict=True)),
        "fall_outcome_differs": sum(a["fell"] != b["fell"] for a, b in zip(seq, other,
                                                                            strict=True)),
        "length_differs": sum(a["frames"] != b["frames"] for a, b in zip(seq, other,
                                                                          strict=True)),
    }  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, required=True, help="dataset folder (grip data build)")
    ap.add_argument("--split", default="test")
    ap.add_argument("--segments", type=int, default=64)
    ap.add_argument("--segment-frames", type=int, default=300)
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--threads", type=int, default=0,
                    help="threads stepping a batch's humanoids (0: the usable cores)")
    ap.add_argument("--torch-threads", type=int, default=1)
    ap.add_argument("--rounds", type=int, default=4,
                    help="the passes take turns on this many parts of the segments")
    ap.add_argument("--no-rowwise", action="store_true", help="skip the batched_rowwise pass")
    ap.add_argument("--policy", type=Path, default=None)
    ap.add_argument("--kin", type=Path, default=None)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()

    import torch

    from grip.assets import SHIPPED_POLICY
    from grip.cli.recordings import kin_checkpoint
    from grip.eval.policy import evaluate_segments
    from grip.eval.segments import list_segments, split_files
    from grip.kinematics.inference import KinematicsEstimator
    from grip.pipeline import usable_cores
    from policies.controller import load_controller

    torch.set_num_threads(args.torch_threads)
    est = KinematicsEstimator.from_checkpoint(kin_checkpoint(args.kin))
    runner = load_controller([args.policy or SHIPPED_POLICY])
    segs = list_segments(split_files(args.data, args.split, set()), args.segment_frames, [],
                         [], limit=args.segments)  # fmt: skip
    evaluate_segments(runner, est, segs[:2], play_batch=2)  # warm-up (imports, first compile)
    passes = [("sequential", runner, 1), ("batched", runner, args.batch)]
    if not args.no_rowwise:
        passes.append(("batched_rowwise", _RowWise(runner), args.batch))
    rows: dict[str, list] = {name: [] for name, _, _ in passes}
    wall = dict.fromkeys(rows, 0.0)
    # the passes take turns on parts of the segments, so that a load that changes over the run
    # (other processes on the cores) weighs on each alike
    size = -(-len(segs) // max(args.rounds, 1))
    for i in range(0, len(segs), size):
        for name, ctrl, batch in passes:
            t0 = time.perf_counter()
            rows[name] += evaluate_segments(ctrl, est, segs[i : i + size], play_batch=batch,
                                            threads=args.threads)  # fmt: skip
            wall[name] += time.perf_counter() - t0
    for name in rows:
        frames = sum(r["frames"] for r in rows[name])
        print(f"{name:16s} {wall[name]:7.2f} s  {frames} frames  "
              f"{1e3 * wall[name] / frames:.3f} ms/frame", flush=True)  # fmt: skip
    out = {
        "data": str(args.data), "split": args.split, "segments": len(segs),
        "segment_frames": args.segment_frames, "batch": args.batch, "rounds": args.rounds,
        "threads": args.threads or usable_cores(), "torch_threads": args.torch_threads,
        "wall_s": wall, "frames": sum(r["frames"] for r in rows["sequential"]),
        "fell": sum(r["fell"] for r in rows["sequential"]),
    }  # fmt: skip
    for name in wall:
        if name == "sequential":
            continue
        out[f"speedup_{name}"] = wall["sequential"] / wall[name]
        out[f"compare_{name}"] = _compare(rows["sequential"], rows[name])
        c = out[f"compare_{name}"]
        worst = max(c["max_abs_diff"].items(), key=lambda kv: kv[1])
        print(f"{name}: {out[f'speedup_{name}']:.2f}x faster; {c['identical_rows']}/{len(segs)} "
              f"rows identical, largest difference {worst[0]} {worst[1]:.4g}, fall outcome "
              f"differs on {c['fall_outcome_differs']}")  # fmt: skip
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=1))
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
