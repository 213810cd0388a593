"""The tracking environment's constructor, as the edge hands it to the learners.

SB3's ``PPO(policy, env)`` receives its environment and never imports one; so do
:class:`policies.train.PolicyTrainer` and :class:`policies.distill.Distiller`. The edge
(``grip policy train``, ``grip policy distill``, tests and benchmarks) passes
:func:`make_tracking_env`, and the learners call it once per vector-env slot.
"""

from __future__ import annotations

import gymnasium as gym

from envs.batched import BatchedTrackingEnv
from envs.clip_cache import ClipCache
from envs.tracking_env import GripTrackingEnv
from envs.wrappers import ActionRepeat
from grip.core.reference_sets import load_reference, select_clips
from grip.task.config import TrackingEnvConfig


def make_tracking_env(env_cfg: TrackingEnvConfig, categories: tuple[str, ...],
                      seed: int) -> gym.Env:  # fmt: skip
    """One training environment, reset with ``seed``.

    Args:
        env_cfg: Settings; ``env_cfg.reference`` names the reference set (``.npz``), loaded once
            per process (:func:`grip.core.reference_sets.load_reference`).
        categories: Category globs of the clips to track (all when empty).
        seed: Seed of the first reset.

    Returns:
        :class:`~envs.tracking_env.GripTrackingEnv`, wrapped in
        :class:`~envs.wrappers.ActionRepeat` when ``env_cfg.action_repeat > 1``.
    """
    ref = select_clips(load_reference(env_cfg.reference), categories)
    env: gym.Env = GripTrackingEnv(env_cfg, ref)
    if env_cfg.action_repeat > 1:
        env = ActionRepeat(env, env_cfg.action_repeat)
    env.reset(seed=seed)
    return env


def make_batched_tracking_env(
    env_cfg: TrackingEnvConfig, categories: tuple[str, ...], seeds: list[int], threads: int = 0
) -> BatchedTrackingEnv:
    """``len(seeds)`` training environments stepped together (:class:`~envs.batched.
    BatchedTrackingEnv`), environment ``i`` reset with ``seeds[i]``: the same transitions as
    ``make_tracking_env(env_cfg, categories, seeds[i])`` for each. ``threads``: physics threads
    (0: the cores this process may use)."""
    ref = select_clips(load_reference(env_cfg.reference), categories)
    envs, compiled, clips = [], {}, ClipCache()
    for seed in seeds:
        env = GripTrackingEnv(env_cfg, ref, compiled_models=compiled, clip_cache=clips)
        env.reset(seed=seed)
        envs.append(env)
    return BatchedTrackingEnv(envs, threads)


make_tracking_env.batched = make_batched_tracking_env  # type: ignore[attr-defined]
"""The batched form a trainer's ``make_vec_env`` uses with ``ppo.vec_env = "batched"``
(:class:`policies.vec_env.EnvMaker`)."""
