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

from envs.config import TrackingEnvConfig
from policies.amp import AmpTrainer
from policies.config import PolicyRunConfig, StageConfig


class EnvMaker(Protocol):
    """The environment constructor a trainer receives from the edge (SB3's ``PPO(policy, env)``
    receives its env the same way).

    ``make_env(env_cfg, categories, seed)`` returns one gymnasium environment, reset with
    ``seed``, that tracks the clips of ``categories`` (category globs; all when empty). The
    tracking env's is :func:`envs.factory.make_tracking_env`. It must pickle, for subprocess
    vector envs (a module-level function does).
    """

    def __call__(self, env_cfg: TrackingEnvConfig, categories: tuple[str, ...],
                 seed: int) -> Any: ...  # fmt: skip


class AmpReward(VecEnvWrapper):
    """Adds ``weight x r_amp`` of the discriminator to the environment reward and keeps the
    rollout's AMP windows for the discriminator's next update (``info["reward/amp"]`` is set)."""

    def __init__(self, venv: VecEnv, amp: AmpTrainer, weight: float) -> None:
        super().__init__(venv)
        self.amp, self.weight = amp, weight
        self._samples: list[np.ndarray] = []

    def reset(self):
        return self.venv.reset()

    def step_wait(self):
        obs, rew, dones, infos = self.venv.step_wait()
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
    fns = [functools.partial(make_env, env_cfg, stage.categories, seed + 1000 * i)
           for i in range(cfg.ppo.n_envs)]  # fmt: skip
    if cfg.ppo.vec_env == "subproc" and cfg.ppo.n_envs > 1:
        return SubprocVecEnv(fns, start_method="forkserver")
    return DummyVecEnv(fns)


def stage2_rollout_env(make_env: EnvMaker, env_cfg: TrackingEnvConfig, reference: str,
                       categories: tuple[str, ...], n_envs: int, seed: int,
                       fall_height_m: float = 0.3,
                       max_episode_frames: int = 1000) -> DummyVecEnv:  # fmt: skip
    """In-process environments from ``make_env`` that play GRIP's stage-2 episodes with an
    exported policy's settings (``env_cfg``, e.g. ``runner.env_cfg``): random starts on the
    clips of ``categories``, no distance termination, a pelvis below ``fall_height_m`` ends an
    episode (:class:`policies.distill.Distiller`'s rollouts, ``benchmarks/policy_style.py``)."""
    cfg = dataclasses.replace(env_cfg, reference=str(reference), random_start=True,
                              clip_index=-1, termination_dist_m=0.0, fall_height_m=fall_height_m,
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
