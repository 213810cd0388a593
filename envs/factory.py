"""The tracking environment's constructor, as the edge hands it to the learners.

SB3's ``PPO(policy, env)`` receives its environment and never imports one; so do
:class:`policies.train.PolicyTrainer` and :class:`policies.distill.Distiller`. The edge
(``grip train-policy``, ``grip distill-policy``, tests and benchmarks) passes
:func:`make_tracking_env`, and the learners call it once per vector-env slot.
"""

from __future__ import annotations

import gymnasium as gym

from envs.config import TrackingEnvConfig
from envs.tracking_env import GripTrackingEnv
from envs.wrappers import ActionRepeat, RandomPushes
from grip.core.reference_sets import load_reference, select_clips


def make_tracking_env(env_cfg: TrackingEnvConfig, categories: tuple[str, ...], seed: int,
                      push: tuple[float, float, float] | None = None) -> gym.Env:  # fmt: skip
    """One training environment, reset with ``seed``.

    Args:
        env_cfg: Settings; ``env_cfg.reference`` names the reference set (``.npz``), loaded once
            per process (:func:`grip.core.reference_sets.load_reference`).
        categories: Category globs of the clips to track (all when empty).
        seed: Seed of the first reset (and of the pushes, offset by 7).
        push: :class:`~envs.wrappers.RandomPushes`' ``(force N, mean wait s, duration s)``;
            ``None``: no pushes.

    Returns:
        :class:`~envs.tracking_env.GripTrackingEnv`, wrapped in the pushes and in
        :class:`~envs.wrappers.ActionRepeat` when ``env_cfg.action_repeat > 1``.
    """
    ref = select_clips(load_reference(env_cfg.reference), categories)
    env: gym.Env = GripTrackingEnv(env_cfg, ref)
    if push is not None:
        env = RandomPushes(env, *push, seed=seed + 7)
    if env_cfg.action_repeat > 1:
        env = ActionRepeat(env, env_cfg.action_repeat)
    env.reset(seed=seed)
    return env
