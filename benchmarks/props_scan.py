"""Props inferred from the shared motion clips (prism_tools/synth/props.py), clip by clip.

Retargets each clip onto the default body, infers the boxes it stands or sits on and prints one
line per clip (kind, top height, top extent, frames supported) and a summary per source. Clips
are all of a source's clips, or a seeded sample of N per source.

    python benchmarks/props_scan.py --sources cmu                     # every CMU clip
    python benchmarks/props_scan.py --per-source 40 --seed 0 --json props.json
"""

from __future__ import annotations

import argparse
import json
import random
import sys
from pathlib import Path

SOURCES = ("bandai_namco/dataset-1", "bandai_namco/dataset-2", "cmu", "deepmimic", "hdm05")


def scan(motions: Path, sources: list[str], per_source: int, seed: int) -> dict:
    """``{"clips": [{clip, source, props}], "sources": {source: {clips, with_props, steps,
    seats}}}``."""
    import numpy as np

    from grip.motion.catalog import find_clips, load_clip
    from grip.motion.retarget import retarget
    from prism_tools.synth.props import infer_props

    refs = find_clips(motions)
    rng = random.Random(seed)
    out: dict = {"clips": [], "sources": {}}
    for source in sources:
        mine = [r for r in refs if r.clip_id.startswith(source + ("/" if "/" not in source
                                                                   else "_"))]  # fmt: skip
        if per_source and len(mine) > per_source:
            mine = rng.sample(mine, per_source)
        summary = {"clips": 0, "with_props": 0, "steps": 0, "seats": 0}
        for ref in mine:
            motion = retarget(load_clip(ref))
            body = motion.body_model()
            g, p = motion.fk(body)
            props = infer_props(g, p, body, motion.fps)
            rows = [{"kind": q.kind, "height_m": round(q.height_m, 3),
                     "extent_m": np.round(q.hi - q.lo, 2).tolist(), "frames": q.frames}
                    for q in props]  # fmt: skip
            out["clips"].append({"clip": ref.clip_id, "source": source, "props": rows})
            summary["clips"] += 1
            summary["with_props"] += bool(rows)
            summary["steps"] += sum(r["kind"] == "step" for r in rows)
            summary["seats"] += sum(r["kind"] == "seat" for r in rows)
            text = ", ".join(f"{r['kind']} {r['height_m']:.2f} m" for r in rows) or "-"
            print(f"{ref.clip_id}: {text}", flush=True)
        out["sources"][source] = summary
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--motions", type=Path, default=None,
                    help="folder of motion clips (default: ../shared/data/motions)")  # fmt: skip
    ap.add_argument("--sources", nargs="+", default=list(SOURCES), choices=SOURCES)
    ap.add_argument("--per-source", type=int, default=0, help="sample N clips per source (0: all)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    from grip.cli.paths import default_motions_dir

    motions = args.motions or default_motions_dir()
    if motions is None or not Path(motions).is_dir():
        print("no motion folder: give --motions", file=sys.stderr)
        return 2
    res = scan(Path(motions), args.sources, args.per_source, args.seed)
    print("\n| source | clips | with props | steps | seats |\n|---|---:|---:|---:|---:|")
    for name, s in res["sources"].items():
        print(f"| {name} | {s['clips']} | {s['with_props']} | {s['steps']} | {s['seats']} |")
    if args.json:
        args.json.write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
