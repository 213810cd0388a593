"""Props inferred from motion (prism_tools.synth.props): boxes a clip stands or sits on."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from grip.core import fk
from grip.core.body import build_body
from grip.core.rotations import rot_x, rot_z
from prism_tools.synth.props import infer_props, props_as_objects, support_height

FPS = 100.0
BODY = build_body()


def _standing(n: int, at=(0.0, 0.0), raise_m: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """``(global_rot, joint_pos)`` of the rest pose, arms lowered, soles ``raise_m`` up."""
    rot, pos = fk.rest_pose(n)
    rot[:, 16], rot[:, 17] = rot_z(np.array(-1.3)), rot_z(np.array(1.3))
    pos[:, :2] = at
    pos[:, 2] = BODY.pelvis_height + raise_m
    return fk.forward_kinematics(rot, pos, BODY.offsets)


def _sitting(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Seated upright, thighs level, shanks vertical, soles on the floor (facing +y)."""
    rot, pos = fk.rest_pose(n)
    for hip, knee in ((1, 4), (2, 5)):
        rot[:, hip], rot[:, knee] = rot_x(np.array(-np.pi / 2)), rot_x(np.array(np.pi / 2))
    pos[:, 2] = 1.0
    _, p = fk.forward_kinematics(rot, pos, BODY.offsets)
    pos[:, 2] -= p[0, 7, 2] - BODY.rest_joint_pos[7, 1]  # ankles at their standing height
    return fk.forward_kinematics(rot, pos, BODY.offsets)


def _in_front_of_the_seat() -> tuple[float, float]:
    """Where :func:`_sitting`'s feet are: a body stands there before and after sitting (it
    cannot stand where the seat is, and a box that would hold it is not inferred:
    test_no_box_holds_the_body)."""
    return 0.0, float(fk.sole_points(*_sitting(1), BODY)[0, :, :, 1].mean())


def _moving(n: int, start, end) -> tuple[np.ndarray, np.ndarray]:
    """The rest pose slid on the floor from ``start`` to ``end`` (x, y) over ``n`` frames."""
    rot, pos = fk.rest_pose(n)
    rot[:, 16], rot[:, 17] = rot_z(np.array(-1.3)), rot_z(np.array(1.3))
    pos[:, :2] = np.linspace(start, end, n)
    pos[:, 2] = BODY.pelvis_height
    return fk.forward_kinematics(rot, pos, BODY.offsets)


def _concat(*parts: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    return tuple(np.concatenate(x) for x in zip(*parts, strict=True))  # type: ignore[return-value]


def test_standing_on_a_box_gives_its_top():
    g, p = _concat(_standing(100), _standing(150, at=(1.0, 0.5), raise_m=0.4))
    (prop,) = infer_props(g, p, BODY, FPS)
    assert prop.kind == "step" and abs(prop.height_m - 0.4) < 0.02
    soles = fk.sole_points(g[100:], p[100:], BODY)[..., :2].reshape(-1, 2)
    assert prop.contains(soles, margin=0.005).all()  # the box is under both feet
    assert not prop.contains(p[:100, 0, :2]).any()  # not where the body stood on the floor
    np.testing.assert_allclose(support_height([prop], np.array([[1.0, 0.5], [0.0, 0.0]])),
                               [prop.height_m, 0.0])  # fmt: skip
    (box,) = props_as_objects([prop]).values()
    assert box.vertices[:, 2].min() == 0.0 and abs(box.vertices[:, 2].max() - prop.height_m) < 1e-12
    np.testing.assert_allclose(box.extents[:2], prop.hi - prop.lo)


def test_flat_ground_and_short_touches_give_none():
    g, p = _standing(200)
    assert infer_props(g, p, BODY, FPS) == []
    assert props_as_objects([]) is None
    # a float of a few centimetres is the floor, a 0.1 s perch is not a step
    g, p = _concat(_standing(100), _standing(100, at=(0.5, 0), raise_m=0.05),
                   _standing(10, at=(1.0, 0), raise_m=0.3), _standing(100, at=(1.5, 0)))
    assert infer_props(g, p, BODY, FPS) == []


def test_a_real_walk_gives_none(cmu_walk):
    b = cmu_walk.body_model()
    g, p = cmu_walk.fk(b)
    assert infer_props(g, p, b, cmu_walk.fps) == []


def test_two_steps_stay_two_boxes_off_the_floor_stance():
    g, p = _concat(_standing(60), _standing(60, at=(0, 0.3), raise_m=0.2),
                   _standing(60, at=(0, 0.6), raise_m=0.4), _standing(60, at=(0, 1.2)))
    props = infer_props(g, p, BODY, FPS)
    assert [round(x.height_m, 2) for x in props] == [0.2, 0.4]
    high = props[1]
    assert not high.contains(fk.sole_points(g[60:120], p[60:120], BODY)[..., :2]).any()
    for q in props:  # neither covers the floor stances
        assert not q.contains(fk.sole_points(g[:60], p[:60], BODY)[..., :2]).any()
        assert not q.contains(fk.sole_points(g[180:], p[180:], BODY)[..., :2]).any()


def test_sitting_gives_a_seat_under_the_pelvis_and_thighs():
    front = _in_front_of_the_seat()
    g, p = _concat(_standing(100, at=front), _sitting(150), _standing(100, at=front))
    props = infer_props(g, p, BODY, FPS)
    assert [x.kind for x in props] == ["seat"]
    seat = props[0]
    hips = p[150, [1, 2]]
    assert seat.contains(p[150, 0, :2]) and seat.contains(hips[:, :2]).all()
    thigh_bottom = hips[:, 2].mean() - 0.034 * BODY.params.height_m
    assert abs(seat.height_m - thigh_bottom) < 0.04
    # the feet stand on the floor: the seat reaches under the level thighs up to the shanks, and
    # so over the heels tucked under the knees (this test used to pin a box that stopped short
    # of the feet); it is a slab there, which they pass under
    soles = fk.sole_points(g[150], p[150], BODY).reshape(-1, 3)
    assert seat.contains(0.5 * (hips[:, :2] + p[150, [4, 5], :2])).all()  # mid-thighs
    np.testing.assert_array_equal(support_height([seat], soles), 0.0)


def test_no_box_holds_the_body():
    """The body passed, feet on the floor, over part of the place where it later stands on a
    0.4 m box: the box keeps its height but not that part, and at no frame does a body point
    lie inside it; where the body went over the whole of it, there is no box."""
    from prism_tools.synth.insole import body_contact_points, insole_cell_positions
    from prism_tools.synth.props import INSIDE_M

    def inside(prop, g, p):
        pts = np.concatenate([body_contact_points(g, p, BODY)[0],
                              fk.sole_points(g, p, BODY).reshape(len(g), -1, 3),
                              insole_cell_positions(g, p, BODY).reshape(len(g), -1, 3)], axis=1)
        return (prop.contains(pts[..., :2]) & (pts[..., 2] < prop.height_m - INSIDE_M)).any()

    g, p = _concat(_standing(60), _moving(400, (-1.0, 0.7), (3.0, 0.7)),
                   _standing(150, at=(1.0, 0.5), raise_m=0.4), _standing(60, at=(1.0, -0.5)))
    (prop,) = infer_props(g, p, BODY, FPS)
    assert abs(prop.height_m - 0.4) < 0.02 and prop.contains(np.array([1.0, 0.5]))
    assert prop.hi[1] < 0.7  # (the soles' outline passed down to y = 0.57)
    assert not inside(prop, g, p)
    g, p = _concat(_standing(60), _moving(400, (-1.0, 0.5), (3.0, 0.5)),
                   _standing(150, at=(1.0, 0.5), raise_m=0.4), _standing(60, at=(1.0, -0.5)))
    assert infer_props(g, p, BODY, FPS) == []


@pytest.mark.parametrize("n", [1, 5])
def test_tiny_clips(n):
    g, p = _standing(n)
    assert infer_props(g, p, BODY, FPS) == []


def test_the_insoles_stand_on_the_props_and_the_recording_carries_them():
    """On a 0.4 m box the insoles carry the body weight (a flat floor would leave the feet in
    the air); the recording's objects hold the box and its extras the props' summary."""
    import json

    from grip.core.rotations import matrix_to_quat
    from grip.motion.motion import Motion
    from prism_tools.synth import recording_from_motion

    rot, pos = fk.rest_pose(300)
    rot[:, 16], rot[:, 17] = rot_z(np.array(-1.3)), rot_z(np.array(1.3))
    pos[:, 2] = BODY.pelvis_height
    pos[150:, 1] += 1.0
    pos[150:, 2] += 0.4
    motion = Motion(fps=FPS, root_pos=pos, local_quat=matrix_to_quat(rot), name="box")
    rec = recording_from_motion(motion, noise=False)
    (box,) = rec.objects.values()
    assert abs(box.vertices[:, 2].max() - 0.4) < 0.02
    (summary,) = json.loads(rec.extras["props"])
    assert summary["kind"] == "step" and abs(summary["height_m"] - 0.4) < 0.02
    force = sum(rec.insole[f].force[:, 0] for f in rec.insole)  # body weights
    np.testing.assert_allclose(force[20:130], 1.0, atol=0.03)  # on the floor
    np.testing.assert_allclose(force[170:280], 1.0, atol=0.03)  # on the box


def test_seated_the_seat_takes_its_share_and_the_insoles_feel_the_rest():
    from grip.core.body import GRAVITY
    from prism_tools.synth.insole import synthesize_insoles

    front = _in_front_of_the_seat()
    g, p = _concat(_standing(100, at=front), _sitting(200), _standing(100, at=front))
    props = infer_props(g, p, BODY, FPS)
    syn = synthesize_insoles(g, p, BODY, FPS, ground=lambda xy: support_height(props, xy))
    bw = BODY.total_mass * GRAVITY
    feet = syn.cell_force_n.sum(axis=(1, 2)) / bw
    other = syn.other_support_force_n / bw
    seated = slice(140, 260)  # away from the (instant) transitions
    assert np.all(feet[seated] < 0.8) and np.all(other[seated] > 0.2)
    np.testing.assert_allclose(feet[seated] + other[seated], 1.0, atol=1e-3)  # F_z, at rest
    np.testing.assert_allclose(feet[20:80], 1.0, atol=0.02)  # standing: the feet carry it all
    assert np.all(other[20:80] < 1e-9)
    assert np.all(syn.zmp_error_m[seated] < 0.01)  # the seat and feet together hold the ZMP


def _perched(n: int) -> tuple[np.ndarray, np.ndarray]:
    """On a high seat (pelvis at 0.75 m, thighs level), the feet off the floor: the left shank
    hanging with the foot pointed, the right leg tucked under the seat (knee bent to 115 deg,
    foot pointed): neither foot is flat, so neither stands on anything."""
    rot, pos = fk.rest_pose(n)
    for hip, knee, bend in ((1, 4, np.pi / 2), (2, 5, 2.0)):
        rot[:, hip], rot[:, knee] = rot_x(np.array(-np.pi / 2)), rot_x(np.array(bend))
    rot[:, 7], rot[:, 8] = rot_x(np.array(np.pi / 2 - 0.6)), rot_x(np.array(2.0 - 0.8))
    pos[:, 2] = 0.75
    return fk.forward_kinematics(rot, pos, BODY.offsets)


def test_a_seat_the_legs_reach_under_is_a_slab_open_underneath():
    """Perched with one foot tucked under the seat: a full-height box would hold the foot, so the
    seat is a slab the foot passes under; a point under it stands on the floor, one on it on
    the seat, and the object is the slab alone."""
    from prism_tools.synth.insole import insole_cell_positions
    from prism_tools.synth.props import SLAB_M

    front = _in_front_of_the_seat()
    g, p = _concat(_standing(100, at=front), _perched(150), _standing(100, at=front))
    (seat,) = infer_props(g, p, BODY, FPS)
    assert seat.kind == "seat" and abs(seat.bottom_m - (seat.height_m - SLAB_M)) < 1e-12
    assert seat.contains(p[150, [0, 1, 2], :2]).all()  # pelvis and both hips on it
    cells = insole_cell_positions(g[150:151], p[150:151], BODY)[0, 1]  # (16, 3) tucked foot
    assert seat.contains(cells[:, :2]).any() and cells[:, 2].max() < seat.bottom_m
    np.testing.assert_array_equal(support_height([seat], cells), 0.0)  # under it: the floor
    assert support_height([seat], cells[:, :2]).max() == seat.height_m  # (heights not given)
    top = np.array([[*p[150, 0, :2], seat.height_m]])
    assert support_height([seat], top)[0] == seat.height_m
    (slab,) = props_as_objects([seat]).values()
    np.testing.assert_allclose([slab.vertices[:, 2].min(), slab.vertices[:, 2].max()],
                               [seat.bottom_m, seat.height_m])  # fmt: skip


@pytest.mark.parametrize("clip", ["step", "seat"])
def test_a_body_that_never_comes_near_the_floor_gets_no_props(clip):
    """Standing on a box, or sitting, 6.4 m up: a 6.8 m tower used to be built under it."""
    lift = 6.4
    if clip == "step":
        g, p = _concat(_standing(100, raise_m=lift), _standing(150, at=(1.0, 0.5),
                                                               raise_m=lift + 0.4))  # fmt: skip
    else:
        g, p = _concat(_standing(100, at=_in_front_of_the_seat()), _sitting(150))
        p = p + np.array([0.0, 0.0, lift])
    with pytest.raises(ValueError, match=r"never comes within 0.5 m of the floor \(its lowest "
                                         r"sole point is 6.4\d m up\)"):  # fmt: skip
        infer_props(g, p, BODY, FPS)


def _turned(pose: tuple[np.ndarray, np.ndarray], yaw: float, at) -> tuple[np.ndarray, np.ndarray]:
    """``pose`` turned by ``yaw`` rad about the vertical through the world origin, then moved
    by ``at`` (x, y): :func:`_sitting` (facing +y) turned by -pi/2 faces +x."""
    g, p = pose
    r = rot_z(np.array(yaw))
    return r @ g, p @ r.T + np.array([*at, 0.0])


def _deepest_in(props, g: np.ndarray, p: np.ndarray) -> float:
    """How deep any limb or trunk capsule (sampled every 5 mm along its axis, independently of
    the props rule's samples) reaches into any prop at any frame, m: the sphere's radius less
    its centre's distance from the box (or slab)."""
    from grip.core.fk import body_points

    depth = 0.0
    for geom in BODY.geoms:
        if geom.kind != "capsule" or geom.body in (7, 8, 10, 11):
            continue
        a, b = geom.fromto()[:3], geom.fromto()[3:]
        local = a + np.linspace(0.0, 1.0, int(np.linalg.norm(b - a) / 0.005) + 2)[:, None] * (b - a)
        c = body_points(g, p, np.full(len(local), geom.body), local)  # (T, n, 3)
        for q in props:
            lo = np.array([*q.lo, q.bottom_m])
            hi = np.array([*q.hi, q.height_m])
            dist = np.linalg.norm(np.maximum(0.0, np.maximum(lo - c, c - hi)), axis=-1)
            depth = max(depth, float((geom.size[0] - dist).max()))
    return depth


def test_two_sittings_facing_opposite_ways_get_a_seat_each_under_the_pelvis():
    """Sitting facing +x, standing up, then sitting facing -x 10 cm further on (CMU 13_01 sits
    on one stool twice, turned): each sitting has its own seat under its pelvis and hips at its
    thighs' height, and no capsule of the body, standing in front of either seat or seated,
    reaches more than SEAT_INSIDE_M into either."""
    from prism_tools.synth.props import SEAT_INSIDE_M

    front = np.array(_in_front_of_the_seat())
    first, second = (-np.pi / 2, (0.0, 0.0)), (np.pi / 2, (0.1, 0.05))
    parts = []
    for yaw, at in (first, second):
        ahead = rot_z(np.array(yaw))[:2, :2] @ front + at
        sit = _turned(_sitting(200), yaw, at)
        parts += [_standing(100, at=ahead), sit, _standing(100, at=ahead)]
    g, p = _concat(*parts)
    seats = infer_props(g, p, BODY, FPS)
    assert [s.kind for s in seats] == ["seat", "seat"]  # (the same height: in sitting order)
    thigh_bottom = p[200, [1, 2], 2].mean() - 0.034 * BODY.params.height_m
    for seat, t in zip(seats, (200, 600), strict=True):  # seated facing +x, then -x
        assert seat.contains(p[t, [0, 1, 2], :2]).all()  # the pelvis and both hips
        thighs = 0.5 * (p[t, [1, 2], :2] + p[t, [4, 5], :2])  # mid-thigh: the seat reaches under
        assert seat.contains(thighs).all() and abs(seat.height_m - thigh_bottom) < 0.04
    assert not seats[1].contains(0.5 * (p[200, [1, 2], :2] + p[200, [4, 5], :2])).any()
    assert _deepest_in(seats, g, p) < SEAT_INSIDE_M + 0.005


def test_a_flight_of_steps_leaves_no_gap_and_holds_every_planted_sole_cell():
    """Climbing three 0.17 m steps 0.38 m apart (the soles are 0.26 m long: 10 cm gaps between
    the feet's places), then back down: consecutive steps meet (the lower one reaches the
    higher one's edge), every insole cell of a foot standing on a step stands on its top, and no
    capsule of the body reaches into a step."""
    from prism_tools.synth.insole import insole_cell_positions
    from prism_tools.synth.props import INSIDE_M

    rise, tread = 0.17, 0.38
    up = [_standing(60, at=(0.0, tread * k), raise_m=rise * k) for k in range(1, 4)]
    g, p = _concat(_standing(60), *up, *up[-2::-1], _standing(60))
    steps = infer_props(g, p, BODY, FPS)
    assert [s.kind for s in steps] == ["step"] * 3
    np.testing.assert_allclose([s.height_m for s in steps], [rise, 2 * rise, 3 * rise], atol=0.01)
    for low, high in itertools.pairwise(steps):
        assert low.hi[1] == pytest.approx(high.lo[1])  # no gap: the lower step meets the higher
        assert min(low.hi[0], high.hi[0]) - max(low.lo[0], high.lo[0]) > 0.2  # side by side
    cells = insole_cell_positions(g[60:-60], p[60:-60], BODY)  # (T, 2, 16, 3) every foot on a step
    under = support_height(steps, cells)
    assert np.all(np.abs(cells[..., 2] - under) < 0.02)
    assert _deepest_in(steps, g, p) < INSIDE_M
    # the floor stances stay off the steps
    floor = insole_cell_positions(np.concatenate([g[:60], g[-60:]]),
                                  np.concatenate([p[:60], p[-60:]]), BODY)
    assert support_height(steps, floor).max() == 0.0


def test_the_body_shapes_are_sampled_densely_along_every_capsule():
    """The props keep clear of spheres sampled along each limb and trunk capsule no further
    apart than SAMPLE_M (a 5 cm slab cannot pass between two), ends included, with the
    capsule's radius; the feet are left to their soles."""
    from prism_tools.synth.props import SAMPLE_M, body_shapes

    g, p = _sitting(1)
    centre, radius, bodies, where = body_shapes(g, p, BODY)
    assert SAMPLE_M <= 0.025 and not np.isin(bodies, (7, 8, 10, 11)).any()
    for geom in BODY.geoms:
        if geom.kind != "capsule" or geom.body in (7, 8, 10, 11):
            continue
        k = bodies == geom.body
        c = centre[0, k][np.argsort(where[k])]
        assert np.linalg.norm(np.diff(c, axis=0), axis=-1).max() <= SAMPLE_M + 1e-9
        np.testing.assert_allclose(radius[k], geom.size[0])
        np.testing.assert_allclose(np.sort(where[k])[[0, -1]], [0.0, 1.0])
