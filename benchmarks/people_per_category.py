"""People (split groups) per motion category of a motion folder, before and after the files added
on 2026-12-04 (issue 49).

Usage::

    .venv/bin/python benchmarks/people_per_category.py [FOLDER] [--json PATH]

FOLDER defaults to the shared motions (``../shared/data/motions`` beside the checkout). A clip's
person is its split group (:func:`grip.motion.catalog.clip_group`: the performer where the source
names one, else Bandai Namco's dataset and style, else the clip itself) and its category comes
from ``configs/categories.toml``. *Before* leaves out what was added on 2026-12-04: the clips
listed in the "Added 2026-12-04" section of ``cmu/SOURCE_AND_LICENSE.md``, DeepMimic's ``sie_*``
clips and the whole ``ase_reallusion`` folder; *after* is every clip. Only the catalog is read
(file names, ``clips.csv``, label files; no clip is loaded): about a second. Every clip counts,
also the few too short to give a training sequence (``grip data info DIR`` counts people with
sequences, per split). *Named* people are the groups of clips whose performer the source names
(HDM05 actors, CMU subjects, a ``clips.csv`` ``person`` column); the others are Bandai Namco
styles (its clips name no actor) and single DeepMimic clips (unnamed performers), which the
split treats as people but which may share a performer.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

from grip.motion.catalog import ClipRef, find_clips, load_category_map

REPO = Path(__file__).resolve().parents[1]
DEFAULT_ROOT = REPO.parent / "shared" / "data" / "motions"
ADDED_SECTION = "## Added 2026-12-04"
_CLIP_CELL = re.compile(r"^\|\s*([^|\s]+\.(?:bvh|amc))\s*\|")


def added_on_2026_12_04(root: Path) -> set[Path]:
    """The clip files added on 2026-12-04 (resolved paths): the CMU clips listed in that section
    of ``cmu/SOURCE_AND_LICENSE.md``, DeepMimic's ``sie_*`` clips, ``ase_reallusion/*.npy``.

    Raises:
        SystemExit: The CMU notes or their section are missing.
    """
    notes = root / "cmu" / "SOURCE_AND_LICENSE.md"
    lines = notes.read_text(encoding="utf-8").splitlines() if notes.is_file() else []
    if ADDED_SECTION not in [ln.split(":")[0] for ln in lines]:
        raise SystemExit(f"{notes}: no section {ADDED_SECTION!r}")
    start = next(i for i, ln in enumerate(lines) if ln.startswith(ADDED_SECTION))
    added: set[Path] = set()
    for ln in lines[start + 1 :]:
        if ln.startswith("## "):
            break
        m = _CLIP_CELL.match(ln)
        if m:
            added.add((root / "cmu" / m.group(1)).resolve())
    added |= {p.resolve() for p in (root / "deepmimic").glob("sie_*")}
    added |= {p.resolve() for p in (root / "ase_reallusion").glob("*.npy")}
    return added


def people_by_category(refs: list[ClipRef], named: bool = False) -> dict[str, list[str]]:
    """Category -> the sorted split groups with a clip of it (``named``: only the groups of
    clips whose performer the source names)."""
    out: dict[str, set[str]] = {}
    for r in refs:
        if r.person or not named:
            out.setdefault(r.category, set()).add(r.group)
    return {c: sorted(g) for c, g in sorted(out.items())}


def compare(root: Path) -> dict:
    """``before``/``after`` (:func:`people_by_category`), ``named_before``/``named_after`` (its
    named performers), ``clips`` (category -> before/after counts) and ``added_clips``."""
    refs = find_clips(root, load_category_map(REPO / "configs" / "categories.toml"))
    added = added_on_2026_12_04(root)
    before = [r for r in refs if r.path.resolve() not in added]
    clips: dict[str, dict[str, int]] = {}
    for part, rows in (("before", before), ("after", refs)):
        for r in rows:
            clips.setdefault(r.category, {"before": 0, "after": 0})[part] += 1
    return {"root": str(root), "added_clips": len(refs) - len(before),
            "before": people_by_category(before), "after": people_by_category(refs),
            "named_before": people_by_category(before, named=True),
            "named_after": people_by_category(refs, named=True),
            "clips": dict(sorted(clips.items()))}  # fmt: skip


def format_table(res: dict) -> str:
    """Markdown: people before and after per category, and who was added."""
    lines = [f"{res['added_clips']} clips added on 2026-12-04 under {res['root']}", "",
             "| category | people before | people after | named before | named after | "
             "clips before | clips after | people added |",
             "|---|---:|---:|---:|---:|---:|---:|---|"]  # fmt: skip
    keys = ("before", "after", "named_before", "named_after")
    total: dict[str, set[str]] = {k: set() for k in keys}
    for cat in sorted(set(res["before"]) | set(res["after"])):
        got = {k: res[k].get(cat, []) for k in keys}
        for k in keys:
            total[k] |= set(got[k])
        new = ", ".join(sorted(set(got["after"]) - set(got["before"]))) or "-"
        n = res["clips"][cat]
        lines.append(f"| {cat} | " + " | ".join(str(len(got[k])) for k in keys)
                     + f" | {n['before']} | {n['after']} | {new} |")  # fmt: skip
    lines.append("| **all** | " + " | ".join(str(len(total[k])) for k in keys)
                 + f" | {sum(n['before'] for n in res['clips'].values())} | "
                 f"{sum(n['after'] for n in res['clips'].values())} | |")  # fmt: skip
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("folder", nargs="?", type=Path, default=DEFAULT_ROOT)
    p.add_argument("--json", type=Path, help="also write the people per category as JSON")
    args = p.parse_args(argv)
    if not args.folder.is_dir():
        print(f"{args.folder}: not a folder", file=sys.stderr)
        return 2
    res = compare(args.folder)
    print(format_table(res))
    if args.json:
        args.json.write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
