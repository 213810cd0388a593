"""Summaries of a dataset folder: ours (with a manifest) or a folder of PRISM recordings."""

from __future__ import annotations

import os
from pathlib import Path

RECORDING_SUFFIXES = (".pkl", ".npz")


def folder_size_bytes(root: Path) -> int:
    """Total size of the files under ``root``, bytes."""
    total = 0
    for dirpath, _dirs, files in os.walk(root):
        for f in files:
            try:
                total += os.path.getsize(os.path.join(dirpath, f))
            except OSError:
                pass
    return total


def dataset_summary(root: str | os.PathLike, scan_limit: int | None = None) -> dict:
    """Counts of recordings, frames and categories.

    With a ``manifest.json`` (built by ``grip data build``) the summary comes from it and the
    split; otherwise every ``*.pkl``/``*.npz`` recording under ``root`` is loaded (safely) and
    counted, which is how a folder of real PRISM takes is inspected.

    Returns:
        A JSON-ready dict: ``recordings``, ``frames``, ``hours``, ``fps``, ``categories``
        (category -> {"recordings", "frames"}), ``splits`` (when known), ``clips_failed``,
        ``size_bytes`` and ``source`` ("manifest" or "scan"); a scan adds ``files`` (files
        tried), ``unreadable`` (``{"file", "error"}`` of each file refused: corrupt,
        hostile or above the input limits of :mod:`grip.core.limits`) and ``sensors_only``
        (recordings without ground truth: no ``smpl_params``).
    """
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: no such dataset folder")
    manifest = root / "manifest.json"
    if manifest.exists():
        try:
            return _summary_from_manifest(root, manifest)
        except (TypeError, AttributeError, KeyError) as e:  # valid JSON, wrong structure
            raise ValueError(f"{manifest}: corrupt manifest ({type(e).__name__}: {e})") from None
    return _summary_from_scan(root, scan_limit)


def _read_json(path: Path) -> dict:
    """A JSON object file, size/depth/integer digits bounded (:mod:`grip.core.limits`).

    Raises:
        ValueError: Unreadable, not JSON, above a limit, or not an object (names the file).
    """
    from grip.core.limits import active_limits, check_file_size, safe_json_loads

    limits = active_limits()
    try:
        check_file_size(path, limits)
        data = safe_json_loads(path.read_text(encoding="utf-8"), limits, path.name)
    except (OSError, ValueError) as e:
        raise ValueError(f"{path}: corrupt or unreadable ({type(e).__name__}: {e})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: corrupt (expected a JSON object, got {type(data).__name__})")
    return data


def _summary_from_manifest(root: Path, manifest_path: Path) -> dict:
    try:
        manifest = _read_json(manifest_path)
    except ValueError as e:
        raise ValueError(f"{manifest_path}: corrupt manifest ({e})") from e
    cats: dict[str, dict[str, int]] = {}
    n_rec = frames = 0
    failed = []
    clips_done = 0
    for c in manifest.get("clips", []):
        if c.get("status") != "done":
            failed.append({"clip_id": c.get("clip_id"), "error": c.get("error", "")})
            continue
        clips_done += 1
        entry = cats.setdefault(c.get("category", "unknown"), {"clips": 0, "recordings": 0,
                                                                "frames": 0})  # fmt: skip
        entry["clips"] += 1
        entry["recordings"] += len(c.get("sequences", []))
        entry["frames"] += int(sum(c.get("sequence_frames", [])))
        n_rec += len(c.get("sequences", []))
        frames += int(sum(c.get("sequence_frames", [])))
    done = [c for c in manifest.get("clips", []) if c.get("status") == "done"]
    synth = sum(int(c.get("synth_frames", 0)) for c in done)
    outside = sum(int(c.get("zmp_outside_frames", 0)) for c in done)
    summary = {
        "source": "manifest",
        "root": str(root),
        "clips": clips_done,
        "recordings": n_rec,
        "frames": frames,
        "fps": 100.0,
        "hours": frames / 100.0 / 3600.0,
        "categories": dict(sorted(cats.items())),
        "clips_failed": failed,
        "config": manifest.get("config", {}),
        "insole_zmp_outside_fraction": outside / synth if synth else None,
        "insole_zmp_outside_by_source": zmp_outside_by_source(done),
        "props": props_summary(done),
        "size_bytes": folder_size_bytes(root),
    }
    split_path = root / "split.json"
    if split_path.exists():
        try:
            split = _read_json(split_path)
            summary.update(_split_summary(split))
            summary["split_people"] = people_per_category(done, split)
        except (ValueError, TypeError, AttributeError):
            summary["splits"] = {"error": f"{split_path}: unreadable"}
    return summary


def clip_source(clip: dict) -> str:
    """The source of a manifest clip (:func:`prism_tools.chunking.clip_source` of its id and
    group): ``"hdm05/bd"`` -> ``"hdm05"``, as the split strata; without a group (a manifest
    built before groups existed) the clip id's top folder (``"cmu/02_01"`` -> ``"cmu"``)."""
    from prism_tools.chunking import clip_source as source_of

    return source_of(str(clip.get("clip_id") or "unknown"), str(clip.get("group") or ""))


def props_summary(clips: list[dict]) -> dict:
    """The props of the finished manifest clips (:func:`prism_tools.synth.props.infer_props`,
    recorded by the build): ``clips`` with props, ``props``, per source ``{"clips", "steps",
    "seats"}`` and up to 12 ``examples`` ``(clip id, "step 0.21 m, seat 0.66 m")``."""
    by_source: dict[str, dict] = {}
    examples = []
    with_props = n_props = 0
    for c in clips:
        props = c.get("props") or []
        if not props:
            continue
        with_props += 1
        n_props += len(props)
        e = by_source.setdefault(clip_source(c), {"clips": 0, "steps": 0, "seats": 0})
        e["clips"] += 1
        for p in props:
            e["seats" if p.get("kind") == "seat" else "steps"] += 1
        if len(examples) < 12:
            examples.append(
                (
                    c.get("clip_id"),
                    ", ".join(
                        f"{p.get('kind')} {float(p.get('height_m', 0.0)):.2f} m"
                        + (" (open underneath)" if float(p.get("bottom_m", 0.0)) > 0 else "")
                        for p in props
                    ),
                )
            )
    return {"clips": with_props, "props": n_props, "by_source": dict(sorted(by_source.items())),
            "examples": examples}  # fmt: skip


def zmp_outside_by_source(clips: list[dict]) -> dict[str, dict]:
    """Per source (:func:`clip_source`): ``clips``, ``synth_frames``, ``zmp_outside_frames`` and
    ``fraction`` (None without synthesised frames) of the finished manifest clips, sorted by
    source. A frame is outside when its ZMP lies more than
    :data:`prism_tools.synth.recording.ZMP_OUTSIDE_M` (3 cm) off the loaded insole cells."""
    out: dict[str, dict] = {}
    for c in clips:
        entry = out.setdefault(clip_source(c), {"clips": 0, "synth_frames": 0,
                                                "zmp_outside_frames": 0})  # fmt: skip
        entry["clips"] += 1
        entry["synth_frames"] += int(c.get("synth_frames", 0))
        entry["zmp_outside_frames"] += int(c.get("zmp_outside_frames", 0))
    for entry in out.values():
        n = entry["synth_frames"]
        entry["fraction"] = entry["zmp_outside_frames"] / n if n else None
    return dict(sorted(out.items()))


def people_per_category(clips: list[dict], split: dict) -> dict[str, dict[str, list[str]]]:
    """The people (split groups) per category on each side of a split.

    A clip's person is its manifest ``group``: its performer where the source names one, else
    the source's finest grouping (:func:`grip.motion.catalog.clip_group`; the clip id in
    manifests written before groups). It counts for the clip's category on the side that holds
    its sequences (``split.json``'s ``groups`` and ``members``; a split without ``members``
    names clips as groups). Clips without sequences count nowhere. Split by clip, one person can
    be on both sides.

    Args:
        clips: The manifest's clips.
        split: The ``split.json`` dict.

    Returns:
        ``category -> {"train": [people], "test": [people]}``, sorted; empty for a split that
        records no groups.
    """
    side_of: dict[str, str] = {}
    members = split.get("members")
    for part, names in (split.get("groups") or {}).items():
        for g in names:
            for clip_id in members.get(g, ()) if members is not None else (g,):
                side_of[clip_id] = part
    out: dict[str, dict[str, set[str]]] = {}
    for c in clips:
        part = side_of.get(str(c.get("clip_id")))
        if c.get("status") != "done" or not c.get("sequences") or part is None:
            continue
        people = out.setdefault(str(c.get("category", "unknown")), {"train": set(), "test": set()})
        people.setdefault(part, set()).add(str(c.get("group") or c.get("clip_id")))
    return {cat: {part: sorted(v) for part, v in parts.items()}
            for cat, parts in sorted(out.items())}  # fmt: skip


def _split_summary(split: dict) -> dict:
    """``splits`` (per side: ``n_chunks``, ``n_frames``, ``categories``, ``groups``, ``clips``),
    ``split_by``, ``split_groups`` (side -> group names) and ``split_sources`` (source -> side
    -> ``groups``, ``clips``, ``sequences``, ``frames``; when the split recorded them) of a
    ``split.json``. A split written before split modes existed has clip groups (``"clip"``)."""
    stats = {k: dict(v) for k, v in split.get("stats", {}).items()}
    groups = split.get("groups", {})
    members = split.get("members")
    for part, names in groups.items():
        entry = stats.setdefault(part, {})
        entry["groups"] = len(names)
        entry["clips"] = (sum(len(members.get(g, ())) for g in names) if members is not None
                          else len(names))  # fmt: skip
    out: dict = {"splits": stats}
    if groups:
        out["split_by"] = split.get("split_by", "clip")
        out["split_groups"] = {part: list(names) for part, names in groups.items()}
    if "sources" in split:
        out["split_sources"] = split["sources"]
    for key in ("seed", "test_fraction"):
        if key in split:
            out[f"split_{key}"] = split[key]
    return out


def _summary_from_scan(root: Path, limit: int | None) -> dict:
    from prism_tools.io import load_recording

    files = sorted(p for p in root.rglob("*") if p.suffix in RECORDING_SUFFIXES and p.is_file())
    if limit is not None:
        files = files[:limit]
    cats: dict[str, dict[str, int]] = {}
    frames = sensors_only = 0
    errors = []
    fps_seen: set[float] = set()
    for p in files:
        try:
            rec = load_recording(p)
        except (OSError, ValueError) as e:  # every loader failure is a RecordingError
            text = str(e)
            reason = text[len(str(p)) + 1 :].strip() if text.startswith(f"{p}:") else text
            errors.append({"file": str(p), "error": reason})
            continue
        cat = rec.category or "unknown"
        entry = cats.setdefault(cat, {"recordings": 0, "frames": 0})
        entry["recordings"] += 1
        entry["frames"] += rec.n_frames
        frames += rec.n_frames
        sensors_only += not rec.has_ground_truth
        fps_seen.add(float(rec.fps))
    n = sum(c["recordings"] for c in cats.values())
    fps = fps_seen.pop() if len(fps_seen) == 1 else None
    return {
        "source": "scan",
        "root": str(root),
        "files": len(files),
        "recordings": n,
        "frames": frames,
        "fps": fps,
        "hours": frames / (fps or 100.0) / 3600.0,
        "categories": dict(sorted(cats.items())),
        "unreadable": errors,
        "sensors_only": sensors_only,
        "size_bytes": folder_size_bytes(root),
    }


def format_summary(s: dict) -> str:
    """A human-readable Markdown rendering of :func:`dataset_summary`."""
    lines = [f"# Dataset {s['root']}", ""]
    if "clips" in s:
        lines.append(f"- clips: {s['clips']}")
    lines += [
        f"- recordings: {s['recordings']}",
        f"- frames: {s['frames']} ({s['hours']:.2f} h at {s['fps'] or '?'} Hz)",
        f"- size on disk: {s['size_bytes'] / 1e6:.1f} MB",
    ]  # fmt: skip
    if s.get("sensors_only"):
        lines.append(f"- without ground truth (sensors only, no smpl_params): {s['sensors_only']}")
    if s.get("insole_zmp_outside_fraction") is not None:
        lines.append(f"- synthesised frames whose ZMP lies > {_zmp_threshold_cm()} outside the "
                     "insole cells: "
                     f"{100 * s['insole_zmp_outside_fraction']:.1f} %")  # fmt: skip
    lines += _format_zmp_by_source(s.get("insole_zmp_outside_by_source") or {})
    lines += _format_props(s.get("props") or {})
    lines += [
        "",
        "| category | clips | recordings | frames |" if "clips" in s
        else "| category | recordings | frames |",
        "|---|---:|---:|---:|" if "clips" in s else "|---|---:|---:|",
    ]  # fmt: skip
    for cat, c in s["categories"].items():
        if "clips" in s:
            lines.append(f"| {cat} | {c['clips']} | {c['recordings']} | {c['frames']} |")
        else:
            lines.append(f"| {cat} | {c['recordings']} | {c['frames']} |")
    splits = s.get("splits")
    if splits and "train" in splits:
        lines += ["", "| split | groups | clips | sequences | frames |",
                  "|---|---:|---:|---:|---:|"]  # fmt: skip
        for part in ("train", "test"):
            p = splits[part]
            lines.append(f"| {part} | {p.get('groups', '-')} | {p.get('clips', '-')} | "
                         f"{p['n_chunks']} | {p['n_frames']} |")  # fmt: skip
        lines += _format_split(s)
    bad = s.get("clips_failed") or s.get("unreadable") or []
    if bad:
        lines += ["", f"{len(bad)} clip(s)/file(s) failed:"]
        lines += [f"- {b.get('clip_id') or b.get('file')}: {b['error']}" for b in bad[:20]]
    return "\n".join(lines)


def _zmp_threshold_cm() -> str:
    """The threshold the build counted ZMP-outside frames with, as text (``"3 cm"``)."""
    from prism_tools.synth.recording import ZMP_OUTSIDE_M

    return f"{100 * ZMP_OUTSIDE_M:g} cm"


def _format_zmp_by_source(by_source: dict[str, dict]) -> list[str]:
    """The table "ZMP outside the insole cells per source" (Markdown lines; none if empty)."""
    if not by_source:
        return []
    lines = ["", f"ZMP outside the insole cells per source (> {_zmp_threshold_cm()}, "
             "docs/insoles_zmp.md):", "",
             "| source | clips | synthesised frames | ZMP outside | share |",
             "|---|---:|---:|---:|---:|"]  # fmt: skip
    for name, e in by_source.items():
        share = "-" if e["fraction"] is None else f"{100 * e['fraction']:.1f} %"
        lines.append(f"| {name} | {e['clips']} | {e['synth_frames']} | "
                     f"{e['zmp_outside_frames']} | {share} |")  # fmt: skip
    return lines


def _format_props(props: dict) -> list[str]:
    """The props table (Markdown lines; none when no clip has props)."""
    if not props.get("clips"):
        return []
    lines = ["", f"Props inferred from the motion (boxes clips stand or sit on, "
             f"prism_tools/synth/props.py): {props['props']} in {props['clips']} clips", "",
             "| source | clips | steps | seats |", "|---|---:|---:|---:|"]  # fmt: skip
    for name, e in props["by_source"].items():
        lines.append(f"| {name} | {e['clips']} | {e['steps']} | {e['seats']} |")
    lines += [""] + [f"- {clip}: {text}" for clip, text in props["examples"]]
    return lines


def _format_split(s: dict) -> list[str]:
    """The split's mode, sources, groups and categories per side (Markdown lines)."""
    lines: list[str] = []
    mode = s.get("split_by")
    if mode is not None:
        what = {"person": "whole performers (else the source's finest grouping) per side",
                "clip": "whole clips per side"}.get(mode, mode)  # fmt: skip
        extra = ", ".join(f"{k.removeprefix('split_').replace('_', ' ')} {s[k]}"
                          for k in ("split_seed", "split_test_fraction") if k in s)  # fmt: skip
        lines += ["", f"split by {mode}: {what}" + (f" ({extra})" if extra else "")]
    sources = s.get("split_sources") or {}
    if sources:
        lines += ["", "| source | train groups | test groups | train sequences | test sequences "
                  "| test share |", "|---|---:|---:|---:|---:|---:|"]  # fmt: skip
        for name, parts in sources.items():
            tr, te = parts["train"], parts["test"]
            total = tr["sequences"] + te["sequences"]
            share = f"{100 * te['sequences'] / total:.1f} %" if total else "-"
            lines.append(f"| {name or '-'} | {len(tr['groups'])} | {len(te['groups'])} | "
                         f"{tr['sequences']} | {te['sequences']} | {share} |")  # fmt: skip
    groups = s.get("split_groups") or {}
    if mode == "person" and sources:
        lines += ["", "groups per split:"]
        for name, parts in sources.items():
            for part in ("train", "test"):
                names = [g.removeprefix(f"{name}/") if name else g for g in parts[part]["groups"]]
                lines.append(f"- {name or '-'} {part} ({len(names)}): {', '.join(names) or '-'}")
    elif groups and mode != "clip":
        lines += ["", "groups per split:"]
        lines += [f"- {part} ({len(names)}): {', '.join(names) or '-'}"
                  for part, names in groups.items()]  # fmt: skip
    splits = s.get("splits") or {}
    people = s.get("split_people") or {}
    cats = sorted(set(splits.get("train", {}).get("categories", {}))
                  | set(splits.get("test", {}).get("categories", {})))  # fmt: skip
    if cats:
        head = "| category | train sequences | test sequences |"
        lines += ["", head + (" train people | test people |" if people else ""),
                  "|---|---:|---:|" + ("---:|---:|" if people else "")]  # fmt: skip
        for c in cats:
            row = (f"| {c} | {splits['train'].get('categories', {}).get(c, 0)} | "
                   f"{splits['test'].get('categories', {}).get(c, 0)} |")  # fmt: skip
            if people:
                p = people.get(c, {})
                row += f" {len(p.get('train', ()))} | {len(p.get('test', ()))} |"
            lines.append(row)
        if people:
            lines.append("(people: the split groups, i.e. performers where the source names "
                         "them, with sequences of the category on that side)")  # fmt: skip
    return lines
