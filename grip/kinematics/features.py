"""Per-frame network inputs and targets from PRISM-format recordings (numpy only).

Inputs follow GRIP's description (PRISM_FORMAT.md, "What GRIP feeds its networks"): for every
configured IMU site, in the order given, the world-frame free acceleration (3), the angular
velocity from finite differences of the orientation x fps (3, world frame; gyroscopes unused)
and the orientation matrix (9); then, optionally, per foot [force, CoP x, CoP y, contact front,
contact back] (10). Unlike GRIP, sites that are not configured are left out rather than zeroed, so
each sensor configuration gets an input of its own size.

Targets are in GRIP's frame: joint positions relative to the root (pelvis) joint but keeping the
body's global rotation (no pelvis IMU exists to remove it), global joint rotations as 6D, and
world-frame velocities of the leaf joints and the pelvis.

The same inputs one frame at a time, as a live system delivers them:
:mod:`grip.kinematics.feature_stream`.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from grip.core import skeleton as sk
from grip.core.body import BodyParams, build_body
from grip.core.fk import forward_kinematics
from grip.core.reconstruction import PoseTrack
from grip.core.rotations import (
    angular_velocity,
    axis_angle_to_matrix,
    matrix_to_6d,
)

DEFAULT_SITES: tuple[str, ...] = ("L_Foot", "R_Foot", "L_Wrist", "R_Wrist")
"""GRIP's 4 wearables, in its channel order."""


TTA_MODES: dict[str, tuple[int, bool]] = {
    "none": (1, False), "mirror": (1, True), "yaw4": (4, False), "full": (4, True),
}  # fmt: skip
"""Test-time augmentation: the number of yaw angles (evenly spaced about the vertical) and
whether the left-right mirror image is added; ``full`` runs 8 copies."""


@dataclass(frozen=True)
class FeatureConfig:
    """Which sensors feed the networks, and how.

    Attributes:
        sites: IMU sites in channel order (any subset of the 8 PRISM parts).
        insoles: Append the 10 insole values.
        use_filtered_acc: Use ``acc_world_filt`` (the recording's causal low-pass) rather than
            ``acc_world_raw``.
        acc_scale: Accelerations are divided by this (m/s^2) to bring them near unit scale.
        align_first_frame: Re-align each IMU's orientation to the ground-truth segment
            orientation at the sequence's first frame (GRIP's calibration; at inference the
            calibration pose plays the role of the ground truth).
    """

    sites: tuple[str, ...] = DEFAULT_SITES
    insoles: bool = True
    use_filtered_acc: bool = True
    acc_scale: float = 30.0
    align_first_frame: bool = True

    def __post_init__(self) -> None:
        unknown = [s for s in self.sites if s not in sk.IMU_PARTS]
        if unknown or not self.sites:
            raise ValueError(f"FeatureConfig.sites: unknown or empty {unknown or self.sites}; "
                             f"choose from {sk.IMU_PARTS}")  # fmt: skip
        if len(set(self.sites)) != len(self.sites):
            raise ValueError(f"FeatureConfig.sites has duplicates: {self.sites}")

    @property
    def n_features(self) -> int:
        return 15 * len(self.sites) + (10 if self.insoles else 0)


def imu_orientations(rec, cfg: FeatureConfig) -> np.ndarray:
    """``(T, S, 3, 3)`` IMU orientations, re-aligned at frame 0 when configured.

    Raises:
        KeyError: naming the missing site when the recording lacks a configured IMU.
    """
    rots = []
    for site in cfg.sites:
        if site not in rec.imu:
            raise KeyError(f"recording {rec.name}: no IMU at site {site!r} "
                           f"(has {sorted(rec.imu)})")  # fmt: skip
        r = np.asarray(rec.imu[site].ori_world, dtype=np.float64)
        if cfg.align_first_frame and site in rec.imu_gt:
            gt0 = np.asarray(rec.imu_gt[site].ori_world[0], dtype=np.float64)
            r = r @ (r[0].T @ gt0)  # constant sensor-to-segment offset from the first frame
        rots.append(r)
    return np.stack(rots, axis=1)


def input_features(rec, cfg: FeatureConfig = FeatureConfig()) -> np.ndarray:
    """``(T, F)`` float32 network inputs of one recording, ``F = cfg.n_features``."""
    rot = imu_orientations(rec, cfg)
    t = rot.shape[0]
    key = "acc_world_filt" if cfg.use_filtered_acc else "acc_world_raw"
    acc = np.stack([np.asarray(getattr(rec.imu[s], key), dtype=np.float64) for s in cfg.sites],
                   axis=1) / cfg.acc_scale  # fmt: skip
    gyr = angular_velocity(rot, float(rec.fps))
    parts = [acc, gyr, rot.reshape(t, len(cfg.sites), 9)]
    feats = np.concatenate(parts, axis=-1).reshape(t, -1)
    if cfg.insoles:
        feats = np.concatenate([feats, insole_features(rec)], axis=-1)
    if not np.all(np.isfinite(feats)):
        bad = int(np.argwhere(~np.isfinite(feats))[0][0])
        raise ValueError(f"recording {rec.name}: non-finite sensor values (first at frame {bad})")
    return feats.astype(np.float32)


@dataclass(frozen=True, eq=False)
class SensorFrame:
    """One frame of the wearables as a live system delivers it (the streaming input).

    Attributes:
        acc: ``(S, 3)`` world-frame free acceleration of the configured sites, in
            :attr:`FeatureConfig.sites` order, m/s^2 (the low-pass filtered stream when
            :attr:`FeatureConfig.use_filtered_acc`, as in the recordings).
        ori: ``(S, 3, 3)`` sensor orientations, sensor -> world.
        insole: ``(10,)`` per foot (left, right) ``[force (body weights), CoP x, CoP y (m),
            front contact, back contact]``, or ``None`` when the features have no insoles.
    """

    acc: np.ndarray
    ori: np.ndarray
    insole: np.ndarray | None = None


def site_arrays(rec, cfg: FeatureConfig = FeatureConfig()) -> tuple[np.ndarray, np.ndarray]:
    """A recording's IMUs at the configured sites, float64: ``acc (T, S, 3)`` world-frame free
    acceleration (filtered or raw as :attr:`FeatureConfig.use_filtered_acc`), m/s^2, and
    ``ori (T, S, 3, 3)`` sensor -> world.

    Raises:
        KeyError: naming the missing site.
    """
    for site in cfg.sites:
        if site not in rec.imu:
            raise KeyError(f"recording {rec.name}: no IMU at site {site!r} "
                           f"(has {sorted(rec.imu)})")  # fmt: skip
    key = "acc_world_filt" if cfg.use_filtered_acc else "acc_world_raw"
    acc = np.stack([np.asarray(getattr(rec.imu[s], key), dtype=np.float64) for s in cfg.sites],
                   axis=1)  # fmt: skip
    ori = np.stack([np.asarray(rec.imu[s].ori_world, dtype=np.float64) for s in cfg.sites],
                   axis=1)  # fmt: skip
    return acc, ori


def sensor_frames(rec, cfg: FeatureConfig = FeatureConfig()) -> Iterator[SensorFrame]:
    """The frames of a recording one at a time, as
    :class:`grip.kinematics.feature_stream.FeatureStream` takes them.

    Raises:
        KeyError: naming the missing site or foot.
    """
    acc, ori = site_arrays(rec, cfg)
    ins = insole_features(rec) if cfg.insoles else None
    for t in range(acc.shape[0]):
        yield SensorFrame(acc[t], ori[t], None if ins is None else ins[t])


@dataclass(frozen=True, eq=False)
class Calibration:
    """What a recording's first frames tell the pipeline beyond its sensors: the pose the subject
    stands in (the humanoid and KinematicsNet's LSTMs start from it) and the sensor-to-segment
    alignment (:attr:`FeatureConfig.align_first_frame`).

    Attributes:
        local_rot: ``(2, 24, 3, 3)`` local joint rotations of the first two frames (row 0 = the
            root's world rotation; frame 1 gives the start velocity).
        root_pos: ``(2, 3)`` pelvis positions of the same frames, world, m.
        imu_ori: ``(S, 3, 3)`` segment orientations of the sensor sites at frame 0 (NaN for a
            site without one: not re-aligned), or ``None`` when alignment is off.
        measured: The pose is the recording's ground truth (``False``: the standing
            calibration, assumed without motion capture).
    """

    local_rot: np.ndarray
    root_pos: np.ndarray
    imu_ori: np.ndarray | None = None
    measured: bool = True


@dataclass(frozen=True, eq=False)
class SensorStream:
    """A recording's sensors as the pipeline reads them (no ground truth), for the sites of one
    :class:`FeatureConfig`.

    Attributes (T frames at ``fps``):
        name, category: Recording name and category.
        fps: Frame rate, Hz.
        body: The subject (height, mass).
        objects: Scene meshes ``{name: (vertices (V, 3), faces (F, 3))}`` or ``None``.
        acc: ``(T, S, 3)`` world-frame free accelerations of the sites (filtered or raw as
            :attr:`FeatureConfig.use_filtered_acc`), m/s^2.
        ori: ``(T, S, 3, 3)`` sensor orientations, sensor -> world.
        insole: ``(T, 10)`` insole values (:func:`insole_features`) or ``None``.
        calibration: The calibration pose and orientations.
    """

    name: str
    category: str
    fps: float
    body: BodyParams
    objects: dict | None
    acc: np.ndarray
    ori: np.ndarray
    insole: np.ndarray | None
    calibration: Calibration

    @property
    def n_frames(self) -> int:
        return int(self.acc.shape[0])

    def frames(self) -> Iterator[SensorFrame]:
        """The frames one at a time, as :class:`grip.kinematics.feature_stream.FeatureStream`
        takes them."""
        ins = self.insole
        for t in range(self.n_frames):
            yield SensorFrame(self.acc[t], self.ori[t], None if ins is None else ins[t])


INITS: tuple[str, ...] = ("truth", "standing")
"""How an estimate starts (``--init``): from the ground truth of the first frame, as GRIP
evaluates, or from the standing pose at the sensors' heading, as a user without motion capture
must (:func:`standing_calibration`)."""


def recording_calibration(rec, cfg: FeatureConfig = FeatureConfig(),
                          init: str = "truth") -> Calibration:  # fmt: skip
    """The :class:`Calibration` of a recording: its ground-truth pose of frames 0 and 1
    (``smpl_params``; frame 0 twice for a one-frame recording) and
    :func:`calibration_orientations`; without ground truth, or with ``init="standing"``,
    :func:`standing_calibration`.

    Raises:
        ValueError: ``init`` is not one of :data:`INITS`.
    """
    if init not in INITS:
        raise ValueError(f"init must be one of {list(INITS)}, got {init!r}")
    if rec.smpl_params is None or init == "standing":
        return standing_calibration(rec, cfg)
    n = min(rec.n_frames, 2)
    sp = rec.smpl_params
    poses = np.asarray(sp.poses, dtype=np.float64)[:n].reshape(-1, sk.N_JOINTS, 3)
    local = axis_angle_to_matrix(poses)
    root = (np.asarray(sp.trans, dtype=np.float64)[:n]
            + np.asarray(sp.root_offset, dtype=np.float64))  # fmt: skip
    if n == 1:
        local, root = np.repeat(local, 2, axis=0), np.repeat(root, 2, axis=0)
    return Calibration(local, root, calibration_orientations(rec, cfg))


HEADING_SITES: tuple[str, ...] = ("L_Foot", "R_Foot")
"""IMU sites whose frame-0 orientation gives the heading of a recording without ground truth
(the feet stand flat in GRIP's calibration; other sites are used when neither foot has one)."""


def sensor_heading(ori0: np.ndarray) -> float:
    """Heading of a subject standing in the rest pose, from sensor orientations.

    In the standing rest pose facing world +y (:func:`grip.core.mjcf.standing_qpos`) every
    segment's forward axis (canonical z) points along +y; a sensor aligned with its segment
    (PRISM's calibrated ``ori_world``) turned by ``psi`` about the vertical points it along
    ``(-sin psi, cos psi)``. The headings of the given sensors are averaged on the circle.

    Args:
        ori0: ``(S, 3, 3)`` sensor orientations at the calibration frame, sensor -> world.

    Returns:
        ``psi``, rad, counter-clockwise about world z from facing +y.
    """
    fwd = np.asarray(ori0, dtype=np.float64)[:, :, 2]  # (S, 3) canonical z in the world
    psi = np.arctan2(-fwd[:, 0], fwd[:, 1])
    return float(np.arctan2(np.sin(psi).mean(), np.cos(psi).mean()))


def standing_calibration(rec, cfg: FeatureConfig = FeatureConfig()) -> Calibration:
    """The :class:`Calibration` of a recording without ground truth: GRIP's calibration pose,
    the subject standing still in the rest T-pose (:func:`grip.core.mjcf.standing_qpos`, pelvis
    above the origin) turned to the heading of the foot IMUs at frame 0 (:data:`HEADING_SITES`,
    :func:`sensor_heading`), at rest (frames 0 and 1 the same pose);
    :func:`calibration_orientations` as with ground truth (NaN without ``imu_gt``: the recorded
    orientations are used as they are, already aligned with their segments as PRISM's are).

    Gauge: on a recording that has ground truth (``smpl_params``, evaluated with
    ``init="standing"``) the pelvis stands at the ground truth's horizontal position of frame 0
    (its height stays the standing pose's, its heading the foot IMUs'). Without motion capture
    the place on the floor is a free choice that carries no information about the pose; putting
    it there gives the estimate and the truth a common origin, so that world trajectories
    compare (root translation errors, ``root_err_m``) between the two starts. A recording
    without ground truth keeps the origin."""
    from grip.core.mjcf import standing_qpos
    from grip.core.reference import local_rot_from_qpos

    sites = [s for s in HEADING_SITES if s in rec.imu] or [s for s in cfg.sites if s in rec.imu]
    psi = sensor_heading(np.stack([rec.imu[s].ori_world[0] for s in sites])) if sites else 0.0
    c, s = np.cos(psi), np.sin(psi)
    yaw = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    q = standing_qpos(recording_body(rec))
    local = local_rot_from_qpos(q[None])[0]
    local[0] = yaw @ local[0]
    root = yaw @ q[:3]
    if rec.smpl_params is not None:  # the gauge: the truth's place on the floor
        sp = rec.smpl_params
        root[:2] = (np.asarray(sp.trans, dtype=np.float64)[0]
                    + np.asarray(sp.root_offset, dtype=np.float64))[:2]  # fmt: skip
    return Calibration(np.repeat(local[None], 2, axis=0), np.repeat(root[None], 2, axis=0),
                       calibration_orientations(rec, cfg), measured=False)  # fmt: skip


def sensor_stream(rec, cfg: FeatureConfig = FeatureConfig(), init: str = "truth") -> SensorStream:
    """The :class:`SensorStream` of a PRISM-format recording (its ground truth, when it has
    one, is only read for the calibration, :func:`recording_calibration` with ``init``).

    Raises:
        KeyError: naming a missing site or foot.
    """
    acc, ori = site_arrays(rec, cfg)
    objects = None
    if rec.objects:
        objects = {n: (np.asarray(o.vertices), np.asarray(o.faces)) for n, o in rec.objects.items()}
    return SensorStream(str(rec.name), rec.category or "unknown", float(rec.fps),
                        recording_body(rec), objects, acc, ori,
                        insole_features(rec) if cfg.insoles else None,
                        recording_calibration(rec, cfg, init))  # fmt: skip


def stream_features(stream: SensorStream, cfg: FeatureConfig = FeatureConfig()) -> np.ndarray:
    """``(T, F)`` float32 network inputs of a :class:`SensorStream`: :func:`input_features`
    (the same values) without the recording."""
    calib = stream.calibration.imu_ori
    rots = []
    for i in range(len(cfg.sites)):
        r = stream.ori[:, i]
        if cfg.align_first_frame and calib is not None and np.isfinite(calib[i]).all():
            r = r @ (r[0].T @ calib[i])  # constant sensor-to-segment offset from the first frame
        rots.append(r)
    rot = np.stack(rots, axis=1)
    t = rot.shape[0]
    gyr = angular_velocity(rot, stream.fps)
    feats = np.concatenate([stream.acc / cfg.acc_scale, gyr, rot.reshape(t, len(cfg.sites), 9)],
                           axis=-1).reshape(t, -1)  # fmt: skip
    if cfg.insoles:
        feats = np.concatenate([feats, stream.insole], axis=-1)
    if not np.all(np.isfinite(feats)):
        bad = int(np.argwhere(~np.isfinite(feats))[0][0])
        raise ValueError(f"recording {stream.name}: non-finite sensor values (first at frame "
                         f"{bad})")  # fmt: skip
    return feats.astype(np.float32)


def first_state(calibration: Calibration, body: BodyParams,
                fps: float) -> dict[str, np.ndarray]:  # fmt: skip
    """KinematicsNet's first-frame states of the calibration pose (``{"lp", "fp", "fa", "lv"}``,
    flat float32): what :meth:`grip.kinematics.inference.KinematicsEstimator.predict` starts its
    LSTMs from. The velocities are the calibration's frame 0 to frame 1 at ``fps`` (Hz), as
    :class:`Targets` gives a training window's first frame: the truth's when the recording
    starts in motion, zero for a standing calibration (its two frames are the same pose)."""
    g_rot, pos = forward_kinematics(calibration.local_rot, calibration.root_pos,
                                    build_body(body).offsets)  # fmt: skip
    rel = pos - pos[:, :1]
    vel = np.gradient(pos[:, list(sk.VELOCITY_JOINTS)], axis=0) * float(fps)
    out = {"lp": rel[0, list(sk.LEAF_JOINTS)], "fp": rel[0], "fa": matrix_to_6d(g_rot)[0],
           "lv": vel[0]}  # fmt: skip
    return {k: v.reshape(-1).astype(np.float32) for k, v in out.items()}


def calibration_orientations(rec, cfg: FeatureConfig = FeatureConfig()) -> np.ndarray | None:
    """``(S, 3, 3)`` ground-truth sensor orientations at the recording's first frame (the
    calibration pose, :attr:`FeatureConfig.align_first_frame`), NaN for sites without
    ground truth; ``None`` when alignment is off."""
    if not cfg.align_first_frame:
        return None
    out = np.full((len(cfg.sites), 3, 3), np.nan)
    for i, site in enumerate(cfg.sites):
        if site in rec.imu_gt:
            out[i] = np.asarray(rec.imu_gt[site].ori_world[0], dtype=np.float64)
    return out


def insole_features(rec) -> np.ndarray:
    """``(T, 10)``: per foot (L, R) ``[force (body weights), CoP x, CoP y (m), front, back]``."""
    cols = []
    for foot in sk.FEET:
        if foot not in rec.insole:
            raise KeyError(f"recording {rec.name}: no insole for {foot!r}")
        ins = rec.insole[foot]
        cols += [np.asarray(ins.force, dtype=np.float64).reshape(-1, 1),
                 np.asarray(ins.CoP, dtype=np.float64),
                 np.asarray(ins.contacts, dtype=np.float64)]  # fmt: skip
    return np.concatenate(cols, axis=-1)


@dataclass(frozen=True)
class Targets:
    """Ground truth of one recording in GRIP's frame.

    Attributes:
        leaf_pos: ``(T, 5, 3)`` leaf joints (wrists, ankles, head) minus the root, world axes, m.
        joint_pos: ``(T, 24, 3)`` all joints minus the root, world axes, m.
        rot6d: ``(T, 24, 6)`` global joint rotations, 6D.
        velocity: ``(T, 6, 3)`` world velocities of the leaves and the pelvis, m/s.
        root_pos: ``(T, 3)`` pelvis position, world, m (for translation metrics).
        global_rot: ``(T, 24, 3, 3)``.
    """

    leaf_pos: np.ndarray
    joint_pos: np.ndarray
    rot6d: np.ndarray
    velocity: np.ndarray
    root_pos: np.ndarray
    global_rot: np.ndarray


def recording_body(rec) -> BodyParams:
    """Body parameters of a recording's subject (defaults where the recording is silent)."""
    h = rec.subject.height_m or 1.70
    m = rec.subject.weight_kg or 70.0
    return BodyParams(height_m=float(h), mass_kg=float(m))


def targets(rec) -> Targets:
    """Ground-truth targets from ``smpl_params`` on the subject's body model.

    Raises:
        prism_tools.RecordingError: The recording has no ground truth (naming its file).
    """
    sp = rec.require_ground_truth("training and evaluation (the ground-truth targets)")
    local = axis_angle_to_matrix(np.asarray(sp.poses, dtype=np.float64).reshape(-1, 24, 3))
    root = np.asarray(sp.trans, dtype=np.float64) + np.asarray(sp.root_offset, dtype=np.float64)
    body = build_body(recording_body(rec))
    g_rot, pos = forward_kinematics(local, root, body.offsets)
    rel = pos - pos[:, :1]
    vel = np.gradient(pos[:, list(sk.VELOCITY_JOINTS)], axis=0) * float(rec.fps)
    return Targets(
        leaf_pos=rel[:, list(sk.LEAF_JOINTS)],
        joint_pos=rel,
        rot6d=matrix_to_6d(g_rot),
        velocity=vel,
        root_pos=pos[:, 0],
        global_rot=g_rot,
    )


@dataclass(frozen=True, eq=False)
class GroundTruth(PoseTrack):
    """Ground truth of one recording in the world frame, on the subject's body model: what
    every evaluation (``grip bench``, ``grip policy eval``, the exports' summary) compares with.

    Attributes:
        name: Recording name.
        fps: Frame rate, Hz.
        body: The subject's parameters (:func:`recording_body`).
        joint_pos: ``(T, 24, 3)`` world joint positions, m.
        global_rot: ``(T, 24, 3, 3)`` world joint rotations.
        insole_force_n: ``(T, 2)`` vertical insole force of the left, right foot, N (stored in
            body weights, scaled by ``mass_kg * g``), or ``None`` without both insoles.
        insole_contacts: ``(T, 2)`` bool insole contact (front or back) per foot, or ``None``.
    """

    name: str
    fps: float
    body: BodyParams
    joint_pos: np.ndarray
    global_rot: np.ndarray
    insole_force_n: np.ndarray | None = None
    insole_contacts: np.ndarray | None = None

    @property
    def foot_contacts(self) -> np.ndarray:
        """``(T, 2)`` bool foot contacts for foot sliding: the insoles' where both exist, else
        :func:`grip.core.metrics.contacts_from_motion` of the true foot joints (TransPose's
        rule)."""
        if self.insole_contacts is not None:
            return self.insole_contacts
        from grip.core.metrics import contacts_from_motion

        return contacts_from_motion(self.joint_pos[:, list(sk.FOOT_JOINTS)], self.fps)

    def head(self, n: int) -> GroundTruth:
        """The first ``n`` frames."""
        cut = lambda a: None if a is None else a[:n]  # noqa: E731
        return GroundTruth(self.name, self.fps, self.body, self.joint_pos[:n],
                           self.global_rot[:n], cut(self.insole_force_n),
                           cut(self.insole_contacts))  # fmt: skip


def ground_truth(rec) -> GroundTruth:
    """The :class:`GroundTruth` of a PRISM-format recording: ``smpl_params`` posed on the
    subject's body (:func:`targets`: root-relative joints plus the pelvis at
    ``trans + root_offset``) and its insoles.

    Raises:
        prism_tools.RecordingError: The recording has no ground truth (naming its file).
    """
    from grip.core.body import GRAVITY

    rec.require_ground_truth("a comparison with the ground truth (metrics, bench, --gt)")
    tg = targets(rec)
    body = recording_body(rec)
    force = contacts = None
    if all(f in rec.insole for f in sk.FEET):
        force = np.stack([np.asarray(rec.insole[f].force, dtype=np.float64)[:, 0]
                          for f in sk.FEET], axis=1) * (body.mass_kg * GRAVITY)  # fmt: skip
        contacts = np.stack([np.asarray(rec.insole[f].contacts, dtype=bool).any(axis=1)
                             for f in sk.FEET], axis=1)  # fmt: skip
    return GroundTruth(str(rec.name), float(rec.fps), body, tg.joint_pos + tg.root_pos[:, None],
                       tg.global_rot, force, contacts)  # fmt: skip
