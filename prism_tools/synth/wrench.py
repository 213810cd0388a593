"""Net external wrench and zero-moment point of a motion (steps 1-2 of
:mod:`prism_tools.synth.insole`): the load the insoles must carry and where it acts."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grip.core.body import BodyModel
from grip.core.fk import segment_com
from grip.core.metrics import net_external_wrench
from prism_tools.synth.config import InsoleSynthConfig

__all__ = ["Wrench", "external_wrench", "zero_moment_point"]


# ------------------------------------------------------------------------------ the wrench
@dataclass(frozen=True)
class Wrench:
    """Net external wrench on the body (ground reaction plus any other external load).

    Attributes:
        force_world: ``(T, 3)`` total external force, world frame, N (``(0, 0, m g)`` standing).
        moment_world: ``(T, 3)`` external moment about the world origin, world frame, N m.
        com_world: ``(T, 3)`` whole-body centre of mass, world frame, m.
        zmp_world: ``(T, 2)`` zero-moment point on the floor, world x/y, m (the COM's ground
            projection where ``F_z`` is below 1 N, where the ZMP is undefined).
    """

    force_world: np.ndarray
    moment_world: np.ndarray
    com_world: np.ndarray
    zmp_world: np.ndarray


def zero_moment_point(
    force_world: np.ndarray,
    moment_world: np.ndarray,
    fallback_xy: np.ndarray | None = None,
    min_fz_n: float = 1.0,
) -> np.ndarray:
    """Point on the floor ``z = 0`` about which the external moment has no horizontal part.

    For ground forces ``f_k`` at floor points ``p_k``: ``N_x = sum p_y f_z``,
    ``N_y = -sum p_x f_z``, hence ``p = (-N_y / F_z, N_x / F_z)``.

    Args:
        force_world: ``(T, 3)`` external force, N.
        moment_world: ``(T, 3)`` external moment about the world origin, N m.
        fallback_xy: ``(T, 2)`` value where ``F_z < min_fz_n`` (default: zeros).
        min_fz_n: Smallest vertical force for which the ZMP is computed, N.

    Returns:
        ``(T, 2)`` world x/y, m.
    """
    fz = force_world[:, 2]
    ok = fz >= min_fz_n
    safe = np.where(ok, fz, 1.0)
    p = np.stack([-moment_world[:, 1] / safe, moment_world[:, 0] / safe], axis=-1)
    fb = np.zeros_like(p) if fallback_xy is None else fallback_xy
    return np.where(ok[:, None], p, fb)


def external_wrench(
    global_rot: np.ndarray,
    joint_pos: np.ndarray,
    body: BodyModel,
    fps: float,
    cfg: InsoleSynthConfig | None = None,
) -> Wrench:
    """Newton-Euler: the external wrench that produces the motion.

    Args:
        global_rot: ``(T, 24, 3, 3)`` global segment rotations.
        joint_pos: ``(T, 24, 3)`` joint positions, world frame, m.
        body: Body model (segment masses, COMs, inertias in the body frames).
        fps: Frame rate, Hz.
        cfg: Smoothing settings (``smoothing_window_s``, ``smoothing_polyorder``).

    Returns:
        The wrench, the COM and the ZMP per frame.
    """
    cfg = cfg or InsoleSynthConfig()
    force, moment = net_external_wrench(
        global_rot, joint_pos, body, fps, cfg.smoothing_window_s, cfg.smoothing_polyorder
    )
    c = segment_com(global_rot, joint_pos, body)
    com = np.einsum("tjk,j->tk", c, body.masses) / body.masses.sum()
    return Wrench(force, moment, com, zero_moment_point(force, moment, com[:, :2]))
