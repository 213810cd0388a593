"""Forward kinematics from global rotations."""

import numpy as np
import pytest

from grip.core.body import build_body
from grip.core.fk import forward_kinematics, joints_from_global
from grip.core.rotations import axis_angle_to_matrix


def test_joints_from_global_matches_forward_kinematics():
    rng = np.random.default_rng(7)
    local = axis_angle_to_matrix(rng.normal(0, 0.6, (5, 24, 3)))
    offsets = build_body().offsets
    g_rot, g_pos = forward_kinematics(local, rng.normal(0, 1, (5, 3)), offsets)
    rel = joints_from_global(g_rot, offsets)
    np.testing.assert_allclose(rel, g_pos - g_pos[:, :1], atol=1e-12)
    with pytest.raises(ValueError, match="global_rot"):
        joints_from_global(g_rot[:, :20], offsets)
