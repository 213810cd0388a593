"""Learning curve and per-category failures of a ``grip policy train`` run, read from its
checkpoint (no simulation): what docs/teacher_student.md reports for the privileged tracker.

* The curve: each rollout's training success rate (episodes that reached their length limit
  without a fall or the distance termination), MPJPE against the reference and episode length
  over the decisions trained, smoothed over ``--window`` rollouts, one colour per stage.
* Per category: the hard-clip miner's decayed episode and failure counts (``state.json``'s
  ``mining``: the last few hundred rollouts), summed over each category's clips.
* A projection: a straight line through the smoothed success rate of the current stage's last
  ``--fit`` rollouts against log(decisions), extended to ``--target``. It is an extrapolation
  of a noisy curve, not a prediction; it says how far the run is at its present pace.

    python benchmarks/teacher_curve.py --run /work/runs/teacher --data /work/data/person2 \\
        --png docs/teacher_curve.png --json docs/perf/teacher_curve.json
"""

from __future__ import annotations

import argparse
import json
import math
import re
from collections import defaultdict
from pathlib import Path

import numpy as np


def _smooth(x: np.ndarray, n: int) -> np.ndarray:
    if len(x) < n or n <= 1:
        return x
    k = np.ones(n) / n
    head = np.cumsum(x[: n - 1]) / np.arange(1, n)
    return np.concatenate([head, np.convolve(x, k, mode="valid")])


def _categories(data: Path) -> dict[str, str]:
    """Clip id -> category from a dataset's manifest."""
    man = json.loads((data / "manifest.json").read_text())
    return {c["clip_id"]: c.get("category") or "unknown" for c in man["clips"]}


def _clip_id(name: str) -> str:
    """``synthetic_<source>/<clip>_seqNNN[#k]`` (a reference clip) -> ``<source>/<clip>``."""
    name = re.sub(r"#\d+$", "", name).removeprefix("synthetic_")
    return re.sub(r"_seq\d+$", "", name)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", type=Path, required=True, help="'grip policy train' run folder")
    ap.add_argument("--data", type=Path, default=None, help="its dataset (categories)")
    ap.add_argument("--window", type=int, default=20, help="rollouts of the moving average")
    ap.add_argument("--fit", type=int, default=100, help="rollouts of the projection's fit")
    ap.add_argument("--target", type=float, default=0.95, help="success rate to project to")
    ap.add_argument("--png", type=Path, default=None)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)

    state = json.loads((args.run / "checkpoint" / "state.json").read_text())
    hist = state["history"]
    steps = np.array([h["timesteps"] for h in hist], float)
    succ = np.array([h.get("success_rate", np.nan) for h in hist], float)
    mpjpe = np.array([h.get("mpjpe_mm", np.nan) for h in hist], float)
    eplen = np.array([h.get("ep_len", np.nan) for h in hist], float)
    stage = [h["stage"] for h in hist]
    wall = float(state["wall_s"])
    w = args.window
    out: dict = {"run": str(args.run), "decisions": int(steps[-1]), "wall_s": wall,
                 "decisions_per_hour": steps[-1] / wall * 3600.0, "stages": {}}  # fmt: skip
    for st in dict.fromkeys(stage):
        idx = np.array([s == st for s in stage])
        sm = _smooth(np.nan_to_num(succ[idx]), args.window)
        out["stages"][st] = {"decisions": [float(steps[idx][0]), float(steps[idx][-1])],
                             "success_last": float(sm[-1]),
                             "mpjpe_mm_last": float(_smooth(mpjpe[idx], w)[-1]),
                             "ep_len_last": float(_smooth(eplen[idx], w)[-1])}  # fmt: skip
    # projection on the current stage
    cur = np.array([s == stage[-1] for s in stage])
    sm = _smooth(np.nan_to_num(succ[cur]), args.window)[-args.fit :]
    xs = np.log(steps[cur][-args.fit :])
    proj = None
    if len(sm) >= 10:
        slope, icpt = np.polyfit(xs, sm, 1)
        if slope > 0:
            need = math.exp((args.target - icpt) / slope)
            proj = {"slope_per_log_decision": float(slope), "decisions_to_target": need,
                    "hours_at_this_rate": need / out["decisions_per_hour"]}  # fmt: skip
        else:
            proj = {"slope_per_log_decision": float(slope), "decisions_to_target": None}
    out["projection"] = proj
    # per category, from the miner's decayed counts
    mining = state.get("mining")
    if mining and args.data is not None:
        cats = _categories(args.data)
        ep, fa = defaultdict(float), defaultdict(float)
        for name, e, f in zip(mining["names"], mining["episodes"], mining["fails"], strict=True):
            c = cats.get(_clip_id(name), "unknown")
            ep[c] += e
            fa[c] += f
        out["categories"] = {c: {"episodes": ep[c], "failure_rate": fa[c] / ep[c]}
                             for c in sorted(ep, key=lambda c: -ep[c]) if ep[c] > 0}  # fmt: skip
    print(f"{out['decisions']:,} decisions in {wall / 3600:.2f} h "
          f"({out['decisions_per_hour'] / 1e6:.2f} M/h)")  # fmt: skip
    for st, v in out["stages"].items():
        print(f"{st}: success {v['success_last']:.3f}, MPJPE {v['mpjpe_mm_last']:.1f} mm, "
              f"episode {v['ep_len_last']:.0f} decisions (last {w} rollouts)")  # fmt: skip
    if proj and proj.get("decisions_to_target"):
        print(f"projection: {args.target:.0%} training success after "
              f"{proj['decisions_to_target']:.3g} decisions, {proj['hours_at_this_rate']:.0f} h "
              "at this rate (a log-linear extrapolation of the current stage)")  # fmt: skip
    for c, v in (out.get("categories") or {}).items():
        print(f"  {c:12s} episodes {v['episodes']:8.1f}  failure rate {v['failure_rate']:.2f}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=1))
    if args.png:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, 3, figsize=(14, 3.8), constrained_layout=True)
        for st in dict.fromkeys(stage):
            idx = np.array([s == st for s in stage])
            x = steps[idx] / 1e6
            for ax, y in zip(axes, (succ, mpjpe, eplen), strict=True):
                ax.plot(x, _smooth(np.nan_to_num(y[idx]), args.window), label=st)
        for ax, lab in zip(axes, ("training success rate", "MPJPE vs reference (mm)",
                                  "episode length (decisions)"), strict=True):  # fmt: skip
            ax.set_xlabel("decisions (M)")
            ax.set_ylabel(lab)
            ax.grid(alpha=0.3)
        axes[0].legend()
        fig.savefig(args.png, dpi=100)
        plt.close(fig)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
