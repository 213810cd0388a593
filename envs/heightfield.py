"""The terrain height field: one grid shared by the MuJoCo physics and the height-map
observation.

:func:`rasterize` turns a :class:`envs.terrain.Scene` into a :class:`HeightField`,
:func:`add_heightfield` writes it into the MJCF, and :func:`sample_heightmap` reads it at the
points of :func:`grip.task.observations.heightmap_grid` for the observation. The design and its
caveats are in :mod:`envs.terrain`.

Grid convention (shared by :class:`HeightField`, MuJoCo and
:func:`grip.task.observations.heightmap_grid`): arrays are indexed ``[row, col]`` with rows along
world (or local) y and columns along x.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

from envs.terrain import Scene

__all__ = [
    "HeightField",
    "add_heightfield",
    "add_scene_assets",
    "add_static_meshes",
    "rasterize",
    "sample_heightmap",
]

_MAX_CELLS = 4_000_000  # rasterize() refuses grids larger than this (2000 x 2000 nodes)
_FLOOR_CONTACT_ATTRS = ("condim", "friction", "solref", "solimp", "solmix", "priority",
                        "margin", "gap")  # fmt: skip
_TERRAIN_RGBA = "0.62 0.56 0.48 1"
_OVERHANG_RGBA = "0.55 0.45 0.35 1"


# --------------------------------------------------------------------------------------------
# Height field
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class HeightField:
    """Terrain heights on a regular xy grid, with fast bilinear sampling.

    Node ``heights[i, j]`` is the terrain height at world
    ``(x, y) = origin_xy + (j, i) * cell_m``: rows run along y, columns along x (the MuJoCo
    hfield convention). Between nodes the height is interpolated bilinearly; outside the grid
    rectangle ``[x0, x0 + (nx-1) cell] x [y0, y0 + (ny-1) cell]`` (closed) it is 0 (the floor).

    The arrays are copied and made read-only at construction, and the per-cell bilinear
    coefficients are precomputed there, so :meth:`sample` is a handful of numpy operations.
    Instances compare by identity.

    Attributes:
        origin_xy: (2,) world xy of grid node (0, 0), metres.
        cell_m: Grid spacing, metres (> 0).
        heights: (ny, nx) float64 heights above z = 0, metres, >= 0; ny, nx >= 2.
    """

    origin_xy: np.ndarray
    cell_m: float
    heights: np.ndarray
    _inv: float = field(init=False, repr=False)
    _ox: float = field(init=False, repr=False)
    _oy: float = field(init=False, repr=False)
    _umax: float = field(init=False, repr=False)
    _vmax: float = field(init=False, repr=False)
    _iu_max: float = field(init=False, repr=False)
    _iv_max: float = field(init=False, repr=False)
    _ncx: float = field(init=False, repr=False)
    _coef: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] = field(init=False, repr=False)
    _max: float = field(init=False, repr=False)

    def __post_init__(self) -> None:
        origin = np.array(self.origin_xy, dtype=np.float64).reshape(-1)
        if origin.shape != (2,) or not np.isfinite(origin).all():
            raise ValueError(f"origin_xy must be 2 finite numbers, got {self.origin_xy!r}")
        cell = float(self.cell_m)
        if not (np.isfinite(cell) and cell > 0.0):
            raise ValueError(f"cell_m must be positive, got {self.cell_m!r}")
        h = np.array(self.heights, dtype=np.float64)
        if h.ndim != 2 or h.shape[0] < 2 or h.shape[1] < 2:
            raise ValueError(f"heights must have shape (ny>=2, nx>=2), got {h.shape}")
        if not np.isfinite(h).all() or h.min() < 0.0:
            raise ValueError("heights must be finite and >= 0")
        origin.setflags(write=False)
        h.setflags(write=False)
        ny, nx = h.shape
        # Bilinear coefficients per cell (ny-1, nx-1): h = a + b fu + c fv + d fu fv.
        a = h[:-1, :-1]
        b = h[:-1, 1:] - a
        c = h[1:, :-1] - a
        d = h[1:, 1:] - h[1:, :-1] - h[:-1, 1:] + a
        coef = tuple(np.ascontiguousarray(t).ravel() for t in (a, b, c, d))
        for name, value in (
            ("origin_xy", origin),
            ("cell_m", cell),
            ("heights", h),
            ("_inv", 1.0 / cell),
            ("_ox", float(origin[0])),
            ("_oy", float(origin[1])),
            ("_umax", float(nx - 1)),
            ("_vmax", float(ny - 1)),
            ("_iu_max", float(nx - 2)),
            ("_iv_max", float(ny - 2)),
            ("_ncx", float(nx - 1)),
            ("_coef", coef),
            ("_max", float(h.max())),
        ):
            object.__setattr__(self, name, value)

    @property
    def shape(self) -> tuple[int, int]:
        """Grid shape ``(ny, nx)``."""
        ny, nx = self.heights.shape
        return ny, nx

    @property
    def max_height(self) -> float:
        """Highest node, metres."""
        return self._max

    @property
    def extent_xy(self) -> np.ndarray:
        """(2, 2) world bounds ``[[x_min, y_min], [x_max, y_max]]`` of the grid, metres."""
        ny, nx = self.heights.shape
        return np.stack([self.origin_xy, self.origin_xy + self.cell_m * np.array([nx - 1, ny - 1])])

    def sample(self, xy: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Bilinear heights at world points.

        Args:
            xy: (N, 2) world xy, metres.
            out: Optional (N,) float64 buffer for the result.

        Returns:
            (N,) heights in metres; 0.0 for points outside the grid, NaN for non-finite points.
        """
        xy = np.asarray(xy, dtype=np.float64)
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise ValueError(f"xy must have shape (N, 2), got {xy.shape}")
        u = xy[:, 0] - self._ox
        u *= self._inv
        v = xy[:, 1] - self._oy
        v *= self._inv
        return self._interp(u, v, out)

    def _interp(self, u: np.ndarray, v: np.ndarray, out: np.ndarray | None) -> np.ndarray:
        """Bilinear interpolation at grid coordinates (column u, row v), both (N,), in cells."""
        # Cell index clamped into the grid (fmax/fmin: NaN -> a valid index, result stays NaN).
        iu = np.floor(u)
        np.fmax(iu, 0.0, out=iu)
        np.fmin(iu, self._iu_max, out=iu)
        iv = np.floor(v)
        np.fmax(iv, 0.0, out=iv)
        np.fmin(iv, self._iv_max, out=iv)
        fu = u - iu
        fv = v - iv
        iv *= self._ncx
        iv += iu
        k = iv.astype(np.intp)
        a, b, c, d = self._coef
        r = d[k]
        r *= fu
        r += c[k]
        r *= fv
        r += a[k]
        t = b[k]
        t *= fu
        r += t
        inside = u >= 0.0
        inside &= u <= self._umax
        inside &= v >= 0.0
        inside &= v <= self._vmax
        return np.multiply(r, inside, out=out)

    def _sample_rigid(
        self, center_xy: np.ndarray, rot2: np.ndarray, grid: np.ndarray, out: np.ndarray | None
    ) -> np.ndarray:
        """Heights at ``center_xy + grid @ rot2.T`` with the transform folded into grid units."""
        inv = self._inv
        m = np.multiply(rot2, inv)
        u = grid @ m[0]
        u += (center_xy[0] - self._ox) * inv
        v = grid @ m[1]
        v += (center_xy[1] - self._oy) * inv
        return self._interp(u, v, out)


def rasterize(scene: Scene, cell_m: float = 0.02, margin_m: float = 1.0) -> HeightField | None:
    """Rasterise a scene's meshes into one height field by downward ray casting.

    The grid covers the union of the meshes' xy bounds plus ``margin_m`` on every side; its
    nodes sit at ``(k + 1/2) * cell_m`` for integer k (so box edges at whole centimetres fall
    between nodes, not on them). At each node a vertical ray is cast down from above the scene
    and the highest hit is kept; nodes with no hit, or hits below z = 0, get 0. Rays are only
    cast inside each mesh's own xy bounds.

    Args:
        scene: The scene.
        cell_m: Grid spacing, metres.
        margin_m: Flat (zero) border around the meshes, metres (>= 0; keep at least one cell so
            the field is 0 on its boundary and continuous with the floor).

    Returns:
        The height field, or None for a flat scene.

    Raises:
        ValueError: Bad ``cell_m``/``margin_m``, or a grid larger than 4 million nodes.
    """
    if scene.is_flat:
        return None
    if not (np.isfinite(cell_m) and cell_m > 0.0):
        raise ValueError(f"cell_m must be positive, got {cell_m}")
    if not (np.isfinite(margin_m) and margin_m >= 0.0):
        raise ValueError(f"margin_m must be >= 0, got {margin_m}")
    bounds = np.array([m.bounds for m in scene.meshes], dtype=np.float64)  # (M, 2, 3)
    lo = bounds[:, 0, :2].min(axis=0) - margin_m
    hi = bounds[:, 1, :2].max(axis=0) + margin_m
    k0 = np.floor(lo / cell_m - 0.5).astype(np.int64)
    k1 = np.ceil(hi / cell_m - 0.5).astype(np.int64)
    nx, ny = (int(n) for n in np.maximum(k1 - k0 + 1, 2))
    if nx * ny > _MAX_CELLS:
        raise ValueError(f"height field of {ny} x {nx} nodes is too large; increase cell_m "
                         f"(scene spans {hi - lo} m)")  # fmt: skip
    xs = (k0[0] + 0.5 + np.arange(nx)) * cell_m
    ys = (k0[1] + 0.5 + np.arange(ny)) * cell_m
    heights = np.zeros((ny, nx))
    z_top = float(bounds[:, 1, 2].max()) + 1.0
    eps = 1e-9
    for mesh, b in zip(scene.meshes, bounds, strict=True):
        c0 = int(np.searchsorted(xs, b[0, 0] - eps, side="left"))  # first node >= x_min
        c1 = int(np.searchsorted(xs, b[1, 0] + eps, side="right"))  # past last node <= x_max
        r0 = int(np.searchsorted(ys, b[0, 1] - eps, side="left"))
        r1 = int(np.searchsorted(ys, b[1, 1] + eps, side="right"))
        if c1 <= c0 or r1 <= r0:
            continue
        gx, gy = np.meshgrid(xs[c0:c1], ys[r0:r1])
        origins = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z_top)])
        directions = np.zeros_like(origins)
        directions[:, 2] = -1.0
        locations, index_ray, _ = mesh.ray.intersects_location(
            origins, directions, multiple_hits=True
        )
        top = np.zeros(gx.size)
        np.maximum.at(top, index_ray, locations[:, 2])  # zeros: misses and hits below z = 0
        block = heights[r0:r1, c0:c1]
        np.maximum(block, top.reshape(block.shape), out=block)
    return HeightField(origin_xy=np.array([xs[0], ys[0]]), cell_m=float(cell_m), heights=heights)


# --------------------------------------------------------------------------------------------
# Height-map observation
# --------------------------------------------------------------------------------------------


def sample_heightmap(
    hf: HeightField | None,
    center_xy: np.ndarray,
    rot2: np.ndarray,
    grid: np.ndarray,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Terrain heights around the humanoid in its heading frame.

    The world sample points are ``center_xy + grid @ rot2.T``.

    Args:
        hf: The scene's height field, or None for a flat scene (all zeros).
        center_xy: (2,) world xy of the frame origin (e.g. the pelvis), metres.
        rot2: (2, 2) heading rotation, local -> world: ``[[cos, -sin], [sin, cos]]`` of the yaw
            of the forward axis (yaw 90 deg = facing world +y, the rest pose).
        grid: (n*n, 2) float64 local offsets from
            :func:`grip.task.observations.heightmap_grid`, metres.
        out: Optional (n*n,) float64 buffer for the result (reused across steps).

    Returns:
        (n*n,) heights above z = 0, metres (``out`` when given).
    """
    if hf is None:
        if out is None:
            return np.zeros(len(grid))
        out.fill(0.0)
        return out
    return hf._sample_rigid(center_xy, rot2, grid, out)


# --------------------------------------------------------------------------------------------
# MuJoCo
# --------------------------------------------------------------------------------------------


def _fmt(x: float) -> str:
    return f"{x:.9g}"


def add_heightfield(
    mjcf_xml: str,
    hf: HeightField,
    name: str = "terrain",
    *,
    base_m: float = 0.01,
    rgba: str = _TERRAIN_RGBA,
) -> str:
    """Add a height field as a static MuJoCo terrain geom to an MJCF document.

    Inserts ``<hfield name=name nrow=ny ncol=nx size="rx ry elev base" elevation="...">`` into
    ``<asset>`` (created if missing) and ``<geom name=name type="hfield" hfield=name>`` into
    ``<worldbody>``. The elevation data is passed inline, so the returned XML compiles with
    ``mujoco.MjModel.from_xml_string`` into a working terrain with no extra step:

    * MuJoCo's hfield spans ``2 rx`` with ``ncol`` vertices including both edges, so
      ``rx = (nx - 1) cell_m / 2`` (same for y) and the geom sits at the grid centre: MuJoCo
      vertex (i, j) is exactly at ``origin_xy + (j, i) * cell_m``.
    * MuJoCo normalises inline elevation to [0, 1] (subtracting the minimum) and scales it by
      ``size[2]``; we pass ``(h - h_min) / (h_max - h_min)``, put the geom at ``z = h_min``
      (0 for :func:`rasterize` output) and use ``size[2] = h_max - h_min``.
    * The inline ``elevation`` text is read image-like (its first row is the +y edge), so rows
      are written in reverse order.
    * The base (``size[3]``) reaches ``base_m`` below the lowest node (to the floor and beyond
      when ``h_min > 0``).

    The geom gets the floor's collision bits ``contype="1" conaffinity="0"`` (the humanoid's
    geoms have conaffinity bit 1), and copies the contact parameters (condim, friction, solref,
    solimp, ...) of the first plane geom of the worldbody (the floor) when there is one.

    Args:
        mjcf_xml: A complete ``<mujoco>`` document with a ``<worldbody>``.
        hf: The height field.
        name: Name of both the hfield asset and the geom (must be unused).
        base_m: Depth of the solid base below the lowest node, metres (> 0).
        rgba: Colour of the terrain geom.

    Returns:
        The modified document as a string.

    Raises:
        ValueError: No worldbody, or an hfield/geom of that name already exists.
    """
    if base_m <= 0.0:
        raise ValueError(f"base_m must be positive, got {base_m}")
    root, world, asset = _world_and_asset(mjcf_xml, ("hfield", "geom"), (name,))
    pos = _add_hfield_asset(asset, hf, name, base_m)
    attrs = {"name": name, "type": "hfield", "hfield": name, "pos": pos}
    _add_static_geom(world, attrs, rgba)
    return ET.tostring(root, encoding="unicode")


def _add_hfield_asset(asset: ET.Element, hf: HeightField, name: str, base_m: float) -> str:
    """Append the ``<hfield>`` of :func:`add_heightfield` to ``asset``; return the ``pos``
    attribute of a geom that puts it in place."""
    h = hf.heights
    ny, nx = h.shape
    h_min = float(h.min())
    span = float(h.max()) - h_min
    elev = (h - h_min) / span if span > 0.0 else np.zeros_like(h)
    rows = (" ".join(_fmt(x) for x in row) for row in elev[::-1])  # first text row = +y edge
    rx = 0.5 * (nx - 1) * hf.cell_m
    ry = 0.5 * (ny - 1) * hf.cell_m
    size_z = span if span > 0.0 else 1e-3  # flat field: any positive scale of all-zero data
    ET.SubElement(asset, "hfield", name=name, nrow=str(ny), ncol=str(nx),
                  size=" ".join(_fmt(s) for s in (rx, ry, size_z, base_m + h_min)),
                  elevation="\n".join(rows))  # fmt: skip
    cx = float(hf.origin_xy[0]) + rx
    cy = float(hf.origin_xy[1]) + ry
    return f"{_fmt(cx)} {_fmt(cy)} {_fmt(h_min)}"


def add_static_meshes(mjcf_xml: str, meshes, prefix: str = "overhang", *,
                      rgba: str = _OVERHANG_RGBA) -> str:  # fmt: skip
    """Add meshes as static MuJoCo geoms (the overhangs of :func:`envs.terrain.split_overhangs`:
    a stool's seat slab), with the floor's collision bits and contact parameters as
    :func:`add_heightfield` gives its field. MuJoCo collides with each mesh's convex hull.

    Args:
        mjcf_xml: A complete ``<mujoco>`` document with a ``<worldbody>``.
        meshes: Triangle meshes (``.vertices (V, 3)``, ``.faces (F, 3)``), world frame, m.
        prefix: Their mesh assets and geoms are named ``<prefix>_<k>`` (must be unused).
        rgba: Their colour.

    Returns:
        The modified document as a string.

    Raises:
        ValueError: No worldbody, or a name already in use.
    """
    names = [f"{prefix}_{k}" for k in range(len(meshes))]
    root, world, asset = _world_and_asset(mjcf_xml, ("mesh", "geom"), names)
    for name, m in zip(names, meshes, strict=True):
        _add_mesh_asset(asset, m, name)
        _add_static_geom(world, {"name": name, "type": "mesh", "mesh": name}, rgba)
    return ET.tostring(root, encoding="unicode")


def add_scene_assets(mjcf_xml: str, fields, meshes, n_overhang_geoms: int, *,
                     base_m: float = 0.01) -> str:  # fmt: skip
    """Add the height fields and overhang meshes of several scenes as assets, with the static
    geoms that show one scene at a time: for a batch of worlds that each show one of them
    (MuJoCo Warp can point a geom at another asset in each world, but cannot give each world
    its own assets; :mod:`envs.warp.scenes` places the geoms per world).

    The fields become ``<hfield>`` assets ``terrain_<k>`` (as :func:`add_heightfield` writes
    them) and the meshes ``<mesh>`` assets ``overhang_mesh_<k>``; one hfield geom ``terrain``
    on field 0, where :func:`add_heightfield` puts it (when there are fields), and
    ``n_overhang_geoms`` mesh geoms ``overhang_<j>`` on mesh 0: the names the geoms of
    :func:`add_heightfield` and :func:`add_static_meshes` have in a scene's own model. All get
    the floor's collision bits and contact parameters.

    Args:
        mjcf_xml: A complete ``<mujoco>`` document with a ``<worldbody>``.
        fields: Height fields.
        meshes: Triangle meshes (``.vertices (V, 3)``, ``.faces (F, 3)``), world frame, m; at
            least one when ``n_overhang_geoms > 0``.
        n_overhang_geoms: The mesh geoms.
        base_m: Depth of each field's base below its lowest node, m.

    Returns:
        The modified document as a string.
    """
    if base_m <= 0.0:
        raise ValueError(f"base_m must be positive, got {base_m}")
    if n_overhang_geoms > 0 and not meshes:
        raise ValueError("overhang geoms need at least one mesh")
    geoms = (["terrain"] if fields else []) + [f"overhang_{j}" for j in range(n_overhang_geoms)]
    fnames = [f"terrain_{k}" for k in range(len(fields))]
    mnames = [f"overhang_mesh_{k}" for k in range(len(meshes))]
    root, world, asset = _world_and_asset(mjcf_xml, ("hfield", "mesh", "geom"),
                                          geoms + fnames + mnames)  # fmt: skip
    pos = [
        _add_hfield_asset(asset, hf, name, base_m) for name, hf in zip(fnames, fields, strict=True)
    ]
    for name, m in zip(mnames, meshes, strict=True):
        _add_mesh_asset(asset, m, name)
    if fields:
        _add_static_geom(world, {"name": "terrain", "type": "hfield", "hfield": fnames[0],
                                 "pos": pos[0]}, _TERRAIN_RGBA)  # fmt: skip
    for name in geoms[1 if fields else 0 :]:
        _add_static_geom(world, {"name": name, "type": "mesh", "mesh": mnames[0]},
                         _OVERHANG_RGBA)  # fmt: skip
    return ET.tostring(root, encoding="unicode")


def _add_mesh_asset(asset: ET.Element, mesh, name: str) -> None:
    """Append a ``<mesh>`` of a triangle mesh's vertices and faces to ``asset``."""
    ET.SubElement(
        asset,
        "mesh",
        name=name,
        vertex=" ".join(_fmt(x) for x in np.asarray(mesh.vertices).reshape(-1)),
        face=" ".join(str(int(i)) for i in np.asarray(mesh.faces).reshape(-1)),
    )


def _world_and_asset(mjcf_xml: str, tags: tuple[str, ...], names) -> tuple:
    """The parsed document, its ``<worldbody>`` and its ``<asset>`` (created if missing);
    ``ValueError`` when there is no worldbody or an element of ``tags`` has one of ``names``."""
    root = ET.fromstring(mjcf_xml)
    world = root.find("worldbody")
    if world is None:
        raise ValueError("the MJCF has no <worldbody>")
    taken = set(names)
    for el in root.iter():
        if el.tag in tags and el.get("name") in taken:
            raise ValueError(f"the MJCF already has a <{el.tag}> named {el.get('name')!r}")
    asset = root.find("asset")
    if asset is None:
        asset = ET.Element("asset")
        root.insert(list(root).index(world), asset)
    return root, world, asset


def _add_static_geom(world: ET.Element, attrs: dict, rgba: str) -> None:
    """A static world geom with the floor's collision bits ``contype="1" conaffinity="0"`` (the
    humanoid's geoms have conaffinity bit 1) and the contact parameters of the worldbody's first
    plane geom (the floor), right after the floor so that the static geoms stay together."""
    floor = next((g for g in world.findall("geom") if g.get("type") == "plane"), None)
    if floor is not None:
        attrs.update({k: floor.get(k) for k in _FLOOR_CONTACT_ATTRS if floor.get(k) is not None})
    attrs.update(contype="1", conaffinity="0", rgba=rgba)
    idx = list(world).index(floor) + 1 if floor is not None else 0
    world.insert(idx, ET.Element("geom", attrs))
