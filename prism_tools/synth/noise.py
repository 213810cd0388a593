"""Seeded sensor noise: IMU white noise, bias, orientation drift, dropped samples; insole noise.

Every function takes the random generator explicitly (``np.random.Generator``), never mutates
its inputs, and draws nothing for a noise term whose magnitude is zero, so
:meth:`~prism_tools.synth.config.NoiseConfig.off` reproduces the clean signals bit for bit.

Shapes: ``T`` frames, ``S`` sensors; world frame z-up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grip.core.body import GRAVITY
from grip.core.rotations import axis_angle_to_matrix
from prism_tools.synth.config import NoiseConfig

__all__ = [
    "NoisyImu",
    "apply_drops",
    "corrupt_imu",
    "corrupt_insole_cells",
    "drop_mask",
    "held_index",
    "orientation_error",
]

_G_UP = np.array([0.0, 0.0, GRAVITY])


def drop_mask(n_frames: int, n_streams: int, prob: float, rng: np.random.Generator) -> np.ndarray:
    """Which samples a logger drops.

    Args:
        n_frames: ``T``.
        n_streams: Number of independent streams (sensors).
        prob: Drop probability per frame and stream, in ``[0, 1)``.
        rng: Random generator.

    Returns:
        ``(T, n_streams)`` bool, True where the sample is dropped; frame 0 is never dropped
        (there is no previous sample to repeat). All False without drawing when ``prob == 0``.
    """
    mask = np.zeros((n_frames, n_streams), dtype=bool)
    if prob > 0 and n_frames > 1:
        mask[1:] = rng.random((n_frames - 1, n_streams)) < prob
    return mask


def held_index(dropped: np.ndarray) -> np.ndarray:
    """Index of the sample a logger actually outputs at each frame (the last one not dropped).

    Args:
        dropped: ``(T, S)`` bool from :func:`drop_mask` (``dropped[0]`` must be False).

    Returns:
        ``(T, S)`` int64 frame indices.
    """
    t = np.arange(dropped.shape[0])[:, None]
    return np.maximum.accumulate(np.where(dropped, 0, t), axis=0)


def apply_drops(x: np.ndarray, dropped: np.ndarray) -> np.ndarray:
    """Repeat the previous sample wherever one is dropped.

    Args:
        x: ``(T, S, ...)`` per-frame, per-stream values.
        dropped: ``(T, S)`` bool.

    Returns:
        A new ``(T, S, ...)`` array (a copy even when nothing is dropped).
    """
    if not dropped.any():
        return np.array(x, copy=True)
    src = held_index(dropped)
    return x[src, np.arange(x.shape[1])[None, :]]


def orientation_error(
    n_frames: int, n_sensors: int, fps: float, cfg: NoiseConfig, rng: np.random.Generator
) -> np.ndarray | None:
    """Error rotation of the sensors' orientation estimates, world frame.

    A random walk (drift) about the world axes, composed by summing the rotation-vector
    increments (exact for yaw-only drift; second-order error in the tilt angle otherwise, which
    is negligible at drift rates of a few degrees), then a small white jitter per sample. The
    walk starts at zero at frame 0.

    Args:
        n_frames: ``T``.
        n_sensors: ``S``.
        fps: Frame rate, Hz.
        cfg: Noise configuration (``ori_drift_*``, ``ori_white_deg``).
        rng: Random generator.

    Returns:
        ``(T, S, 3, 3)`` rotations ``D`` with ``R_measured = D @ R_true``, or None when all
        orientation noise terms are zero.
    """
    yaw = np.deg2rad(cfg.ori_drift_yaw_deg_per_sqrt_s) / np.sqrt(fps)
    tilt = np.deg2rad(cfg.ori_drift_tilt_deg_per_sqrt_s) / np.sqrt(fps)
    white = np.deg2rad(cfg.ori_white_deg)
    if yaw == 0 and tilt == 0 and white == 0:
        return None
    rotvec = np.zeros((n_frames, n_sensors, 3))
    if (yaw > 0 or tilt > 0) and n_frames > 1:
        steps = rng.standard_normal((n_frames - 1, n_sensors, 3)) * np.array([tilt, tilt, yaw])
        rotvec[1:] = np.cumsum(steps, axis=0)
    d = axis_angle_to_matrix(rotvec)
    if white > 0:
        d = axis_angle_to_matrix(rng.standard_normal((n_frames, n_sensors, 3)) * white) @ d
    return d


@dataclass(frozen=True)
class NoisyImu:
    """IMU readings after noise, before the low-pass filter.

    Attributes:
        acc_world: ``(T, S, 3)`` free acceleration computed by the device, world frame, m/s^2.
        ori_world: ``(T, S, 3, 3)`` estimated orientation, sensor -> world.
        acc_local: ``(T, S, 3)`` accelerometer reading (specific force), sensor frame, m/s^2.
        gyr_local: ``(T, S, 3)`` gyroscope reading, sensor frame, rad/s.
        dropped: ``(T, S)`` bool, samples the logger dropped (they repeat the previous one).
    """

    acc_world: np.ndarray
    ori_world: np.ndarray
    acc_local: np.ndarray
    gyr_local: np.ndarray
    dropped: np.ndarray


def corrupt_imu(
    acc_world: np.ndarray,
    ori_world: np.ndarray,
    acc_local: np.ndarray,
    gyr_local: np.ndarray,
    fps: float,
    cfg: NoiseConfig,
    rng: np.random.Generator,
) -> NoisyImu:
    """Apply the IMU noise model to clean signals.

    The accelerometer error ``e = bias + white`` lives in the sensor frame; the orientation
    estimate is ``D @ R``; the device's world free acceleration is then
    ``D @ (R @ (f + e)) - g_up = a + D @ R @ e + (D - I) @ (a + g_up)``, written so that it is
    exactly ``a`` when every term is zero.

    Args:
        acc_world: ``(T, S, 3)`` clean free acceleration, world frame, m/s^2.
        ori_world: ``(T, S, 3, 3)`` clean orientation, sensor -> world.
        acc_local: ``(T, S, 3)`` clean specific force, sensor frame, m/s^2.
        gyr_local: ``(T, S, 3)`` clean angular velocity, sensor frame, rad/s.
        fps: Frame rate, Hz.
        cfg: Noise configuration.
        rng: Random generator (draw order is fixed, so a seed reproduces the output).

    Returns:
        The noisy readings (new arrays; the inputs are not modified).
    """
    t, s = acc_world.shape[:2]
    acc_err = np.zeros((t, s, 3))
    if cfg.acc_bias_m_s2 > 0:
        acc_err = acc_err + rng.standard_normal((1, s, 3)) * cfg.acc_bias_m_s2
    if cfg.acc_white_m_s2 > 0:
        acc_err = acc_err + rng.standard_normal((t, s, 3)) * cfg.acc_white_m_s2
    gyr_err = np.zeros((t, s, 3))
    if cfg.gyr_bias_rad_s > 0:
        gyr_err = gyr_err + rng.standard_normal((1, s, 3)) * cfg.gyr_bias_rad_s
    if cfg.gyr_white_rad_s > 0:
        gyr_err = gyr_err + rng.standard_normal((t, s, 3)) * cfg.gyr_white_rad_s
    d = orientation_error(t, s, fps, cfg, rng)

    acc_loc = acc_local + acc_err
    gyr = gyr_local + gyr_err
    if d is None:
        ori = np.array(ori_world, copy=True)
        acc_w = acc_world + np.einsum("tsij,tsj->tsi", ori_world, acc_err)
    else:
        ori = d @ ori_world
        acc_w = (
            np.einsum("tsij,tsj->tsi", d, acc_world + _G_UP)
            - _G_UP
            + np.einsum("tsij,tsj->tsi", ori, acc_err)
        )

    dropped = drop_mask(t, s, cfg.imu_drop_prob, rng)
    return NoisyImu(
        acc_world=apply_drops(acc_w, dropped),
        ori_world=apply_drops(ori, dropped),
        acc_local=apply_drops(acc_loc, dropped),
        gyr_local=apply_drops(gyr, dropped),
        dropped=dropped,
    )


def corrupt_insole_cells(
    cell_force_n: np.ndarray, area_cm2: np.ndarray, cfg: NoiseConfig, rng: np.random.Generator
) -> np.ndarray:
    """Apply the insole noise model to clean cell forces.

    ``max(0, gain_foot * f * (1 + rel * n1) + area * (bias_cell + abs * n2))`` with a constant
    gain per foot, a constant pressure offset per cell and white noises ``n1, n2``. Sample drops
    are applied later to the derived readings (see :mod:`prism_tools.synth.insole`).

    Args:
        cell_force_n: ``(T, 2, 16)`` clean cell forces, N.
        area_cm2: ``(2, 16)`` cell areas, cm^2.
        cfg: Noise configuration.
        rng: Random generator.

    Returns:
        ``(T, 2, 16)`` noisy, non-negative cell forces, N (a new array).
    """
    t = cell_force_n.shape[0]
    f = np.array(cell_force_n, dtype=np.float64, copy=True)
    if cfg.insole_gain_std > 0:
        f = f * (1.0 + rng.standard_normal((1, 2, 1)) * cfg.insole_gain_std)
    if cfg.insole_rel_noise > 0:
        f = f * (1.0 + rng.standard_normal((t, 2, 16)) * cfg.insole_rel_noise)
    offset = np.zeros((1, 2, 16))
    if cfg.insole_bias_n_per_cm2 > 0:
        offset = offset + rng.standard_normal((1, 2, 16)) * cfg.insole_bias_n_per_cm2
    if cfg.insole_abs_noise_n_per_cm2 > 0:
        offset = offset + rng.standard_normal((t, 2, 16)) * cfg.insole_abs_noise_n_per_cm2
    if np.any(offset != 0):
        f = f + offset * area_cm2
    return np.maximum(f, 0.0)
