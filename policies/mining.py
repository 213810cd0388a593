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
