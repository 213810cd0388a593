"""The AMP discriminator's initial weights come from the run's seed."""

from __future__ import annotations

import numpy as np
import torch

from grip.task.amp import FRAME_DIM
from policies.amp import AmpTrainer, Discriminator, RealSampler
from policies.config import AmpConfig


def _weights(tr: AmpTrainer) -> list[torch.Tensor]:
    return [p.detach().clone() for p in tr.disc.parameters()]


def test_same_seed_same_discriminator_other_seed_another():
    cfg = AmpConfig(window=2, hidden=(16, 8))
    real = RealSampler([np.random.default_rng(0).normal(size=(50, FRAME_DIM))], window=2)
    torch.manual_seed(123)  # (the global generator must not matter)
    a = _weights(AmpTrainer(cfg, real, seed=4))
    torch.manual_seed(456)
    b = _weights(AmpTrainer(cfg, real, seed=4))
    c = _weights(AmpTrainer(cfg, real, seed=5))
    assert len(a) == len(b) == len(c) == 6
    for x, y in zip(a, b, strict=True):
        torch.testing.assert_close(x, y, rtol=0, atol=0)
    # every layer's weights differ under another seed (biases of the head start at zero)
    for x, z in zip(a, c, strict=True):
        assert not torch.equal(x, z) or not z.any()
    assert not torch.equal(a[0], c[0])


def test_discriminator_draws_from_the_generator_it_is_given():
    d1 = Discriminator(10, (4,), generator=torch.Generator().manual_seed(1))
    d2 = Discriminator(10, (4,), generator=torch.Generator().manual_seed(1))
    for p1, p2 in zip(d1.parameters(), d2.parameters(), strict=True):
        assert torch.equal(p1, p2)
    # the default initialisation's scale (PyTorch's bound 1/sqrt(fan_in); a small head)
    assert d1.trunk[0].weight.abs().max() <= 1 / np.sqrt(10)
    assert d1.head.weight.abs().max() <= 0.01
