"""MuJoCo Warp (CPU device, float32) against MuJoCo C (float64) on the project's humanoid, from
the same states under the same controls (:mod:`envs.warp.physics_check`).

Flat floor: the states of a bundled clip driven toward its estimate for 400 physics steps stay
within 1e-3 m / rad (measured: 1.4e-4 m and 9e-5 rad at most, docs/gpu.md) with the same
contact pairs at every step, up to grazing ones (shallower than 1 mm). Height field: MuJoCo Warp
keeps at most 4 contacts per geom-hfield pair where MuJoCo C keeps one per prism, so only quiet
stances are held to a bound (measured: 1e-3 m over 400 steps); dynamic contact on terrain
diverges (docs/gpu.md).
"""

from __future__ import annotations

import pytest

from envs.warp import warp_available

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not warp_available(), reason="needs mujoco-warp (pip install -e .[gpu])"),
]


def test_flat_floor_matches_mujoco_c():
    import warp as wp

    from envs.tracking_env import SAMPLE_REFERENCE
    from envs.warp.physics_check import compare_physics, tracking_case
    from grip.core.reference import ReferenceSet
    from grip.task.config import TrackingEnvConfig

    wp.config.quiet = True
    case = tracking_case(TrackingEnvConfig(), ReferenceSet.load(SAMPLE_REFERENCE), 0, [0, 60],
                         400)  # fmt: skip
    gap = compare_physics(*case)
    assert gap.root_pos_m.max() < 1e-3
    assert gap.hinge_rad.max() < 1e-3
    assert gap.contacts_equal.all()
    assert (gap.pairs_c > 0).mean() > 0.5  # (the feet touch the floor most of the time)


def test_standing_on_a_height_field_stays_close():
    import warp as wp

    from envs.warp.physics_check import compare_physics, terrain_case
    from grip.task.config import TrackingEnvConfig

    wp.config.quiet = True
    model, qpos, qvel, ctrl = terrain_case(TrackingEnvConfig(terrain="stairs"), 400)
    gap = compare_physics(model, qpos[:2], qvel[:2], ctrl[:, :2])  # on the floor, on the landing
    assert gap.root_pos_m.max() < 1e-2
    assert gap.contacts_equal.all()
    assert (gap.pairs_c > 20).all()  # (the sole pads rest on the height field)
