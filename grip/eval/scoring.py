"""The metrics of one reconstructed segment against its ground truth (``grip bench``, ``grip
policy eval``); the keys and units are listed in :mod:`grip.eval.bench`."""

from __future__ import annotations

import numpy as np

from grip.core import metrics as M
from grip.core import skeleton as sk
from grip.core.body import BodyParams, build_body
from grip.core.fk import sole_points
from grip.core.reconstruction import Reconstruction
from grip.kinematics.features import GroundTruth

__all__ = [
    "FEET",
    "METRIC_KEYS",
    "PACE_METRIC_KEYS",
    "PER_JOINT_KEYS",
    "foot_penetration_mm",
    "foot_sliding_mps",
    "pace_metrics",
    "segment_metrics",
    "vgrf_error_n",
]

METRIC_KEYS: tuple[str, ...] = (
    "MPJPE_mm", "PEL_MPJPE_mm", "PA_MPJPE_mm", "MPJRE_deg", "Acc_mps2", "FS_mps", "FP_mm",
    "vGRF_N", "success_rate", "ms_per_frame", *M.PACE_KEYS, *M.ROOT_GT_KEYS,
)  # fmt: skip
PACE_METRIC_KEYS: tuple[str, ...] = (*M.PACE_KEYS, *M.ROOT_GT_KEYS)
"""The pace keys of :data:`METRIC_KEYS` (:func:`pace_metrics`)."""
PER_JOINT_KEYS: tuple[str, ...] = ("MPJPE_mm", "PEL_MPJPE_mm", "MPJRE_deg")

FEET = sk.FEET
"""Foot order of the ``(T, 2)`` force and contact arrays."""


def foot_sliding_mps(pos: np.ndarray, contacts: np.ndarray, fps: float) -> float:
    """Foot sliding (m/s) of the predicted feet over ``contacts`` frames; NaN under 2 frames.

    Args:
        pos: ``(T, 24, 3)`` predicted joint positions, world, m.
        contacts: ``(T, 2)`` bool ground-truth contacts (``GroundTruth.foot_contacts``).
        fps: Frame rate, Hz.
    """
    if len(pos) < 2:
        return float("nan")
    return float(M.foot_sliding(pos, contacts, fps))


def foot_penetration_mm(rot: np.ndarray, pos: np.ndarray, body: BodyParams) -> float:
    """Foot penetration (mm) of the sole points of ``body`` posed by ``rot`` ``(T, 24, 3, 3)``
    and ``pos`` ``(T, 24, 3)`` (world, m), against the floor ``z = 0``."""
    return float(M.foot_penetration(sole_points(rot, pos, build_body(body))))


def vgrf_error_n(pred_fz_n: np.ndarray | None, insole_fz_n: np.ndarray | None) -> float:
    """Vertical GRF error, N: :func:`grip.core.metrics.vgrf_error` of ``(T, 2)`` forces.

    Frames whose predicted force is not finite are left out (GRIP's fall recovery replaces
    the frames of a fall by the kinematic estimate, which has no forces). NaN when the method
    has no forces, the recording no insoles, or no frame has a finite prediction.
    """
    if pred_fz_n is None or insole_fz_n is None:
        return float("nan")
    return M.vgrf_error(pred_fz_n, insole_fz_n)


def pace_metrics(recon: Reconstruction, gt_root: np.ndarray, fps: float) -> dict[str, float]:
    """The pace keys (:data:`PACE_METRIC_KEYS`) of a reconstruction.

    ``pace_*`` and ``drift_mps``: its pelvis against the pelvis it followed
    (``recon.ref_root_pos``; NaN for a method that follows none); ``root_gt_*``: its pelvis
    against the truth's (:func:`grip.core.metrics.measure_pace`; horizontal distances, m, at
    1 s, 5 s and the last frame; drift rate in m/s).

    Args:
        recon: The method's output.
        gt_root: ``(T, 3)`` the ground truth's pelvis, world, m (as many frames as ``recon``).
        fps: Frame rate, Hz.
    """
    if recon.ref_root_pos is None:
        to_gt = M.horizontal_gap(recon.root_pos, gt_root, fps)
        return dict.fromkeys(M.PACE_KEYS, float("nan")) | to_gt.root_gt_metrics()
    return M.measure_pace(recon.root_pos, recon.ref_root_pos, fps, gt_root).metrics()


def segment_metrics(
    recon: Reconstruction, gt: GroundTruth, can_fall: bool
) -> tuple[dict[str, float], dict[str, np.ndarray]]:
    """Metrics of one reconstruction against its segment's ground truth.

    Args:
        recon: The method's output, as many frames as ``gt``.
        gt: :func:`grip.kinematics.features.ground_truth` of the segment.
        can_fall: The method can fall; otherwise ``success_rate`` is NaN.

    Returns:
        ``{key: value}`` for :data:`METRIC_KEYS` except ``ms_per_frame`` (units in
        :mod:`grip.eval.bench`; the pace keys from :func:`pace_metrics`), and ``{key: (24,)
        per-joint means}`` for :data:`PER_JOINT_KEYS`.
    """
    if recon.n_frames != len(gt.joint_pos):
        raise ValueError(f"reconstruction has {recon.n_frames} frames, ground truth "
                         f"{len(gt.joint_pos)}")  # fmt: skip
    pos, rot, fps = recon.joint_pos, recon.global_rot, gt.fps
    nan = float("nan")
    out = {
        "MPJPE_mm": float(M.mpjpe(pos, gt.joint_pos)),
        "PEL_MPJPE_mm": float(M.pel_mpjpe(pos, gt.joint_pos)),
        "PA_MPJPE_mm": float(M.pa_mpjpe(pos, gt.joint_pos)),
        "MPJRE_deg": float(M.mpjre(rot, gt.global_rot)),
        "Acc_mps2": float(M.acceleration_error(pos, gt.joint_pos, fps)) if len(pos) >= 3 else nan,
        "FS_mps": foot_sliding_mps(pos, gt.foot_contacts, fps),
        "FP_mm": foot_penetration_mm(rot, pos, gt.body),
        "vGRF_N": vgrf_error_n(None if recon.grf is None else recon.grf[..., 2], gt.insole_force_n),
        "success_rate": M.success_rate([recon.fell]) if can_fall else nan,
        **pace_metrics(recon, gt.root_pos, fps),
    }
    per_joint = {
        "MPJPE_mm": M.mpjpe(pos, gt.joint_pos, per_joint=True),
        "PEL_MPJPE_mm": M.pel_mpjpe(pos, gt.joint_pos, per_joint=True),
        "MPJRE_deg": M.mpjre(rot, gt.global_rot, per_joint=True),
    }
    return out, per_joint
