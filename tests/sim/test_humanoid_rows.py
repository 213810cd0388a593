"""A humanoid's state gathered as one row equals what MjData holds."""

from __future__ import annotations

import mujoco
import numpy as np

from grip.sim.humanoid import ROW, ROW_DIM, Humanoid, HumanoidConfig, absurd_rows, body_state
from grip.sim.model import load_model


def _moving_humanoid() -> Humanoid:
    h = Humanoid(load_model())
    d = h.data
    mujoco.mj_resetDataKeyframe(h.model, d, h.model.key("stand").id)
    rng = np.random.default_rng(0)
    d.qvel[:] = rng.normal(0.0, 0.2, d.qvel.shape)
    h.ctrl[h.act] = np.clip(d.qpos[h.index.hinge_qpos_adr] + rng.normal(0, 0.1, 69), h.lo, h.hi)
    mujoco.mj_forward(h.model, d)
    for _ in range(5):
        h.step()
    return h


def test_gathered_row_equals_the_mjdata_arrays() -> None:
    h = _moving_humanoid()
    d, ix = h.data, h.index
    row = h.gather(np.empty(ROW_DIM))
    ids = ix.body_ids
    np.testing.assert_array_equal(row[ROW["rot"]], d.xmat[ids].ravel())
    np.testing.assert_array_equal(row[ROW["hinge_q"]], h.hinge_angles())
    np.testing.assert_array_equal(row[ROW["hinge_qd"]], h.hinge_velocities())
    np.testing.assert_array_equal(row[ROW["torque"]], h.torques())
    rv = ix.root_dof_adr
    np.testing.assert_array_equal(row[ROW["root_linvel"]], d.qvel[rv : rv + 3])
    np.testing.assert_array_equal(row[ROW["root_angvel"]], d.qvel[rv + 3 : rv + 6])
    assert row[ROW["root_z"]][0] == d.qpos[ix.root_qpos_adr + 2]
    pvw, rot = body_state(row[None].copy())
    np.testing.assert_array_equal(pvw[0, 0], d.xpos[ids])
    np.testing.assert_array_equal(pvw[0, 2], d.cvel[ids, :3])
    # the body-origin velocity: cvel (at the pelvis subtree's COM) moved to the origin; and
    # MuJoCo's own velocity of each body's COM (mj_objectVelocity) moved there alike
    w = d.cvel[ids, :3]
    want = d.cvel[ids, 3:] + np.cross(w, d.xpos[ids] - d.subtree_com[h.pelvis_body])
    np.testing.assert_allclose(pvw[0, 1], want, rtol=1e-12, atol=1e-12)
    v6 = np.zeros(6)
    for j, b in enumerate(ids.tolist()):
        mujoco.mj_objectVelocity(h.model, d, mujoco.mjtObj.mjOBJ_BODY, b, v6, 0)
        at_origin = v6[3:] + np.cross(v6[:3], d.xpos[b] - d.xipos[b])
        np.testing.assert_allclose(pvw[0, 1, j], at_origin, atol=1e-9)
    s_pvw, s_rot = h.state()
    np.testing.assert_array_equal(s_pvw, pvw[0])
    np.testing.assert_array_equal(s_rot, rot[0])
    assert not np.shares_memory(s_pvw, h.state()[0])


def test_absurd_rows_agree_with_blown_up() -> None:
    h = _moving_humanoid()
    cfg = HumanoidConfig()
    z = np.array([h.z_range])
    assert not absurd_rows(h.gather(np.empty((1, ROW_DIM))[0])[None], cfg, z)[0]
    assert not h.blown_up()
    for adr, value in ((h.index.root_dof_adr, 60.0), (h.index.hinge_dof_adr[5], 300.0),
                       (h.index.root_dof_adr + 4, np.nan)):  # fmt: skip
        keep = h.data.qvel[adr]
        h.data.qvel[adr] = value
        assert absurd_rows(h.gather(np.empty(ROW_DIM))[None], cfg, z)[0]
        assert h.blown_up()
        h.data.qvel[adr] = keep


def test_sensors_off_keep_the_physics_and_the_foot_forces() -> None:
    """Sensors never act on the motion: off, the steps are bit for bit those with them on, and
    foot_forces still reads its sensors (computed for the call); the env turns them off."""
    on, off = _moving_humanoid(), _moving_humanoid()
    off.sensors = False
    assert on.sensors and not off.sensors
    mujoco.mj_resetDataKeyframe(on.model, on.data, on.model.key("stand").id)
    mujoco.mj_resetDataKeyframe(off.model, off.data, off.model.key("stand").id)
    for h in (on, off):
        h.data.qpos[h.index.root_qpos_adr + 2] -= 0.05  # (feet pressed into the floor)
        mujoco.mj_forward(h.model, h.data)
    for _ in range(20):
        on.step()
        off.step()
    np.testing.assert_array_equal(off.data.qpos, on.data.qpos)
    np.testing.assert_array_equal(off.data.qvel, on.data.qvel)
    assert not off.data.sensordata.any() and on.data.sensordata.any()
    grf_on, cop_on = on.foot_forces()
    grf_off, cop_off = off.foot_forces()
    assert grf_on[:, 2].sum() > 100.0  # (standing: the feet carry the body)
    np.testing.assert_array_equal(grf_off, grf_on)
    np.testing.assert_array_equal(cop_off, cop_on)
    assert not off.sensors


def test_the_tracking_env_turns_sensors_and_islands_off() -> None:
    from envs.tracking_env import GripTrackingEnv

    env = GripTrackingEnv()
    env.reset(seed=0)
    assert not env.humanoid.sensors and not env.humanoid.islands


def test_model_arrays_find_the_differing_arrays_and_are_shared_read_only() -> None:
    """One pass over the bytes finds the arrays that differ between two subjects (those an
    array-by-array comparison finds); two humanoids switching with shared arrays end with the
    other subject's model, bit for bit, and leave the shared arrays as they were."""
    from grip.core.body import BodyParams
    from grip.sim.model import ModelArrays, _model_arrays

    short, tall = load_model(BodyParams(1.62, 58.0)), load_model(BodyParams(1.88, 92.0))
    a, b = ModelArrays(short), ModelArrays(tall)
    want = {n for n, v in _model_arrays(short).items()
            if not np.array_equal(v, _model_arrays(tall)[n], equal_nan=True)}  # fmt: skip
    assert set(a.differing(b)) == want and "body_mass" in want and not a.differing(a)
    kept = {n: v.copy() for n, v in b.arrays.items()}
    humans = [Humanoid(mujoco.MjModel.__copy__(short), key="short", arrays=a) for _ in range(2)]
    for h in humans:
        h.add("tall", tall, b)
        h.switch("tall")
        for n, v in _model_arrays(tall).items():
            np.testing.assert_array_equal(_model_arrays(h.model)[n], v, err_msg=n)
        h.switch("short")
        np.testing.assert_array_equal(h.model.body_mass, short.body_mass)
    for n, v in kept.items():
        np.testing.assert_array_equal(b.arrays[n], v)


def test_islands_off_keep_the_physics() -> None:
    """One body tree on the floor is one island: without island discovery the steps are bit
    for bit the same, contacts and PD included (the tracking env turns it off)."""
    on, off = _moving_humanoid(), _moving_humanoid()
    off.islands = False
    assert on.islands and not off.islands
    rng = np.random.default_rng(1)
    for _ in range(60):
        target = np.clip(on.hinge_angles() + rng.normal(0.0, 0.3, 69), on.lo, on.hi)
        for h in (on, off):
            h.set_targets(target)
            h.step()
    assert on.data.ncon > 0  # (it fell onto the floor: contacts were solved)
    np.testing.assert_array_equal(off.data.qpos, on.data.qpos)
    np.testing.assert_array_equal(off.data.qvel, on.data.qvel)
