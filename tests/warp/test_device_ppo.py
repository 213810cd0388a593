"""The device twins of the CPU trainer's pieces against the pieces themselves (no MuJoCo Warp
needed): SB3's ``RunningMeanStd`` / ``VecNormalize`` / ``DictRolloutBuffer`` and the AMP
style reward."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from gymnasium import spaces
from stable_baselines3.common.buffers import DictRolloutBuffer
from stable_baselines3.common.running_mean_std import RunningMeanStd
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from policies.amp import Discriminator
from policies.config import AmpConfig
from policies.vec_env import load_vecnorm_state, vecnorm_state
from policies.warp.amp import DeviceAmpTrainer, style_reward
from policies.warp.rollout import DeviceRolloutBuffer, DeviceRunningMeanStd, DeviceVecNormalize

CPU = torch.device("cpu")


def test_running_mean_std_matches_sb3():
    rng = np.random.default_rng(0)
    ours, theirs = DeviceRunningMeanStd((3,), CPU), RunningMeanStd(shape=(3,))
    for n in (5, 1, 17):
        x = rng.normal(2.0, 3.0, (n, 3))
        ours.update(torch.as_tensor(x))
        theirs.update(x)
    np.testing.assert_allclose(ours.mean, theirs.mean, atol=1e-12)
    np.testing.assert_allclose(ours.var, theirs.var, atol=1e-12)
    assert ours.count == pytest.approx(theirs.count)


def test_vec_normalize_matches_sb3():
    """Observations and rewards of a sequence with episode ends, normalised by both."""
    import gymnasium as gym

    rng = np.random.default_rng(1)
    n, steps, gamma = 3, 6, 0.9
    obs_seq = rng.normal(1.0, 2.0, (steps + 1, n, 4)).astype(np.float32)
    rew_seq = rng.normal(0.5, 1.5, (steps, n)).astype(np.float32)
    done_seq = rng.random((steps, n)) < 0.3

    class Env(gym.Env):
        observation_space = spaces.Dict({"a": spaces.Box(-np.inf, np.inf, (4,), np.float32)})
        action_space = spaces.Box(-1, 1, (1,), np.float32)

    venv = VecNormalize(DummyVecEnv([Env] * n), norm_obs=True, norm_reward=True, clip_obs=3.0,
                        gamma=gamma)  # fmt: skip
    ours = DeviceVecNormalize({"a": (4,)}, n, CPU, True, 3.0, gamma)
    # VecNormalize's own update path: reset, then step_wait's order (obs stats, returns)
    venv.obs_rms["a"].update(obs_seq[0])
    ours.update_obs({"a": torch.as_tensor(obs_seq[0])})
    for t in range(steps):
        o = {"a": obs_seq[t + 1]}
        venv.obs_rms["a"].update(o["a"])
        want_obs = venv.normalize_obs(o)["a"]
        venv.returns = venv.returns * gamma + rew_seq[t]
        venv.ret_rms.update(venv.returns)
        want_rew = venv.normalize_reward(rew_seq[t])
        venv.returns[done_seq[t]] = 0
        ours.update_obs({"a": torch.as_tensor(o["a"])})
        got_obs = ours.normalize_obs({"a": torch.as_tensor(o["a"])})["a"].numpy()
        got_rew = ours.normalize_reward(torch.as_tensor(rew_seq[t]),
                                        torch.as_tensor(done_seq[t])).numpy()  # fmt: skip
        np.testing.assert_allclose(got_obs, want_obs, atol=1e-5)
        np.testing.assert_allclose(got_rew, want_rew, atol=1e-5)
    # the checkpoint helpers of the CPU trainer read and write it as VecNormalize
    state = vecnorm_state(ours)
    np.testing.assert_allclose(state["obs/a/mean"], venv.obs_rms["a"].mean, atol=1e-9)
    other = DeviceVecNormalize({"a": (4,)}, n, CPU, True, 3.0, gamma)
    load_vecnorm_state(other, state)
    np.testing.assert_allclose(vecnorm_state(other)["ret_var"], state["ret_var"])


def _buffers(n: int, steps: int):
    obs_space = spaces.Dict({"a": spaces.Box(-np.inf, np.inf, (2,), np.float32),
                             "b": spaces.Box(-np.inf, np.inf, (3,), np.float32)})  # fmt: skip
    act_space = spaces.Box(-1, 1, (4,), np.float32)
    args = (steps, obs_space, act_space)
    kw = dict(device="cpu", gae_lambda=0.8, gamma=0.95, n_envs=n)
    return DictRolloutBuffer(*args, **kw), DeviceRolloutBuffer(*args, **kw)


def test_rollout_buffer_gae_and_batches_match_sb3():
    rng = np.random.default_rng(2)
    n, steps = 3, 5
    theirs, ours = _buffers(n, steps)
    ours.seed(0)
    for _ in range(steps):
        obs = {"a": rng.normal(size=(n, 2)).astype(np.float32),
               "b": rng.normal(size=(n, 3)).astype(np.float32)}  # fmt: skip
        act = rng.normal(size=(n, 4)).astype(np.float32)
        rew = rng.normal(size=n).astype(np.float32)
        start = rng.random(n) < 0.3
        v = torch.as_tensor(rng.normal(size=(n, 1)), dtype=torch.float32)
        lp = torch.as_tensor(rng.normal(size=n), dtype=torch.float32)
        theirs.add(obs, act, rew, start, v, lp)
        ours.add({k: torch.as_tensor(x) for k, x in obs.items()}, torch.as_tensor(act),
                 torch.as_tensor(rew), torch.as_tensor(start), v, lp)  # fmt: skip
    last_v = torch.as_tensor(rng.normal(size=(n, 1)), dtype=torch.float32)
    dones = rng.random(n) < 0.5
    theirs.compute_returns_and_advantage(last_v, dones)
    ours.compute_returns_and_advantage(last_v, torch.as_tensor(dones))
    np.testing.assert_allclose(ours.advantages.numpy(), theirs.advantages, atol=1e-5)
    np.testing.assert_allclose(ours.returns, theirs.returns, atol=1e-5)
    # one full batch of each, ordered by sample: the same samples, environment-major
    (b_t,) = theirs.get(None)
    batches = list(ours.get(4))
    assert [len(b.actions) for b in batches] == [4, 4, 4, 3]
    (b_o,) = list(ours.get(None))
    key_t = np.argsort(b_t.old_log_prob.numpy())
    key_o = np.argsort(b_o.old_log_prob.numpy())
    for f in ("actions", "old_values", "advantages", "returns"):
        np.testing.assert_allclose(getattr(b_o, f).numpy()[key_o],
                                   getattr(b_t, f).numpy()[key_t], atol=1e-5)  # fmt: skip
    np.testing.assert_allclose(b_o.observations["b"].numpy()[key_o],
                               b_t.observations["b"].numpy()[key_t])  # fmt: skip


@pytest.mark.parametrize("loss", ["lsgan", "bce"])
def test_style_reward_is_the_discriminators(loss):
    disc = Discriminator(6, (8,), loss, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():
        disc.head.weight.mul_(300.0)  # (scores well away from 0, both branches of the clamps)
    x = np.random.default_rng(3).normal(size=(32, 6)).astype(np.float32)
    got = style_reward(disc(torch.as_tensor(x)).detach(), loss).double().numpy()
    np.testing.assert_allclose(got, disc.reward(x), atol=1e-6)


def test_device_amp_real_windows_stay_in_their_clip_and_training_separates():
    cfg = AmpConfig(window=3, hidden=(16,), batch_size=64, updates_per_rollout=40, lr=3e-3,
                    replay_size=100)  # fmt: skip
    frames = torch.arange(10, dtype=torch.float32)[:, None].repeat(1, 2)  # 2 clips: rows 0-5, 6-9
    clip_start = torch.tensor([0] * 6 + [6] * 4)
    from grip.task import amp as A

    dim = cfg.window * A.FRAME_DIM
    big = torch.zeros(10, A.FRAME_DIM)
    big[:, :2] = frames
    amp = DeviceAmpTrainer(cfg, Discriminator(dim, cfg.hidden, cfg.loss), big, clip_start, CPU)
    w = amp.sample_real(500).reshape(500, cfg.window, A.FRAME_DIM)[:, :, 0]
    assert bool(((w[:, 0] >= 6) == (w[:, -1] >= 6)).all())  # never across the clip boundary
    assert bool((w[:, 1:] >= w[:, :-1]).all())  # oldest first, the first frame repeated
    fake = torch.full((150, dim), 5.0)
    stats = amp.update(fake)
    # (the accuracies are means over the 40 updates, the first ones near chance)
    assert amp.replay_n == 100 and stats["acc_fake"] > 0.6 and stats["acc_real"] > 0.6
    assert float(amp.reward(fake[:4]).max()) < float(amp.reward(amp.sample_real(4)).min())
    # checkpoint round trip, generator included
    state = amp.state_dict()
    a = amp.sample_real(3)
    amp.load_state_dict(state)
    torch.testing.assert_close(amp.sample_real(3), a)
