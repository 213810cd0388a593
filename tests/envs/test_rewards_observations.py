import itertools

import numpy as np
import pytest

from envs.rewards import (
    imitation_terms,
    mechanical_power,
    root_position_term,
    root_velocity_term,
    rotation_angles,
)
from grip.core import skeleton as sk
from grip.core.rotations import rot_x, rot_z
from grip.task import observations as O
from grip.task.config import RewardConfig


def _state(n: int = 24, seed: int = 0):
    rng = np.random.default_rng(seed)
    rot = rot_z(rng.uniform(-3, 3, n)) @ rot_x(rng.uniform(-1, 1, n))
    return rng.normal(size=(3, n, 3)), rot


def test_imitation_terms_are_one_at_perfect_tracking_and_fall_with_error() -> None:
    pvw, rot = _state()
    cfg = RewardConfig()
    perfect, sq = imitation_terms(pvw, rot, pvw, rot, cfg)
    assert perfect == pytest.approx(dict.fromkeys(perfect, 1.0)) and not sq.any()
    prev = perfect
    for err in (0.01, 0.05, 0.2):
        terms, _ = imitation_terms(pvw + err, rot @ rot_x(np.full(24, err)), pvw, rot, cfg)
        assert all(terms[k] < prev[k] for k in terms)
        prev = terms


def test_imitation_kernels_match_hand_computed_values() -> None:
    pvw, rot = _state()
    off = pvw.copy()
    off[0, :, 0] += 0.1  # every joint 0.1 m off along x: mean squared error 0.01 m^2
    t, sq = imitation_terms(off, rot, pvw, rot, RewardConfig())
    assert t["imit_pos"] == pytest.approx(np.exp(-100 * 0.01))
    assert t["imit_vel"] == pytest.approx(1.0)
    np.testing.assert_allclose(sq[0], 0.01)
    t, _ = imitation_terms(off, rot, pvw, rot, RewardConfig(form="norm"))
    assert t["imit_pos"] == pytest.approx(np.exp(-100 * np.sqrt(24 * 0.01)))
    t, _ = imitation_terms(pvw, rot @ rot_x(np.full(24, 0.2)), pvw, rot, RewardConfig())
    assert t["imit_rot"] == pytest.approx(np.exp(-100 * 0.04))
    ang = rotation_angles(rot @ rot_x(np.full(24, 0.3)), rot)
    np.testing.assert_allclose(ang, 0.3, atol=1e-9)


def test_mechanical_power() -> None:
    assert mechanical_power(np.array([2.0, -3.0]), np.array([1.0, 2.0])) == pytest.approx(8.0)


def test_heading_matrix_points_x_where_the_pelvis_faces() -> None:
    # canonical forward is the pelvis' +z axis; a body turned to face world -x
    face = np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]]).T  # columns: images of x, y, z
    h = O.heading_matrix(face)
    np.testing.assert_allclose(np.array([-1.0, 0, 0]) @ h, [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(h), 1.0)


@pytest.mark.parametrize("variant", ["OA", "OAV", "OAV_Jglo", "OAV_Jrel", "OAV_Jrel_root"])
def test_state_difference_vanishes_when_the_estimate_equals_the_simulation(variant) -> None:
    pvw, rot = _state()
    pos, vel, w = pvw
    h = O.heading_matrix(rot[0])
    imu = list(O.IMU_JOINTS)
    kin, self_vec = O.observation_parts(variant, h, pvw, rot, pos - pos[0], rot[imu],
                                        vel[list(sk.VELOCITY_JOINTS)], w[imu], pos[0])  # fmt: skip
    assert kin.shape == (O.kinematic_dim(variant),) and self_vec.shape == (O.SELF_DIM,)
    n_imu = len(O.IMU_JOINTS)
    d_rot = kin[: 6 * n_imu].reshape(n_imu, 6)
    np.testing.assert_allclose(d_rot, np.tile([1, 0, 0, 0, 1, 0], (n_imu, 1)), atol=1e-12)
    diffs = kin[12 * n_imu :]  # after d_theta and theta_leaf: d_omega, d_v, d_p are zero
    p_at = diffs.size - (2 if variant == "OAV_Jrel_root" else 0)  # (the root gap ends it)
    n_zero = p_at - (72 if variant.startswith("OAV_J") else 0)
    np.testing.assert_allclose(diffs[:n_zero], 0.0, atol=1e-12)
    np.testing.assert_allclose(diffs[p_at:], 0.0, atol=1e-12)
    assert self_vec[0] == pos[0, 2]


def test_observations_are_invariant_to_a_yaw_of_the_whole_scene() -> None:
    pvw, rot = _state(seed=3)
    est_pos, est_rot = pvw[0][::-1] * 0.9 - pvw[0, 0], rot[::-1]
    est_vel, est_w = pvw[1, :6] + 0.3, pvw[2][::-1]

    def parts(r):
        rw = lambda v: v @ r.T  # noqa: E731
        rr = r @ rot
        imu = list(O.IMU_JOINTS)
        kin, self_vec = O.observation_parts(
            "OAV_Jglo", O.heading_matrix(rr[0]), rw(pvw), rr, rw(est_pos), (r @ est_rot)[imu],
            rw(est_vel), rw(est_w)[imu], rw(pvw[0, 0] + 0.1),
        )  # fmt: skip
        return np.concatenate([kin, self_vec[1:]])

    yaw = rot_z(np.array(0.7))
    np.testing.assert_allclose(parts(yaw), parts(np.eye(3)), atol=1e-9)


def test_root_velocity_term_on_hand_computed_windows() -> None:
    # 0.3 m instead of 0.6 m in 0.3 s: 1 m/s too slow -> exp(-k)
    assert root_velocity_term(np.array([0.3, 0.0]), np.array([0.6, 0.0]), 0.3, 10.0) == (
        pytest.approx(np.exp(-10.0)))
    # the same ground covered in another place: perfect
    assert root_velocity_term(np.array([0.1, 0.2]), np.array([0.1, 0.2]), 0.3, 10.0) == 1.0
    # sideways instead of forward: |(0, 0.3) - (0.3, 0)| / 0.5 s = 0.3 sqrt(2) / 0.5 m/s
    e2 = (0.3 * np.sqrt(2) / 0.5) ** 2
    assert root_velocity_term(np.array([0.0, 0.3]), np.array([0.3, 0.0]), 0.5, 2.0) == (
        pytest.approx(np.exp(-2.0 * e2)))


def test_the_root_gap_observation_is_the_followed_pelvis_in_the_heading_frame() -> None:
    """``OAV_Jrel_root`` ends with (forward, left) of the followed pelvis seen from the
    simulated one, clipped per axis; the rest equals ``OAV_Jrel``."""
    pvw, rot = _state(seed=5)
    pos, vel, w = pvw
    imu = list(O.IMU_JOINTS)
    h = O.heading_matrix(rot[0])
    fwd, left = h[:, 0], h[:, 1]
    args = (pvw, rot, pos - pos[0], rot[imu], vel[list(sk.VELOCITY_JOINTS)], w[imu])
    base, _ = O.observation_parts("OAV_Jrel", h, *args, pos[0])
    for ahead, side, want in ((0.4, -0.2, (0.4, -0.2)), (3.0, 0.1, (O.ROOT_GAP_CLIP_M, 0.1))):
        followed = pos[0] + ahead * fwd + side * left + np.array([0.0, 0.0, 0.7])  # (z ignored)
        kin, _ = O.observation_parts("OAV_Jrel_root", h, *args, followed)
        np.testing.assert_allclose(kin[:-2], base, atol=1e-12)
        np.testing.assert_allclose(kin[-2:], want, atol=1e-12)
        kb, _ = O.observation_parts_batch("OAV_Jrel_root", h[None], *(a[None] for a in args),
                                          followed[None])  # fmt: skip
        np.testing.assert_allclose(kb[0], kin, atol=1e-12)


def test_root_position_term_pays_for_being_where_the_pelvis_is_followed() -> None:
    assert root_position_term(np.zeros(2), 4.0) == 1.0
    assert root_position_term(np.array([0.15, 0.0]), 4.0) == pytest.approx(np.exp(-4 * 0.0225))
    # a body left behind earns less the further it is, and still has slope at 1 m
    vals = [root_position_term(np.array([d, 0.0]), 4.0) for d in (0.0, 0.15, 0.5, 1.0, 2.0)]
    assert all(a > b for a, b in itertools.pairwise(vals))
    assert vals[3] > 0.01
