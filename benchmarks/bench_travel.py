"""How much ground each method's pelvis covers against the truth's, from a ``grip bench`` folder.

Usage::

    grip bench --data DATA --methods kinematics,kin+pip --category walk --save-recons --out D
    .venv/bin/python benchmarks/bench_travel.py D --data DATA [--json PATH]

For every saved reconstruction (``D/recons/<method>/<segment>.npz``) the pelvis' horizontal
path length over that of the segment's ground truth (1: the walker's ground, < 1: short of
it), and the horizontal pelvis distance to the truth at the last frame; per method the median
and the mean over its segments. A physics method that loses travel shows it even where the
estimate it was given does not (docs/pace.md, "The shipped pair"). The segment's recording is
found by its name in ``DATA``'s sequences (``<stem>_f<start>``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def path_length(xy: np.ndarray) -> float:
    """Horizontal path length, m, of ``(T, 2)`` positions."""
    return float(np.linalg.norm(np.diff(np.asarray(xy, dtype=np.float64), axis=0), axis=-1).sum())


def travel(recon_pelvis: np.ndarray, truth_pelvis: np.ndarray) -> tuple[float, float]:
    """``(path ratio, end distance m)`` of a pelvis track against the truth's (``(T, 3)`` or
    ``(T, 2)``; the common frames)."""
    n = min(len(recon_pelvis), len(truth_pelvis))
    a, b = np.asarray(recon_pelvis)[:n, :2], np.asarray(truth_pelvis)[:n, :2]
    gt = path_length(b)
    ratio = path_length(a) / gt if gt > 0 else float("nan")
    return ratio, float(np.linalg.norm(a[-1] - b[-1]))


def _segment_recording(data: Path, seg: str, frames: int):
    """Frames ``[start, start + frames)`` of segment ``seg``'s recording in ``data``."""
    from prism_tools.io import load_recording

    stem, _, start = seg.rpartition("_f")
    rec = load_recording(data / "sequences" / f"{stem}.npz")
    return rec.slice_frames(int(start), min(int(start) + frames, rec.n_frames))


def measure(bench_dir: Path, data: Path) -> dict[str, dict]:
    """``{method: {"segments", "travel_median", "travel_mean", "end_to_truth_median_m"}}``."""
    from grip.core.reconstruction import Reconstruction
    from grip.kinematics.features import ground_truth

    root = bench_dir / "recons"
    if not root.is_dir():
        raise SystemExit(f"{root}: no saved reconstructions; run 'grip bench ... --save-recons'")
    out = {}
    truths: dict[str, np.ndarray] = {}
    for method_dir in sorted(p for p in root.iterdir() if p.is_dir()):
        rows = []
        for f in sorted(method_dir.glob("*.npz")):
            recon = Reconstruction.load(f)
            if f.stem not in truths:
                rec = _segment_recording(data, f.stem, recon.n_frames)
                truths[f.stem] = ground_truth(rec).joint_pos[:, 0]
            rows.append(travel(recon.joint_pos[:, 0], truths[f.stem]))
        if rows:
            a = np.array(rows)
            out[method_dir.name] = {"segments": len(rows),
                                    "travel_median": float(np.nanmedian(a[:, 0])),
                                    "travel_mean": float(np.nanmean(a[:, 0])),
                                    "end_to_truth_median_m": float(np.median(a[:, 1]))}  # fmt: skip
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bench", type=Path, help="a 'grip bench --save-recons' output folder")
    ap.add_argument("--data", type=Path, required=True, help="the dataset folder it ran on")
    ap.add_argument("--json", type=Path, help="also write the numbers here")
    args = ap.parse_args(argv)
    res = measure(args.bench, args.data)
    print("| method | segments | travel / truth (median) | (mean) | pelvis to truth at the end "
          "(median, m) |\n|---|---:|---:|---:|---:|")  # fmt: skip
    for m, r in res.items():
        print(f"| {m} | {r['segments']} | {r['travel_median']:.3f} | {r['travel_mean']:.3f} | "
              f"{r['end_to_truth_median_m']:.2f} |")  # fmt: skip
    if args.json:
        args.json.write_text(json.dumps(res, indent=1) + "\n")
    return 0 if res else 1


if __name__ == "__main__":
    sys.exit(main())
