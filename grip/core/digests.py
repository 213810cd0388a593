"""What a file held: the records a resumable run keeps of its inputs (stdlib only).

A resumed run keeps what an earlier run finished, so those results must come from the same
models and data: a model or recording replaced in place at the same path (a training run
rewrites its ``policy.pt``) would otherwise mix two versions in one result. Each run records,
per input file, the SHA-256 of its contents with the file's size, modification time and
status-change time (a :data:`Record`); a resume compares them (:func:`change_text` says what
changed).

Hashing every input again on each resume would make a resume over thousands of recordings read
them all, so :class:`FileDigests` trusts a record whose size, ``mtime_ns`` and ``ctime_ns``
still match the file (a file rewritten in place changes them; ``ctime`` cannot be set back as
``mtime`` can) and hashes only the others, each at most once.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Mapping
from pathlib import Path

__all__ = ["FileDigests", "Record", "change_text", "file_sha256", "same_contents"]

Record = dict
"""``{"sha256": hex, "size": bytes, "mtime_ns": int, "ctime_ns": int}`` of one file."""

_STAT_KEYS = ("size", "mtime_ns", "ctime_ns")


def file_sha256(path: str | os.PathLike) -> str:
    """SHA-256 of a file's contents (hex)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _stat(st: os.stat_result) -> tuple[int, int, int]:
    return st.st_size, st.st_mtime_ns, st.st_ctime_ns


def _valid(record: object) -> bool:
    return (isinstance(record, Mapping) and isinstance(record.get("sha256"), str)
            and all(type(record.get(k)) is int for k in _STAT_KEYS))  # fmt: skip


class FileDigests:
    """Records of files (:data:`Record`), each file hashed at most once while it is unchanged.

    Args:
        known: Records made earlier, by resolved path (a run folder's): a file whose size,
            ``mtime_ns`` and ``ctime_ns`` still match its record is not read again.
    """

    def __init__(self, known: Mapping[str, object] | None = None) -> None:
        self._known: dict[str, Record] = {k: dict(v) for k, v in (known or {}).items()
                                          if _valid(v)}  # fmt: skip
        self.hashed = 0
        """Files read and hashed by this object (the others were trusted by their stat)."""

    def record(self, path: str | os.PathLike, known: object = None) -> Record | None:
        """The record of ``path`` now, or ``None`` when it is not a readable file.

        Args:
            path: The file.
            known: An earlier record of it (else the one given to the constructor, by resolved
                path), reused when the file's size and times still match it.
        """
        key = str(Path(path).resolve())
        try:
            stat = _stat(os.stat(key))
            match = [r for r in (known, self._known.get(key))
                     if _valid(r) and tuple(r[k] for k in _STAT_KEYS) == stat]  # fmt: skip
            if match:
                sha = match[0]["sha256"]
            else:
                sha = file_sha256(key)
                self.hashed += 1
        except OSError:
            return None
        rec = {"sha256": sha, **dict(zip(_STAT_KEYS, stat, strict=True))}
        self._known[key] = rec
        return dict(rec)


def same_contents(old: object, new: Record | None) -> bool:
    """Whether two records (either may be ``None``: no file) describe the same contents."""
    if old is None or new is None:
        return old is None and new is None
    return _valid(old) and old["sha256"] == new["sha256"]  # type: ignore[index]


def change_text(path: str | os.PathLike, old: object, new: Record | None) -> str:
    """``"FILE: its contents changed (SHA-256 0123456789ab... then, 89abcdef0123... now)"``,
    or that it appeared or is gone."""
    if new is None:
        return f"{path}: gone or unreadable (it was read before)"
    if old is None or not _valid(old):
        return f"{path}: not read before"
    return (f"{path}: its contents changed (SHA-256 {old['sha256'][:12]}... then, "  # type: ignore[index]
            f"{new['sha256'][:12]}... now)")  # fmt: skip
