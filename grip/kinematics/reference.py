"""Precompute the environment's reference clips: KinematicsNet estimates + ground truth + sensors.

The environment (``envs``, no torch) reads :class:`grip.core.reference.ReferenceSet` files;
this module is the torch side that makes them: it runs KinematicsNet once per recording, offline
and batched, exactly as at inference (the LSTMs are initialised from the recording's first frame).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from grip.core.reference import ReferenceClip, ReferenceSet
from grip.core.rotations import (
    axis_angle_to_matrix,
    matrix_to_6d,
    matrix_to_euler_xyz,
    matrix_to_quat,
)
from grip.kinematics.features import FeatureConfig, input_features, recording_body, targets


def gt_qpos(rec) -> np.ndarray:
    """``(T, 76)`` ground-truth ``[root_pos, root_quat_wxyz, 69 hinges (SMPL order)]``."""
    sp = rec.smpl_params
    local = axis_angle_to_matrix(np.asarray(sp.poses, dtype=np.float64).reshape(-1, 24, 3))
    root = np.asarray(sp.trans, dtype=np.float64) + np.asarray(sp.root_offset, dtype=np.float64)
    t = local.shape[0]
    q = np.empty((t, 76))
    q[:, :3] = root
    q[:, 3:7] = matrix_to_quat(local[:, 0])
    q[:, 7:] = matrix_to_euler_xyz(local[:, 1:]).reshape(t, 69)
    return q


def reference_clip(rec, est, features: np.ndarray) -> ReferenceClip:
    """One :class:`ReferenceClip` from a recording and its :class:`KinematicEstimate`."""
    objects = None
    if rec.objects:
        objects = {n: (np.asarray(o.vertices), np.asarray(o.faces)) for n, o in rec.objects.items()}
    return ReferenceClip(
        name=rec.name,
        category=rec.category or "unknown",
        fps=float(rec.fps),
        body=recording_body(rec),
        gt_qpos=gt_qpos(rec),
        est_pos=est.joint_pos,
        est_rot6d=matrix_to_6d(est.global_rot),
        est_vel=est.velocity,
        sensor=features,
        objects=objects,
    )


def oracle_reference_clip(rec, features: FeatureConfig | None = None) -> ReferenceClip:
    """A clip whose "estimate" is the ground truth itself (numpy only, no network).

    The upper bound of what a controller can do with a perfect KinematicsNet; used by the
    environment's tests and for debugging policies.
    """
    t = targets(rec)

    class _Perfect:
        joint_pos, global_rot, velocity = t.joint_pos, t.global_rot, t.velocity

    return reference_clip(rec, _Perfect, input_features(rec, features or FeatureConfig()))


def build_reference_set(
    recs: Sequence,
    estimator,
    batch: int = 16,
    progress: Callable[[int], object] | None = None,
    source: str = "<memory>",
) -> ReferenceSet:
    """Run KinematicsNet over recordings (batched) and package them for the environment.

    Args:
        recs: PRISM-format recordings with ground truth (``smpl_params``).
        estimator: A :class:`grip.kinematics.inference.KinematicsEstimator`; its feature
            settings fix the sensor observation.
        batch: Recordings per forward pass.
        progress: Called with the number of recordings finished after each batch.
        source: Description stored for messages.
    """
    clips = []
    cfg = estimator.cfg.features
    for i in range(0, len(recs), batch):
        part = list(recs[i : i + batch])
        for rec, est in zip(part, estimator.predict(part), strict=True):
            clips.append(reference_clip(rec, est, input_features(rec, cfg)))
        if progress is not None:
            progress(len(part))
    return ReferenceSet(clips, tuple(cfg.sites), cfg.insoles, source)
