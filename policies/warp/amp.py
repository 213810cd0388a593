"""The AMP discriminator's training on a torch device: :class:`policies.amp.AmpTrainer`'s update
(the same :class:`policies.amp.Discriminator`, losses, gradient penalty, logit regulariser and
Adam settings) with the real windows, the replay buffer of policy windows and the random draws
as device tensors, so that a rollout of thousands of environments never leaves the device.
"""

from __future__ import annotations

import json

import numpy as np
import torch

from policies.amp import AmpTrainer, Discriminator, discriminator_step, real_clip_probabilities
from policies.config import AmpConfig


def style_reward(score: torch.Tensor, loss: str) -> torch.Tensor:
    """:meth:`policies.amp.Discriminator.reward` of raw scores ``(B,)``: ``max(0, 1 - (D - 1)^2
    / 4)`` for ``"lsgan"``, ``-log(max(1 - sigmoid(D), 1e-4))`` for ``"bce"``."""
    if loss == "lsgan":
        return torch.clamp(1.0 - 0.25 * (score - 1.0) ** 2, min=0.0)
    return -torch.log(torch.clamp(1.0 - torch.sigmoid(score), min=1e-4))


class DeviceAmpTrainer:
    """Discriminator, optimiser, real windows and replay buffer on ``device``.

    Built from the CPU trainer's :class:`policies.amp.AmpTrainer` of the run (:meth:`from_cpu`),
    so the initial discriminator and its input normaliser are the CPU path's for the same seed.

    Args:
        cfg: The AMP settings.
        disc: The discriminator (moved to ``device``).
        real_frames: ``(F, FRAME_DIM)`` every clip's ground-truth AMP frames, concatenated.
        clip_start: ``(F,)`` int, the first row of each frame's clip (windows never cross clips).
        device: The torch device.
        seed: Seed of the device generator (real and replay draws).
        clip_offset, clip_len: ``(C,)`` int, each clip's first row and frames (for
            :meth:`set_real_clip_probabilities`); ``None``: one clip of all frames.
        active: As :class:`policies.amp.AmpTrainer` (``False``: AMP off, nothing run or
            trained).
    """

    def __init__(self, cfg: AmpConfig, disc: Discriminator, real_frames: torch.Tensor,
                 clip_start: torch.Tensor, device: torch.device, seed: int = 0,
                 clip_offset: torch.Tensor | None = None, clip_len: torch.Tensor | None = None,
                 active: bool = True) -> None:  # fmt: skip
        self.cfg, self.device = cfg, device
        self.active = bool(active)
        self.disc = disc.to(device)
        self.opt = torch.optim.Adam(self.disc.parameters(), lr=cfg.lr,
                                    weight_decay=cfg.weight_decay)  # fmt: skip
        self.frames = real_frames.to(device, torch.float32)
        self.clip_start = clip_start.to(device, torch.int64)
        n = len(self.frames)
        self.clip_offset = (torch.zeros(1, dtype=torch.int64) if clip_offset is None
                            else clip_offset).to(device, torch.int64)  # fmt: skip
        self.clip_len = (torch.full((1,), n, dtype=torch.int64) if clip_len is None
                         else clip_len).to(device, torch.int64)  # fmt: skip
        self.clip_p: torch.Tensor | None = None  # (None: every frame equally)
        self._back = torch.arange(-cfg.window + 1, 1, device=device)
        dim = disc.in_dim
        self.replay = torch.zeros(cfg.replay_size, dim, dtype=torch.float32, device=device)
        self.replay_n = 0
        self.replay_pos = 0
        self.gen = torch.Generator(device=device)
        self.gen.manual_seed(int(seed))

    @classmethod
    def from_cpu(cls, amp: AmpTrainer, device: torch.device, seed: int = 0) -> DeviceAmpTrainer:
        """The device trainer of a freshly built :class:`policies.amp.AmpTrainer` (its
        discriminator, normaliser included, and its real windows)."""
        real = amp.real
        return cls(amp.cfg, amp.disc, torch.as_tensor(real.frames),
                   torch.as_tensor(real.clip_start), device, seed,
                   torch.as_tensor(real.clip_offset), torch.as_tensor(real.clip_len),
                   amp.active)  # fmt: skip

    # ------------------------------------------------------------------ samples
    def set_real_clip_probabilities(self, p: np.ndarray | None) -> None:
        """Draw real windows' clips with probabilities ``p (C,)``, then a frame uniformly in
        the clip; ``None``: every frame equally (:meth:`policies.amp.RealSampler.
        set_clip_probabilities`, whose checks apply)."""
        if p is None:
            self.clip_p = None
            return
        q = real_clip_probabilities(p, self.clip_len.cpu().numpy())
        self.clip_p = torch.as_tensor(q, device=self.device)

    def sample_real(self, n: int) -> torch.Tensor:
        """``(n, window * FRAME_DIM)`` random windows of the ground truth (as
        :meth:`policies.amp.RealSampler.sample`)."""
        if self.clip_p is None:
            t = torch.randint(0, len(self.frames), (n,), generator=self.gen, device=self.device)
        else:
            c = torch.multinomial(self.clip_p, n, replacement=True, generator=self.gen)
            u = torch.rand(n, generator=self.gen, device=self.device, dtype=torch.float64)
            k = (u * self.clip_len[c]).long().minimum(self.clip_len[c] - 1)
            t = self.clip_offset[c] + k
        idx = torch.maximum(t[:, None] + self._back, self.clip_start[t][:, None])
        return self.frames[idx].reshape(n, -1)

    def add_fake(self, x: torch.Tensor) -> None:
        """Put policy windows ``(B, dim)`` in the replay ring (oldest replaced first)."""
        size = len(self.replay)
        x = x[-size:]
        k = len(x)
        idx = (self.replay_pos + torch.arange(k, device=self.device)) % size
        self.replay[idx] = x
        self.replay_pos = (self.replay_pos + k) % size
        self.replay_n = min(self.replay_n + k, size)

    def sample_fake(self, n: int) -> torch.Tensor:
        i = torch.randint(0, self.replay_n, (n,), generator=self.gen, device=self.device)
        return self.replay[i]

    # ------------------------------------------------------------------ reward, update
    @torch.no_grad()
    def reward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B,)`` ``reward_scale`` x the style reward of raw windows ``(B, dim)`` (0 with AMP
        off)."""
        if not self.active:
            return torch.zeros(len(x), dtype=torch.float32, device=self.device)
        return self.cfg.reward_scale * style_reward(self.disc(x), self.cfg.loss)

    def update(self, fake: torch.Tensor) -> dict[str, float]:
        """Add a rollout's policy windows ``(B, dim)`` and train the discriminator
        (:meth:`policies.amp.AmpTrainer.update`; the same statistics, one host copy)."""
        cfg = self.cfg
        keys = ("loss", "grad_penalty", "acc_real", "acc_fake", "score_real", "score_fake")
        if not self.active:
            return dict.fromkeys(keys, 0.0)
        if len(fake):
            self.add_fake(fake)
            self.disc.norm.update(fake)
        if self.replay_n == 0:
            return dict.fromkeys(keys, 0.0)
        n = cfg.updates_per_rollout
        acc = torch.zeros(len(keys), dtype=torch.float64, device=self.device)
        for _ in range(n):
            loss, gp, d_real, d_fake = discriminator_step(
                self.disc, self.opt, cfg, self.sample_real(cfg.batch_size),
                self.sample_fake(cfg.batch_size))
            with torch.no_grad():
                acc += torch.stack([loss, gp, (d_real > 0).float().mean(),
                                    (d_fake < 0).float().mean(), d_real.mean(),
                                    d_fake.mean()]).to(torch.float64)  # fmt: skip
        return dict(zip(keys, (acc / n).tolist(), strict=True))

    # ------------------------------------------------------------------ checkpoint
    def state_dict(self) -> dict:
        """Discriminator (CPU tensors: ``export_policy`` reads it), optimiser and generator
        state (a list of bytes, JSON-encoded by the trainer's checkpoint)."""
        return {"disc": {k: v.detach().cpu() for k, v in self.disc.state_dict().items()},
                "opt": self.opt.state_dict(), "rng": self.gen.get_state().tolist()}  # fmt: skip

    def load_state_dict(self, state: dict) -> None:
        self.disc.load_state_dict(state["disc"])
        self.opt.load_state_dict(state["opt"])
        rng = state["rng"]
        if isinstance(rng, str):
            rng = json.loads(rng)
        if not isinstance(rng, list):
            raise ValueError("discriminator checkpoint: its generator state is not a device "
                             "trainer's (a CPU run's checkpoint?)")  # fmt: skip
        self.gen.set_state(torch.tensor(rng, dtype=torch.uint8))
