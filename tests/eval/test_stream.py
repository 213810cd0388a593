"""Streaming GRIP gives the offline reconstruction, two frames later.

A scripted policy and an oracle estimator (it replays the ground truth, like
:func:`grip.kinematics.reference.oracle_reference_clip`) check the stream's machinery against
:func:`grip.eval.reconstruct.simulate_clip` closely, falls and recoveries included; the shipped
models check the whole stack against ``GripReconstructor``.
"""

from __future__ import annotations

import numpy as np
import pytest

from envs.config import TrackingEnvConfig
from grip.core.reference import ReferenceSet
from grip.core.rotations import matrix_to_6d
from grip.eval.reconstruct import RecoveryConfig, inference_env, simulate_clip
from grip.eval.stream import LATENCY_FRAMES, GripStream
from grip.kinematics.features import FeatureConfig, SensorFrame, sensor_frames, targets
from grip.kinematics.reference import oracle_reference_clip
from prism_tools.io import load_recording

SAMPLE = "grip/assets/sample_recording.npz"


class _Runner:
    """Policy stand-in: a constant action; ``prob`` is the discriminator's answer."""

    def __init__(self, action: float, prob: float = 0.0) -> None:
        self.action, self.prob = action, prob
        self.disc = object()
        self.env_cfg = TrackingEnvConfig(amp_window=2)

    def act(self, obs: dict) -> np.ndarray:
        return np.full(69, self.action)

    def fall_probability(self, amp_obs: np.ndarray) -> np.ndarray:
        return np.array([self.prob])


class _Oracle:
    """Estimator stand-in that replays the ground truth of a recording frame by frame."""

    def __init__(self, rec, cfg: FeatureConfig) -> None:
        self.cfg = type("Cfg", (), {"features": cfg})()
        self._t = targets(rec)

    def stream(self, calibration):
        t, i = self._t, iter(range(10**9))
        step = lambda row: (lambda k: {  # noqa: E731
            "fp": t.joint_pos[k], "fa": matrix_to_6d(t.global_rot[k]), "lv": t.velocity[k],
        })(next(i))  # fmt: skip
        return type("S", (), {"step": staticmethod(step)})()


@pytest.fixture(scope="module")
def rec():
    return load_recording(SAMPLE).slice_frames(0, 160)


def _run(stream: GripStream, frames) -> list:
    outs = [stream.push(f) for f in frames]
    assert outs[:LATENCY_FRAMES] == [None] * LATENCY_FRAMES
    outs = outs[LATENCY_FRAMES:] + stream.finish()
    assert [o.frame for o in outs] == list(range(len(frames)))  # push t -> frame t - 2
    return outs


@pytest.mark.parametrize("action", [0.0, -1.0])  # -1: the humanoid collapses, recoveries
def test_stream_gives_the_offline_reconstruction(rec, action) -> None:
    cfg = FeatureConfig()
    runner, recovery = _Runner(action), RecoveryConfig(history_frames=20)
    clip = oracle_reference_clip(rec, cfg)
    env = inference_env(runner, ReferenceSet([clip], cfg.sites, cfg.insoles))
    offline, _ = simulate_clip(env, runner, 0, recovery)
    stream = GripStream(runner, _Oracle(rec, cfg), rec.slice_frames(0, 2), recovery, capacity=64)
    outs = _run(stream, list(sensor_frames(rec, cfg)))
    live = stream.reconstruction()
    assert live.n_frames == offline.n_frames == rec.n_frames
    np.testing.assert_array_equal(live.falls, offline.falls)
    assert offline.fell or action == 0.0
    for k in ("joint_pos", "global_rot", "grf", "torques"):
        np.testing.assert_allclose(getattr(live, k), getattr(offline, k), atol=1e-6, err_msg=k)
    np.testing.assert_array_equal(live.contacts, offline.contacts)
    # frames handed out equal the final ones, except those a later recovery replaced
    replaced = np.zeros(rec.n_frames, dtype=bool)
    for s, t in offline.falls:
        replaced[s:t] = True
        assert outs[t].fall == (s, t)
    for o in outs:
        if not replaced[o.frame]:
            np.testing.assert_allclose(o.joint_pos, offline.joint_pos[o.frame], atol=1e-6)
    assert live.ms_per_frame > 0
    with pytest.raises(ValueError, match="push after finish"):
        stream.push(next(sensor_frames(rec, cfg)))


def test_stream_with_the_shipped_models_matches_the_offline_path(rec) -> None:
    from grip.eval.reconstruct import GripReconstructor

    short = rec.slice_frames(0, 100)
    g = GripReconstructor.from_files("grip/assets/policy_default.pt",
                                     "grip/assets/kinematics_default.pt")  # fmt: skip
    offline = g.reconstruct([short])[0]
    stream = g.stream(short.slice_frames(0, 2))
    _run(stream, list(sensor_frames(short, g.estimator.cfg.features)))
    live = stream.reconstruction()
    # KinematicsNet's batch-1 steps differ from its sequence pass by float32 rounding (1e-6);
    # the simulation carries that along without amplifying it much over 100 frames
    np.testing.assert_allclose(live.joint_pos, offline.joint_pos, atol=1e-4)
    np.testing.assert_array_equal(live.falls, offline.falls)


def test_bad_input_is_named(rec) -> None:
    cfg = FeatureConfig()
    stream = GripStream(_Runner(0.0), _Oracle(rec, cfg), rec.slice_frames(0, 2))
    frame = next(sensor_frames(rec, cfg))
    with pytest.raises(ValueError, match="frame 0: the features need the 10 insole values"):
        stream.push(SensorFrame(frame.acc, frame.ori))
    stream.push(frame)
    with pytest.raises(ValueError, match="at least 2 frames, got 1"):
        stream.finish()
    with pytest.raises(ValueError, match="no frame simulated"):
        stream.reconstruction()
