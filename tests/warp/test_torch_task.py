"""The torch twins of the task's numpy kernels (:mod:`envs.warp.torch_task`) equal them.

Inputs are random states of 7 bodies-worth of noise on real rotations, in float64 on both sides,
so the pairs agree to 1e-12 (only the order of sums may differ). No MuJoCo Warp is needed.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from envs import rewards as R
from envs.heightfield import HeightField, sample_heightmap
from envs.warp import torch_task as T
from grip.core import skeleton as sk
from grip.task import amp as A
from grip.task import observations as O
from grip.task.config import KINEMATIC_OBS, RewardConfig

B, NJ = 7, sk.N_JOINTS


def _rotations(rng: np.random.Generator, *shape: int) -> np.ndarray:
    n = int(np.prod(shape))
    return Rotation.random(n, random_state=rng.integers(1 << 31)).as_matrix().reshape(*shape, 3, 3)


@pytest.fixture
def states():
    rng = np.random.default_rng(0)
    pvw = rng.normal(size=(B, 3, NJ, 3))
    pvw[:, 0] += np.array([1.0, -2.0, 0.9])
    rot = _rotations(rng, B, NJ)
    rot[0, 0] = np.diag([1.0, -1.0, -1.0])  # pelvis facing straight down: identity heading
    est = rng.normal(size=(B, O.OBS_ROW_DIM))
    est[:, O.OBS_ROW["leaf_rot"]] = _rotations(rng, B, 4).reshape(B, -1)
    ref_pvw = pvw + 0.05 * rng.normal(size=pvw.shape)
    ref_rot = _rotations(rng, B, NJ)
    hinges = rng.normal(size=(B, 2 * A.N_HINGES))
    return pvw, rot, est, ref_pvw, ref_rot, hinges


def _t(a: np.ndarray) -> torch.Tensor:
    return torch.as_tensor(a, dtype=torch.float64)


def test_heading_matrices_equal_numpy(states):
    _, rot, *_ = states
    want = O.heading_matrices(rot[:, 0])
    np.testing.assert_allclose(T.heading_matrices(_t(rot[:, 0])).numpy(), want, atol=1e-14)
    np.testing.assert_array_equal(want[0], np.eye(3))


@pytest.mark.parametrize("variant", KINEMATIC_OBS)
def test_observations_equal_numpy(states, variant):
    pvw, rot, est, *_ = states
    h = O.heading_matrices(rot[:, 0])
    kin, self_vec = O.observation_rows(variant, h, pvw, rot, est)
    tk, ts = T.observation_parts(variant, _t(h), _t(pvw), _t(rot), _t(est))
    assert tk.shape == kin.shape == (B, O.kinematic_dim(variant))
    np.testing.assert_allclose(tk.numpy(), kin, atol=1e-12)
    np.testing.assert_allclose(ts.numpy(), self_vec, atol=1e-12)


@pytest.mark.parametrize("align", [True, False])
@pytest.mark.parametrize("form", ["mean_sq", "norm"])
def test_tracking_terms_equal_numpy(states, align, form):
    pvw, rot, _, ref_pvw, ref_rot, _ = states
    cfg = dataclasses.replace(RewardConfig(), form=form)
    rng = np.random.default_rng(1)
    sd, rd = rng.normal(size=(B, 2)), rng.normal(size=(B, 2))
    gap = 0.3 * rng.normal(size=(B, 2))

    def rows(p, r):
        return np.concatenate([p.reshape(B, -1), r.reshape(B, -1)], axis=1)

    want, sq = R.tracking_terms_rows(rows(pvw, rot), rows(ref_pvw, ref_rot), cfg, align, sd.copy(),
                                     rd, 0.3, gap)  # fmt: skip
    got, tsq = T.tracking_terms(_t(pvw), _t(rot), _t(ref_pvw), _t(ref_rot), cfg, align, _t(sd),
                                _t(rd), 0.3, _t(gap))  # fmt: skip
    np.testing.assert_allclose(got.numpy(), want, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(tsq.numpy(), sq, rtol=1e-12, atol=1e-14)
    assert (want < 1).all()  # (the inputs are off the reference: no term saturates)


def test_amp_frames_equal_numpy(states):
    pvw, rot, _, _, _, hinges = states
    h = O.heading_matrices(rot[:, 0])
    want = A.amp_frames(pvw, rot, hinges, h, np.empty((B, A.FRAME_DIM)))
    got = T.amp_frames(_t(pvw), _t(rot), _t(hinges), _t(h))
    np.testing.assert_allclose(got.numpy(), want, atol=1e-13)


def test_height_fields_equal_numpy():
    """Each row samples its own field (two fields of different grids) or the flat floor (-1)."""
    rng = np.random.default_rng(2)
    fields = [
        HeightField(np.array([-1.0, 0.5]), 0.1, rng.uniform(0, 0.5, size=(12, 17))),
        HeightField(np.array([0.3, -1.2]), 0.05, rng.uniform(0, 0.8, size=(30, 21))),
    ]
    grid = O.heightmap_grid(9, 1.5)
    centers = rng.uniform(-2.0, 2.5, size=(B, 2))  # partly off the grids: 0 there
    yaw = rng.uniform(-np.pi, np.pi, size=B)
    h = np.zeros((B, 3, 3))
    h[:, 0, 0] = h[:, 1, 1] = np.cos(yaw)
    h[:, 1, 0], h[:, 0, 1], h[:, 2, 2] = np.sin(yaw), -np.sin(yaw), 1.0
    field = np.arange(B) % 3 - 1  # -1 (flat), 0, 1, -1, ...
    want = np.stack([sample_heightmap(fields[k] if k >= 0 else None, c, hh[:2, :2], grid)
                     for c, hh, k in zip(centers, h, field, strict=True)])  # fmt: skip
    th = T.TorchHeightFields(fields, "cpu", torch.float64)
    got = th.around(_t(centers), _t(h), _t(grid), torch.as_tensor(field))
    np.testing.assert_allclose(got.numpy(), want, atol=1e-12)
    for k in (0, 1):
        assert (want[field == k] > 0).any() and (want[field == k] == 0).any()
    assert (want[field == -1] == 0).all()
    np.testing.assert_array_equal(th.max_height, [f.max_height for f in fields])
