"""What a resumed ``grip bench`` compares before it keeps a finished segment.

A benchmark's numbers must belong to one set of models and one version of the data. A folder
records, next to its results:

- ``segments/<label>/method.json``: the method's name and options (compared as they are) and,
  under ``"models"``, each model file it reads (:func:`grip.eval.methods.model_files`: the given
  files and the shipped defaults) with the SHA-256 of its contents;
- ``inputs.json``: each recording the segments were cut from, with the SHA-256 of its contents.

A resume whose options differ, or one of whose model files or recordings has other contents now
(replaced in place at the same path), is refused with a :class:`BenchError` that names the file
and says how to start afresh. Files are hashed once per run and a resume trusts a file whose
size and times still match its record (:class:`grip.core.digests.FileDigests`), so resuming over
thousands of recordings reads none of them again.

A folder written before these records existed has nothing to compare: it resumes, its results
kept as they are (their files assumed unchanged), with a note saying so, and the records are
written from then on.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Protocol

from grip.core.atomic import atomic_write_text
from grip.core.digests import FileDigests, change_text, same_contents
from grip.eval.report import jsonable
from grip.eval.segments import BenchError

__all__ = ["INPUTS", "check_inputs", "check_method"]

INPUTS = "inputs.json"
"""The file of a benchmark folder that records its recordings' contents."""


class _Run(Protocol):
    label: str

    def describe(self) -> dict: ...

    def model_files(self) -> dict[str, Path]: ...


def _afresh(out_dir: Path) -> str:
    return f"use another --out to start afresh (or delete {out_dir})"


def _read_json(path: Path) -> object:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        raise BenchError(f"{path}: unreadable ({e}); {_afresh(path.parent)}") from e


def check_method(out_dir: Path, run: _Run, log: Callable[[str], object] = print) -> None:
    """Refuse to resume ``run``'s results in ``out_dir`` with other options or other model
    contents; record both (``method.json``) for the next resume.

    Raises:
        BenchError: ``method.json`` is unreadable, records other options, or a model file's
            contents differ from those recorded (the message names the file).
    """
    path = out_dir / "segments" / run.label / "method.json"
    want = jsonable(run.describe())
    files = run.model_files()
    stored: object = {}
    if path.is_file():
        have = _read_json(path)
        stored = have.pop("models", None) if isinstance(have, dict) else None
        if isinstance(have, dict) and isinstance(have.get("options"), dict):
            # (written before MethodOptions.init existed: those runs started from the truth)
            have["options"].setdefault("init", "truth")
            have["options"].setdefault("restart", "simulated")  # (GRIP's, before --restart)
            have["options"].setdefault("lost_gap_m", 0.0)  # (only falls, before --lost-gap)
            have["options"].setdefault("pace_gain", 0.0)  # (no pace keeper before it existed)
            have["options"].setdefault("pace_lead_max_m", 0.5)
            have["options"].setdefault("lean_gain_deg", 0.0)  # (no lean keeper before it existed)
            have["options"].setdefault("lean_max_deg", 5.0)
        if have != want:
            raise BenchError(f"{path.parent}: results of {run.label} with other settings "
                             f"({have} vs now {want}); use another output folder")  # fmt: skip
        if not isinstance(stored, dict):
            log(f"note: {path}: no record of the model files' contents (written by an older "
                "version): its results are kept, their models assumed unchanged; a change is "
                "refused from now on")  # fmt: skip
            stored = {}
    old = {k: v.get("record") for k, v in stored.items() if isinstance(v, dict)}
    digests = FileDigests()
    now = {key: {"path": str(p), "record": digests.record(p, known=old.get(key))}
           for key, p in files.items()}  # fmt: skip
    changed = []
    for key in dict.fromkeys([*old, *now]) if stored else ():
        rec = now[key]["record"] if key in now else None
        if not same_contents(old.get(key), rec):
            where = now[key]["path"] if key in now else stored[key].get("path")
            changed.append(f"{key} {change_text(where, old.get(key), rec)}")
    if changed:
        raise BenchError(f"{path.parent}: results of {run.label} were computed with other "
                         f"models: {'; '.join(changed)}; a resume would mix two models in one "
                         f"result: {_afresh(out_dir)}")  # fmt: skip
    if not path.is_file() or stored != now:
        atomic_write_text(path, json.dumps({**want, "models": now}, indent=1) + "\n")


def _has_rows(out_dir: Path) -> bool:
    return any(p.name != "method.json" for p in (out_dir / "segments").glob("*/*.json"))


def check_inputs(out_dir: Path, files: Iterable[str | Path],
                 log: Callable[[str], object] = print) -> None:  # fmt: skip
    """Refuse to resume in ``out_dir`` when a recording has other contents than those its
    results were computed from; record every recording's contents (``inputs.json``, records of
    files not in this run kept) for the next resume.

    Raises:
        BenchError: ``inputs.json`` is unreadable, or a recording it records has other contents
            now (the message names it).
    """
    path = out_dir / INPUTS
    stored: Mapping = {}
    if path.is_file():
        have = _read_json(path)
        stored = have.get("files") if isinstance(have, dict) else None
        if not isinstance(stored, dict):
            raise BenchError(f"{path}: no 'files' record; {_afresh(out_dir)}")
    elif _has_rows(out_dir):
        log(f"note: {out_dir}: no record of the recordings' contents (results written by an "
            "older version): its results are kept, their recordings assumed unchanged; a change "
            "is refused from now on")  # fmt: skip
    digests = FileDigests(stored)
    now: dict[str, dict] = {}
    changed: list[str] = []
    for f in dict.fromkeys(str(Path(f).resolve()) for f in files):
        rec = digests.record(f)
        if f in stored and not same_contents(stored[f], rec):
            changed.append(change_text(f, stored[f], rec))
        if rec is not None:
            now[f] = rec
    if changed:
        more = f" (and {len(changed) - 1} other recording(s))" if len(changed) > 1 else ""
        raise BenchError(
            f"{out_dir}: results were computed from other data: {changed[0]}{more}; "
            f"a resume would mix two versions of the data: {_afresh(out_dir)}"
        )
    if any(stored.get(f) != rec for f, rec in now.items()):
        atomic_write_text(path, json.dumps({"files": {**stored, **now}}, indent=1) + "\n")
