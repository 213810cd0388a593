"""Terrain scenes: one height field shared by the MuJoCo physics and the height-map observation.

Design
------
A terrain :class:`Scene` is a tuple of triangle meshes (trimesh) in world coordinates: z up,
metres, floor at z = 0. Built-in scenes are made of boxes (:func:`boxes_scene`,
:func:`stairs_scene`, :func:`chair_scene`); a recording's ``objects`` become a scene through
:func:`scene_from_objects`; :func:`make_scene` picks one by name.

The scene's meshes are rasterised into ONE height field (:mod:`envs.heightfield`:
:func:`~envs.heightfield.rasterize` makes a :class:`~envs.heightfield.HeightField`): a regular
xy grid whose value at each node is the highest surface point above it, found by casting a
vertical ray downwards with trimesh (``rtree`` accelerates the ray queries). That single grid is
then used twice:

* Physics: :func:`~envs.heightfield.add_heightfield` writes it into the MJCF as an ``<hfield>``
  asset plus a static ``type="hfield"`` geom whose vertices are exactly the grid nodes. MuJoCo
  splits each cell into two triangles while the observation interpolates bilinearly; the two
  agree at every node and in every planar cell (flat tops, floor, the one-cell ramp along a
  straight edge) and differ only in the few cells under a box corner, by at most a quarter of
  the height jump.
  The flat floor plane stays as it is; the height field sits on top of it, with the floor's
  collision bits (``contype=1, conaffinity=0``) and contact parameters.
* Observation: :func:`~envs.heightfield.sample_heightmap` reads the same grid at the 25 x 25
  points of :func:`~envs.heightfield.heightmap_grid` (1.5 m x 1.5 m, centred on the humanoid,
  heading-aligned) with :meth:`~envs.heightfield.HeightField.sample` (vectorised bilinear
  interpolation, ~20 us per call).

So the policy observes exactly the geometry it collides with, and nothing has to be kept in sync.

Why not give MuJoCo the meshes directly? MuJoCo collides with the *convex hull* of a mesh geom,
so stairs would become a ramp-shaped solid and a chair a solid blob with the space above the
seat filled in; decomposing every object into convex parts is a whole pipeline of its own. A
height field is exact for everything that is a function z = h(x, y).

Overhangs: a height field cannot represent the space under a stool's seat or a table top. A
mesh that does not reach the floor (its lowest vertex more than :data:`OVERHANG_MIN_M` above it:
the open-underside seats of :mod:`prism_tools.synth.props`) is therefore not rasterised but given
to MuJoCo as a static mesh geom (:func:`split_overhangs`, :func:`~envs.heightfield.
add_static_meshes`): MuJoCo collides with its convex hull, exact for a slab or box. The height-map
observation does not show such overhangs (only what the height field holds). A mesh that rests on
the floor is rasterised whole: the space under a chair seat given as one mesh with its legs is
filled down to the floor (sitting on it works, putting the feet under it does not).

Caveats: vertical walls become slopes one cell wide (2 cm with the default ``cell_m``), and
features thinner than a cell can be missed or widened by up to one cell.

Grid convention: see :mod:`envs.heightfield`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import trimesh

__all__ = [
    "DEFAULT_BOXES",
    "SCENE_NAMES",
    "Scene",
    "boxes_scene",
    "chair_scene",
    "flat_scene",
    "make_scene",
    "scene_from_objects",
    "split_overhangs",
    "stairs_scene",
]

SCENE_NAMES: tuple[str, ...] = ("flat", "boxes", "stairs", "chair", "objects")
"""Names accepted by :func:`make_scene`."""

OVERHANG_MIN_M = 0.01
"""A mesh whose lowest vertex lies more than this above the floor is an overhang (a geom, not
part of the height field)."""

DEFAULT_BOXES: tuple[tuple[float, float, float, float, float], ...] = (
    # (centre x, centre y, size x, size y, height), metres. The humanoid starts at the origin
    # facing +y; every box keeps at least 0.6 m clear of the origin.
    (0.0, 1.0, 0.6, 0.4, 0.15),
    (0.95, 0.35, 0.4, 0.5, 0.30),
    (-0.9, -0.45, 0.5, 0.4, 0.45),
    (0.3, -1.05, 0.7, 0.3, 0.25),
)
"""Boxes of :func:`boxes_scene`: ``(cx, cy, sx, sy, height)`` in metres, resting on the floor."""


# --------------------------------------------------------------------------------------------
# Scenes
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Scene:
    """A terrain scene: static triangle meshes resting on the floor.

    Attributes:
        name: Scene name (``"flat"``, ``"boxes"``, ``"stairs"``, ``"chair"``, ``"objects"`` for
            the built-in builders).
        meshes: Triangle meshes in world coordinates (z up, metres, floor at z = 0). An empty
            tuple is the flat floor.
    """

    name: str
    meshes: tuple[trimesh.Trimesh, ...] = ()

    def __post_init__(self) -> None:
        meshes = tuple(self.meshes)
        for i, m in enumerate(meshes):
            if not isinstance(m, trimesh.Trimesh):
                raise TypeError(f"scene {self.name!r}: mesh {i} is {type(m).__name__}, "
                                "not trimesh.Trimesh")  # fmt: skip
            if len(m.faces) == 0:
                raise ValueError(f"scene {self.name!r}: mesh {i} has no faces")
            if not np.isfinite(m.vertices).all():
                raise ValueError(f"scene {self.name!r}: mesh {i} has non-finite vertices")
        object.__setattr__(self, "meshes", meshes)

    @property
    def is_flat(self) -> bool:
        """True when the scene has no meshes (plain floor, no height field needed)."""
        return len(self.meshes) == 0


def _box(center: Sequence[float], extents: Sequence[float]) -> trimesh.Trimesh:
    """Axis-aligned box mesh.

    Args:
        center: Box centre (3,), metres.
        extents: Full side lengths (3,), metres, all > 0.

    Returns:
        The box as a watertight trimesh.
    """
    if min(extents) <= 0.0:
        raise ValueError(f"box extents must be positive, got {tuple(extents)}")
    return trimesh.creation.box(
        extents=np.asarray(extents, dtype=np.float64),
        transform=trimesh.transformations.translation_matrix(np.asarray(center, np.float64)),
    )


def flat_scene() -> Scene:
    """The flat floor: no meshes.

    Returns:
        ``Scene("flat", ())``.
    """
    return Scene("flat", ())


def boxes_scene(
    boxes: Sequence[tuple[float, float, float, float, float]] = DEFAULT_BOXES,
) -> Scene:
    """A few boxes of different heights standing on the floor around (not at) the origin.

    Args:
        boxes: ``(cx, cy, sx, sy, height)`` per box in metres: centre xy, side lengths in x and
            y, and height (the box spans z in [0, height]). Defaults to :data:`DEFAULT_BOXES`
            (heights 0.15-0.45 m, all at least 0.6 m away from the origin).

    Returns:
        Scene ``"boxes"`` with one box mesh per entry.
    """
    meshes = tuple(_box((cx, cy, h / 2.0), (sx, sy, h)) for cx, cy, sx, sy, h in boxes)
    return Scene("boxes", meshes)


def stairs_scene(
    n_steps: int = 4,
    rise_m: float = 0.15,
    run_m: float = 0.30,
    width_m: float = 1.2,
    start_m: float = 0.8,
    landing_m: float = 1.0,
    center_x_m: float = 0.0,
) -> Scene:
    """A straight staircase going up along world +y, with a top landing.

    Tread k (k = 1..n_steps) is at height ``k * rise_m`` and starts at
    ``y = start_m + (k - 1) * run_m``; the top tread is the landing and is ``run_m + landing_m``
    deep. The stairs span ``x`` in ``center_x_m +- width_m / 2``. The humanoid starts at the
    origin facing +y, so it walks straight into the first step ``start_m`` ahead.

    Args:
        n_steps: Number of rises (>= 1).
        rise_m: Height of each rise, metres.
        run_m: Depth of each tread, metres.
        width_m: Stair width along x, metres.
        start_m: y of the front edge of the first step, metres.
        landing_m: Extra depth of the top tread (the landing), metres (>= 0).
        center_x_m: x of the stair centre line, metres.

    Returns:
        Scene ``"stairs"`` with one box per step (each from the floor up to its tread).
    """
    if n_steps < 1:
        raise ValueError(f"n_steps must be >= 1, got {n_steps}")
    if landing_m < 0.0:
        raise ValueError(f"landing_m must be >= 0, got {landing_m}")
    meshes = []
    for k in range(1, n_steps + 1):
        y0 = start_m + (k - 1) * run_m
        depth = run_m + (landing_m if k == n_steps else 0.0)
        h = k * rise_m
        meshes.append(_box((center_x_m, y0 + depth / 2.0, h / 2.0), (width_m, depth, h)))
    return Scene("stairs", tuple(meshes))


def chair_scene(
    seat_height_m: float = 0.45,
    seat_width_m: float = 0.45,
    seat_depth_m: float = 0.42,
    back_height_m: float = 0.85,
    front_gap_m: float = 0.12,
    thickness_m: float = 0.04,
    leg_m: float = 0.04,
) -> Scene:
    """A simple chair made of boxes, behind the origin (at -y), facing +y.

    The humanoid starts at the origin facing +y, so it sits down by moving backwards. The seat
    spans ``x`` in ``+- seat_width_m / 2`` and ``y`` in ``[-front_gap_m - seat_depth_m,
    -front_gap_m]``; the backrest stands on its back edge. Note that in the height field the
    space under the seat is filled (see the module docstring), so the legs are only visible in
    :attr:`Scene.meshes`.

    Args:
        seat_height_m: Height of the seat top, metres.
        seat_width_m: Seat size along x, metres.
        seat_depth_m: Seat size along y, metres.
        back_height_m: Height of the backrest top, metres (> seat_height_m).
        front_gap_m: Distance from the origin to the front edge of the seat along -y, metres.
        thickness_m: Thickness of the seat board and of the backrest, metres.
        leg_m: Side of the square legs, metres.

    Returns:
        Scene ``"chair"``: seat, backrest and four legs.
    """
    if back_height_m <= seat_height_m:
        raise ValueError("back_height_m must be larger than seat_height_m")
    y_front = -front_gap_m
    y_back = -front_gap_m - seat_depth_m
    y_mid = 0.5 * (y_front + y_back)
    seat = _box((0.0, y_mid, seat_height_m - thickness_m / 2.0),
                (seat_width_m, seat_depth_m, thickness_m))  # fmt: skip
    back_h = back_height_m - seat_height_m
    back = _box((0.0, y_back + thickness_m / 2.0, seat_height_m + back_h / 2.0),
                (seat_width_m, thickness_m, back_h))  # fmt: skip
    leg_h = seat_height_m - thickness_m
    dx = seat_width_m / 2.0 - leg_m / 2.0
    legs = [
        _box((sx * dx, y, leg_h / 2.0), (leg_m, leg_m, leg_h))
        for sx in (-1.0, 1.0)
        for y in (y_front - leg_m / 2.0, y_back + leg_m / 2.0)
    ]
    return Scene("chair", (seat, back, *legs))


def _field(obj: Any, key: str) -> Any:
    """``obj.key``, or ``obj[key]`` for mappings (recordings loaded as plain dicts)."""
    if isinstance(obj, Mapping):
        return obj[key]
    return getattr(obj, key)


def scene_from_objects(objects: Mapping[str, Any]) -> Scene:
    """Scene from a recording's objects.

    Args:
        objects: Object name -> object with ``.vertices`` (V, 3) float array (world
            coordinates, z up, metres, floor at z = 0) and ``.faces`` (F, 3) integer array of
            vertex indices (mappings with those keys are accepted too). An empty mapping gives
            a flat scene.

    Returns:
        Scene ``"objects"`` with one mesh per object, in the mapping's order.

    Raises:
        ValueError: An object lacks vertices/faces, has non-finite vertices, wrong shapes, a
            non-integer face array or face indices out of range; the message names the object.
    """
    meshes = []
    for name, obj in objects.items():
        try:
            vertices = np.asarray(_field(obj, "vertices"), dtype=np.float64)
            faces_raw = np.asarray(_field(obj, "faces"))
        except (AttributeError, KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"object {name!r}: needs numeric 'vertices' and 'faces' ({exc})") \
                from exc  # fmt: skip
        if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) < 3:
            raise ValueError(f"object {name!r}: vertices must have shape (V>=3, 3), "
                             f"got {vertices.shape}")  # fmt: skip
        if not np.isfinite(vertices).all():
            raise ValueError(f"object {name!r}: vertices contain NaN or inf")
        if faces_raw.ndim != 2 or faces_raw.shape[1] != 3 or len(faces_raw) == 0:
            raise ValueError(f"object {name!r}: faces must have shape (F>=1, 3), "
                             f"got {faces_raw.shape}")  # fmt: skip
        if not np.issubdtype(faces_raw.dtype, np.integer):
            raise ValueError(f"object {name!r}: faces must be integers, got {faces_raw.dtype}")
        faces = faces_raw.astype(np.int64)
        if faces.min() < 0 or faces.max() >= len(vertices):
            raise ValueError(f"object {name!r}: face indices out of range [0, {len(vertices)}), "
                             f"got [{faces.min()}, {faces.max()}]")  # fmt: skip
        meshes.append(trimesh.Trimesh(vertices=vertices, faces=faces, process=False))
    return Scene("objects", tuple(meshes))


def split_overhangs(scene: Scene) -> tuple[Scene, tuple[trimesh.Trimesh, ...]]:
    """The scene's meshes that rest on the floor (a scene of the same name, for the height
    field) and those that do not (overhangs: static geoms)."""
    resting = tuple(m for m in scene.meshes if float(m.vertices[:, 2].min()) <= OVERHANG_MIN_M)
    over = tuple(m for m in scene.meshes if float(m.vertices[:, 2].min()) > OVERHANG_MIN_M)
    return Scene(scene.name, resting), over


_BUILDERS: dict[str, Callable[[], Scene]] = {
    "flat": flat_scene,
    "boxes": boxes_scene,
    "stairs": stairs_scene,
    "chair": chair_scene,
}


def make_scene(name: str, objects: Mapping[str, Any] | None = None) -> Scene:
    """Scene by name, with default parameters.

    Args:
        name: One of :data:`SCENE_NAMES`.
        objects: A recording's objects (see :func:`scene_from_objects`); required for
            ``"objects"`` and ignored by the built-in scenes.

    Returns:
        The scene.

    Raises:
        ValueError: Unknown name, or ``"objects"`` without objects.
    """
    if name == "objects":
        if objects is None:
            raise ValueError("scene 'objects' needs the recording's objects")
        return scene_from_objects(objects)
    if name not in _BUILDERS:
        raise ValueError(f"unknown scene {name!r}; choose one of {', '.join(SCENE_NAMES)}")
    return _BUILDERS[name]()
