"""Device twins of stable-baselines3's rollout buffer and ``VecNormalize`` statistics.

:class:`DeviceRolloutBuffer` is SB3's ``DictRolloutBuffer`` with its arrays as torch tensors on
the learner's device, so that ``PPO.train()`` (unchanged) draws its minibatches without a copy
from the host. :class:`DeviceVecNormalize` keeps ``VecNormalize``'s running statistics (the
same update and the same formulas) as device tensors; its ``obs_rms`` / ``ret_rms`` entries show
``mean``, ``var`` and ``count`` as numpy values, so that the CPU trainer's checkpoint and
warm-start code (:func:`policies.vec_env.vecnorm_state`, :func:`policies.vec_env.
load_vecnorm_state`, :meth:`policies.train.PolicyTrainer.warm_start`) reads and writes them
unchanged, and the exported file is the CPU path's.

Shapes: N environments, T = ``n_steps`` decisions per rollout.
"""

from __future__ import annotations

from collections.abc import Generator, Mapping

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.buffers import DictRolloutBuffer
from stable_baselines3.common.type_aliases import DictRolloutBufferSamples

NORM_EPS = 1e-8
"""``VecNormalize``'s epsilon: ``(x - mean) / sqrt(var + eps)``."""
REWARD_CLIP = 10.0
"""``VecNormalize``'s ``clip_reward`` default (the CPU trainer keeps it)."""


class DeviceRunningMeanStd:
    """SB3's ``RunningMeanStd`` (parallel mean and variance, float64) on a torch device.

    ``mean``, ``var`` and ``count`` read as numpy copies and accept numpy values, as the
    SB3 object's attributes do; the tensors are ``mean_t`` and ``var_t``.
    """

    def __init__(self, shape: tuple[int, ...], device: torch.device,
                 epsilon: float = 1e-4) -> None:  # fmt: skip
        self.device = device
        self.mean_t = torch.zeros(shape, dtype=torch.float64, device=device)
        self.var_t = torch.ones(shape, dtype=torch.float64, device=device)
        self._count = float(epsilon)

    @property
    def mean(self) -> np.ndarray:
        return self.mean_t.cpu().numpy()

    @mean.setter
    def mean(self, value) -> None:
        self.mean_t = torch.as_tensor(np.asarray(value), dtype=torch.float64,
                                      device=self.device).clone()  # fmt: skip

    @property
    def var(self) -> np.ndarray:
        return self.var_t.cpu().numpy()

    @var.setter
    def var(self, value) -> None:
        self.var_t = torch.as_tensor(np.asarray(value), dtype=torch.float64,
                                     device=self.device).clone()  # fmt: skip

    @property
    def count(self) -> float:
        return self._count

    @count.setter
    def count(self, value) -> None:
        self._count = float(value)

    @torch.no_grad()
    def update(self, x: torch.Tensor) -> None:
        """Add a batch ``(B, *shape)`` (SB3's ``update_from_moments``: population variance)."""
        x = x.to(torch.float64)
        n = x.shape[0]
        if n == 0:
            return
        b_mean, b_var = x.mean(0), x.var(0, unbiased=False)
        delta = b_mean - self.mean_t
        tot = self._count + n
        self.mean_t = self.mean_t + delta * (n / tot)
        m2 = self.var_t * self._count + b_var * n + delta.square() * (self._count * n / tot)
        self.var_t = m2 / tot
        self._count = tot


class DeviceVecNormalize:
    """``VecNormalize(norm_obs=True, norm_reward=..., clip_obs=..., gamma=...)``'s statistics
    and formulas on a torch device, for a batch of N environments.

    Args:
        obs_shapes: Observation part -> shape, in the observation space's order.
        num_envs: N.
        device: The torch device.
        norm_reward: Scale rewards by the running std of the discounted return.
        clip_obs: Normalised observations are clipped to +- this.
        gamma: Discount of the return whose std scales the rewards.
    """

    def __init__(self, obs_shapes: Mapping[str, tuple[int, ...]], num_envs: int,
                 device: torch.device, norm_reward: bool, clip_obs: float,
                 gamma: float) -> None:  # fmt: skip
        self.obs_rms = {k: DeviceRunningMeanStd(tuple(s), device) for k, s in obs_shapes.items()}
        self.ret_rms = DeviceRunningMeanStd((), device)
        self.norm_reward, self.clip_obs, self.gamma = norm_reward, float(clip_obs), float(gamma)
        self.returns = torch.zeros(num_envs, dtype=torch.float64, device=device)
        self.training = True

    def update_obs(self, obs: Mapping[str, torch.Tensor]) -> None:
        """Add raw observations to the statistics (while training)."""
        if self.training:
            for k, rms in self.obs_rms.items():
                rms.update(obs[k])

    def normalize_obs(self, obs: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """``clip((obs - mean) / sqrt(var + eps), -clip_obs, clip_obs)`` per part, float32."""
        out = {}
        for k, rms in self.obs_rms.items():
            x = (obs[k].to(torch.float64) - rms.mean_t) / torch.sqrt(rms.var_t + NORM_EPS)
            out[k] = x.clamp(-self.clip_obs, self.clip_obs).to(torch.float32)
        return out

    def normalize_reward(self, reward: torch.Tensor, dones: torch.Tensor) -> torch.Tensor:
        """``VecNormalize.step_wait``'s reward: update the discounted returns and their
        statistics, scale, clip; the returns of ended episodes restart at 0. ``(N,)``."""
        if not self.norm_reward:
            return reward.to(torch.float32)
        r = reward.to(torch.float64)
        if self.training:
            self.returns = self.returns * self.gamma + r
            self.ret_rms.update(self.returns)
        out = (r / torch.sqrt(self.ret_rms.var_t + NORM_EPS)).clamp(-REWARD_CLIP, REWARD_CLIP)
        self.returns = torch.where(dones, torch.zeros_like(self.returns), self.returns)
        return out.to(torch.float32)

    def close(self) -> None:
        """Nothing to release (the trainer closes its env itself); kept for the trainer."""


class DeviceRolloutBuffer(DictRolloutBuffer):
    """SB3's ``DictRolloutBuffer`` with its arrays as tensors on ``device``: ``add`` takes
    tensors, GAE runs in torch and ``get`` yields minibatches of device tensors, drawn from a
    ``torch.Generator`` (:meth:`seed`). ``values`` and ``returns`` read as numpy copies (for
    the explained variance of ``PPO.train()``); the tensors are ``values_t``, ``returns_t``.
    """

    def __init__(self, buffer_size: int, observation_space: spaces.Dict,
                 action_space: spaces.Space, device: torch.device | str = "cpu",
                 gae_lambda: float = 1.0, gamma: float = 0.99,
                 n_envs: int = 1) -> None:  # fmt: skip
        self._gen: torch.Generator | None = None
        super().__init__(buffer_size, observation_space, action_space, device, gae_lambda, gamma,
                         n_envs)  # fmt: skip

    def seed(self, seed: int) -> None:
        """Seed the minibatch permutations."""
        self._gen = torch.Generator(device=self.device)
        self._gen.manual_seed(int(seed))

    @property
    def values(self) -> np.ndarray:
        return self.values_t.cpu().numpy()

    @property
    def returns(self) -> np.ndarray:
        return self.returns_t.cpu().numpy()

    def reset(self) -> None:
        t, n, dev = self.buffer_size, self.n_envs, self.device
        f32 = dict(dtype=torch.float32, device=dev)
        self.observations = {k: torch.zeros((t, n, *s), **f32) for k, s in self.obs_shape.items()}
        self.actions = torch.zeros((t, n, self.action_dim), **f32)
        self.rewards = torch.zeros((t, n), **f32)
        self.returns_t = torch.zeros((t, n), **f32)
        self.episode_starts = torch.zeros((t, n), **f32)
        self.values_t = torch.zeros((t, n), **f32)
        self.log_probs = torch.zeros((t, n), **f32)
        self.advantages = torch.zeros((t, n), **f32)
        self.generator_ready = False
        self.pos = 0
        self.full = False

    def add(self, obs: Mapping[str, torch.Tensor], action: torch.Tensor, reward: torch.Tensor,
            episode_start: torch.Tensor, value: torch.Tensor,
            log_prob: torch.Tensor) -> None:  # fmt: skip
        """One decision of every environment (``(N, ...)`` tensors; ``value (N, 1)``)."""
        p = self.pos
        for k in self.observations:
            self.observations[k][p] = obs[k]
        self.actions[p] = action.reshape(self.n_envs, self.action_dim)
        self.rewards[p] = reward
        self.episode_starts[p] = episode_start.to(torch.float32)
        self.values_t[p] = value.reshape(-1)
        self.log_probs[p] = log_prob.reshape(-1)
        self.pos += 1
        if self.pos == self.buffer_size:
            self.full = True

    @torch.no_grad()
    def compute_returns_and_advantage(self, last_values: torch.Tensor,
                                      dones: torch.Tensor) -> None:  # fmt: skip
        """GAE(lambda) as SB3 computes it (``last_values (N, 1)``, ``dones (N,)`` bool)."""
        last = last_values.reshape(-1).to(torch.float32)
        gae = torch.zeros_like(last)
        for step in reversed(range(self.buffer_size)):
            if step == self.buffer_size - 1:
                non_terminal = 1.0 - dones.to(torch.float32)
                next_values = last
            else:
                non_terminal = 1.0 - self.episode_starts[step + 1]
                next_values = self.values_t[step + 1]
            delta = (self.rewards[step] + self.gamma * next_values * non_terminal
                     - self.values_t[step])  # fmt: skip
            gae = delta + self.gamma * self.gae_lambda * non_terminal * gae
            self.advantages[step] = gae
        self.returns_t = self.advantages + self.values_t

    def get(self, batch_size: int | None = None
            ) -> Generator[DictRolloutBufferSamples, None, None]:  # fmt: skip
        if not self.full:
            raise RuntimeError("DeviceRolloutBuffer.get: the rollout is not complete")
        total = self.buffer_size * self.n_envs
        idx = torch.randperm(total, generator=self._gen, device=self.device)
        if not self.generator_ready:
            self.observations = {k: self._flat(v) for k, v in self.observations.items()}
            self.actions = self._flat(self.actions)
            self.values_t = self._flat(self.values_t)
            self.log_probs = self._flat(self.log_probs)
            self.advantages = self._flat(self.advantages)
            self.returns_t = self._flat(self.returns_t)
            self.generator_ready = True
        batch_size = batch_size or total
        for start in range(0, total, batch_size):
            yield self._get_samples(idx[start : start + batch_size])

    @staticmethod
    def _flat(x: torch.Tensor) -> torch.Tensor:
        """``(T, N, ...)`` -> ``(T * N, ...)``, environment-major (SB3's ``swap_and_flatten``)."""
        return x.transpose(0, 1).reshape(-1, *x.shape[2:])

    def _get_samples(self, batch_inds: torch.Tensor, env=None) -> DictRolloutBufferSamples:
        return DictRolloutBufferSamples(
            observations={k: v[batch_inds] for k, v in self.observations.items()},
            actions=self.actions[batch_inds],
            old_values=self.values_t[batch_inds].flatten(),
            old_log_prob=self.log_probs[batch_inds].flatten(),
            advantages=self.advantages[batch_inds].flatten(),
            returns=self.returns_t[batch_inds].flatten(),
        )
