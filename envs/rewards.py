"""Reward terms of the tracking task (GRIP supplement eq. 8-9), as pure numpy functions.

Each function returns raw, unweighted terms; the environment multiplies them by
:class:`grip.task.config.RewardWeights` and reports every term as ``info["reward/<name>"]``.
"""

from __future__ import annotations

import numpy as np

from grip.task.config import RewardConfig

IMITATION_TERMS: tuple[str, ...] = ("imit_pos", "imit_rot", "imit_vel", "imit_angvel")
TERMS: tuple[str, ...] = (*IMITATION_TERMS, "root_vel", "root_pos", "energy", "amp")
TRACKING_TERMS = 6
"""The first terms of :data:`TERMS` that :func:`tracking_terms_rows` computes."""


def rotation_angles(sim_rot: np.ndarray, ref_rot: np.ndarray) -> np.ndarray:
    """Per-joint angle of ``sim^T ref``, rad. ``(J, 3, 3) x (J, 3, 3) -> (J,)``."""
    tr = np.einsum("jab,jab->j", sim_rot, ref_rot)
    return np.arccos(np.minimum(np.maximum((tr - 1.0) * 0.5, -1.0), 1.0))


def imitation_terms(
    sim_pvw: np.ndarray,
    sim_rot: np.ndarray,
    ref_pvw: np.ndarray,
    ref_rot: np.ndarray,
    cfg: RewardConfig,
) -> tuple[dict[str, float], np.ndarray]:
    """GRIP's imitation kernels against the ground-truth reference, each in (0, 1].

    Args:
        sim_pvw, ref_pvw: ``(3, J, 3)`` stacked world joint positions (m), linear velocities
            (m/s) and angular velocities (rad/s) of the simulation and of the reference.
        sim_rot, ref_rot: ``(J, 3, 3)`` global joint rotations.
        cfg: Kernel coefficients and form (``mean_sq``: exp(-k mean_j e_j^2); ``norm``:
            exp(-k sqrt(sum_j e_j^2))).

    Returns:
        ``{"imit_pos", "imit_rot", "imit_vel", "imit_angvel"}`` (all 1 at perfect tracking) and
        the per-joint squared position/velocity/angular-velocity errors ``(3, J)``.
    """
    e = sim_pvw - ref_pvw
    sq = np.einsum("kji,kji->kj", e, e)
    ang = rotation_angles(sim_rot, ref_rot)
    tot = sq.sum(axis=1)
    # (products then sums, not dot products: BLAS may fuse them, and the batched version
    # below gives the same bits only for the same operations)
    x = np.array([tot[0], (ang * ang).sum(), tot[1], tot[2]])
    x = x * (1.0 / ang.size) if cfg.form == "mean_sq" else np.sqrt(x)
    r = np.exp(-np.array([cfg.k_pos, cfg.k_rot, cfg.k_vel, cfg.k_angvel]) * x)
    return dict(zip(IMITATION_TERMS, r.tolist(), strict=True)), sq


def root_velocity_term(sim_disp: np.ndarray, ref_disp: np.ndarray, seconds: float,
                       k: float) -> float:  # fmt: skip
    """Kernel on the horizontal pelvis velocity averaged over a window, in (0, 1].

    Args:
        sim_disp, ref_disp: ``(2,)`` horizontal pelvis displacement of the simulation and of the
            reference over the same ``seconds``, m.
        seconds: Length of the window, s (> 0).
        k: Kernel coefficient, 1/(m/s)^2.

    Returns:
        ``exp(-k |v_sim - v_ref|^2)`` with the window's mean velocities ``v = disp / seconds``:
        1 when the body covers the reference's ground, whatever its position (the imitation
        terms compare positions with the pelvis moved over the reference's, so without this
        term a body that walks too slowly loses nothing for it).
    """
    e = (np.asarray(sim_disp, dtype=np.float64) - ref_disp) / seconds
    return float(np.exp(-k * (e * e).sum()))


def root_position_term(gap_xy: np.ndarray, k: float) -> float:
    """Kernel on the horizontal distance between the simulated pelvis and the pelvis it follows,
    in (0, 1].

    Args:
        gap_xy: ``(2,)`` followed pelvis minus simulated pelvis, horizontal, m (the estimate's
            integrated root in training and at inference; the ground truth for a teacher).
        k: Kernel coefficient, 1/m^2.

    Returns:
        ``exp(-k |gap|^2)``: 1 on the followed pelvis. Unlike the imitation terms (compared with
        the pelvis moved over the reference's, ``align_root_xy``) and ``root_vel`` (a
        velocity: a lost metre is never paid back), this term pays a body for being where it
        is asked to be, so one that fell behind is paid for catching up (docs/pace.md).
    """
    g = np.asarray(gap_xy, dtype=np.float64)
    return float(np.exp(-k * (g * g).sum()))


def mechanical_power(torque: np.ndarray, joint_vel: np.ndarray) -> float:
    """Sum over actuated DoF of ``|tau * qdot|``, W (GRIP eq. 9 before the ``-alpha`` weight)."""
    return float(np.abs(torque * joint_vel).sum())


def imitation_terms_batch(
    sim_pvw: np.ndarray,
    sim_rot: np.ndarray,
    ref_pvw: np.ndarray,
    ref_rot: np.ndarray,
    cfg: RewardConfig,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`imitation_terms` of B states at once (the batched training env's).

    Args:
        sim_pvw, ref_pvw: ``(B, 3, J, 3)``; sim_rot, ref_rot: ``(B, J, 3, 3)``.
        cfg: As :func:`imitation_terms`.

    Returns:
        ``(B, 4)`` terms in :data:`IMITATION_TERMS` order and ``(B, 3, J)`` squared errors.
    """
    e = sim_pvw - ref_pvw
    sq = np.einsum("bkji,bkji->bkj", e, e)
    tr = np.einsum("bjac,bjac->bj", sim_rot, ref_rot)
    ang = np.arccos(np.minimum(np.maximum((tr - 1.0) * 0.5, -1.0), 1.0))
    tot = sq.sum(axis=2)
    x = np.stack([tot[:, 0], (ang * ang).sum(axis=1), tot[:, 1], tot[:, 2]], axis=1)
    x = x * (1.0 / ang.shape[1]) if cfg.form == "mean_sq" else np.sqrt(x)
    return np.exp(-np.array([cfg.k_pos, cfg.k_rot, cfg.k_vel, cfg.k_angvel]) * x), sq


def root_velocity_terms(sim_disp: np.ndarray, ref_disp: np.ndarray, seconds: float,
                        k: float) -> np.ndarray:  # fmt: skip
    """:func:`root_velocity_term` of ``(B, 2)`` displacements: ``(B,)``."""
    e = (sim_disp - ref_disp) / seconds
    return np.exp(-k * (e * e).sum(axis=1))


_K_ORDER = np.array([0, 3, 1, 2, 4, 5])  # (pos, vel, angvel, rot, root_vel, root_pos) -> TERMS


def tracking_terms_rows(sim_rows: np.ndarray, ref_rows: np.ndarray, cfg: RewardConfig,
                        align_root_xy: bool, sim_disp: np.ndarray, ref_disp: np.ndarray,
                        seconds: float,
                        root_gap: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """:func:`imitation_terms`, :func:`root_velocity_term` and :func:`root_position_term` of B
    states at once, on flat rows, with one ``exp`` for all (the tracking environments' step).

    Args:
        sim_rows, ref_rows: ``(B, >= 432)``: ``(3, J, 3)`` world positions (m), linear (m/s) and
            angular (rad/s) velocities flattened, then ``(J, 3, 3)`` world rotations
            flattened (J = 24; :data:`grip.sim.humanoid.ROW_PARTS` starts so).
        cfg: Kernel coefficients and form.
        align_root_xy: Compare positions with the simulated pelvis moved over the reference's
            horizontally (each joint's xy error minus the pelvis' xy error).
        sim_disp, ref_disp: ``(B, 2)`` horizontal pelvis displacements over ``seconds``, m.
        seconds: Length of the root-velocity window, s.
        root_gap: ``(B, 2)`` followed pelvis minus simulated pelvis, horizontal, m.

    Returns:
        ``(B, 6)`` terms in :data:`TERMS` order (the imitation terms, ``root_vel``,
        ``root_pos``) and
        ``(B, 3, J)`` per-joint squared position (aligned as asked), velocity and angular
        velocity errors.
    """
    b = sim_rows.shape[0]
    j = 24
    n = 9 * j
    e = sim_rows[:, :n] - ref_rows[:, :n]
    if align_root_xy:
        ep = e[:, : 3 * j].reshape(b, j, 3)
        ep[:, :, :2] -= ep[:, :1, :2].copy()
    e *= e
    sq = e.reshape(b, 3 * j, 3).sum(axis=2).reshape(b, 3, j)
    x = np.empty((b, 6))  # pos, vel, angvel, rot, root_vel, root_pos
    np.sum(sq, axis=2, out=x[:, :3])
    tr = (sim_rows[:, n : 2 * n] * ref_rows[:, n : 2 * n]).reshape(b, j, 9).sum(axis=2)
    tr -= 1.0
    tr *= 0.5
    np.maximum(tr, -1.0, out=tr)
    np.minimum(tr, 1.0, out=tr)
    np.arccos(tr, out=tr)
    tr *= tr
    np.sum(tr, axis=1, out=x[:, 3])
    if cfg.form == "mean_sq":
        x[:, :4] *= 1.0 / j
    else:
        np.sqrt(x[:, :4], out=x[:, :4])
    d = sim_disp - ref_disp
    d /= seconds
    d *= d
    np.sum(d, axis=1, out=x[:, 4])
    np.sum(root_gap * root_gap, axis=1, out=x[:, 5])
    x *= -np.array([cfg.k_pos, cfg.k_vel, cfg.k_angvel, cfg.k_rot, cfg.k_root_vel, cfg.k_root_pos])
    np.exp(x, out=x)
    return x[:, _K_ORDER], sq
