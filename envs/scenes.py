"""Humanoids in their scenes: one compiled :class:`grip.sim.humanoid.Humanoid` per scene, the
subjects switched in (the training task and the inference pipeline share it)."""

from __future__ import annotations

import copy
import dataclasses
import functools
import types

import mujoco
import trimesh

from envs.heightfield import (
    HeightField,
    add_heightfield,
    add_static_meshes,
    rasterize,
    sample_heightmap,
)
from envs.terrain import make_scene, split_overhangs
from grip.core.body import BodyParams
from grip.core.mjcf import SIM_TEXTURE_PX, MjcfConfig, build_mjcf
from grip.sim.humanoid import Humanoid, HumanoidConfig
from grip.sim.model import ModelArrays
from grip.task.config import TrackingEnvConfig

SceneObjects = dict  # {name: (vertices (V, 3), faces (F, 3))}


class HumanoidScenes:
    """A bounded cache of humanoids, one per scene; a new subject is compiled once and then
    swapped in by copying arrays (:class:`grip.sim.model.ModelVariants`), so that moving across
    the many subjects of a training set does not compile models.

    Args:
        cfg: Stepping and blow-up bounds of every humanoid.
        mjcf: Humanoid and simulation options.
        terrain: ``"auto"`` (a recording's scene objects, else flat) or a fixed scene name
            (:func:`envs.terrain.make_scene`).
        heightfield_cell_m: Resolution of a terrain height field, m.
        max_scenes: Scenes kept (the oldest is dropped).
        compiled: Compiled models by (scene, subject), shared by the ``HumanoidScenes`` of
            environments with the same settings and clips (a batch of training environments:
            each compiles a scene and subject once, not once per environment); ``None``: this
            object's own.
    """

    def __init__(self, cfg: HumanoidConfig, mjcf: MjcfConfig, terrain: str = "auto",
                 heightfield_cell_m: float = 0.02, max_scenes: int = 16,
                 compiled: dict | None = None) -> None:  # fmt: skip
        self.cfg, self.mjcf, self.terrain = cfg, mjcf, terrain
        self.cell_m, self.max_scenes = heightfield_cell_m, max_scenes
        self._scenes: dict[tuple, Humanoid] = {}
        self._compiled = {} if compiled is None else compiled

    def _scene_key(self, objects: SceneObjects | None, tag) -> tuple:
        if self.terrain == "auto":
            return ("objects", tag) if objects else ("flat",)
        return (self.terrain,)

    def _compile(self, body: BodyParams, objects: SceneObjects | None, kind: str):
        hf, overhangs = scene_parts(kind, objects, self.cell_m)
        model = compile_scene(body, self.mjcf, hf, overhangs)
        # (its arrays, compared once against each humanoid that switches to it: shared by the
        # environments that share the compiled models)
        return model, hf, ModelArrays(model)

    def _compiled_model(self, body: BodyParams, objects: SceneObjects | None, skey: tuple,
                        bkey: tuple):  # fmt: skip
        """The model (read only: copy it to simulate), height field and
        :class:`grip.sim.model.ModelArrays` of a scene and subject, compiled once."""
        key = (skey, bkey)
        hit = self._compiled.get(key)
        if hit is None:
            if len(self._compiled) >= 4 * self.max_scenes:
                self._compiled.pop(next(iter(self._compiled)))
            hit = self._compiled[key] = self._compile(body, objects, skey[0])
        return hit

    def get(self, body: BodyParams, objects: SceneObjects | None = None, tag=None) -> Humanoid:
        """The humanoid of ``body`` in the scene of ``objects`` (``tag`` names that scene: scenes
        with objects are told apart by it, e.g. a clip index)."""
        skey, bkey = self._scene_key(objects, tag), (body.height_m, body.mass_kg)
        h = self._scenes.get(skey)
        if h is not None:
            if h.key != bkey:
                if not h.has(bkey):
                    model, _, arrays = self._compiled_model(body, objects, skey, bkey)
                    h.add(bkey, model, arrays)
                h.switch(bkey)
            return h
        model, hf, arrays = self._compiled_model(body, objects, skey, bkey)
        model = copy.copy(model)  # (switching subjects changes a humanoid's model in place)
        terrain = None if hf is None else functools.partial(sample_heightmap, hf)
        top = 0.0 if hf is None else float(hf.heights.max())
        h = Humanoid(model, self.cfg, bkey, terrain, top, arrays)
        if len(self._scenes) >= self.max_scenes:
            self._scenes.pop(next(iter(self._scenes)))
        self._scenes[skey] = h
        return h


def scene_parts(kind: str, objects: SceneObjects | None = None, cell_m: float = 0.02
                ) -> tuple[HeightField | None, tuple[trimesh.Trimesh, ...]]:  # fmt: skip
    """What a scene adds to the humanoid's model: the height field of the meshes that rest on
    the floor (``None`` when there are none) and the meshes that do not (overhangs, such as a
    stool's seat slab: static geoms, which the height map does not show).

    Args:
        kind: ``"objects"`` (a clip's ``objects``) or a scene name of
            :func:`envs.terrain.make_scene`.
        objects: The clip's scene objects (``kind = "objects"``).
        cell_m: Resolution of the height field, m.
    """
    if kind == "objects":
        objs = {n: types.SimpleNamespace(vertices=v, faces=f)
                for n, (v, f) in objects.items()}  # fmt: skip
        scene = make_scene("objects", objects=objs)
    else:
        scene = make_scene(kind)
    resting, overhangs = split_overhangs(scene)
    hf = None if resting.is_flat else rasterize(resting, cell_m)
    return hf, overhangs


def humanoid_xml(body: BodyParams, mjcf: MjcfConfig) -> str:
    """The MJCF of a subject's humanoid on the flat floor, as the scenes compile it."""
    # (small textures: they are only drawn by an env's render(); the physics is the same)
    return build_mjcf(body, dataclasses.replace(mjcf, texture_px=SIM_TEXTURE_PX))


def compile_scene(body: BodyParams, mjcf: MjcfConfig, hf: HeightField | None,
                  overhangs: tuple[trimesh.Trimesh, ...] = ()) -> mujoco.MjModel:  # fmt: skip
    """A subject's humanoid in a scene of :func:`scene_parts`: its height field as the
    ``"terrain"`` geom, its overhangs as the static mesh geoms ``"overhang_<k>"``."""
    xml = humanoid_xml(body, mjcf)
    if hf is not None:
        xml = add_heightfield(xml, hf)
    if overhangs:
        xml = add_static_meshes(xml, overhangs)
    return mujoco.MjModel.from_xml_string(xml)


def humanoid_config(cfg: TrackingEnvConfig) -> HumanoidConfig:
    """The :class:`grip.sim.humanoid.HumanoidConfig` of a tracking env's settings."""
    return HumanoidConfig(cfg.substeps, cfg.blowup_lin_vel_mps, cfg.blowup_ang_vel_radps,
                          cfg.blowup_height_m, cfg.blowup_depth_m)  # fmt: skip


def humanoid_scenes(cfg: TrackingEnvConfig, compiled: dict | None = None) -> HumanoidScenes:
    """The humanoids of a tracking env's settings (a policy's ``env_cfg``), one per scene
    (``compiled``: see :class:`HumanoidScenes`)."""
    return HumanoidScenes(humanoid_config(cfg), cfg.mjcf, cfg.terrain, cfg.heightfield_cell_m,
                          compiled=compiled)  # fmt: skip
