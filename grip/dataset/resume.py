"""What a resumed ``grip data build`` compares before it keeps a finished clip.

A finished clip's ``done`` marker records, under ``"inputs"``, what its source files held when
it was built: the clip file (``"clip"``) and, for an AMC clip, its ASF skeleton
(``"skeleton"``), each with its resolved path and a :data:`grip.core.digests.Record` (SHA-256,
size and times). A resume compares them with the files now: a source replaced in place would
leave recordings of the old motion in a dataset that claims to be built from the new one, so
the build is refused, naming the file. A file whose size and times still match its record is
not read again (:class:`grip.core.digests.FileDigests`).

A marker written before these records existed has nothing to compare: the clip is kept (its
sources assumed unchanged), counted, and given the records of its sources now.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict, replace
from pathlib import Path
from typing import TYPE_CHECKING

from grip.core.atomic import atomic_write_text
from grip.core.digests import FileDigests, change_text, same_contents

if TYPE_CHECKING:
    from grip.dataset.build import ClipResult, ClipSpec

__all__ = ["check_sources", "done_marker", "source_records"]


def done_marker(out: Path, clip_id: str) -> Path:
    """The ``done`` marker of a clip in the dataset folder ``out``."""
    from prism_tools.chunking import safe_name

    return out / "done" / f"{safe_name(clip_id)}.json"


def source_records(files: dict[str, str | Path | None], digests: FileDigests | None = None,
                   known: dict | None = None) -> dict[str, dict]:  # fmt: skip
    """``{role: {"path": resolved path, **record}}`` of the source files that exist.

    Args:
        files: ``{role: file}`` (``None``: no such file, left out).
        digests: Hashes files (shared to read each file once).
        known: Earlier records by role, trusted where the same file's size and times match.
    """
    digests = digests or FileDigests()
    out: dict[str, dict] = {}
    for role, f in files.items():
        if f is None:
            continue
        path = str(Path(f).resolve())
        old = (known or {}).get(role)
        rec = digests.record(path, known=old if isinstance(old, dict)
                             and old.get("path") == path else None)  # fmt: skip
        if rec is not None:
            out[role] = {"path": path, **rec}
    return out


def _skeleton(spec: ClipSpec) -> Path | None:
    """The ASF skeleton the clip search finds for an AMC clip (``None``: other formats)."""
    from grip.motion.catalog import clip_ref
    from grip.motion.source import MotionImportError

    try:
        return clip_ref(spec.path).asf_path
    except MotionImportError:
        return None


def _skeleton_now(old: dict, spec: ClipSpec) -> str | Path | None:
    """Where a clip's skeleton is now: its recorded path, else what the clip search finds."""
    if isinstance(old.get("path"), str) and Path(old["path"]).is_file():
        return old["path"]
    return _skeleton(spec)


def check_sources(out: Path, pairs: Sequence[tuple[ClipSpec, ClipResult]]
                  ) -> tuple[dict[str, ClipResult], int]:  # fmt: skip
    """Compare the finished clips' sources with their records, before anything is changed.

    Args:
        out: The dataset folder.
        pairs: Each finished clip's spec (from the clip search now) and ``done`` result.

    Returns:
        ``{clip_id: result}`` of the clips whose records were written or refreshed (their
        markers rewritten), and how many clips had no record (a marker of an older version).

    Raises:
        ValueError: A source has other contents than its clip was built from (the message
            names the file and the clip, and how to start afresh).
    """
    digests = FileDigests()
    changed: list[str] = []
    updated: dict[str, ClipResult] = {}
    unrecorded = 0
    for spec, res in pairs:
        old = res.inputs if isinstance(res.inputs, dict) else {}
        if not old:
            unrecorded += 1
            now = source_records({"clip": spec.path, "skeleton": _skeleton(spec)}, digests)
        else:
            files = {role: spec.path if role == "clip" else _skeleton_now(rec, spec)
                     for role, rec in old.items() if isinstance(rec, dict)}  # fmt: skip
            now = source_records(files, digests, old)
            for role, rec in old.items():
                if not same_contents(rec, now.get(role)):
                    where = files.get(role) or (rec.get("path") if isinstance(rec, dict) else role)
                    changed.append(f"{change_text(where, rec, now.get(role))} since clip "
                                   f"{res.clip_id} was built from it; delete "
                                   f"{done_marker(out, res.clip_id)} to build only that clip "
                                   "again")  # fmt: skip
        if now != old:
            updated[res.clip_id] = replace(res, inputs=now)
    if changed:
        more = f" (and {len(changed) - 1} other source(s))" if len(changed) > 1 else ""
        raise ValueError(f"{out}: {changed[0]}{more}; the folder's recordings of it come from "
                         "the old contents: use another --out to start afresh")  # fmt: skip
    for res in updated.values():
        atomic_write_text(done_marker(out, res.clip_id), json.dumps(asdict(res), indent=1))
    return updated, unrecorded
