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


class RandomPushes(gym.Wrapper):
    """Random horizontal pushes on the pelvis while the controller trains: a body pushed off
    its reference has to catch itself (a step, a lean), which following the reference alone
    never asks for. Inference never wraps its environment in this.

    A push starts after a wait drawn from an exponential distribution of mean ``every_s``
    (counted from the end of the previous push, or from the reset), lasts ``duration_s`` and
    applies a constant force in a uniformly random horizontal direction, of magnitude uniform in
    ``[force_n / 2, force_n]``, at the pelvis' centre of mass
    (:meth:`envs.tracking_env.GripTrackingEnv.push_pelvis`). It wraps the per-frame
    environment (inside :class:`ActionRepeat`), so waits and durations count frames.
    ``info["push_n"]`` holds the force applied during the step, N.

    Args:
        env: A :class:`envs.tracking_env.GripTrackingEnv` (or a wrapper of one).
        force_n: Largest force, N (> 0).
        every_s: Mean wait between pushes, s (> 0).
        duration_s: Length of a push, s (> 0; at least one frame).
        seed: Seed of the pushes' own random generator.
    """

    def __init__(self, env: gym.Env, force_n: float, every_s: float, duration_s: float,
                 seed: int | None = None) -> None:  # fmt: skip
        super().__init__(env)
        if not (force_n > 0 and every_s > 0 and duration_s > 0):
            raise ValueError("RandomPushes: force_n, every_s and duration_s must be > 0, got "
                             f"{force_n}, {every_s}, {duration_s}")  # fmt: skip
        self.force_n, self.every_s = float(force_n), float(every_s)
        self._dt = float(env.unwrapped.cfg.control_dt_s)
        self._frames = max(1, round(duration_s / self._dt))
        self._rng = np.random.default_rng(seed)
        self._force = self._none = np.zeros(3)
        self._left = 0
        self._wait = self._draw_wait()

    def _draw_wait(self) -> int:
        return max(1, round(self._rng.exponential(self.every_s) / self._dt))

    def reset(self, **kwargs):
        self._left, self._wait = 0, self._draw_wait()
        return self.env.reset(**kwargs)

    def step(self, action):
        if self._left == 0:
            self._wait -= 1
            if self._wait <= 0:
                ang = self._rng.uniform(0.0, 2.0 * np.pi)
                mag = self.force_n * self._rng.uniform(0.5, 1.0)
                self._force = np.array([mag * np.cos(ang), mag * np.sin(ang), 0.0])
                self._left, self._wait = self._frames, self._draw_wait()
        force = self._force if self._left > 0 else self._none
        self.env.unwrapped.push_pelvis(force)
        self._left = max(self._left - 1, 0)
        obs, reward, terminated, truncated, info = self.env.step(action)
        info["push_n"] = float(np.linalg.norm(force))
        return obs, reward, terminated, truncated, info
