"""A/B of the teacher's learning curve per decision: train short runs, then plot them together.

``train``: stage 1 of a recipe (default ``configs/policy/teacher.toml``) for ``--decisions``
(then ``--stage2`` decisions of its stage 2, default none) on
a reference set, one torch thread and one physics thread, seed 0 unless overridden, in a run
folder (resumable, as ``grip policy train``). To train with another checkout's code (the code
before a change), run this file with that checkout first on ``PYTHONPATH``::

    git worktree add /tmp/before COMMIT
    PYTHONPATH=/tmp/before python benchmarks/teacher_ab.py train --out runs/ab_before \\
        --reference REF.npz --decisions 400000
    python benchmarks/teacher_ab.py train --out runs/ab_after --reference REF.npz \\
        --decisions 400000 [--set ppo.n_epochs=2 ...]

``plot``: the runs' training success, MPJPE, episode length and style reward (smoothed over
``--window`` rollouts) against decisions, with a summary per run (the means over the last
``--tail`` decisions; the mean over the whole curve; wall seconds, which depend on what else
ran on the machine: speed is ``benchmarks/policy_throughput.py``'s to measure) in JSON::

    python benchmarks/teacher_ab.py plot --run before=runs/ab_before --run after=runs/ab_after \\
        --png docs/teacher_ab.png --json docs/perf/teacher_ab.json

Two runs of one seed differ by the luck of their episodes as soon as anything in them
differs; compare a change's gap with the noise of a curve (the rollout-to-rollout spread the
summary reports), not with zero.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SERIES = (("success_rate", "training success"), ("mpjpe_mm", "MPJPE (mm)"),
          ("ep_len", "episode length (frames)"), ("reward/amp", "style reward"))  # fmt: skip


def train(args) -> int:
    from envs.factory import make_tracking_env
    from grip.config import load_config
    from policies.config import PolicyRunConfig
    from policies.train import PolicyTrainer

    sets = ["ppo.threads=1", "ppo.env_threads=1", "seed=0", *args.overrides]
    cfg = load_config(args.config, PolicyRunConfig(), sets)
    cfg = dataclasses.replace(
        cfg, stage1=dataclasses.replace(cfg.stage1, timesteps=args.decisions),
        stage2=dataclasses.replace(cfg.stage2, timesteps=args.stage2))  # fmt: skip
    t = time.perf_counter()
    PolicyTrainer(cfg, args.out, args.reference, make_tracking_env).train()
    print(f"{args.out}: {args.decisions + args.stage2} decisions in "
          f"{time.perf_counter() - t:.0f} s")
    return 0


def history(run: Path) -> list[dict]:
    """The rows of a run folder's checkpoint (one per rollout)."""
    return json.loads((run / "checkpoint" / "state.json").read_text())["history"]


def summary(rows: list[dict], tail: int) -> dict:
    """Means over the last ``tail`` decisions and over the whole run, per series."""
    t = np.array([r["timesteps"] for r in rows], dtype=float)
    out = {"decisions": int(t[-1]), "rollouts": len(rows), "wall_s": rows[-1]["wall_s"]}
    last = t > t[-1] - tail
    for key, _ in SERIES:
        v = np.array([r.get(key, np.nan) for r in rows], dtype=float)
        out[key] = {"last": float(np.nanmean(v[last])), "whole": float(np.nanmean(v)),
                    "rollout_sd_last": float(np.nanstd(v[last]))}  # fmt: skip
    return out


def plot(args) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = {}
    for item in args.runs:
        name, _, path = item.partition("=")
        runs[name] = history(Path(path))
    fig, axes = plt.subplots(1, len(SERIES), figsize=(4.2 * len(SERIES), 3.8), squeeze=False)
    out = {"window": args.window, "tail": args.tail, "runs": {}}
    for name, rows in runs.items():
        t = np.array([r["timesteps"] for r in rows], dtype=float)
        for j, (key, label) in enumerate(SERIES):
            v = np.array([r.get(key, np.nan) for r in rows], dtype=float)
            ok = np.isfinite(v)
            s = np.convolve(np.where(ok, v, 0.0), np.ones(args.window), "full")[: len(v)]
            cnt = np.convolve(ok.astype(float), np.ones(args.window), "full")[: len(v)]
            axes[0, j].plot(t / 1e6, s / np.maximum(cnt, 1), label=name)
            axes[0, j].set_title(label)
            axes[0, j].set_xlabel("decisions (M)")
        out["runs"][name] = summary(rows, args.tail)
    for ax in axes.ravel():
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize="small")
    stages = sorted({r.get("stage", "stage1") for rows in runs.values() for r in rows})
    fig.suptitle(f"teacher recipe, {' and '.join(stages)} (smoothed over {args.window} rollouts)")
    fig.tight_layout()
    args.png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.png, dpi=90)
    print(json.dumps(out, indent=1))
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("train", help="a short run of the recipe")
    t.add_argument("--out", type=Path, required=True)
    t.add_argument("--reference", type=Path, required=True)
    t.add_argument("--decisions", type=int, default=400_000, help="stage 1's decisions")
    t.add_argument("--stage2", type=int, default=0, metavar="N",
                   help="then N decisions of the recipe's stage 2 (default 0: stage 1 only)")
    t.add_argument("--config", type=Path, default=ROOT / "configs" / "policy" / "teacher.toml")
    t.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    p = sub.add_parser("plot", help="plot runs together")
    p.add_argument("--run", dest="runs", action="append", required=True, metavar="NAME=DIR")
    p.add_argument("--window", type=int, default=10, help="rollouts to smooth over")
    p.add_argument("--tail", type=int, default=100_000, help="decisions of the summary's end")
    p.add_argument("--png", type=Path, required=True)
    p.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    return train(args) if args.cmd == "train" else plot(args)


if __name__ == "__main__":
    sys.exit(main())
