"""Small, valid, self-consistent random recordings for tests and demos.

:func:`make_recording` builds a subject who stands still for the first second (insole forces sum
to 1 body weight, as in PRISM's initial T-pose) and then walks along +y. All signals are smooth
random functions of time drawn from ``np.random.default_rng(seed)``:

* IMU orientations are smooth random rotations; ``imu_gt`` velocities/accelerations are finite
  differences of the positions; recorded accelerations add noise; foot IMUs carry the
  accelerometer (specific force, gravity included) and gyroscope readings in the sensor frame.
* The 16 insole cells of each foot sum exactly to that foot's force; contacts follow the cell
  rule (front: cells 8-15, back: cells 0-3, above :data:`CONTACT_THRESHOLD_BW`); the centre of
  pressure is the force-weighted mean of the cell centres.

It is not a biomechanical model: limbs do not stay connected and SMPL poses are random.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.spatial.transform import Rotation

from prism_tools.schema import Recording
from prism_tools.streams import (
    DEFAULT_FPS,
    FEET,
    IMU_PARTS,
    INSOLE_BACK_CELLS,
    INSOLE_FRONT_CELLS,
    N_INSOLE_CELLS,
    DataInfo,
    ImuGt,
    ImuStream,
    InsoleCombined,
    InsoleStream,
    Slam,
    SmplParams,
    SubjectInfo,
    box_object,
    contacts_from_cells,
)

__all__ = ["CONTACT_THRESHOLD_BW", "INSOLE_CELL_XY_M", "make_recording"]

CONTACT_THRESHOLD_BW = 0.02
"""Summed cell force above which a contact (front or back) is on, body weights."""

INSOLE_CELL_XY_M = np.array(
    [
        [-0.105, 0.011], [-0.105, -0.011], [-0.075, 0.012], [-0.075, -0.014],   # heel
        [-0.036, 0.004], [-0.036, -0.020], [0.000, 0.019], [0.000, -0.025],     # midfoot
        [0.049, 0.026], [0.052, 0.011], [0.047, -0.002], [0.039, -0.014],      # metatarsals
        [0.029, -0.027], [0.104, 0.023], [0.099, 0.002], [0.086, -0.019],      # 12; toes
    ]
)  # fmt: skip
"""``(16, 2)`` approximate cell centres of a 26 cm insole, metres, insole frame: x from heel to
toe (origin mid-foot), y towards the medial side."""

_STILL_S = 1.0
_RAMP_S = 0.5
_GAIT_HZ = 1.0
_WALK_SPEED_MPS = 1.0
_PELVIS_HEIGHT_M = 0.93
_ANKLE_HEIGHT_M = 0.08
_GRAVITY_WORLD = np.array([0.0, 0.0, 9.81])

# Sensor offsets from the pelvis in the T-pose, metres, world frame (subject faces +y, so +x is
# the subject's right).
_PART_OFFSET_M = {
    "Pelvis": (0.0, 0.0, 0.0),
    "Head": (0.0, 0.02, 0.62),
    "L_Wrist": (-0.75, 0.0, 0.42),
    "R_Wrist": (0.75, 0.0, 0.42),
    "L_Knee": (-0.1, 0.05, -0.45),
    "R_Knee": (0.1, 0.05, -0.45),
}
_FOOT_SIDE = {"L_Foot": -1.0, "R_Foot": 1.0}  # x side; also the sign of the gait phase


def _smooth(rng: np.random.Generator, t: np.ndarray, dims: int, max_hz: float = 1.5) -> np.ndarray:
    """``(F, dims)`` sum of 3 random sinusoids per dimension, unit-ish amplitude."""
    n_harm = 3
    freq = rng.uniform(0.1, max_hz, size=(n_harm, dims))
    phase = rng.uniform(0.0, 2 * np.pi, size=(n_harm, dims))
    amp = rng.uniform(0.3, 1.0, size=(n_harm, dims)) / n_harm
    return (amp * np.sin(2 * np.pi * freq * t[:, None, None] + phase)).sum(axis=1)


def make_recording(
    n_frames: int = 300,
    seed: int = 0,
    *,
    parts: Sequence[str] = IMU_PARTS,
    with_objects: bool = False,
) -> Recording:
    """A small, valid, self-consistent random recording at 100 fps.

    Args:
        n_frames: Number of frames ``F >= 2`` (the first 100 are a still stance).
        seed: Seed of the only random generator used (``np.random.default_rng(seed)``).
        parts: IMU parts to include (subset of :data:`~prism_tools.streams.IMU_PARTS`); ``imu``
            and ``imu_gt`` hold these. Both insoles are always present.
        with_objects: Add a ``BoxSmall`` scene object.

    Returns:
        A recording that passes :func:`~prism_tools.validation.validate`, with extras
        ``{"category": "walk", "source_clip": "synthetic", "noise_seed": seed}``.
    """
    if n_frames < 2:
        raise ValueError(f"n_frames must be >= 2, got {n_frames}")
    unknown = [p for p in parts if p not in IMU_PARTS]
    if unknown:
        raise ValueError(f"unknown IMU parts {unknown}; expected a subset of {IMU_PARTS}")
    rng = np.random.default_rng(seed)
    fps = DEFAULT_FPS
    dt = 1.0 / fps
    t = np.arange(n_frames) * dt
    ramp = np.clip((t - _STILL_S) / _RAMP_S, 0.0, 1.0)  # 0 while standing, 1 while walking
    phase = 2 * np.pi * _GAIT_HZ * np.maximum(t - _STILL_S, 0.0)

    # ---------------------------------------------------------------- root trajectory (world)
    root_offset = rng.normal(0.0, 0.01, size=3)
    trans = np.zeros((n_frames, 3))
    trans[:, 1] = np.cumsum(_WALK_SPEED_MPS * ramp) * dt
    trans[:, 2] = _PELVIS_HEIGHT_M - root_offset[2] + 0.02 * ramp * np.sin(2 * phase)
    trans[:, :2] -= root_offset[:2]
    root_world = trans + root_offset

    # ------------------------------------------------------------------- sensor kinematics
    def orientation(amplitude: float) -> np.ndarray:
        base = rng.normal(0.0, 0.05, size=3)
        rotvec = base + amplitude * ramp[:, None] * _smooth(rng, t, 3)
        return Rotation.from_rotvec(rotvec).as_matrix()

    pos: dict[str, np.ndarray] = {}
    ori: dict[str, np.ndarray] = {}
    for part in IMU_PARTS:  # all parts, so the random stream does not depend on `parts`
        if part in FEET:
            side = _FOOT_SIDE[part]
            swing = np.maximum(-side * np.sin(phase), 0.0) * ramp  # 1 at mid-swing
            p = np.stack(
                [
                    root_world[:, 0] + side * 0.1,
                    root_world[:, 1] + 0.3 * ramp * np.sin(phase - side * np.pi / 2),
                    _ANKLE_HEIGHT_M + 0.1 * swing,
                ],
                axis=1,
            )
            ori[part] = orientation(0.25)
        else:
            p = root_world + np.asarray(_PART_OFFSET_M[part])
            p = p + 0.05 * ramp[:, None] * _smooth(rng, t, 3)
            ori[part] = orientation(0.4)
        pos[part] = p
    vel = {p: np.gradient(x, dt, axis=0) for p, x in pos.items()}
    acc = {p: np.gradient(v, dt, axis=0) for p, v in vel.items()}

    imu: dict[str, ImuStream] = {}
    imu_gt: dict[str, ImuGt] = {}
    for part in parts:
        r = ori[part]
        acc_raw = acc[part] + rng.normal(0.0, 0.05, size=(n_frames, 3))
        acc_local = gyr_local = None
        if part in FEET:
            acc_local = np.einsum("fji,fj->fi", r, acc_raw + _GRAVITY_WORLD)  # R^T (a + g)
            rel = Rotation.from_matrix(r[:-1]).inv() * Rotation.from_matrix(r[1:])
            gyr = rel.as_rotvec() * fps  # body-frame angular velocity, rad/s
            gyr_local = np.concatenate([gyr, gyr[-1:]], axis=0)
        imu[part] = ImuStream(
            acc_world_raw=acc_raw,
            acc_world_filt=uniform_filter1d(acc_raw, size=5, axis=0, mode="nearest"),
            ori_world=r,
            acc_local_raw=acc_local,
            gyr_local_raw=gyr_local,
        )
        imu_gt[part] = ImuGt(
            pos_world=pos[part], vel_world=vel[part], acc_world=acc[part], ori_world=r
        )

    # ------------------------------------------------------------------------------ insoles
    group_share = rng.dirichlet(np.full(N_INSOLE_CELLS, 4.0))  # within-group cell proportions
    back, mid = list(INSOLE_BACK_CELLS), list(range(4, 8))
    front = list(INSOLE_FRONT_CELLS)
    insole: dict[str, InsoleStream] = {}
    for foot in FEET:
        side = _FOOT_SIDE[foot]
        load = np.clip(0.5 + 0.8 * side * np.sin(phase) * ramp, 0.0, None)
        load = load * (1.0 + 0.1 * ramp * np.sin(2 * phase))
        load = load + rng.normal(0.0, 0.005, n_frames) * (load > 0)
        force = np.clip(load, 0.0, None)
        roll = 0.5 + 0.5 * ramp * np.cos(phase + (side < 0) * np.pi)  # 0 heel .. 1 toe
        w = np.empty((n_frames, N_INSOLE_CELLS))
        for cells, weight in (
            (back, 0.05 + 0.45 * (1 - roll)),
            (mid, np.full(n_frames, 0.15)),
            (front, 0.05 + 0.45 * roll),
        ):
            share = group_share[cells] / group_share[cells].sum()
            w[:, cells] = weight[:, None] * share
        w /= w.sum(axis=1, keepdims=True)
        forces = force[:, None] * w
        total = forces.sum(axis=1)  # equals `force` up to rounding
        loaded = total > 1e-9
        cop = np.where(
            loaded[:, None],
            (forces @ INSOLE_CELL_XY_M) / np.where(loaded, total, 1.0)[:, None],
            0.0,
        )
        foot_pos = pos[foot]
        medial = -side  # left foot (x < 0): medial is +x
        cop_world = np.stack(
            [foot_pos[:, 0] + medial * cop[:, 1], foot_pos[:, 1] + cop[:, 0], np.zeros(n_frames)],
            axis=1,
        )
        force_world = np.zeros((n_frames, 3))
        force_world[:, 2] = total
        insole[foot] = InsoleStream(
            contacts=contacts_from_cells(forces, CONTACT_THRESHOLD_BW),
            force=total[:, None],
            forces=forces,
            CoP=cop,
            force_world=force_world,
            CoP_world=cop_world,
        )
    fz = np.stack([insole[f].force[:, 0] for f in FEET], axis=1)  # (F, 2)
    fz_sum = fz.sum(axis=1, keepdims=True)
    cops = np.stack([insole[f].CoP_world for f in FEET], axis=1)  # (F, 2, 3)
    weights = np.where(fz_sum > 1e-9, fz / np.where(fz_sum > 1e-9, fz_sum, 1.0), 0.5)
    combined = InsoleCombined(
        force_world=sum(insole[f].force_world for f in FEET),  # type: ignore[arg-type]
        CoP_world=(weights[:, :, None] * cops).sum(axis=1),
    )

    # ------------------------------------------------------------------------- SMPL and rest
    poses = np.zeros((n_frames, 72), dtype=np.float32)
    poses[:, :3] = Rotation.from_matrix(ori["Pelvis"]).as_rotvec()
    poses[:, 3:] = 0.2 * ramp[:, None] * _smooth(rng, t, 69)
    betas = np.tile(rng.normal(0.0, 1.0, size=10), (n_frames, 1)).astype(np.float32)
    smpl = SmplParams(
        poses=poses, betas=betas, trans=trans, gender="neutral", root_offset=root_offset
    )
    floor = np.column_stack([rng.uniform(-3, 3, 150), rng.uniform(-1, 5, 150), np.zeros(150)])
    walls = rng.uniform([-3, -1, 0], [3, 5, 2.5], size=(50, 3))
    slam = Slam(points=np.concatenate([floor, walls]), head_traj=pos["Head"].copy())
    objects = None
    if with_objects:
        centroid = np.array([0.6, 1.5, 0.15]) + rng.normal(0.0, 0.05, 3) * np.array([1, 1, 0])
        objects = {"BoxSmall": box_object(centroid, np.array([0.4, 0.3, 0.3]))}

    gender = str(rng.choice(["female", "male"]))
    subject = SubjectInfo(
        subj_id=f"subj{seed % 1000:03d}",
        gender=gender,
        age=int(rng.integers(20, 60)),
        height_m=float(np.round(rng.uniform(1.55, 1.95), 3)),
        weight_kg=float(np.round(rng.uniform(50.0, 95.0), 1)),
        shoe_length=0.27,
        arm_length=float(np.round(rng.uniform(0.55, 0.7), 3)),
    )
    synth = {p: np.zeros(0, dtype=np.int64) for p in ("L_Wrist", "R_Wrist") if p in parts}
    data_info = DataInfo(
        take_id=f"take{seed % 1000:03d}",
        trial_name="synthetic_walk",
        insole_size="42",
        fps=fps,
        synth_imu_frames=synth,
    )
    extras = {"category": "walk", "source_clip": "synthetic", "noise_seed": seed}
    return Recording.from_streams(
        subject, data_info, imu, insole, combined, extras,
        smpl_params=smpl, imu_gt=imu_gt, slam=slam, objects=objects,
    )  # fmt: skip
