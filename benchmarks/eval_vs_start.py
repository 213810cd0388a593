"""``grip policy eval`` end to end, as a user runs it, against the same command of the code
before issue 32's work: the issue's "at least 3x faster than today on 2 cores".

Both run as separate processes, one after the other and in turns (``--rounds``), on the same
segments of the same dataset, with the shipped controller and KinematicsNet of each tree and
their own defaults (torch threads, workers) except what the command line below sets (the
JSON's ``same_assets`` says whether the two trees ship the same model files: they do for
d6d90de):

- ``before``: the tree of ``--before`` (default d6d90de, the last commit before issue 32's work:
  one segment after another), checked out with ``git worktree add --detach`` into a temporary
  folder (removed afterwards) unless ``--tree`` names one;
- ``current``: this checkout, with ``--batch`` and ``--workers``.

The wall time includes each process's start (imports, models, the workers' start), as a user
sees it. The aggregate metrics of both JSONs are compared: the controller, KinematicsNet and
the physics of the two trees may differ (the shipped assets, the foot-force read-out), so the
differences are reported, not required to be zero; ``benchmarks/eval_batch.py`` checks the
batched player against the sequential one of the same tree.

    python benchmarks/eval_vs_start.py --data data/person --segments 64 --segment-frames 300 \\
        --json docs/perf/eval_vs_start.json
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

_ROOT = Path(__file__).resolve().parents[1]
_START = "d6d90de"
_COMPARED = ("success_rate", "MPJPE_mm", "PA_MPJPE_mm", "FS_mps", "FP_mm", "vGRF_N",
             "kin_MPJPE_mm", "frames", "segments")  # fmt: skip


def _eval(tree: Path, args, extra: list[str], out: Path) -> float:
    """Wall seconds of ``grip policy eval`` of ``tree`` (its JSON to ``out``)."""
    cmd = [sys.executable, "-c", "from grip.cli.main import main; main()", "policy", "eval",
           "--data", str(args.data), "--split", args.split, "--segments", str(args.segments),
           "--segment-frames", str(args.segment_frames), "--json", str(out), *extra]  # fmt: skip
    env = dict(os.environ, PYTHONPATH=str(tree))
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"grip policy eval of {tree} failed ({proc.returncode}):\n"
                         f"{proc.stderr[-3000:]}")  # fmt: skip
    return wall


def _assets(tree: Path) -> dict[str, str]:
    """sha256 of the shipped controller and KinematicsNet of ``tree``."""
    return {name: hashlib.sha256((tree / "grip" / "assets" / name).read_bytes()).hexdigest()
            for name in ("policy_default.pt", "kinematics_default.pt")}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, required=True, help="dataset folder (grip data build)")
    ap.add_argument("--split", default="test")
    ap.add_argument("--segments", type=int, default=64)
    ap.add_argument("--segment-frames", type=int, default=300)
    ap.add_argument("--batch", type=int, default=16, help="--batch of the current command")
    ap.add_argument("--workers", type=int, default=2, help="--workers of the current command")
    ap.add_argument("--rounds", type=int, default=2, help="turns of the two commands")
    ap.add_argument("--before", default=_START,
                    help="commit of the reference (default: %(default)s)")
    ap.add_argument("--tree", type=Path, default=None,
                    help="an existing checkout of --before (default: a temporary worktree)")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    args.data = args.data.resolve()

    with tempfile.TemporaryDirectory(prefix="grip_eval_vs_start_") as tmp:
        tmp = Path(tmp)
        tree = args.tree
        if tree is None:
            tree = tmp / "before"
            subprocess.run(["git", "-C", str(_ROOT), "worktree", "add", "--detach", str(tree),
                            args.before], check=True, capture_output=True)  # fmt: skip
        try:
            same_assets = _assets(tree) == _assets(_ROOT)
            print("the two trees ship " + ("the same" if same_assets else "DIFFERENT") +
                  " controller and KinematicsNet files")  # fmt: skip
            wall = {"before": 0.0, "current": 0.0}
            runs = {"before": (tree, []),
                    "current": (_ROOT, ["--batch", str(args.batch), "--workers",
                                        str(args.workers)])}  # fmt: skip
            got = {}
            for r in range(args.rounds):
                for name, (root, extra) in runs.items():
                    out = tmp / f"{name}_{r}.json"
                    w = _eval(root, args, extra, out)
                    wall[name] += w
                    got[name] = json.loads(out.read_text())
                    print(f"round {r + 1}/{args.rounds} {name:8s} {w:7.2f} s", flush=True)
        finally:
            if args.tree is None:
                subprocess.run(["git", "-C", str(_ROOT), "worktree", "remove", "--force",
                                str(tree)], capture_output=True)  # fmt: skip
    speedup = wall["before"] / wall["current"]
    diff = {k: got["current"].get(k, float("nan")) - got["before"].get(k, float("nan"))
            for k in _COMPARED}  # fmt: skip
    out = {
        "data": str(args.data), "split": args.split, "segments": args.segments,
        "segment_frames": args.segment_frames, "batch": args.batch, "workers": args.workers,
        "rounds": args.rounds, "before": args.before, "cores": os.cpu_count(),
        "same_assets": same_assets, "wall_s": wall, "speedup": speedup, "metrics": got,
        "current_minus_before": diff,
    }  # fmt: skip
    print(f"current ({args.batch=}, {args.workers=}) is {speedup:.2f}x faster than "
          f"{args.before}, process starts included")
    for k, d in diff.items():
        print(f"  {k:14s} before {got['before'].get(k)!s:>22}  current "
              f"{got['current'].get(k)!s:>22}  diff {d:+.4g}")  # fmt: skip
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=1))
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
