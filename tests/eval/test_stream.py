"""Streaming GRIP gives the offline reconstruction, two frames later.

A scripted policy and an oracle estimator (it replays the ground truth, like
:func:`grip.kinematics.reference.oracle_reference_clip`) check the stream's machinery against
:class:`grip.pipeline.Player` on the whole clip closely, falls and recoveries included; the shipped
models check the whole stack against ``GripReconstructor``.
"""

from __future__ import annotations

import numpy as np
import pytest

from grip.core.rotations import matrix_to_6d
from grip.eval.stream import LATENCY_FRAMES, GripStream
from grip.kinematics.features import FeatureConfig, SensorFrame, sensor_frames, targets
from grip.kinematics.reference import oracle_reference_clip
from grip.pipeline import GripPipeline, RecoveryConfig, start_from_clip
from grip.task.config import TrackingEnvConfig
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

    def stream_from(self, first):
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
    offline, _ = GripPipeline(runner, None, recovery).play(clip, start_from_clip(clip), clip.body)
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


# ------------------------------------------------------------------ time: indices and gaps
def _stream(rec, runner=None, **kw) -> GripStream:
    cfg = FeatureConfig()
    return GripStream(runner or _Runner(0.0), _Oracle(rec, cfg), rec.slice_frames(0, 2),
                      RecoveryConfig(history_frames=20), capacity=64, **kw)  # fmt: skip


def _push_all(stream: GripStream, frames: dict, **how) -> dict[int, object]:
    """Push ``{index: frame}`` in order (``how``: "index" or "timestamp_s"); the outputs by the
    input index; then finish."""
    outs = {}
    for i, f in frames.items():
        key = how.get("key")
        kw = {} if key is None else {key: i if key == "index" else 1000.0 + i / 100 + 0.002}
        outs[i] = stream.push(f, **kw)
    for o in stream.finish():
        outs[o.frame + LATENCY_FRAMES] = o
    return outs


def _numbered(outs: dict) -> None:
    for i, o in outs.items():
        assert o is None or o.frame == i - LATENCY_FRAMES, (i, o.frame)


@pytest.fixture(scope="module")
def full(rec):
    """The stream of every frame, for comparisons."""
    stream = _stream(rec)
    _run(stream, list(sensor_frames(rec, FeatureConfig())))
    return stream.reconstruction()


def test_a_refused_frame_keeps_the_numbers_of_the_next_ones(rec, full) -> None:
    frames = list(sensor_frames(rec, FeatureConfig()))
    stream = _stream(rec)
    outs = {}
    for i, f in enumerate(frames):
        if i == 50:  # a sensor dropout: refused, and the next frame is still frame 51
            with pytest.raises(ValueError, match="non-finite sensor values at frame 50"):
                stream.push(SensorFrame(np.full_like(f.acc, np.nan), f.ori, f.insole))
            continue
        outs[i] = stream.push(f)
    for o in stream.finish():
        outs[o.frame + LATENCY_FRAMES] = o
    _numbered(outs)
    live = stream.reconstruction()
    assert live.n_frames == rec.n_frames and live.notes["stream_filled"] == [[50, 50]]
    assert [(e.kind, e.first, e.last) for e in stream.events] == [("filled", 50, 50)]
    # the oracle estimate does not read the sensors: the filled frame is simulated as before
    np.testing.assert_allclose(live.joint_pos, full.joint_pos, atol=1e-9)


@pytest.mark.parametrize("key", ["index", "timestamp_s"])
def test_duplicate_and_earlier_frames_are_refused_and_change_nothing(rec, full, key) -> None:
    frames = dict(enumerate(sensor_frames(rec, FeatureConfig())))
    stream = _stream(rec)
    at = (lambda i: {key: i}) if key == "index" else (lambda i: {key: 1000.0 + i / 100})
    for i in range(40):
        stream.push(frames[i], **at(i))
    with pytest.raises(ValueError, match=r"frame 39.* already pushed"):
        stream.push(frames[39], **at(39))
    with pytest.raises(ValueError, match=r"frame 12.* earlier than frame 39"):
        stream.push(frames[12], **at(12))
    outs = _push_all(stream, {i: frames[i] for i in range(40, rec.n_frames)}, key=key)
    _numbered(outs)
    live = stream.reconstruction()
    assert live.n_frames == rec.n_frames and stream.events == []
    np.testing.assert_allclose(live.joint_pos, full.joint_pos, atol=1e-9)
    with pytest.raises(ValueError, match="not both"):
        _stream(rec).push(frames[0], index=0, timestamp_s=0.0)


@pytest.mark.parametrize("key", ["index", "timestamp_s"])
def test_a_short_gap_is_interpolated_and_simulated(rec, full, key) -> None:
    frames = {i: f for i, f in enumerate(sensor_frames(rec, FeatureConfig()))
              if not 70 <= i <= 74}  # fmt: skip
    stream = _stream(rec)
    outs = _push_all(stream, frames, key=key)
    _numbered(outs)
    assert outs[75].frame == 73  # the newest frame, after the five filled ones
    assert [o.frame for o in (stream.frame(t) for t in range(70, 74))] == [70, 71, 72, 73]
    live = stream.reconstruction()
    assert live.n_frames == rec.n_frames and live.notes["stream_filled"] == [[70, 74]]
    np.testing.assert_allclose(live.joint_pos, full.joint_pos, atol=1e-9)


def test_the_interpolated_sensors_lie_between_their_neighbours(rec) -> None:
    frames = list(sensor_frames(rec, FeatureConfig()))
    seen = []
    stream = _stream(rec)
    push = stream._features.push
    stream._features.push = lambda f: (seen.append(f), push(f))[1]
    for i in (0, 1, 2, 6):
        stream.push(frames[i], index=i)
    a, b = frames[2], frames[6]
    for k, f in enumerate(seen[3:6], start=1):  # frames 3, 4, 5
        np.testing.assert_allclose(f.acc, a.acc + k / 4 * (b.acc - a.acc), atol=1e-12)
        np.testing.assert_allclose(f.insole, a.insole + k / 4 * (b.insole - a.insole))
        np.testing.assert_allclose(f.ori @ np.swapaxes(f.ori, -1, -2), np.broadcast_to(
            np.eye(3), f.ori.shape), atol=1e-9)  # rotations  # fmt: skip


class _IndexedOracle(_Oracle):
    """The ground truth of the frame whose accelerations the row carries (a stream does not
    step the estimator over a gap it does not fill, so counting steps loses the frame)."""

    def stream_from(self, first):
        t, cfg = self._t, self.cfg.features
        acc = np.stack([f.acc.reshape(-1) for f in sensor_frames(self._rec, cfg)])
        s = len(cfg.sites)

        def step(row):  # a row starts with (acc / acc_scale, gyr, ori) of each site
            a = row[: 15 * s].reshape(s, 15)[:, :3].reshape(-1)
            k = int(np.argmin(np.abs(acc / cfg.acc_scale - a).sum(axis=1)))
            return {"fp": t.joint_pos[k], "fa": matrix_to_6d(t.global_rot[k]), "lv": t.velocity[k]}

        return type("S", (), {"step": staticmethod(step)})()


def test_a_long_gap_is_reported_and_the_stream_resumes_after_it(rec, full) -> None:
    frames = {i: f for i, f in enumerate(sensor_frames(rec, FeatureConfig()))
              if not 60 <= i <= 99}  # fmt: skip
    stream = _stream(rec)
    oracle = _IndexedOracle(rec, FeatureConfig())
    oracle._rec = rec
    stream._kin = oracle.stream_from(None)
    outs = _push_all(stream, frames, key="index")
    _numbered(outs)
    assert outs[100] is None and outs[101] is None  # the pipeline restarts...
    assert outs[102].frame == 100  # ... and gives frame t - 2 again
    assert [(e.kind, e.first, e.last) for e in stream.events] == [("gap", 60, 99)]
    live = stream.reconstruction()
    assert live.n_frames == rec.n_frames and live.notes["stream_gap"] == [[60, 99]]
    # before the gap: as without it; in it: the last pose held, no forces; after it: standing
    np.testing.assert_allclose(live.joint_pos[:58], full.joint_pos[:58], atol=1e-9)
    np.testing.assert_allclose(live.joint_pos[60:100], np.broadcast_to(
        live.joint_pos[59], (40, 24, 3)))  # fmt: skip
    assert np.isnan(live.torques[60:100]).all() and np.isfinite(live.torques[100:]).all()
    # it restarts at the estimate (the oracle's: the truth) and follows it as before the gap
    pose = live.joint_pos[100] - live.joint_pos[100, :1]
    assert np.linalg.norm(pose - targets(rec).joint_pos[100], axis=-1).mean() < 0.02
    assert live.joint_pos[100:110, 0, 2].min() > 0.6  # standing


def test_a_gap_before_the_calibration_frames_is_refused(rec) -> None:
    frames = list(sensor_frames(rec, FeatureConfig()))
    stream = _stream(rec)
    stream.push(frames[0], index=0)
    with pytest.raises(ValueError, match="starts with frames 0 and 1"):
        stream.push(frames[3], index=3)


class _BlowingRunner(_Runner):
    """Zero actions; before the step to ``frame`` the stream's simulation gets ``qvel``."""

    def __init__(self, frame: int, qvel: float) -> None:
        super().__init__(0.0)
        self.disc, self.frame, self.qvel, self.stream = None, frame, qvel, None

    def act(self, obs: dict) -> np.ndarray:
        player = self.stream.player
        if player.t + 1 == self.frame:
            player.h.data.qvel[:] = self.qvel
        return np.zeros(69)


@pytest.mark.parametrize("qvel", [1e3, 1e12])
def test_a_blow_up_is_recovered_and_the_stream_goes_on(rec, qvel) -> None:
    runner = _BlowingRunner(60, qvel)
    stream = runner.stream = _stream(rec, runner)
    outs = _run(stream, list(sensor_frames(rec, FeatureConfig())))  # every frame comes out
    assert outs[60].blowup and outs[60].fall[1] == 60
    assert [(e.kind, e.last) for e in stream.events] == [("blowup", 60)]
    live = stream.reconstruction()
    assert live.n_frames == rec.n_frames and live.notes["blowups"] == 1
    assert np.linalg.norm(live.joint_pos - targets(rec).root_pos[:, None], axis=-1).max() < 3


# ------------------------------------------------------------------ clock jumps (issue 50)
def test_a_clock_jump_beyond_the_limits_is_refused_at_once(rec, full, monkeypatch) -> None:
    """10,000 s between two frames (a wall clock set by NTP): a million frames to hold, which
    blocked the stream for minutes; refused before any of them is held, and the stream goes
    on."""
    from grip.core.reference import LiveEstimate

    frames = list(sensor_frames(rec, FeatureConfig()))
    stream = _stream(rec)
    for i in range(60):
        stream.push(frames[i], timestamp_s=1000.0 + i / 100)

    def no_hold(self, n):
        raise AssertionError(f"{n} frames held before the refusal")

    with monkeypatch.context() as m:
        m.setattr(LiveEstimate, "append_held", no_hold)
        refused = r"frame 1000060 \(t = 11000\.6000 s\).*max_duration_s"
        with pytest.raises(ValueError, match=refused):
            stream.push(frames[60], timestamp_s=11000.6)
    with pytest.raises(ValueError, match=r"frame 2000000.*max_duration_s"):
        stream.push(frames[60], index=2_000_000)
    stream._limits = stream._limits.with_overrides(["max_duration_s=inf"])
    with pytest.raises(ValueError, match=r"frame 2000000.*max_frames"):
        stream.push(frames[60], index=2_000_000)
    outs = _push_all(stream, {i: frames[i] for i in range(60, rec.n_frames)}, key="timestamp_s")
    _numbered(outs)
    live = stream.reconstruction()
    assert live.n_frames == rec.n_frames and stream.events == []
    np.testing.assert_allclose(live.joint_pos, full.joint_pos, atol=1e-9)


def test_a_long_gap_within_the_limits_is_held_quickly(rec, monkeypatch) -> None:
    """300 s of dropout (30,000 frames at 100 Hz) took 18 s to hold frame by frame: the gap is
    now held in one step (counted, not timed: no frame of it is appended or simulated)."""
    from grip.core.reference import LiveEstimate

    frames = list(sensor_frames(rec, FeatureConfig()))
    stream = _stream(rec)
    for i in range(60):
        stream.push(frames[i], timestamp_s=i / 100)
    calls = {"append": 0, "step": 0}
    append, step = LiveEstimate.append, type(stream.player).step

    def counted_append(self, *a, **k):
        calls["append"] += 1
        return append(self, *a, **k)

    def counted_step(self, *a, **k):
        calls["step"] += 1
        return step(self, *a, **k)

    monkeypatch.setattr(LiveEstimate, "append", counted_append)
    monkeypatch.setattr(type(stream.player), "step", counted_step)
    for k, i in enumerate(range(60, 70)):
        stream.push(frames[i], timestamp_s=300.0 + k / 100)
    assert calls["append"] <= 20 and calls["step"] <= 20, calls  # (10 frames pushed, not 30,000)
    tail = stream.finish()
    assert tail[-1].frame == 30_009
    assert [(e.kind, e.first, e.last) for e in stream.events] == [("gap", 60, 29_999)]
    live = stream.reconstruction()
    assert live.n_frames == 30_010 and np.isnan(live.torques[60:30_000]).all()
    np.testing.assert_allclose(live.joint_pos[60:30_000], np.broadcast_to(
        live.joint_pos[59], (29_940, 24, 3)))  # fmt: skip


@pytest.mark.parametrize("after", [0, 1, 5])
def test_finish_after_a_dropout_longer_than_the_buffer(rec, after) -> None:
    """The stream's buffers hold 64 frames; a dropout of 140 frames, then ``after`` more
    frames, then the end: ``finish`` raised IndexError."""
    frames = list(sensor_frames(rec, FeatureConfig()))
    stream = _stream(rec)
    for i in range(60):
        stream.push(frames[i], index=i)
    for k in range(after + 1):
        stream.push(frames[60 + k], index=200 + k)
    tail = stream.finish()
    assert tail and tail[-1].frame == 200 + after
    assert [(e.kind, e.first, e.last) for e in stream.events] == [("gap", 60, 199)]
    live = stream.reconstruction()
    assert live.n_frames == 201 + after
    assert np.isfinite(live.joint_pos).all()
