"""benchmarks/pace_cause.py: how far the followed pelvis runs from the truth's."""

from __future__ import annotations

import numpy as np
import pytest

from tests.cli.test_data_cli import _benchmark


def _walk(speed: float, frames: int, fps: float = 100.0) -> np.ndarray:
    t = np.arange(frames) / fps
    return np.stack([speed * t, np.zeros(frames), np.full(frames, 0.9)], axis=1)


def test_a_followed_pelvis_that_runs_ahead_of_the_truth() -> None:
    pc = _benchmark("pace_cause")
    truth = _walk(1.2, 600)
    ahead = _walk(1.32, 700)[:, :2] + [3.0, -2.0]  # 10 % faster, starting elsewhere
    d = pc.followed_to_truth(ahead, truth, 100.0)
    assert d["ref_to_truth_1s_m"] == pytest.approx(0.12, abs=1e-9)
    assert d["ref_to_truth_5s_m"] == pytest.approx(0.12 * 4.99, abs=1e-9)
    assert d["ref_to_truth_end_m"] == pytest.approx(0.12 * 5.99, abs=1e-9)  # common frames only
    assert d["ref_over_truth_speed"] == pytest.approx(1.1)
    same = pc.followed_to_truth(truth[:, :2] + 5.0, truth, 100.0)
    assert max(same[k] for k in ("ref_to_truth_1s_m", "ref_to_truth_5s_m")) < 1e-9
    short = pc.followed_to_truth(truth[:300, :2], truth, 100.0)
    assert short["ref_to_truth_5s_m"] is None  # a segment shorter than 5 s has no 5 s value
