"""BVH (Biovision Hierarchy) export of a reconstruction on the body model.

File layout
-----------
* **Hierarchy**: the 24 SMPL joints with their SMPL names and parents; each OFFSET is the body
  model's rest offset (:attr:`grip.core.body.BodyModel.offsets`). The five leaves get an End Site
  (toe tips, top of the head, finger tips of the hand capsules).
* **Units**: centimetres by default (``unit="cm"``, what most animation tools assume), or metres
  (``unit="m"``). BVH has no comment syntax, so the unit is not written into the file; the
  project's reader (:func:`grip.motion.bvh.load_bvh`) infers it from the skeleton's height.
* **Axes**: y up, the body model's canonical frame (:data:`grip.export.common.Y_UP_FROM_WORLD`:
  x = world -x, y = world z, z = world y; a proper rotation). The zero pose (every channel 0) is
  the body model's T-pose standing upright and facing +z.
* **Channels**: the root has ``Xposition Yposition Zposition Yrotation Xrotation Zrotation``
  (pelvis position; heading first, so the Euler angles lock only for a body lying flat). Every
  other joint has three rotation channels in its MuJoCo hinge order
  (:data:`grip.core.skeleton.HINGE_ORDERS`: ``Xrotation Yrotation Zrotation``, shoulders Y X Z,
  elbows Y Z X), so its channel values are exactly the humanoid's hinge angles in degrees.
  Channels compose in the listed order (intrinsic): ``Yrotation Xrotation Zrotation`` means
  ``R = Ry @ Rx @ Rz``. Angles are unwrapped over time (no 360 deg jumps between frames).
* **Frame Time** is ``1 / recon.fps``.

Lengths are written to 1e-8 m (6 decimals in cm, 8 in m) and angles with 6 decimals of a degree, so
reading the file back reproduces the body's forward kinematics to well under a millimetre.
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Literal

import numpy as np

from grip.core import skeleton as sk
from grip.core.body import BodyModel, BodyParams
from grip.core.reconstruction import Reconstruction
from grip.core.reference import hinges_from_local
from grip.core.rotations import matrix_to_euler
from grip.export.common import Y_UP_FROM_WORLD, body_model, check_rotations, write_file

UNITS: dict[str, float] = {"cm": 100.0, "m": 1.0}
"""File units per metre."""

ROOT_EULER_ORDER = "yxz"
"""Rotation channel order of the root (y-up frame): heading, then pitch, then roll."""

_LEAVES: tuple[int, ...] = tuple(j for j in range(sk.N_JOINTS) if j not in sk.PARENTS)


def _children() -> list[list[int]]:
    kids: list[list[int]] = [[] for _ in range(sk.N_JOINTS)]
    for j in range(1, sk.N_JOINTS):
        kids[int(sk.PARENTS[j])].append(j)
    return kids


def hierarchy_order() -> list[int]:
    """SMPL joint indices in the order the hierarchy lists them (depth first), which is also
    the order of their channels in every motion line."""
    kids = _children()
    order: list[int] = []
    stack = [0]
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(kids[j]))
    return order


def end_site_offsets(body: BodyModel) -> dict[int, np.ndarray]:
    """``{leaf joint: (3,) End Site offset}`` in the leaf's frame, m: the far end of the leaf's
    shape (toe tip on the sole line, top of the head sphere, tip of the hand capsule)."""
    out: dict[int, np.ndarray] = {}
    for j in _LEAVES:
        g = next(g for g in body.geoms if g.body == j)
        if g.kind == "sphere":
            out[j] = g.pos + np.array([0.0, g.size[0], 0.0])
        elif g.kind == "capsule":
            out[j] = g.fromto()[3:] + g.size[0] * g.axis
        else:  # toe box: front edge, centre line, at the height of the toe joint
            out[j] = np.array([g.pos[0], 0.0, g.pos[2] + g.size[2]])
    return out


def _fmt(v: np.ndarray, decimals: int) -> str:
    return " ".join(f"{x:.{decimals}f}" for x in v)


def _decimals(scale: float) -> int:
    """Decimals of lengths: 1e-8 m whatever the unit."""
    return 6 + round(np.log10(UNITS["cm"] / scale))


def _hierarchy_text(body: BodyModel, scale: float) -> str:
    kids = _children()
    ends = end_site_offsets(body)
    dec = _decimals(scale)
    lines = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        pad = "  " * depth
        name = sk.JOINT_NAMES[j]
        if j == 0:
            lines.append(f"ROOT {name}")
            channels = ("6 Xposition Yposition Zposition "
                        + " ".join(f"{c.upper()}rotation" for c in ROOT_EULER_ORDER))  # fmt: skip
        else:
            lines.append(f"{pad}JOINT {name}")
            channels = "3 " + " ".join(f"{c.upper()}rotation" for c in sk.HINGE_ORDERS[j])
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET {_fmt(body.offsets[j] * scale, dec)}")
        lines.append(f"{pad}  CHANNELS {channels}")
        for c in kids[j]:
            emit(c, depth + 1)
        if j in ends:
            end = _fmt(ends[j] * scale, dec)
            lines.extend([f"{pad}  End Site", f"{pad}  {{", f"{pad}    OFFSET {end}", f"{pad}  }}"])
        lines.append(f"{pad}}}")

    emit(0, 0)
    return "\n".join(lines) + "\n"


def motion_channels(recon: Reconstruction, unit: str = "cm") -> np.ndarray:
    """The motion block as numbers: ``(T, 6 + 69)`` channel values per frame.

    Columns: root position in the y-up frame (file units), root Euler angles
    (:data:`ROOT_EULER_ORDER`), then each joint's three hinge angles in :func:`hierarchy_order`,
    all angles in degrees and unwrapped over time.
    """
    scale = _scale(unit)
    local = recon.local_rot
    t = recon.n_frames
    root_rot = np.einsum("ij,tjk->tik", Y_UP_FROM_WORLD, local[:, 0])
    hinges = hinges_from_local(local[:, 1:]).reshape(t, sk.N_JOINTS - 1, 3)
    order = hierarchy_order()[1:]
    angles = np.concatenate(
        [matrix_to_euler(root_rot, ROOT_EULER_ORDER),
         hinges[:, np.asarray(order) - 1].reshape(t, -1)], axis=1)  # fmt: skip
    angles = np.rad2deg(np.unwrap(angles, axis=0))
    pos = recon.root_pos @ Y_UP_FROM_WORLD.T * scale
    return np.concatenate([pos, angles], axis=1)


def _scale(unit: str) -> float:
    if unit not in UNITS:
        raise ValueError(f"BVH unit must be one of {sorted(UNITS)}, got {unit!r}")
    return UNITS[unit]


def bvh_text(
    recon: Reconstruction,
    body: BodyParams | BodyModel | None = None,
    *,
    unit: Literal["cm", "m"] = "cm",
) -> str:
    """The BVH file of a reconstruction (see the module docstring for the layout).

    Args:
        recon: The reconstruction; its local rotations and pelvis trajectory are written.
        body: Subject whose rest skeleton gives the OFFSETs (``None``: ``BodyParams()``,
            1.70 m, 70 kg).
        unit: ``"cm"`` or ``"m"``, the length unit of OFFSETs and root positions.

    Returns:
        The whole file as text.
    """
    scale = _scale(unit)
    bm = body_model(body)
    values = motion_channels(recon, unit)
    buf = io.StringIO()
    buf.write(_hierarchy_text(bm, scale))
    buf.write(f"MOTION\nFrames: {recon.n_frames}\nFrame Time: {1.0 / recon.fps:.8f}\n")
    dec = _decimals(scale)
    fmt = [f"%.{dec}f"] * 3 + ["%.6f"] * (values.shape[1] - 3)
    np.savetxt(buf, values, fmt=fmt)
    return buf.getvalue()


def write_bvh(
    recon: Reconstruction,
    path: str | os.PathLike,
    body: BodyParams | BodyModel | None = None,
    *,
    unit: Literal["cm", "m"] = "cm",
) -> Path:
    """Write :func:`bvh_text` to ``path`` atomically.

    Raises:
        ExportError: The file cannot be written, or a rotation is no rotation
            (:func:`grip.export.common.check_rotations`); the message names the file.
        ValueError: ``unit`` is neither ``"cm"`` nor ``"m"``.
    """
    check_rotations(recon, path)
    data = bvh_text(recon, body, unit=unit).encode("ascii")
    return write_file(path, lambda f: f.write(data))
