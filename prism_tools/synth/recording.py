"""Assemble a PRISM-format :class:`~prism_tools.schema.Recording` from a motion.

:func:`synthesize_sensors` runs forward kinematics once and synthesises every sensor (clean
signals, readings and diagnostics); :func:`recording_from_motion` packs the result into the
PRISM layout. Our body is not SMPL: ``smpl_params.poses`` are the motion's own joint rotations
on the project's SMPL-topology body (same joints, order and rest-pose convention, different
rest skeleton), ``betas`` are zeros, ``root_offset`` is zero and ``trans`` is the pelvis joint
position, so ``trans + root_offset`` is our root position.
"""

from __future__ import annotations

import dataclasses
import functools
import json
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from grip.core import skeleton as sk
from grip.core.body import GRAVITY, BodyModel
from grip.core.rotations import quat_to_axis_angle
from prism_tools.schema import Recording
from prism_tools.streams import (
    DataInfo,
    ImuGt,
    ImuStream,
    InsoleCombined,
    InsoleStream,
    SmplParams,
    SubjectInfo,
)
from prism_tools.synth.config import NoiseConfig, SynthConfig, config_to_json
from prism_tools.synth.imu import ImuKinematics, ImuReadings, measure_imu, synthesize_imu
from prism_tools.synth.insole import (
    InsoleReadings,
    InsoleSynth,
    measure_insoles,
    synthesize_insoles,
)
from prism_tools.synth.props import Prop, infer_props, props_as_objects, support_height
from prism_tools.validation import validate

if TYPE_CHECKING:  # prism_tools must not import grip.motion at run time (STYLE.md layering)
    from grip.motion.motion import Motion

__all__ = ["SensorSynthesis", "recording_from_motion", "synthesize_sensors"]

SMPL_NOTE = (
    "smpl_params hold this project's body model (SMPL joint topology and rest-pose convention, "
    "own anthropometric rest skeleton), not an SMPL fit: poses = axis-angle of the motion's "
    "local joint rotations (joint 0 = global orientation), trans = pelvis joint position, "
    "root_offset = 0, betas = 0."
)

ZMP_OUTSIDE_M = 0.03
"""A frame counts as 'ZMP outside the support' in the diagnostics above this error, m.

The error is the distance from the cells' force centroid to the ZMP, so it is the ZMP's distance
outside the hull of the loaded cell centres. Those centres sit inside the sole: the heel cells
2.3 cm in front of the heel, the toe cells 2.6 cm behind the tip, the outer cells 2.1 cm inside
the sole's edge (layout :data:`grip.core.skeleton.INSOLE_CELL_UV`, 1.70 m body). A physically
possible ZMP under the sole's rim is therefore up to ~2.6 cm outside the cells' hull, where no
cell distribution (nor a real insole's CoP) can follow it; 3 cm flags a ZMP outside the
foot itself, which is what ``grip data info``, the README and the manifest report
(docs/insoles_zmp.md)."""


@dataclass(frozen=True)
class SensorSynthesis:
    """Everything synthesised from one motion.

    Attributes:
        body: The body model used.
        imu: Clean IMU signals and ground truth.
        imu_readings: IMU readings (noisy unless the noise was off).
        insole: Clean insole synthesis with its diagnostics.
        insole_readings: Insole readings (noisy unless the noise was off).
        noise: The noise configuration applied.
        props: The boxes the motion stands or sits on (:func:`prism_tools.synth.props.
            infer_props`), which the insoles stand on; empty on flat ground.
    """

    body: BodyModel
    imu: ImuKinematics
    imu_readings: ImuReadings
    insole: InsoleSynth
    insole_readings: InsoleReadings
    noise: NoiseConfig
    props: tuple[Prop, ...] = ()


def synthesize_sensors(
    motion: Motion, cfg: SynthConfig | None = None, seed: int = 0, *, noise: bool = True
) -> SensorSynthesis:
    """Synthesise all IMUs and both insoles from a motion.

    Args:
        motion: The motion (any fps; the PRISM rate is 100 Hz).
        cfg: Synthesis configuration.
        seed: Seed of the noise generator (IMU and insole noise use independent child streams).
        noise: Apply ``cfg.noise``; False gives exact clean readings.

    Returns:
        Clean signals, readings and diagnostics.
    """
    cfg = cfg or SynthConfig()
    body = motion.body_model()
    global_rot, joint_pos = motion.fk(body)
    noise_cfg = cfg.noise if noise else NoiseConfig.off()
    imu_rng, insole_rng = np.random.default_rng(seed).spawn(2)
    imu = synthesize_imu(global_rot, joint_pos, body, motion.fps, cfg.imu)
    props = tuple(infer_props(global_rot, joint_pos, body, motion.fps))
    ground = functools.partial(support_height, list(props)) if props else None
    ins = synthesize_insoles(global_rot, joint_pos, body, motion.fps, cfg.insole, ground)
    return SensorSynthesis(
        body=body,
        imu=imu,
        imu_readings=measure_imu(imu, motion.fps, cfg.imu, noise_cfg, imu_rng),
        insole=ins,
        insole_readings=measure_insoles(ins, body, cfg.insole, noise_cfg, insole_rng),
        noise=noise_cfg,
        props=props,
    )


def _imu_streams(r: ImuReadings, k: ImuKinematics) -> tuple[dict, dict]:
    imu: dict[str, ImuStream] = {}
    gt: dict[str, ImuGt] = {}
    for i, part in enumerate(r.parts):
        foot = part in sk.FEET
        imu[part] = ImuStream(
            acc_world_raw=np.ascontiguousarray(r.acc_world_raw[:, i]),
            acc_world_filt=np.ascontiguousarray(r.acc_world_filt[:, i]),
            ori_world=np.ascontiguousarray(r.ori_world[:, i]),
            acc_local_raw=np.ascontiguousarray(r.acc_local_raw[:, i]) if foot else None,
            gyr_local_raw=np.ascontiguousarray(r.gyr_local_raw[:, i]) if foot else None,
        )
        gt[part] = ImuGt(
            pos_world=np.ascontiguousarray(k.pos_world[:, i]),
            vel_world=np.ascontiguousarray(k.vel_world[:, i]),
            acc_world=np.ascontiguousarray(k.acc_world_gt[:, i]),
            ori_world=np.ascontiguousarray(k.ori_world[:, i]),
        )
    return imu, gt


def _insole_streams(r: InsoleReadings) -> tuple[dict, InsoleCombined]:
    insole = {
        foot: InsoleStream(
            contacts=np.ascontiguousarray(r.contacts[:, f]),
            force=np.ascontiguousarray(r.force_bw[:, f, None]),
            forces=np.ascontiguousarray(r.cell_force_bw[:, f]),
            CoP=np.ascontiguousarray(r.cop_insole_m[:, f]),
            force_world=np.ascontiguousarray(r.force_world_bw[:, f]),
            CoP_world=np.ascontiguousarray(r.cop_world_m[:, f]),
        )
        for f, foot in enumerate(sk.FEET)
    }
    combined = InsoleCombined(
        force_world=r.combined_force_world_bw.copy(), CoP_world=r.combined_cop_world_m.copy()
    )
    return insole, combined


def recording_from_motion(
    motion: Motion, cfg: SynthConfig | None = None, seed: int = 0, *, noise: bool = True
) -> Recording:
    """A complete, validated PRISM-format recording synthesised from a motion.

    Fields: subject from the motion's body parameters (height, weight, arm and foot length when
    set; gender ``"neutral"``); ``data_info.take_id`` = motion name, ``trial_name`` = category;
    ``smpl_params`` as described in the module docstring; all eight IMUs (``imu``: readings with
    noise unless ``noise=False``, ``acc_world_filt`` through the causal low-pass; feet also
    ``acc_local_raw``/``gyr_local_raw``); ``imu_gt`` (position, central-difference velocity,
    plain second-difference acceleration, orientation); both insoles and the combined insole
    (forces and cell values in body weights, cells summing to the foot force; CoP in metres);
    ``objects`` the boxes the motion stands or sits on (``prop_00``, ...; None on flat ground,
    :mod:`prism_tools.synth.props`), ``slam`` None. ``extras`` holds the provenance:
    ``source_clip``, ``category``, ``synthetic``, ``noise``, ``noise_seed``,
    ``synthesis_config`` (JSON), ``body_params`` (JSON), ``source_meta`` (JSON), ``smpl_note``,
    ``dropped_frames``
    (``{"imu": {part: idx}, "insole": {foot: idx}}``) and insole diagnostics
    (``insole_zmp_outside_frames`` counted above ``insole_zmp_outside_threshold_m``;
    ``insole_other_support_frames``: frames where body parts other than the feet carry more than
    5 % of the body weight), and
    ``props`` (JSON: kind, top height, top extent, frames and underside height of each prop).

    Args:
        motion: The motion.
        cfg: Synthesis configuration.
        seed: Noise seed.
        noise: Apply ``cfg.noise``; False gives ground-truth readings.

    Returns:
        The recording (passes :func:`prism_tools.validation.validate`).
    """
    cfg = cfg or SynthConfig()
    syn = synthesize_sensors(motion, cfg, seed, noise=noise)
    n = motion.n_frames
    params = motion.body
    subject = SubjectInfo(
        subj_id="synthetic",
        gender="neutral",
        age=None,
        height_m=float(params.height_m),
        weight_kg=float(params.mass_kg),
        shoe_length=params.foot_length_m,
        arm_length=params.arm_length_m,
    )
    data_info = DataInfo(
        take_id=motion.name,
        trial_name=motion.category,
        insole_size=None,
        fps=float(motion.fps),
        synth_imu_frames={},
    )
    smpl = SmplParams(
        poses=quat_to_axis_angle(motion.local_quat).reshape(n, 72).astype(np.float32),
        betas=np.zeros((n, 10), dtype=np.float32),
        trans=np.asarray(motion.root_pos, dtype=np.float64).copy(),
        gender="neutral",
        root_offset=np.zeros(3),
    )
    imu, imu_gt = _imu_streams(syn.imu_readings, syn.imu)
    insole, combined = _insole_streams(syn.insole_readings)
    ins = syn.insole
    extras = {
        "source_clip": motion.name,
        "category": motion.category,
        "synthetic": True,
        "noise": bool(noise),
        "noise_seed": int(seed) if noise else None,
        "synthesis_config": config_to_json(dataclasses.replace(cfg, noise=syn.noise)),
        "body_params": json.dumps(dataclasses.asdict(params)),
        "source_meta": json.dumps(motion.meta, sort_keys=True, default=str),
        "smpl_note": SMPL_NOTE,
        "imu_acc_smoothing_frames": int(syn.imu.acc_smoothing_frames),
        "dropped_frames": {
            "imu": dict(syn.imu_readings.dropped),
            "insole": dict(syn.insole_readings.dropped),
        },
        "insole_unsupported_frames": int(np.count_nonzero(ins.unsupported_force_n > 1.0)),
        "insole_zmp_outside_frames": int(np.count_nonzero(ins.zmp_error_m > ZMP_OUTSIDE_M)),
        "insole_zmp_outside_threshold_m": ZMP_OUTSIDE_M,
        "insole_max_zmp_error_m": float(ins.zmp_error_m.max(initial=0.0)),
        "insole_solver_fallback_frames": int(ins.fallback_frames.size),
        "insole_other_support_frames": int(np.count_nonzero(
            ins.other_support_force_n > 0.05 * syn.body.total_mass * GRAVITY)),
        "props": json.dumps([{"kind": p.kind, "height_m": round(p.height_m, 4),
                              "lo": p.lo.round(4).tolist(), "hi": p.hi.round(4).tolist(),
                              "frames": p.frames, "bottom_m": round(p.bottom_m, 4)}
                             for p in syn.props]),
    }
    rec = Recording.from_streams(subject, data_info, imu, insole, combined, extras,
                                 smpl_params=smpl, imu_gt=imu_gt,
                                 objects=props_as_objects(list(syn.props)))  # fmt: skip
    validate(rec)
    return rec
