"""Retarget every clip of a motion folder and report foot sliding, penetration and contact.

Usage::

    .venv/bin/python benchmarks/retarget_quality.py [FOLDER] [--json out.json] [--workers N]
        [--set floor_percentile=20 --set fix_penetration=false] [--limit N]

FOLDER defaults to the shared motions (``../shared/data/motions`` beside the checkout). Prints one
Markdown table per dataset (the clip id's top folder) and one per category, then the total time.
Metric definitions: :mod:`grip.motion.quality`.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
import traceback
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from grip.core.runs import exit_with_parent
from grip.motion.catalog import ClipRef, find_clips, load_clip
from grip.motion.quality import foot_metrics, summarize
from grip.motion.retarget import RetargetConfig, retarget

DEFAULT_ROOT = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "motions"


def _parse_overrides(items: list[str]) -> RetargetConfig:
    fields = {f.name: f for f in dataclasses.fields(RetargetConfig)}
    kwargs: dict[str, object] = {}
    for item in items:
        key, _, raw = item.partition("=")
        if key not in fields:
            raise SystemExit(
                f"--set: unknown RetargetConfig field {key!r}; valid: {', '.join(fields)}"
            )
        low = raw.strip().lower()
        if low in ("none", "null"):
            kwargs[key] = None
        elif low in ("true", "false"):
            kwargs[key] = low == "true"
        else:
            try:
                kwargs[key] = float(raw)
            except ValueError:
                kwargs[key] = raw
    return RetargetConfig(**kwargs)  # type: ignore[arg-type]


def _one(args: tuple[ClipRef, RetargetConfig]) -> dict:
    ref, cfg = args
    t0 = time.perf_counter()
    try:
        motion = retarget(load_clip(ref), cfg=cfg)
        row = foot_metrics(motion)
        row["floor_from"] = motion.meta.get("floor_from")
        row["floor_tilt_deg"] = motion.meta.get("floor_tilt_deg")
        row["lift_max_m"] = motion.meta.get("penetration_lift_max_m")
    except Exception as exc:  # reported per clip, the run goes on
        row = {
            "name": ref.clip_id,
            "category": ref.category,
            "error": repr(exc),
            "trace": traceback.format_exc(limit=3),
        }
    row["dataset"] = ref.clip_id.split("/")[0]
    row["seconds"] = time.perf_counter() - t0
    return row


def _table(summary: dict[str, dict[str, float]], title: str) -> str:
    lines = [
        f"| {title} | clips | frames | FS m/s | FP mean mm | FP max mm | contact | float mm |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for group, s in summary.items():
        name = f"**{group}**" if group == "all" else group
        lines.append(
            f"| {name} | {s['clips']} | {s['frames']} | {s['fs_mps']:.3f} | "
            f"{s['fp_mean_mm']:.2f} | {s['fp_max_mm']:.1f} | {s['contact_fraction']:.2f} | "
            f"{s['float_mm']:.1f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("folder", nargs="?", default=str(DEFAULT_ROOT))
    parser.add_argument("--json", type=Path, help="write per-clip metrics and summaries here")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--limit", type=int, default=0, help="only the first N clips")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="RetargetConfig override, repeatable",
    )
    args = parser.parse_args(argv)
    cfg = _parse_overrides(args.set)
    refs = find_clips(args.folder)
    if args.limit:
        refs = refs[: args.limit]
    if not refs:
        print(f"no clips under {args.folder}", file=sys.stderr)
        return 1
    t0 = time.perf_counter()
    jobs = [(r, cfg) for r in refs]
    if args.workers > 1:
        with ProcessPoolExecutor(args.workers, initializer=exit_with_parent) as pool:
            rows = list(pool.map(_one, jobs, chunksize=4))
    else:
        rows = [_one(j) for j in jobs]
    wall = time.perf_counter() - t0
    ok = [r for r in rows if "error" not in r]
    bad = [r for r in rows if "error" in r]
    by_dataset = summarize(ok, by="dataset")
    by_category = summarize(ok, by="category")
    print(_table(by_dataset, "dataset"))
    print()
    print(_table(by_category, "category"))
    print()
    frames = sum(r["n_frames"] for r in ok)
    cpu = sum(r["seconds"] for r in rows)
    print(
        f"{len(ok)} clips retargeted, {len(bad)} failed, {frames} frames at {cfg.fps:g} Hz; "
        f"wall {wall:.1f} s with {args.workers} worker(s), {cpu:.1f} s of work "
        f"({cpu / max(len(rows), 1) * 1000:.0f} ms per clip)"
    )
    for r in bad:
        print(f"FAILED {r['name']}: {r['error']}", file=sys.stderr)
    if args.json:
        out = {
            "config": dataclasses.asdict(cfg),
            "wall_s": wall,
            "clips": rows,
            "by_dataset": by_dataset,
            "by_category": by_category,
        }
        args.json.parent.mkdir(parents=True, exist_ok=True)
        tmp = args.json.with_suffix(args.json.suffix + ".tmp")
        tmp.write_text(json.dumps(out, indent=1, default=_json_default), encoding="utf-8")
        os.replace(tmp, args.json)
    return 1 if bad else 0


def _json_default(obj: object) -> object:
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


if __name__ == "__main__":
    raise SystemExit(main())
