"""glTF binary (``.glb``) meshes of a reconstruction, built with trimesh.

The body is drawn from the body model's own shapes (:attr:`grip.core.body.BodyModel.geoms`:
capsules, boxes and a head sphere, the same shapes MuJoCo collides with), posed with the
reconstruction's rotations and pelvis trajectory (:func:`grip.export.common.posed_body`). Two files:

* :func:`write_pose_glb`: one frame as a single mesh (node ``"body"``).
* :func:`write_strobe_glb`: every Nth frame along the trajectory, one node per frame named
  ``"frame_000120"`` (the frame index), coloured from blue (start) to orange (end), frames inside
  a fall event red, plus a grey ``"floor"`` slab whose top is the floor plane.

Vertices are written in world coordinates (node transforms are the identity) in glTF's y-up
frame (:data:`grip.export.common.Y_UP_FROM_WORLD`), metres. Left-side segments are tinted blue and
right-side ones red in the single-frame mesh. No glTF animation is written: the strobe scene is
static (BVH and MP4 carry the motion).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from grip.core import skeleton as sk
from grip.core.body import BodyModel, BodyParams
from grip.core.reconstruction import Reconstruction
from grip.core.rotations import rotation_between
from grip.export.common import (
    Y_UP_FROM_WORLD,
    ExportError,
    body_model,
    check_rotations,
    posed_body,
    write_file,
)

_SIDE_RGBA = {
    "L": np.array([90, 140, 220, 255], dtype=np.uint8),
    "R": np.array([220, 110, 90, 255], dtype=np.uint8),
    "C": np.array([200, 200, 200, 255], dtype=np.uint8),
}
_START_RGB = np.array([60.0, 110.0, 220.0])
_END_RGB = np.array([240.0, 150.0, 40.0])
_FALL_RGBA = np.array([220, 30, 30, 255], dtype=np.uint8)
_FLOOR_RGBA = np.array([150, 150, 150, 255], dtype=np.uint8)
_FLOOR_MARGIN_M = 1.0
_FLOOR_THICKNESS_M = 0.02


@dataclass(frozen=True, eq=False)
class BodyMesh:
    """All shapes of a body model as one triangle mesh in the bodies' rest frames.

    Attributes:
        vertices: ``(V, 3)`` vertex in the frame of the body that carries it, m.
        faces: ``(F, 3)`` int vertex indices.
        vertex_body: ``(V,)`` SMPL index of the carrying body.
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_body: np.ndarray

    def pose(self, global_rot: np.ndarray, joint_pos: np.ndarray) -> np.ndarray:
        """``(V, 3)`` vertices for one frame (``(24, 3, 3)``, ``(24, 3)``), world (z up), m."""
        r = global_rot[self.vertex_body]
        return np.einsum("vij,vj->vi", r, self.vertices) + joint_pos[self.vertex_body]


def body_mesh(body: BodyParams | BodyModel | None = None, segments: int = 12) -> BodyMesh:
    """Triangulate the body model's shapes once (capsules with ``segments`` around the axis).

    Args:
        body: Subject (``None``: ``BodyParams()``).
        segments: Resolution of capsules (around / along); spheres use an icosphere.
    """
    if segments < 4:
        raise ValueError(f"segments must be >= 4, got {segments}")
    bm = body_model(body)
    verts, faces, owner = [], [], []
    n = 0
    for g in bm.geoms:
        if g.kind == "capsule":
            m = trimesh.creation.capsule(height=2.0 * float(g.size[1]), radius=float(g.size[0]),
                                         count=[segments, max(4, segments // 2)])  # fmt: skip
            rot = rotation_between(np.array([0.0, 0.0, 1.0]), g.axis)
            v = m.vertices @ rot.T + g.pos
        elif g.kind == "box":
            m = trimesh.creation.box(extents=2.0 * np.asarray(g.size, dtype=np.float64))
            v = m.vertices + g.pos
        elif g.kind == "sphere":
            m = trimesh.creation.icosphere(subdivisions=2, radius=float(g.size[0]))
            v = m.vertices + g.pos
        else:
            raise ValueError(f"body {sk.JOINT_NAMES[g.body]}: unknown geom kind {g.kind!r}")
        verts.append(v)
        faces.append(m.faces + n)
        owner.append(np.full(len(v), g.body, dtype=np.int64))
        n += len(v)
    return BodyMesh(np.concatenate(verts), np.concatenate(faces), np.concatenate(owner))


def _side_colors(vertex_body: np.ndarray) -> np.ndarray:
    side = np.array([n[0] if n[:2] in ("L_", "R_") else "C" for n in sk.JOINT_NAMES])
    table = np.stack([_SIDE_RGBA[s] for s in side])
    return table[vertex_body]


def _check_frame(recon: Reconstruction, frame: int) -> int:
    if not -recon.n_frames <= frame < recon.n_frames:
        raise ValueError(f"frame {frame} is outside reconstruction {recon.name!r} "
                         f"(0..{recon.n_frames - 1})")  # fmt: skip
    return frame % recon.n_frames


def posed_mesh(
    recon: Reconstruction, frame: int, body: BodyParams | BodyModel | None = None
) -> trimesh.Trimesh:
    """The body at one frame as a mesh, glTF y-up frame, m (left side blue, right side red)."""
    frame = _check_frame(recon, frame)
    bm = body_model(body)
    mesh = body_mesh(bm)
    rot, pos = posed_body(recon.slice_frames(frame, frame + 1), bm)
    v = mesh.pose(rot[0], pos[0]) @ Y_UP_FROM_WORLD.T
    return trimesh.Trimesh(v, mesh.faces, vertex_colors=_side_colors(mesh.vertex_body),
                           process=False)  # fmt: skip


def strobe_frames(n_frames: int, every: int) -> np.ndarray:
    """Frames of a strobe: ``0, every, 2 every, ...`` and always the last frame."""
    if every < 1:
        raise ValueError(f"strobe spacing must be >= 1 frame, got {every}")
    idx = np.arange(0, n_frames, every)
    if idx[-1] != n_frames - 1:
        idx = np.append(idx, n_frames - 1)
    return idx


def strobe_scene(
    recon: Reconstruction,
    body: BodyParams | BodyModel | None = None,
    *,
    every: int | None = None,
    floor: bool = True,
) -> trimesh.Scene:
    """Every ``every``-th frame of the motion as one node each, plus the floor.

    Args:
        recon: The reconstruction.
        body: Subject (``None``: ``BodyParams()``).
        every: Frames between two poses; ``None``: half a second (``round(fps / 2)``).
        floor: Add the ``"floor"`` node: a slab under the trajectory, top face at the floor.

    Returns:
        A scene in glTF's y-up frame, m.
    """
    bm = body_model(body)
    every = max(1, round(recon.fps / 2)) if every is None else int(every)
    frames = strobe_frames(recon.n_frames, every)
    mesh = body_mesh(bm)
    rot, pos = posed_body(recon, bm)
    in_fall = np.zeros(recon.n_frames, dtype=bool)
    for a, b in recon.falls:
        in_fall[a : b + 1] = True
    scene = trimesh.Scene()
    for k, t in enumerate(frames):
        v = mesh.pose(rot[t], pos[t]) @ Y_UP_FROM_WORLD.T
        w = k / max(len(frames) - 1, 1)
        rgba = (_FALL_RGBA if in_fall[t] else
                np.append((1 - w) * _START_RGB + w * _END_RGB, 255).astype(np.uint8))  # fmt: skip
        m = trimesh.Trimesh(v, mesh.faces, vertex_colors=np.broadcast_to(rgba, (len(v), 4)),
                            process=False)  # fmt: skip
        name = f"frame_{t:06d}"
        scene.add_geometry(m, node_name=name, geom_name=name)
    if floor:
        root = recon.root_pos[frames] @ Y_UP_FROM_WORLD.T
        lo = root.min(axis=0) - _FLOOR_MARGIN_M
        hi = root.max(axis=0) + _FLOOR_MARGIN_M
        lo[1], hi[1] = -_FLOOR_THICKNESS_M, 0.0
        slab = trimesh.creation.box(bounds=np.stack([lo, hi]))
        slab.visual.vertex_colors = np.broadcast_to(_FLOOR_RGBA, (len(slab.vertices), 4))
        scene.add_geometry(slab, node_name="floor", geom_name="floor")
    return scene


def _export_glb(geometry: trimesh.Trimesh | trimesh.Scene, path: Path) -> Path:
    try:
        data = geometry.export(file_type="glb")
    except (ValueError, TypeError) as e:  # trimesh's errors for unexportable geometry
        raise ExportError(f"{path}: cannot encode glTF ({e})") from e
    return write_file(path, lambda f: f.write(data))


def write_pose_glb(
    recon: Reconstruction,
    path: str | os.PathLike,
    frame: int,
    body: BodyParams | BodyModel | None = None,
) -> Path:
    """Write the body at ``frame`` (:func:`posed_mesh`) as a ``.glb`` with one node
    ``"body"``, atomically.

    Raises:
        ExportError: The file cannot be written, or a rotation is no rotation (the message
            names the file).
        ValueError: ``frame`` is outside the reconstruction.
    """
    check_rotations(recon, path)
    scene = trimesh.Scene()
    scene.add_geometry(posed_mesh(recon, frame, body), node_name="body", geom_name="body")
    return _export_glb(scene, Path(path))


def write_strobe_glb(
    recon: Reconstruction,
    path: str | os.PathLike,
    body: BodyParams | BodyModel | None = None,
    *,
    every: int | None = None,
    floor: bool = True,
) -> Path:
    """Write :func:`strobe_scene` as a ``.glb``, atomically.

    Raises:
        ExportError: The file cannot be written, or a rotation is no rotation (the message
            names the file).
    """
    check_rotations(recon, path)
    return _export_glb(strobe_scene(recon, body, every=every, floor=floor), Path(path))
