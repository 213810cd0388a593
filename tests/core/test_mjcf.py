"""MJCF text of the humanoid: structure, numbers and geometry, checked without running physics."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pytest

from grip.core import skeleton as sk
from grip.core.body import CANONICAL_TO_WORLD, BodyParams, build_body
from grip.core.fk import body_points, forward_kinematics, rest_pose
from grip.core.mjcf import (
    MjcfConfig,
    build_mjcf,
    hinge_names,
    insole_site_half_sizes,
    insole_site_names,
    rest_overlap_pairs,
    standing_qpos,
)
from grip.core.rotations import quat_to_matrix


@pytest.fixture(scope="module")
def body():
    return build_body()


@pytest.fixture(scope="module")
def root(body) -> ET.Element:
    return ET.fromstring(build_mjcf(body))


def test_hinge_names_follow_smpl_order() -> None:
    names = hinge_names()
    assert len(names) == 69
    assert names[:4] == ["L_Hip_x", "L_Hip_y", "L_Hip_z", "R_Hip_x"]
    assert names[-1] == "R_Hand_z"
    assert names[15 * 3 : 16 * 3] == ["L_Shoulder_y", "L_Shoulder_x", "L_Shoulder_z"]
    assert names[17 * 3 : 18 * 3] == ["L_Elbow_y", "L_Elbow_z", "L_Elbow_x"]


def test_body_tree_matches_skeleton(root: ET.Element, body) -> None:
    bodies = {b.get("name"): b for b in root.iter("body")}
    assert sorted(bodies) == sorted(sk.JOINT_NAMES)
    parent_of = {c.get("name"): p.get("name") for p in root.iter("body") for c in p.findall("body")}
    for j in range(1, sk.N_JOINTS):
        name = sk.JOINT_NAMES[j]
        assert parent_of[name] == sk.JOINT_NAMES[sk.PARENTS[j]]
        np.testing.assert_allclose(np.fromstring(bodies[name].get("pos"), sep=" "), body.offsets[j])
        joints = bodies[name].findall("joint")
        assert [jt.get("name") for jt in joints] == [f"{name}_{a}" for a in sk.HINGE_ORDERS[j]]
        for ax, jt in zip(sk.HINGE_ORDERS[j], joints, strict=True):
            a = "xyz".index(ax)
            np.testing.assert_array_equal(np.fromstring(jt.get("axis"), sep=" "), np.eye(3)[a])
            np.testing.assert_allclose(np.fromstring(jt.get("range"), sep=" "),
                                       body.hinge_range[j, a])  # fmt: skip
    assert bodies["Pelvis"].find("freejoint").get("name") == "root"
    actuators = [a.get("joint") for a in root.find("actuator")]
    assert actuators == hinge_names()


def test_standing_qpos_is_upright_tpose_on_floor(body) -> None:
    q = standing_qpos(body)
    assert q.shape == (76,)
    np.testing.assert_allclose(quat_to_matrix(q[3:7]), CANONICAL_TO_WORLD, atol=1e-12)
    assert q[2] == body.pelvis_height
    assert not q[7:].any()


@pytest.mark.parametrize("params", [BodyParams(), BodyParams(1.55, 52.0, foot_length_m=0.23),
                                    BodyParams(1.92, 95.0, leg_length_m=0.98)])  # fmt: skip
def test_soles_touch_the_floor_in_the_standing_pose(params: BodyParams) -> None:
    bm = build_body(params)
    rot, pos = rest_pose(1)
    pos[0, 2] = bm.pelvis_height
    g_rot, g_pos = forward_kinematics(rot, pos, bm.offsets)
    # Foot and toe boxes of the body model: the lowest corner of each is at z = 0.
    for g in bm.geoms:
        if g.kind == "box":
            corners = g.pos + g.size * np.array(np.meshgrid(*[[-1, 1]] * 3)).reshape(3, -1).T
            z = body_points(g_rot, g_pos, np.full(8, g.body), corners)[0, :, 2]
            assert z.min() == pytest.approx(0.0, abs=1e-12)
    cells = body_points(g_rot, g_pos, bm.insole_body.reshape(-1), bm.insole_pos.reshape(-1, 3))
    np.testing.assert_allclose(cells[0, :, 2], 0.0, atol=1e-12)


def test_insole_sites_do_not_overlap(body) -> None:
    half = insole_site_half_sizes(body)
    assert np.all(half > 0.003)
    for f in range(2):
        xz = body.insole_pos[f][:, [0, 2]]
        for i in range(16):
            for j in range(i + 1, 16):
                if body.insole_body[f, i] != body.insole_body[f, j]:
                    continue
                gap = np.abs(xz[i] - xz[j]).max() - half[f, i] - half[f, j]
                assert gap > 0.0, (f, i, j)


def test_rest_overlap_pairs_exclude_chest_vs_upper_arms(body) -> None:
    pairs = rest_overlap_pairs(body)
    names = {(sk.JOINT_NAMES[i], sk.JOINT_NAMES[j]) for i, j in pairs}
    assert ("Spine3", "L_Shoulder") in names and ("Spine3", "R_Shoulder") in names
    assert all(sk.PARENTS[j] != i for i, j in pairs)  # MuJoCo filters those already
    assert ("L_Hip", "R_Hip") not in names  # the thighs may collide with each other


@pytest.mark.parametrize(
    "params", [BodyParams(1.70, 70.0), BodyParams(1.83, 91.5, arm_length_m=0.6)]
)
def test_total_mass_equals_requested_mass(params: BodyParams) -> None:
    model = mujoco.MjModel.from_xml_string(build_mjcf(params))
    assert model.nq == 76 and model.nv == 75 and model.nu == 69
    assert mujoco.mj_getTotalmass(model) == pytest.approx(params.mass_kg, rel=1e-9)
    bm = build_body(params)
    ids = [model.body(n).id for n in sk.JOINT_NAMES]
    np.testing.assert_allclose(model.body_mass[ids], bm.masses, rtol=1e-12)
    np.testing.assert_allclose(model.body_ipos[ids], bm.com_local, atol=1e-12)


def test_actuator_gains_and_ranges(body) -> None:
    model = mujoco.MjModel.from_xml_string(build_mjcf(body, MjcfConfig(gain_scale=2.0)))
    for k, name in enumerate(hinge_names()):
        act = model.actuator(name)
        j = sk.JOINT_INDEX[name[:-2]]
        assert act.id == k
        assert model.joint(int(act.trnid[0])).name == name
        assert act.gainprm[0] == pytest.approx(2.0 * body.kp[j])
        np.testing.assert_allclose(act.biasprm[:3], [0.0, -2.0 * body.kp[j], -2.0 * body.kd[j]])
        np.testing.assert_allclose(act.ctrlrange, body.hinge_range[j, "xyz".index(name[-1])])


def test_general_and_position_actuators_give_the_same_torques(body) -> None:
    out = []
    for kind in ("position", "general"):
        model = mujoco.MjModel.from_xml_string(build_mjcf(body, MjcfConfig(actuator=kind)))
        data = mujoco.MjData(model)
        rng = np.random.default_rng(7)  # the same state for both models
        data.qpos[7:] = rng.uniform(-0.3, 0.3, 69)
        data.qvel[6:] = rng.uniform(-1.0, 1.0, 69)
        data.ctrl[:] = rng.uniform(-0.2, 0.2, 69)
        mujoco.mj_forward(model, data)
        out.append(data.qfrc_actuator.copy())
    np.testing.assert_allclose(out[0], out[1], rtol=1e-12, atol=1e-9)


def test_config_switches(body) -> None:
    bare = MjcfConfig(insole_sensors=False, imu_sensors=False, floor=False, sole_pads=False,
                      foot_force_sensors=False)  # fmt: skip
    model = mujoco.MjModel.from_xml_string(build_mjcf(body, bare))
    assert model.nsensor == 0
    assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor") == -1
    assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "sole_L_0") == -1
    # Without sole pads the feet are the body model's boxes, unchanged.
    box = model.geom("L_Ankle_box0")
    g = next(g for g in body.geoms if g.body == sk.FOOT_BODY["L_Foot"])
    np.testing.assert_allclose(box.size, g.size)
    full = mujoco.MjModel.from_xml_string(build_mjcf(body))
    assert full.nsensor == 32 + 3 * 8 + 2  # touch cells, IMUs, the feet's net contact forces
    assert all(full.site(n).id >= 0 for row in insole_site_names() for n in row)


@pytest.mark.parametrize("bad", [{"timestep_s": 0.0}, {"actuator": "motor"},
                                 {"armature": -0.1}, {"friction": float("nan")}])  # fmt: skip
def test_config_rejects_bad_values(bad: dict) -> None:
    with pytest.raises(ValueError, match=next(iter(bad))):
        MjcfConfig(**bad)
