"""Learning curve and per-category failures of a ``grip policy train`` run, read from its
checkpoint (no simulation): what docs/teacher_student.md reports for the privileged tracker.

* The curve: each rollout's training success rate (episodes that reached their length limit
  without a fall or the distance termination), MPJPE against the reference and episode length
  over the decisions trained, smoothed over ``--window`` rollouts, one colour per stage.
* Per category: the hard-clip miner's decayed episode and failure counts (``state.json``'s
  ``mining``: the last few hundred rollouts), summed over each category's clips (with
  ``--by-source``, over each category's clips of one source).
* Per category over time: training success of the episodes of each category that ended in
  each block of ``--block`` decisions (rows' ``by_category`` counts, recorded by runs since
  2026-12-04), with each rising category's log-linear projection to ``--target``.
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


def _categories(data: Path, by_source: bool = False) -> dict[str, str]:
    """Clip id -> category from a dataset's manifest; with ``by_source``, ``"category
    source"``, the source being the clip's split group without its last part (the folder of
    people or styles: ``bandai_namco/dataset-1``, ``cmu``, ``hdm05``)."""
    man = json.loads((data / "manifest.json").read_text())
    out = {}
    for c in man["clips"]:
        cat = c.get("category") or "unknown"
        if by_source:
            cat = f"{cat} {str(c.get('group') or c['clip_id']).rsplit('/', 1)[0]}"
        out[c["clip_id"]] = cat
    return out


def _clip_id(name: str) -> str:
    """``synthetic_<source>/<clip>[@x<factor>]_seqNNN[#k]`` (a reference clip; ``@x`` a clip
    played faster by ``speed_factors``, its category unchanged) -> ``<source>/<clip>``."""
    name = re.sub(r"#\d+$", "", name).removeprefix("synthetic_")
    return re.sub(r"(@x[0-9.]+)?_seq\d+$", "", name)


def _loglinear_to(log_x, y, target: float) -> tuple[float, float | None]:
    """The slope of a straight line through ``y`` against ``log_x``, and the decisions where
    it reaches ``target``: None for a line that does not rise (or reaches it only after
    1e15 decisions)."""
    slope, icpt = np.polyfit(log_x, y, 1)
    if slope <= 1e-6 or (target - icpt) / slope > math.log(1e15):
        return float(slope), None
    return float(slope), float(math.exp((target - icpt) / slope))


def _category_curves(hist: list[dict], block: int, target: float,
                     min_episodes: int) -> dict[str, dict]:  # fmt: skip
    """Training success per category in blocks of ``block`` decisions, from the rows' episode
    counts (``by_category``: recorded by runs since 2026-12-04), and where a category's
    success rises, the decisions its log-linear fit reaches ``target`` at."""
    rows = [h for h in hist if "by_category" in h]
    counts: dict[str, dict[int, list[int]]] = defaultdict(dict)
    for h in rows:
        b = int(h["timesteps"]) // block
        for c, (n, f) in h["by_category"].items():
            cell = counts[c].setdefault(b, [0, 0])
            cell[0] += n
            cell[1] += f
    out = {}
    for c in sorted(counts, key=lambda c: -sum(v[0] for v in counts[c].values())):
        bs = sorted(b for b, v in counts[c].items() if v[0] >= min_episodes)
        if not bs:
            continue
        x = [(b + 0.5) * block for b in bs]
        succ = [1.0 - counts[c][b][1] / counts[c][b][0] for b in bs]
        need = _loglinear_to(np.log(x), succ, target)[1] if len(bs) >= 3 else None
        out[c] = {"decisions": x, "episodes": [counts[c][b][0] for b in bs], "success": succ,
                  "decisions_to_target": need}  # fmt: skip
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", type=Path, required=True, help="'grip policy train' run folder")
    ap.add_argument("--data", type=Path, default=None, help="its dataset (categories)")
    ap.add_argument("--window", type=int, default=20, help="rollouts of the moving average")
    ap.add_argument("--fit", type=int, default=100, help="rollouts of the projection's fit")
    ap.add_argument("--target", type=float, default=0.95, help="success rate to project to")
    ap.add_argument("--block", type=int, default=250_000,
                    help="decisions per block of the per-category curves")
    ap.add_argument("--min-episodes", type=int, default=20,
                    help="episodes a block needs to count in a category's curve")
    ap.add_argument("--by-source", action="store_true",
                    help="the miner's failure rates per category and source")
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
        slope, need = _loglinear_to(xs, sm, args.target)
        proj = {"slope_per_log_decision": slope, "decisions_to_target": need}
        if need is not None:
            proj["hours_at_this_rate"] = need / out["decisions_per_hour"]
    out["projection"] = proj
    # per category, from the miner's decayed counts
    mining = state.get("mining")
    if mining and args.data is not None:
        cats = _categories(args.data, args.by_source)
        ep, fa = defaultdict(float), defaultdict(float)
        for name, e, f in zip(mining["names"], mining["episodes"], mining["fails"], strict=True):
            c = cats.get(_clip_id(name), "unknown")
            ep[c] += e
            fa[c] += f
        out["categories"] = {c: {"episodes": ep[c], "failure_rate": fa[c] / ep[c]}
                             for c in sorted(ep, key=lambda c: -ep[c]) if ep[c] > 0}  # fmt: skip
    out["category_curves"] = _category_curves(hist, args.block, args.target,
                                              args.min_episodes)
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
    if out["category_curves"]:
        print(f"training success per category, blocks of {args.block / 1e6:g} M decisions "
              "(episodes that ended in the block):")  # fmt: skip
        for c, v in out["category_curves"].items():
            cells = " ".join(f"{s_:.2f}" for s_ in v["success"])
            need = v["decisions_to_target"]
            tail = f"  -> {args.target:.0%} at {need:.3g}" if need else "  (not rising)"
            print(f"  {c:12s} {cells}{tail}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=1))
    if args.png:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        curves = out["category_curves"]
        fig, axes = plt.subplots(1, 4 if curves else 3, figsize=(19 if curves else 14, 3.8),
                                 constrained_layout=True)  # fmt: skip
        if curves:
            for c, v in curves.items():
                axes[3].plot(np.array(v["decisions"]) / 1e6, v["success"], marker=".", label=c)
            axes[3].set_xlabel("decisions (M)")
            axes[3].set_ylabel(f"success per category ({args.block / 1e6:g} M blocks)")
            axes[3].grid(alpha=0.3)
            axes[3].legend(fontsize=6, ncol=2)
        for st in dict.fromkeys(stage):
            idx = np.array([s == st for s in stage])
            x = steps[idx] / 1e6
            for ax, y in zip(axes[:3], (succ, mpjpe, eplen), strict=True):
                ax.plot(x, _smooth(np.nan_to_num(y[idx]), args.window), label=st)
        for ax, lab in zip(axes[:3], ("training success rate", "MPJPE vs reference (mm)",
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
