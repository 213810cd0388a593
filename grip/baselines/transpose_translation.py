"""TransPose's global translation (Trans-B1 + Trans-B2 fusion), numpy only, z-up, 100 Hz.

BASELINES_AND_METRICS.md section 2.2. Per frame ``t >= 1`` (m/frame):

- supporting foot ``f = argmax(s_l, s_r)`` with ``s = max(s_l, s_r)`` the contact probability;
- foot branch ``v_f = FK(theta_{t-1})_f - FK(theta_t)_f + g`` with the SMPL foot joint (10/11)
  reached through the lower-body chain (pelvis, hip, knee, ankle) of a body model with mean or
  the user's leg lengths, and ``g`` the "gravity velocity" pulling the body down (TransPose code:
  0.018 m/frame at 60 Hz = 1.08 m/s, always added to the foot branch);
- network branch ``v_e = R_root v~_e * 3 / fps`` (Trans-B2, here passed in as world m/s);
- fusion ``w = clip((s - s_low) / (s_high - s_low), 0, 1)``, ``v = (1 - w) v_e + w v_f``;
- penetration guard: if the lowest foot joint would end below the joint floor, the vertical
  velocity is set so that it lands exactly on it;
- translation = cumulative sum of ``v``, starting at the first frame's (ground-truth) root.

The guard's recursion ``z_t = max(z_{t-1} + v_z(t), floor - min_foot_z(t))`` is evaluated
without a Python loop: with ``S_t = sum_{k<=t} v_z(k)`` it is
``z_t = S_t + max(z_0, max_{1<=k<=t}(floor - min_foot_z(k) - S_k))``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grip.core import skeleton as sk
from grip.core.body import BodyModel

FPS_HZ = 100.0
"""Frame rate of GRIP's data (TransPose ran at 60 Hz)."""

GRAVITY_VELOCITY_MPS = 0.018 * 60.0
"""TransPose's gravity velocity, 0.018 m/frame at 60 Hz, as a speed (1.08 m/s; 0.0108 m/frame at
100 Hz)."""

PROB_LOW = 0.5
PROB_HIGH = 0.9
"""Fusion thresholds on the supporting foot's contact probability (TransPose ``prob_threshold``)."""

_FOOT_CHAINS: np.ndarray = np.array([[1, 4, 7, 10], [2, 5, 8, 11]], dtype=np.int64)
"""Joints from the pelvis down to the left/right SMPL foot joint (hip, knee, ankle, foot)."""


@dataclass(frozen=True)
class TranslationConfig:
    """Settings of the translation estimate.

    Attributes:
        fps: Frame rate of the inputs, Hz.
        gravity_velocity_mps: Downward speed added to the foot branch, m/s.
        prob_low: Contact probability at and below which only Trans-B2 is used.
        prob_high: Contact probability at and above which only the supporting foot is used.
        penetration_guard: Keep the lowest foot joint at or above the joint floor.
    """

    fps: float = FPS_HZ
    gravity_velocity_mps: float = GRAVITY_VELOCITY_MPS
    prob_low: float = PROB_LOW
    prob_high: float = PROB_HIGH
    penetration_guard: bool = True

    def __post_init__(self) -> None:
        if not self.fps > 0:
            raise ValueError(f"TranslationConfig.fps must be positive, got {self.fps}")
        if not 0.0 <= self.prob_low < self.prob_high <= 1.0:
            raise ValueError("TranslationConfig: need 0 <= prob_low < prob_high <= 1, got "
                             f"{self.prob_low}, {self.prob_high}")  # fmt: skip


def joint_floor_height(body: BodyModel, floor_z_m: float = 0.0) -> float:
    """Height of the "joint floor": where the SMPL foot joints (10/11) rest when the soles touch
    a floor at ``floor_z_m``, m (the foot joint's rest height above the sole)."""
    return float(floor_z_m + body.rest_joint_pos[sk.FOOT_JOINTS[0], 1])


def _check(name: str, a: np.ndarray, shape: tuple[int | None, ...]) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    ok = a.ndim == len(shape) and all(s is None or s == d for s, d in zip(shape, a.shape,
                                                                          strict=True))  # fmt: skip
    if not ok:
        want = "(" + ", ".join("T" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name}: expected shape {want}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        bad = int(np.argwhere(~np.isfinite(a.reshape(a.shape[0], -1)))[0][0])
        raise ValueError(f"{name}: non-finite values (first at frame {bad})")
    return a


def foot_positions(global_rot: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Root-relative positions of the SMPL foot joints through the lower-body chain.

    Args:
        global_rot: ``(T, 24, 3, 3)`` global joint rotations (only 0, 1, 2, 4, 5, 7, 8 are used).
        offsets: ``(24, 3)`` rest offsets of the body model (mean or user leg lengths), m.

    Returns:
        ``(T, 2, 3)`` left/right foot joint minus the pelvis joint, world axes, m.
    """
    global_rot = _check("global_rot", global_rot, (None, sk.N_JOINTS, 3, 3))
    offsets = _check("offsets", offsets, (sk.N_JOINTS, 3))
    parents = sk.PARENTS[_FOOT_CHAINS]  # (2, 4)
    # segment vector of each chain joint: its parent's global rotation times its rest offset
    seg = np.einsum("tfkij,fkj->tfki", global_rot[:, parents], offsets[_FOOT_CHAINS])
    return seg.sum(axis=2)


def fusion_weight(prob: np.ndarray, low: float = PROB_LOW, high: float = PROB_HIGH) -> np.ndarray:
    """Weight of the supporting-foot branch: ``clip((prob - low) / (high - low), 0, 1)``."""
    return np.clip((np.asarray(prob, dtype=np.float64) - low) / (high - low), 0.0, 1.0)


def fused_velocity(
    foot_rel: np.ndarray,
    contact_prob: np.ndarray,
    root_vel_world: np.ndarray,
    cfg: TranslationConfig = TranslationConfig(),
) -> np.ndarray:
    """Per-frame root displacement of the two fused branches, before the penetration guard.

    Args:
        foot_rel: ``(T, 2, 3)`` root-relative foot joints (:func:`foot_positions`), m.
        contact_prob: ``(T, 2)`` left/right foot contact probabilities in [0, 1].
        root_vel_world: ``(T, 3)`` Trans-B2 root velocity in the world frame, m/s.
        cfg: Frame rate, gravity term and fusion thresholds.

    Returns:
        ``(T, 3)`` displacement from frame ``t - 1`` to ``t``, m; row 0 is zero.
    """
    n = foot_rel.shape[0]
    prob = np.asarray(contact_prob, dtype=np.float64)
    support = np.argmax(prob, axis=1)  # ties -> left, as TransPose's max().indices
    s = prob[np.arange(n), support]
    foot = foot_rel[np.arange(n), support]  # supporting foot at t
    prev = foot_rel[np.arange(n - 1), support[1:]]  # the same foot at t - 1
    v_f = np.zeros((n, 3))
    v_f[1:] = prev - foot[1:]
    v_f[1:, 2] -= cfg.gravity_velocity_mps / cfg.fps
    v_e = np.asarray(root_vel_world, dtype=np.float64) / cfg.fps
    w = fusion_weight(s, cfg.prob_low, cfg.prob_high)[:, None]
    v = (1.0 - w) * v_e + w * v_f
    v[0] = 0.0
    return v


def guard_heights(root_z0: float, v_z: np.ndarray, min_foot_rel_z: np.ndarray,
                  joint_floor_z: float) -> np.ndarray:  # fmt: skip
    """Root heights with the penetration guard: ``z_t = max(z_{t-1} + v_z(t), floor - foot_t)``.

    Args:
        root_z0: Root height at frame 0 (kept as is), m.
        v_z: ``(T,)`` vertical displacements (row 0 unused), m.
        min_foot_rel_z: ``(T,)`` height of the lower foot joint relative to the root, m.
        joint_floor_z: Height the foot joints may not go below, m.

    Returns:
        ``(T,)`` root heights, m.
    """
    s = np.concatenate([[0.0], np.cumsum(v_z[1:])])
    lift = joint_floor_z - min_foot_rel_z - s
    lift[0] = root_z0
    return s + np.maximum.accumulate(lift)


def root_translation(
    global_rot: np.ndarray,
    contact_prob: np.ndarray,
    root_vel_world: np.ndarray,
    offsets: np.ndarray,
    root0: np.ndarray,
    joint_floor_z: float,
    cfg: TranslationConfig = TranslationConfig(),
) -> np.ndarray:
    """TransPose's root trajectory from the estimated pose, contacts and Trans-B2 velocity.

    Args:
        global_rot: ``(T, 24, 3, 3)`` estimated global joint rotations (world, z up).
        contact_prob: ``(T, 2)`` left/right foot contact probabilities (Trans-B1), in [0, 1].
        root_vel_world: ``(T, 3)`` Trans-B2 root velocity rotated to the world frame, m/s.
        offsets: ``(24, 3)`` rest offsets of the body used for the foot FK (mean or user legs), m.
        root0: ``(3,)`` root (pelvis joint) position at frame 0, world, m (GRIP protocol: GT).
        joint_floor_z: Height of the joint floor (:func:`joint_floor_height`), m.
        cfg: Frame rate, gravity term, fusion thresholds, guard switch.

    Returns:
        ``(T, 3)`` pelvis joint positions, world, m.

    Raises:
        ValueError: Shapes disagree, values are non-finite or probabilities leave [0, 1].
    """
    foot_rel = foot_positions(global_rot, offsets)
    n = foot_rel.shape[0]
    prob = _check("contact_prob", contact_prob, (n, 2))
    if prob.min() < 0.0 or prob.max() > 1.0:
        raise ValueError("contact_prob: probabilities must lie in [0, 1] "
                         f"(got {prob.min():.3g} to {prob.max():.3g})")  # fmt: skip
    vel = _check("root_vel_world", root_vel_world, (n, 3))
    root0 = _check("root0", np.reshape(root0, (1, 3)), (1, 3))[0]
    v = fused_velocity(foot_rel, prob, vel, cfg)
    pos = root0 + np.cumsum(v, axis=0)
    if cfg.penetration_guard:
        pos[:, 2] = guard_heights(root0[2], v[:, 2], foot_rel[:, :, 2].min(axis=1), joint_floor_z)
    return pos
