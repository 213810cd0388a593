import numpy as np
import pytest

from grip.core import skeleton as sk
from grip.core.body import CANONICAL_TO_WORLD, BodyParams, build_body
from grip.core.fk import center_of_mass, forward_kinematics, rest_pose, sole_points
from grip.core.rotations import axis_angle_to_matrix


def test_skeleton_topology_is_smpl():
    assert len(sk.JOINT_NAMES) == 24 and sk.JOINT_NAMES[15] == "Head"
    assert all(sk.PARENTS[j] < j for j in range(1, 24))
    assert sk.PARENTS[20] == 18 and sk.PARENTS[10] == 7
    assert all(sk.MIRROR[sk.MIRROR] == np.arange(24))


@pytest.mark.parametrize("params", [BodyParams(), BodyParams(1.85, 92.5, 0.98, 0.62, 0.29)])
def test_masses_and_measured_lengths(params):
    b = build_body(params)
    assert b.masses.sum() == pytest.approx(params.mass_kg, rel=1e-12)
    assert np.all(b.masses > 0)
    if params.leg_length_m:
        assert b.leg_length == pytest.approx(params.leg_length_m)
        arm = np.linalg.norm(b.rest_joint_pos[20] - b.rest_joint_pos[16])
        assert arm == pytest.approx(params.arm_length_m)
        assert b.foot_length == pytest.approx(params.foot_length_m)
    # Inertia tensors are symmetric positive definite and obey the triangle inequality.
    ev = np.linalg.eigvalsh(b.inertia_local)
    assert np.all(ev > 0)
    assert np.all(ev[:, 0] + ev[:, 1] >= ev[:, 2] - 1e-12)


def test_height_scales_the_skeleton():
    a, b = build_body(BodyParams(1.6)), build_body(BodyParams(1.9))
    np.testing.assert_allclose(b.rest_joint_pos, a.rest_joint_pos * 1.9 / 1.6, atol=1e-12)


def test_bad_params_are_refused():
    with pytest.raises(ValueError, match="height_m"):
        BodyParams(height_m=-1.0)
    with pytest.raises(ValueError, match="mass_kg"):
        BodyParams(mass_kg=float("nan"))


def test_upright_rest_pose_stands_on_the_floor_facing_plus_y():
    b = build_body()
    rot, root = rest_pose(1)
    root[:, 2] = b.pelvis_height
    g, p = forward_kinematics(rot, root, b.offsets)
    soles = sole_points(g, p, b)
    np.testing.assert_allclose(soles[..., 2], 0.0, atol=1e-12)  # every sole corner on z = 0
    assert p[0, 15, 2] > p[0, 12, 2] > p[0, 0, 2] > p[0, 4, 2] > p[0, 7, 2]
    assert p[0, 1, 0] < 0 < p[0, 2, 0]  # left hip on -x when facing +y
    assert p[0, 10, 1] > p[0, 7, 1]  # toes in front of the ankle
    np.testing.assert_allclose(CANONICAL_TO_WORLD @ [0, 0, 1.0], [0, 1.0, 0])
    com = center_of_mass(g, p, b)[0]
    assert 0.5 * 1.7 < com[2] < 0.62 * 1.7


def test_fk_known_rotation_of_the_knee():
    b = build_body()
    rot, root = rest_pose(1, world=False)
    rot[0, 4] = axis_angle_to_matrix(np.array([np.pi / 2, 0.0, 0.0]))  # flex left knee 90 deg
    g, p = forward_kinematics(rot, root, b.offsets)
    shank = b.offsets[7]
    expected = p[0, 4] + axis_angle_to_matrix(np.array([np.pi / 2, 0, 0])) @ shank
    np.testing.assert_allclose(p[0, 7], expected, atol=1e-12)
    assert p[0, 7, 2] < p[0, 4, 2]  # canonical frame: the shank now points backwards (-z)
    np.testing.assert_allclose(g[0, 10], g[0, 7], atol=1e-12)


def test_fk_rejects_bad_shapes():
    b = build_body()
    with pytest.raises(ValueError, match="24, 3, 3"):
        forward_kinematics(np.zeros((5, 23, 3, 3)), np.zeros((5, 3)), b.offsets)
