"""``benchmarks/bench_travel.py``: the ground a pelvis covers against the truth's."""

from __future__ import annotations

import numpy as np
import pytest

from tests.cli.test_data_cli import _benchmark


def _line(speed: float, frames: int) -> np.ndarray:
    t = np.arange(frames) / 100.0
    return np.stack([speed * t, np.zeros(frames), np.full(frames, 0.9)], axis=1)


def test_a_pelvis_that_covers_less_ground_than_the_walker() -> None:
    bt = _benchmark("bench_travel")
    truth = _line(1.2, 501)
    ratio, end = bt.travel(_line(1.08, 501), truth)  # 10 % short
    assert ratio == pytest.approx(0.9) and end == pytest.approx(0.6)
    wiggle = truth.copy()
    wiggle[1::2, 1] += 0.05  # the same end, a longer zig-zag path
    ratio, end = bt.travel(wiggle, truth)
    assert ratio > 1.5 and end == pytest.approx(0.0)
    assert bt.travel(_line(1.2, 600), truth)[0] == pytest.approx(1.0)  # common frames only
    assert np.isnan(bt.travel(truth, np.zeros((10, 3)))[0])  # a truth that does not move


def test_a_folder_without_reconstructions_is_refused(tmp_path) -> None:
    bt = _benchmark("bench_travel")
    with pytest.raises(SystemExit, match="--save-recons"):
        bt.main([str(tmp_path), "--data", str(tmp_path)])
