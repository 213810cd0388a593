"""The curricula over one training stage's clips that the CPU and device trainers share.

:class:`StageCurriculum` holds, for the stage's clips (in the environments' clip order), what
the trainer learns from the episodes that end and hands to the environments after each rollout:

- hard-clip mining (``mining_mix``, :class:`policies.mining.ClipFailureStats`): clip weights,
  ``set_clip_weights``;
- failure-weighted starts within each clip (``mining_bins_mix``,
  :class:`policies.mining.StartBinStats`): per-clip bin weights, ``set_start_bin_weights``;
- a termination distance per category (``termination_category_min_m``,
  :class:`CategoryTermination`): one distance per clip, ``set_clip_termination_dists``;
- the probability of each clip of the run's reference set that the discriminator's real windows
  follow (``amp.real_sampling = "episodes"``): the episodes' clip probabilities
  (:func:`grip.core.reference_sets.clip_probabilities`), zero outside the stage.

Its state goes into the run's ``state.json`` (``"mining"`` as before, ``"start_bins"``,
``"termination"``), each with the stage it belongs to, and is restored on resume. Pure numpy.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from grip.core.reference import ReferenceClip
from grip.core.reference_sets import clip_probabilities
from policies.config import StageConfig
from policies.mining import START_BIN_S, ClipFailureStats, StartBinStats

TERMINATION_MEMORY = 10.0
"""Episodes of a category that its share of episodes reaching their limit is judged on
(:class:`CategoryTermination`): after a rollout with ``n`` of its episodes its counts decay by
``max(0.5, 1 - n / 10)``, so a category of 40 episodes a rollout is judged on about its last
two rollouts and one of 0.5 on about its last twenty."""

TERMINATION_MIN_EPISODES = 4.0
"""Decayed episodes a category needs before its distance moves (a rare category's share of a
rollout or two is noise)."""


class CategoryTermination:
    """A termination distance per motion category, driven by how its episodes end (PBHC's
    and ASAP's termination curricula, per category).

    After each rollout, a category that had episodes in it and has at least
    :data:`TERMINATION_MIN_EPISODES` (decayed) episodes, whose share of episodes that reached
    their length limit (truncated, not terminated) is above ``band[1]``, gets a distance
    ``(1 - step)`` times tighter, below ``band[0]`` ``(1 + step)`` times looser, always within
    ``[min_m, max_m]``. The counts then decay by the category's new episodes (memory
    ``memory`` episodes, :data:`TERMINATION_MEMORY`), so rare and common categories are judged
    on as many episodes.

    Args:
        clip_categories: ``(C,)`` each clip's category, in the environments' clip order.
        start_m: The starting distance of every category (clamped into the bounds).
        min_m, max_m: Bounds of the distance, m (``0 < min_m <= max_m``).
        band: ``(low, high)`` shares of episodes that reached their limit.
        step: Relative change per rollout, in (0, 1).
        memory: Episodes a category is judged on (> 0).
    """

    def __init__(self, clip_categories: Sequence[str], start_m: float, min_m: float,
                 max_m: float, band: tuple[float, float], step: float,
                 memory: float = TERMINATION_MEMORY) -> None:  # fmt: skip
        if not 0 < min_m <= max_m or not 0 < step < 1 or not memory > 0:
            raise ValueError("category termination needs 0 < min_m <= max_m, 0 < step < 1, "
                             "memory > 0")  # fmt: skip
        self.categories = list(dict.fromkeys(clip_categories))
        index = {c: i for i, c in enumerate(self.categories)}
        self.clip_category = np.array([index[c] for c in clip_categories], dtype=np.int64)
        self.min_m, self.max_m = float(min_m), float(max_m)
        self.band, self.step = (float(band[0]), float(band[1])), float(step)
        self.memory = float(memory)
        k = len(self.categories)
        self.dist_m = np.full(k, float(np.clip(start_m, self.min_m, self.max_m)))
        self.episodes = np.zeros(k)
        self.reached = np.zeros(k)
        self._new = np.zeros(k)  # episodes since the last end_rollout

    def add(self, clip_index, reached) -> None:
        """Count finished episodes (scalars or ``(E,)`` arrays): clip and whether each reached
        its length limit."""
        cat = self.clip_category[np.atleast_1d(np.asarray(clip_index, dtype=np.int64))]
        np.add.at(self.episodes, cat, 1.0)
        np.add.at(self._new, cat, 1.0)
        np.add.at(self.reached, cat, np.atleast_1d(np.asarray(reached, dtype=np.float64)))

    def end_rollout(self) -> None:
        """Move the distance of each category that had episodes, then decay its counts."""
        seen = (self.episodes >= TERMINATION_MIN_EPISODES) & (self._new > 0)
        share = self.reached / np.maximum(self.episodes, 1e-12)
        tighten = seen & (share > self.band[1])
        loosen = seen & (share < self.band[0])
        self.dist_m[tighten] *= 1.0 - self.step
        self.dist_m[loosen] *= 1.0 + self.step
        np.clip(self.dist_m, self.min_m, self.max_m, out=self.dist_m)
        d = np.maximum(0.5, 1.0 - self._new / self.memory)
        self.episodes *= d
        self.reached *= d
        self._new[:] = 0.0

    def clip_dists(self) -> np.ndarray:
        """``(C,)`` the distance of each clip's category, m."""
        return self.dist_m[self.clip_category]

    def by_category(self) -> dict[str, float]:
        return dict(zip(self.categories, self.dist_m.tolist(), strict=True))

    def state_dict(self) -> dict:
        return {"categories": list(self.categories), "dist_m": self.dist_m.tolist(),
                "episodes": self.episodes.tolist(), "reached": self.reached.tolist()}  # fmt: skip

    def load_state_dict(self, state: dict) -> None:
        """Restore by category name (categories unknown to this run are dropped; new ones keep
        their start); distances are clamped into this run's bounds."""
        index = {c: i for i, c in enumerate(self.categories)}
        for c, d, e, r in zip(state["categories"], state["dist_m"], state["episodes"],
                              state["reached"], strict=True):  # fmt: skip
            i = index.get(c)
            if i is not None:
                self.dist_m[i] = float(np.clip(d, self.min_m, self.max_m))
                self.episodes[i], self.reached[i] = float(e), float(r)


class StageCurriculum:
    """One stage's clip bookkeeping: mining, start bins, per-category termination, real-window
    probabilities (see the module docstring).

    Args:
        stage: The stage's settings.
        clips: The stage's clips, in the environments' order.
        real_index: ``(C,)`` each clip's index in the run's reference set (the discriminator's
            real clips, :class:`policies.amp.RealSampler`).
        n_real: Clips in the run's reference set.
        fps: Frames per second of the clips (the env's control rate).
        start_dist_m: The stage's termination distance when it starts (its curriculum's).
    """

    def __init__(self, stage: StageConfig, clips: Sequence[ReferenceClip],
                 real_index: Sequence[int], n_real: int, fps: float,
                 start_dist_m: float) -> None:  # fmt: skip
        self.names = [c.name for c in clips]
        self.categories = [c.category for c in clips]
        self.lengths = np.array([c.n_frames for c in clips], dtype=np.float64)
        self.real_index = np.asarray(real_index, dtype=np.int64)
        self.n_real = int(n_real)
        self.bin_frames = max(1, round(START_BIN_S * fps))
        self.mining: ClipFailureStats | None = None
        self.bins: StartBinStats | None = None
        self.termination: CategoryTermination | None = None
        if stage.mining_mix > 0:
            self.mining = ClipFailureStats(self.names, stage.mining_mix, stage.mining_decay,
                                           stage.mining_prior)  # fmt: skip
        if stage.mining_bins_mix > 0:
            self.bins = StartBinStats(self.names, self.lengths.astype(np.int64), self.bin_frames,
                                      stage.mining_bins_mix, stage.mining_bins_memory,
                                      stage.mining_prior)  # fmt: skip
        if stage.termination_category_min_m > 0:
            start = start_dist_m if start_dist_m > 0 else stage.termination_category_max_m
            self.termination = CategoryTermination(
                self.categories, start, stage.termination_category_min_m,
                stage.termination_category_max_m, stage.termination_category_band,
                stage.termination_category_step)  # fmt: skip

    @property
    def needs_episodes(self) -> bool:
        """Whether :meth:`add` needs each episode's frames (start bins) or its clip
        (per-category termination), beyond the per-clip counts of mining."""
        return self.bins is not None or self.termination is not None

    # ------------------------------------------------------------------ episodes
    def add(self, clip_index, start, end, failed, mining: bool = True) -> None:
        """Count finished episodes (scalars or ``(E,)`` arrays): clip, start and end frame, and
        whether each failed (a termination, not a truncation); ``mining`` false: not for
        mining (its per-clip counts came by :meth:`add_clip_counts`)."""
        c = np.atleast_1d(np.asarray(clip_index, dtype=np.int64))
        fail = np.atleast_1d(np.asarray(failed, dtype=bool))
        if mining and self.mining is not None:
            self.add_clip_counts(np.bincount(c, minlength=len(self.names)),
                                 np.bincount(c[fail], minlength=len(self.names)))  # fmt: skip
        if self.bins is not None:
            self.bins.add(c, np.maximum(np.atleast_1d(start), 0), end, fail)
        if self.termination is not None:
            self.termination.add(c, ~fail)

    def add_clip_counts(self, ended: np.ndarray, failed: np.ndarray) -> None:
        """Count finished episodes for mining by clip: ``(C,)`` the episodes that ended and
        those that failed (what :meth:`policies.mining.ClipFailureStats.add` of each would
        count)."""
        if self.mining is not None:
            self.mining.episodes += ended
            self.mining.fails += failed

    def end_rollout(self) -> dict[str, float]:
        """Decay and update everything once (after each rollout).

        Returns:
            Scalars to log (``"mining/..."``, ``"termination/..."``).
        """
        log: dict[str, float] = {}
        if self.mining is not None:
            self.mining.end_rollout()
            w = self.mining.weights()
            log["mining/max_weight"], log["mining/min_weight"] = float(w.max()), float(w.min())
        if self.bins is not None:
            log["mining/bins_decay"] = self.bins.end_rollout()
            w = np.concatenate(self.bins.weights())
            log["mining/bins_max_weight"] = float(w.max())
        if self.termination is not None:
            self.termination.end_rollout()
            d = self.termination.dist_m
            log["termination/min_m"], log["termination/max_m"] = float(d.min()), float(d.max())
        return log

    # ------------------------------------------------------------------ what the envs get
    def clip_weights(self) -> np.ndarray:
        """``(C,)`` the clip weights (mining's; all 1 without)."""
        return self.mining.weights() if self.mining is not None else np.ones(len(self.names))

    def real_probabilities(self) -> np.ndarray:
        """``(n_real,)`` the probability of each clip of the run's reference set that an
        episode starts on it (zero outside the stage)."""
        p = np.zeros(self.n_real)
        p[self.real_index] = clip_probabilities(self.lengths, self.clip_weights())
        return p

    def termination_m(self) -> float | None:
        """The mean per-category distance over the stage's clips by length (what the history
        row's ``termination_m`` shows); ``None`` without per-category termination."""
        if self.termination is None:
            return None
        return float(np.average(self.termination.clip_dists(), weights=self.lengths))

    def termination_by_category(self) -> dict[str, float] | None:
        """``{category: distance m}`` (``None`` without per-category termination)."""
        return None if self.termination is None else self.termination.by_category()

    def push(self, call: Callable[..., object]) -> None:
        """Hand the environments their settings: ``call(method_name, *args)`` for
        ``set_clip_weights`` (mining), ``set_start_bin_weights`` and
        ``set_clip_termination_dists``, each only when its curriculum is on."""
        if self.mining is not None:
            call("set_clip_weights", self.mining.weights())
        if self.bins is not None:
            call("set_start_bin_weights", self.bin_frames, self.bins.weights())
        if self.termination is not None:
            call("set_clip_termination_dists", self.termination.clip_dists())

    # ------------------------------------------------------------------ checkpoint
    def state(self, stage_index: int) -> dict:
        """The ``state.json`` entries of the curricula that are on, tagged with the stage."""
        out = {}
        for key, part in (("mining", self.mining), ("start_bins", self.bins),
                          ("termination", self.termination)):  # fmt: skip
            if part is not None:
                out[key] = {"stage_index": stage_index, **part.state_dict()}
        return out

    def restore(self, state: dict | None, stage_index: int) -> None:
        """Take the counts of a checkpoint's ``state.json`` that belong to this stage."""
        if not state:
            return
        for key, part in (("mining", self.mining), ("start_bins", self.bins),
                          ("termination", self.termination)):  # fmt: skip
            saved = state.get(key)
            if part is not None and saved is not None and saved.get("stage_index") == stage_index:
                part.load_state_dict(saved)
