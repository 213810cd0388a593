"""Clips with their own scene objects on MuJoCo Warp: one model holds the height field and the
overhang meshes of every scene, and each world shows its clip's scene.

On the CPU each props clip has its own model (:class:`envs.scenes.HumanoidScenes`: its height
field as the ``terrain`` geom, its overhangs as ``overhang_<k>`` mesh geoms). MuJoCo Warp 4.0.0
steps all worlds with one model: its assets (``hfield_data``, ``hfield_size``, ``mesh_vert``, ...)
have no world dimension, but the arrays of its geoms can (``put_model(batch_sizes=...)``):

* the height-field collision reads the field of ``geom_dataid[world % rows, geom]``
  (``collision_convex.py``: ``_hfield_filter``, ``ccd_hfield_kernel``), and so does the convex
  (mesh) collision (``geom_collision_pair``);
* the broadphase reads ``geom_aabb`` and ``geom_rbound`` per world, and every geom's pose from
  ``Data.geom_xpos`` / ``geom_xmat``, which for a static geom ``make_data`` computes once and no
  step rewrites (``smooth.py``: ``_geom_local_to_global`` skips them).

So the model (:func:`scenes_xml`) holds every scene's field as an ``<hfield>`` asset and every
overhang as a ``<mesh>`` asset, with one ``terrain`` geom and as many ``overhang_<j>`` geoms as
the scene with the most overhangs has (the slots). A world of scene ``s`` points the slots at
``s``'s assets and places them where ``s``'s own model has them (:class:`SceneSlots`: the values
are read from the compiled model of that scene alone). A slot its scene does not fill (a flat
clip's terrain, the overhang slots beyond its scene's) is parked at :data:`PARKED_POS`, far
under the floor, where the broadphase's bounding-sphere test never pairs it with the body.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import mujoco
import numpy as np

from envs.heightfield import HeightField, add_scene_assets

SceneParts = tuple[HeightField | None, tuple]
"""A scene as :func:`envs.scenes.scene_parts` gives it: its height field and overhang meshes."""

SLOT_FIELDS = ("geom_dataid", "geom_pos", "geom_quat", "geom_size", "geom_aabb", "geom_rbound")
"""The model arrays of the slot geoms that differ between scenes (batched per world)."""

PARKED_POS = np.array([0.0, 0.0, -1000.0])
"""Where an unused slot geom sits, m: 1 km under the floor (with the default
:attr:`grip.task.config.TrackingEnvConfig.blowup_depth_m` a pelvis 1 m under it is a blow-up)."""


def scenes_xml(xml: str, scenes: Sequence[SceneParts]) -> str:
    """A subject's MJCF (:func:`envs.scenes.humanoid_xml`) with every scene's field and
    overhangs as assets and the slot geoms (:func:`envs.heightfield.add_scene_assets`): field
    ``k`` is the ``k``-th field of ``scenes`` in order, mesh ``k`` their ``k``-th overhang."""
    fields = [hf for hf, _ in scenes if hf is not None]
    meshes = [m for _, over in scenes for m in over]
    n_over = max((len(over) for _, over in scenes), default=0)
    return add_scene_assets(xml, fields, meshes, n_over)


@dataclasses.dataclass(frozen=True)
class SceneSlots:
    """The slot geoms of each scene (S scenes, G slots).

    Attributes:
        geoms: ``(G,)`` the slot geoms' ids in the model: ``terrain`` (when a scene has a
            field), then ``overhang_0``, ``overhang_1``, ...
        model: :data:`SLOT_FIELDS` name -> ``(S + 1, G, ...)`` the values of the slot geoms in
            each scene; row ``S``: none filled (a flat clip's world), all parked.
        xpos: ``(S + 1, G, 3)`` their world positions (``Data.geom_xpos``), m.
        xmat: ``(S + 1, G, 9)`` their world orientations (``Data.geom_xmat``).
    """

    geoms: np.ndarray
    model: dict[str, np.ndarray]
    xpos: np.ndarray
    xmat: np.ndarray


def scene_slots(model: mujoco.MjModel, scenes: Sequence[SceneParts],
                scene_models: Sequence[mujoco.MjModel]) -> SceneSlots:  # fmt: skip
    """Each scene's values of the slot geoms of ``model`` (a subject's :func:`scenes_xml`),
    read from that scene's own model.

    Args:
        model: The model of every scene's assets and the slot geoms.
        scenes: The scenes, in the order :func:`scenes_xml` was given them.
        scene_models: Each scene's own model (:func:`envs.scenes.compile_scene` of its field
            and overhangs, any subject): where its ``terrain`` and ``overhang_<j>`` geoms sit
            and what they look like (MuJoCo places a mesh geom at its mesh's inertial frame).
    """

    def gid(m: mujoco.MjModel, name: str) -> int:
        return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, name)

    def asset(kind: mujoco.mjtObj, name: str) -> int:
        i = mujoco.mj_name2id(model, kind, name)
        assert i >= 0, name
        return i

    has_terrain = any(hf is not None for hf, _ in scenes)
    n_over = max((len(over) for _, over in scenes), default=0)
    names = ["terrain"] * has_terrain + [f"overhang_{j}" for j in range(n_over)]
    geoms = np.array([gid(model, n) for n in names], dtype=np.int64)
    assert (geoms >= 0).all(), names
    base = mujoco.MjData(model)
    mujoco.mj_kinematics(model, base)
    # row S (and every unfilled slot): the model's own values, parked
    parked = {k: getattr(model, k)[geoms] for k in SLOT_FIELDS}
    parked["geom_pos"] = np.tile(PARKED_POS, (len(geoms), 1))
    rows = {k: np.repeat(v[None], len(scenes) + 1, axis=0) for k, v in parked.items()}
    xpos = np.repeat(np.tile(PARKED_POS, (1, len(geoms), 1)), len(scenes) + 1, axis=0)
    xmat = np.repeat(base.geom_xmat[geoms][None], len(scenes) + 1, axis=0)
    n_field = n_mesh = 0
    for s, ((hf, over), ms) in enumerate(zip(scenes, scene_models, strict=True)):
        # (slot, the geom in the scene's own model, its asset's id in the model)
        filled = [(int(has_terrain) + j, gid(ms, f"overhang_{j}"),
                   asset(mujoco.mjtObj.mjOBJ_MESH, f"overhang_mesh_{n_mesh + j}"))
                  for j in range(len(over))]  # fmt: skip
        n_mesh += len(over)
        if hf is not None:
            filled.append((0, gid(ms, "terrain"),
                           asset(mujoco.mjtObj.mjOBJ_HFIELD, f"terrain_{n_field}")))  # fmt: skip
            n_field += 1
        own = mujoco.MjData(ms)
        mujoco.mj_kinematics(ms, own)
        for slot, g, data_id in filled:
            assert g >= 0, (s, slot)
            for k in SLOT_FIELDS:
                rows[k][s, slot] = getattr(ms, k)[g]
            rows["geom_dataid"][s, slot] = data_id
            xpos[s, slot] = own.geom_xpos[g]
            xmat[s, slot] = own.geom_xmat[g]
    return SceneSlots(geoms, rows, xpos, xmat)
