"""benchmarks/kernel_slope.py: the kernels' values and slopes, the errors read back from the
env's reward terms, and a few episodes of the shipped policy."""

from __future__ import annotations

import argparse
import math

import numpy as np
import pytest

from grip.task.config import RewardConfig
from tests.cli.test_data_cli import _benchmark

K = _benchmark("kernel_slope")


def test_kernel_value_slope_and_the_error_read_back():
    r, s = K.kernel_value_slope(0.1, 100.0, "mean_sq")
    assert r == pytest.approx(math.exp(-1.0)) and s == pytest.approx(-20.0 * math.exp(-1.0))
    assert K.steepest_slope(100.0, "mean_sq") == pytest.approx(math.sqrt(200) * math.exp(-0.5))
    e_star = 1 / math.sqrt(200.0)  # (the steepest point)
    _, s_star = K.kernel_value_slope(e_star, 100.0, "mean_sq")
    assert -s_star == pytest.approx(K.steepest_slope(100.0, "mean_sq"))
    for e in (0.0, 0.03, 0.2):
        np.testing.assert_allclose(K.kernel_error(np.exp(-100.0 * e * e), 100.0, "mean_sq"), e,
                                   atol=1e-9)  # fmt: skip
    r, s = K.kernel_value_slope(0.5, 2.0, "norm")
    assert r == pytest.approx(math.exp(-1.0)) and s == pytest.approx(-2.0 * math.exp(-1.0))
    assert K.kernel_error(np.exp(-1.0), 2.0, "norm") == pytest.approx(0.5)
    # a rotation error of 0.3 rad RMS: value exp(-9), flat (slope under a tenth of the steepest)
    rows = np.array([[np.exp(-1.0), np.exp(-9.0), np.exp(-1.0), np.exp(-0.1)]] * 3)
    out = K.summarise(rows, RewardConfig())
    assert out["imit_pos"]["error_median"] == pytest.approx(0.1)
    assert out["imit_rot"]["error_median"] == pytest.approx(0.3)
    assert out["imit_rot"]["flat_share"] == 1.0 and out["imit_pos"]["flat_share"] == 0.0
    assert out["imit_pos"]["slope_at_median"] == pytest.approx(-20.0 * math.exp(-1.0))


def test_a_few_episodes_of_the_shipped_policy(tmp_path):
    """A tight distance (5 cm) so that episodes fail: every failure is read back, and the
    position kernel's error at the failing frame is above the errors of the decisions before."""
    from envs.tracking_env import SAMPLE_REFERENCE
    from grip.assets import SHIPPED_POLICY

    args = argparse.Namespace(policy=str(SHIPPED_POLICY), reference=str(SAMPLE_REFERENCE),
                              truth=False, category=None, episodes=4, termination_m=0.05,
                              fall_height=0.3, fall_below=0.0, max_frames=60, seed=0,
                              before_s=[0.05])  # fmt: skip
    out = K.play(args)
    assert out["episodes"] == 4 and out["failures"] >= 1
    at, every = out["at_failure"], out["every_decision"]
    assert set(at) == {"imit_pos", "imit_rot", "imit_vel", "imit_angvel"}
    assert at["imit_pos"]["error_median"] >= every["imit_pos"]["error_median"]
    assert sum(n for n, _ in out["by_category"].values()) == 4
