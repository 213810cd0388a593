"""The segments every evaluation runs on (``grip bench``, ``grip kin eval``, ``grip policy eval``).

The recordings of a dataset split are cut into consecutive ``segment_frames``-frame segments
(the GRIP protocol: each one starts from the ground truth at its first frame). A file that cannot
be read is either an error or, with an ``errors`` list, reported there and skipped.
"""

from __future__ import annotations

import fnmatch
import os
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "SPLITS",
    "BenchError",
    "Segment",
    "SegmentReader",
    "list_segments",
    "select_segments",
    "split_files",
]

SPLITS: tuple[str, ...] = ("train", "test", "all", "holdout")
"""Dataset splits; ``"holdout"``: the training files whose stems a policy held out."""


class BenchError(ValueError):
    """An evaluation cannot run as asked (bad data, settings that differ from a previous run)."""


@dataclass(frozen=True)
class Segment:
    """Frames ``[start, stop)`` of one recording file.

    Attributes:
        id: ``<file stem>_f<start>`` (unique within a dataset, safe as a file name; the stem
            cleaned as names are, :func:`grip.core.text.clean_text`).
        path: Recording file.
        start, stop: Frame range.
        category: The recording's motion category (``"unknown"`` when it has none).
    """

    id: str
    path: Path
    start: int
    stop: int
    category: str

    @property
    def n_frames(self) -> int:
        return self.stop - self.start


def split_files(data: str | os.PathLike, split: str, holdout: Collection[str] = ()) -> list[Path]:
    """The recording files of a dataset split.

    Args:
        data: Dataset folder (with ``split.json``).
        split: One of :data:`SPLITS`.
        holdout: For ``"holdout"``: the file stems held out (of the train split).

    Raises:
        OSError, ValueError: No or a broken ``split.json``, or an unknown split.
    """
    from grip.kinematics.dataset import split_files as dataset_split

    if split != "holdout":
        return dataset_split(Path(data), split)
    held = set(holdout)
    return [f for f in dataset_split(Path(data), "train") if f.stem in held]


def list_segments(
    files: Sequence[str | os.PathLike], segment_frames: int = 500, categories: Sequence[str] = (),
    errors: list[tuple[str, str]] | None = None, *, stride: int = 0, min_frames: int | None = None,
    limit: int = 0,
) -> list[Segment]:  # fmt: skip
    """Consecutive ``segment_frames``-frame segments of recording files.

    Args:
        files: Recording files (a dataset split).
        segment_frames: Segment length, frames.
        categories: Keep recordings whose category matches one of these globs (all if empty).
        errors: If given, a file that cannot be read is skipped and ``(file, reason)`` appended
            here instead of raising.
        stride: A segment starts every ``stride`` frames (0: ``segment_frames``, no overlap).
        min_frames: Shortest segment kept (a shorter tail is left out); ``None``:
            ``segment_frames`` (tails left out).
        limit: At most this many segments, the first in file order (0: all).

    Raises:
        BenchError: A file cannot be read and ``errors`` is ``None`` (the message names it), or
            no segment results.
    """
    from grip.core.text import clean_text
    from prism_tools.chunking import segments
    from prism_tools.io import load_recording

    if segment_frames < 3:
        raise BenchError(f"segment_frames must be >= 3, got {segment_frames}")
    out: list[Segment] = []
    for f in files:
        path = Path(f)
        try:
            rec = load_recording(path)
        except (OSError, ValueError) as e:
            if errors is None:
                raise BenchError(f"{path}: {e}" if str(path) not in str(e) else str(e)) from e
            errors.append((str(path), str(e).removeprefix(f"{path}:").strip()))
            continue
        cat = rec.category or "unknown"
        if categories and not any(fnmatch.fnmatch(cat, c) for c in categories):
            continue
        cuts = segments(rec.n_frames, segment_frames, stride=stride,
                        min_length=segment_frames if min_frames is None else min_frames)
        stem = clean_text(path.stem)  # (an undecodable byte of a file name: U+FFFD)
        out += [Segment(f"{stem}_f{sl.start:06d}", path, sl.start, sl.stop, cat)
                for sl in cuts]  # fmt: skip
        if limit and len(out) >= limit:
            return out[:limit]
    if not out:
        what = f" of categories {list(categories)}" if categories else ""
        raise BenchError(f"no {segment_frames}-frame segment in {len(files)} recording(s){what}")
    return out


def select_segments(segments: Sequence[Segment], n: int) -> list[Segment]:
    """At most ``n`` segments (all if ``n <= 0``), spread over the categories.

    Categories are visited in sorted order, taking each one's next segment in turn, so every
    category is represented before any gets a second segment. Deterministic; the result keeps
    the input order.
    """
    if n <= 0 or n >= len(segments):
        return list(segments)
    by_cat: dict[str, list[int]] = {}
    for i, s in enumerate(segments):
        by_cat.setdefault(s.category, []).append(i)
    chosen: list[int] = []
    rank = 0
    while len(chosen) < n:
        for cat in sorted(by_cat):
            if rank < len(by_cat[cat]) and len(chosen) < n:
                chosen.append(by_cat[cat][rank])
        rank += 1
    return [segments[i] for i in sorted(chosen)]


class SegmentReader:
    """Loads segment recordings, keeping the last file read (segments come file by file)."""

    def __init__(self) -> None:
        self._path: Path | None = None
        self._rec = None

    def __call__(self, seg: Segment):
        """The recording of ``seg``: its file's frames ``[start, stop)``."""
        return self.whole(seg).slice_frames(seg.start, seg.stop)

    def whole(self, seg: Segment):
        """The whole recording of ``seg``'s file (the frames around the segment too)."""
        from prism_tools.io import load_recording

        if self._path != seg.path:
            self._rec, self._path = load_recording(seg.path), seg.path
        return self._rec
