"""Would the gate tell the motions apart better from a second of the wearables than from one frame?

The gate of ``grip policy combine --gate`` classifies each frame's sensor features alone. On the
test people it sends only a third of the sideways-walking frames to their controller
(docs/teacher_student.md § R2 measured). This benchmark fits the same gate
(:func:`policies.gate.fit_gate`) with causal context (``window``: each feature's mean and
standard deviation over the last ``W`` frames, the ``sensor_context`` observation at run time),
and prints the routes on the train and the test split for each window, without simulation:

    python benchmarks/gate_context.py --data DATA --gate walk-back,walk-side --windows 1 30 60 \
        [--json F]

``W = 1`` is the frame alone (``grip policy combine --gate-window 1``).
"""

from __future__ import annotations

import argparse
import json

from grip.cli.recordings import kin_checkpoint
from grip.kinematics.dataset import load_split_sequences
from grip.kinematics.inference import KinematicsEstimator
from policies.gate import fit_gate, route_counts


def family_shares(gate, xs, cats) -> dict[str, float]:
    """Per category, the share of its frames routed to its own trained route."""
    return {c: float(n[gate.route_of(c)] / n.sum())
            for c, n in route_counts(gate, xs, cats).items()}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--data", required=True, help="dataset folder (grip data build)")
    ap.add_argument("--gate", action="append", required=True,
                    help="category globs of one family (repeatable, as in grip policy combine)")
    ap.add_argument("--windows", type=int, nargs="+", default=[1, 30, 60],
                    help="context windows in frames (1: the frame alone)")
    ap.add_argument("--steps", type=int, default=3000, help="gate training steps")
    ap.add_argument("--kin", default=None, help="KinematicsNet whose input features to use")
    ap.add_argument("--json", default=None, help="write the shares here")
    args = ap.parse_args()
    fams = [tuple(c.strip() for c in g.split(",") if c.strip()) for g in args.gate]
    feats = KinematicsEstimator.from_checkpoint(kin_checkpoint(args.kin)).cfg.features
    train = load_split_sequences(args.data, "train", feats)
    test = load_split_sequences(args.data, "test", feats)
    out: dict[str, dict] = {}
    for w in args.windows:
        tr, te = [s.x for s in train], [s.x for s in test]
        gate, _ = fit_gate(tr, [s.category for s in train], fams, steps=args.steps, window=w)
        out[str(w)] = {"train": family_shares(gate, tr, [s.category for s in train]),
                       "test": family_shares(gate, te, [s.category for s in test])}  # fmt: skip
        print(f"\nwindow {w} frames: share of each category's frames on its trained route")
        print("| category | train | test |\n|---|---:|---:|")
        shares = out[str(w)]
        for c, v in shares["test"].items():
            print(f"| {c} | {100 * shares['train'].get(c, float('nan')):.1f} | {100 * v:.1f} |")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"families": [list(f) for f in fams], "windows": out}, f, indent=1)


if __name__ == "__main__":
    main()
