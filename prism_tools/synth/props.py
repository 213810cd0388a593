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
   support patch (when the pelvis stands :data:`PELVIS_ABOVE_FOOT_M` above it): the sole
   outline's horizontal extent over the run at that height.
2. **A seat.** The pelvis is still for at least :data:`MIN_SEATED_S`, the torso upright above it
   (:data:`TORSO_ABOVE_SEAT_M`) and the thighs flexed (:data:`SEATED_THIGH_DEG`), while the
   whole-body centre of mass lies more than :data:`COM_OUTSIDE_M` outside the hull of the soles
   on the ground: the feet cannot hold the body up alone, so something under the pelvis and
   thighs does. The
   patch's height is the lowest point of the pelvis and proximal thigh shapes
   (:class:`grip.core.body.Geom` capsules), its extent theirs plus :data:`SEAT_MARGIN_M`. Seats
   lower than :data:`MIN_HEIGHT_M` are the floor (sitting or lying on it needs no prop).

Patches of about the same height (:data:`MERGE_HEIGHT_M`) whose extents come within
:data:`MERGE_GAP_M` of each other merge into one box (both feet on a step, repeated visits).
A box may not cover a place where a sole is planted lower than its top, nor hold any part of the
body: a sole (its outline and insole cells), or the lowest point of a limb or trunk shape
(:func:`prism_tools.synth.insole.body_contact_points`) more than :data:`INSIDE_M` below its top
over it, at any frame (standing thighs in front of a stool, a swinging foot in front of a
step). Such a box is cut back from that side, keeping its own patches (the steps of a staircase
stay separate boxes). Where the body was inside a step's patches themselves at other frames,
the box becomes its largest rectangle that no body point enters, and is dropped when that is
narrower than :data:`MIN_TOP_M`: the simulation would otherwise start the body inside its
prop.

A seat that the body reaches under (a high stool: the legs stand in front of it before sitting,
the feet tuck under it onto its rungs) is a slab instead: :data:`SLAB_M` thick, open underneath
(``Prop.bottom_m`` > 0). Only body shapes that reach the slab's height cut it back: lowest
points between :data:`UNDER_M` + :data:`REACH_M` under its bottom and :data:`INSIDE_M` under its
top; everything lower passes under it. The simulation collides with it as a static geom (it
needs no legs), and points under it stand on the floor (:func:`support_height` with heights).
Seats within :data:`SEAT_MERGE_HEIGHT_M` of each other are one seat (two postures on one
stool).

A body whose soles never come within :data:`FLOATING_M` of the floor is refused: where nothing
touches the floor, the floor level and so the props cannot be told.

Every threshold is a module constant with its reason; none is a setting to tune.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grip.core.body import BodyModel
from grip.core.fk import center_of_mass, sole_points
from prism_tools.streams import SceneObject, box_object
from prism_tools.synth.insole import (
    body_contact_points,
    insole_cell_positions,
    smooth_derivative,
)

__all__ = ["Prop", "infer_props", "props_as_objects", "support_height"]

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
SEAT_MARGIN_M = 0.05
"""The seat reaches this far beyond the pelvis and thigh points that rest on it."""
MERGE_HEIGHT_M = 0.05
"""Patches whose heights differ by less than this are the same surface (a seat's lowest point
varies by a few centimetres with the posture; steps of a staircase differ by 15-20 cm)."""
SEAT_MERGE_HEIGHT_M = 0.08
"""Seats whose heights differ by less than this are one seat: the pelvis' lowest point sits up
to 6 cm lower upright than perched on the same stool (CMU 13_01: 0.56 and 0.62 m); two slabs
would stack, and the lower posture would sit inside the upper one."""
MERGE_GAP_M = 0.3
"""... when their extents come closer than this (both feet on a step, a second visit)."""
CUT_MARGIN_M = 0.02
"""A box cut back from a lower planted sole stops this far from it."""
PAD_M = 0.01
"""A foot patch reaches this far beyond the planted sole's outline (heel, toe-base and toe-tip
corners)."""
INSIDE_M = 0.06
"""A body point this far below a box's top, over it, is inside the box (the box is cut back from
it). Points resting on a box lie up to :data:`MERGE_HEIGHT_M` below its top (the merged
patches' heights spread that much; a hand resting on a seat lies at its top); a thigh standing
in front of a stool lies 10-20 cm below it, a foot on the floor the whole height."""
MIN_TOP_M = 0.1
"""A box cut narrower than this (either side of its top) carries nothing and is dropped."""
FREE_CELL_M = 0.01
"""Grid of the search for the largest part of a box that no body point enters."""
SLAB_M = 0.05
"""Thickness of an open-underside seat (a stool's top, 3-5 cm, and the body's resting points
spread a few centimetres below the merged top: :data:`INSIDE_M`)."""
UNDER_M = 0.03
"""Body shapes pass under a slab with this clearance."""
REACH_M = 0.06
"""A limb or trunk shape whose lowest point lies this far under a slab's clearance still reaches
into the slab (about a thigh capsule's radius on a 1.7 m body: its axis is at the slab's
underside): a thigh standing in front of a stool, the pelvis of a lower sitting posture. A
foot on a rung 30-40 cm below passes under it. (Twice this, a whole thigh's thickness, cuts CMU
14_27's seat below :data:`MIN_TOP_M`, and with this value no shape's lowest point lies within
twice this under any inferred slab on more than 0.2 % of a clip's frames.)"""


@dataclass(frozen=True)
class Prop:
    """A box resting on the floor, or a slab open underneath (a stool's seat).

    Attributes:
        lo: ``(2,)`` minimum x, y of its top, m (world frame, z up).
        hi: ``(2,)`` maximum x, y, m.
        height_m: Top above the floor (z = 0), m.
        kind: ``"step"`` (feet stood on it) or ``"seat"`` (the pelvis rested on it; a seat
            that feet also stood on stays a seat).
        frames: Frames supported by it.
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


def _seat_points(global_rot: np.ndarray, joint_pos: np.ndarray, body: BodyModel) -> np.ndarray:
    """``(T, K, 3)`` lowest points of the shapes a seat carries: the pelvis capsule's and the
    proximal half of each thigh's (:func:`prism_tools.synth.insole.body_contact_points`)."""
    pts, bodies, where = body_contact_points(global_rot, joint_pos, body)
    keep = (bodies == 0) | (np.isin(bodies, (1, 2)) & (where <= 0.5))
    return pts[:, keep]


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


def _seat_patches(global_rot, joint_pos, body, cells, fps, floor) -> list[tuple]:
    pelvis = joint_pos[:, 0]
    still = horizontal_speed(pelvis, fps) < SEATED_SPEED_M_S
    com = center_of_mass(global_rot, joint_pos, body)
    z = cells[..., 2].reshape(len(cells), -1)
    flat = cells[..., :2].reshape(len(cells), -1, 2)
    seat = _seat_points(global_rot, joint_pos, body)
    upright = (joint_pos[:, TORSO_JOINTS, 2].min(1) - seat[..., 2].min(1)) >= TORSO_ABOVE_SEAT_M
    thigh = joint_pos[:, (4, 5)] - joint_pos[:, (1, 2)]  # hips -> knees
    down = -thigh[..., 2] / np.maximum(np.linalg.norm(thigh, axis=-1), 1e-9)
    flexed = np.degrees(np.arccos(np.clip(down, -1.0, 1.0))).mean(1) >= SEATED_THIGH_DEG
    needs = np.zeros(len(cells), dtype=bool)
    for t in np.flatnonzero(still & upright & flexed):
        ground = z[t] <= z[t].min() + GROUND_SOLE_M
        needs[t] = _outside_hull(com[t, :2], flat[t, ground]) > COM_OUTSIDE_M
    out = []
    for run in _runs(needs, round(MIN_SEATED_S * fps)):
        pts = seat[run]
        low = pts[..., 2].min(axis=1)  # (n,) the lowest point of each frame
        h = float(np.median(low))
        if h - floor < MIN_HEIGHT_M:
            continue
        resting = pts[pts[..., 2] <= low[:, None] + 0.05][:, :2]  # the points on the seat
        out.append((resting.min(0), resting.max(0), SEAT_MARGIN_M, h, "seat",
                    run.stop - run.start))  # fmt: skip
    return out


def _merge(patches: list[tuple]) -> list[dict]:
    """Patches ``(core_lo, core_hi, margin, height, kind, frames)`` of one surface joined:
    ``{"core": (lo, hi), "box": (lo, hi), "heights", "kinds", "frames"}`` per surface (the core:
    the points that rested on it; the box: the core grown by each patch's margin)."""
    groups: list[dict] = []
    for lo, hi, margin, h, kind, n in sorted(patches, key=lambda p: p[3]):
        for g in groups:
            glo, ghi = g["box"]
            near = np.all(lo <= ghi + MERGE_GAP_M) and np.all(hi >= glo - MERGE_GAP_M)
            seats = kind == "seat" and "seat" in g["kinds"]
            tol = SEAT_MERGE_HEIGHT_M if seats else MERGE_HEIGHT_M
            if near and abs(np.average(g["heights"], weights=g["frames"]) - h) < tol:
                g["core"] = (np.minimum(g["core"][0], lo), np.maximum(g["core"][1], hi))
                g["box"] = (np.minimum(glo, lo - margin), np.maximum(ghi, hi + margin))
                g["heights"].append(h), g["kinds"].append(kind), g["frames"].append(n)
                break
        else:
            groups.append({"core": (lo, hi), "box": (lo - margin, hi + margin), "heights": [h],
                           "kinds": [kind], "frames": [n]})  # fmt: skip
    return groups


def _cut(lo: np.ndarray, hi: np.ndarray, keep_lo: np.ndarray, keep_hi: np.ndarray,
         bad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Shrink the box ``[lo, hi]`` from one side at a time until no point of ``bad (N, 2)`` lies
    over it, never past its own patches ``[keep_lo, keep_hi]``; the side that keeps the most
    area is cut first. Points that cannot be cut away (inside the patches) stay."""
    lo, hi = lo.copy(), hi.copy()
    while True:
        inside = bad[np.all((bad >= lo) & (bad <= hi), axis=1)]
        inside = inside[~np.all((inside >= keep_lo) & (inside <= keep_hi), axis=1)]
        if not len(inside):
            return lo, hi
        best = None
        for axis in (0, 1):
            for side in ("lo", "hi"):
                n_lo, n_hi = lo.copy(), hi.copy()
                if side == "lo":
                    beyond = inside[inside[:, axis] < keep_lo[axis], axis]
                    if not len(beyond):
                        continue
                    n_lo[axis] = beyond.max() + CUT_MARGIN_M
                else:
                    beyond = inside[inside[:, axis] > keep_hi[axis], axis]
                    if not len(beyond):
                        continue
                    n_hi[axis] = beyond.min() - CUT_MARGIN_M
                n_lo, n_hi = np.minimum(n_lo, keep_lo), np.maximum(n_hi, keep_hi)
                area = float(np.prod(n_hi - n_lo))
                if best is None or area > best[0]:
                    best = (area, n_lo, n_hi)
        if best is None:
            return lo, hi
        lo, hi = best[1], best[2]


def _largest_free(lo: np.ndarray, hi: np.ndarray,
                  bad: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:  # fmt: skip
    """The largest rectangle inside ``[lo, hi]`` that stays :data:`CUT_MARGIN_M` from every
    point of ``bad (N, 2)`` (on a grid of :data:`FREE_CELL_M`), or ``None`` when it would be
    narrower than :data:`MIN_TOP_M`."""
    from scipy.ndimage import binary_dilation

    n = np.maximum(np.ceil((hi - lo) / FREE_CELL_M).astype(int), 1)
    taken = np.zeros(n, dtype=bool)
    ij = np.floor((bad - lo) / FREE_CELL_M).astype(int)
    ij = ij[np.all((ij >= 0) & (ij < n), axis=1)]
    taken[ij[:, 0], ij[:, 1]] = True
    r = round(CUT_MARGIN_M / FREE_CELL_M)
    taken = binary_dilation(taken, np.ones((2 * r + 1, 2 * r + 1), dtype=bool))
    best, run = (0, 0, 0, 0, 0), np.zeros(n[0], dtype=int)  # (area, i0, i1, j0, j1)
    for j in range(n[1]):  # the largest rectangle under the histogram of free runs
        run = np.where(taken[:, j], 0, run + 1)
        stack: list[int] = []
        for i in range(n[0] + 1):
            h = run[i] if i < n[0] else 0
            while stack and run[stack[-1]] >= h:
                top = stack.pop()
                left = stack[-1] + 1 if stack else 0
                area = run[top] * (i - left)
                if area > best[0]:
                    best = (area, left, i, j - run[top] + 1, j + 1)
            stack.append(i)
    _, i0, i1, j0, j1 = best
    new_lo = lo + FREE_CELL_M * np.array([i0, j0])
    new_hi = np.minimum(lo + FREE_CELL_M * np.array([i1, j1]), hi)
    if np.any(new_hi - new_lo < MIN_TOP_M):
        return None
    return new_lo, new_hi


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
    patches = []
    n_min = round(MIN_PLANTED_S * fps)
    for f in range(2):
        for run in _runs(planted[:, f], n_min):
            h = float(np.median(height[run, f]))
            above = float(np.median(joint_pos[run, 0, 2])) - h
            if h - floor >= MIN_HEIGHT_M and above >= PELVIS_ABOVE_FOOT_M:
                xy = soles[run, f, :, :2].reshape(-1, 2)
                patches.append((xy.min(0), xy.max(0), PAD_M, h, "step", run.stop - run.start))
    patches += _seat_patches(global_rot, joint_pos, body, cells, fps, floor)
    if not patches:
        return []
    # planted soles, to keep every box off the places where a foot stands lower than its top
    soles_xy = cells[..., :2][planted]  # (N, 16, 2)
    soles_h = height[planted]  # (N,)
    # and every point of the body at every frame, to keep the body out of every box
    limbs = body_contact_points(global_rot, joint_pos, body)[0]
    points = np.concatenate([limbs, soles.reshape(len(soles), -1, 3),
                             cells.reshape(len(cells), -1, 3)], axis=1).reshape(-1, 3)  # fmt: skip
    props = []
    for g in _merge(patches):
        h = float(np.average(g["heights"], weights=g["frames"]))
        bad = np.concatenate([soles_xy[soles_h < h - MERGE_HEIGHT_M].reshape(-1, 2),
                              points[points[:, 2] < h - INSIDE_M, :2]])  # fmt: skip
        kind = "seat" if "seat" in g["kinds"] else "step"
        bottom = 0.0
        if kind == "seat" and _entered(g["core"], bad):
            # the body reached under the seat: a slab, which only points at its height cut
            bottom = h - SLAB_M
            z = points[:, 2]
            bad = points[(z > bottom - UNDER_M - REACH_M) & (z < h - INSIDE_M), :2]
        box = _free_box(g, bad)
        if box is not None:
            props.append(Prop(*box, h, kind, int(sum(g["frames"])), bottom))
    return props


def _entered(core: tuple[np.ndarray, np.ndarray], bad: np.ndarray) -> bool:
    """Whether a point of ``bad (N, 2)`` lies over a surface's own patches ``core``."""
    return bool(len(bad)) and bool(np.all((bad >= core[0]) & (bad <= core[1]), axis=1).any())


def _free_box(group: dict, bad: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """A merged surface's box cut back from the points ``bad (N, 2)`` (:func:`_cut`), or its
    largest free rectangle where they entered its own patches; ``None`` when too small."""
    if not len(bad):
        return group["box"]
    lo, hi = _cut(*group["box"], *group["core"], bad)
    if np.all((bad >= lo) & (bad <= hi), axis=1).any():
        return _largest_free(lo, hi, bad)  # (the body entered the patches)
    return lo, hi


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

