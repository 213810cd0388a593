"""What every exporter of :mod:`grip.export` shares: the y-up export frame, the body model posed
by a reconstruction, the rotation and ground-truth checks and atomic file writes that raise
:class:`ExportError`.

The format modules (:mod:`grip.export.bvh`, :mod:`~grip.export.glb`, :mod:`~grip.export.video`,
:mod:`~grip.export.summary`) import this module, never the package ``__init__``, so the package
has no import cycle. Imports numpy, :mod:`grip.core` and :mod:`grip.kinematics.features`
(numpy only).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import IO

import numpy as np

from grip.core.atomic import atomic_write
from grip.core.body import CANONICAL_TO_WORLD, BodyModel, BodyParams, build_body
from grip.core.fk import forward_kinematics
from grip.core.reconstruction import Reconstruction
from grip.kinematics.features import GroundTruth

Y_UP_FROM_WORLD: np.ndarray = CANONICAL_TO_WORLD.T.copy()
"""``(3, 3)`` rotation from the z-up world to the y-up export frame (BVH, glTF):
``v_export = Y_UP_FROM_WORLD @ v_world``. Equal to its own inverse."""


class ExportError(ValueError):
    """An export failed or its input is unusable; the message names the file and the problem."""


def write_file(path: str | os.PathLike, write: Callable[[IO[bytes]], None]) -> Path:
    """Atomically write ``path`` with ``write(f)``; file-system errors become
    :class:`ExportError` naming the file.

    Returns:
        The path written.
    """
    path = Path(path)
    try:
        atomic_write(path, write)
    except OSError as e:
        raise ExportError(f"{path}: cannot write ({e.strerror or e})") from e
    return path


def body_model(body: BodyParams | BodyModel | None) -> BodyModel:
    """The body model to pose: built from ``body``, or the default ``BodyParams()``."""
    if isinstance(body, BodyModel):
        return body
    if body is not None and not isinstance(body, BodyParams):
        raise TypeError(f"body must be BodyParams, BodyModel or None, got {type(body).__name__}")
    return build_body(body or BodyParams())


def posed_body(
    recon: Reconstruction, body: BodyParams | BodyModel | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The body model in the reconstruction's pose (what every export shows).

    Args:
        recon: The reconstruction (its local rotations and pelvis trajectory are used).
        body: Subject parameters (``None``: ``BodyParams()``).

    Returns:
        ``global_rot (T, 24, 3, 3)`` and ``joint_pos (T, 24, 3)``, world frame (z up), m.
    """
    bm = body_model(body)
    return forward_kinematics(recon.local_rot, recon.root_pos, bm.offsets)


def fk_mismatch_m(recon: Reconstruction, body: BodyParams | BodyModel | None = None) -> float:
    """Largest distance between ``recon.joint_pos`` and the posed body's joints, m.

    Zero (to rounding) when the reconstruction was made on this body; centimetres mean the
    export's skeleton is not the one the method used (pass the subject's BodyParams).
    """
    _, pos = posed_body(recon, body)
    return float(np.linalg.norm(pos - recon.joint_pos, axis=-1).max())


ROTATION_TOLERANCE = 1e-3
"""Largest ``|R^T R - I|`` entry accepted in ``global_rot``; beyond it the matrix is no
rotation and the export is refused (below it, writers that need one project it onto the nearest
rotation)."""


def check_rotations(recon: Reconstruction, path: str | os.PathLike | None = None) -> None:
    """Raise :class:`ExportError` unless every ``global_rot`` is a proper rotation (orthonormal
    within :data:`ROTATION_TOLERANCE`, determinant +1): a zero matrix or a reflection would
    be written as a collapsed or mirrored body. Every writer calls it first.

    Args:
        recon: The reconstruction.
        path: The file being written, named first in the message.
    """
    r = recon.global_rot
    err = np.abs(np.swapaxes(r, -1, -2) @ r - np.eye(3)).max(axis=(-2, -1))
    det = np.linalg.det(r)
    bad = ~(err <= ROTATION_TOLERANCE) | ~(det > 0)
    if bad.any():
        from grip.core import skeleton as sk

        t, j = (int(i) for i in np.argwhere(bad)[0])
        where = f"{path}: " if path is not None else ""
        raise ExportError(f"{where}reconstruction {recon.name!r}: global_rot of joint "
                          f"{sk.JOINT_NAMES[j]} at frame {t} is not a rotation (|R^T R - I| = "
                          f"{err[t, j]:.3g}, det {det[t, j]:.3g}; {int(bad.sum())} such "
                          "matrices): nothing written")  # fmt: skip


def check_ground_truth(recon: Reconstruction, gt: GroundTruth) -> None:
    """Raise :class:`ExportError` unless ``gt`` covers the same frames as ``recon``."""
    if gt.n_frames != recon.n_frames:
        raise ExportError(
            f"ground truth {gt.name!r} has {gt.n_frames} frames but reconstruction "
            f"{recon.name!r} has {recon.n_frames}: pass the recording (or segment) it was made from"
        )
    if not np.isclose(gt.fps, recon.fps):
        raise ExportError(f"ground truth {gt.name!r} is at {gt.fps:g} Hz but reconstruction "
                          f"{recon.name!r} is at {recon.fps:g} Hz")  # fmt: skip
