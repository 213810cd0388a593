"""Exports of a :class:`~grip.core.reconstruction.Reconstruction` to files other tools read.

One module per format, imported explicitly (this package's ``__init__`` stays light):

===========================  ====================================================================
module                       writes
===========================  ====================================================================
:mod:`grip.export.bvh`       BVH motion of the body model (y up, cm or m)
:mod:`grip.export.glb`       glTF binary meshes: one posed frame, or a strobe of every Nth frame
:mod:`grip.export.video`     MP4 rendered offscreen by MuJoCo (needs an OpenGL backend)
:mod:`grip.export.summary`   PNG overview: trajectory, GRF vs insoles, contacts, falls, errors
:mod:`grip.export.amass`     AMASS-style npz: SMPL-order axis-angle poses, trans (our body)
:mod:`grip.export.html`      one self-contained interactive 3D page (three.js, ``grip view``)
===========================  ====================================================================

Shared conventions
------------------
* **Body.** A reconstruction stores joint rotations and the pelvis trajectory but no body. Every
  exporter poses the project's body model (:func:`grip.core.body.build_body`) with the
  reconstruction's local joint rotations and pelvis trajectory, so BVH, GLB and MP4 show the same
  motion. Pass the subject's :class:`~grip.core.body.BodyParams`; ``None`` means the default
  ``BodyParams()`` (1.70 m, 70 kg). The joint positions of the export then differ from
  ``recon.joint_pos`` where the reconstruction was made on another body:
  :func:`~grip.export.common.fk_mismatch_m` measures by how much.
* **Axes.** The world is z up (MuJoCo, PRISM). BVH and glTF expect y up; both exports use the
  body model's canonical frame (:data:`~grip.export.common.Y_UP_FROM_WORLD`): x = world -x,
  y = world z (up), z = world y. It is a proper rotation (no mirroring), and a subject facing
  world +y faces +z, glTF's "front". MP4 and PNG stay in the world frame.
* **Files.** Every writer is atomic (:mod:`grip.core.atomic`: a failure never leaves a partial
  file) and raises :class:`~grip.export.common.ExportError` naming the file.

The shared pieces (export frame, posed body, ground-truth check, file writes) are
:mod:`grip.export.common`; the format modules import it and never this ``__init__``, which
imports them only inside :func:`export_reconstruction` (no import cycle). This module imports
numpy-level code only: :mod:`grip.export.common` and :mod:`grip.kinematics.features`.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from grip.core.body import BodyParams
from grip.core.reconstruction import Reconstruction
from grip.export.common import ExportError, check_ground_truth, check_rotations
from grip.kinematics.features import ground_truth

__all__ = ["FORMATS", "export_reconstruction"]


FORMATS: tuple[str, ...] = ("bvh", "glb", "mp4", "png", "amass", "html")


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
            ``<stem>.png``, ``<stem>_amass.npz``, ``<stem>.html``.
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
            elif fmt == "amass":
                from grip.export.amass import write_amass

                written.append(write_amass(recon, out / f"{stem}_amass.npz", body))
            elif fmt == "html":
                from grip.export.html import write_viewer

                check_rotations(recon, out / f"{stem}.html")  # (write_viewer does not)
                page = write_viewer(recon, out / f"{stem}.html", recording=recording, body=body)
                written.append(page.path)
            else:
                from grip.export.summary import write_summary_png

                write_summary_png(recon, out / f"{stem}.png", gt=gt)
                written.append(out / f"{stem}.png")
        except (ExportError, OSError, RuntimeError, ValueError) as e:
            failed[fmt] = str(e)
    return written, failed
