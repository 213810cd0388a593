"""The vector environments of DynamicsNet training and DAgger rollouts: the environment
constructor a trainer receives (:class:`EnvMaker`), the AMP style reward added to a rollout
(:class:`AmpReward`), each stage's vector env and its normaliser's state as plain arrays."""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, Protocol

import numpy as np
from stable_baselines3.common.vec_env import (
    DummyVecEnv,
    SubprocVecEnv,
    VecEnv,
    VecEnvWrapper,
    VecNormalize,
)

from grip.task.config import TrackingEnvConfig
from policies.amp import AmpTrainer
from policies.config import PolicyRunConfig, StageConfig


class EnvMaker(Protocol):
    """The environment constructor a trainer receives from the edge (SB3's ``PPO(policy, env)``
    receives its env the same way).

    ``make_env(env_cfg, categories, seed)`` returns one gymnasium environment, reset with
    ``seed``, that tracks the clips of ``categories`` (category globs; all when empty). The
    tracking env's is :func:`envs.factory.make_tracking_env`. It must pickle, for subprocess
    vector envs (a module-level function does). For ``ppo.vec_env = "batched"`` it also has
    an attribute ``batched(env_cfg, categories, seeds, threads)`` that returns the
    environments of all ``seeds`` as one batch (:class:`BatchedVecEnv`).
    """

    def __call__(self, env_cfg: TrackingEnvConfig, categories: tuple[str, ...],
                 seed: int) -> Any: ...  # fmt: skip


class BatchedVecEnv(VecEnv):
    """SB3 ``VecEnv`` over a batch of environments stepped by one call
    (``envs.batched.BatchedTrackingEnv``, which an :class:`EnvMaker`'s ``batched`` attribute
    builds): auto-reset with ``info["terminal_observation"]`` and ``"TimeLimit.truncated"``
    as :class:`DummyVecEnv` does, so both give the same rollouts.

    ``batch`` needs ``num_envs``, ``observation_space``, ``action_space``, ``envs`` (the
    environments, for ``get_attr``/``env_method``), ``step(actions) -> (obs dict of (N, ...),
    reward (N,), terminated (N,), truncated (N,), infos)``, ``reset(i, seed, options) ->
    (obs, info)`` and ``close()``.
    """

    def __init__(self, batch: Any) -> None:
        self.batch = batch
        self.envs = batch.envs
        super().__init__(batch.num_envs, batch.observation_space, batch.action_space)
        self._actions: np.ndarray | None = None

    def reset(self):
        n = self.num_envs
        obs = {k: np.zeros((n, *s.shape), s.dtype) for k, s in self.observation_space.items()}
        for i in range(n):
            o, self.reset_infos[i] = self.batch.reset(
                i, seed=self._seeds[i], options=self._options[i] or None
            )
            for k in obs:
                obs[k][i] = o[k]
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        obs, rew, term, trunc, infos = self.batch.step(self._actions)
        dones = term | trunc
        for i, info in enumerate(infos):
            info["TimeLimit.truncated"] = bool(trunc[i] and not term[i])
        for i in np.flatnonzero(dones).tolist():
            infos[i]["terminal_observation"] = {k: v[i].copy() for k, v in obs.items()}
            o, self.reset_infos[i] = self.batch.reset(i)
            for k in obs:
                obs[k][i] = o[k]
        return obs, rew.astype(np.float32), dones, infos

    def close(self) -> None:
        self.batch.close()

    def get_images(self):
        return [env.render() for env in self.envs]

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return [getattr(self.envs[i], attr_name) for i in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        for i in self._get_indices(indices):
            setattr(self.envs[i], attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None,
                   **method_kwargs) -> list[Any]:  # fmt: skip
        return [getattr(self.envs[i], method_name)(*method_args, **method_kwargs)
                for i in self._get_indices(indices)]  # fmt: skip

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]


class AmpReward(VecEnvWrapper):
    """Adds ``weight x r_amp`` of the discriminator to the environment reward and keeps the
    rollout's AMP windows for the discriminator's next update (``info["reward/amp"]`` is set).
    With AMP off (``amp.active`` false) neither: ``info["reward/amp"]`` is 0."""

    def __init__(self, venv: VecEnv, amp: AmpTrainer, weight: float) -> None:
        super().__init__(venv)
        self.amp, self.weight = amp, weight
        self._samples: list[np.ndarray] = []

    def reset(self):
        return self.venv.reset()

    def step_wait(self):
        obs, rew, dones, infos = self.venv.step_wait()
        if not self.amp.active:
            for info in infos:
                info["reward/amp"] = 0.0
            return obs, rew, dones, infos
        x = np.stack([info["amp_obs"] for info in infos])
        r = self.amp.reward(x)
        for info, ri in zip(infos, r, strict=True):
            info["reward/amp"] = float(ri)
        self._samples.append(x)
        return obs, rew + (self.weight * r).astype(rew.dtype), dones, infos

    def pop_samples(self) -> np.ndarray:
        x = np.concatenate(self._samples) if self._samples else np.zeros((0, 1), np.float32)
        self._samples = []
        return x


def make_vec_env(cfg: PolicyRunConfig, stage: StageConfig, reference: str, seed: int,
                 make_env: EnvMaker) -> VecEnv:  # fmt: skip
    """The vector env of one training stage: ``cfg.ppo.n_envs`` environments from
    ``make_env``, seeded ``seed``, ``seed + 1000``, ..."""
    env_cfg = cfg.env_config(stage, reference)
    if cfg.ppo.vec_env == "batched":
        batched = getattr(make_env, "batched", None)
        if batched is None:
            raise ValueError("ppo.vec_env = 'batched' needs an env maker with a 'batched' form "
                             "(envs.factory.make_tracking_env has one)")  # fmt: skip
        seeds = [seed + 1000 * i for i in range(cfg.ppo.n_envs)]
        return BatchedVecEnv(batched(env_cfg, stage.categories, seeds, cfg.ppo.env_threads))
    fns = [functools.partial(make_env, env_cfg, stage.categories, seed + 1000 * i)
           for i in range(cfg.ppo.n_envs)]  # fmt: skip
    if cfg.ppo.vec_env == "subproc" and cfg.ppo.n_envs > 1:
        return SubprocVecEnv(fns, start_method="forkserver")
    return DummyVecEnv(fns)


def stage2_rollout_env(make_env: EnvMaker, env_cfg: TrackingEnvConfig, reference: str,
                       categories: tuple[str, ...], n_envs: int, seed: int,
                       fall_height_m: float = 0.3, max_episode_frames: int = 1000,
                       fall_below_reference_m: float = 0.0) -> DummyVecEnv:  # fmt: skip
    """In-process environments from ``make_env`` that play GRIP's stage-2 episodes with an
    exported policy's settings (``env_cfg``, e.g. ``runner.env_cfg``): random starts on the
    clips of ``categories``, no distance termination, a pelvis below ``fall_height_m`` (and
    ``fall_below_reference_m`` below the truth's) ends an episode
    (:class:`policies.distill.Distiller`'s rollouts, ``benchmarks/policy_style.py``)."""
    cfg = dataclasses.replace(env_cfg, reference=str(reference), random_start=True,
                              clip_index=-1, termination_dist_m=0.0, fall_height_m=fall_height_m,
                              fall_below_reference_m=fall_below_reference_m,
                              max_episode_frames=max_episode_frames)  # fmt: skip
    return DummyVecEnv([functools.partial(make_env, cfg, tuple(categories), seed + 1000 * i)
                        for i in range(n_envs)])  # fmt: skip


def vecnorm_state(vn: VecNormalize) -> dict[str, np.ndarray]:
    """VecNormalize statistics as plain arrays (saved as npz, not as a pickle)."""
    out = {"ret_mean": vn.ret_rms.mean, "ret_var": vn.ret_rms.var, "ret_count": vn.ret_rms.count}
    for k, rms in vn.obs_rms.items():
        out[f"obs/{k}/mean"], out[f"obs/{k}/var"] = rms.mean, rms.var
        out[f"obs/{k}/count"] = np.array(rms.count)
    return {k: np.asarray(v, dtype=np.float64) for k, v in out.items()}


def load_vecnorm_state(vn: VecNormalize, state: dict[str, np.ndarray]) -> None:
    vn.ret_rms.mean, vn.ret_rms.var = state["ret_mean"], state["ret_var"]
    vn.ret_rms.count = float(state["ret_count"])
    for k, rms in vn.obs_rms.items():
        rms.mean, rms.var = state[f"obs/{k}/mean"], state[f"obs/{k}/var"]
        rms.count = float(state[f"obs/{k}/count"])
