"""Exports of a :class:`~grip.core.reconstruction.Reconstruction` to files other tools read.

One module per format, imported explicitly (this package's ``__init__`` stays light):

===========================  ====================================================================
module                       writes
===========================  ====================================================================
:mod:`grip.export.bvh`       BVH motion of the body model (y up, cm or m)
:mod:`grip.export.glb`       glTF binary meshes: one posed frame, or a strobe of every Nth frame
:mod:`grip.export.video`     MP4 rendered offscreen by MuJoCo (needs an OpenGL backend)
:mod:`grip.export.summary`   PNG overview: trajectory, GRF vs insoles, contacts, falls, errors
===========================  ====================================================================

Shared conventions
------------------
* **Body.** A reconstruction stores joint rotations and the pelvis trajectory but no body. Every
  exporter poses the project's body model (:func:`grip.core.body.build_body`) with the
  reconstruction's local joint rotations and pelvis trajectory, so BVH, GLB and MP4 show the same
  motion. Pass the subject's :class:`~grip.core.body.BodyParams`; ``None`` means the default
  ``BodyParams()`` (1.70 m, 70 kg). The joint positions of the export then differ from
  ``recon.joint_pos`` where the reconstruction was made on another body:
  :func:`fk_mismatch_m` measures by how much.
* **Axes.** The world is z up (MuJoCo, PRISM). BVH and glTF expect y up; both exports use the
  body model's canonical frame (:data:`Y_UP_FROM_WORLD`): x = world -x, y = world z (up),
  z = world y. It is a proper rotation (no mirroring), and a subject facing world +y faces +z,
  glTF's "front". MP4 and PNG stay in the world frame.
* **Files.** Every writer is atomic (:mod:`grip.core.atomic`: a failure never leaves a partial
  file) and raises :class:`ExportError` naming the file.

This module imports numpy and :mod:`grip.core`/:mod:`grip.kinematics.features` (numpy only).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import IO

import numpy as np

from grip.core.atomic import atomic_write
from grip.core.body import CANONICAL_TO_WORLD, BodyModel, BodyParams, build_body
from grip.core.fk import forward_kinematics
from grip.core.reconstruction import Reconstruction
from grip.kinematics.features import GroundTruth, ground_truth

__all__ = [
    "FORMATS",
    "Y_UP_FROM_WORLD",
    "ExportError",
    "GroundTruth",
    "body_model",
    "check_ground_truth",
    "export_reconstruction",
    "fk_mismatch_m",
    "ground_truth",
    "posed_body",
    "write_file",
]

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


FORMATS: tuple[str, ...] = ("bvh", "glb", "mp4", "png")


def export_reconstruction(
    recon: Reconstruction,
    out_dir: str | os.PathLike,
    formats: Sequence[str],
    *,
    stem: str,
    recording=None,
    body: BodyParams | None = None,
) -> tuple[list[Path], dict[str, str]]:
    """Write the requested formats of one reconstruction (the library side of ``grip export``
    and ``grip reconstruct --formats``).

    Args:
        recon: The reconstruction.
        out_dir: Folder; files are ``<stem>.bvh``, ``<stem>_strobe.glb``, ``<stem>.mp4``,
            ``<stem>.png``.
        formats: Any of :data:`FORMATS`.
        stem: File name stem.
        recording: The source recording, if any: its subject's body is used and its ground
            truth (when present) is overlaid in the MP4 and compared in the PNG.
        body: Body parameters (default: the recording's subject, else 1.70 m, 70 kg).

    Returns:
        The files written and ``{format: error message}`` for formats that could not be written
        (no OpenGL backend for MP4, ...): one failing format never stops the others.
    """
    unknown = sorted(set(formats) - set(FORMATS))
    if unknown:
        raise ExportError(f"unknown export format(s) {unknown}; use {', '.join(FORMATS)}")
    out = Path(out_dir)
    gt = None
    if recording is not None and getattr(recording, "smpl_params", None) is not None:
        gt = ground_truth(recording)
        check_ground_truth(recon, gt)
        body = body or gt.body
    written: list[Path] = []
    failed: dict[str, str] = {}
    for fmt in formats:
        try:
            if fmt == "bvh":
                from grip.export.bvh import write_bvh

                written.append(write_bvh(recon, out / f"{stem}.bvh", body))
            elif fmt == "glb":
                from grip.export.glb import write_strobe_glb

                every = max(1, round(recon.fps / 2))
                written.append(write_strobe_glb(recon, out / f"{stem}_strobe.glb", body,
                                                every=every))  # fmt: skip
            elif fmt == "mp4":
                from grip.export.video import write_video

                write_video(recon, out / f"{stem}.mp4", body, gt=gt)
                written.append(out / f"{stem}.mp4")
            else:
                from grip.export.summary import write_summary_png

                write_summary_png(recon, out / f"{stem}.png", gt=gt)
                written.append(out / f"{stem}.png")
        except (ExportError, OSError, RuntimeError, ValueError) as e:
            failed[fmt] = str(e)
    return written, failed
