"""Reference sets as a training process shares them: loaded once per path, narrowed to
categories.

The training environments (:func:`envs.factory.make_tracking_env`) and the trainer's AMP real
samples (:class:`policies.train.PolicyTrainer`) read the same reference file; in one process they
share one copy (:func:`load_reference`), since a large set takes gigabytes. numpy only.
"""

from __future__ import annotations

import fnmatch

import numpy as np

from grip.core.reference import ReferenceSet

_REFERENCE: dict[str, ReferenceSet] = {}


def load_reference(path: str) -> ReferenceSet:
    """The reference set at ``path``, loaded once per process (the last path asked for is
    kept; another path replaces it), its clips compact (float32,
    :meth:`grip.core.reference.ReferenceClip.compact`)."""
    ref = _REFERENCE.get(path)
    if ref is None:
        _REFERENCE.clear()
        ref = _REFERENCE[path] = ReferenceSet.load(path, compact=True)
    return ref


def select_clip_indices(ref: ReferenceSet, patterns: tuple[str, ...]) -> list[int]:
    """The indices in ``ref`` of the clips :func:`select_clips` keeps, in its order.

    Raises:
        ValueError: naming the set and the categories it has, when no clip matches.
    """
    if not patterns:
        return list(range(len(ref.clips)))
    keep = [i for i, c in enumerate(ref.clips)
            if any(fnmatch.fnmatch(c.category, p) for p in patterns)]  # fmt: skip
    if not keep:
        cats = sorted({c.category for c in ref.clips})
        raise ValueError(f"{ref.source}: no clip matches categories {list(patterns)} "
                         f"(categories present: {cats})")  # fmt: skip
    return keep


def select_clips(ref: ReferenceSet, patterns: tuple[str, ...]) -> ReferenceSet:
    """The clips whose category matches one of the glob ``patterns`` (all when empty).

    Raises:
        ValueError: naming the set and the categories it has, when no clip matches.
    """
    if not patterns:
        return ref
    clips = [ref.clips[i] for i in select_clip_indices(ref, patterns)]
    return ReferenceSet(clips, ref.sensor_sites, ref.insoles, ref.source)


def clip_probabilities(lengths: np.ndarray, weights) -> np.ndarray:
    """The probability of starting an episode on each clip: its length times its weight,
    normalised (the environments' ``set_clip_weights``; hard-clip mining's weights).

    Raises:
        ValueError: ``weights`` is not one finite value >= 0 per clip, or all are zero.
    """
    w = np.asarray(weights, dtype=np.float64)
    if w.shape != lengths.shape or not np.isfinite(w).all() or (w < 0).any():
        raise ValueError(f"clip weights must be {lengths.size} finite values >= 0, "
                         f"got shape {w.shape}")  # fmt: skip
    p = lengths * w
    if p.sum() <= 0:
        raise ValueError("clip weights are all zero: no clip could be picked")
    return p / p.sum()


def start_bin_probabilities(last_start: int, bin_frames: int, weights) -> np.ndarray:
    """The probability of starting an episode in each bin of ``bin_frames`` frames of a clip
    whose random starts are frames ``0 .. last_start``: the bin's start frames times its
    weight, normalised (the environments' ``set_start_bin_weights``; failure-weighted starts,
    :class:`policies.mining.StartBinStats`). All weights equal: every start frame equally
    likely, as without bins.

    Args:
        last_start: The last frame an episode may start at (>= 0).
        bin_frames: Frames per bin (> 0).
        weights: ``(>= B,)`` finite values >= 0, one per bin of the clip from its frame 0
            (``B = ceil((last_start + 1) / bin_frames)`` bins hold start frames; the rest are
            ignored).

    Returns:
        ``(B,)`` probabilities.

    Raises:
        ValueError: ``weights`` is too short, not finite or negative, or zero on every bin
            that holds a start frame.
    """
    if last_start < 0 or bin_frames < 1:
        raise ValueError(f"need last_start >= 0 and bin_frames >= 1, got {last_start}, "
                         f"{bin_frames}")  # fmt: skip
    n = last_start + 1
    nb = -(-n // bin_frames)
    w = np.asarray(weights, dtype=np.float64)
    if w.ndim != 1 or w.size < nb or not np.isfinite(w).all() or (w < 0).any():
        raise ValueError(f"start bin weights must be >= {nb} finite values >= 0, got shape "
                         f"{w.shape}")  # fmt: skip
    counts = np.minimum(bin_frames, n - bin_frames * np.arange(nb))
    p = counts * w[:nb]
    if p.sum() <= 0:
        raise ValueError("start bin weights are all zero where episodes can start")
    return p / p.sum()


def start_bin_table(last_starts: np.ndarray, bin_frames: int, weights) -> np.ndarray:
    """:func:`start_bin_probabilities` of every clip as one ``(C, most bins)`` table (zeros
    after a clip's bins), for an environment that draws on a device.

    Args:
        last_starts: ``(C,)`` each clip's last start frame.
        bin_frames: Frames per bin.
        weights: Per clip, its bin weights or ``None`` (every start frame equally).
    """
    rows = []
    for s, w in zip(np.asarray(last_starts).tolist(), weights, strict=True):
        if w is None:
            w = np.ones(-(-(int(s) + 1) // bin_frames))
        rows.append(start_bin_probabilities(int(s), bin_frames, w))
    table = np.zeros((len(rows), max(len(r) for r in rows)))
    for i, r in enumerate(rows):
        table[i, : len(r)] = r
    return table
