"""Forward kinematics from global rotations."""

import numpy as np
import pytest

from grip.core import skeleton as sk
from grip.core.body import build_body
from grip.core.fk import joints_from_global
from grip.core.rotations import axis_angle_to_matrix


def _rest_positions(offsets):
    pos = np.zeros((24, 3))
    for j in range(1, 24):
        pos[j] = pos[sk.PARENTS[j]] + offsets[j]
    return pos


def test_identity_rotations_give_the_rest_pose_and_a_turned_hip_swings_its_leg():
    offsets = build_body().offsets
    rest = _rest_positions(offsets)
    eye = np.broadcast_to(np.eye(3), (2, 24, 3, 3)).copy()
    np.testing.assert_allclose(joints_from_global(eye, offsets), np.stack([rest, rest]), atol=1e-12)
    # turn the left thigh and everything below it 90 deg about x: the leg swings about the hip
    r = axis_angle_to_matrix(np.array([np.pi / 2, 0.0, 0.0]))
    leg = [sk.JOINT_INDEX[n] for n in ("L_Hip", "L_Knee", "L_Ankle", "L_Foot")]
    g = eye[0].copy()
    g[leg] = r
    pos = joints_from_global(g, offsets)
    hip = rest[sk.JOINT_INDEX["L_Hip"]]
    for name in ("L_Knee", "L_Ankle", "L_Foot"):
        j = sk.JOINT_INDEX[name]
        np.testing.assert_allclose(pos[j], hip + r @ (rest[j] - hip), atol=1e-12)
    others = [j for j in range(24) if j not in leg[1:]]
    np.testing.assert_allclose(pos[others], rest[others], atol=1e-12)


def test_joints_from_global_checks_its_shape():
    with pytest.raises(ValueError, match="global_rot"):
        joints_from_global(np.zeros((5, 20, 3, 3)), build_body().offsets)
