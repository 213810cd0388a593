"""Pace metrics (:mod:`grip.core.metrics.pace`) on hand-computed pelvis tracks."""

import math

import numpy as np
import pytest

from grip.core import metrics as M

FPS = 100.0
SPEED = 1.3  # m/s, a walk


def _walk(n: int, speed: float = SPEED, direction=(0.6, 0.8), start=(2.0, -1.0)) -> np.ndarray:
    """``(n, 3)`` a pelvis walking in a straight line at ``speed`` from ``start``, 0.9 m up."""
    t = np.arange(n) / FPS
    xy = np.asarray(start) + np.outer(speed * t, direction)
    return np.column_stack([xy, np.full(n, 0.9)])


def test_a_body_that_stands_still_while_its_reference_walks_away_fails() -> None:
    ref = _walk(500)
    still = np.repeat(ref[:1], 500, axis=0)
    p = M.measure_pace(still, ref, FPS)
    walked = np.linalg.norm(ref[:, :2] - ref[0, :2], axis=1)
    np.testing.assert_allclose(p.to_ref.distance_m, walked, atol=1e-12)
    m = p.metrics()
    # frame 499 closes the first 5 s: the distance the reference walked by then
    assert m["pace_5s_m"] == pytest.approx(walked[499]) == pytest.approx(SPEED * 4.99)
    assert m["pace_1s_m"] == pytest.approx(SPEED * 0.99)
    assert m["pace_end_m"] == pytest.approx(walked[-1])
    assert m["drift_mps"] == pytest.approx(SPEED)
    assert m["pace_5s_m"] > 6.0  # metres behind: the metric flags it
    assert all(math.isnan(m[k]) for k in M.ROOT_GT_KEYS)  # no truth given


def test_a_body_that_keeps_pace_has_no_gap_and_no_drift() -> None:
    ref = _walk(500)
    m = M.measure_pace(ref.copy(), ref, FPS).metrics()
    for k in M.PACE_KEYS:
        assert m[k] == pytest.approx(0.0, abs=1e-12), k


def test_a_slower_body_drifts_at_the_speed_difference() -> None:
    ref = _walk(300)
    slow = _walk(300, speed=0.8 * SPEED)
    p = M.measure_pace(slow, ref, FPS)
    assert p.to_ref.drift_mps == pytest.approx(0.2 * SPEED)
    assert p.to_ref.at_end_m == pytest.approx(0.2 * SPEED * 2.99)
    assert math.isnan(p.to_ref.at_5s_m)  # 3 s of frames: no 5 s value


def test_a_constant_offset_and_height_are_not_drift() -> None:
    ref = _walk(200)
    beside = ref + np.array([0.0, 0.3, -0.4])  # 0.3 m to the side, 0.4 m lower
    g = M.horizontal_gap(beside, ref, FPS)
    np.testing.assert_allclose(g.distance_m, 0.3, atol=1e-12)
    assert g.at_1s_m == pytest.approx(0.3) and g.at_end_m == pytest.approx(0.3)
    assert g.drift_mps == pytest.approx(0.0, abs=1e-12)


def test_the_truth_gives_the_distance_to_the_ground_truth() -> None:
    gt = _walk(600)
    ref = _walk(600, speed=1.1 * SPEED)  # the estimate overshoots the truth
    sim = _walk(600, speed=0.9 * SPEED)  # the body lags the truth
    m = M.measure_pace(sim, ref, FPS, gt).metrics()
    assert m["pace_5s_m"] == pytest.approx(0.2 * SPEED * 4.99)
    assert m["root_gt_1s_m"] == pytest.approx(0.1 * SPEED * 0.99)
    assert m["root_gt_5s_m"] == pytest.approx(0.1 * SPEED * 4.99)
    assert m["root_gt_end_m"] == pytest.approx(0.1 * SPEED * 5.99)
    assert list(m) == [*M.PACE_KEYS, *M.ROOT_GT_KEYS]


def test_times_and_rates_at_the_edges() -> None:
    d = np.arange(5.0)
    assert M.distance_at(d, 2.0, 1.0) == 1.0  # frame 2 fps - 1
    assert M.distance_at(d, 2.0, 2.5) == 4.0  # the 5th frame closes 2.5 s at 2 Hz
    assert math.isnan(M.distance_at(d, 2.0, 3.0))
    assert M.distance_at(d, 2.0, None) == 4.0
    assert math.isnan(M.distance_at(np.zeros(0), FPS, None))
    assert M.drift_rate(d, 2.0) == pytest.approx(2.0)  # 1 m per frame at 2 Hz
    assert math.isnan(M.drift_rate(d[:1], FPS))
    one = M.horizontal_gap(_walk(1), _walk(1), FPS)
    assert one.at_end_m == 0.0 and math.isnan(one.drift_mps) and math.isnan(one.at_1s_m)


def test_shape_errors() -> None:
    with pytest.raises(ValueError, match="differ"):
        M.horizontal_distance(_walk(10), _walk(11))
    with pytest.raises(ValueError, match=r"\(T >= 1, 3\)"):
        M.horizontal_distance(np.zeros((10, 2)), np.zeros((10, 2)))
    with pytest.raises(ValueError, match="fps"):
        M.horizontal_gap(_walk(10), _walk(10), 0.0)
    with pytest.raises(ValueError, match="differ"):
        M.measure_pace(_walk(10), _walk(10), FPS, _walk(9))
