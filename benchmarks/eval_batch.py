"""``grip policy eval`` one segment after another (``--batch 1``), side by side (``--batch N``)
and in worker processes (``--batch N --workers K``): wall time of each, the speed-ups, and how
far the per-segment metrics move.

Four passes over the same segments, each with torch on one thread, taking turns on parts of the
segments (``--rounds`` of them, fewer when a part would hold less than ``--workers`` whole
batches; a load from other processes that changes during the run weighs on each pass alike):

- ``sequential``: :meth:`grip.pipeline.GripPipeline.play` per segment, in this process;
- ``batched``: ``grip policy eval --batch N`` (:func:`grip.eval.policy.evaluate_batches` in
  this process): :class:`grip.pipeline.BatchedPlayer` per batch of N segments, one controller
  forward per frame over the rows whose decision is due;
- ``batched_workers``: ``grip policy eval --batch N --workers K``: the same batches played by K
  worker processes (started, and their models built, before the timing: ``workers_start_s``
  reports that time); its rows must equal the batched ones bit for bit;
- ``batched_rowwise``: the batched player over each part, but the controller run on each row
  alone (what a row's action is when played alone): isolates the batched player itself (its
  numbers must equal the sequential ones exactly) from the float32 rounding of a batched
  forward, which the simulation may amplify into another trajectory.

The per-segment metrics of each other pass are compared with the sequential ones (and
``batched_workers`` also with ``batched``): the largest absolute difference per metric, the
segments whose rows are identical, and those whose fall outcome or length differ.

    python benchmarks/eval_batch.py --data data/person --segments 64 \\
        --segment-frames 300 --batch 16 --workers 2 --json runs/eval_batch.json
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


def _parts(n: int, rounds: int, whole: int) -> list[slice]:
    """``rounds`` parts of ``n`` segments, each a whole multiple of ``whole`` (but the last)."""
    size = -(-n // max(rounds, 1))
    size = max(whole, -(-size // whole) * whole)
    return [slice(i, i + size) for i in range(0, n, size)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, required=True, help="dataset folder (grip data build)")
    ap.add_argument("--split", default="test")
    ap.add_argument("--segments", type=int, default=64)
    ap.add_argument("--segment-frames", type=int, default=300)
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--workers", type=int, default=2,
                    help="worker processes of the batched_workers pass (0: skip it)")  # fmt: skip
    ap.add_argument("--threads", type=int, default=0,
                    help="threads stepping a batch's humanoids in each process (0: the usable "
                    "cores, shared out over the workers in batched_workers)")  # fmt: skip
    ap.add_argument("--rounds", type=int, default=4,
                    help="the passes take turns on this many parts of the segments (fewer "
                    "when a part would hold less than --workers whole batches)")  # fmt: skip
    ap.add_argument("--no-rowwise", action="store_true", help="skip the batched_rowwise pass")
    ap.add_argument("--policy", type=Path, default=None)
    ap.add_argument("--kin", type=Path, default=None)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()

    import contextlib

    import torch

    from grip.assets import SHIPPED_POLICY
    from grip.cli.recordings import kin_checkpoint
    from grip.eval.policy import PolicySetup, evaluate_batches, evaluate_segments
    from grip.eval.pool import WorkerPool
    from grip.eval.segments import list_segments, split_files
    from grip.pipeline import usable_cores

    torch.set_num_threads(1)  # (as grip policy eval plays its batches, and as a worker)
    setup = PolicySetup((str((args.policy or SHIPPED_POLICY).resolve()),),
                        str(kin_checkpoint(args.kin).resolve()))  # fmt: skip
    runner, est = setup.build()
    segs = list_segments(split_files(args.data, args.split, set()), args.segment_frames, [],
                         [], limit=args.segments)  # fmt: skip
    evaluate_segments(runner, est, segs[:2], play_batch=2)  # warm-up (imports, first compile)

    def batched(part, pool=None):
        (got,) = evaluate_batches(setup, part, args.batch, threads=args.threads,
                                  built=(runner, est), pool=pool)  # fmt: skip
        return got

    passes = {
        "sequential": lambda part, pool: evaluate_segments(runner, est, part, play_batch=1,
                                                           threads=args.threads),
        "batched": lambda part, pool: batched(part),
    }  # fmt: skip
    if args.workers > 0:
        passes["batched_workers"] = batched
    if not args.no_rowwise:
        passes["batched_rowwise"] = lambda part, pool: evaluate_segments(
            _RowWise(runner), est, part, play_batch=args.batch, threads=args.threads
        )
    rows: dict[str, list] = {name: [] for name in passes}
    wall = dict.fromkeys(rows, 0.0)
    with contextlib.ExitStack() as stack:
        pool, start_s = None, 0.0
        if args.workers > 0:
            pool = stack.enter_context(WorkerPool(args.workers))
            t0 = time.perf_counter()  # the workers start and build their models: one batch each
            evaluate_batches(setup, segs[: 2 * args.workers], 2, pool=pool)
            start_s = time.perf_counter() - t0
        # the passes take turns on parts of the segments, so that a load that changes over the
        # run (other processes on the cores) weighs on each alike
        parts = _parts(len(segs), args.rounds, args.batch * max(args.workers, 1))
        for part in parts:
            for name, play in passes.items():
                t0 = time.perf_counter()
                rows[name] += play(segs[part], pool)
                wall[name] += time.perf_counter() - t0
    for name in rows:
        frames = sum(r["frames"] for r in rows[name])
        print(f"{name:16s} {wall[name]:7.2f} s  {frames} frames  "
              f"{1e3 * wall[name] / frames:.3f} ms/frame", flush=True)  # fmt: skip
    out = {
        "data": str(args.data), "split": args.split, "segments": len(segs),
        "segment_frames": args.segment_frames, "batch": args.batch, "workers": args.workers,
        "rounds": len(parts), "threads": args.threads or usable_cores(), "torch_threads": 1,
        "wall_s": wall, "frames": sum(r["frames"] for r in rows["sequential"]),
        "fell": sum(r["fell"] for r in rows["sequential"]),
    }  # fmt: skip
    if args.workers > 0:
        out["workers_start_s"] = start_s
        print(f"workers: {start_s:.2f} s to start and build their models (not in the passes)")
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
    if "batched_workers" in wall:
        w = wall["batched_workers"]
        out["speedup_batched_workers_over_batched"] = wall["batched"] / w
        out["speedup_batched_workers_with_start"] = wall["sequential"] / (w + start_s)
        same = sum(_same(a, b) for a, b in zip(rows["batched"], rows["batched_workers"],
                                               strict=True))  # fmt: skip
        out["batched_workers_identical_to_batched"] = same
        print(f"batched_workers: {out['speedup_batched_workers_over_batched']:.2f}x batched, "
              f"{out['speedup_batched_workers_with_start']:.2f}x sequential with the workers' "
              f"start; {same}/{len(segs)} rows identical to batched"
              + ("" if same == len(segs) else " (THEY MUST ALL BE)"))  # fmt: skip
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=1))
        print(f"wrote {args.json}")
    if "batched_workers" in wall and out["batched_workers_identical_to_batched"] != len(segs):
        raise SystemExit(1)


if __name__ == "__main__":
    main()
