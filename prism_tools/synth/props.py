"""Support surfaces (props) inferred from a motion: the boxes a clip stands or sits on.

Motion capture of stepping onto stairs or sitting on a stool records the body, not the prop. A
flat floor then cannot carry the motion: the feet stand in the air, the pelvis rests on
nothing. This module finds the surfaces the motion needs and returns them as boxes resting on
the floor (PRISM ``objects``, :class:`prism_tools.streams.SceneObject`), which the synthesis
(insole contact heights) and the simulation (terrain height field) then use.

Two kinds of evidence, both from the ground-truth motion alone:

1. **A foot planted above the floor.** Per foot and frame the 16 insole cells
   (:func:`prism_tools.synth.insole.insole_cell_positions`) give the sole: planted when it is
   flat (cell heights within :data:`FLAT_M`) and still (horizontal and vertical speed below
   :data:`PLANTED_SPEED_M_S`). A planted run of at least :data:`MIN_PLANTED_S` whose median
   height lies :data:`MIN_HEIGHT_M` or more above the clip's floor level (the low percentile of
   all planted soles, so that a motion whose feet float a few centimetres makes no props) is a
   step's evidence (when the pelvis stands :data:`PELVIS_ABOVE_FOOT_M` above it). Runs of
   about the same height (:data:`MERGE_HEIGHT_M`) whose soles come within :data:`MERGE_GAP_M`
   of each other are one step (both feet on it, repeated visits); its top is their mean
   height (weighted by their lengths), and its boxes are to hold every insole cell of its runs
   (those not hanging more than :data:`INSIDE_M` below it, over an edge), reaching
   :data:`PAD_M` beyond them and their soles' outlines.
2. **A seat.** The pelvis is still for at least :data:`MIN_SEATED_S`, the torso upright above it
   (:data:`TORSO_ABOVE_SEAT_M`) and the thighs flexed (:data:`SEATED_THIGH_DEG`), while the
   whole-body centre of mass lies more than :data:`COM_OUTSIDE_M` outside the hull of the soles
   on the ground: the feet cannot hold the body up alone, so something under the pelvis and
   thighs does. Each sitting episode (the frames of one stretch of flexed thighs: standing up
   ends it) gets its own seat: its top at the median height of the lowest point of the
   buttocks (the pelvis shape and the proximal :data:`SEAT_THIGH_SHARE` of the thighs), under
   every pelvis and thigh point that rests at that height (:data:`REST_M`) plus
   :data:`SEAT_MARGIN_M`: the thighs as far as they are level. Seats lower than
   :data:`MIN_HEIGHT_M` are the floor (sitting or lying on it needs no prop).

No prop may hold the body: at no frame may a shape of the body (a sphere every
:data:`SAMPLE_M` along each limb and trunk capsule, the soles' outlines and insole cells) reach
more than :data:`INSIDE_M` (a seat: :data:`SEAT_INSIDE_M`) below its top over it, and no step
may cover a place where a sole is planted lower than its top: where the evidence and the body
disagree (a heel over a step's edge where the other foot stood on the floor), the body wins. A
prop is therefore the rectangle, among those that keep :data:`CUT_MARGIN_M` from every such
shape, that holds the most of its evidence (the largest of those), on a grid of
:data:`FREE_CELL_M`; a step whose evidence one rectangle cannot hold gets up to
:data:`MAX_STEP_BOXES` of them. Props narrower than :data:`MIN_TOP_M` are dropped. Then each
step's top reaches toward the nearest higher step beside it (a gap up to :data:`MAX_GAP_M`)
until it meets it or a shape of the body: a flight of steps leaves no gap a sole could stand
over. (A body shape is a sphere of the capsule's radius: it keeps a prop clear by its
cross-section at the prop's height, which the lowest points alone miss: a thigh standing in
front of a stool reaches its radius toward it.)

A seat that the body reaches under (a high stool: the legs stand in front of it before sitting,
the feet tuck under it onto its rungs) is a slab instead, where that holds more of its
evidence: :data:`SLAB_M` thick, open underneath (``Prop.bottom_m`` > 0). Only shapes that reach
into it (above :data:`UNDER_M` under its underside) keep it out; everything lower passes under
it. The simulation collides with it as a static geom (it needs no legs), and points under it
stand on the floor (:func:`support_height` with heights).

A body whose soles never come within :data:`FLOATING_M` of the floor is refused: where nothing
touches the floor, the floor level and so the props cannot be told.

Every threshold is a module constant with its reason; none is a setting to tune.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grip.core import skeleton as sk
from grip.core.body import BodyModel
from grip.core.fk import center_of_mass, sole_points
from prism_tools.streams import SceneObject, box_object
from prism_tools.synth.insole import insole_cell_positions, smooth_derivative

__all__ = ["Prop", "body_shapes", "infer_props", "props_as_objects", "support_height"]

FLAT_M = 0.08
"""A planted sole's 16 cells lie within this height range: a foot on a stair's edge tilts ~7 cm
heel to toe (CMU 13_35); a pointed foot (a leg held up) tilts more."""
PLANTED_SPEED_M_S = 0.15
"""Above this speed of the sole's centre (horizontal or vertical) the foot is moving."""
MIN_PLANTED_S = 0.25
"""Shortest planted run that counts as standing on something (a touch of the toe does not)."""
MIN_HEIGHT_M = 0.08
"""Supports lower than this above the floor level are the floor: retargeted feet float up to
6 cm in stance (``InsoleSynthConfig.contact_float_tolerance_m``), the lowest step is ~15 cm."""
PELVIS_ABOVE_FOOT_M = 0.25
"""A foot that carries the body has the pelvis at least this far above it (standing on a step:
~0.8 m; perched with a foot on a stool's rung: ~0.3 m); a still foot level with the pelvis is a
leg lying on the floor or held up, not standing on anything."""
FLOATING_M = 0.5
"""A body whose soles never come this close to the floor (z = 0) floats: its supports cannot be
told from its position (a clip 6.4 m up made a 6.8 m tower), so it is refused. Retargeted feet
float a few centimetres; ten times that is no floor contact at all."""
FLOOR_PERCENTILE = 5.0
"""The clip's floor level: this percentile of the heights of all planted soles."""
MIN_SEATED_S = 0.5
"""Shortest still, unsupported pelvis that counts as sitting."""
SEATED_SPEED_M_S = 0.1
"""Above this pelvis speed the body is not resting on a seat."""
COM_OUTSIDE_M = 0.05
"""The centre of mass this far outside the hull of the soles on the ground needs another support
(inside it, a still pose stands on its feet: a squat, a bow)."""
TORSO_ABOVE_SEAT_M = 0.15
"""A seated torso's joints (spine, neck, collars, head) stay at least this far above the seat:
sitting upright they are 0.24 m or more above it; lying or leaning back on the floor they are
not, and then the back, not a prop, carries the body."""
TORSO_JOINTS: tuple[int, ...] = (3, 6, 9, 12, 13, 14, 15)
"""Spine1, Spine2, Spine3, Neck, L_Collar, R_Collar, Head (``grip.core.skeleton.JOINT_NAMES``)."""
SEATED_THIGH_DEG = 45.0
"""Seated thighs point at least this far from straight down (perched on a high stool ~67 deg,
on a stepstool ~100 deg, CMU 13_01 and 14_31); a standing leg (~10 deg) is not on a seat, even
when the retargeted centre of mass strays outside the feet (a held dance pose)."""
GROUND_SOLE_M = 0.03
"""Cells within this of the frame's lowest cell are the soles on the ground."""
SEAT_THIGH_SHARE = 0.05
"""The buttocks: the pelvis shape and this proximal share of each thigh rest on the seat however
the thighs slope (perched on a stool's edge, CMU 13_01, the thighs fall 1.4 cm per tenth of
their length; the points beyond the buttocks rest only where the thighs are level)."""
REST_M = 0.03
"""Pelvis and thigh points up to this above a seat's top rest on it (level thighs: CMU 13_01's
second sitting, 2 cm from hip to knee); the seat reaches under them."""
SEAT_MARGIN_M = 0.05
"""The seat reaches this far beyond the pelvis and thigh points that rest on it."""
MERGE_HEIGHT_M = 0.05
"""Planted runs whose heights differ by less than this are the same step (one step's runs
spread a few centimetres; steps of a staircase differ by 15-20 cm)."""
MERGE_GAP_M = 0.3
"""... when their soles come closer than this (both feet on a step, a second visit)."""
CUT_MARGIN_M = 0.02
"""A prop stops this far from a body shape that it would otherwise hold."""
PAD_M = 0.01
"""A step reaches this far beyond the planted soles' insole cells and outlines."""
INSIDE_M = 0.06
"""A body shape reaching this far below a step's top, over it, is inside the step. Soles
resting on a step lie up to :data:`MERGE_HEIGHT_M` below its top (its runs' heights spread that
much); a swinging foot in front of a step, or one on the floor beside it, lies lower."""
SEAT_INSIDE_M = 0.03
"""The same for a seat: its top is its own sitting's buttocks' median lowest point, which varies
by a centimetre or two while seated; a thigh standing in front of a stool lies 10-20 cm below
it, a thigh sloping off its edge more than this below it where it stops resting."""
SAMPLE_M = 0.02
"""Spacing of the spheres sampled along each limb and trunk capsule: the body's shapes are
checked against the props densely enough that a 5 cm slab cannot pass between two samples."""
MIN_TOP_M = 0.1
"""A prop narrower than this (either side of its top) carries nothing and is dropped."""
FREE_CELL_M = 0.01
"""Grid of the search for a prop's rectangle."""
MAX_STEP_BOXES = 3
"""Boxes of one step at most: where the body stood inside the rectangle of a step's soles at
other frames (the other foot on the floor beside a narrow step), the rest of its soles gets a
box of its own."""
MAX_GAP_M = 0.4
"""A gap up to this (about a tread) between a step and a higher one beside it is filled: a sole
could stand over it. Wider gaps are floor between separate props."""
SLAB_M = 0.05
"""Thickness of an open-underside seat (a stool's top, 3-5 cm)."""
UNDER_M = 0.03
"""Body shapes pass under a slab with this clearance."""
REACH_M = 0.06
"""A sole point (outline or insole cell) reaches this far above itself: the foot's thickness
(its box, 7.6 cm on a 1.7 m body, less the sole's rounding). A foot on a rung 30-40 cm below a
stool's top passes under it; a foot lifted to the slab's underside reaches into it."""


@dataclass(frozen=True)
class Prop:
    """A box resting on the floor, or a slab open underneath (a stool's seat).

    Attributes:
        lo: ``(2,)`` minimum x, y of its top, m (world frame, z up).
        hi: ``(2,)`` maximum x, y, m.
        height_m: Top above the floor (z = 0), m.
        kind: ``"step"`` (feet stood on it) or ``"seat"`` (the pelvis rested on it).
        frames: Frames supported by it (a step's boxes: all of the step's).
        bottom_m: Its underside above the floor, m: 0 for a box, ``height_m - SLAB_M`` for a
            seat the body reaches under.
    """

    lo: np.ndarray
    hi: np.ndarray
    height_m: float
    kind: str
    frames: int
    bottom_m: float = 0.0

    def contains(self, xy: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Whether points ``(..., 2)`` lie over the top (grown by ``margin``)."""
        return np.all((xy >= self.lo - margin) & (xy <= self.hi + margin), axis=-1)


def _runs(mask: np.ndarray, min_len: int) -> list[slice]:
    """Slices of the runs of True at least ``min_len`` long."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    return [slice(a, b) for a, b in zip(starts, stops, strict=True) if b - a >= min_len]


def horizontal_speed(x: np.ndarray, fps: float) -> np.ndarray:
    """``(T,)`` speed of ``x (T, D)`` (Savitzky-Golay, 0.1 s)."""
    return np.linalg.norm(smooth_derivative(x, fps, 0.1, 2, deriv=1), axis=-1)


def planted_feet(cells: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """``(T, 2)`` planted flags and ``(T, 2)`` median sole heights of both feet."""
    z = cells[..., 2]
    height = np.median(z, axis=-1)
    flat = z.max(-1) - z.min(-1) < FLAT_M
    planted = np.empty_like(flat)
    for f in range(2):
        centre = np.concatenate([cells[:, f, :, :2].mean(1), height[:, f, None]], -1)
        planted[:, f] = flat[:, f] & (horizontal_speed(centre, fps) < PLANTED_SPEED_M_S)
    return planted, height


# ------------------------------------------------------------------------------- body shapes
def body_shapes(
    global_rot: np.ndarray, joint_pos: np.ndarray, body: BodyModel
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The limb and trunk shapes as spheres: each capsule sampled every :data:`SAMPLE_M` or
    closer along its axis (ends included), each sphere itself; the feet and toes are left to
    their soles.

    Returns:
        ``(T, K, 3)`` centres, world frame, m; ``(K,)`` radii, m; ``(K,)`` carrying body;
        ``(K,)`` position along the capsule (0 proximal end, 1 distal end; 0.5 for a sphere).
    """
    feet = {*sk.FOOT_BODY.values(), *sk.TOE_BODY.values()}
    bodies, local, radius, where = [], [], [], []
    for g in body.geoms:
        if g.body in feet or g.kind == "box":
            continue
        if g.kind == "sphere":
            frac = np.array([0.5])
            pts = g.pos[None]
        else:
            a, b = g.fromto()[:3], g.fromto()[3:]
            frac = np.linspace(0.0, 1.0, max(2, int(np.ceil(np.linalg.norm(b - a) / SAMPLE_M)) + 1))
            pts = a + frac[:, None] * (b - a)
        local.append(pts), where.append(frac)
        bodies += [g.body] * len(frac)
        radius += [g.size[0]] * len(frac)
    bodies_a, local_a = np.asarray(bodies), np.concatenate(local)
    out = np.empty((*joint_pos.shape[:-2], len(bodies_a), 3))
    for j in np.unique(bodies_a):  # one body at a time: no (T, K, 3, 3) rotation copies
        k = bodies_a == j
        out[..., k, :] = joint_pos[..., j, None, :] + np.einsum(
            "...ij,kj->...ki", global_rot[..., j, :, :], local_a[k]
        )
    return out, np.asarray(radius), bodies_a, np.concatenate(where)


@dataclass(frozen=True)
class _Shapes:
    """Every body shape at every frame, to keep the props out of: ``centre (T, K, 3)``, and per
    shape its ``radius (K,)`` and ``reach (K,)``, how far it stands up from its centre (a sole
    point: :data:`REACH_M`; a sphere: 0)."""

    centre: np.ndarray
    radius: np.ndarray
    reach: np.ndarray

    def inside(self, lo: np.ndarray, hi: np.ndarray, z0: float,
               z1: float) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
        """The shapes that reach the heights ``[z0, z1]`` near ``[lo, hi]`` (within their
        radius and :data:`CUT_MARGIN_M`): ``(N, 2)`` their centres and ``(N,)`` the half width
        of their cross-section there, m."""
        grow = float(self.radius.max(initial=0.0)) + CUT_MARGIN_M
        c = self.centre
        near = np.all((c[..., :2] >= lo - grow) & (c[..., :2] <= hi + grow), axis=-1)
        t, k = np.nonzero(near)
        z = c[t, k, 2]
        d = np.maximum(0.0, np.maximum(z - z1, z0 - z - self.reach[k]))
        hit = d <= self.radius[k]
        r, d = self.radius[k][hit], d[hit]
        return c[t[hit], k[hit], :2], np.sqrt(np.maximum(r * r - d * d, 0.0))


# ------------------------------------------------------------------------------- rectangles
def _raster(lo: np.ndarray, hi: np.ndarray, xy: np.ndarray,
            width: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """``(nx, ny)`` cells of :data:`FREE_CELL_M` over ``[lo, hi]`` holding a point of
    ``xy (N, 2)``, or, with ``width``, within each point's width plus :data:`CUT_MARGIN_M`."""
    from scipy.ndimage import binary_dilation

    n = np.maximum(np.ceil((hi - lo) / FREE_CELL_M - 1e-9).astype(int), 1)
    if width is None:
        grow = np.zeros(len(xy), dtype=int)
    else:  # each point's width in cells
        grow = np.ceil((width + CUT_MARGIN_M) / FREE_CELL_M).astype(int)
    out = np.zeros(n, dtype=bool)
    ij = np.floor((xy - lo) / FREE_CELL_M).astype(int)
    for k in np.unique(grow):
        pad = np.zeros(n + 2 * k, dtype=bool)
        sel = ij[grow == k] + k
        sel = sel[np.all((sel >= 0) & (sel < n + 2 * k), axis=1)]
        pad[sel[:, 0], sel[:, 1]] = True
        if k:
            g = np.arange(-k, k + 1)
            pad = binary_dilation(pad, g[:, None] ** 2 + g[None, :] ** 2 <= k * k)
        out |= pad[k : k + n[0], k : k + n[1]]
    return out


def _best_rect(free: np.ndarray, need: np.ndarray) -> tuple[int, int, int, int] | None:
    """``(i0, i1, j0, j1)`` cells of the rectangle of ``free`` cells at least :data:`MIN_TOP_M`
    wide that holds the most ``need`` cells (the largest of those), or ``None`` where none holds
    any: the maximal free rectangles, from the histograms of free runs (row by row)."""
    n0, n1 = free.shape
    m = round(MIN_TOP_M / FREE_CELL_M)
    cs = np.zeros((n0 + 1, n1 + 1))
    cs[1:, 1:] = need.cumsum(0).cumsum(1)
    best, run = (0.0, 0, None), np.zeros(n0, dtype=int)
    for j in range(n1):
        run = np.where(free[:, j], run + 1, 0)
        stack: list[int] = []
        for i in range(n0 + 1):
            h = run[i] if i < n0 else 0
            while stack and run[stack[-1]] >= h:
                height = run[stack.pop()]
                left = stack[-1] + 1 if stack else 0
                if height < m or i - left < m:
                    continue
                j0 = j + 1 - height
                got = cs[i, j + 1] - cs[left, j + 1] - cs[i, j0] + cs[left, j0]
                if got > 0 and (got, height * (i - left)) > best[:2]:
                    best = (got, height * (i - left), (left, i, j0, j + 1))
            stack.append(i)
    return best[2]


def _cover(lo: np.ndarray, hi: np.ndarray, need_xy: np.ndarray, bad_xy: np.ndarray,
           bad_width: np.ndarray, boxes: int) -> list[tuple]:  # fmt: skip
    """Up to ``boxes`` rectangles inside ``[lo, hi]`` that keep clear of the shapes
    ``bad_xy (N, 2)`` (half widths ``bad_width``) and together hold the most of the points
    ``need_xy (M, 2)``, each the largest that holds its share: ``(lo, hi, need cells held)``."""
    free = ~_raster(lo, hi, bad_xy, bad_width)
    need = _raster(lo, hi, need_xy)
    out = []
    while len(out) < boxes:
        rect = _best_rect(free, need)
        if rect is None:
            break
        i0, i1, j0, j1 = rect
        out.append((lo + FREE_CELL_M * np.array([i0, j0]),
                    np.minimum(lo + FREE_CELL_M * np.array([i1, j1]), hi),
                    int(need[i0:i1, j0:j1].sum())))  # fmt: skip
        need[i0:i1, j0:j1] = False
    return out


# ------------------------------------------------------------------------------- steps
def _step_groups(cells: np.ndarray, soles: np.ndarray, planted: np.ndarray, height: np.ndarray,
                 pelvis_z: np.ndarray, fps: float, floor: float) -> list[dict]:  # fmt: skip
    """The planted runs above the floor joined into steps: ``{"heights", "frames", "cells"
    (N, 3), "outline" (M, 3), "lo", "hi"}`` per step (the insole cells and sole outlines of its
    runs, their outlines' extent)."""
    runs = []
    for f in range(2):
        for run in _runs(planted[:, f], round(MIN_PLANTED_S * fps)):
            h = float(np.median(height[run, f]))
            if h - floor >= MIN_HEIGHT_M and np.median(pelvis_z[run]) - h >= PELVIS_ABOVE_FOOT_M:
                runs.append((h, run.stop - run.start, cells[run, f].reshape(-1, 3),
                             soles[run, f].reshape(-1, 3)))  # fmt: skip
    groups: list[dict] = []
    for h, n, c, o in sorted(runs, key=lambda r: r[0]):
        lo, hi = o[:, :2].min(0), o[:, :2].max(0)
        for g in groups:
            near = np.all(lo <= g["hi"] + MERGE_GAP_M) and np.all(hi >= g["lo"] - MERGE_GAP_M)
            if near and abs(np.average(g["heights"], weights=g["frames"]) - h) < MERGE_HEIGHT_M:
                g["lo"], g["hi"] = np.minimum(g["lo"], lo), np.maximum(g["hi"], hi)
                g["cells"], g["outline"] = np.vstack([g["cells"], c]), np.vstack([g["outline"], o])
                g["heights"].append(h), g["frames"].append(n)
                break
        else:
            groups.append({"heights": [h], "frames": [n], "cells": c, "outline": o, "lo": lo,
                           "hi": hi})  # fmt: skip
    return groups


def _lower_soles(low: tuple[np.ndarray, np.ndarray], h: float) -> np.ndarray:
    """``(N, 2)`` the planted insole cells ``low`` (``(N, 2)`` cells, ``(N,)`` their soles'
    heights) of soles planted lower than a step's top ``h``: no step covers them."""
    return low[0][low[1] < h - MERGE_HEIGHT_M]


def _step_boxes(group: dict, shapes: _Shapes, low: tuple[np.ndarray, np.ndarray]) -> list[Prop]:
    """A step's boxes (module docstring): they hold its runs' insole cells (those not hanging
    over an edge) and keep clear of the body and of lower planted soles."""
    h = float(np.average(group["heights"], weights=group["frames"]))
    cells = group["cells"][group["cells"][:, 2] >= h - INSIDE_M, :2]
    outline = group["outline"][group["outline"][:, 2] >= h - INSIDE_M, :2]
    if not len(cells):
        return []
    ext = np.vstack([cells, outline])
    lo, hi = ext.min(0) - PAD_M, ext.max(0) + PAD_M
    bad, width = shapes.inside(lo, hi, -np.inf, h - INSIDE_M)
    lower = _lower_soles(low, h)
    boxes = _cover(lo, hi, cells, np.vstack([bad, lower]),
                   np.concatenate([width, np.zeros(len(lower))]), MAX_STEP_BOXES)  # fmt: skip
    return [Prop(a, b, h, "step", int(sum(group["frames"]))) for a, b, _ in boxes]


def _fill_gaps(steps: list[Prop], shapes: _Shapes,
               low: tuple[np.ndarray, np.ndarray]) -> list[Prop]:  # fmt: skip
    """Each step's top reaches toward the nearest higher step beside it (along x or y, across
    a gap up to :data:`MAX_GAP_M`, where their sides overlap) until it meets it, or stops
    :data:`CUT_MARGIN_M` short of a body shape inside it or a lower planted sole."""
    out = []
    for a in steps:
        lo, hi = a.lo.copy(), a.hi.copy()
        for axis in (0, 1):
            o = 1 - axis
            for sign in (1.0, -1.0):
                ahead = [
                    b
                    for b in steps
                    if b.height_m > a.height_m + MERGE_HEIGHT_M
                    and min(a.hi[o], b.hi[o]) > max(a.lo[o], b.lo[o])
                    and (b.hi[axis] > a.hi[axis] if sign > 0 else b.lo[axis] < a.lo[axis])
                ]
                gap = min((b.lo[axis] - a.hi[axis] if sign > 0 else a.lo[axis] - b.hi[axis]
                           for b in ahead), default=0.0)  # fmt: skip
                if not 0.0 < gap <= MAX_GAP_M:  # (none, or one already meets it)
                    continue
                s_lo, s_hi = a.lo.copy(), a.hi.copy()  # the strip across the gap
                if sign > 0:
                    s_lo[axis], s_hi[axis] = a.hi[axis], a.hi[axis] + gap
                else:
                    s_lo[axis], s_hi[axis] = a.lo[axis] - gap, a.lo[axis]
                bad, width = shapes.inside(s_lo, s_hi, -np.inf, a.height_m - INSIDE_M)
                lower = _lower_soles(low, a.height_m)
                blocked = _raster(s_lo, s_hi, np.vstack([bad, lower]),
                                  np.concatenate([width, np.zeros(len(lower))]))  # fmt: skip
                rows = blocked.any(axis=o)[:: int(sign)]  # from the step outwards
                free = int(np.argmax(rows)) if rows.any() else None
                if sign > 0:
                    hi[axis] = s_hi[axis] if free is None else s_lo[axis] + FREE_CELL_M * free
                else:
                    lo[axis] = s_lo[axis] if free is None else s_hi[axis] - FREE_CELL_M * free
        out.append(Prop(lo, hi, a.height_m, a.kind, a.frames, a.bottom_m))
    return out


# ------------------------------------------------------------------------------- seats
def _outside_hull(p: np.ndarray, q: np.ndarray) -> float:
    """Distance of point ``p (2,)`` outside the convex hull of ``q (N, 2)`` (0 inside); the
    distance to the nearest point when the hull is degenerate."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = ConvexHull(q)
    except (QhullError, ValueError):
        return float(np.min(np.linalg.norm(q - p, axis=-1)))
    # Each facet: n . x + c <= 0 inside; the largest violation bounds the distance from below,
    # and equals it wherever the nearest hull point lies on a facet's interior.
    return float(max(0.0, np.max(hull.equations[:, :2] @ p + hull.equations[:, 2])))


def _sittings(global_rot: np.ndarray, joint_pos: np.ndarray, body: BodyModel, cells: np.ndarray,
              fps: float, low: np.ndarray, seat_k: np.ndarray) -> list[np.ndarray]:  # fmt: skip
    """The frames of each sitting episode: those where the body sits unsupported by its feet
    within one stretch of flexed thighs holding such a run of :data:`MIN_SEATED_S`.
    ``low (T, K)``: the lowest points of the body shapes, ``seat_k (K,)``: the pelvis' and the
    proximal halves of the thighs'."""
    still = horizontal_speed(joint_pos[:, 0], fps) < SEATED_SPEED_M_S
    com = center_of_mass(global_rot, joint_pos, body)
    z = cells[..., 2].reshape(len(cells), -1)
    flat = cells[..., :2].reshape(len(cells), -1, 2)
    upright = (joint_pos[:, TORSO_JOINTS, 2].min(1) - low[:, seat_k].min(1)) >= TORSO_ABOVE_SEAT_M
    thigh = joint_pos[:, (4, 5)] - joint_pos[:, (1, 2)]  # hips -> knees
    down = -thigh[..., 2] / np.maximum(np.linalg.norm(thigh, axis=-1), 1e-9)
    flexed = np.degrees(np.arccos(np.clip(down, -1.0, 1.0))).mean(1) >= SEATED_THIGH_DEG
    needs = np.zeros(len(cells), dtype=bool)
    for t in np.flatnonzero(still & upright & flexed):
        ground = z[t] <= z[t].min() + GROUND_SOLE_M
        needs[t] = _outside_hull(com[t, :2], flat[t, ground]) > COM_OUTSIDE_M
    n_min = round(MIN_SEATED_S * fps)
    return [part.start + np.flatnonzero(needs[part]) for part in _runs(flexed, 1)
            if _runs(needs[part], n_min)]  # fmt: skip


def _seat(frames: np.ndarray, centre: np.ndarray, low: np.ndarray, bodies: np.ndarray,
          where: np.ndarray, shapes: _Shapes, floor: float) -> Prop | None:  # fmt: skip
    """The seat of one sitting episode (module docstring): a box, or a slab where that holds
    more of the resting points; ``None`` on the floor or where none fits."""
    thighs = np.isin(bodies, (1, 2))
    buttocks = (bodies == 0) | (thighs & (where <= SEAT_THIGH_SHARE))
    h = float(np.median(low[frames][:, buttocks].min(1)))
    if h - floor < MIN_HEIGHT_M:
        return None
    rest = (bodies == 0) | thighs
    lz = low[frames][:, rest]
    need = centre[frames][:, rest][(lz >= h - SEAT_INSIDE_M) & (lz <= h + REST_M), :2]
    if not len(need):
        return None
    lo, hi = need.min(0) - SEAT_MARGIN_M, need.max(0) + SEAT_MARGIN_M
    best = None
    for bottom in (0.0, h - SLAB_M):
        z0 = bottom - UNDER_M if bottom else -np.inf
        boxes = _cover(lo, hi, need, *shapes.inside(lo, hi, z0, h - SEAT_INSIDE_M), 1)
        if boxes and (best is None or boxes[0][2] > best[2]):
            best = (*boxes[0], bottom)
    if best is None:
        return None
    return Prop(best[0], best[1], h, "seat", len(frames), best[3])


# ------------------------------------------------------------------------------- props
def infer_props(global_rot: np.ndarray, joint_pos: np.ndarray, body: BodyModel,
                fps: float) -> list[Prop]:  # fmt: skip
    """The boxes a motion stands or sits on (module docstring), lowest first.

    Args:
        global_rot: ``(T, 24, 3, 3)`` global segment rotations.
        joint_pos: ``(T, 24, 3)`` joint positions, world frame (z up, floor z = 0), m.
        body: The body model of the motion.
        fps: Frame rate, Hz.

    Returns:
        The props; empty for a motion on flat ground.

    Raises:
        ValueError: The soles never come within :data:`FLOATING_M` of the floor (a motion
            that floats: put it on the floor first).
    """
    cells = insole_cell_positions(global_rot, joint_pos, body)  # (T, 2, 16, 3)
    lowest = float(cells[..., 2].min()) if cells.size else 0.0
    if lowest > FLOATING_M:
        raise ValueError(f"the body never comes within {FLOATING_M:g} m of the floor (its lowest "
                         f"sole point is {lowest:.2f} m up): no supports can be inferred for a "
                         "floating motion; put it on the floor (z = 0) first")  # fmt: skip
    planted, height = planted_feet(cells, fps)
    if not planted.any():
        return []
    floor = float(np.percentile(height[planted], FLOOR_PERCENTILE))
    soles = sole_points(global_rot, joint_pos, body)  # (T, 2, 6, 3) the soles' outlines
    centre, radius, bodies, where = body_shapes(global_rot, joint_pos, body)
    feet = np.concatenate(
        [soles.reshape(len(soles), -1, 3), cells.reshape(len(cells), -1, 3)], axis=1
    )  # (T, 44, 3) the soles' outlines and insole cells
    shapes = _Shapes(
        np.concatenate([centre, feet], axis=1),
        np.concatenate([radius, np.zeros(feet.shape[1])]),
        np.concatenate([np.zeros(len(radius)), np.full(feet.shape[1], REACH_M)]),
    )
    low_soles = (cells[..., :2][planted].reshape(-1, 2), np.repeat(height[planted], 16))
    steps = []
    for g in _step_groups(cells, soles, planted, height, joint_pos[:, 0, 2], fps, floor):
        steps += _step_boxes(g, shapes, low_soles)
    steps = _fill_gaps(steps, shapes, low_soles)
    low = centre[..., 2] - radius  # (T, K) the shapes' lowest points
    seat_k = (bodies == 0) | (np.isin(bodies, (1, 2)) & (where <= 0.5))
    seats = [
        _seat(fr, centre, low, bodies, where, shapes, floor)
        for fr in _sittings(global_rot, joint_pos, body, cells, fps, low, seat_k)
    ]
    return sorted(steps + [s for s in seats if s is not None], key=lambda p: p.height_m)


def support_height(props: list[Prop], points: np.ndarray) -> np.ndarray:
    """Height of the ground under points: the highest prop top under each, else the floor (0),
    m.

    Args:
        props: The props.
        points: ``(..., 2)`` x, y, or ``(..., 3)`` x, y, z: with heights, a slab (a prop with
            ``bottom_m`` > 0) is under a point only when the point is not below its underside
            (a foot under a stool stands on the floor).

    Returns:
        ``(...)`` heights, m.
    """
    xy = points[..., :2]
    z = points[..., 2] if points.shape[-1] == 3 else None
    out = np.zeros(xy.shape[:-1])
    for p in props:
        over = p.contains(xy)
        if z is not None and p.bottom_m > 0.0:
            over &= z >= p.bottom_m
        out = np.where(over, np.maximum(out, p.height_m), out)
    return out


def props_as_objects(props: list[Prop]) -> dict[str, SceneObject] | None:
    """PRISM ``objects`` of the props (``prop_00``, ``prop_01``, ...; boxes from their
    undersides, the floor or a slab's bottom, to their tops), ``None`` without props."""
    if not props:
        return None
    out = {}
    for i, p in enumerate(props):
        centre = np.array([*(0.5 * (p.lo + p.hi)), 0.5 * (p.bottom_m + p.height_m)])
        extents = np.array([*(p.hi - p.lo), p.height_m - p.bottom_m])
        out[f"prop_{i:02d}"] = box_object(centre, extents)
    return out
