"""Chunking recordings into fixed-length sequences and building train/test split files.

PRISM's evaluation slices every take into 1000-frame (10 s at 100 fps) chunks, ``seq000`` = frames
0-999, ``seq001`` = frames 1000-1999 and so on, and splits the chunks at random (seed 42) into
train and test, with chunks whose wrist IMU was synthesised kept in train.
"""

from __future__ import annotations

import json
import math
import os
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from grip.core.limits import active_limits, check_file_size, safe_json_loads
from prism_tools.io import atomic_write
from prism_tools.schema import Recording

__all__ = [
    "chunk_id",
    "chunk_recording",
    "load_split",
    "make_split",
    "save_split",
    "segments",
    "stratified_test_groups",
]

SPLIT_FORMAT = "grip-prism-split"
SPLIT_VERSION = 1


def safe_name(clip_id: str) -> str:
    """The file-name form of a clip id (``DATA/motions/<safe_name>.npz``, the stem of its
    sequences' names)."""
    return clip_id.replace("/", "__")


def group_source(group: str) -> str:
    """The source a group belongs to, the stratum of a split by person: the group id less its
    last part (``"hdm05/bd"`` -> ``"hdm05"``, ``"bandai_namco/dataset-2/active"`` ->
    ``"bandai_namco/dataset-2"``, ``"deepmimic/walk"`` -> ``"deepmimic"``)."""
    return group.rsplit("/", 1)[0] if "/" in group else ""


def clip_source(clip: str, group: str | None = None) -> str:
    """The source of a clip (its id or its :func:`safe_name` form): :func:`group_source` of its
    ``group`` when it has a group with a source (a dataset split by person), else the clip's top
    folder (``"cmu/walk_01"`` or ``"cmu__walk_01"`` -> ``"cmu"``)."""
    source = group_source(group) if group else ""
    return source or clip.replace("__", "/").split("/")[0]


def chunk_id(take_name: str, index: int) -> str:
    """``chunk_id("subj001_take002", 3) -> "subj001_take002_seq003"``."""
    return f"{take_name}_seq{index:03d}"


def segments(n_frames: int, length: int = 500, *, min_length: int = 1,
             stride: int = 0) -> list[slice]:  # fmt: skip
    """Frame windows of ``length`` starting every ``stride`` frames (default ``length``:
    consecutive, non-overlapping windows covering ``[0, n_frames)``).

    Args:
        n_frames: Number of frames, ``>= 0``.
        length: Window length in frames, ``>= 1``.
        min_length: A last window shorter than this is dropped (default 1: keep every frame).
        stride: Frames between window starts, ``>= 1``; 0 = ``length``. A stride below the
            length gives overlapping windows (more start points for an evaluation).

    Returns:
        ``[slice(0, length), slice(stride, stride + length), ...]``; a window at the end may be
        shorter than ``length`` (but not shorter than ``min_length``). ``segments(1000, 500)``
        gives two, ``segments(1000, 500, min_length=500, stride=100)`` six.
    """
    if length < 1:
        raise ValueError(f"length must be >= 1, got {length}")
    if n_frames < 0:
        raise ValueError(f"n_frames must be >= 0, got {n_frames}")
    if stride < 0:
        raise ValueError(f"stride must be >= 0, got {stride}")
    starts = range(0, n_frames, stride or length)
    out = [slice(s, min(s + length, n_frames)) for s in starts]
    return [s for s in out if s.stop - s.start >= min_length]


def chunk_recording(
    rec: Recording, length: int = 1000, *, min_length: int | None = None
) -> list[Recording]:
    """Slices a take into consecutive chunks, PRISM style.

    Chunk ``i`` holds frames ``[i * length, (i + 1) * length)`` (arrays copied). A tail shorter than
    ``min_length`` is dropped. Each chunk's extras gain ``chunk_id``
    (``"<take>_seq000"``, from :attr:`Recording.take_name`), ``chunk_index``,
    ``chunk_start_frame`` and ``take_name`` (the parent's).

    Args:
        rec: The take.
        length: Chunk length in frames (1000 = 10 s at 100 fps).
        min_length: Shortest tail kept, ``1 <= min_length <= length``; default ``length`` (only
            full chunks, as PRISM does).

    Returns:
        The chunks in order; 2500 frames give 2 chunks of 1000 by default.
    """
    if length < 1:
        raise ValueError(f"length must be >= 1, got {length}")
    min_len = length if min_length is None else min_length
    if not 1 <= min_len <= length:
        raise ValueError(f"min_length must be in [1, {length}], got {min_length}")
    take = rec.take_name
    chunks = []
    for i, sl in enumerate(segments(rec.n_frames, length, min_length=min_len)):
        chunk = rec.slice_frames(sl.start, sl.stop)
        chunk.extras.update(
            take_name=take,
            chunk_id=chunk_id(take, i),
            chunk_index=i,
            chunk_start_frame=sl.start,
        )
        chunks.append(chunk)
    return chunks


def _stats(
    ids: Iterable[str], categories: Mapping[str, str], frames: int | Mapping[str, int]
) -> dict[str, Any]:
    ids = list(ids)
    n_frames = len(ids) * frames if isinstance(frames, int) else sum(int(frames[i]) for i in ids)
    cats = Counter(categories.get(i, "unknown") for i in ids)
    return {"n_chunks": len(ids), "n_frames": n_frames, "categories": dict(sorted(cats.items()))}


def make_split(
    chunk_ids: Sequence[str],
    test_fraction: float = 0.2,
    seed: int = 42,
    train_only: Iterable[str] = (),
    *,
    categories: Mapping[str, str] | None = None,
    frames_per_chunk: int | Mapping[str, int] = 1000,
    groups: Mapping[str, str] | None = None,
    strata: Mapping[str, str] | None = None,
    test_groups: Iterable[str] = (),
) -> dict[str, Any]:
    """Chunk-level random train/test split, in the shape of PRISM's statistics JSON.

    The chunks not in ``train_only`` are sorted, permuted with ``np.random.default_rng(seed)``
    and the first ``ceil(test_fraction * n_eligible)`` go to test; everything else (including all
    of ``train_only``, e.g. chunks with a synthesised wrist IMU) goes to train. The result
    depends only on the set of ids, not on their order. (PRISM: 1275 chunks, 1021 train / 254
    test, which ``ceil(0.2 * 1270)`` reproduces with 5 train-only chunks.)

    Returned dict (JSON-ready)::

        {
          "format": "grip-prism-split", "version": 1,
          "seed": 42, "test_fraction": 0.2,
          "train": ["subj001_take002_seq000", ...],   # sorted chunk ids
          "test": [...],                              # sorted chunk ids
          "train_only": [...],                        # sorted, all also in "train"
          "stats": {
            "train": {"n_chunks": int, "n_frames": int, "categories": {category: n_chunks}},
            "test":  {... same ...},
            "total": {... same ...},
          },
        }

    Args:
        chunk_ids: All chunk ids (unique).
        test_fraction: Fraction of the eligible chunks put in test, in ``[0, 1]``.
        seed: Seed of the permutation (PRISM: 42).
        train_only: Chunk ids forced into train; each must be in ``chunk_ids``.
        categories: Chunk id -> activity category for the per-category counts; ids missing from
            it (or all, when ``None``) count as ``"unknown"``.
        frames_per_chunk: Frames per chunk, one number or a chunk id -> frames mapping.
        groups: Optional chunk id -> group id (e.g. the source clip). Whole groups are then
            assigned: groups are permuted with the seed and go to test until it holds
            ``ceil(test_fraction * n_eligible)`` chunks, so chunks of one motion (its noise
            variants and consecutive pieces) never straddle train and test. A group with any
            ``train_only`` chunk stays in train. The returned dict then also lists
            ``"groups": {"train": [...], "test": [...]}``.
        strata: Optional group id -> stratum (e.g. the source a person was recorded by); needs
            ``groups``. Test groups are then chosen within each stratum
            (:func:`stratified_test_groups`): a stratum of two or more eligible groups gets
            about ``test_fraction`` of its eligible chunks in test and at least one group on
            each side; a stratum of one group stays in train. Groups missing from ``strata``
            form one stratum of their own.
        test_groups: Groups put in test whatever the draw (needs ``groups``), e.g. the one
            performer whose clips have props; the draw then picks the other test groups among
            the rest as usual.

    Returns:
        The split dict described above.

    Raises:
        ValueError: Duplicate ids, ``train_only`` ids not in ``chunk_ids``, a bad fraction, or
            ``strata`` without ``groups``.
    """
    ids = [str(i) for i in chunk_ids]
    if len(set(ids)) != len(ids):
        dups = sorted(i for i, c in Counter(ids).items() if c > 1)
        raise ValueError(f"make_split: duplicate chunk ids {dups[:5]}")
    if not 0.0 <= test_fraction <= 1.0:
        raise ValueError(f"make_split: test_fraction must be in [0, 1], got {test_fraction}")
    forced = {str(i) for i in train_only}
    unknown = sorted(forced - set(ids))
    if unknown:
        raise ValueError(f"make_split: train_only ids not in chunk_ids: {unknown[:5]}")
    if strata is not None and groups is None:
        raise ValueError("make_split: strata need groups")
    must = {str(g) for g in test_groups}
    if must and groups is None:
        raise ValueError("make_split: test_groups need groups")
    eligible = sorted(set(ids) - forced)
    n_test = min(len(eligible), math.ceil(test_fraction * len(eligible) - 1e-9))
    group_lists: dict[str, list[str]] | None = None
    if groups is None:
        perm = np.random.default_rng(seed).permutation(len(eligible))
        test_set = {eligible[i] for i in perm[:n_test]}
    else:
        missing = sorted(set(ids) - set(groups))
        if missing:
            raise ValueError(f"make_split: chunk ids without a group: {missing[:5]}")
        members: dict[str, list[str]] = {}
        for i in ids:
            members.setdefault(str(groups[i]), []).append(i)
        unknown = sorted(must - set(members))
        if unknown:
            raise ValueError(f"make_split: test_groups {unknown[:5]} are not groups of the "
                             f"chunks (e.g. {sorted(members)[:3]})")  # fmt: skip
        blocked = {g for g, m in members.items() if forced.intersection(m)}
        names = sorted(g for g in members if g not in blocked and g not in must)
        test_set = {i for g in must for i in members[g]}  # (they count toward n_test)
        test_groups = sorted(must)
        if strata is not None:
            sizes = {g: len(members[g]) for g in names}
            drawn = stratified_test_groups(sizes, {g: strata.get(g, "") for g in names},
                                           test_fraction, seed)  # fmt: skip
            test_groups += drawn
            for g in drawn:
                test_set.update(members[g])
        else:
            perm = np.random.default_rng(seed).permutation(len(names))
            for k in perm:
                if len(test_set) >= n_test:
                    break
                test_groups.append(names[k])
                test_set.update(members[names[k]])
        group_lists = {
            "train": sorted(g for g in members if g not in set(test_groups)),
            "test": sorted(test_groups),
        }
    test = sorted(test_set)
    train = sorted(i for i in ids if i not in test_set)
    cats = categories or {}
    out = {
        "format": SPLIT_FORMAT,
        "version": SPLIT_VERSION,
        "seed": seed,
        "test_fraction": test_fraction,
        "train": train,
        "test": test,
        "train_only": sorted(forced),
        "stats": {
            "train": _stats(train, cats, frames_per_chunk),
            "test": _stats(test, cats, frames_per_chunk),
            "total": _stats(sorted(ids), cats, frames_per_chunk),
        },
    }
    if group_lists is not None:
        out["groups"] = group_lists
    return out


#: Random greedy fills tried per stratum by :func:`stratified_test_groups`.
STRATIFIED_TRIES = 256


def stratified_test_groups(sizes: Mapping[str, int], strata: Mapping[str, str],
                           test_fraction: float, seed: int) -> list[str]:  # fmt: skip
    """The groups of a stratified group split's test side.

    In each stratum with at least two groups, :data:`STRATIFIED_TRIES` random orders of its
    groups are each filled greedily: a group joins the test side when that brings the test
    side's size nearer to ``test_fraction`` of the stratum's size (the first group always joins,
    and one group always stays in train). Each stratum draws from its own generator, seeded by
    ``seed`` and the stratum's name, so that its choice does not depend on the other strata.
    The fill nearest to the target wins; the first of equals.
    So every such stratum has a group on each side and about the test fraction of its size in
    test, as near as its group sizes allow, and the choice depends only on ``seed``, the sizes
    and the names (not their order). A stratum of one group stays in train; with
    ``test_fraction`` 0 nothing goes to test, with 1 everything does (a folder of one's own
    recordings to evaluate).

    Args:
        sizes: Group -> size (chunks).
        strata: Group -> stratum, for every group of ``sizes``.
        test_fraction: Wanted share of each stratum's size in test, in ``[0, 1]``.
        seed: Seed of the random orders.

    Returns:
        The test groups, sorted.
    """
    by_stratum: dict[str, list[str]] = {}
    for g in sorted(sizes):
        by_stratum.setdefault(str(strata[g]), []).append(g)
    chosen: list[str] = []
    if test_fraction <= 0:
        return chosen
    if test_fraction >= 1:
        return sorted(sizes)
    for stratum in sorted(by_stratum):
        names = by_stratum[stratum]
        if len(names) < 2:
            continue
        target = test_fraction * sum(int(sizes[g]) for g in names)
        rng = np.random.default_rng([seed, *stratum.encode("utf-8")])
        best: list[str] = []
        best_err = math.inf
        for _ in range(STRATIFIED_TRIES):
            picked: list[str] = []
            total = 0
            for i in rng.permutation(len(names)):
                if len(picked) == len(names) - 1:
                    break
                n = int(sizes[names[i]])
                if not picked or abs(total + n - target) < abs(total - target):
                    picked.append(names[i])
                    total += n
            err = abs(total - target)
            if err < best_err - 1e-9:
                best, best_err = picked, err
        chosen += best
    return sorted(chosen)


def save_split(split: Mapping[str, Any], path: str | os.PathLike[str]) -> None:
    """Writes a split dict as indented JSON, atomically (see :func:`prism_tools.io.atomic_write`).

    Args:
        split: A dict from :func:`make_split`.
        path: Destination ``.json`` file.
    """
    _check_split(split, str(path))
    data = (json.dumps(split, indent=2, sort_keys=False) + "\n").encode("utf-8")
    atomic_write(path, lambda f: f.write(data))


def load_split(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Reads and checks a split JSON file.

    Args:
        path: File written by :func:`save_split` (or any JSON with ``"train"``/``"test"`` lists).

    Returns:
        The split dict.

    Raises:
        FileNotFoundError: No such file.
        ValueError: Not valid JSON (or above the input limits of :mod:`grip.core.limits`),
            ``train``/``test`` missing or not lists of strings, or a chunk in both; the message
            starts with the path.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such split file")
    limits = active_limits()
    try:
        check_file_size(p, limits)
        split = safe_json_loads(p.read_text(encoding="utf-8"), limits, "split JSON")
    except (OSError, ValueError) as e:  # JSON, UTF-8, size/depth/digit limits
        raise ValueError(f"{p}: not a valid split JSON file ({e})") from None
    _check_split(split, str(p))
    return split


def _check_split(split: Any, where: str) -> None:
    if not isinstance(split, Mapping):
        raise ValueError(f"{where}: a split must be a dict, got {type(split).__name__}")
    for key in ("train", "test"):
        ids = split.get(key)
        if not isinstance(ids, list) or not all(isinstance(i, str) for i in ids):
            raise ValueError(f"{where}: {key!r} must be a list of chunk id strings")
    both = sorted(set(split["train"]) & set(split["test"]))
    if both:
        raise ValueError(f"{where}: chunks in both train and test: {both[:5]}")
