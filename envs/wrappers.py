"""Gymnasium wrappers of the tracking environment."""

from __future__ import annotations

import gymnasium as gym
import numpy as np


class ActionRepeat(gym.Wrapper):
    """The controller decides every ``k`` frames: one step of the wrapper plays the same action
    for ``k`` frames of the wrapped environment (fewer, stronger-acting decisions per second of
    motion: the PPO horizon in seconds and the motion covered by each sample both grow by
    ``k``).

    The reward is the mean of the ``k`` frame rewards and each ``reward/*`` term of ``info``
    the mean of its frame values, so rewards keep their per-frame scale. The step ends early at
    a termination or truncation. ``info`` is the last frame's with ``"frames"`` (frames played
    by this step) added; ``mpjpe_m`` stays the last frame's.

    With relative actions the PD target still follows the reference frame by frame; only the
    policy's correction is held (:class:`grip.pipeline.Player` holds it the same
    way at inference).
    """

    def __init__(self, env: gym.Env, k: int) -> None:
        super().__init__(env)
        if int(k) != k or k < 1:
            raise ValueError(f"action repeat must be a positive integer, got {k!r}")
        self.k = int(k)

    def step(self, action):
        total = 0.0
        sums: dict[str, float] = {}
        n = 0
        while n < self.k:
            obs, reward, terminated, truncated, info = self.env.step(action)
            n += 1
            total += float(reward)
            for key, v in info.items():
                if key.startswith("reward/"):
                    sums[key] = sums.get(key, 0.0) + float(v)
            if terminated or truncated:
                break
        info = dict(info)
        info.update({key: v / n for key, v in sums.items()})
        info["frames"] = n
        return obs, np.float64(total / n), terminated, truncated, info

