import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from grip.core import rotations as R


@pytest.fixture
def rng():
    return np.random.default_rng(0)


def _random_mats(rng, shape):
    return Rotation.random(int(np.prod(shape)), random_state=rng).as_matrix().reshape(*shape, 3, 3)


def test_quat_matrix_round_trip_matches_scipy(rng):
    m = _random_mats(rng, (7, 5))
    q = R.matrix_to_quat(m)
    assert q.shape == (7, 5, 4)
    ref = Rotation.from_matrix(m.reshape(-1, 3, 3)).as_quat(scalar_first=True).reshape(7, 5, 4)
    ref = np.where(ref[..., :1] < 0, -ref, ref)
    np.testing.assert_allclose(q, ref, atol=1e-10)
    np.testing.assert_allclose(R.quat_to_matrix(q), m, atol=1e-10)


def test_axis_angle_round_trip_and_known_value(rng):
    aa = rng.normal(size=(10, 3))
    aa *= (np.pi * 0.95 / np.linalg.norm(aa, axis=-1, keepdims=True)) * rng.uniform(0, 1, (10, 1))
    np.testing.assert_allclose(R.matrix_to_axis_angle(R.axis_angle_to_matrix(aa)), aa, atol=1e-9)
    # 90 degrees about z maps x to y.
    m = R.axis_angle_to_matrix(np.array([0.0, 0.0, np.pi / 2]))
    np.testing.assert_allclose(m @ [1.0, 0, 0], [0, 1.0, 0], atol=1e-12)
    np.testing.assert_allclose(R.axis_angle_to_matrix(np.zeros(3)), np.eye(3))
    np.testing.assert_allclose(R.quat_to_axis_angle(R.axis_angle_to_quat(aa)), aa, atol=1e-9)


def test_6d_round_trip(rng):
    m = _random_mats(rng, (4, 24))
    np.testing.assert_allclose(R.sixd_to_matrix(R.matrix_to_6d(m)), m, atol=1e-12)


def test_euler_xyz_is_intrinsic_xyz(rng):
    e = rng.uniform(-1.2, 1.2, size=(50, 3))
    m = R.euler_xyz_to_matrix(e)
    ref = Rotation.from_euler("XYZ", e).as_matrix()
    np.testing.assert_allclose(m, ref, atol=1e-12)
    np.testing.assert_allclose(R.matrix_to_euler_xyz(m), e, atol=1e-9)


@pytest.mark.parametrize("order", ["xyz", "xzy", "yxz", "yzx", "zxy", "zyx"])
def test_euler_orders_are_intrinsic(rng, order):
    e = rng.uniform(-1.4, 1.4, size=(50, 3))
    m = R.euler_to_matrix(e, order)
    np.testing.assert_allclose(m, Rotation.from_euler(order.upper(), e).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(R.matrix_to_euler(m, order), e, atol=1e-9)
    # At the gimbal lock the angles are not unique, but they still give back the rotation.
    locked = e.copy()
    locked[:, 1] = np.pi / 2 * np.sign(e[:, 1])
    m = R.euler_to_matrix(locked, order)
    np.testing.assert_allclose(R.euler_to_matrix(R.matrix_to_euler(m, order), order), m, atol=1e-9)


def test_euler_order_must_be_a_permutation():
    with pytest.raises(ValueError, match="permutation"):
        R.matrix_to_euler(np.eye(3), "xxy")


def test_heading_of_yaw_rotation():
    yaw = np.array([0.3, -2.0])
    m = R.rot_z(yaw)
    # Forward axis x in the body frame: heading equals the yaw itself.
    np.testing.assert_allclose(R.heading_angle(m, np.array([1.0, 0, 0])), yaw, atol=1e-12)
    np.testing.assert_allclose(R.heading_rotation(m, np.array([1.0, 0, 0])), m, atol=1e-12)


def test_slerp_midpoint_and_resample():
    q0 = R.axis_angle_to_quat(np.array([0.0, 0.0, 0.0]))
    q1 = R.axis_angle_to_quat(np.array([0.0, 0.0, 1.0]))
    mid = R.quat_slerp(q0, q1, 0.5)
    np.testing.assert_allclose(R.quat_to_axis_angle(mid), [0, 0, 0.5], atol=1e-12)
    t = np.array([0.0, 1.0, 2.0])
    q = R.axis_angle_to_quat(np.array([[0, 0, 0.0], [0, 0, 1.0], [0, 0, 2.0]]))
    out = R.resample_quats(t, q, np.array([0.25, 1.5]))
    np.testing.assert_allclose(R.quat_to_axis_angle(out)[:, 2], [0.25, 1.5], atol=1e-12)


def test_rotation_between_and_geodesic(rng):
    u = rng.normal(size=(20, 3))
    v = rng.normal(size=(20, 3))
    m = R.rotation_between(u, v)
    got = np.einsum("nij,nj->ni", m, u / np.linalg.norm(u, axis=-1, keepdims=True))
    np.testing.assert_allclose(got, v / np.linalg.norm(v, axis=-1, keepdims=True), atol=1e-9)
    anti = R.rotation_between(np.array([1.0, 0, 0]), np.array([-1.0, 0, 0]))
    np.testing.assert_allclose(anti @ [1.0, 0, 0], [-1, 0, 0], atol=1e-12)
    a = R.axis_angle_to_matrix(np.array([0.0, 0.7, 0.0]))
    assert R.geodesic_angle(np.eye(3), a) == pytest.approx(0.7)


def test_angular_velocity_of_constant_spin():
    fps = 100.0
    w = np.array([0.0, 0.0, 2.0])  # rad/s about z
    t = np.arange(50) / fps
    m = R.axis_angle_to_matrix(w[None] * t[:, None])
    np.testing.assert_allclose(R.angular_velocity(m, fps), np.broadcast_to(w, (50, 3)), atol=1e-9)
    np.testing.assert_allclose(R.angular_velocity(m, fps, local=True),
                               np.broadcast_to(w, (50, 3)), atol=1e-9)  # fmt: skip


@pytest.mark.parametrize("n", [1, 2, 3, 7])
def test_angular_velocity_at_one_frame_equals_the_whole_track(n) -> None:
    from grip.core.rotations import angular_velocity, angular_velocity_at, axis_angle_to_matrix

    rot = axis_angle_to_matrix(np.random.default_rng(n).normal(size=(n, 5, 3)))
    whole = angular_velocity(rot, 60.0)
    for i in range(n):
        np.testing.assert_allclose(angular_velocity_at(rot, i, 60.0), whole[i], atol=1e-12)
