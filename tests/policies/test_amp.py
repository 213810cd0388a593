"""AMP discriminator parts: normaliser, buffers, sampler, loss forms and learning."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from grip.task.amp import FRAME_DIM
from policies.amp import AmpTrainer, Discriminator, RealSampler, ReplayBuffer, RunningNorm
from policies.config import AmpConfig


def test_running_norm_matches_numpy_over_batches():
    rng = np.random.default_rng(0)
    x = rng.normal(3.0, 2.0, size=(1000, 5))
    n = RunningNorm(5)
    for part in np.array_split(x, 7):
        n.update(torch.as_tensor(part))
    np.testing.assert_allclose(n.mean.numpy(), x.mean(0), atol=1e-6)
    np.testing.assert_allclose(n.var.numpy(), x.var(0), rtol=1e-4)


def test_replay_buffer_wraps_and_keeps_the_newest():
    b = ReplayBuffer(5, 1)
    b.add(np.arange(3, dtype=np.float32)[:, None])
    b.add(np.arange(3, 7, dtype=np.float32)[:, None])
    assert len(b) == 5
    assert sorted(b.data[:, 0].tolist()) == [2, 3, 4, 5, 6]
    b.add(np.arange(10, 22, dtype=np.float32)[:, None])  # more than the buffer holds
    assert sorted(b.data[:, 0].tolist()) == [17, 18, 19, 20, 21]


def test_real_windows_never_cross_clips():
    a = np.zeros((4, FRAME_DIM))
    b = np.ones((6, FRAME_DIM))
    s = RealSampler([a, b], window=3)
    w = s.sample(500, np.random.default_rng(0)).reshape(500, 3, FRAME_DIM)
    per_window = w[:, :, 0]
    assert np.all((per_window == 0).all(1) | (per_window == 1).all(1))


def _labelled_clips(lengths):
    """Clips whose frames hold (clip index, frame index) in their first two values."""
    return [np.stack([np.full(n, c), np.arange(n)], 1) @ np.eye(2, FRAME_DIM)
            for c, n in enumerate(lengths)]  # fmt: skip


def test_real_windows_follow_the_clip_probabilities():
    """``"episodes"``: clips drawn with the given probabilities (chi-square on a seeded draw
    of 20,000: the test fails with the by-frame draw, whose shares are 0.1/0.3/0.6), frames
    uniform within the drawn clip, windows within it; ``None`` restores the by-frame draw."""
    lengths = [10, 30, 60]
    s = RealSampler(_labelled_clips(lengths), window=3)
    p = np.array([0.5, 0.0, 0.5])
    s.set_clip_probabilities(2 * p)  # (normalised)
    n = 20000
    w = s.sample(n, np.random.default_rng(1)).reshape(n, 3, FRAME_DIM)
    clip, frame = w[:, -1, 0].astype(int), w[:, -1, 1].astype(int)
    assert (w[:, :, 0] == clip[:, None]).all()  # (no window crosses clips)
    counts = np.bincount(clip, minlength=3)
    assert counts[1] == 0
    expected = n * p[[0, 2]]
    chi2 = (((counts[[0, 2]] - expected) ** 2) / expected).sum()
    assert chi2 < 10.8  # (1 degree of freedom, p = 0.001)
    for c in (0, 2):  # uniform over the clip's frames
        f = np.bincount(frame[clip == c], minlength=lengths[c])
        e = (clip == c).sum() / lengths[c]
        assert (((f - e) ** 2) / e).sum() < 2 * lengths[c] + 30
    s.set_clip_probabilities(None)
    by_frame = np.bincount(s.sample(n, np.random.default_rng(1))[:, -FRAME_DIM].astype(int),
                           minlength=3) / n  # fmt: skip
    np.testing.assert_allclose(by_frame, np.array(lengths) / 100, atol=0.02)
    for bad in ([1.0, 1.0], [np.nan, 1, 1], [-1, 1, 1]):
        with pytest.raises(ValueError, match="real clip probabilities"):
            s.set_clip_probabilities(bad)
    with pytest.raises(ValueError, match="all zero"):
        s.set_clip_probabilities([0.0, 0.0, 0.0])


def test_the_default_real_draw_is_unchanged():
    """Without clip probabilities the sampler draws exactly as before (one integer per window
    over all frames), so older runs resume with the same draws."""
    s = RealSampler(_labelled_clips([10, 30]), window=2)
    got = s.sample(50, np.random.default_rng(7))
    t = np.random.default_rng(7).integers(0, 40, 50)
    np.testing.assert_array_equal(got[:, -FRAME_DIM], (t >= 10).astype(np.float32))
    np.testing.assert_array_equal(got[:, -FRAME_DIM + 1], np.where(t >= 10, t - 10, t))


def test_an_inactive_trainer_neither_scores_nor_trains():
    """AMP off (``active`` false): reward 0 without running the discriminator, no update, no
    replay; the blank output layer gives probability 0.5 on any window (under the fall
    detector's 0.7: a fall is the pelvis height alone)."""
    cfg = AmpConfig(window=1, hidden=(8,), batch_size=16, updates_per_rollout=2)
    real = RealSampler([np.random.default_rng(0).normal(size=(50, FRAME_DIM))], window=1)
    amp = AmpTrainer(cfg, real, seed=0, active=False)
    before = {k: v.clone() for k, v in amp.disc.state_dict().items()}
    fake = np.random.default_rng(1).normal(size=(64, FRAME_DIM)).astype(np.float32)
    assert amp.reward(fake).tolist() == [0.0] * 64
    stats = amp.update(fake)
    assert set(stats.values()) == {0.0} and len(amp.replay) == 0
    for k, v in amp.disc.state_dict().items():
        assert torch.equal(v, before[k]), k
    assert not amp.opt.state
    np.testing.assert_array_equal(amp.disc.probability(fake), 0.5)
    on = AmpTrainer(cfg, real, seed=0)
    on.update(fake)
    assert len(on.replay) == 64 and on.opt.state  # (the same calls train an active one)


@pytest.mark.parametrize("loss", ["lsgan", "bce"])
def test_discriminator_learns_to_tell_two_motions_apart(loss):
    cfg = AmpConfig(window=1, hidden=(32,), loss=loss, lr=3e-3, batch_size=128,
                    updates_per_rollout=60, replay_size=2000, grad_penalty=1.0)  # fmt: skip
    rng = np.random.default_rng(0)
    real = RealSampler([rng.normal(0.0, 1.0, size=(3000, FRAME_DIM))], window=1)
    tr = AmpTrainer(cfg, real, seed=0)
    fake = rng.normal(0.0, 1.0, size=(2000, FRAME_DIM)).astype(np.float32)
    fake[:, :20] += 2.0  # shifted in 20 dimensions
    stats = tr.update(fake)
    assert stats["acc_real"] > 0.8 and stats["acc_fake"] > 0.8
    r_real = tr.reward(real.sample(500, rng)).mean()
    r_fake = tr.reward(fake[:500]).mean()
    assert r_real > r_fake
    p_real = tr.disc.probability(real.sample(500, rng))
    p_fake = tr.disc.probability(fake[:500])
    assert 0 <= p_fake.min() and p_real.max() <= 1 and p_real.mean() > p_fake.mean() + 0.3
    # state round trip: same scores after loading into a fresh trainer
    tr2 = AmpTrainer(cfg, real, seed=1)
    tr2.load_state_dict(tr.state_dict())
    np.testing.assert_allclose(tr2.reward(fake[:50]), tr.reward(fake[:50]), rtol=1e-6)


def test_lsgan_reward_and_probability_formulas():
    d = Discriminator(3, (), "lsgan")
    with torch.no_grad():
        d.head.weight.zero_()
        d.head.bias.fill_(1.0)  # D = 1 everywhere: "real"
    x = np.zeros((2, 3), np.float32)
    np.testing.assert_allclose(d.reward(x), 1.0)
    np.testing.assert_allclose(d.probability(x), 1.0)
    with torch.no_grad():
        d.head.bias.fill_(-1.0)  # D = -1: "fake", r = max(0, 1 - 4/4) = 0
    np.testing.assert_allclose(d.reward(x), 0.0)
    np.testing.assert_allclose(d.probability(x), 0.0)
