"""The compiled MuJoCo humanoid against numpy FK, and its physics: standing, insoles, stability."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from grip.cli.main import main
from grip.core import skeleton as sk
from grip.core.body import GRAVITY, BodyParams, build_body
from grip.core.fk import body_points, forward_kinematics
from grip.core.mjcf import MjcfConfig, standing_qpos
from grip.core.reference import local_from_hinges
from grip.core.rotations import euler_xyz_to_matrix, matrix_to_quat, quat_normalize
from grip.sim.model import (
    HumanoidIndex,
    body_positions,
    body_rotations,
    insole_forces,
    load_model,
    set_pose,
)


@pytest.fixture(scope="module")
def body():
    return build_body(BodyParams(1.76, 74.0))


@pytest.fixture(scope="module")
def model(body) -> mujoco.MjModel:
    return load_model(body)


@pytest.fixture(scope="module")
def index(model) -> HumanoidIndex:
    return HumanoidIndex.from_model(model)


def _random_pose(body, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Local rotations ``(24, 3, 3)``, root position ``(3,)`` and hinge angles ``(23, 3)`` (each
    joint's in its composition order)."""
    axes = np.array([["xyz".index(a) for a in sk.HINGE_ORDERS[j]] for j in range(1, sk.N_JOINTS)])
    rng_ordered = np.take_along_axis(body.hinge_range[1:], axes[..., None], axis=1)
    angles = rng.uniform(rng_ordered[..., 0], rng_ordered[..., 1])
    local = np.empty((sk.N_JOINTS, 3, 3))
    local[0] = euler_xyz_to_matrix(rng.uniform(-np.pi, np.pi, 3))
    local[1:] = local_from_hinges(angles.reshape(-1))
    return local, rng.uniform(-2.0, 2.0, 3), angles


def test_index_resolves_every_part(model, index: HumanoidIndex) -> None:
    assert index.body_ids.shape == (24,) and len(set(index.body_ids)) == 24
    assert index.root_qpos_adr == 0 and index.root_dof_adr == 0
    assert sorted(index.hinge_qpos_adr) == list(range(7, 76))
    assert sorted(index.hinge_dof_adr) == list(range(6, 75))
    # qpos is in depth-first order, not SMPL order: the mapping is not the identity.
    assert not np.array_equal(index.hinge_qpos_adr, np.arange(7, 76))
    np.testing.assert_array_equal(index.actuator_ids, np.arange(69))
    jnt_of_act = model.actuator_trnid[index.actuator_ids, 0]
    np.testing.assert_array_equal(model.jnt_qposadr[jnt_of_act], index.hinge_qpos_adr)
    assert index.imu_site_ids.shape == (8,) and index.insole_site_ids.shape == (2, 16)
    assert index.touch_adr.shape == (2, 16) and len(set(index.touch_adr.ravel())) == 32
    bare = load_model(None, MjcfConfig(insole_sensors=False))
    assert HumanoidIndex.from_model(bare).touch_adr.size == 0


@pytest.mark.parametrize("via_set_pose", [False, True])
def test_mujoco_kinematics_equals_numpy_fk(body, model, index, via_set_pose: bool) -> None:
    rng = np.random.default_rng(11)
    data = mujoco.MjData(model)
    imu_bodies = np.array([body.imu_sites[p][0] for p in sk.IMU_PARTS])
    imu_pos = np.stack([body.imu_sites[p][1] for p in sk.IMU_PARTS])
    for _ in range(20):
        local, root_pos, angles = _random_pose(body, rng)
        if via_set_pose:
            set_pose(model, data, index, local, root_pos)
        else:  # raw hinge angles: checks MuJoCo's x-y-z hinge composition itself
            data.qpos[:3] = root_pos
            data.qpos[3:7] = matrix_to_quat(local[0])
            data.qpos[index.hinge_qpos_adr] = angles.reshape(-1)
            mujoco.mj_kinematics(model, data)
        g_rot, g_pos = forward_kinematics(local, root_pos, body.offsets)
        np.testing.assert_allclose(body_positions(data, index), g_pos, atol=1e-6)
        np.testing.assert_allclose(body_rotations(data, index), g_rot, atol=1e-6)
        np.testing.assert_allclose(
            data.site_xpos[index.imu_site_ids],
            body_points(g_rot, g_pos, imu_bodies, imu_pos),
            atol=1e-6,
        )
        cells = body_points(g_rot, g_pos, body.insole_body.reshape(-1),
                            body.insole_pos.reshape(-1, 3))  # fmt: skip
        np.testing.assert_allclose(data.site_xpos[index.insole_site_ids.reshape(-1)], cells,
                                   atol=1e-6)  # fmt: skip
        # IMU orientation = the carrying segment's world rotation.
        np.testing.assert_allclose(data.site_xmat[index.imu_site_ids].reshape(-1, 3, 3),
                                   g_rot[imu_bodies], atol=1e-6)  # fmt: skip


def test_keyframe_stand_is_qpos0_with_pads_on_the_floor(body, model) -> None:
    np.testing.assert_allclose(model.key("stand").qpos, standing_qpos(body))
    np.testing.assert_allclose(model.qpos0, standing_qpos(body))
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("stand").id)
    mujoco.mj_kinematics(model, data)
    pads = [model.geom(f"sole_{s}_{k}").id for s in "LR" for k in range(16)]
    np.testing.assert_allclose(data.geom_xpos[pads, 2] - model.geom_size[pads, 0], 0.0,
                               atol=1e-12)  # fmt: skip
    # Foot and toe boxes hover just above the floor, so the pads carry a flat foot.
    for name in ("L_Ankle_box0", "R_Ankle_box0", "L_Foot_box0", "R_Foot_box0"):
        g = model.geom(name).id
        corners = np.array(np.meshgrid(*[[-1, 1]] * 3)).reshape(3, -1).T * model.geom_size[g]
        z = data.geom_xpos[g, 2] + corners @ data.geom_xmat[g].reshape(3, 3)[2]
        assert z.min() == pytest.approx(MjcfConfig().foot_box_clearance_m, abs=1e-9)


@pytest.fixture(scope="module")
def standing_run(model, index) -> dict:
    """10 s of PD hold at the rest pose from the 'stand' keyframe."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("stand").id)
    mujoco.mj_forward(model, data)
    start = body_positions(data, index)
    out: dict = {"start": start, "bad": 0, "finite": True}
    n_steps = round(10.0 / model.opt.timestep)
    for step in range(n_steps):
        mujoco.mj_step(model, data)
        out["bad"] += data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number
        out["finite"] &= bool(np.isfinite(data.qpos).all())
        if step + 1 == round(1.0 / model.opt.timestep):
            out["insole_1s"] = insole_forces(data, index)
            out["ncon_1s"] = data.ncon
    out["end"] = body_positions(data, index)
    out["pelvis_up"] = body_rotations(data, index)[0] @ np.array([0.0, 1.0, 0.0])
    return out


def test_stands_for_ten_seconds_under_pd_hold(standing_run: dict) -> None:
    assert standing_run["bad"] == 0 and standing_run["finite"]
    start, end = standing_run["start"], standing_run["end"]
    assert abs(end[0, 2] - start[0, 2]) < 0.02  # pelvis height
    assert np.linalg.norm(end[0, :2] - start[0, :2]) < 0.06  # a small forward lean, no fall
    assert standing_run["pelvis_up"][2] > 0.99
    feet = [sk.FOOT_BODY["L_Foot"], sk.FOOT_BODY["R_Foot"]]
    np.testing.assert_allclose(end[feet], start[feet], atol=0.003)  # feet do not slide


def test_touch_sensors_add_up_to_body_weight(model, standing_run: dict) -> None:
    forces = standing_run["insole_1s"]
    weight = mujoco.mj_getTotalmass(model) * GRAVITY
    assert forces.sum() == pytest.approx(weight, rel=0.05)
    left, right = forces.sum(axis=1)
    assert left == pytest.approx(right, rel=0.1)
    assert (forces > 0).sum() >= 24  # the load is spread over the soles, not on a few corners


def test_random_pd_targets_do_not_blow_up(model) -> None:
    rng = np.random.default_rng(5)
    data = mujoco.MjData(model)
    lo, hi = model.actuator_ctrlrange.T
    mujoco.mj_resetDataKeyframe(model, data, model.key("stand").id)
    for step in range(600):  # 3 s, a new random target every 0.1 s
        if step % 20 == 0:
            data.ctrl[:] = rng.uniform(lo, hi)
        mujoco.mj_step(model, data)
        assert data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number == 0, step
    assert np.isfinite(data.qpos).all()


def test_set_pose_root_quaternion_is_normalised(model, index) -> None:
    data = mujoco.MjData(model)
    local = np.broadcast_to(np.eye(3), (24, 3, 3)).copy()
    set_pose(model, data, index, local, np.zeros(3))
    np.testing.assert_allclose(data.qpos[3:7], quat_normalize(np.array([1.0, 0, 0, 0])))
    assert not data.qpos[7:].any()
    with pytest.raises(ValueError, match="24, 3, 3"):
        set_pose(model, data, index, local[:23], np.zeros(3))


# ----------------------------------------------------------------------------- CLI
def _exit_code(argv: list[str]) -> int:
    try:
        return main(argv)
    except SystemExit as e:  # argparse errors
        return int(e.code)


def test_cli_body_export_writes_a_loadable_model(tmp_path: Path, capsys) -> None:
    out = tmp_path / "models" / "subject.xml"
    code = _exit_code(["body", "export", "--out", str(out), "--height", "1.82", "--mass", "78",
                       "--timestep", "0.004"])  # fmt: skip
    assert code == 0
    m = mujoco.MjModel.from_xml_string(out.read_text())
    assert (m.nq, m.nv, m.nu) == (76, 75, 69)
    assert mujoco.mj_getTotalmass(m) == pytest.approx(78.0, rel=1e-9)
    assert m.opt.timestep == 0.004
    text = capsys.readouterr().out
    assert "nq=76" in text and "mujoco.viewer" in text
    assert list(out.parent.iterdir()) == [out]  # no temporary file left behind


def test_cli_body_export_without_insole_sensors(tmp_path: Path) -> None:
    out = tmp_path / "bare.xml"
    assert _exit_code(["body", "export", "--out", str(out), "--no-insole-sensors"]) == 0
    m = mujoco.MjModel.from_xml_string(out.read_text())
    assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, "touch_L_0") == -1


@pytest.mark.parametrize("argv", [["--height", "-1.7"], ["--height", "3.5"], ["--height", "abc"]])
def test_cli_body_export_rejects_bad_height(tmp_path: Path, capsys, argv: list[str]) -> None:
    out = tmp_path / "x.xml"
    assert _exit_code(["body", "export", "--out", str(out), *argv]) == 2
    err = capsys.readouterr().err
    assert "error:" in err and "--height" in err and "Traceback" not in err
    assert not out.exists()


def test_texture_size_is_visual_only(body, model) -> None:
    """The simulation scenes' small textures change the texture arrays and nothing that
    steps: 200 steps under random PD targets are the same bit for bit."""
    from envs.scenes import HumanoidScenes
    from grip.core.mjcf import SIM_TEXTURE_PX
    from grip.sim.humanoid import HumanoidConfig

    small = load_model(body, MjcfConfig(texture_px=SIM_TEXTURE_PX))
    assert small.tex_data.nbytes < model.tex_data.nbytes / 50
    assert list(small.tex_width) == [SIM_TEXTURE_PX] * 2
    rng = np.random.default_rng(3)
    datas = [mujoco.MjData(m) for m in (model, small)]
    for m, d in zip((model, small), datas, strict=True):
        mujoco.mj_resetDataKeyframe(m, d, 0)
    for _ in range(200):
        ctrl = rng.uniform(-0.3, 0.3, model.nu)
        for m, d in zip((model, small), datas, strict=True):
            d.ctrl[:] = ctrl
            mujoco.mj_step(m, d)
    np.testing.assert_array_equal(datas[0].qpos, datas[1].qpos)
    np.testing.assert_array_equal(datas[0].sensordata, datas[1].sensordata)
    h = HumanoidScenes(HumanoidConfig(), MjcfConfig()).get(BodyParams(1.76, 74.0))
    assert list(h.model.tex_width) == [SIM_TEXTURE_PX] * 2


@pytest.mark.parametrize("px", [0, -3, 1.5, True])
def test_texture_size_must_be_a_positive_int(px) -> None:
    with pytest.raises(ValueError, match="texture_px"):
        MjcfConfig(texture_px=px)
