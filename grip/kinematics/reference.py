"""Precompute the environment's reference clips: KinematicsNet estimates + ground truth + sensors.

The environment (``envs``, no torch) reads :class:`grip.core.reference.ReferenceSet` files;
this module is the torch side that makes them: it runs KinematicsNet once per recording, offline
and batched, exactly as at inference (the LSTMs are initialised from the recording's first frame).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from grip.core.reference import ReferenceClip, ReferenceSet, pose_vector
from grip.core.rotations import axis_angle_to_matrix, matrix_to_6d
from grip.kinematics.features import FeatureConfig, input_features, recording_body, targets


def gt_qpos(rec) -> np.ndarray:
    """``(T, 76)`` ground-truth ``[root_pos, root_quat_wxyz, 69 hinges (SMPL order)]``."""
    sp = rec.smpl_params
    local = axis_angle_to_matrix(np.asarray(sp.poses, dtype=np.float64).reshape(-1, 24, 3))
    root = np.asarray(sp.trans, dtype=np.float64) + np.asarray(sp.root_offset, dtype=np.float64)
    return pose_vector(local, root)


def reference_clip(rec, joint_pos: np.ndarray, global_rot: np.ndarray, velocity: np.ndarray,
                   features: np.ndarray) -> ReferenceClip:  # fmt: skip
    """One :class:`ReferenceClip` from a recording and an estimate of it.

    Args:
        rec: The recording (ground truth, subject, scene objects).
        joint_pos: ``(T, 24, 3)`` estimated joints minus the root, world axes, m.
        global_rot: ``(T, 24, 3, 3)`` estimated global rotations.
        velocity: ``(T, 6, 3)`` estimated world velocities of the leaves and the pelvis, m/s.
        features: ``(T, F)`` the KinematicsNet inputs of the recording.
    """
    objects = None
    if rec.objects:
        objects = {n: (np.asarray(o.vertices), np.asarray(o.faces)) for n, o in rec.objects.items()}
    return ReferenceClip(
        name=rec.name,
        category=rec.category or "unknown",
        fps=float(rec.fps),
        body=recording_body(rec),
        gt_qpos=gt_qpos(rec),
        est_pos=joint_pos,
        est_rot6d=matrix_to_6d(global_rot),
        est_vel=velocity,
        sensor=features,
        objects=objects,
    )


def oracle_reference_clip(rec, features: FeatureConfig | None = None) -> ReferenceClip:
    """A clip whose "estimate" is the ground truth itself (numpy only, no network).

    The upper bound of what a controller can do with a perfect KinematicsNet; used by the
    environment's tests and benchmarks and for debugging policies.
    """
    t = targets(rec)
    feats = input_features(rec, features or FeatureConfig())
    return reference_clip(rec, t.joint_pos, t.global_rot, t.velocity, feats)


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
            clips.append(reference_clip(rec, est.joint_pos, est.global_rot, est.velocity,
                                        input_features(rec, cfg)))  # fmt: skip
        if progress is not None:
            progress(len(part))
    return ReferenceSet(clips, tuple(cfg.sites), cfg.insoles, source)


def merge_reference_sets(sets: Sequence[ReferenceSet], source: str = "<memory>") -> ReferenceSet:
    """One reference set holding the clips of several, e.g. the same recordings estimated by
    several KinematicsNets (``grip train-policy --kin A --kin B``): the controller then trains
    on references with the errors of each estimator. Clip names of the k-th set (k >= 1) get
    the suffix ``#k`` so that every clip keeps a unique name.

    Raises:
        ValueError: No set, or sets whose sensor observations differ (sites or insoles).
    """
    if not sets:
        raise ValueError("merge_reference_sets needs at least one reference set")
    first = sets[0]
    clips = list(first.clips)
    for k, other in enumerate(sets[1:], start=1):
        if other.sensor_sites != first.sensor_sites or other.insoles != first.insoles:
            raise ValueError(f"{other.source}: sensor sites {list(other.sensor_sites)} / insoles "
                             f"{other.insoles} differ from {first.source}'s "
                             f"{list(first.sensor_sites)} / {first.insoles}")  # fmt: skip
        for c in other.clips:
            c.name = f"{c.name}#{k}"
            clips.append(c)
    return ReferenceSet(clips, first.sensor_sites, first.insoles, source)
