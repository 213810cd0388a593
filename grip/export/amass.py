"""AMASS-style ``.npz`` export of a reconstruction (SMPL joint order, axis-angle, z up).

What the file holds
-------------------
==========================  =========  ==========================================================
key                         shape      meaning
==========================  =========  ==========================================================
poses                       (T, 72)    axis-angle rotation of the 24 SMPL joints (rad), joint
                                       ``j`` in columns ``3j:3j+3``: the root's orientation in
                                       the world first, then each joint relative to its parent
trans                       (T, 3)     SMPL model translation, world, m: the pelvis joint is at
                                       ``trans + grip_trans_to_pelvis_m`` (see below)
mocap_framerate             ()         frames per second (the reconstruction's ``fps``)
betas                       (16,)      zeros: no SMPL shape (the body is not SMPL)
gender                      ()         ``"neutral"``
note                        ()         text: what the body is, what differs from SMPL
grip_trans_to_pelvis_m      (3,)       pelvis joint minus ``trans``, world, m
grip_body_params            (5,)       the body the motion was posed on
                                       (:meth:`grip.core.body.BodyParams.to_array`: height m,
                                       mass kg, leg, arm, foot length m, NaN when unset)
==========================  =========  ==========================================================

Conventions (checked against :mod:`grip.core.body` and :mod:`grip.motion.amass`)
-------------------------------------------------------------------------------
* **Axes.** AMASS's world is z up, metres, as ours (MuJoCo, PRISM): no axis change. Each joint
  frame of the rest pose is the SMPL canonical frame (x = the subject's left, y = up, z =
  forward) in both: a rotation about a joint's local axis means the same thing here and in SMPL,
  and the root orientation maps that frame into the z-up world (a subject standing upright and
  facing +y has the root rotation :data:`grip.core.body.CANONICAL_TO_WORLD`; AMASS's own clips
  mostly face -y, ``Rx(90 deg)``: nothing is turned on export).
* **Rotations.** A reconstruction stores *global* joint rotations (``global_rot``); the file
  stores the *local* ones SMPL expects, ``L_j = G_parent(j)^T G_j``
  (:attr:`~grip.core.reconstruction.PoseTrack.local_rot`), row 0 the root's global rotation.
* **Translation.** In SMPL the pelvis joint sits at ``trans + J_0``, ``J_0`` being the rest
  pelvis in model space added without rotation. The file uses the approximate neutral ``J_0``
  that :mod:`grip.motion.amass` reads AMASS files with (:data:`SMPL_NEUTRAL_PELVIS_M`), so an
  SMPL viewer and the project's own reader place the pelvis where the reconstruction has it;
  ``grip_trans_to_pelvis_m`` records the offset for tools that want the pelvis itself.
* **Body.** The project's body model has SMPL's topology and joint order but its own proportions
  (:func:`grip.core.body.build_body`): an SMPL model posed with these rotations has other bone
  lengths (its joints differ by centimetres), and there are no ``betas`` for our shape. Forward
  kinematics of the file on ``build_body(BodyParams.from_array(grip_body_params))`` gives back
  the reconstruction's joints (to float rounding) when the reconstruction was made on that body.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from grip.core import skeleton as sk
from grip.core.body import BodyModel, BodyParams
from grip.core.reconstruction import Reconstruction
from grip.core.rotations import matrix_to_axis_angle, orthonormalize
from grip.export.common import (
    ExportError,
    body_model,
    check_rotations,
    write_file,
)

SMPL_NEUTRAL_PELVIS_M: np.ndarray = np.array([0.0, -0.22, 0.03])
"""``J_0``: the approximate rest pelvis of the neutral SMPL model in model space, m, added to
``trans`` unrotated. The value :mod:`grip.motion.amass` reads AMASS files with
(``SMPL_PELVIS_M``; a test keeps the two equal: this layer may not import that one)."""

N_BETAS = 16
"""Length of the (zero) ``betas`` vector, as AMASS's SMPL+H files store it."""

NOTE = (
    "Written by GRIP (grip export --formats amass). SMPL joint order and conventions (axis-angle "
    "poses, root orientation first, z-up world, metres), but the body is GRIP's own model with "
    "SMPL topology, not SMPL: its bone lengths and joint offsets differ, betas are zeros and "
    "mean nothing. The pelvis joint is at trans + grip_trans_to_pelvis_m (SMPL's neutral rest "
    "pelvis, approximately); grip_body_params is the GRIP body (height m, mass kg, leg, arm, "
    "foot length m; NaN unset) the motion was posed on."
)
"""The ``note`` string of every file."""


def amass_arrays(recon: Reconstruction,
                 body: BodyParams | BodyModel | None = None) -> dict[str, np.ndarray]:  # fmt: skip
    """The arrays of the AMASS-style file of ``recon`` (the module docstring lists them).

    Args:
        recon: The reconstruction (its global rotations and pelvis trajectory are used).
        body: The body it was made on, recorded in ``grip_body_params`` (``None``:
            ``BodyParams()``, 1.70 m, 70 kg; a :class:`BodyModel` records its ``params``).

    Returns:
        ``{key: array}``; ``poses (T, 72)`` and ``trans (T, 3)`` float64.

    Raises:
        ExportError: A ``global_rot`` entry is not a rotation.
    """
    check_rotations(recon)
    params = body_model(body).params
    local = orthonormalize(recon.local_rot)  # rounding of the stored matrices, nothing more
    poses = matrix_to_axis_angle(local).reshape(recon.n_frames, 3 * sk.N_JOINTS)
    return {
        "poses": poses,
        "trans": recon.root_pos - SMPL_NEUTRAL_PELVIS_M,
        "mocap_framerate": np.array(float(recon.fps)),
        "betas": np.zeros(N_BETAS),
        "gender": np.array("neutral"),
        "note": np.array(NOTE),
        "grip_trans_to_pelvis_m": SMPL_NEUTRAL_PELVIS_M.copy(),
        "grip_body_params": params.to_array(),
    }


def write_amass(recon: Reconstruction, path: str | os.PathLike,
                body: BodyParams | BodyModel | None = None) -> Path:  # fmt: skip
    """Write the AMASS-style ``.npz`` of ``recon`` (compressed, atomically).

    Args:
        recon: The reconstruction.
        path: Output file (``.npz``).
        body: The body it was made on (see :func:`amass_arrays`).

    Returns:
        The path written.

    Raises:
        ExportError: Naming the file, when a rotation is malformed or the file cannot be
            written.
    """
    path = Path(path)
    try:
        arrays = amass_arrays(recon, body)
    except ExportError as e:
        raise ExportError(f"{path}: {e}") from None
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return write_file(path, lambda f: f.write(buf.getvalue()))
