"""The row kernels of the tracking environments' step give the numbers of the per-state pure
functions (rewards, observations, AMP frames) to float rounding."""

from __future__ import annotations

import numpy as np
import pytest

from envs import rewards as R
from grip.core.rotations import rot_x, rot_z
from grip.task import amp as A
from grip.task import observations as O
from grip.task.config import RewardConfig


def _states(b: int, seed: int):
    rng = np.random.default_rng(seed)
    rot = rot_z(rng.uniform(-3, 3, (b, 24))) @ rot_x(rng.uniform(-1, 1, (b, 24)))
    return rng.normal(size=(b, 3, 24, 3)), rot


def _rows(pvw, rot):
    b = pvw.shape[0]
    return np.concatenate([pvw.reshape(b, -1), rot.reshape(b, -1), np.zeros((b, 5))], axis=1)


@pytest.mark.parametrize("form", ["mean_sq", "norm"])
@pytest.mark.parametrize("align", [False, True])
def test_tracking_terms_rows_equal_the_per_state_terms(form, align) -> None:
    cfg = RewardConfig(form=form)
    sim_pvw, sim_rot = _states(3, 0)
    ref_pvw, ref_rot = _states(3, 1)
    ref_pvw = sim_pvw + 0.05 * (ref_pvw - sim_pvw)
    rng = np.random.default_rng(2)
    sim_disp, ref_disp = rng.normal(size=(3, 2)), rng.normal(size=(3, 2))
    gap = rng.normal(size=(3, 2)) * 0.3
    terms, sq = R.tracking_terms_rows(_rows(sim_pvw, sim_rot), _rows(ref_pvw, ref_rot)[:, :432],
                                      cfg, align, sim_disp, ref_disp, 0.3, gap)  # fmt: skip
    assert terms.shape == (3, R.TRACKING_TERMS) and sq.shape == (3, 3, 24)
    for i in range(3):
        p = sim_pvw[i].copy()
        if align:
            p[0, :, :2] += ref_pvw[i, 0, 0, :2] - p[0, 0, :2]
        want, want_sq = R.imitation_terms(p, sim_rot[i], ref_pvw[i], ref_rot[i], cfg)
        np.testing.assert_allclose(terms[i, :4], [want[k] for k in R.IMITATION_TERMS],
                                   rtol=1e-12)  # fmt: skip
        np.testing.assert_allclose(sq[i], want_sq, rtol=1e-12, atol=1e-15)
        rv = R.root_velocity_term(sim_disp[i], ref_disp[i], 0.3, cfg.k_root_vel)
        np.testing.assert_allclose(terms[i, 4], rv, rtol=1e-12)
        np.testing.assert_allclose(terms[i, 5], R.root_position_term(gap[i], cfg.k_root_pos),
                                   rtol=1e-12)  # fmt: skip


def test_amp_frames_equal_amp_features() -> None:
    pvw, rot = _states(4, 3)
    hinges = np.random.default_rng(4).normal(size=(4, 138))
    h = O.heading_matrices(rot[:, 0])
    got = A.amp_frames(pvw, rot, hinges, h, np.empty((4, A.FRAME_DIM)))
    want = A.amp_features(pvw[:, 0, 0], rot[:, 0], pvw[:, 1, 0], pvw[:, 2, 0], hinges[:, :69],
                          hinges[:, 69:], pvw[:, 0, list(A.KEY_JOINTS)])  # fmt: skip
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-14)


def test_heading_matrices_equal_heading_matrix_also_facing_straight_up() -> None:
    _, rot = _states(5, 5)
    rot = rot[:, 0].copy()
    rot[2] = np.eye(3)  # the forward axis (+z) along world z: no heading
    h = O.heading_matrices(rot)
    for i in range(5):
        np.testing.assert_allclose(h[i], O.heading_matrix(rot[i]), rtol=1e-15, atol=1e-15)
    np.testing.assert_array_equal(h[2], np.eye(3))


@pytest.mark.parametrize("variant", ["OA", "OAV", "OAV_Jglo", "OAV_Jrel"])
def test_observation_rows_equal_observation_parts(variant) -> None:
    pvw, rot = _states(2, 6)
    rng = np.random.default_rng(7)
    est = rng.normal(size=(2, O.OBS_ROW_DIM))
    h = O.heading_matrices(rot[:, 0])
    kin32 = np.empty((2, O.kinematic_dim(variant)), np.float32)
    self32 = np.empty((2, O.SELF_DIM), np.float32)
    kin, self_vec = O.observation_rows(variant, h, pvw, rot, est, kin32, self32)
    assert kin is kin32 and self_vec is self32
    r = O.OBS_ROW
    for i in range(2):
        e = est[i]
        want_kin, want_self = O.observation_parts(
            variant, h[i], pvw[i], rot[i], e[r["est_pos"]].reshape(24, 3),
            e[r["leaf_rot"]].reshape(4, 3, 3), e[r["est_vel"]].reshape(-1, 3),
            e[r["leaf_angvel"]].reshape(4, 3), e[r["est_root_pos"]])  # fmt: skip
        np.testing.assert_allclose(kin[i], want_kin, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(self_vec[i], want_self, rtol=1e-6, atol=1e-6)
