"""Clips with their own scene objects (props) in ``WarpTrackingEnv``, against the CPU env.

The clips: the bundled sample's walk and run on the flat floor; a body standing (one frame of
the walk held) on a 0.2 m box; the same body on an open-underside slab 0.25-0.30 m up (an
overhang: a static mesh geom, not in the height field) with a 0.4 m box beside it and a second
slab high above; the walk with boxes beside its path and a slab over it. One model holds the
three scenes, and each world shows its clip's (``envs.warp.scenes``):

* each world's slot geoms point at its clip's field and meshes and sit where the CPU env's own
  model of that clip has them; unused ones are parked;
* the height map of every world equals the CPU env's for its clip;
* flat and props worlds step together: the flat worlds as on the CPU (as
  ``test_warp_env.py`` requires), the standing bodies stay on their box and slab with the
  pelvis within :data:`PROP_Z_ATOL` of the CPU env's (MuJoCo Warp keeps at most 4 contacts per
  geom-hfield pair, MuJoCo C one per prism: docs/gpu.md); then the worlds are dealt other clips
  (props to flat and back) and step on.

``slow``: MuJoCo Warp compiles its kernels on first use; skipped without the ``gpu`` extra.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from envs.warp import warp_available

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not warp_available(), reason="needs mujoco-warp (pip install -e .[gpu])"),
]

STAND_FRAME = 20  # a frame of the walk with both feet down: held, the body stands
BOX_M, SLAB_M = 0.2, 0.3  # top of the box and of the slab the body stands on
FLAT, BOX, SLAB, WALK = 0, 2, 3, 4  # clip indices (1: the run, flat)
N_DECISIONS = 50  # x 2 substeps = 100 physics steps per phase
QPOS_ATOL = 1e-3  # flat worlds, as test_warp_env.py
OBS_ATOL = {"sensor": 0.0, "kinematic": 2e-3, "self": 2e-3, "environment": 1e-5}
REWARD_ATOL = 2e-4
PROP_Z_ATOL = 5e-3  # pelvis height on a prop, m (a quiet stance on a height field: 1e-3)
GRAZING_M = 1e-3


def _box(center, extents):
    import trimesh

    at = trimesh.transformations.translation_matrix(center)
    m = trimesh.creation.box(extents=extents, transform=at)
    return np.asarray(m.vertices), np.asarray(m.faces)


def _standing(src, lift_m, objects, frames=120):
    """``src``'s frame :data:`STAND_FRAME` held for ``frames`` frames, ``lift_m`` up."""
    f = STAND_FRAME
    q = np.tile(src.gt_qpos[f], (frames, 1))
    q[:, 2] += lift_m
    return dataclasses.replace(
        src, name=f"stand_{lift_m}", gt_qpos=q, est_pos=np.tile(src.est_pos[f], (frames, 1, 1)),
        est_rot6d=np.tile(src.est_rot6d[f], (frames, 1, 1)),
        est_vel=np.zeros((frames, *src.est_vel.shape[1:])),
        sensor=np.tile(src.sensor[f], (frames, 1)), objects=objects)  # fmt: skip


def _reference():
    from envs.tracking_env import SAMPLE_REFERENCE
    from grip.core.reference import ReferenceSet

    ref = ReferenceSet.load(SAMPLE_REFERENCE)
    walk = ref.clip(0)
    x, y = walk.gt_qpos[STAND_FRAME, :2]
    path_x = float(np.median(walk.gt_qpos[:, 0]))
    clips = [
        walk,
        ref.clip(1),
        _standing(walk, BOX_M, {"box": _box((x, y, BOX_M / 2), (1.0, 1.0, BOX_M))}),
        _standing(walk, SLAB_M, {"slab": _box((x, y, SLAB_M - 0.025), (1.0, 1.0, 0.05)),
                                 "side": _box((x + 0.7, y, 0.2), (0.3, 0.3, 0.4)),
                                 "high": _box((x, y + 3.0, 1.5), (0.3, 0.3, 0.05))}),
        dataclasses.replace(walk, name="walk_by_boxes", objects={
            "low": _box((path_x + 0.6, -3.2, 0.1), (0.4, 0.8, 0.2)),
            "mid": _box((path_x - 0.6, -2.0, 0.25), (0.4, 0.6, 0.5)),
            "over": _box((path_x, -1.0, 2.2), (1.0, 0.4, 0.05))}),
    ]  # fmt: skip
    return ReferenceSet(clips, ref.sensor_sites, ref.insoles)


@pytest.fixture(scope="module")
def props():
    import warp as wp

    from envs.warp.env import WarpTrackingEnv
    from grip.task.config import TrackingEnvConfig

    wp.config.quiet = True
    ref = _reference()
    # (no early termination: the standing bodies and the flat walks play 2 x 50 decisions)
    cfg = TrackingEnvConfig(termination_dist_m=0.0, random_start=False)
    return cfg, ref, WarpTrackingEnv(cfg, ref, 4, device="cpu")


def _reset(gpu, clips, starts):
    import torch

    n = len(clips)
    gpu.reset(torch.ones(n, dtype=torch.bool), torch.as_tensor(clips), torch.as_tensor(starts))


def _cpu_env(cfg, ref, clip, start):
    from envs.tracking_env import GripTrackingEnv

    env = GripTrackingEnv(cfg, ref)
    obs, _ = env.reset(options={"clip": clip, "start": start})
    return env, obs


def test_each_world_shows_its_clips_scene(props):
    """The slot geoms of each world, read back from the warp model and data, are those of the
    CPU env's own model of the world's clip: the field a world's terrain geom points at holds
    the clip's rasterised objects, its overhang geoms' meshes the clip's slabs, each placed as
    the CPU model places it; slots the clip's scene lacks (all of them on a flat clip) are
    parked 1 km under the floor."""
    import mujoco

    from envs.scenes import scene_parts
    from envs.warp.scenes import PARKED_POS, SLOT_FIELDS

    cfg, ref, gpu = props
    clips = [FLAT, BOX, SLAB, WALK]
    _reset(gpu, clips, [0] * 4)
    m, d = gpu.model, gpu.data
    arrays = {k: getattr(m, k).numpy() for k in SLOT_FIELDS}
    xpos, xmat = d.geom_xpos.numpy(), d.geom_xmat.numpy().reshape(4, -1, 9)
    size, adr = m.hfield_size.numpy(), m.hfield_adr.numpy()
    nrow, ncol, hdata = m.hfield_nrow.numpy(), m.hfield_ncol.numpy(), m.hfield_data.numpy()
    vadr, vnum, vert = m.mesh_vertadr.numpy(), m.mesh_vertnum.numpy(), m.mesh_vert.numpy()
    mjm = gpu.mj_model
    slots = [mujoco.mj_id2name(mjm, mujoco.mjtObj.mjOBJ_GEOM, g) for g in range(mjm.ngeom)]
    slots = [s for s in slots if s and (s == "terrain" or s.startswith("overhang_"))]
    assert sorted(slots) == ["overhang_0", "overhang_1", "terrain"]
    for w, c in enumerate(clips):
        env, _ = _cpu_env(cfg, ref, c, 0)
        own, own_d = env.model, env.data
        for name in slots:
            g = mjm.geom(name).id
            og = mujoco.mj_name2id(own, mujoco.mjtObj.mjOBJ_GEOM, name)
            if og < 0:  # (the clip's scene has no such geom)
                np.testing.assert_array_equal(xpos[w, g], PARKED_POS, err_msg=f"{c} {name}")
                continue
            for k in SLOT_FIELDS[1:]:
                np.testing.assert_allclose(arrays[k][w, g].reshape(-1),
                                           getattr(own, k)[og].reshape(-1), atol=1e-6,
                                           err_msg=f"clip {c}, {name}: {k}")  # fmt: skip
            np.testing.assert_allclose(xpos[w, g], own_d.geom_xpos[og], atol=1e-6)
            np.testing.assert_allclose(xmat[w, g], own_d.geom_xmat[og], atol=1e-6)
            k, ok = arrays["geom_dataid"][w, g], own.geom_dataid[og]
            if name == "terrain":
                np.testing.assert_allclose(size[k], own.hfield_size[ok], atol=1e-6)
                field = hdata[adr[k] : adr[k] + nrow[k] * ncol[k]].reshape(nrow[k], ncol[k])
                hf, _ = scene_parts("objects", ref.clip(c).objects, cfg.heightfield_cell_m)
                assert field.shape == hf.heights.shape
                np.testing.assert_allclose(field * size[k, 2] + xpos[w, g, 2], hf.heights,
                                           atol=1e-6)  # fmt: skip
            else:
                a = own.mesh_vertadr[ok]
                want = own.mesh_vert[a : a + own.mesh_vertnum[ok]]
                np.testing.assert_allclose(vert[vadr[k] : vadr[k] + vnum[k]], want, atol=1e-6)
        n_own = sum(mujoco.mj_name2id(own, mujoco.mjtObj.mjOBJ_GEOM, s) >= 0 for s in slots)
        assert n_own == {FLAT: 0, BOX: 1, SLAB: 3, WALK: 2}[c]


@pytest.mark.parametrize("starts", [(0, 0), (60, 140), (120, 100)])
def test_height_map_of_each_clip_matches_cpu_env(props, starts):
    """The observations after a reset, the height map included, equal the CPU env's for each
    world's clip: the flat floor, the box, the box beside the slab (the slab itself is not in
    the height map, as on the CPU), and the walk past its boxes from several frames."""
    cfg, ref, gpu = props
    clips = [FLAT, BOX, SLAB, WALK]
    walk_start = starts[1]
    _reset(gpu, clips, [starts[0], 0, 0, walk_start])
    obs_g = gpu.observe()
    for w, c in enumerate(clips):
        _, obs_c = _cpu_env(cfg, ref, c, (starts[0], 0, 0, walk_start)[w])
        for k, tol in OBS_ATOL.items():
            np.testing.assert_allclose(obs_g[k][w].numpy(), obs_c[k], atol=max(tol, 1e-5),
                                       err_msg=f"clip {c}: {k}")  # fmt: skip
        ptp = np.ptp(obs_c["environment"])
        assert (ptp == 0) if c == FLAT else (ptp > 0.1), (c, ptp)  # (a prop's edge in view)


def _contact_names(model, pairs: dict) -> dict:
    import mujoco

    def name(g):
        return mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)

    return {tuple(sorted((name(a), name(b)))): v for (a, b), v in pairs.items()}


def _contacts_cpu(env) -> dict:
    d = env.humanoid.data
    out: dict = {}
    for c in d.contact[: d.ncon]:
        key = (int(min(c.geom)), int(max(c.geom)))
        out[key] = min(out.get(key, np.inf), float(c.dist))
    return _contact_names(env.model, out)


def _unmatched_depth(a: dict, b: dict) -> float:
    extra = [v for k, v in a.items() if k not in b] + [v for k, v in b.items() if k not in a]
    return max([0.0, *(-v for v in extra)])


def test_flat_and_props_worlds_step_together(props):
    """Four worlds step together for 2 x 50 decisions (relative actions 0), against the CPU env
    (MuJoCo C, each clip in its own scene); between the phases the worlds are dealt other clips,
    so a world goes from a prop to the flat floor and back."""
    import torch

    from envs.batched import BatchedTrackingEnv
    from envs.tracking_env import GripTrackingEnv

    cfg, ref, gpu = props
    phases = (((FLAT, 0), (BOX, 0), (SLAB, 0), (1, 20)),
              ((SLAB, 0), (FLAT, 30), (1, 40), (BOX, 0)))  # fmt: skip
    lift = {BOX: BOX_M, SLAB: SLAB_M}
    n = gpu.num_envs
    envs = [GripTrackingEnv(cfg, ref) for _ in range(n)]
    for e in envs:
        e.reset(seed=0)
    cpu = BatchedTrackingEnv(envs, threads=1)
    act = np.zeros((n, 69), np.float32)
    worst = dict.fromkeys(("flat_qpos", "prop_pelvis_z", "unmatched_contact_m"), 0.0)
    try:
        for phase in phases:
            for i, (c, s) in enumerate(phase):
                cpu.reset(i, options={"clip": c, "start": s})
            _reset(gpu, [c for c, _ in phase], [s for _, s in phase])
            flat = np.array([c not in lift for c, _ in phase])
            for step in range(N_DECISIONS):
                o_c, r_c, te_c, tr_c, _ = cpu.step(act)
                o_g, r_g, te_g, tr_g, _ = gpu.step(torch.as_tensor(act))
                at = f"phase {phase}, step {step}"
                assert not (te_c.any() or tr_c.any()), at  # (every episode plays on)
                np.testing.assert_array_equal(te_g.numpy(), te_c, err_msg=at)
                np.testing.assert_array_equal(tr_g.numpy(), tr_c, err_msg=at)
                q_c = np.stack([e.humanoid.data.qpos for e in cpu.envs])
                q_g = gpu.qpos.numpy()
                dq = np.abs(q_g[flat] - q_c[flat]).max()
                assert dq < QPOS_ATOL, f"flat worlds' qpos differs by {dq}, {at}"
                worst["flat_qpos"] = max(worst["flat_qpos"], dq)
                for k, tol in OBS_ATOL.items():
                    d = np.abs(o_g[k].numpy()[flat] - o_c[k][flat]).max()
                    assert d <= tol, f"flat worlds' obs {k} differs by {d}, {at}"
                assert np.abs(r_g.numpy()[flat] - r_c[flat]).max() < REWARD_ATOL, at
                depths = gpu.contact_depths()
                for i in np.flatnonzero(flat):
                    c_i = _contacts_cpu(cpu.envs[i])
                    g_i = _contact_names(gpu.mj_model, depths[i])
                    d = _unmatched_depth(g_i, c_i)
                    assert d < GRAZING_M, f"world {i}: {g_i}, C {c_i}"
                    worst["unmatched_contact_m"] = max(worst["unmatched_contact_m"], d)
                for i, (c, _) in enumerate(phase):
                    if c in lift:  # the pelvis stands on the prop, as on the CPU
                        dz = abs(q_g[i, 2] - q_c[i, 2])
                        assert dz < PROP_Z_ATOL, f"world {i} (clip {c}): pelvis {dz} m off, {at}"
                        worst["prop_pelvis_z"] = max(worst["prop_pelvis_z"], dz)
                        assert q_g[i, 2] > lift[c] + 0.8, at
            assert any(len(_contacts_cpu(cpu.envs[i])) for i in np.flatnonzero(flat))
    finally:
        cpu.close()
    print("largest differences:", {k: f"{v:.2e}" for k, v in worst.items()})
