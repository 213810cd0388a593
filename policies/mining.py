"""Hard-clip mining: sample the training clips the policy falls on more often.

PHC trains its imitation policy on the sequences it still fails more often than on those it has
mastered (hard-negative mining). This is the clip-level version for GRIP's training loop: the
trainer counts, per clip, the episodes that ended and those that ended in a failure (a
termination: a fall, or the stage-1 distance rule), with counts that decay after every rollout
so that the estimate follows the policy as it improves; the environments then start episodes on
clip ``i`` with probability proportional to its length times :meth:`ClipFailureStats.weights`.

The failure rate of a clip is shrunk towards the overall rate with a prior worth ``prior``
episodes, so a clip seen once does not jump to weight 0 or to the top. The weight mixes uniform
sampling with the failure-proportional one::

    f_i = (fails_i + prior * f) / (episodes_i + prior)      f = overall failure rate
    w_i = (1 - mix) + mix * f_i / f

``mix = 0`` is plain sampling by length (weights all 1); ``mix = 1`` samples in proportion to
the failure rate. Pure numpy; the state is a dict of plain lists keyed by clip name, so it goes
into the run's ``state.json``.

Within a clip, :class:`StartBinStats` does the same for the start frame: 1-second bins, the
failure rate of the episodes that reach each, and start weights that favour the bins where
episodes end in a failure (BeyondMimic's adaptive sampling, with rates instead of counts and a
decay set by the episodes per bin).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


class ClipFailureStats:
    """Decayed per-clip episode and failure counts, and the sampling weights they give.

    Args:
        names: Clip names, in the environments' clip order.
        mix: Share of failure-proportional sampling, in [0, 1].
        decay: Factor applied to all counts after each rollout, in (0, 1]; ``1 / (1 - decay)``
            rollouts is the memory of the estimate.
        prior: Weight of the overall failure rate in each clip's estimate, episodes (> 0).
    """

    def __init__(self, names: Sequence[str], mix: float, decay: float = 0.995,
                 prior: float = 2.0) -> None:  # fmt: skip
        if not 0.0 <= mix <= 1.0:
            raise ValueError(f"mining mix must be in [0, 1], got {mix}")
        if not 0.0 < decay <= 1.0:
            raise ValueError(f"mining decay must be in (0, 1], got {decay}")
        if not prior > 0:
            raise ValueError(f"mining prior must be > 0 episodes, got {prior}")
        self.names = list(names)
        if len(set(self.names)) != len(self.names):
            raise ValueError("clip names must be unique")
        self.mix, self.decay, self.prior = float(mix), float(decay), float(prior)
        self.episodes = np.zeros(len(self.names))
        self.fails = np.zeros(len(self.names))

    def add(self, clip_index: int, failed: bool) -> None:
        """Count one finished episode of clip ``clip_index``."""
        self.episodes[clip_index] += 1.0
        self.fails[clip_index] += float(failed)

    def end_rollout(self) -> None:
        """Decay all counts (once per rollout)."""
        self.episodes *= self.decay
        self.fails *= self.decay

    def failure_rates(self) -> np.ndarray:
        """``(n,)`` shrunk failure rate of every clip (the overall rate where nothing was seen)."""
        total = self.episodes.sum()
        f = self.fails.sum() / total if total > 0 else 0.0
        return (self.fails + self.prior * f) / (self.episodes + self.prior)

    def weights(self) -> np.ndarray:
        """``(n,)`` sampling weights (multiply the by-length probabilities); all 1 until a
        failure was seen or with ``mix = 0``."""
        total = self.episodes.sum()
        f = self.fails.sum() / total if total > 0 else 0.0
        if f <= 0.0 or self.mix == 0.0:
            return np.ones(len(self.names))
        return (1.0 - self.mix) + self.mix * self.failure_rates() / f

    def state_dict(self) -> dict:
        return {"names": list(self.names), "episodes": self.episodes.tolist(),
                "fails": self.fails.tolist()}  # fmt: skip

    def load_state_dict(self, state: dict) -> None:
        """Restore counts by clip name (clips unknown to this run are dropped, new ones start
        at zero), so a run resumed on a changed clip selection keeps what still applies."""
        idx = {n: i for i, n in enumerate(self.names)}
        self.episodes[:] = 0.0
        self.fails[:] = 0.0
        for name, e, k in zip(state["names"], state["episodes"], state["fails"], strict=True):
            i = idx.get(name)
            if i is not None:
                self.episodes[i], self.fails[i] = float(e), float(k)

    def hardest(self, k: int = 5) -> list[tuple[str, float, float]]:
        """The ``k`` clips with the highest shrunk failure rate: ``(name, rate, episodes)``."""
        rates = self.failure_rates()
        order = np.argsort(-rates, kind="stable")[:k]
        return [(self.names[i], float(rates[i]), float(self.episodes[i])) for i in order]


START_BIN_S = 1.0
"""Length of the bins of failure-weighted starts (:class:`StartBinStats`), s."""

MIN_BIN_DECAY = 0.5
"""The bins' counts never decay by more than this factor per rollout (a stage of few bins)."""


class StartBinStats:
    """Failure-weighted starts within each clip: per 1-second bin, decayed counts of the
    episodes that played through it and of the failures that ended in it, and the start
    weights they give.

    An episode that starts at frame ``s`` and ends at frame ``e`` counts once in every bin from
    ``s``'s to ``e``'s, and a failure (a termination) in ``e``'s bin: a bin's failure rate is
    the share of the episodes reaching it that end there. It is shrunk towards its clip's rate
    (itself shrunk towards the overall rate) with a prior worth ``prior`` episodes, so a bin
    seen once starts from its clip's rate. A clip's start weights mix uniform starts with
    failure-proportional ones::

        w_b = (1 - mix) + mix * f_b / f_clip        f_clip = the clip's rate

    and the environment draws a start bin with probability its start frames times ``w_b``
    (:func:`grip.core.reference_sets.start_bin_probabilities`), then a frame uniformly in it.

    The decay follows the data rather than the clock: after a rollout that added ``v`` episodes
    per bin on average, every count is multiplied by ``max(MIN_BIN_DECAY, 1 - v / memory)``, so
    an average bin's estimate remembers about ``memory`` episodes whatever the number of
    environments and of bins (16 environments on a thousand clips add about 0.02 episodes per
    bin per rollout: a memory of a few hundred rollouts; on one category's 14 clips about 1:
    ten rollouts).

    Args:
        names: Clip names, in the environments' clip order.
        n_frames: ``(C,)`` frames of each clip.
        bin_frames: Frames per bin (1 s of frames).
        mix: Share of failure-proportional starts, in [0, 1].
        memory: Episodes an average bin's estimate remembers (> 0).
        prior: Episodes' worth of the clip's (overall) rate in a bin's (clip's) estimate (> 0).
    """

    def __init__(self, names: Sequence[str], n_frames: Sequence[int], bin_frames: int,
                 mix: float, memory: float = 8.0, prior: float = 2.0) -> None:  # fmt: skip
        if not 0.0 <= mix <= 1.0:
            raise ValueError(f"start bin mix must be in [0, 1], got {mix}")
        if not memory > 0 or not prior > 0 or bin_frames < 1:
            raise ValueError("start bins need memory > 0, prior > 0 and bin_frames >= 1")
        self.names = list(names)
        if len(set(self.names)) != len(self.names) or len(n_frames) != len(self.names):
            raise ValueError("clip names must be unique, one length per clip")
        self.bin_frames = int(bin_frames)
        self.mix, self.memory, self.prior = float(mix), float(memory), float(prior)
        self.n_bins = np.maximum(1, -(-np.asarray(n_frames, dtype=np.int64) // self.bin_frames))
        self.offset = np.concatenate([[0], np.cumsum(self.n_bins)[:-1]]).astype(np.int64)
        self.clip_of_bin = np.repeat(np.arange(len(self.names)), self.n_bins)
        self.episodes = np.zeros(int(self.n_bins.sum()))  # decayed episodes through each bin
        self.fails = np.zeros(int(self.n_bins.sum()))  # decayed failures that ended in it
        self._added = 0.0  # episodes x bins added since the last decay
        self.last_decay = 1.0

    def add(self, clip_index, start, end, failed) -> None:
        """Count finished episodes (scalars or ``(E,)`` arrays): clip, start and end frame,
        and whether each failed."""
        c = np.atleast_1d(np.asarray(clip_index, dtype=np.int64))
        nb = self.n_bins[c]
        b0 = np.minimum(np.atleast_1d(np.asarray(start, dtype=np.int64)) // self.bin_frames,
                        nb - 1)  # fmt: skip
        b1 = np.clip(np.atleast_1d(np.asarray(end, dtype=np.int64)) // self.bin_frames, b0,
                     nb - 1)  # fmt: skip
        fail = np.atleast_1d(np.asarray(failed, dtype=bool))
        off = self.offset[c]
        for o, a, b in zip(off.tolist(), b0.tolist(), b1.tolist(), strict=True):
            self.episodes[o + a : o + b + 1] += 1.0
        np.add.at(self.fails, (off + b1)[fail], 1.0)
        self._added += float((b1 - b0 + 1).sum())

    def end_rollout(self) -> float:
        """Decay all counts once (after each rollout) by the data-driven factor; returns it."""
        v = self._added / len(self.episodes)
        d = max(MIN_BIN_DECAY, 1.0 - v / self.memory)
        self.episodes *= d
        self.fails *= d
        self._added = 0.0
        self.last_decay = d
        return d

    def clip_rates(self) -> np.ndarray:
        """``(C,)`` each clip's failure rate per episode through one of its bins, shrunk
        towards the overall rate."""
        total = self.episodes.sum()
        f = self.fails.sum() / total if total > 0 else 0.0
        c = len(self.names)
        e = np.bincount(self.clip_of_bin, self.episodes, minlength=c)
        k = np.bincount(self.clip_of_bin, self.fails, minlength=c)
        return (k + self.prior * f) / (e + self.prior)

    def bin_rates(self) -> np.ndarray:
        """``(sum of bins,)`` every bin's shrunk failure rate (clip ``c``'s bins from
        ``offset[c]``)."""
        fc = self.clip_rates()[self.clip_of_bin]
        return (self.fails + self.prior * fc) / (self.episodes + self.prior)

    def weights(self) -> list[np.ndarray]:
        """Per clip, ``(n_bins,)`` start weights (all 1 where its rate is 0, or ``mix = 0``)."""
        fb, fc = self.bin_rates(), self.clip_rates()
        out = []
        for i, (o, n) in enumerate(zip(self.offset.tolist(), self.n_bins.tolist(), strict=True)):
            if fc[i] <= 0.0 or self.mix == 0.0:
                out.append(np.ones(n))
            else:
                out.append((1.0 - self.mix) + self.mix * fb[o : o + n] / fc[i])
        return out

    def state_dict(self) -> dict:
        spans = list(zip(self.offset.tolist(), self.n_bins.tolist(), strict=True))
        return {"names": list(self.names), "bin_frames": self.bin_frames,
                "episodes": [self.episodes[o : o + n].tolist() for o, n in spans],
                "fails": [self.fails[o : o + n].tolist() for o, n in spans]}  # fmt: skip

    def load_state_dict(self, state: dict) -> None:
        """Restore counts by clip name: clips unknown to this run, of another number of bins
        or saved with other bins are dropped; the others' counts are restored."""
        self.episodes[:] = 0.0
        self.fails[:] = 0.0
        if int(state["bin_frames"]) != self.bin_frames:
            return
        idx = {n: i for i, n in enumerate(self.names)}
        for name, e, k in zip(state["names"], state["episodes"], state["fails"], strict=True):
            i = idx.get(name)
            if i is not None and len(e) == self.n_bins[i] == len(k):
                o = self.offset[i]
                self.episodes[o : o + len(e)] = e
                self.fails[o : o + len(k)] = k
