"""The recording's sensor context (``TrackingEnvConfig.sensor_context``), what a gate with a
context window reads: each sensor feature's mean and standard deviation over the last W frames,
the same in the whole-recording form the gate is trained on, the single and the batched
environment and the inference player."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
from stable_baselines3.common.vec_env import DummyVecEnv

from envs.batched import BatchedTrackingEnv
from envs.tracking_env import SAMPLE_REFERENCE, GripTrackingEnv
from grip.core.reference import ReferenceSet
from grip.pipeline import GripPipeline, RecoveryConfig, start_from_clip
from grip.task.config import TrackingEnvConfig
from grip.task.observations import sensor_context_at, sensor_context_rows
from policies.vec_env import BatchedVecEnv

W = 12
CFG = TrackingEnvConfig(termination_dist_m=0.0, max_episode_frames=30, min_episode_frames=30,
                        sensor_context=W)  # fmt: skip


def test_the_rows_and_one_frame_agree_and_read_no_later_frame() -> None:
    x = np.random.default_rng(0).normal(0.0, 1.0, (50, 5))
    rows = sensor_context_rows(x, W)
    assert rows.shape == (50, 10)
    np.testing.assert_allclose(rows[0], np.r_[x[0], np.zeros(5)], atol=1e-12)
    np.testing.assert_allclose(rows[30], np.r_[x[19:31].mean(0), x[19:31].std(0)], atol=1e-9)
    for t in range(50):
        later = x.copy()
        later[t + 1:] = 99.0  # (a stream's frames not yet arrived)
        np.testing.assert_allclose(sensor_context_at(later, t, W), rows[t], atol=1e-5)
    with pytest.raises(ValueError, match="sensor_context"):
        TrackingEnvConfig(sensor_context=1)


def _frame(env: GripTrackingEnv) -> int:
    return min(env._t + 1, env._clip.n_frames - 1)  # (the frame the observation aims at)


def test_the_environments_observe_the_recordings_context(reference) -> None:
    plain = GripTrackingEnv(dataclasses.replace(CFG, sensor_context=0), reference)
    assert "sensor_context" not in plain.observation_space
    env = GripTrackingEnv(CFG, reference)
    assert env.observation_space["sensor_context"].shape == (2 * reference.clip(0).sensor.shape[1],)
    rows = sensor_context_rows(reference.clip(0).sensor, W)
    obs, _ = env.reset(seed=3)
    for _ in range(8):
        np.testing.assert_allclose(obs["sensor_context"], rows[_frame(env)], atol=1e-5)
        obs, *_ = env.step(np.zeros(69, np.float32))

    def single(seed):
        e = GripTrackingEnv(CFG, reference)
        e.reset(seed=seed)
        return e

    seeds = [7, 1007]
    ref = DummyVecEnv([functools.partial(single, s) for s in seeds])
    envs = [GripTrackingEnv(CFG, reference) for _ in seeds]
    for e, s in zip(envs, seeds, strict=True):
        e.reset(seed=s)
    bat = BatchedVecEnv(BatchedTrackingEnv(envs, 1))
    ref.seed(3)
    bat.seed(3)
    o1, o2 = ref.reset(), bat.reset()
    for _ in range(5):
        np.testing.assert_allclose(o2["sensor_context"], o1["sensor_context"], atol=1e-6)
        a = np.zeros((2, 69), np.float32)
        (o1, *_), (o2, *_) = ref.step(a), bat.step(a)
    bat.close()


class _Recorder:
    """Policy stand-in that follows the estimate and keeps what it was shown."""

    def __init__(self) -> None:
        self.disc = None
        self.env_cfg = TrackingEnvConfig(amp_window=2, sensor_context=W)
        self.seen: list[tuple[int, np.ndarray]] = []

    def act(self, obs: dict) -> np.ndarray:
        self.seen.append((self.player.t, obs["sensor_context"].copy()))
        return np.zeros(69)

    def fall_probability(self, amp_obs: np.ndarray) -> np.ndarray:
        return np.zeros(1)


def test_the_player_shows_the_context_of_the_frame_it_aims_at() -> None:
    clip = ReferenceSet.load(SAMPLE_REFERENCE).clip(0)
    runner = _Recorder()
    player = runner.player = GripPipeline(runner, None, RecoveryConfig(enabled=False)).player(
        clip.body, clip.objects)
    player.start(clip, start_from_clip(clip), clip.name, clip.fps)
    for _ in range(20):
        player.advance()
    rows = sensor_context_rows(clip.sensor, W)
    assert len(runner.seen) == 20
    for t, got in runner.seen:
        np.testing.assert_allclose(got, rows[t + 1], atol=1e-5)
