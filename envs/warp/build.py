"""What :class:`envs.warp.env.WarpTrackingEnv` builds once, at construction: the models of the
clips' subjects in their scenes (:func:`build_models`) and every clip's per-frame arrays on the
device (:func:`build_clips`).

Every clip's body is compiled once (:mod:`envs.scenes`); the first subject's model is the warp
model, and the model arrays that differ between subjects (segment lengths, masses, gains) become
per-subject tables, written into the worlds at each reset. With ``terrain = "auto"`` the model
holds every props clip's scene (:mod:`envs.warp.scenes`), with per-scene tables of its slot geoms.
"""

from __future__ import annotations

import copy
import dataclasses

import mujoco
import mujoco_warp as mjw
import numpy as np
import torch

from envs.scenes import compile_scene, humanoid_scenes, humanoid_xml, scene_parts
from envs.warp import torch_task as T
from envs.warp.scenes import SceneSlots, scene_slots, scenes_xml
from grip.core.reference import ReferenceSource
from grip.sim.model import HumanoidIndex
from grip.task import amp as A
from grip.task import observations as O
from grip.task.config import TrackingEnvConfig

UNBATCHED_OK = frozenset(("site_size", "key_qpos", "dof_length"))
"""Model arrays that may differ between subjects and that MuJoCo Warp does not batch per world:
none of them is read by a step with sensors off (site sizes are the insole touch zones, the
keyframe is never loaded, dof_length only scales the sleeping and set_const heuristics)."""


def _batchable_fields() -> dict[str, bool]:
    """MuJoCo Warp's ``Model`` array fields: name -> whether they can hold one row per world."""
    out = {}
    for f in dataclasses.fields(mjw.Model):
        shape = getattr(f.type, "shape", None)
        if shape is not None:
            out[f.name] = bool(shape) and shape[0] == "*"
    return out


@dataclasses.dataclass(frozen=True)
class Models:
    """The subjects' models in the scenes and the per-clip scene tables (C clips).

    Attributes:
        mj_model: The first subject's model, sensors off: the one the warp model is put from.
        subject_models: The compiled MuJoCo model of each subject, in the scene (with
            ``terrain = "auto"`` and props clips: the assets of every props clip's scene).
        index: Name -> index resolution of ``mj_model``.
        lo, hi: ``(69,)`` the hinge limits (PD target range), rad.
        kd_over_kp: Per subject, the ratio of the PD gains.
        clip_subject: Per clip, its subject's index.
        subject_fields: Model array name -> ``(subjects, ...)`` its value in each subject's model,
            on the device, for the arrays that differ between subjects.
        slots: The slot geoms of each scene (:func:`envs.warp.scenes.scene_slots`); ``None``
            without props scenes.
        clip_scene: ``(C,)`` int64 each clip's scene (-1: none of its own).
        clip_field: ``(C,)`` int64 each clip's height field (-1: flat).
        clip_z_hi: ``(C,)`` the highest pelvis allowed in each clip's scene, m.
        heightfields: The scenes' height fields on the device; ``None`` when no scene has one.
        has_terrain: Whether a scene has a height field or overhangs.
    """

    mj_model: mujoco.MjModel
    subject_models: list[mujoco.MjModel]
    index: HumanoidIndex
    lo: np.ndarray
    hi: np.ndarray
    kd_over_kp: list[np.ndarray]
    clip_subject: list[int]
    subject_fields: dict[str, torch.Tensor]
    slots: SceneSlots | None
    clip_scene: np.ndarray
    clip_field: np.ndarray
    clip_z_hi: np.ndarray
    heightfields: T.TorchHeightFields | None
    has_terrain: bool


def build_models(cfg: TrackingEnvConfig, reference: ReferenceSource,
                 device: torch.device) -> Models:  # fmt: skip
    """Compile each subject's humanoid in the scene; keep the first as the warp model and
    the arrays that differ as per-subject tables. Clips with their own scene objects
    (``terrain = "auto"``) get one model of every scene and per-scene tables of its slot
    geoms (:mod:`envs.warp.scenes`).

    Raises:
        NotImplementedError: The subjects differ in a model array MuJoCo Warp cannot hold per
            world (other than :data:`UNBATCHED_OK`).
    """
    n_clips = len(reference)
    # the scenes: one per props clip (as the CPU env's HumanoidScenes, keyed by clip), or
    # the fixed terrain of every clip
    parts: list = []
    clip_scene = np.full(n_clips, -1, dtype=np.int64)
    if cfg.terrain == "auto":
        for i in range(n_clips):
            objects = reference.clip(i).objects
            if objects:
                clip_scene[i] = len(parts)
                parts.append(scene_parts("objects", objects, cfg.heightfield_cell_m))
        fixed = None
    else:
        fixed = scene_parts(cfg.terrain, None, cfg.heightfield_cell_m)
    scenes = humanoid_scenes(cfg)
    subjects: dict[tuple, int] = {}
    models: list[mujoco.MjModel] = []
    clip_subject = []
    kd_over_kp = []
    for i in range(n_clips):
        clip = reference.clip(i)
        key = (clip.body.height_m, clip.body.mass_kg)
        if key not in subjects:
            h = scenes.get(clip.body)
            subjects[key] = len(models)
            if parts:
                xml = scenes_xml(humanoid_xml(clip.body, cfg.mjcf), parts)
                models.append(mujoco.MjModel.from_xml_string(xml))
            else:
                models.append(copy.copy(h.model))  # (a snapshot: switching changes h.model)
            kd_over_kp.append(h.kd_over_kp.copy())
            if len(models) == 1:
                index = HumanoidIndex.from_model(models[0])
                lo, hi = h.lo.copy(), h.hi.copy()
                body0 = clip.body
        clip_subject.append(subjects[key])
    mjm = copy.copy(models[0])
    mjm.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_SENSOR)
    # the slot geoms of each scene; the height map's field and the blow-up height of each
    # clip's scene
    slots = None
    if parts:
        own = [compile_scene(body0, cfg.mjcf, hf, over) for hf, over in parts]
        slots = scene_slots(models[0], parts, own)
    scene_list = parts if fixed is None else [fixed]
    fields = [hf for hf, _ in scene_list if hf is not None]
    has_field = np.array([hf is not None for hf, _ in scene_list], dtype=bool)
    # (index -1, a flat clip, reads the -1 appended)
    scene_field = np.append(np.where(has_field, np.cumsum(has_field) - 1, -1), -1)
    clip_field = scene_field[clip_scene if fixed is None else np.zeros(n_clips, np.int64)]
    tops = np.append([hf.max_height for hf in fields], 0.0)
    # the arrays that differ between subjects, per subject
    subject_fields: dict[str, torch.Tensor] = {}
    for name, can_batch in _batchable_fields().items():
        base = getattr(mjm, name, None)
        if not isinstance(base, np.ndarray):
            continue
        rows = [getattr(m, name) for m in models]
        if all(np.array_equal(r, base) for r in rows[1:]):
            continue
        if not can_batch:
            if name in UNBATCHED_OK:
                continue
            raise NotImplementedError(f"WarpTrackingEnv: subjects differ in {name}, which "
                                      "MuJoCo Warp cannot hold per world")  # fmt: skip
        subject_fields[name] = torch.as_tensor(np.stack(rows), device=device)
    return Models(
        mj_model=mjm, subject_models=models, index=index, lo=lo, hi=hi, kd_over_kp=kd_over_kp,
        clip_subject=clip_subject, subject_fields=subject_fields, slots=slots,
        clip_scene=clip_scene, clip_field=clip_field.astype(np.int64),
        clip_z_hi=tops[clip_field] + cfg.blowup_height_m,
        heightfields=T.TorchHeightFields(fields, device) if fields else None,
        has_terrain=bool(fields) or any(over for _, over in scene_list))  # fmt: skip


@dataclasses.dataclass(frozen=True)
class Clips:
    """Every clip's per-frame arrays, concatenated along frames (clip ``c`` starts at row
    ``offset[c]``), float32 on the device unless said otherwise."""

    offset: torch.Tensor  # (C,) int64
    n_frames: torch.Tensor  # (C,) int64
    subject: torch.Tensor  # (C,) int64: index into the subjects
    gt_pvw: torch.Tensor  # (F, 3, J, 3) ground-truth positions, velocities, angular velocities
    gt_rot: torch.Tensor  # (F, J, 3, 3)
    qpos: torch.Tensor  # (F, nq) ground-truth pose in MuJoCo's qpos order
    qvel: torch.Tensor  # (F, nv)
    obs_rows: torch.Tensor  # (F, OBS_ROW_DIM) the estimate (EstimateFrames.obs_rows)
    target: torch.Tensor  # (F, 69) PD target of a relative action of 0, rad
    sensor: torch.Tensor  # (F, S) KinematicsNet inputs
    est_root: torch.Tensor  # (F, 3) integrated estimated root, m
    amp: torch.Tensor  # (F, FRAME_DIM) ground-truth AMP frames


def build_clips(cfg: TrackingEnvConfig, reference: ReferenceSource, models: Models,
                device: torch.device) -> tuple[Clips, np.ndarray]:  # fmt: skip
    """Concatenate every clip's per-frame arrays on the device.

    Returns:
        The :class:`Clips` and ``(C,)`` float64 the clips' lengths in frames, on the host.
    """
    ix, m = models.index, models.mj_model
    parts: dict[str, list[np.ndarray]] = {
        k: []
        for k in (
            "gt_pvw",
            "gt_rot",
            "qpos",
            "qvel",
            "obs_rows",
            "target",
            "sensor",
            "est_root",
            "amp",
        )
    }
    lengths = []
    for i in range(len(reference)):
        clip = reference.clip(i)
        t = clip.n_frames
        lengths.append(t)
        est = O.EstimateFrames()
        est.update(clip, models.kd_over_kp[models.clip_subject[i]], cfg.velocity_feedforward)
        parts["gt_pvw"].append(np.stack([clip.gt_pos, clip.gt_vel, clip.gt_angvel], axis=1))
        parts["gt_rot"].append(clip.gt_rot)
        q = np.tile(m.qpos0, (t, 1))
        r = ix.root_qpos_adr
        q[:, r : r + 7] = clip.gt_qpos[:, :7]
        q[:, ix.hinge_qpos_adr] = clip.gt_qpos[:, 7:]
        v = np.zeros((t, m.nv))
        rv = ix.root_dof_adr
        v[:, rv : rv + 6] = clip.gt_qvel[:, :6]
        v[:, ix.hinge_dof_adr] = clip.gt_qvel[:, 6:]
        parts["qpos"].append(q)
        parts["qvel"].append(v)
        parts["obs_rows"].append(est.obs_rows[:t])
        parts["target"].append(est.target[:t])
        parts["sensor"].append(clip.sensor[:t])
        parts["est_root"].append(clip.est_root_pos[:t])
        parts["amp"].append(A.reference_amp_features(clip))

    def cat(k: str) -> torch.Tensor:
        return torch.as_tensor(np.concatenate(parts[k]), dtype=torch.float32, device=device)

    lengths_t = torch.as_tensor(lengths, dtype=torch.int64, device=device)
    clips = Clips(
        offset=torch.cumsum(lengths_t, 0) - lengths_t, n_frames=lengths_t,
        subject=torch.as_tensor(models.clip_subject, dtype=torch.int64, device=device),
        **{k: cat(k) for k in parts})  # fmt: skip
    return clips, np.asarray(lengths, dtype=np.float64)
