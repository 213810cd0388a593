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

import numpy as np

SOURCES = ("bandai_namco/dataset-1", "bandai_namco/dataset-2", "cmu", "deepmimic", "hdm05")


def body_points(g, p, body):
    """``(T, K, 3)`` the points the props rule keeps out of every prop: limb and trunk shapes'
    lowest points, the soles' outlines and the insole cells."""
    import numpy as np

    from grip.core.fk import sole_points
    from prism_tools.synth.insole import body_contact_points, insole_cell_positions

    t = len(g)
    return np.concatenate([body_contact_points(g, p, body)[0],
                           sole_points(g, p, body).reshape(t, -1, 3),
                           insole_cell_positions(g, p, body).reshape(t, -1, 3)],
                          axis=1)  # fmt: skip


def inside_share(prop, pts) -> float:
    """Share of frames where some body point lies inside ``prop``: over its top, more than
    ``INSIDE_M`` below the top and, for a slab, with its shape reaching the slab (above its
    underside less ``REACH_M``)."""
    from prism_tools.synth.props import INSIDE_M, REACH_M

    z = pts[..., 2]
    floor = prop.bottom_m - REACH_M if prop.bottom_m > 0 else -np.inf
    inside = prop.contains(pts[..., :2]) & (z < prop.height_m - INSIDE_M) & (z > floor)
    return float(inside.any(axis=1).mean())


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
            pts = body_points(g, p, body)
            rows = [{"kind": q.kind, "height_m": round(q.height_m, 3),
                     "bottom_m": round(q.bottom_m, 3), "lo": np.round(q.lo, 2).tolist(),
                     "hi": np.round(q.hi, 2).tolist(),
                     "extent_m": np.round(q.hi - q.lo, 2).tolist(), "frames": q.frames,
                     "inside_share": round(inside_share(q, pts), 4)}
                    for q in props]  # fmt: skip
            out["clips"].append({"clip": ref.clip_id, "source": source, "props": rows})
            summary["clips"] += 1
            summary["with_props"] += bool(rows)
            summary["steps"] += sum(r["kind"] == "step" for r in rows)
            summary["seats"] += sum(r["kind"] == "seat" for r in rows)
            text = ", ".join(
                f"{r['kind']} {r['height_m']:.2f} m"
                + (f" (slab from {r['bottom_m']:.2f} m)" if r["bottom_m"] > 0 else "")
                + f" [{100 * r['inside_share']:.1f} % of frames with the body inside]"
                for r in rows) or "-"
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
