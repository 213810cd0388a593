"""The AMP discriminator: style reward for PPO and the fall detector's probability.

Real samples are windows of ground-truth AMP frames of the training motions
(:func:`grip.task.amp.reference_amp_features`); fake samples are the simulated humanoid's windows
(``info["amp_obs"]`` of the environment), kept in a replay buffer. Both are normalised by a
running mean and variance of the real samples and the policy's samples.

Loss forms (:attr:`policies.config.AmpConfig.loss`):

- ``lsgan`` (default; the AMP paper): ``L = E_real (D - 1)^2 + E_fake (D + 1)^2
  + w_gp / 2 E_real ||grad_x D||^2``; reward ``max(0, 1 - (D - 1)^2 / 4)`` in [0, 1];
  probability of "real" ``clip((D + 1) / 2, 0, 1)``.
- ``bce`` (PHC's code): logits with binary cross-entropy and the same gradient penalty; reward
  ``-log(max(1 - sigmoid(D), 1e-4))``; probability ``sigmoid(D)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch
from torch import nn

from grip.task import amp as A
from policies.config import AmpConfig


class RunningNorm(nn.Module):
    """Running mean and variance of inputs (parallel Welford), stored as buffers."""

    def __init__(self, dim: int, eps: float = 1e-5, clip: float = 10.0) -> None:
        super().__init__()
        self.register_buffer("mean", torch.zeros(dim, dtype=torch.float64))
        self.register_buffer("var", torch.ones(dim, dtype=torch.float64))
        self.register_buffer("count", torch.tensor(1e-4, dtype=torch.float64))
        self.eps, self.clip = eps, clip

    @torch.no_grad()
    def update(self, x: torch.Tensor) -> None:
        x = x.to(torch.float64)
        n = x.shape[0]
        if n == 0:
            return
        m, v = x.mean(0), x.var(0, unbiased=False)
        tot = self.count + n
        delta = m - self.mean
        self.mean += delta * n / tot
        self.var.copy_((self.var * self.count + v * n + delta**2 * self.count * n / tot) / tot)
        self.count.fill_(float(tot))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = (x - self.mean.to(x.dtype)) / torch.sqrt(self.var.to(x.dtype) + self.eps)
        return y.clamp(-self.clip, self.clip)


class Discriminator(nn.Module):
    """MLP over normalised AMP windows; one output (LSGAN score or BCE logit).

    Args:
        in_dim: Length of a window.
        hidden: Widths of the hidden layers.
        loss: ``"lsgan"`` or ``"bce"``.
        generator: Draws the initial weights (PyTorch's default initialisation, from this
            generator); ``None``: from torch's global generator.
    """

    def __init__(self, in_dim: int, hidden: Sequence[int], loss: str = "lsgan",
                 generator: torch.Generator | None = None) -> None:  # fmt: skip
        super().__init__()
        self.in_dim, self.loss = in_dim, loss
        self.norm = RunningNorm(in_dim)
        layers: list[nn.Module] = []
        d = in_dim
        for h in hidden:
            layers += [nn.Linear(d, h), nn.ReLU()]
            d = h
        self.trunk = nn.Sequential(*layers)
        self.head = nn.Linear(d, 1)
        if generator is not None:
            for layer in self.trunk:
                if isinstance(layer, nn.Linear):  # (nn.Linear.reset_parameters, seeded)
                    nn.init.kaiming_uniform_(layer.weight, a=math.sqrt(5), generator=generator)
                    bound = 1.0 / math.sqrt(layer.in_features)
                    nn.init.uniform_(layer.bias, -bound, bound, generator=generator)
        # PHC: a small logit layer at the start
        nn.init.uniform_(self.head.weight, -1.0, 1.0, generator=generator)
        self.head.weight.data.mul_(0.01)
        nn.init.zeros_(self.head.bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(N,)`` raw scores of raw (unnormalised) windows ``(N, in_dim)``."""
        return self.head(self.trunk(self.norm(x))).squeeze(-1)

    @torch.no_grad()
    def reward(self, x: np.ndarray) -> np.ndarray:
        """``(N,)`` style reward of raw windows (see the module docstring)."""
        d = self(torch.as_tensor(x, dtype=torch.float32)).double()
        if self.loss == "lsgan":
            r = torch.clamp(1.0 - 0.25 * (d - 1.0) ** 2, min=0.0)
        else:
            r = -torch.log(torch.clamp(1.0 - torch.sigmoid(d), min=1e-4))
        return r.numpy()

    @torch.no_grad()
    def probability(self, x: np.ndarray) -> np.ndarray:
        """``(N,)`` probability that windows are real motion (the fall detector's rho)."""
        d = self(torch.as_tensor(x, dtype=torch.float32)).double()
        p = torch.clamp((d + 1.0) / 2.0, 0.0, 1.0) if self.loss == "lsgan" else torch.sigmoid(d)
        return p.numpy()


def real_clip_probabilities(p, clip_len: np.ndarray) -> np.ndarray:
    """``p (C,)`` checked and normalised, zero on clips without frames (``clip_len (C,)``).

    Raises:
        ValueError: ``p`` is not one finite value >= 0 per clip, or puts no weight on a clip
            with frames.
    """
    q = np.asarray(p, dtype=np.float64)
    if q.shape != clip_len.shape or not np.isfinite(q).all() or (q < 0).any():
        raise ValueError(f"real clip probabilities must be {clip_len.size} finite values >= 0, "
                         f"got shape {q.shape}")  # fmt: skip
    q = np.where(clip_len > 0, q, 0.0)
    if q.sum() <= 0:
        raise ValueError("real clip probabilities are all zero")
    return q / q.sum()


class RealSampler:
    """Random windows of ground-truth AMP frames from several clips (never across clips).

    The window's last frame is drawn uniformly over every frame of every clip (the default,
    ``amp.real_sampling = "frames"``), or, once :meth:`set_clip_probabilities` was called, a
    clip is drawn with the given probabilities and the frame uniformly within it
    (``"episodes"``: the clips' probabilities of the environments' episodes).

    Args:
        clip_frames: ``(T_c, FRAME_DIM)`` ground-truth AMP frames of each clip.
        window: Frames per window.

    Attributes:
        frames: ``(F, FRAME_DIM)`` float32, every clip's frames concatenated.
        clip_start: ``(F,)`` the first row of each frame's clip.
        clip_offset, clip_len: ``(C,)`` each clip's first row and frames.
        clip_p: ``(C,)`` the clip probabilities, or ``None`` (by frame).
    """

    def __init__(self, clip_frames: Sequence[np.ndarray], window: int) -> None:
        if not clip_frames:
            raise ValueError("RealSampler needs at least one clip")
        self.frames = np.concatenate(clip_frames).astype(np.float32)
        self.clip_len = np.array([len(f) for f in clip_frames], dtype=np.int64)
        self.clip_offset = np.concatenate([[0], np.cumsum(self.clip_len)[:-1]]).astype(np.int64)
        self.clip_start = np.repeat(self.clip_offset, self.clip_len)
        self.window = window
        self.clip_p: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.frames)

    def set_clip_probabilities(self, p: np.ndarray | None) -> None:
        """Draw clips with probabilities ``p (C,)`` (finite, >= 0, normalised here; zero on
        clips without frames), then a frame uniformly within; ``None``: every frame equally.

        Raises:
            ValueError: ``p`` is not one finite value >= 0 per clip, or puts no weight on a
                clip with frames.
        """
        self.clip_p = None if p is None else real_clip_probabilities(p, self.clip_len)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``(n, window * FRAME_DIM)`` float32."""
        if self.clip_p is None:
            t = rng.integers(0, len(self.frames), n)
        else:
            c = rng.choice(len(self.clip_p), size=n, p=self.clip_p)
            t = self.clip_offset[c] + rng.integers(0, self.clip_len[c])
        idx = t[:, None] + np.arange(-self.window + 1, 1)[None, :]
        idx = np.maximum(idx, self.clip_start[t][:, None])
        return self.frames[idx].reshape(n, -1)


class ReplayBuffer:
    """Ring buffer of the policy's AMP windows."""

    def __init__(self, size: int, dim: int) -> None:
        self.data = np.zeros((size, dim), dtype=np.float32)
        self.n = 0
        self.pos = 0

    def __len__(self) -> int:
        return self.n

    def add(self, x: np.ndarray) -> None:
        size = len(self.data)
        x = x[-size:]
        k = len(x)
        end = self.pos + k
        if end <= size:
            self.data[self.pos : end] = x
        else:
            first = size - self.pos
            self.data[self.pos :] = x[:first]
            self.data[: k - first] = x[first:]
        self.pos = end % size
        self.n = min(self.n + k, size)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        return self.data[rng.integers(0, self.n, n)]


def discriminator_step(disc: Discriminator, opt: torch.optim.Optimizer, cfg: AmpConfig,
                       real: torch.Tensor, fake: torch.Tensor):  # fmt: skip
    """One gradient step of ``disc`` on a batch of reference windows ``real`` and policy windows
    ``fake`` (raw, ``(B, dim)``): ``cfg.loss`` (least squares or BCE), AMP's gradient penalty on
    the real windows (``cfg.grad_penalty``) and the optional logit regularisation. The CPU and
    the device trainers (:mod:`policies.warp.amp`) share it.

    Returns:
        ``(loss, gradient penalty, d_real, d_fake)``, detached.
    """
    real.requires_grad_(True)
    d_real, d_fake = disc(real), disc(fake)
    if cfg.loss == "lsgan":
        loss = ((d_real - 1.0) ** 2).mean() + ((d_fake + 1.0) ** 2).mean()
    else:
        bce = nn.functional.binary_cross_entropy_with_logits
        loss = bce(d_real, torch.ones_like(d_real)) + bce(d_fake, torch.zeros_like(d_fake))
    (grad,) = torch.autograd.grad(d_real.sum(), real, create_graph=True)
    gp = grad.pow(2).sum(-1).mean()
    total = loss + 0.5 * cfg.grad_penalty * gp
    if cfg.logit_reg > 0:
        total = total + cfg.logit_reg * disc.head.weight.pow(2).sum()
    opt.zero_grad(set_to_none=True)
    total.backward()
    opt.step()
    return loss.detach(), gp.detach(), d_real.detach(), d_fake.detach()


def blank_head(disc: Discriminator) -> None:
    """Zero the discriminator's output layer: its score is 0 on every window, so its style
    reward is a constant and its probability of "real" exactly 0.5 (both losses), under the
    fall detector's threshold (0.7): GRIP's fall rule becomes the pelvis height alone, as for
    a policy file without a discriminator. For a run without AMP (:class:`AmpTrainer`,
    ``active`` false), whose discriminator is never trained."""
    with torch.no_grad():
        disc.head.weight.zero_()
        disc.head.bias.zero_()


class AmpTrainer:
    """Discriminator, optimiser, real sampler and replay buffer; one :meth:`update` per rollout.

    Args:
        cfg: The AMP settings.
        real: The real windows.
        seed: Seeds the initial weights and the draws.
        active: ``False`` for a run without the style reward (``env.reward.weights.amp = 0``):
            :meth:`reward` is 0 without running the discriminator, :meth:`update` neither keeps
            the policy's windows nor trains, and the discriminator's output layer is blank
            (:func:`blank_head`) unless a warm start loads another.
    """

    def __init__(self, cfg: AmpConfig, real: RealSampler, seed: int = 0,
                 active: bool = True) -> None:  # fmt: skip
        self.cfg = cfg
        self.active = bool(active)
        dim = cfg.window * A.FRAME_DIM
        # the initial weights come from the run's seed (the same seed: the same discriminator)
        gen = torch.Generator().manual_seed(int(seed))
        self.disc = Discriminator(dim, cfg.hidden, cfg.loss, generator=gen)
        if not self.active:
            blank_head(self.disc)
        self.opt = torch.optim.Adam(self.disc.parameters(), lr=cfg.lr,
                                    weight_decay=cfg.weight_decay)  # fmt: skip
        self.real = real
        self.replay = ReplayBuffer(cfg.replay_size, dim)
        self.rng = np.random.default_rng(seed)
        self.disc.norm.update(torch.as_tensor(real.sample(min(len(real), 20000), self.rng)))

    def set_real_clip_probabilities(self, p: np.ndarray | None) -> None:
        """The real windows' clip probabilities (:meth:`RealSampler.set_clip_probabilities`)."""
        self.real.set_clip_probabilities(p)

    def reward(self, x: np.ndarray) -> np.ndarray:
        if not self.active:
            return np.zeros(len(x))
        return self.cfg.reward_scale * self.disc.reward(x)

    def update(self, fake: np.ndarray) -> dict[str, float]:
        """Add the rollout's policy windows to the replay buffer and train the discriminator
        (neither when not :attr:`active`: all statistics 0).

        Returns mean loss, gradient penalty, accuracy on real and fake samples and the mean
        score of each (for TensorBoard).
        """
        cfg = self.cfg
        stats = {"loss": 0.0, "grad_penalty": 0.0, "acc_real": 0.0, "acc_fake": 0.0,
                 "score_real": 0.0, "score_fake": 0.0}  # fmt: skip
        if not self.active:
            return stats
        if len(fake):
            self.replay.add(fake)
            self.disc.norm.update(torch.as_tensor(fake))
        if len(self.replay) == 0:
            return stats
        n = cfg.updates_per_rollout
        thr = 0.0
        for _ in range(n):
            real = torch.as_tensor(self.real.sample(cfg.batch_size, self.rng))
            fk = torch.as_tensor(self.replay.sample(cfg.batch_size, self.rng))
            loss, gp, d_real, d_fake = discriminator_step(self.disc, self.opt, cfg, real, fk)
            with torch.no_grad():
                stats["loss"] += float(loss) / n
                stats["grad_penalty"] += float(gp) / n
                stats["acc_real"] += float((d_real > thr).float().mean()) / n
                stats["acc_fake"] += float((d_fake < thr).float().mean()) / n
                stats["score_real"] += float(d_real.mean()) / n
                stats["score_fake"] += float(d_fake.mean()) / n
        return stats

    def state_dict(self) -> dict:
        return {"disc": self.disc.state_dict(), "opt": self.opt.state_dict(),
                "rng": self.rng.bit_generator.state}  # fmt: skip

    def load_state_dict(self, state: dict) -> None:
        self.disc.load_state_dict(state["disc"])
        self.opt.load_state_dict(state["opt"])
        self.rng.bit_generator.state = state["rng"]
