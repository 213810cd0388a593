"""Random pushes on the pelvis while the controller trains or distils (an experiment).

Measured, not adopted (docs/controller.md, "Random pushes" and run X ``policy_x28`` in "Two
more runs on T's lineage"; the pushes again from the shipped file's members; the
distillation's ``d4``): the library had it as ``push_force_n`` / ``push_every_s`` /
``push_duration_s`` up to commit 42da3e6.
This script reruns it without a library setting: it wraps every training environment in
:class:`RandomPushes` and hands the command its own environment constructor.

    python experiments/random_pushes.py --force-n 150 --every-s 3 --duration-s 0.2 -- \
        policy train --data DATA --out RUN --init E.pt --config configs/policy/finetune.toml
    python experiments/random_pushes.py --force-n 150 -- policy distill --data DATA --out RUN

Everything after ``--`` is a ``grip`` command line (``policy train`` or ``policy distill``).
Environments are built in the learner process (``ppo.vec_env = "dummy"``, the default recipe's);
with ``"subproc"`` the workers import this file by name, so run it from the repository root.
"""

from __future__ import annotations

import argparse
import functools
import sys

import gymnasium as gym
import numpy as np

import envs.factory
from envs.tracking_env import GripTrackingEnv
from envs.wrappers import ActionRepeat
from grip.core.reference_sets import load_reference, select_clips
from grip.task.config import TrackingEnvConfig


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


def make_pushed_env(env_cfg: TrackingEnvConfig, categories: tuple[str, ...], seed: int,
                    push: tuple[float, float, float]) -> gym.Env:  # fmt: skip
    """:func:`envs.factory.make_tracking_env` with :class:`RandomPushes` inside the action
    repeat (waits and pushes count frames); ``push`` = (force N, mean wait s, duration s), the
    pushes seeded ``seed + 7``."""
    ref = select_clips(load_reference(env_cfg.reference), categories)
    env: gym.Env = RandomPushes(GripTrackingEnv(env_cfg, ref), *push, seed=seed + 7)
    if env_cfg.action_repeat > 1:
        env = ActionRepeat(env, env_cfg.action_repeat)
    env.reset(seed=seed)
    return env


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    ours, grip_argv = (argv[: argv.index("--")], argv[argv.index("--") + 1 :]) if (
        "--" in argv) else (argv, [])  # fmt: skip
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                usage="%(prog)s [--force-n F] [--every-s S] [--duration-s S] "
                                "-- policy train|distill ...")  # fmt: skip
    p.add_argument("--force-n", type=float, default=150.0, help="largest push force, N")
    p.add_argument("--every-s", type=float, default=3.0, help="mean wait between pushes, s")
    p.add_argument("--duration-s", type=float, default=0.2, help="length of a push, s")
    args = p.parse_args(ours)
    if grip_argv[:2] not in (["policy", "train"], ["policy", "distill"]):
        p.error("after --: a 'grip policy train' or 'grip policy distill' command line")
    push = (args.force_n, args.every_s, args.duration_s)
    if min(push) <= 0:
        p.error("--force-n, --every-s and --duration-s must be > 0")
    # the commands look the constructor up in envs.factory when they run
    envs.factory.make_tracking_env = functools.partial(make_pushed_env, push=push)
    from grip.cli.main import main as grip_main

    return grip_main(grip_argv)


if __name__ == "__main__":
    sys.exit(main())
