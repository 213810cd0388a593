"""How still the reference's feet are while they carry load: a check of reference quality per
group of built sequences (no simulation).

For each sequence of a group (the first ``--per-group`` in name order) and each foot, the frames
where the synthesised insole's total force is above ``--load`` of its 95th percentile count as
loaded; printed per group: the median horizontal speed of the foot sensor over loaded frames
(foot skating), the median height of the foot sensor there, and the loaded share of frames.

    python benchmarks/reference_contacts.py --data DATA [--group 'cmu=cmu__*' ...]
"""

from __future__ import annotations

import argparse
import fnmatch
from pathlib import Path

import numpy as np

DEFAULT_GROUPS = (
    "bandai dataset-1 walk=bandai_namco__dataset-1_walk_*",
    "bandai dataset-2 walk=bandai_namco__dataset-2_walk_*",
    "bandai dataset-1 walk-back=bandai_namco__dataset-1_walk-back_*",
    "bandai dataset-1 dance=bandai_namco__dataset-1_dance*",
    "cmu=cmu__*",
    "hdm05=hdm05__*",
)


def foot_stats(path: Path, load: float) -> list[tuple[float, float, float]]:
    """``(speed m/s, height m, loaded share)`` of each foot with at least 10 loaded frames."""
    out = []
    with np.load(path) as z:
        for side in ("L", "R"):
            force = z[f"insole/{side}_Foot/force"][:, 0]
            loaded = force > load * np.percentile(force, 95)
            if loaded.sum() < 10:
                continue
            vel = z[f"imu_gt/{side}_Foot/vel_world"][loaded, :2]
            height = z[f"imu_gt/{side}_Foot/pos_world"][loaded, 2]
            out.append((float(np.median(np.linalg.norm(vel, axis=1))),
                        float(np.median(height)), float(loaded.mean())))  # fmt: skip
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, required=True, help="'grip data build' output folder")
    ap.add_argument("--group", action="append", default=None, metavar="NAME=GLOB",
                    help="a group of sequence files (repeatable; default: six source groups)")
    ap.add_argument("--per-group", type=int, default=30, help="sequences per group")
    ap.add_argument("--load", type=float, default=0.3,
                    help="loaded: force above this share of the foot's 95th percentile")
    args = ap.parse_args(argv)
    files = sorted((args.data / "sequences").glob("*.npz"))
    print("| group | sequences | foot speed under load (m/s) | foot sensor height (m) "
          "| loaded share |")
    print("|---|---:|---:|---:|---:|")
    for spec in args.group or DEFAULT_GROUPS:
        name, _, pattern = spec.partition("=")
        chosen = [f for f in files if fnmatch.fnmatch(f.name, pattern)][: args.per_group]
        rows = np.array([r for f in chosen for r in foot_stats(f, args.load)])
        if not len(rows):
            print(f"| {name} | {len(chosen)} | - | - | - |")
            continue
        print(f"| {name} | {len(chosen)} | {rows[:, 0].mean():.3f} | {rows[:, 1].mean():.3f} "
              f"| {rows[:, 2].mean():.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
