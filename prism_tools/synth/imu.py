"""IMU signals at the eight PRISM sites, synthesised from a motion on the body model.

Orientation = global rotation of the carrying segment (times an optional fixed mounting
offset); position = the mount point by forward kinematics; free acceleration (gravity removed,
world frame) = TransPose's smoothed second difference ``(x(t-n) + x(t+n) - 2 x(t)) / (n dt)^2``
with ``n = 1`` near the ends and zero at the first and last frame. The feet also get the insole
IMU's raw readings: the accelerometer's specific force ``R^T (a + (0, 0, g))`` and the
gyroscope's body-frame angular velocity, both in the sensor frame.

Shapes: ``T`` frames, ``S`` sensors (in :data:`grip.core.skeleton.IMU_PARTS` order); world frame
z-up, metres, seconds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from grip.core import skeleton as sk
from grip.core.body import GRAVITY, BodyModel
from grip.core.fk import body_points
from grip.core.rotations import angular_velocity, axis_angle_to_matrix
from prism_tools.synth.config import ImuSynthConfig, NoiseConfig
from prism_tools.synth.noise import corrupt_imu

__all__ = [
    "ImuKinematics",
    "ImuReadings",
    "central_velocity",
    "lowpass_causal",
    "measure_imu",
    "resolve_acc_smoothing_frames",
    "second_difference",
    "synthesize_imu",
]

_G_UP = np.array([0.0, 0.0, GRAVITY])


def resolve_acc_smoothing_frames(cfg: ImuSynthConfig, fps: float) -> int:
    """The frame spacing ``n`` of the smoothed second difference at ``fps``.

    Returns:
        ``cfg.acc_smoothing_frames``, or ``max(1, round(cfg.acc_smoothing_s * fps))`` for
        ``"auto"`` (7 at 100 Hz, 4 at 60 Hz).
    """
    if cfg.acc_smoothing_frames == "auto":
        return max(1, round(cfg.acc_smoothing_s * fps))
    return int(cfg.acc_smoothing_frames)


def second_difference(x: np.ndarray, fps: float, n: int = 1) -> np.ndarray:
    """TransPose's smoothed second derivative along axis 0.

    ``a(t) = (x(t-n) + x(t+n) - 2 x(t)) / (n dt)^2`` for ``n <= t < T - n``; the plain second
    difference (``n = 1``) for the remaining interior frames; zero at the first and last frame.

    Args:
        x: ``(T, ...)`` positions sampled at ``fps``.
        fps: Frame rate, Hz.
        n: Frame spacing, >= 1.

    Returns:
        ``(T, ...)`` second derivative, units of ``x`` per s^2.
    """
    x = np.asarray(x, dtype=np.float64)
    a = np.zeros_like(x)
    t = x.shape[0]
    if t < 3:
        return a
    a[1:-1] = (x[:-2] + x[2:] - 2.0 * x[1:-1]) * fps**2
    if n > 1 and t > 2 * n:
        a[n:-n] = (x[: -2 * n] + x[2 * n :] - 2.0 * x[n:-n]) * (fps / n) ** 2
    return a


def central_velocity(x: np.ndarray, fps: float) -> np.ndarray:
    """First derivative along axis 0 by central differences (one-sided at the ends).

    Args:
        x: ``(T, ...)`` samples at ``fps``.
        fps: Frame rate, Hz.

    Returns:
        ``(T, ...)``, units of ``x`` per s (zeros when ``T == 1``).
    """
    x = np.asarray(x, dtype=np.float64)
    if x.shape[0] < 2:
        return np.zeros_like(x)
    return np.gradient(x, 1.0 / fps, axis=0)


def lowpass_causal(x: np.ndarray, fps: float, cutoff_hz: float, order: int = 2) -> np.ndarray:
    """Causal Butterworth low-pass along axis 0 (what a device filters in real time).

    The filter state starts at steady state for the first sample, so a constant signal passes
    unchanged and there is no start-up transient.

    Args:
        x: ``(T, ...)`` samples at ``fps``.
        fps: Frame rate, Hz.
        cutoff_hz: -3 dB cut-off, Hz; at or above Nyquist the input is returned (copied).
        order: Filter order.

    Returns:
        ``(T, ...)`` filtered copy.
    """
    x = np.asarray(x, dtype=np.float64)
    wn = cutoff_hz / (0.5 * fps)
    if wn >= 1.0 or x.shape[0] == 0:
        return x.copy()
    b, a = signal.butter(order, wn)
    zi = signal.lfilter_zi(b, a).reshape(-1, *([1] * (x.ndim - 1))) * x[:1]
    y, _ = signal.lfilter(b, a, x, axis=0, zi=zi)
    return y


@dataclass(frozen=True)
class ImuKinematics:
    """Clean (noise-free) IMU signals and their ground truth.

    Attributes:
        parts: ``S`` part names, :data:`grip.core.skeleton.IMU_PARTS` order.
        pos_world: ``(T, S, 3)`` sensor position, world frame, m.
        vel_world: ``(T, S, 3)`` sensor velocity by central differences, world frame, m/s.
        ori_world: ``(T, S, 3, 3)`` sensor orientation, sensor -> world.
        acc_world: ``(T, S, 3)`` free acceleration with TransPose's n-frame smoothing, world
            frame, m/s^2 (what the synthetic device reports).
        acc_world_gt: ``(T, S, 3)`` plain second difference (n = 1), world frame, m/s^2.
        acc_local: ``(T, S, 3)`` specific force ``R^T (acc_world + (0, 0, g))``, sensor frame,
            m/s^2 (an accelerometer's reading).
        gyr_local: ``(T, S, 3)`` angular velocity, sensor frame, rad/s.
        acc_smoothing_frames: The ``n`` used for ``acc_world``.
    """

    parts: tuple[str, ...]
    pos_world: np.ndarray
    vel_world: np.ndarray
    ori_world: np.ndarray
    acc_world: np.ndarray
    acc_world_gt: np.ndarray
    acc_local: np.ndarray
    gyr_local: np.ndarray
    acc_smoothing_frames: int


def _mount_offsets(cfg: ImuSynthConfig, parts: tuple[str, ...]) -> np.ndarray | None:
    """``(S, 3, 3)`` mounting rotations, or None when all are the identity."""
    given = dict(cfg.mount_offsets_rotvec_rad)
    unknown = set(given) - set(parts)
    if unknown:
        raise ValueError(f"mount_offsets_rotvec_rad: unknown part(s) {sorted(unknown)}")
    if not given:
        return None
    rv = np.array([given.get(p, (0.0, 0.0, 0.0)) for p in parts], dtype=np.float64)
    return axis_angle_to_matrix(rv)


def synthesize_imu(
    global_rot: np.ndarray,
    joint_pos: np.ndarray,
    body: BodyModel,
    fps: float,
    cfg: ImuSynthConfig | None = None,
    parts: tuple[str, ...] = sk.IMU_PARTS,
) -> ImuKinematics:
    """Clean IMU signals at the PRISM mount points.

    Args:
        global_rot: ``(T, 24, 3, 3)`` global segment rotations from forward kinematics.
        joint_pos: ``(T, 24, 3)`` joint positions, world frame (z up, floor z = 0), m.
        body: The body model (IMU sites ``body.imu_sites``).
        fps: Frame rate, Hz.
        cfg: IMU synthesis configuration (default :class:`ImuSynthConfig`).
        parts: Sensors to synthesise, a subset of :data:`grip.core.skeleton.IMU_PARTS`.

    Returns:
        The clean signals and ground truth of every sensor.
    """
    cfg = cfg or ImuSynthConfig()
    bodies = np.array([body.imu_sites[p][0] for p in parts], dtype=np.int64)
    local = np.stack([body.imu_sites[p][1] for p in parts])
    pos = body_points(global_rot, joint_pos, bodies, local)
    ori = global_rot[:, bodies]
    offsets = _mount_offsets(cfg, parts)
    if offsets is not None:
        ori = ori @ offsets
    n = resolve_acc_smoothing_frames(cfg, fps)
    acc = second_difference(pos, fps, n)
    acc_local = np.einsum("tsji,tsj->tsi", ori, acc + _G_UP)
    return ImuKinematics(
        parts=tuple(parts),
        pos_world=pos,
        vel_world=central_velocity(pos, fps),
        ori_world=np.ascontiguousarray(ori),
        acc_world=acc,
        acc_world_gt=second_difference(pos, fps, 1),
        acc_local=acc_local,
        gyr_local=angular_velocity(ori, fps, local=True),
        acc_smoothing_frames=n,
    )


@dataclass(frozen=True)
class ImuReadings:
    """What the IMUs report (after the noise model and the device's low-pass filter).

    Attributes:
        parts: ``S`` part names.
        acc_world_raw: ``(T, S, 3)`` free acceleration, world frame, m/s^2.
        acc_world_filt: ``(T, S, 3)`` the same through the causal low-pass, m/s^2.
        ori_world: ``(T, S, 3, 3)`` orientation estimate, sensor -> world.
        acc_local_raw: ``(T, S, 3)`` accelerometer reading (specific force), sensor frame, m/s^2.
        gyr_local_raw: ``(T, S, 3)`` gyroscope reading, sensor frame, rad/s.
        dropped: part -> ``(K,)`` int64 indices of the frames whose sample was dropped (the
            logger repeated the previous sample).
    """

    parts: tuple[str, ...]
    acc_world_raw: np.ndarray
    acc_world_filt: np.ndarray
    ori_world: np.ndarray
    acc_local_raw: np.ndarray
    gyr_local_raw: np.ndarray
    dropped: dict[str, np.ndarray]


def measure_imu(
    kin: ImuKinematics,
    fps: float,
    cfg: ImuSynthConfig | None = None,
    noise: NoiseConfig | None = None,
    rng: np.random.Generator | None = None,
) -> ImuReadings:
    """Device readings from clean IMU signals: noise model, then the causal low-pass.

    Args:
        kin: Clean signals from :func:`synthesize_imu`.
        fps: Frame rate, Hz.
        cfg: IMU configuration (filter settings).
        noise: Noise configuration; None means :meth:`NoiseConfig.off`.
        rng: Random generator; required unless the noise is off.

    Returns:
        The readings; with the noise off they equal ``kin`` exactly (and ``acc_world_filt`` is
        the filtered ``acc_world``).
    """
    cfg = cfg or ImuSynthConfig()
    noise = noise or NoiseConfig.off()
    if rng is None:
        if not noise.is_off:
            raise ValueError("measure_imu: a random generator is required when noise is on")
        rng = np.random.default_rng(0)  # never drawn from: every noise term is zero
    noisy = corrupt_imu(kin.acc_world, kin.ori_world, kin.acc_local, kin.gyr_local, fps, noise, rng)
    return ImuReadings(
        parts=kin.parts,
        acc_world_raw=noisy.acc_world,
        acc_world_filt=lowpass_causal(noisy.acc_world, fps, cfg.filt_cutoff_hz, cfg.filt_order),
        ori_world=noisy.ori_world,
        acc_local_raw=noisy.acc_local,
        gyr_local_raw=noisy.gyr_local,
        dropped={
            p: np.flatnonzero(noisy.dropped[:, i]).astype(np.int64) for i, p in enumerate(kin.parts)
        },
    )
