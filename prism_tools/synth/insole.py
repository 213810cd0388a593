"""Pressure insoles synthesised from physics: Newton-Euler wrench, ZMP, cell force distribution.

1. The net external wrench on the body follows from the motion alone (Newton-Euler over the 24
   rigid segments of the body model): ``F = sum_j m_j (c''_j - g)`` and, about the world
   origin, ``N = sum_j c_j x m_j (c''_j - g) + d/dt sum_j I_j w_j`` with ``g = (0, 0, -9.81)``,
   ``I_j = R_j I_local R_j^T`` and ``w_j`` the world angular velocity (``I_j w_j`` is
   computed as ``R_j I_local w_local``). Positions and the spin angular momentum are
   differentiated with a Savitzky-Golay filter (window ``InsoleSynthConfig.smoothing_window_s``,
   0.1 s, quadratic) so that the ZMP is not dominated by noise (0.2 s, about 5 Hz, removes
   more: docs/insoles_zmp.md).
2. On the flat floor ``z = 0`` the ground reaction acts through the zero-moment point
   ``p = (-N_y / F_z, N_x / F_z)``.
3. Each of the 32 cells (16 per foot) gets a soft support weight in ``[0, 1]`` from its height
   above the ground (the floor, or a prop under it) and its horizontal speed (smooth ramps), so
   load fades in and out. So do the lowest points of the other body shapes
   (:func:`body_contact_points`): a seat, knees, hands or the back resting on the ground carry
   their part, which the insoles do not feel.
4. ``F_z`` (clamped at 0) is spread over the cells and resting body points: non-negative
   forces ``f`` with ``sum f = F_z`` minimising
   ``1/2 sum f_k^2 / s_k + beta/2 |centroid(f) - p|^2``, where
   ``s_k = support_k * area_k * prior_k`` (see
   :func:`~prism_tools.synth.force_distribution.distribute_force`). The solution is a
   linear pressure field clipped at zero, ``f_k = s_k max(0, a + b . x_k)``, found exactly by a
   vectorised active-set (semi-smooth) Newton method on the three multipliers ``(a, b)``.
5. Per foot: force (body weights), CoP in the insole frame and in the world, PRISM contacts.

Steps 1-2 live in :mod:`prism_tools.synth.wrench`, step 4 in
:mod:`prism_tools.synth.force_distribution`.

Shapes: ``T`` frames, ``P`` cells (32 = 2 feet x 16), feet ordered (L, R).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import signal

from grip.core import skeleton as sk
from grip.core.body import GRAVITY, BodyModel
from grip.core.fk import body_points
from prism_tools.streams import contacts_from_cells
from prism_tools.synth.config import InsoleSynthConfig, NoiseConfig
from prism_tools.synth.force_distribution import distribute_force
from prism_tools.synth.imu import central_velocity, second_difference
from prism_tools.synth.noise import apply_drops, corrupt_insole_cells, drop_mask
from prism_tools.synth.wrench import Wrench, external_wrench

__all__ = [
    "InsoleReadings",
    "InsoleSynth",
    "cell_support_weights",
    "insole_cell_positions",
    "insole_cell_uv",
    "insole_origin_world",
    "insole_readings_from_cells",
    "measure_insoles",
    "smooth_derivative",
    "synthesize_insoles",
]

_OTHER_CAPACITY = 0.25
"""Capacity of a body point resting on the ground (:func:`body_contact_points`) as a share of one
foot's insole area: a seat's five points together carry like a foot and a quarter, so sitting
with the feet down shares the weight between them as the ZMP requires."""
_SLIDING_PENALTY_M = 1.0  # height added to a fully sliding cell when finding the contact level
_FEET_SEGMENTS = (sk.FOOT_BODY["L_Foot"], sk.FOOT_BODY["R_Foot"])


# ------------------------------------------------------------------------------- derivatives
def _savgol_window(window_s: float, fps: float, polyorder: int, n_frames: int) -> int | None:
    """Odd Savitzky-Golay window in frames, shrunk to fit short clips; None if impossible."""
    w = max(round(window_s * fps), polyorder + 1)
    w += 1 - w % 2
    if w > n_frames:
        w = n_frames - (1 - n_frames % 2)
    return w if w > polyorder else None


def smooth_derivative(
    x: np.ndarray, fps: float, window_s: float, polyorder: int, deriv: int
) -> np.ndarray:
    """Savitzky-Golay derivative along axis 0 (local polynomial fits; ``interp`` at the ends).

    Args:
        x: ``(T, ...)`` samples at ``fps``.
        fps: Frame rate, Hz.
        window_s: Window length, s (rounded to an odd frame count, shrunk for short clips).
        polyorder: Polynomial order (>= ``deriv``).
        deriv: 1 or 2.

    Returns:
        ``(T, ...)`` derivative, units of ``x`` per s^deriv. Clips too short for the filter fall
        back to plain central differences.
    """
    x = np.asarray(x, dtype=np.float64)
    w = _savgol_window(window_s, fps, polyorder, x.shape[0])
    if w is None:
        return central_velocity(x, fps) if deriv == 1 else second_difference(x, fps, 1)
    return signal.savgol_filter(
        x, w, polyorder, deriv=deriv, delta=1.0 / fps, axis=0, mode="interp"
    )


# ---------------------------------------------------------------------------- insole geometry
def insole_cell_positions(
    global_rot: np.ndarray, joint_pos: np.ndarray, body: BodyModel
) -> np.ndarray:
    """``(T, 2, 16, 3)`` world positions of the insole cell centres (on the sole), m."""
    pts = body_points(
        global_rot, joint_pos, body.insole_body.reshape(-1), body.insole_pos.reshape(-1, 3)
    )
    return pts.reshape(pts.shape[0], 2, sk.N_INSOLE_CELLS, 3)


_SHANKS = (4, 5)  # knee -> ankle bodies: only their knee end may rest on the ground (kneeling)
_FOOT_BODIES = frozenset((7, 8, 10, 11))  # feet and toes: the insole cells stand for them


def body_contact_points(
    global_rot: np.ndarray, joint_pos: np.ndarray, body: BodyModel
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lowest surface points of the body's shapes other than the feet: where the body can
    rest on the ground or a prop besides its soles (sitting, kneeling, hands on the floor,
    lying). Each capsule gives its two ends and its middle, a sphere its centre, lowered by the
    radius; a shank only its knee end (its ankle end is the foot's business).

    Returns:
        ``(T, K, 3)`` points, world frame, m; ``(K,)`` carrying body of each; ``(K,)`` position
        along its capsule (0 proximal end, 0.5 middle, 1 distal end; 0.5 for a sphere).
    """
    bodies, local, where, radius = [], [], [], []
    for g in body.geoms:
        if g.body in _FOOT_BODIES or g.kind == "box":
            continue
        if g.kind == "sphere":
            samples = [(g.pos, 0.5)]
        else:
            ends = g.fromto()
            a, b = ends[:3], ends[3:]
            samples = [(a, 0.0)]
            if g.body not in _SHANKS:
                samples += [(0.5 * (a + b), 0.5), (b, 1.0)]
        for pt, frac in samples:
            bodies.append(g.body), local.append(pt), where.append(frac), radius.append(g.size[0])
    bodies_a = np.asarray(bodies, dtype=np.int64)
    pts = body_points(global_rot, joint_pos, bodies_a, np.asarray(local, dtype=np.float64))
    pts[..., 2] -= np.asarray(radius)
    return pts, bodies_a, np.asarray(where)


def insole_origin_world(
    global_rot: np.ndarray, joint_pos: np.ndarray, body: BodyModel
) -> np.ndarray:
    """``(T, 2, 3)`` world positions of the two insole-frame origins (mid-foot on the sole), m."""
    return body_points(global_rot, joint_pos, np.array(_FEET_SEGMENTS), body.insole_origin)


def insole_cell_uv(body: BodyModel) -> np.ndarray:
    """``(2, 16, 2)`` cell centres in the flat insole frame (forward, medial), m.

    Computed from the rest geometry (toe cells expressed in the foot frame with the toes
    straight), i.e. the coordinates of the printed sensor layout.
    """
    toe = np.array([sk.TOE_BODY["L_Foot"], sk.TOE_BODY["R_Foot"]])
    on_toe = body.insole_body == toe[:, None]
    pos_foot = body.insole_pos + np.where(on_toe[..., None], body.offsets[toe][:, None, :], 0.0)
    rel = pos_foot - body.insole_origin[:, None, :]
    return np.einsum("fpk,fak->fpa", rel, body.insole_axes)


# ------------------------------------------------------------------------------- contacts
def _ramp_down(x: np.ndarray, full: float, zero: float) -> np.ndarray:
    """1 for ``x <= full``, 0 for ``x >= zero``, smoothstep in between."""
    t = np.clip((x - full) / (zero - full), 0.0, 1.0)
    return 1.0 - t * t * (3.0 - 2.0 * t)


def cell_support_weights(
    cell_pos_world: np.ndarray, fps: float, cfg: InsoleSynthConfig | None = None,
    ground_z: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Soft weight of each cell's ability to carry load: near the contact level and not sliding.

    The contact level is the floor (``z = 0``), raised to the lowest slow cell of the frame when
    that cell hovers above the floor by at most ``cfg.contact_float_tolerance_m`` (motions whose
    feet float a few centimetres during stance keep their support). "Lowest slow cell" is a
    soft minimum: each cell's height plus 1 m times ``(1 - speed weight)``, so a sliding cell
    does not set the level and the level changes continuously.

    Args:
        cell_pos_world: ``(T, C, 3)`` cell positions, world frame, m.
        fps: Frame rate, Hz.
        cfg: Thresholds ``contact_height_*``, ``contact_speed_*``,
            ``contact_float_tolerance_m`` and the smoothing window (for the horizontal speed).
        ground_z: ``(T, C)`` height of the ground under each cell (props,
            :mod:`prism_tools.synth.props`); heights are then measured from it. ``None``: the
            flat floor.

    Returns:
        ``(T, C)`` weights in ``[0, 1]`` (a smooth height ramp above the contact level times a
        smooth speed ramp) and ``(T,)`` the contact level above the ground, m.
    """
    cfg = cfg or InsoleSynthConfig()
    h = cell_pos_world[..., 2] if ground_z is None else cell_pos_world[..., 2] - ground_z
    vel = smooth_derivative(
        cell_pos_world[..., :2], fps, cfg.smoothing_window_s, cfg.smoothing_polyorder, deriv=1
    )
    w_speed = _ramp_down(
        np.linalg.norm(vel, axis=-1), cfg.contact_speed_full_m_s, cfg.contact_speed_zero_m_s
    )
    level = np.min(h + (1.0 - w_speed) * _SLIDING_PENALTY_M, axis=1, initial=np.inf)
    level = np.clip(level, 0.0, cfg.contact_float_tolerance_m)
    w_height = _ramp_down(h - level[:, None], cfg.contact_height_full_m, cfg.contact_height_zero_m)
    return w_height * w_speed, level


# -------------------------------------------------------------------------------- readings
@dataclass(frozen=True)
class InsoleReadings:
    """What the two insoles report (feet ordered L, R).

    Attributes:
        contacts: ``(T, 2, 2)`` bool ``[front, back]``: cells 8-15 / cells 0-3 above the
            contact threshold.
        force_bw: ``(T, 2)`` vertical force per foot, body weights (``/ (m g)``).
        cell_force_bw: ``(T, 2, 16)`` cell forces, body weights (they sum to ``force_bw``).
        cell_pressure_n_per_cm2: ``(T, 2, 16)`` cell pressures (force / area), N/cm^2, as the
            Moticon insole reports them.
        cop_insole_m: ``(T, 2, 2)`` CoP in the insole frame (forward, medial from the insole
            origin), m; ``(0, 0)`` below ``cop_min_force_n``.
        force_world_bw: ``(T, 2, 3)`` ``(0, 0, force_bw)``, world frame, body weights.
        cop_world_m: ``(T, 2, 3)`` CoP on the sole, world frame, m (the insole origin below
            ``cop_min_force_n``).
        combined_force_world_bw: ``(T, 3)`` both feet, world frame, body weights.
        combined_cop_world_m: ``(T, 3)`` force-weighted CoP of the loaded feet, world frame, m
            (the midpoint of the two feet's ``cop_world_m`` when neither is loaded).
        dropped: foot -> ``(K,)`` int64 frames whose sample was dropped (previous one repeated).
    """

    contacts: np.ndarray
    force_bw: np.ndarray
    cell_force_bw: np.ndarray
    cell_pressure_n_per_cm2: np.ndarray
    cop_insole_m: np.ndarray
    force_world_bw: np.ndarray
    cop_world_m: np.ndarray
    combined_force_world_bw: np.ndarray
    combined_cop_world_m: np.ndarray
    dropped: dict[str, np.ndarray]


def insole_readings_from_cells(
    cell_force_n: np.ndarray,
    cell_pos_world: np.ndarray,
    origin_world: np.ndarray,
    body: BodyModel,
    cfg: InsoleSynthConfig | None = None,
    dropped: np.ndarray | None = None,
) -> InsoleReadings:
    """Derive every insole reading from cell forces, as the insole's software does.

    Args:
        cell_force_n: ``(T, 2, 16)`` cell forces, N.
        cell_pos_world: ``(T, 2, 16, 3)`` cell positions, world frame, m.
        origin_world: ``(T, 2, 3)`` insole-frame origins, world frame, m.
        body: Body model (mass, cell areas, insole layout).
        cfg: Contact threshold and minimum CoP force.
        dropped: Optional ``(T, 2)`` bool of dropped samples: every per-foot reading repeats the
            previous frame there (the combined values are derived after that).

    Returns:
        The readings.
    """
    cfg = cfg or InsoleSynthConfig()
    bw = body.total_mass * GRAVITY
    f = np.asarray(cell_force_n, dtype=np.float64)
    foot = f.sum(axis=-1)  # (T, 2)
    loaded = foot >= cfg.cop_min_force_n
    safe = np.where(loaded, foot, 1.0)[..., None]
    uv = insole_cell_uv(body)
    cop_uv = np.where(loaded[..., None], np.einsum("tfp,fpa->tfa", f, uv) / safe, 0.0)
    cop_w = np.where(
        loaded[..., None], np.einsum("tfp,tfpk->tfk", f, cell_pos_world) / safe, origin_world
    )
    contacts = contacts_from_cells(f, cfg.contact_threshold_n)
    pressure = f / body.insole_area_cm2
    if dropped is not None and dropped.any():
        f, foot, cop_uv, cop_w, contacts, pressure = (
            apply_drops(v, dropped) for v in (f, foot, cop_uv, cop_w, contacts, pressure)
        )
        loaded = foot >= cfg.cop_min_force_n
    force_world = np.zeros((*foot.shape, 3))
    force_world[..., 2] = foot / bw
    wsum = np.sum(foot * loaded, axis=1)
    any_loaded = wsum > 0
    combined_cop = np.where(
        any_loaded[:, None],
        np.einsum("tf,tfk->tk", foot * loaded, cop_w) / np.where(any_loaded, wsum, 1.0)[:, None],
        cop_w.mean(axis=1),
    )
    none = np.zeros(0, dtype=np.int64)
    return InsoleReadings(
        contacts=contacts,
        force_bw=foot / bw,
        cell_force_bw=f / bw,
        cell_pressure_n_per_cm2=pressure,
        cop_insole_m=cop_uv,
        force_world_bw=force_world,
        cop_world_m=cop_w,
        combined_force_world_bw=force_world.sum(axis=1),
        combined_cop_world_m=combined_cop,
        dropped={
            foot_name: (none if dropped is None else np.flatnonzero(dropped[:, i]))
            for i, foot_name in enumerate(sk.FEET)
        },
    )


# ------------------------------------------------------------------------------- synthesis
@dataclass(frozen=True)
class InsoleSynth:
    """Clean insole synthesis and its diagnostics.

    Attributes:
        wrench: The external wrench, COM and ZMP.
        support: ``(T, 2, 16)`` soft support weight of each cell, in ``[0, 1]``.
        contact_level_m: ``(T,)`` height from which cell heights were measured, m: 0 on a
            well-grounded motion, up to ``contact_float_tolerance_m`` where the feet float.
        cell_force_n: ``(T, 2, 16)`` clean cell forces, N.
        cell_pos_world: ``(T, 2, 16, 3)`` cell positions, world frame, m.
        origin_world: ``(T, 2, 3)`` insole-frame origins, world frame, m.
        unsupported_force_n: ``(T,)`` positive vertical force that no cell could carry (no foot
            near the floor), N; large values flag motions that float or penetrate.
        zmp_error_m: ``(T,)`` distance from the cells' force centroid to the ZMP, m (0 while the
            ZMP lies in the support polygon; 0 without load).
        fallback_frames: ``(K,)`` frames solved by the nnls fallback.
        other_support_force_n: ``(T,)`` vertical force carried by body parts other than the
            feet that rest on the ground or a prop (:func:`body_contact_points`: seat, knees,
            hands, back), N; the insoles do not feel it.
        zmp_world: ``(T, 2)`` the ZMP the cells were asked to follow, world x/y, m: on the
            plane of the supported cells' mean ground height (``wrench.zmp_world`` on the flat
            floor).
        other_support: ``(T, K)`` soft support weight of each of those body points, in
            ``[0, 1]`` (0: well above the ground or sliding).
    """

    wrench: Wrench
    support: np.ndarray
    contact_level_m: np.ndarray
    cell_force_n: np.ndarray
    cell_pos_world: np.ndarray
    origin_world: np.ndarray
    unsupported_force_n: np.ndarray
    zmp_error_m: np.ndarray
    fallback_frames: np.ndarray
    other_support_force_n: np.ndarray
    zmp_world: np.ndarray
    other_support: np.ndarray


def synthesize_insoles(
    global_rot: np.ndarray,
    joint_pos: np.ndarray,
    body: BodyModel,
    fps: float,
    cfg: InsoleSynthConfig | None = None,
    ground: Callable[[np.ndarray], np.ndarray] | None = None,
) -> InsoleSynth:
    """Clean cell forces of both insoles from the whole-body motion.

    Args:
        global_rot: ``(T, 24, 3, 3)`` global segment rotations.
        joint_pos: ``(T, 24, 3)`` joint positions, world frame (z up, floor z = 0), m.
        body: Body model.
        fps: Frame rate, Hz.
        cfg: Insole synthesis configuration.
        ground: Height of the ground under points ``(..., 3)`` (the props a motion stands on,
            :func:`prism_tools.synth.props.support_height`: a point under a seat's slab stands
            on the floor); ``None``: the flat floor. Cells
            carry load near the ground under them, and the ZMP is taken on the plane of the
            supported cells' mean ground height (``p_h = p_0 + h F_xy / F_z``).

    Returns:
        Cell forces, geometry and diagnostics; :func:`insole_readings_from_cells` turns them into
        readings.
    """
    cfg = cfg or InsoleSynthConfig()
    wrench = external_wrench(global_rot, joint_pos, body, fps, cfg)
    cells = insole_cell_positions(global_rot, joint_pos, body)
    t, n_cells = cells.shape[0], 2 * sk.N_INSOLE_CELLS
    others = body_contact_points(global_rot, joint_pos, body)[0]  # (T, K, 3)
    points = np.concatenate([cells.reshape(t, -1, 3), others], axis=1)
    flat_xy = points[..., :2]
    ground_z = None if ground is None else ground(points)
    support, level = cell_support_weights(points, fps, cfg, ground_z)
    zmp = wrench.zmp_world
    if ground_z is not None:
        w = support.sum(1)
        plane = np.where(w > 0, (support * ground_z).sum(1) / np.where(w > 0, w, 1.0), 0.0)
        f = wrench.force_world
        zmp = zmp + plane[:, None] * f[:, :2] / np.where(f[:, 2] > 0, f[:, 2], 1.0)[:, None]
    cell_capacity = support[:, :n_cells] * (body.insole_area_cm2
                                            * np.asarray(cfg.cell_prior)).reshape(-1)  # fmt: skip
    other_capacity = support[:, n_cells:] * (_OTHER_CAPACITY * body.insole_area_cm2.sum() / 2)
    fz = np.maximum(wrench.force_world[:, 2], 0.0)
    forces, fallback = distribute_force(
        fz,
        zmp,
        flat_xy,
        np.concatenate([cell_capacity, other_capacity], axis=1),
        cfg.zmp_penalty_per_m2,
        cfg.max_newton_iters,
    )
    carried = forces.sum(axis=1)
    safe = np.where(carried > 0, carried, 1.0)
    centroid = np.einsum("tp,tpk->tk", forces, flat_xy) / safe[:, None]
    zmp_err = np.where(carried > 0, np.linalg.norm(centroid - zmp, axis=1), 0.0)
    return InsoleSynth(
        wrench=wrench,
        support=support[:, :n_cells].reshape(t, 2, sk.N_INSOLE_CELLS),
        contact_level_m=level,
        cell_force_n=forces[:, :n_cells].reshape(t, 2, sk.N_INSOLE_CELLS),
        cell_pos_world=cells,
        origin_world=insole_origin_world(global_rot, joint_pos, body),
        unsupported_force_n=np.where(carried > 0, 0.0, fz),
        zmp_error_m=zmp_err,
        fallback_frames=np.flatnonzero(fallback).astype(np.int64),
        other_support_force_n=forces[:, n_cells:].sum(axis=1),
        zmp_world=zmp,
        other_support=support[:, n_cells:],
    )


def measure_insoles(
    synth: InsoleSynth,
    body: BodyModel,
    cfg: InsoleSynthConfig | None = None,
    noise: NoiseConfig | None = None,
    rng: np.random.Generator | None = None,
) -> InsoleReadings:
    """Insole readings: cell noise, then the derived quantities, then dropped samples.

    Args:
        synth: Clean synthesis from :func:`synthesize_insoles`.
        body: Body model.
        cfg: Insole configuration.
        noise: Noise configuration; None means :meth:`NoiseConfig.off`.
        rng: Random generator; required unless the noise is off.

    Returns:
        The readings (exactly the clean ones when the noise is off).
    """
    noise = noise or NoiseConfig.off()
    if rng is None:
        if not noise.is_off:
            raise ValueError("measure_insoles: a random generator is required when noise is on")
        rng = np.random.default_rng(0)  # never drawn from: every noise term is zero
    cells = corrupt_insole_cells(synth.cell_force_n, body.insole_area_cm2, noise, rng)
    dropped = drop_mask(cells.shape[0], 2, noise.insole_drop_prob, rng)
    return insole_readings_from_cells(
        cells, synth.cell_pos_world, synth.origin_world, body, cfg, dropped
    )
