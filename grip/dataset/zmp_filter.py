"""Dynamic filter: a small horizontal pelvis correction that brings the ZMP onto the feet.

The synthesised insoles reproduce the motion's external wrench exactly (:mod:`prism_tools.synth.
insole`), so wherever a retargeted motion is not dynamically consistent on our body, its
zero-moment point (ZMP) leaves the feet while only the feet carry it, and the cells cannot follow
(docs/insoles_zmp.md, cause 2: pelvis and trunk dynamics at step frequency that do not match our
foot placement). In the spirit of Yamane & Nakamura's dynamics filter, this module changes the
motion a little so that it becomes consistent:

* The correction is a horizontal shift ``d(t)`` of the pelvis (the root), with both feet kept
  where they were by the two-bone leg IK (:func:`grip.motion.retarget_feet.leg_ik`): the upper
  body translates by ``d``, the legs re-bend, the feet do not move.
* Translating a mass share ``alpha`` of the body by ``d`` moves the ZMP by
  ``alpha (d - z d'' / (g + z''))`` (cart-table model, ``z`` the COM height above the support;
  the spin angular momentum does not change under a translation). At step frequency the second
  term dominates: at 2 Hz and ``z`` = 0.9 m a 3 mm shift moves the ZMP by about 4 cm.
* Frames where the feet alone carry the body (:func:`feet_alone_frames`) want the ZMP inside the
  support region: the convex hull of the cells that can take load (support weight above
  ``cell_support``), as the synthesis defines it. Other frames (flight, hands, knees, a seat or
  the back on the ground, no foot down) want nothing: there the ZMP may rightly lie off the feet.
* ``d`` (x and y share one matrix) minimises ::

      sum_t w_t huber(dist(ZMP_t(d), hull_t)) + lambda |d|^2 + mu |d'|^2 + nu |d''|^2
                                                + kappa |d'''|^2

  with ``w_t`` the squared vertical force in body weights (capped at 1; the residual moment is
  ``F_z`` times the ZMP distance) on frames carried by the feet alone, 0 elsewhere, and a Huber
  loss that stops growing quadratically beyond ``huber_m`` (a ZMP far off the feet means
  something the contact rules did not see holds the body). The problem is convex; it is solved
  by majorise-minimise steps (the distance is replaced by the distance to the current nearest
  hull point, each step one sparse banded solve). The linear ZMP model uses the synthesis's own
  Savitzky-Golay second derivative and is refreshed from a new synthesis ``iterations`` times
  (its mass share and heights are approximations); a refresh is kept only when the true
  objective goes down.

:func:`zmp_filter` returns the corrected motion, ``d`` and diagnostics. Measured effect and
settings: docs/insoles_zmp.md ("Dynamic filter").
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from scipy import sparse
from scipy.sparse.linalg import splu
from scipy.spatial import ConvexHull, QhullError

from grip.core import skeleton as sk
from grip.core.body import GRAVITY, BodyModel
from grip.core.fk import center_of_mass, forward_kinematics
from grip.core.rotations import matrix_to_quat
from grip.motion.motion import Motion
from grip.motion.retarget_feet import leg_ik
from prism_tools.synth.config import InsoleSynthConfig
from prism_tools.synth.insole import InsoleSynth, smooth_derivative, synthesize_insoles
from prism_tools.synth.props import infer_props, support_height

__all__ = ["ZmpFilterConfig", "ZmpFilterResult", "feet_alone_frames", "inferred_ground",
           "project_to_hulls", "support_hulls", "zmp_filter"]  # fmt: skip

_ANKLES = (sk.JOINT_INDEX["L_Ankle"], sk.JOINT_INDEX["R_Ankle"])
_MIN_FRAMES = 8  # shorter clips are returned unchanged


@dataclass(frozen=True)
class ZmpFilterConfig:
    """Settings of :func:`zmp_filter`.

    Attributes:
        shift_weight: ``lambda``, weight of ``|d|^2`` against the squared ZMP distance (both
            m^2, summed over frames): a ZMP offset that only a steady shift can remove is
            removed by the share ``alpha^2 / (alpha^2 + lambda)``.
        velocity_weight_s2: ``mu``, weight of ``|d'|^2`` (d' in m/s), s^2.
        accel_weight_s4: ``nu``, weight of ``|d''|^2`` (d'' in m/s^2), s^4: keeps the added
            pelvis acceleration (what the IMUs see of the correction) small and ``d`` smooth.
        jerk_weight_s6: ``kappa``, weight of ``|d'''|^2`` (d''' in m/s^3), s^6: keeps ``d``
            free of content above ~10 Hz (the retarget's low-pass), which the synthesis's
            derivative filter would otherwise let the solve use.
        huber_m: The squared ZMP distance becomes linear beyond this (Huber loss), m: frames
            whose ZMP lies far off the feet (something else holds the body that the contact
            rules did not see) pull no harder than this.
        margin_m: The ZMP is pulled this far inside the hull, m (the cells' hull lies 2-3 cm
            inside the soles, so the target is still under the foot).
        iterations: Refreshes of the linear ZMP model from the synthesis.
        inner_iterations: Majorise-minimise steps per refresh.
        min_force_bw: Frames with a vertical force below this (body weights) want nothing.
        foot_supported: A foot is down when its cells' mean support weight exceeds this.
        cell_support: Cells whose support weight exceeds this span the support region.
        other_contact: A frame is supported by something other than the feet when a body point
            (:func:`prism_tools.synth.insole.body_contact_points`) has a support weight above
            this.
    """

    shift_weight: float = 5.0
    velocity_weight_s2: float = 1e-3
    accel_weight_s4: float = 0.0
    jerk_weight_s6: float = 1e-7
    huber_m: float = 0.1
    margin_m: float = 0.005
    iterations: int = 3
    inner_iterations: int = 10
    min_force_bw: float = 0.2
    foot_supported: float = 0.2
    cell_support: float = 0.1
    other_contact: float = 0.05

    def __post_init__(self) -> None:
        if (
            min(
                self.shift_weight,
                self.velocity_weight_s2,
                self.accel_weight_s4,
                self.jerk_weight_s6,
            )
            < 0
        ):
            raise ValueError("ZmpFilterConfig: the weights must be >= 0")
        if self.shift_weight <= 0:
            raise ValueError("ZmpFilterConfig: shift_weight must be > 0")
        if self.iterations < 1 or self.inner_iterations < 1 or self.margin_m < 0:
            raise ValueError("ZmpFilterConfig: iterations >= 1, inner_iterations >= 1, "
                             "margin_m >= 0")  # fmt: skip


@dataclass(frozen=True)
class ZmpFilterResult:
    """Outcome of :func:`zmp_filter`.

    Attributes:
        motion: The corrected motion (``meta["zmp_filter"]`` holds a summary).
        shift_m: ``(T, 2)`` horizontal pelvis shift ``d``, world x/y, m.
        feet_alone: ``(T,)`` frames where the feet alone carry the body (of the input motion).
        ankle_moved_m: ``(T, 2)`` how far each ankle ended up from where it was (the leg IK
            clamps targets out of reach), m.
        synth_before: Insole synthesis of the input motion.
        synth_after: Insole synthesis of the corrected motion.
    """

    motion: Motion
    shift_m: np.ndarray
    feet_alone: np.ndarray
    ankle_moved_m: np.ndarray
    synth_before: InsoleSynth
    synth_after: InsoleSynth


# ----------------------------------------------------------------------------- support
def feet_alone_frames(synth: InsoleSynth, body: BodyModel,
                      cfg: ZmpFilterConfig | None = None) -> np.ndarray:  # fmt: skip
    """``(T,)`` frames where the feet alone carry the body.

    The rule: the vertical force is at least ``cfg.min_force_bw`` body weights, at least one
    foot is down (its cells' mean support weight above ``cfg.foot_supported``) and no other body
    point (seat, knees, hands, back, ...) can take load (support weight at most
    ``cfg.other_contact``, i.e. it is about 3 cm or more above the ground, or sliding).
    """
    cfg = cfg or ZmpFilterConfig()
    fz_bw = synth.wrench.force_world[:, 2] / (body.total_mass * GRAVITY)
    foot_down = (synth.support.mean(axis=-1) > cfg.foot_supported).any(axis=1)
    others = synth.other_support
    no_other = (others.max(axis=1, initial=0.0) <= cfg.other_contact) if others.size else True
    return (fz_bw >= cfg.min_force_bw) & foot_down & no_other


def support_hulls(cell_xy: np.ndarray, use: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Convex hull of the used cells of each frame, as a padded polygon.

    Args:
        cell_xy: ``(T, P, 2)`` cell positions, m.
        use: ``(T, P)`` cells that span the support region.

    Returns:
        ``(T, V, 2)`` vertices, counter-clockwise, padded by repeating the first vertex, and
        ``(T,)`` the number of vertices: 0 for a frame without cells, 1 or 2 where the cells are
        a point or a line (the padded polygon is then that point or segment).
    """
    t = cell_xy.shape[0]
    polys: list[np.ndarray] = []
    for i in range(t):
        pts = cell_xy[i][use[i]]
        if len(pts) == 0:
            polys.append(np.zeros((0, 2)))
            continue
        try:
            polys.append(pts[ConvexHull(pts).vertices])
        except (QhullError, ValueError):  # fewer than 3 cells, or collinear ones
            axis = pts[-1] - pts[0]
            s = pts @ axis
            polys.append(pts[[int(np.argmin(s)), int(np.argmax(s))]])
    n = np.array([len(p) for p in polys], dtype=np.int64)
    v = max(int(n.max(initial=0)), 1)
    out = np.zeros((t, v, 2))
    for i, poly in enumerate(polys):
        if len(poly):
            out[i, : len(poly)] = poly
            out[i, len(poly) :] = poly[0]
    return out, n


def project_to_hulls(q: np.ndarray, verts: np.ndarray, n_verts: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Nearest point of each frame's polygon (:func:`support_hulls`) to ``q (T, 2)``.

    Returns:
        ``(T, 2)`` the nearest point (``q`` itself inside; ``q`` where a frame has no cells) and
        ``(T,)`` the distance outside (0 inside), m.
    """
    a = verts
    b = np.roll(verts, -1, axis=1)
    ab = b - a
    aq = q[:, None, :] - a
    cross = ab[..., 0] * aq[..., 1] - ab[..., 1] * aq[..., 0]
    inside = (cross >= 0).all(axis=1) & (n_verts >= 3)
    len2 = np.sum(ab * ab, axis=-1)
    s = np.clip(np.sum(aq * ab, axis=-1) / np.where(len2 > 0, len2, 1.0), 0.0, 1.0)
    near = a + s[..., None] * ab
    dist = np.linalg.norm(q[:, None, :] - near, axis=-1)
    k = np.argmin(dist, axis=1)
    rows = np.arange(len(q))
    proj = np.where((inside | (n_verts == 0))[:, None], q, near[rows, k])
    out = np.where(inside | (n_verts == 0), 0.0, dist[rows, k])
    return proj, out


# ------------------------------------------------------------------------------- the solve
def _difference(t: int, fps: float, order: int) -> sparse.csr_matrix:
    """``(T - order, T)`` forward difference of the given order, per s^order."""
    coef = np.array([1.0])
    for _ in range(order):
        coef = np.convolve(coef, [-1.0, 1.0])
    n = t - order
    return sparse.diags([np.full(n, c) for c in coef], list(range(order + 1)),
                        shape=(n, t)).tocsr() * fps**order  # fmt: skip


def _acceleration_operator(t: int, fps: float, cfg: InsoleSynthConfig) -> sparse.csr_matrix:
    """``(T, T)`` matrix of the synthesis's second derivative (the Savitzky-Golay filter of
    :func:`~prism_tools.synth.insole.smooth_derivative`, ends included), found by probing the
    filter with combs of unit impulses far enough apart not to overlap."""

    def op(x: np.ndarray) -> np.ndarray:
        return smooth_derivative(x, fps, cfg.smoothing_window_s, cfg.smoothing_polyorder, 2)

    w = round(cfg.smoothing_window_s * fps) + cfg.smoothing_polyorder + 3
    m = 2 * w + 1  # a column reaches at most w - 1 rows away (the end rows' polynomial fits)
    if m >= t:
        return sparse.csr_matrix(op(np.eye(t)))
    rows = np.arange(t)
    probes = np.zeros((t, m))
    probes[rows, rows % m] = 1.0
    resp = op(probes)  # (T, m)
    k = np.arange(m)
    cols = rows[:, None] + (k[None, :] - rows[:, None] + m // 2) % m - m // 2  # nearest j = k mod m
    ok = (cols >= 0) & (cols < t) & (resp != 0)
    return sparse.csr_matrix((resp[ok], (np.broadcast_to(rows[:, None], cols.shape)[ok],
                                         cols[ok])), shape=(t, t))  # fmt: skip


def _huber(x: np.ndarray, c: float) -> np.ndarray:
    """``x^2`` up to ``c``, then linear (``2 c x - c^2``)."""
    return np.where(x <= c, x * x, 2 * c * x - c * c)


def _moving_share(local: np.ndarray, root: np.ndarray, body: BodyModel) -> float:
    """Share of the body's mass that a pelvis shift with planted feet translates (median over
    frames of the COM shift per unit pelvis shift, from a 1 cm test shift)."""
    step = np.array([0.01, 0.0, 0.0])
    c0 = center_of_mass(*forward_kinematics(local, root, body.offsets), body)
    local1, root1 = _shifted(local, root, body, np.broadcast_to(step[:2], (len(root), 2)))
    c1 = center_of_mass(*forward_kinematics(local1, root1, body.offsets), body)
    return float(np.clip(np.median(c1[:, 0] - c0[:, 0]) / step[0], 0.3, 1.0))


def _shifted(local: np.ndarray, root: np.ndarray, body: BodyModel, d: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Local rotations and root with the pelvis shifted by ``d (T, 2)`` and the feet kept."""
    shift = np.zeros_like(root)
    shift[:, :2] = d
    new_root = root + shift
    disp = np.repeat(-shift[:, None, :], 2, axis=1)
    return leg_ik(local, new_root, body, disp), new_root


def inferred_ground(motion: Motion) -> Callable[[np.ndarray], np.ndarray] | None:
    """The ground the sensor synthesis stands ``motion`` on: the props inferred from it
    (:func:`prism_tools.synth.props.infer_props`, as
    :func:`~prism_tools.synth.recording.synthesize_sensors` does), None on flat ground."""
    body = motion.body_model()
    g, p = motion.fk(body)
    props = infer_props(g, p, body, motion.fps)
    return functools.partial(support_height, props) if props else None


def zmp_filter(
    motion: Motion,
    cfg: ZmpFilterConfig | None = None,
    synth_cfg: InsoleSynthConfig | None = None,
    ground: Callable[[np.ndarray], np.ndarray] | None = None,
) -> ZmpFilterResult:
    """Shift the pelvis horizontally, feet kept, so that the ZMP stays on the feet where they
    alone carry the body (module docstring).

    Args:
        motion: A retargeted motion (z-up world, floor z = 0).
        cfg: Filter settings.
        synth_cfg: Insole synthesis settings (smoothing window, contact ramps) used to compute
            the ZMP and the support, as the recordings will be synthesised.
        ground: Height of the ground under points (the motion's props), as for
            :func:`prism_tools.synth.insole.synthesize_insoles`; None: the flat floor.

    Returns:
        The corrected motion, the shift and diagnostics. Clips shorter than 8 frames, without a
        frame carried by the feet alone or that no shift improves come back unchanged (zero
        shift).
    """
    cfg = cfg or ZmpFilterConfig()
    synth_cfg = synth_cfg or InsoleSynthConfig()
    body = motion.body_model()
    fps = float(motion.fps)
    local0 = motion.local_rot()
    root0 = np.asarray(motion.root_pos, dtype=np.float64)
    t = root0.shape[0]
    g, p = forward_kinematics(local0, root0, body.offsets)
    before = synthesize_insoles(g, p, body, fps, synth_cfg, ground)
    feet = feet_alone_frames(before, body, cfg)
    d = np.zeros((t, 2))
    if t < _MIN_FRAMES or not feet.any():
        return ZmpFilterResult(motion, d, feet, np.zeros((t, 2)), before, before)

    cells = before.cell_pos_world[..., :2].reshape(t, -1, 2)
    use = (before.support.reshape(t, -1) > cfg.cell_support) & feet[:, None]
    verts, n_verts = support_hulls(cells, use)
    alpha = _moving_share(local0, root0, body)
    plane = np.zeros(t)  # height of the ground the ZMP is taken on (props)
    if ground is not None:
        sup = before.support.reshape(t, -1)
        tot = sup.sum(axis=1)
        under = ground(before.cell_pos_world.reshape(t, -1, 3))
        plane = np.where(tot > 0, np.sum(sup * under, axis=1) / np.maximum(tot, 1e-12),
                         0.0)  # fmt: skip
    # Frames weigh by their vertical force squared (the residual moment is F_z times the ZMP
    # distance), capped at one body weight; a push-off at 0.2 body weights counts little.
    fz_bw = before.wrench.force_world[:, 2] / (body.total_mass * GRAVITY)
    w = np.where(feet, np.minimum(fz_bw, 1.0) ** 2, 0.0)
    reg = cfg.shift_weight * sparse.identity(t)
    for order, weight in enumerate((cfg.velocity_weight_s2, cfg.accel_weight_s4,
                                    cfg.jerk_weight_s6), start=1):  # fmt: skip
        if weight > 0 and t > order:
            dk = _difference(t, fps, order)
            reg = reg + weight * (dk.T @ dk)
    acc_op = _acceleration_operator(t, fps, synth_cfg)
    c = cfg.huber_m

    def objective(zmp: np.ndarray, shift: np.ndarray) -> float:
        out = project_to_hulls(zmp, verts, n_verts)[1]
        data = _huber(np.where(out > 0, out + cfg.margin_m, 0.0), c)
        return float(np.sum(w * data) + np.sum(shift * (reg @ shift)))

    synth, local, root = before, local0, root0
    best = objective(synth.zmp_world, d)
    for _ in range(cfg.iterations):
        # Linear model of the ZMP change per unit extra shift: alpha (I - diag(h) S2), S2 the
        # synthesis's own second derivative and h = z / (g + z'') from the current motion.
        com = synth.wrench.com_world
        z = np.maximum(com[:, 2] - plane, 0.05)
        zdd = acc_op @ com[:, 2]
        h = z / np.maximum(GRAVITY + zdd, 0.3 * GRAVITY)
        a_mat = (alpha * (sparse.identity(t) - sparse.diags(h) @ acc_op)).tocsr()
        lu = splu((a_mat.T @ sparse.diags(w) @ a_mat + reg).tocsc())
        zmp = synth.zmp_world
        delta = np.zeros((t, 2))
        for _inner in range(cfg.inner_iterations):
            # Majorise-minimise: pull each frame's predicted ZMP towards its nearest hull point
            # (plus the margin), by at most huber_m (the Huber loss's quadratic majoriser).
            pred = zmp + a_mat @ delta
            near, out = project_to_hulls(pred, verts, n_verts)
            gap = near - pred
            unit = gap / np.maximum(out, 1e-12)[:, None]
            gap = gap + cfg.margin_m * unit * (out > 0)[:, None]
            size = np.linalg.norm(gap, axis=1)
            gap *= np.minimum(1.0, c / np.maximum(size, 1e-12))[:, None]
            err = zmp - (pred + gap)
            delta = lu.solve(-(a_mat.T @ (w[:, None] * err)) - reg @ d)
        # Keep the step only if the true objective (from a new synthesis) goes down.
        for step in (1.0, 0.5, 0.25):
            trial = d + step * delta
            local_t, root_t = _shifted(local0, root0, body, trial)
            g, p = forward_kinematics(local_t, root_t, body.offsets)
            synth_t = synthesize_insoles(g, p, body, fps, synth_cfg, ground)
            value = objective(synth_t.zmp_world, trial)
            if value < best:
                break
        else:
            break
        best, d, local, root, synth = value, trial, local_t, root_t, synth_t

    if not np.any(d):
        return ZmpFilterResult(motion, d, feet, np.zeros((t, 2)), before, before)
    p = forward_kinematics(local, root, body.offsets)[1]
    p0 = forward_kinematics(local0, root0, body.offsets)[1]
    ankle_moved = np.linalg.norm(p[:, _ANKLES] - p0[:, _ANKLES], axis=-1)
    mag = np.linalg.norm(d, axis=1)
    meta = dict(motion.meta)
    meta["zmp_filter"] = {
        "shift_median_m": float(np.median(mag)),
        "shift_max_m": float(mag.max()),
        "ankle_moved_max_m": float(ankle_moved.max()),
        "feet_alone_frames": int(feet.sum()),
        "moving_mass_share": alpha,
        "config": {k: getattr(cfg, k) for k in cfg.__dataclass_fields__},
    }
    out = replace(motion, root_pos=root, local_quat=matrix_to_quat(local), meta=meta)
    return ZmpFilterResult(out, d, feet, ankle_moved, before, synth)
