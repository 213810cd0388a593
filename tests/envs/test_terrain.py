"""Terrain: scene builders, rasterised height field, height-map observation, MuJoCo hfield."""

from __future__ import annotations

from types import SimpleNamespace

import mujoco
import numpy as np
import pytest
import trimesh

from envs.heightfield import (
    HeightField,
    add_heightfield,
    rasterize,
    sample_heightmap,
)
from envs.terrain import (
    SCENE_NAMES,
    Scene,
    boxes_scene,
    chair_scene,
    flat_scene,
    make_scene,
    scene_from_objects,
    stairs_scene,
)
from grip.task.observations import heightmap_grid

RADIUS = 0.05


def _box_scene(center_xy=(0.5, -0.2), extents=(0.4, 0.6, 0.3)) -> Scene:
    box = trimesh.creation.box(
        extents=extents,
        transform=trimesh.transformations.translation_matrix(
            (center_xy[0], center_xy[1], extents[2] / 2)
        ),
    )
    return Scene("box", (box,))


def _rot(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s], [s, c]])


@pytest.fixture(scope="module")
def stairs_hf() -> HeightField:
    hf = rasterize(stairs_scene())
    assert hf is not None
    return hf


# ---------------------------------------------------------------------------------------------
# Rasterisation
# ---------------------------------------------------------------------------------------------


def test_flat_scene_has_no_height_field():
    assert flat_scene().is_flat
    assert rasterize(flat_scene()) is None
    assert not stairs_scene().is_flat


def test_rasterize_single_box():
    hf = rasterize(_box_scene(), cell_m=0.02, margin_m=0.5)
    assert hf is not None
    assert hf.max_height == pytest.approx(0.3)
    assert hf.heights.min() == 0.0
    lo, hi = hf.extent_xy
    # Covers the box bounds (x 0.3..0.7, y -0.5..0.1) plus the margin.
    assert lo[0] <= 0.3 - 0.5 and lo[1] <= -0.5 - 0.5
    assert hi[0] >= 0.7 + 0.5 and hi[1] >= 0.1 + 0.5
    assert hi[0] <= 0.7 + 0.5 + 0.02 and hi[1] <= 0.1 + 0.5 + 0.02

    rng = np.random.default_rng(0)
    inside = rng.uniform((0.3 + 0.03, -0.5 + 0.03), (0.7 - 0.03, 0.1 - 0.03), (500, 2))
    np.testing.assert_allclose(hf.sample(inside), 0.3, atol=1e-9)
    pts = rng.uniform(lo - 1.0, hi + 1.0, (4000, 2))
    away = (np.abs(pts[:, 0] - 0.5) > 0.2 + 0.03) | (np.abs(pts[:, 1] + 0.2) > 0.3 + 0.03)
    np.testing.assert_array_equal(hf.sample(pts[away]), 0.0)
    # Every node is either on the box top or on the floor.
    assert set(np.unique(np.round(hf.heights, 9))) == {0.0, 0.3}


def test_rasterize_stairs_step_heights(stairs_hf):
    # Defaults: 4 rises of 0.15 m, treads 0.30 m deep starting at y = 0.8, landing 1.0 m,
    # width 1.2 m centred on x = 0.
    pts = np.array([
        [0.0, 0.0], [0.0, 0.7],            # before the stairs
        [0.0, 0.95], [0.3, 1.25], [-0.5, 1.55],  # treads 1..3
        [0.0, 1.85], [0.4, 2.5], [0.0, 2.95],  # top tread / landing
        [0.0, 3.1], [0.7, 1.25], [-0.7, 2.0],  # behind the landing, beside the stairs
    ])  # fmt: skip
    expected = [0, 0, 0.15, 0.30, 0.45, 0.60, 0.60, 0.60, 0, 0, 0]
    np.testing.assert_allclose(stairs_hf.sample(pts), expected, atol=1e-9)
    assert stairs_hf.max_height == pytest.approx(0.6)


def test_rasterize_clips_below_floor_and_keeps_highest_surface():
    low = trimesh.creation.box(extents=(0.4, 0.4, 0.2))  # z in [-0.1, 0.1]
    sunk = trimesh.creation.box(
        extents=(0.2, 0.2, 0.2),
        transform=trimesh.transformations.translation_matrix((1.0, 0.0, -0.2)),
    )
    high = trimesh.creation.box(
        extents=(0.1, 0.1, 0.5),
        transform=trimesh.transformations.translation_matrix((0.0, 0.0, 0.25)),
    )
    hf = rasterize(Scene("mix", (low, sunk, high)), margin_m=0.1)
    np.testing.assert_allclose(hf.sample(np.array([[0.15, 0.15], [0.0, 0.0], [1.0, 0.0]])),
                               [0.1, 0.5, 0.0], atol=1e-9)  # fmt: skip
    assert hf.heights.min() >= 0.0


# ---------------------------------------------------------------------------------------------
# HeightField
# ---------------------------------------------------------------------------------------------


def test_heightfield_sample_bilinear():
    h = np.array([[0.0, 1.0, 0.0, 2.0],
                  [2.0, 5.0, 1.0, 0.5],
                  [0.0, 0.0, 3.0, 1.0]])  # fmt: skip
    hf = HeightField(origin_xy=np.array([1.0, -2.0]), cell_m=0.5, heights=h)
    assert hf.shape == (3, 4)
    assert hf.max_height == 5.0

    # Every node, edges included (the grid rectangle is closed).
    ii, jj = np.meshgrid(np.arange(3), np.arange(4), indexing="ij")
    nodes = np.column_stack([1.0 + 0.5 * jj.ravel(), -2.0 + 0.5 * ii.ravel()])
    np.testing.assert_allclose(hf.sample(nodes), h.ravel(), atol=1e-12)

    # Cell centres: mean of the 4 corners; edge midpoints: mean of 2 nodes.
    centres = nodes.reshape(3, 4, 2)[:-1, :-1].reshape(-1, 2) + 0.25
    corner_mean = 0.25 * (h[:-1, :-1] + h[:-1, 1:] + h[1:, :-1] + h[1:, 1:])
    np.testing.assert_allclose(hf.sample(centres), corner_mean.ravel(), atol=1e-12)
    mid_x = nodes.reshape(3, 4, 2)[:, :-1].reshape(-1, 2) + np.array([0.25, 0.0])
    np.testing.assert_allclose(hf.sample(mid_x), (0.5 * (h[:, :-1] + h[:, 1:])).ravel(),
                               atol=1e-12)  # fmt: skip
    mid_y = nodes.reshape(3, 4, 2)[:-1, :].reshape(-1, 2) + np.array([0.0, 0.25])
    np.testing.assert_allclose(hf.sample(mid_y), (0.5 * (h[:-1] + h[1:])).ravel(), atol=1e-12)

    # A generic point: bilinear formula in cell (row 1, col 1), fu = 0.3, fv = 0.8.
    p = np.array([[1.0 + 0.5 * 1.3, -2.0 + 0.5 * 1.8]])
    fu, fv = 0.3, 0.8
    want = ((1 - fu) * (1 - fv) * h[1, 1] + fu * (1 - fv) * h[1, 2]
            + (1 - fu) * fv * h[2, 1] + fu * fv * h[2, 2])  # fmt: skip
    np.testing.assert_allclose(hf.sample(p), [want], atol=1e-12)

    # Outside the grid (even just outside a non-zero edge): the floor.
    outside = np.array([[0.999, -1.0], [2.501, -1.5], [1.5, -2.001], [1.5, -0.999],
                        [-50.0, 3.0], [1e9, -1e9]])  # fmt: skip
    np.testing.assert_array_equal(hf.sample(outside), 0.0)

    # The output buffer is filled and returned.
    out = np.full(len(nodes), -1.0)
    assert hf.sample(nodes, out=out) is out
    np.testing.assert_allclose(out, h.ravel(), atol=1e-12)


def test_heightfield_validation():
    with pytest.raises(ValueError):
        HeightField(np.zeros(2), 0.1, -np.ones((3, 3)))
    with pytest.raises(ValueError):
        HeightField(np.zeros(2), 0.1, np.zeros((1, 5)))
    with pytest.raises(ValueError):
        HeightField(np.zeros(2), 0.0, np.zeros((3, 3)))
    with pytest.raises(ValueError):
        HeightField(np.zeros(3), 0.1, np.zeros((3, 3)))
    hf = HeightField(np.zeros(2), 0.1, np.zeros((3, 3)))
    assert not hf.heights.flags.writeable
    with pytest.raises(ValueError):
        hf.sample(np.zeros(4))


# ---------------------------------------------------------------------------------------------
# Height-map observation
# ---------------------------------------------------------------------------------------------


def test_heightmap_grid_layout():
    g = heightmap_grid()
    assert g.shape == (625, 2) and g.dtype == np.float64 and g.flags.c_contiguous
    np.testing.assert_allclose(g.min(axis=0), [-0.75, -0.75])
    np.testing.assert_allclose(g.max(axis=0), [0.75, 0.75])
    np.testing.assert_allclose(g[312], [0.0, 0.0], atol=1e-15)  # centre sample
    s = np.linspace(-0.75, 0.75, 25)
    gg = g.reshape(25, 25, 2)
    np.testing.assert_allclose(gg[..., 0], np.broadcast_to(s, (25, 25)))  # columns: forward x
    np.testing.assert_allclose(gg[..., 1], np.broadcast_to(s[:, None], (25, 25)))  # rows: left y
    np.testing.assert_allclose(g[1] - g[0], [1.5 / 24, 0.0])  # x varies fastest
    assert heightmap_grid(5, 1.0).shape == (25, 2)


def test_sample_heightmap_heading_rotation():
    # A box ahead of the origin along world +y: x in [-0.2, 0.2], y in [0.25, 0.65].
    hf = rasterize(_box_scene(center_xy=(0.0, 0.45), extents=(0.4, 0.4, 0.3)))
    g = heightmap_grid()
    clear = 0.03  # skip samples within ~a cell of the box edges

    def expected(fwd_lo, fwd_hi, left_lo, left_hi):
        x, y = g[:, 0], g[:, 1]
        inside = (x > fwd_lo + clear) & (x < fwd_hi - clear)
        inside &= (y > left_lo + clear) & (y < left_hi - clear)
        outside = (x < fwd_lo - clear) | (x > fwd_hi + clear)
        outside |= (y < left_lo - clear) | (y > left_hi + clear)
        return inside, outside

    # Heading 90 deg (facing world +y, the rest pose): the box is straight ahead, local +x.
    hm = sample_heightmap(hf, np.zeros(2), _rot(np.pi / 2), g)
    inside, outside = expected(0.25, 0.65, -0.2, 0.2)
    assert inside.sum() >= 25 and outside.sum() > 400
    np.testing.assert_allclose(hm[inside], 0.3, atol=1e-9)
    np.testing.assert_array_equal(hm[outside], 0.0)
    # Image view: rows = left, columns = forward; the box is in the right-hand middle.
    img = hm.reshape(25, 25)
    assert img[12, 20] == pytest.approx(0.3) and img[12, 4] == 0.0 and img[20, 12] == 0.0

    # Heading 0 (facing world +x): the same box is on the left, local +y.
    hm0 = sample_heightmap(hf, np.zeros(2), _rot(0.0), g)
    inside, outside = expected(-0.2, 0.2, 0.25, 0.65)
    np.testing.assert_allclose(hm0[inside], 0.3, atol=1e-9)
    np.testing.assert_array_equal(hm0[outside], 0.0)

    # Any pose equals sampling the world points center + grid @ rot2.T; `out` is reused.
    rng = np.random.default_rng(1)
    out = np.empty(len(g))
    for _ in range(5):
        c, rot = rng.uniform(-1, 1, 2), _rot(rng.uniform(-np.pi, np.pi))
        res = sample_heightmap(hf, c, rot, g, out=out)
        assert res is out
        np.testing.assert_allclose(res, hf.sample(c + g @ rot.T), atol=1e-12)


def test_sample_heightmap_flat_is_zero():
    g = heightmap_grid()
    np.testing.assert_array_equal(sample_heightmap(None, np.zeros(2), np.eye(2), g), 0.0)
    out = np.ones(len(g))
    assert sample_heightmap(None, np.zeros(2), np.eye(2), g, out=out) is out
    np.testing.assert_array_equal(out, 0.0)


# ---------------------------------------------------------------------------------------------
# MuJoCo
# ---------------------------------------------------------------------------------------------


def _balls_mjcf(positions) -> str:
    """Plane floor + free spheres (radius 5 cm) that touch the floor but not each other."""
    bodies = "".join(
        f'<body name="ball{i}" pos="{x} {y} {z}"><freejoint/>'
        f'<geom type="sphere" size="{RADIUS}" mass="0.2" contype="2" conaffinity="1"/></body>'
        for i, (x, y, z) in enumerate(positions)
    )
    return (
        '<mujoco><option timestep="0.002"/><worldbody>'
        '<geom name="floor" type="plane" size="0 0 0.05" contype="1" conaffinity="0" '
        f'friction="0.9 0.005 0.0001"/>{bodies}</worldbody></mujoco>'
    )


def _drop(hf: HeightField, xy: np.ndarray, seconds: float = 1.0) -> np.ndarray:
    """Drop balls 0.2 m above the terrain at xy (N, 2); return their final positions (N, 3)."""
    z0 = hf.sample(xy) + RADIUS + 0.2
    model = mujoco.MjModel.from_xml_string(add_heightfield(_balls_mjcf(np.c_[xy, z0]), hf))
    data = mujoco.MjData(model)
    for _ in range(round(seconds / model.opt.timestep)):
        mujoco.mj_step(model, data)
    assert np.abs(data.qvel.reshape(-1, 6)[:, :3]).max() < 0.01  # at rest (spin is free)
    return data.qpos.reshape(-1, 7)[:, :3].copy()


def test_mujoco_balls_rest_on_stairs_and_floor(stairs_hf):
    xy = np.array([[0.0, 0.95], [0.2, 1.25], [-0.3, 1.55], [0.0, 2.3],  # treads and landing
                   [0.0, 0.0], [1.2, 1.2], [0.0, 3.6]])  # fmt: skip  # floor around
    pos = _drop(stairs_hf, xy)
    want = np.array([0.15, 0.30, 0.45, 0.60, 0.0, 0.0, 0.0]) + RADIUS
    np.testing.assert_allclose(pos[:, 2], want, atol=0.01)
    np.testing.assert_allclose(pos[:, :2], xy, atol=0.01)  # dropped straight, did not roll


def test_mujoco_balls_rest_on_boxes():
    hf = rasterize(boxes_scene())
    xy = np.array([[0.0, 1.0], [0.95, 0.35], [-0.9, -0.45], [0.3, -1.05], [0.0, 0.0]])
    pos = _drop(hf, xy)
    np.testing.assert_allclose(pos[:, 2], [0.15 + RADIUS, 0.30 + RADIUS, 0.45 + RADIUS,
                                           0.25 + RADIUS, RADIUS], atol=0.01)  # fmt: skip


def test_mujoco_hfield_reproduces_heights(stairs_hf):
    """Vertical rays against the compiled hfield hit exactly the height-field nodes."""
    xml = add_heightfield(_balls_mjcf([]), stairs_hf)
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "terrain")
    assert model.geom_contype[gid] == 1 and model.geom_conaffinity[gid] == 0
    assert model.geom_friction[gid][0] == pytest.approx(0.9)  # copied from the floor
    ny, nx = stairs_hf.shape
    assert (model.hfield_nrow[0], model.hfield_ncol[0]) == (ny, nx)

    rng = np.random.default_rng(2)
    ii, jj = rng.integers(0, ny, 300), rng.integers(0, nx, 300)
    pts = stairs_hf.origin_xy + np.c_[jj, ii] * stairs_hf.cell_m
    geomid = np.zeros(1, np.int32)
    down = np.array([0.0, 0.0, -1.0])
    z = np.array(
        [
            2.0 - mujoco.mj_ray(model, data, np.array([x, y, 2.0]), down, None, 1, -1, geomid)
            for x, y in pts
        ]
    )
    np.testing.assert_allclose(z, stairs_hf.heights[ii, jj], atol=1e-5)


def test_add_heightfield_structure():
    hf = HeightField(np.array([-0.5, -0.5]), 0.5, np.array([[0.0, 0.0, 0.0],
                                                            [0.0, 0.2, 0.0],
                                                            [0.0, 0.0, 0.0]]))  # fmt: skip
    base = "<mujoco><worldbody><geom type='plane' size='1 1 0.1'/></worldbody></mujoco>"
    xml = add_heightfield(base, hf, name="bump")
    model = mujoco.MjModel.from_xml_string(xml)
    assert model.nhfield == 1 and model.ngeom == 2
    np.testing.assert_allclose(model.hfield_size[0], [0.5, 0.5, 0.2, 0.01])
    np.testing.assert_allclose(model.hfield_data.reshape(3, 3), hf.heights / 0.2, atol=1e-6)
    with pytest.raises(ValueError, match="bump"):
        add_heightfield(xml, hf, name="bump")
    with pytest.raises(ValueError, match="worldbody"):
        add_heightfield("<mujoco/>", hf)


# ---------------------------------------------------------------------------------------------
# Scene builders and validation
# ---------------------------------------------------------------------------------------------


def test_builders_place_objects_as_specified():
    # Boxes: several heights in 0.15..0.45 m, nothing at the origin where a clip starts.
    hf = rasterize(boxes_scene())
    assert len(boxes_scene().meshes) >= 3
    assert 0.4 <= hf.max_height <= 0.45 + 1e-9
    ang = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    ring = np.concatenate([r * np.c_[np.cos(ang), np.sin(ang)] for r in (0.0, 0.2, 0.4)])
    np.testing.assert_array_equal(hf.sample(ring), 0.0)

    # Chair behind the origin (-y): seat 0.45 m, backrest higher and further back.
    hf = rasterize(chair_scene())
    seat, back, front = hf.sample(np.array([[0.0, -0.33], [0.0, -0.52], [0.0, 0.0]]))
    assert seat == pytest.approx(0.45) and back == pytest.approx(0.85) and front == 0.0
    np.testing.assert_array_equal(hf.sample(np.array([[0.0, 0.3], [0.6, -0.3]])), 0.0)


def test_scene_from_objects():
    box = trimesh.creation.box(
        extents=(0.5, 0.5, 0.7),
        transform=trimesh.transformations.translation_matrix((1.0, 2.0, 0.35)),
    )
    objects = {"table": SimpleNamespace(vertices=np.asarray(box.vertices),
                                        faces=np.asarray(box.faces))}  # fmt: skip
    scene = make_scene("objects", objects)
    assert scene.name == "objects" and len(scene.meshes) == 1
    hf = rasterize(scene)
    np.testing.assert_allclose(hf.sample(np.array([[1.0, 2.0], [0.0, 0.0]])), [0.7, 0.0])
    # Mappings with the same keys work too; an empty mapping is the flat floor.
    assert len(scene_from_objects({"t": {"vertices": box.vertices, "faces": box.faces}}).meshes)
    assert scene_from_objects({}).is_flat


@pytest.mark.parametrize(
    ("vertices", "faces", "match"),
    [
        (np.array([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]], float), np.array([[0, 1, 2]]), "NaN"),
        (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 3]]), "range"),
        (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, -1, 2]]), "range"),
        (np.zeros((3, 2)), np.array([[0, 1, 2]]), "shape"),
        (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([0, 1, 2]), "shape"),
        (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0.0, 1, 2]]), "integer"),
    ],
)
def test_scene_from_objects_rejects_bad_input(vertices, faces, match):
    objects = {"good": SimpleNamespace(vertices=np.eye(3), faces=np.array([[0, 1, 2]])),
               "broken_chair": SimpleNamespace(vertices=vertices, faces=faces)}  # fmt: skip
    with pytest.raises(ValueError, match=match) as err:
        scene_from_objects(objects)
    assert "'broken_chair'" in str(err.value)


def test_scene_from_objects_rejects_missing_fields():
    with pytest.raises(ValueError, match="'lamp'"):
        scene_from_objects({"lamp": SimpleNamespace(vertices=np.eye(3))})


def test_make_scene_names():
    for name in ("flat", "boxes", "stairs", "chair"):
        assert make_scene(name).name == name
    assert set(SCENE_NAMES) == {"flat", "boxes", "stairs", "chair", "objects"}
    with pytest.raises(ValueError, match="flat, boxes, stairs, chair, objects"):
        make_scene("lava")
    with pytest.raises(ValueError, match="objects"):
        make_scene("objects")


def test_an_overhang_is_a_geom_the_body_passes_under():
    """A slab 0.50-0.55 m above the floor (a stool's seat, prism_tools.synth.props) is not
    rasterised (the field would fill it down to the floor) but added as a static geom: a ball
    dropped on it rests on its top, one under it rests on the floor; the box beside it stays in
    the height field. The scenes of the tracking env compile it so."""
    from envs.heightfield import add_static_meshes
    from envs.scenes import HumanoidScenes
    from envs.terrain import scene_from_objects, split_overhangs
    from grip.core.body import BodyParams
    from grip.core.mjcf import MjcfConfig
    from grip.sim.humanoid import HumanoidConfig
    from prism_tools.streams import box_object

    objects = {"step": box_object(np.array([1.0, 0.0, 0.15]), np.array([0.4, 0.4, 0.3])),
               "seat": box_object(np.array([0.0, 0.0, 0.525]), np.array([0.4, 0.4, 0.05]))}
    resting, over = split_overhangs(scene_from_objects(objects))
    assert len(resting.meshes) == 1 and len(over) == 1
    hf = rasterize(resting)
    np.testing.assert_allclose(hf.sample(np.array([[0.0, 0.0], [1.0, 0.0]])), [0.0, 0.3])
    xy = np.array([[0.0, 0.0], [1.0, 0.0]])
    xml = add_static_meshes(add_heightfield(_balls_mjcf([[0.0, 0.0, 0.7], [0.1, 0.0, 0.2],
                                                         [1.0, 0.0, 0.6]]), hf), over)  # fmt: skip
    model = mujoco.MjModel.from_xml_string(xml)
    gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "overhang_0")
    assert model.geom_contype[gid] == 1 and model.geom_conaffinity[gid] == 0
    assert model.geom_friction[gid][0] == pytest.approx(0.9)  # copied from the floor
    data = mujoco.MjData(model)
    for _ in range(500):
        mujoco.mj_step(model, data)
    z = data.qpos.reshape(-1, 7)[:, 2]  # on the slab, under it on the floor, on the box
    np.testing.assert_allclose(z, [0.55 + RADIUS, RADIUS, 0.3 + RADIUS], atol=0.01)
    with pytest.raises(ValueError, match="overhang_0"):
        add_static_meshes(xml, over)
    scene = {n: (o.vertices, o.faces) for n, o in objects.items()}
    h = HumanoidScenes(HumanoidConfig(), MjcfConfig()).get(BodyParams(), scene, tag="stool")
    names = {mujoco.mj_id2name(h.model, mujoco.mjtObj.mjOBJ_GEOM, i) for i in range(h.model.ngeom)}
    assert {"terrain", "overhang_0"} <= names
    np.testing.assert_allclose(h.heights_around(np.zeros(2), np.eye(2), xy), [0.0, 0.3])
