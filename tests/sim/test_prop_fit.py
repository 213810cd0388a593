"""benchmarks/prop_fit.py: penetration read from MuJoCo's contacts in a synthetic scene (a box
under the standing humanoid, its soles 2 and 5 cm inside), the props read back from scene
objects and the soles' heights against a prop's top."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from grip.core.body import BodyParams, build_body
from grip.core.fk import forward_kinematics, rest_pose
from grip.core.mjcf import standing_qpos
from prism_tools.synth.props import Prop, props_as_objects

_PATH = Path(__file__).resolve().parents[2] / "benchmarks" / "prop_fit.py"
_SPEC = importlib.util.spec_from_file_location("benchmarks_prop_fit", _PATH)
PF = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(PF)

TOP = 0.3
BOX = Prop(np.array([-0.5, -0.5]), np.array([0.5, 0.5]), TOP, "step", 1)


def _objects(props):
    objs = props_as_objects(props)
    return None if objs is None else {n: (o.vertices, o.faces) for n, o in objs.items()}


def _humanoid(objects):
    from envs.scenes import HumanoidScenes, humanoid_config
    from grip.task.config import TrackingEnvConfig

    cfg = TrackingEnvConfig()
    return HumanoidScenes(humanoid_config(cfg), cfg.mjcf).get(BodyParams(), objects, 0)


def _standing(*lifts: float) -> np.ndarray:
    """Rows of the standing pose, its soles ``lift`` m above the floor."""
    q = np.tile(standing_qpos(), (len(lifts), 1))
    q[:, 2] += lifts
    return q


def test_soles_2_and_5_cm_inside_a_box_read_so_and_a_pose_above_it_none():
    from grip.core.mjcf import MjcfConfig

    # the foot boxes' undersides sit foot_box_clearance_m above the sole (the sole pads'
    # depths against a height field stop growing near their radius): they read the depth
    clear = MjcfConfig().foot_box_clearance_m
    tracks = PF.playback(_humanoid(_objects([BOX])),
                         _standing(TOP - 0.02, TOP - 0.05, TOP + 0.05))  # fmt: skip
    np.testing.assert_allclose(tracks["prop"]["depth"][:2], [0.02 - clear, 0.05 - clear],
                               atol=1e-4)  # fmt: skip
    assert np.isnan(tracks["prop"]["depth"][2]) and tracks["prop"]["n"][2] == 0
    prop, floor = PF.contact_summary(tracks["prop"]), PF.contact_summary(tracks["floor"])
    assert prop["frames"] == 2 and floor["frames"] == 0
    assert prop["max_depth_m"] == pytest.approx(0.05 - clear, abs=1e-4)
    assert {"L_foot", "R_foot", "L_foot pads", "R_foot pads"} <= set(prop["parts"])
    assert [(r["start"], r["stop"]) for r in prop["runs"]] == [(0, 2)]


def test_on_flat_ground_every_contact_is_the_floor():
    tracks = PF.playback(_humanoid(None), _standing(-0.01, 0.02))
    prop, floor = PF.contact_summary(tracks["prop"]), PF.contact_summary(tracks["floor"])
    assert prop["frames"] == 0 and prop["max_depth_m"] == 0.0
    assert floor["frames"] == 1 and floor["max_depth_m"] == pytest.approx(0.01, abs=2e-3)


def test_props_read_back_from_their_objects():
    slab = Prop(np.array([0.1, -0.3]), np.array([0.4, 0.0]), 0.6, "seat", 1, 0.55)
    back = PF.prop_boxes(_objects([BOX, slab]))
    assert [p.kind for p in back] == ["box", "slab"]
    for got, want in zip(back, [BOX, slab], strict=True):
        np.testing.assert_allclose([*got.lo, *got.hi, got.height_m, got.bottom_m],
                                   [*want.lo, *want.hi, want.height_m, want.bottom_m])  # fmt: skip


def test_soles_standing_2_cm_inside_a_box_sit_2_cm_under_its_top():
    body = build_body(BodyParams())
    local, root = rest_pose(20)
    root[:, 2] = body.pelvis_height + TOP - 0.02
    g, p = forward_kinematics(local, root, body.offsets)
    fit = PF.support_fit(g, p, body, 100.0, [BOX])
    feet = fit["props"][0]["feet"]
    assert feet["foot_frames"] == 40 and fit["floor"]["foot_frames"] == 0
    assert feet["sole_minus_top"]["median_m"] == pytest.approx(-0.02, abs=1e-6)
    assert feet["cells_supported_median"] == 1.0
    assert fit["raised"]["foot_frames"] == 40 and fit["raised"]["under_half_supported"] == 0
    assert fit["sitting"]["frames"] == 0
