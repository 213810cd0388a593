"""Per-clip arrays of a reference set laid out for the control step, kept across episodes and
shared by the environments of one learner.

An episode start needs, for its clip and subject, the estimate laid out for the step
(:class:`grip.task.observations.EstimateFrames`), the ground-truth rows the reward reads and the
clip's ground-truth AMP frames: a few milliseconds to build for a clip of 500 frames, and
about 6.4 kB per frame to keep. A learner's environments draw from the same clips, so one
bounded cache serves them all (the batched factory shares one; a lone environment has its
own): the same memory holds as many times more clips as there are environments.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Hashable
from dataclasses import dataclass

import numpy as np

from grip.core import skeleton as sk
from grip.task import amp as A
from grip.task import observations as O

GT_DIM = 2 * 9 * sk.N_JOINTS
"""A ground-truth row: ``pvw (3, J, 3)`` then ``rot (J, 3, 3)``, flat (what the reward reads)."""

DEFAULT_MAX_BYTES = 512 * 2**20
"""The default bound of a cache, bytes (about 80,000 frames)."""


@dataclass(frozen=True)
class ClipArrays:
    """One clip's arrays for one subject (read only once built).

    Attributes:
        clip: The reference clip they were built from.
        est: The estimate laid out for the step.
        gt: ``(T, GT_DIM)`` ground-truth rows.
        amp: ``(T, A.FRAME_DIM)`` ground-truth AMP frames.
        truth: The ground truth laid out as an estimate (a privileged teacher's inputs), or
            ``None``.
    """

    clip: object
    est: O.EstimateFrames
    gt: np.ndarray
    amp: np.ndarray
    truth: O.EstimateFrames | None

    @property
    def nbytes(self) -> int:
        frames = [self.est] + ([self.truth] if self.truth is not None else [])
        return int(self.gt.nbytes + self.amp.nbytes
                   + sum(f.obs_rows.nbytes + f.target.nbytes for f in frames))  # fmt: skip


def build_clip_arrays(clip, kd_over_kp: np.ndarray, feedforward: bool,
                      teacher: bool) -> ClipArrays:  # fmt: skip
    """The arrays of ``clip`` (a :class:`grip.core.reference.ReferenceClip`) for a subject whose
    servos have ``kd_over_kp (69,)`` (s; the relative action's velocity feed-forward)."""
    t = clip.n_frames
    gt = np.empty((t, GT_DIM))
    gt[:, : GT_DIM // 2] = np.stack([clip.gt_pos, clip.gt_vel, clip.gt_angvel],
                                    axis=1).reshape(t, -1)  # fmt: skip
    gt[:, GT_DIM // 2 :] = clip.gt_rot.reshape(t, -1)
    est = O.EstimateFrames()
    est.update(clip, kd_over_kp, feedforward)
    truth = None
    if teacher:
        truth = O.EstimateFrames()
        truth.update(clip.oracle(), kd_over_kp, feedforward)
    return ClipArrays(clip, est, gt, A.reference_amp_features(clip), truth)


class ClipCache:
    """A bounded cache of :class:`ClipArrays` by ``(clip index, subject)``, the least recently
    used dropped first.

    Args:
        max_bytes: Bound on the arrays kept, bytes (one clip is always kept, whatever its
            size).
    """

    def __init__(self, max_bytes: int = DEFAULT_MAX_BYTES) -> None:
        self.max_bytes = int(max_bytes)
        self.nbytes = 0
        self.hits = self.misses = 0
        self._items: OrderedDict[Hashable, ClipArrays] = OrderedDict()

    def __len__(self) -> int:
        return len(self._items)

    def get(self, i: int, subject: Hashable, clip, kd_over_kp: np.ndarray, feedforward: bool,
            teacher: bool) -> ClipArrays:  # fmt: skip
        """The arrays of clip ``i`` (``clip``) for ``subject`` (built on a miss; see
        :func:`build_clip_arrays`)."""
        key = (i, subject, feedforward, teacher)
        got = self._items.get(key)
        if got is not None and got.clip is clip:
            self._items.move_to_end(key)
            self.hits += 1
            return got
        self.misses += 1
        if got is not None:
            self._drop(key)
        got = build_clip_arrays(clip, kd_over_kp, feedforward, teacher)
        self._items[key] = got
        self.nbytes += got.nbytes
        while self.nbytes > self.max_bytes and len(self._items) > 1:
            self._drop(next(iter(self._items)))
        return got

    def _drop(self, key: Hashable) -> None:
        self.nbytes -= self._items.pop(key).nbytes
