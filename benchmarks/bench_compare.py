"""Two ``grip bench`` folders of the same segments side by side, per motion category.

Usage::

    .venv/bin/python benchmarks/bench_compare.py BEFORE AFTER [--method grip] [--json PATH]

For each category (and all segments): the method's MPJPE in BEFORE and AFTER, the
kinematics-only MPJPE (BEFORE's ``kinematics`` rows, else AFTER's; n/a without either), the
events (falls, with ``--lost-gap`` the lost recoveries among them), the segments without any
event (the bench's success) and those without a fall proper (events that are not lost
recoveries). Segments are matched by name; a segment missing or failed in either folder is left
out and counted. Only the two ``segments.csv`` files are read (a folder or the file itself).

``--pose-by-events`` prints instead, for BEFORE and AFTER, the method's pose errors (PEL-MPJPE,
MPJRE) and the kinematics-only ones on the same segments, over the segments without any event
and over those with one or more: is the pose worse than the estimate only where it falls? With
``--paired`` both folders are split alike: the segments without an event (fall or lost) in
either folder, and the other segments of both: the same segments on both sides.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from collections import defaultdict
from pathlib import Path


def _rows(folder: Path, method: str) -> dict[str, dict]:
    path = folder if folder.suffix == ".csv" else folder / "segments.csv"
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        raise SystemExit(f"{path}: cannot read ({e}); give 'grip bench' output folders") from e
    return {r["segment"]: r for r in rows if r.get("method") == method and r.get("status") == "ok"}


def _num(row: dict | None, key: str) -> float:
    try:
        return float(row[key]) if row is not None and row.get(key) not in (None, "") else math.nan
    except ValueError:
        return math.nan


def _count(row: dict, key: str) -> int:
    """An event count of a row; 0 where the column is empty or absent (``lost`` before it
    existed)."""
    v = _num(row, key)
    return 0 if math.isnan(v) else int(v)


def _mean(xs: list[float]) -> float:
    xs = [x for x in xs if not math.isnan(x)]
    return sum(xs) / len(xs) if xs else math.nan


def compare(before: Path, after: Path, method: str = "grip") -> dict:
    """``{"categories": {category | "all": {...}}, "unmatched": n}`` (keys as the table's)."""
    a, b = _rows(before, method), _rows(after, method)
    kin = _rows(before, "kinematics") or _rows(after, "kinematics")
    both = [s for s in a if s in b]
    by_cat: dict[str, list[str]] = defaultdict(list)
    for s in both:
        by_cat[a[s]["category"]].append(s)
        by_cat["all"].append(s)
    out = {}
    for cat, segs in sorted(by_cat.items(), key=lambda kv: (kv[0] == "all", kv[0])):
        ev = lambda rows, s: _count(rows[s], "falls")  # noqa: E731
        lost = lambda rows, s: _count(rows[s], "lost")  # noqa: E731
        out[cat] = {
            "segments": len(segs),
            "mpjpe_before": _mean([_num(a[s], "MPJPE_mm") for s in segs]),
            "mpjpe_after": _mean([_num(b[s], "MPJPE_mm") for s in segs]),
            "mpjpe_kinematics": _mean([_num(kin.get(s), "MPJPE_mm") for s in segs]),
            "events_before": sum(ev(a, s) for s in segs),
            "events_after": sum(ev(b, s) for s in segs),
            "lost_after": sum(lost(b, s) for s in segs),
            "no_event_before": sum(ev(a, s) == 0 for s in segs),
            "no_event_after": sum(ev(b, s) == 0 for s in segs),
            "no_fall_before": sum(ev(a, s) - lost(a, s) == 0 for s in segs),
            "no_fall_after": sum(ev(b, s) - lost(b, s) == 0 for s in segs),
        }
    return {"categories": out, "unmatched": len(set(a) ^ set(b))}


def pose_by_events(folder: Path, method: str = "grip", calm: set[str] | None = None) -> dict:
    """``{"no event" | "events": {"segments", "pel_mpjpe", "mpjre", "kin_pel_mpjpe",
    "kin_mpjre"}}``: the method's mean pose errors and the kinematics-only ones on the same
    segments, split by whether the method had any event (fall) in the segment, or, with
    ``calm``, by whether the segment is one of those (the rest of ``calm``'s folder pair:
    :func:`calm_in_both`)."""
    rows, kin = _rows(folder, method), _rows(folder, "kinematics")
    if calm is None:
        split = {s: _count(r, "falls") == 0 for s, r in rows.items()}
    else:
        split = {s: s in calm for s in rows}
    out = {}
    for name, keep in (("no event", True), ("events", False)):
        segs = [s for s in rows if split[s] == keep]
        out[name] = {
            "segments": len(segs),
            "pel_mpjpe": _mean([_num(rows[s], "PEL_MPJPE_mm") for s in segs]),
            "mpjre": _mean([_num(rows[s], "MPJRE_deg") for s in segs]),
            "kin_pel_mpjpe": _mean([_num(kin.get(s), "PEL_MPJPE_mm") for s in segs]),
            "kin_mpjre": _mean([_num(kin.get(s), "MPJRE_deg") for s in segs]),
        }
    return out


def calm_in_both(before: Path, after: Path, method: str = "grip") -> tuple[set[str], set[str]]:
    """The segments of both folders without any event (neither a fall nor a lost recovery) in
    either, and the segments of both folders."""
    a, b = _rows(before, method), _rows(after, method)
    both = set(a) & set(b)
    quiet = lambda r: _count(r, "falls") == 0 and _count(r, "lost") == 0  # noqa: E731
    return {s for s in both if quiet(a[s]) and quiet(b[s])}, both


def pose_table(results: dict[str, dict]) -> str:
    lines = ["| folder | segments | PEL-MPJPE (mm) | MPJRE (deg) | kinematics only: PEL-MPJPE / "
             "MPJRE |", "|---|---|---:|---:|---|"]  # fmt: skip
    f = lambda x, d=0: "n/a" if math.isnan(x) else f"{x:.{d}f}"  # noqa: E731
    for folder, res in results.items():
        for name, r in res.items():
            lines.append(f"| {folder} | {name}: {r['segments']} | {f(r['pel_mpjpe'])} | "
                         f"{f(r['mpjre'], 1)} | {f(r['kin_pel_mpjpe'])} / {f(r['kin_mpjre'], 1)} |")
    return "\n".join(lines)


def table(res: dict) -> str:
    head = ("| category | segments | MPJPE before | MPJPE after | kinematics only | events "
            "(lost) | no event | no fall |")  # fmt: skip
    lines = [head, "|---|---:|---:|---:|---:|---|---|---|"]
    f = lambda x: "n/a" if math.isnan(x) else f"{x:.0f}"  # noqa: E731
    for cat, r in res["categories"].items():
        lines.append(f"| {cat} | {r['segments']} | {f(r['mpjpe_before'])} | {f(r['mpjpe_after'])} "
                     f"| {f(r['mpjpe_kinematics'])} | {r['events_before']} -> {r['events_after']}"
                     f" ({r['lost_after']}) | {r['no_event_before']} -> {r['no_event_after']} | "
                     f"{r['no_fall_before']} -> {r['no_fall_after']} |")  # fmt: skip
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--method", default="grip", help="the bench label to compare (default grip)")
    ap.add_argument("--json", type=Path, help="also write the numbers here")
    ap.add_argument("--pose-by-events", action="store_true",
                    help="pose errors of each folder over segments without and with events")
    ap.add_argument("--paired", action="store_true",
                    help="with --pose-by-events: the same segments in both folders (without an "
                    "event in either, and the rest of those in both)")  # fmt: skip
    args = ap.parse_args(argv)
    if args.pose_by_events:
        calm, both = calm_in_both(args.before, args.after, args.method) if args.paired else \
            (None, None)  # fmt: skip
        res = {}
        for d in (args.before, args.after):
            r = pose_by_events(d, args.method, calm)
            if both is not None:  # (the events row over the segments of both folders only)
                r["events"] = pose_by_events(d, args.method, both - calm)["no event"]
            res[str(d)] = r
        if not any(r["no event"]["segments"] + r["events"]["segments"] for r in res.values()):
            print(f"no segment of method {args.method!r}", file=sys.stderr)
            return 1
        print(pose_table(res))
        if args.json:
            args.json.write_text(json.dumps(res, indent=1) + "\n")
        return 0
    res = compare(args.before, args.after, args.method)
    if not res["categories"]:
        print(f"no segment of method {args.method!r} in both folders", file=sys.stderr)
        return 1
    print(table(res))
    if res["unmatched"]:
        print(f"({res['unmatched']} segment(s) in only one folder left out)")
    if args.json:
        args.json.write_text(json.dumps(res, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
