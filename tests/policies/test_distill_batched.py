"""DAgger rollouts on the batched training environments (``vec_env = "batched"``, the default)
collect what one-by-one environments (``"dummy"``) collect, to float rounding."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from envs.factory import make_tracking_env
from envs.tracking_env import SAMPLE_REFERENCE
from grip.assets import SHIPPED_POLICY
from policies.distill import DistillConfig, Distiller


def _collect(tmp_path, vec_env: str):
    cfg = DistillConfig(iterations=1, decisions_per_iteration=24, n_envs=3, max_samples=64,
                        categories=(), reverse_categories=(), mirror_references=False,
                        max_episode_frames=5, vec_env=vec_env)  # fmt: skip
    dist = Distiller(cfg, [SHIPPED_POLICY], tmp_path / vec_env, SAMPLE_REFERENCE,
                     make_tracking_env)  # fmt: skip
    return dist.collect()


def test_batched_rollouts_collect_the_dummy_ones(tmp_path) -> None:
    xb, yb, sb = _collect(tmp_path, "batched")
    xd, yd, sd = _collect(tmp_path, "dummy")
    assert xb.shape == xd.shape and yb.shape == yd.shape
    # float16 samples: equal up to a rounding step of the (normalised, clipped) inputs
    np.testing.assert_allclose(xb.astype(np.float32), xd.astype(np.float32), atol=2e-2)
    np.testing.assert_allclose(yb.astype(np.float32), yd.astype(np.float32), atol=2e-2)
    assert sb["episodes"] == sd["episodes"] and sb["falls"] == sd["falls"]


def test_vec_env_is_checked() -> None:
    with pytest.raises(ValueError, match="vec_env"):
        DistillConfig(vec_env="subproc")
    with pytest.raises(ValueError, match="teacher_root must be one of"):
        DistillConfig(teacher_root="pelvis")


def test_the_rollouts_take_the_teacher_root(tmp_path) -> None:
    """``teacher_root`` reaches every rollout environment's settings."""
    cfg = DistillConfig(iterations=1, decisions_per_iteration=24, n_envs=2, max_samples=64,
                        categories=(), reverse_categories=(), mirror_references=False,
                        max_episode_frames=5, teacher_root="estimate")  # fmt: skip
    dist = Distiller(cfg, [SHIPPED_POLICY], tmp_path / "d", SAMPLE_REFERENCE, make_tracking_env)
    venv = dist._make_env()
    try:
        assert {e.cfg.teacher_root for e in venv.envs} == {"estimate"}
    finally:
        venv.close()


def test_the_sample_buffer_keeps_the_newest_in_one_copy() -> None:
    from policies.distill import SampleBuffer

    buf = SampleBuffer(5)
    with pytest.raises(ValueError, match="no samples"):
        buf.samples()
    buf.add(np.arange(3, dtype=np.float16)[:, None], np.arange(3, dtype=np.float16)[:, None])
    assert sorted(buf.samples()[0][:, 0]) == [0, 1, 2]
    buf.add(np.arange(3, 7, dtype=np.float16)[:, None], np.arange(3, 7, dtype=np.float16)[:, None])
    x, y = buf.samples()
    assert sorted(x[:, 0]) == [2, 3, 4, 5, 6] and (x == y).all()
    buf.add(np.arange(10, 18, dtype=np.float16)[:, None], np.zeros((8, 1), np.float16))
    assert sorted(buf.samples()[0][:, 0]) == [13, 14, 15, 16, 17]  # a chunk above capacity
    with pytest.raises(ValueError, match="3 inputs against 2"):
        buf.add(np.zeros((3, 1)), np.zeros((2, 1)))


def test_a_larger_student_is_its_own_network_and_exports(tmp_path) -> None:
    """``student_hidden``: the student is a fresh network of those widths between the member's
    inputs and outputs, it acts, and its policy file loads with its own sizes."""
    from policies.runner import PolicyRunner

    cfg = DistillConfig(iterations=1, decisions_per_iteration=24, n_envs=2, max_samples=64,
                        categories=(), reverse_categories=(), mirror_references=False,
                        max_episode_frames=5, student_hidden=(96, 48))  # fmt: skip
    dist = Distiller(cfg, [SHIPPED_POLICY], tmp_path / "d", SAMPLE_REFERENCE, make_tracking_env)
    widths = [m.out_features for m in dist.student.actor if isinstance(m, torch.nn.Linear)]
    assert widths[:2] == [96, 48]
    x, y, _ = dist.collect()
    assert len(x) == 24 and y.shape[1] == widths[-1]
    dist.export(tmp_path / "s.pt")
    loaded = PolicyRunner.load(tmp_path / "s.pt")
    assert [m.out_features for m in loaded.actor if isinstance(m, torch.nn.Linear)] == widths
    with pytest.raises(ValueError, match="student_hidden"):
        DistillConfig(student_hidden=(0,))
