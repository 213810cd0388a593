"""Episodes played side by side (:class:`grip.pipeline.BatchedPlayer`) give each episode the
numbers it gets played alone.

A scripted controller acts row by row (elementwise numpy on its observation), so its action for
a row of a batch equals its action for that observation alone, bit for bit; the batched
reconstructions must then equal the sequential ones exactly (tolerance 0), falls, recoveries,
episodes of different lengths and subjects, and a failing episode included. (A torch MLP's
batched products may round the last float32 bits of an action otherwise:
``benchmarks/eval_batch.py`` measures what that does to the metrics.)
"""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest

from envs.tracking_env import SAMPLE_REFERENCE
from grip.core.reference import PRIMARY, ReferenceSet
from grip.pipeline import Episode, GripPipeline, RecoveryConfig, start_from_clip
from grip.task.config import TrackingEnvConfig


class _RowRunner:
    """Acts from the kinematic observation, elementwise (a batch's rows are independent);
    ``action`` in [-1, 1] by frame; ``prob``: the discriminator's answer (0: every low pelvis
    is a fall)."""

    obs_keys = ("kinematic",)

    def __init__(self, gain: float = 0.4, prob: float = 0.0, repeat: int = 1) -> None:
        self.gain, self.prob = gain, prob
        self.disc = object()
        self.env_cfg = TrackingEnvConfig(amp_window=2, action_repeat=repeat)
        self.calls: list[int] = []  # rows per call

    def act(self, obs: dict) -> np.ndarray:
        x = np.asarray(obs["kinematic"], np.float64)
        self.calls.append(1 if x.ndim == 1 else x.shape[0])
        return self.gain * np.tanh(x[..., :69]) - 0.3

    def fall_probability(self, amp_obs: np.ndarray) -> np.ndarray:
        return np.full(np.atleast_2d(amp_obs).shape[0], self.prob)


@pytest.fixture(scope="module")
def clips():
    ref = ReferenceSet.load(SAMPLE_REFERENCE)
    return [ref.clip(0), ref.clip(1)]


def _part(clip, start: int, stop: int, taller_m: float = 0.0):
    """Frames ``start..stop`` of a clip, on a body ``taller_m`` taller (another subject)."""
    arrays = {k: getattr(clip, k)[start:stop] for k in PRIMARY}
    body = dataclasses.replace(clip.body, height_m=clip.body.height_m + taller_m)
    return dataclasses.replace(clip, body=body, **arrays)


def _episodes(clips, stop_at_fall: bool = False) -> list:
    """Seven episodes of 40..250 frames, three subjects; the fifth fails at frame 30 (its
    estimate turns NaN there, so the controller's action does)."""
    a, b = clips
    parts = [_part(a, 0, 250), _part(b, 10, 90, 0.05), _part(a, 40, 80), _part(b, 0, 250),
             _part(a, 20, 160, -0.04), _part(b, 100, 240), _part(a, 0, 120, 0.05)]  # fmt: skip
    bad = copy.copy(parts[4])  # (a copy without the clip's validation)
    bad.est_pos = bad.est_pos.copy()
    bad.est_pos[30:] = np.nan
    parts[4] = bad
    return [Episode(c, start_from_clip(c), c.body, None, stop_at_fall) for c in parts]


def _play(runner, recovery: RecoveryConfig, episodes: list, batch: int, threads: int = 1):
    pipe = GripPipeline(runner, None, recovery)
    got = {i: (r, info) for i, r, info in pipe.play_many(episodes, batch, threads)}
    return [got[i] for i in range(len(episodes))]


_FIELDS = ("joint_pos", "global_rot", "grf", "cop", "torques", "contacts", "falls")


def _assert_same(seq: list, bat: list) -> None:
    for (r1, i1), (r2, i2) in zip(seq, bat, strict=True):
        if isinstance(r1, Exception):
            assert type(r2) is type(r1) and str(r2) == str(r1)
            continue
        for k in _FIELDS:
            np.testing.assert_array_equal(getattr(r2, k), getattr(r1, k), err_msg=k)
        assert r2.notes == r1.notes and i2["blowups"] == i1["blowups"]


@pytest.mark.parametrize("repeat", [1, 3])
def test_batched_play_equals_sequential_with_falls_recovery_and_a_failure(clips, repeat):
    rec = RecoveryConfig(history_frames=20)
    seq = _play(_RowRunner(repeat=repeat), rec, _episodes(clips), batch=1)
    runner = _RowRunner(repeat=repeat)
    bat = _play(runner, rec, _episodes(clips), batch=3, threads=2)
    _assert_same(seq, bat)
    # what the comparison covers: recovered falls, different lengths, one failure
    recons = [r for r, _ in seq if not isinstance(r, Exception)]
    assert sum(r.falls.shape[0] for r in recons) >= 2
    assert len({r.n_frames for r in recons}) >= 4
    assert isinstance(seq[4][0], ValueError) and "finite" in str(seq[4][0])
    assert max(runner.calls) == 3  # one forward over the rows whose decision is due


def test_batched_evaluation_stops_each_episode_at_its_own_fall(clips):
    off = RecoveryConfig(enabled=False)
    seq = _play(_RowRunner(), off, _episodes(clips, stop_at_fall=True), batch=1)
    for batch, threads in ((4, 1), (16, 2)):  # more rows than episodes: the batch shrinks
        _assert_same(seq, _play(_RowRunner(), off, _episodes(clips, True), batch, threads))
    ends = [r.n_frames for r, _ in seq if not isinstance(r, Exception)]
    fell = [r.fell for r, _ in seq if not isinstance(r, Exception)]
    assert any(fell) and len(set(ends)) >= 4


def test_an_exception_in_place_of_an_episode_is_its_result(clips):
    eps = _episodes(clips)[:2]
    oops = OSError("unreadable")
    got = _play(_RowRunner(), RecoveryConfig(), [eps[0], oops, eps[1]], batch=2)
    assert got[1][0] is oops and got[0][0].n_frames == 250 and got[2][0].n_frames == 80


def test_policy_eval_rows_are_the_same_batched(monkeypatch):
    import grip.eval.policy as P
    from grip.kinematics.features import FeatureConfig
    from prism_tools.io import load_recording

    rec = load_recording("grip/assets/sample_recording.npz")
    recs = [rec.slice_frames(0, 120), rec.slice_frames(100, 180), rec.slice_frames(50, 250)]
    est = type("Est", (), {"cfg": type("Cfg", (), {"features": FeatureConfig()})()})()
    seq = P.evaluate_policy(_RowRunner(), est, recs, reference="truth")
    bat = P.evaluate_policy(_RowRunner(), est, recs, reference="truth", play_batch=2,
                            threads=2)  # fmt: skip
    assert [r["frames"] for r in bat] == [r["frames"] for r in seq]
    for a, b in zip(seq, bat, strict=True):
        assert a.keys() == b.keys()
        for k, v in a.items():
            assert v == b[k] or (v != v and b[k] != b[k]), k  # (NaN == NaN)
