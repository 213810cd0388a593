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
    kept; another path replaces it)."""
    ref = _REFERENCE.get(path)
    if ref is None:
        _REFERENCE.clear()
        ref = _REFERENCE[path] = ReferenceSet.load(path)
    return ref


def select_clips(ref: ReferenceSet, patterns: tuple[str, ...]) -> ReferenceSet:
    """The clips whose category matches one of the glob ``patterns`` (all when empty).

    Raises:
        ValueError: naming the set and the categories it has, when no clip matches.
    """
    if not patterns:
        return ref
    clips = [c for c in ref.clips if any(fnmatch.fnmatch(c.category, p) for p in patterns)]
    if not clips:
        cats = sorted({c.category for c in ref.clips})
        raise ValueError(f"{ref.source}: no clip matches categories {list(patterns)} "
                         f"(categories present: {cats})")  # fmt: skip
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
