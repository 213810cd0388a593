"""The humanoid's speed in one ``pace_cause.py`` run over its speed in another, walk by walk.

Medians over the walks kept compare different sets of walks when the two runs keep different
ones; this pairs them: over the segments kept in both runs (the same segment ids, the same
reference), the ratio of the humanoid's path speed in run B to that in run A. With A the run
as it is and B the same policy with ``--root-speed-scale 1.1``, the ratio is the controller's
response to a followed root 10 % faster (docs/pace.md § E4).

    python benchmarks/pace_paired.py A.json B.json [--reference estimate] [--json F]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def paired_speed_ratio(a: dict, b: dict, reference: str = "estimate") -> dict:
    """``{"walks", "median", "mean", "q25", "q75"}`` of the per-segment ratios
    ``sim_speed_mps`` of ``b`` over that of ``a`` (two ``pace_cause.py`` outputs) over the
    segments neither run lost to a fall; the statistics are ``None`` when none is shared."""
    rows = [{r["segment"]: r for r in d["by_reference"][reference]["rows"]} for d in (a, b)]
    both = [k for k in rows[0] if k in rows[1] and not rows[0][k]["fell"]
            and not rows[1][k]["fell"]]  # fmt: skip
    r = np.array([rows[1][k]["sim_speed_mps"] / rows[0][k]["sim_speed_mps"] for k in both])
    if not len(r):
        return {"walks": 0, "median": None, "mean": None, "q25": None, "q75": None}
    return {"walks": len(r), "median": float(np.median(r)), "mean": float(r.mean()),
            "q25": float(np.quantile(r, 0.25)), "q75": float(np.quantile(r, 0.75))}  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a", type=Path, help="pace_cause.py output: the baseline run")
    ap.add_argument("b", type=Path, help="pace_cause.py output: the changed run")
    ap.add_argument("--reference", default="estimate")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    a, b = (json.loads(p.read_text()) for p in (args.a, args.b))
    out = {"a": str(args.a), "b": str(args.b), "reference": args.reference,
           **paired_speed_ratio(a, b, args.reference)}  # fmt: skip
    if args.json is not None:
        args.json.write_text(json.dumps(out, indent=1))
    print(json.dumps(out))


if __name__ == "__main__":
    main()
