"""Precompute the environment's reference clips: KinematicsNet estimates + ground truth + sensors.

The environment (``envs``, no torch) reads :class:`grip.core.reference.ReferenceSet` files;
this module is the torch side that makes them: it runs KinematicsNet once per recording, offline
and batched, exactly as at inference (the LSTMs are initialised from the recording's first frame).
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence

import numpy as np

from grip.core import skeleton as sk
from grip.core.reference import ReferenceClip, ReferenceSet, pose_vector
from grip.core.rotations import axis_angle_to_matrix, matrix_to_6d
from grip.kinematics.features import FeatureConfig, input_features, recording_body, targets


def gt_qpos(rec) -> np.ndarray:
    """``(T, 76)`` ground-truth ``[root_pos, root_quat_wxyz, 69 hinges (SMPL order)]``."""
    sp = rec.require_ground_truth("a training reference clip")
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
    truth: bool = False,
    compact: bool = False,
) -> ReferenceSet:
    """Run KinematicsNet over recordings (batched) and package them for the environment.

    Args:
        recs: PRISM-format recordings with ground truth (``smpl_params``).
        estimator: A :class:`grip.kinematics.inference.KinematicsEstimator`; its feature
            settings fix the sensor observation.
        batch: Recordings per forward pass.
        progress: Called with the number of recordings finished after each batch.
        source: Description stored for messages.
        truth: The clips' "estimate" is the ground truth (:func:`oracle_reference_clip`, the
            references of a privileged tracker); the network is not run, only its feature
            settings are used.
        compact: Each clip :meth:`~grip.core.reference.ReferenceClip.compact` as soon as its
            batch is made (a training set: half the memory while it is built).
    """
    clips = []
    cfg = estimator.cfg.features
    for i in range(0, len(recs), batch):
        part = list(recs[i : i + batch])
        if truth:
            clips += [oracle_reference_clip(rec, cfg) for rec in part]
        else:
            for rec, est in zip(part, estimator.predict(part), strict=True):
                clips.append(reference_clip(rec, est.joint_pos, est.global_rot, est.velocity,
                                            input_features(rec, cfg)))  # fmt: skip
        if compact:
            for c in clips[len(clips) - len(part) :]:
                c.compact()
        if progress is not None:
            progress(len(part))
    return ReferenceSet(clips, tuple(cfg.sites), cfg.insoles, source)


def fold_partition(estimators: Sequence, sources: Sequence[str]) -> tuple[int, int] | None:
    """``(folds, seed)`` when the KinematicsNet ``estimators`` are the K fold models of one
    split by person (``train.val_source = "fold"``, the same ``folds`` and ``seed``, each fold
    once, in any order); ``None`` when none is a fold model.

    Raises:
        ValueError: naming ``sources`` (the checkpoints), when some are fold models and others
            not, or the fold models are not one whole partition.
    """
    trains = [e.cfg.train for e in estimators]
    is_fold = [t.val_source == "fold" for t in trains]
    if not any(is_fold):
        return None
    names = ", ".join(str(s) for s in sources)
    if not all(is_fold):
        raise ValueError(f"{names}: some are fold models (train.val_source = 'fold') and some "
                         "not; cross-fitted estimates need exactly the K fold models")  # fmt: skip
    if any(e.cfg.features != estimators[0].cfg.features for e in estimators):
        raise ValueError(f"{names}: the fold models read different sensor features")
    parts = {(t.folds, t.seed) for t in trains}
    folds, seed = next(iter(parts))
    if len(parts) > 1 or sorted(t.fold for t in trains) != list(range(folds)):
        got = [(t.fold, t.folds, t.seed) for t in trains]
        raise ValueError(f"{names}: not the {folds} fold models of one split (fold, folds, seed "
                         f"= {got}); each fold 0..K-1 once, the same folds and seed")  # fmt: skip
    return folds, seed


def fold_model_chooser(estimators: Sequence, groups, sources: Sequence[str]):
    """``rec -> estimator``: of the K fold models ``estimators`` (:func:`fold_partition`; any
    order), the one that never saw the recording's person
    (:func:`grip.kinematics.dataset.recording_group` in ``groups``, the clip -> group map of
    the recordings' dataset, :func:`grip.kinematics.dataset.dataset_groups`).

    Raises:
        ValueError: naming ``sources``, when the estimators are not one whole partition (or no
            fold models); the chooser raises for a recording whose person is unknown.
    """
    from grip.kinematics.dataset import group_fold, recording_group

    part = fold_partition(estimators, sources)
    if part is None:
        raise ValueError(f"{', '.join(str(s) for s in sources)}: not fold models "
                         "(train.val_source = 'fold')")  # fmt: skip
    by_fold = {e.cfg.train.fold: e for e in estimators}
    return lambda rec: by_fold[group_fold(recording_group(rec, groups), *part)]


def build_cross_fitted_reference_set(
    recs: Sequence,
    choose: Callable,
    progress: Callable[[int], object] | None = None,
    source: str = "<memory>",
    compact: bool = False,
) -> ReferenceSet:
    """The reference set of ``recs`` in which every recording is estimated by the fold model
    that never saw its person (cross-fitting): the errors of the training clips' estimates
    are then those of people the estimator never saw, as at test time.

    Args:
        choose: ``rec -> estimator`` (:func:`fold_model_chooser`); the recordings are run in
            batches per estimator and keep their order.

    Raises:
        ValueError: a recording's person is unknown
            (:func:`grip.kinematics.dataset.recording_group`).
    """
    chosen = [choose(r) for r in recs]
    clips: list = [None] * len(recs)
    for est in {id(e): e for e in chosen}.values():
        idx = [i for i, e in enumerate(chosen) if e is est]
        ref = build_reference_set([recs[i] for i in idx], est, progress=progress,
                                  compact=compact)  # fmt: skip
        for i, c in zip(idx, ref.clips, strict=True):
            clips[i] = c
    cfg = chosen[0].cfg.features if chosen else None
    sites, insoles = (tuple(cfg.sites), cfg.insoles) if cfg else ((), False)
    return ReferenceSet(clips, sites, insoles, source)


def merge_reference_sets(sets: Sequence[ReferenceSet], source: str = "<memory>",
                         suffixes: Sequence[str] | None = None) -> ReferenceSet:  # fmt: skip
    """One reference set holding the clips of several, e.g. the same recordings estimated by
    several KinematicsNets (``grip policy train --kin A --kin B``): the controller then trains
    on references with the errors of each estimator. Clip names of the k-th set (k >= 1) get
    the suffix ``#k`` (or ``suffixes[k]``) so that every clip keeps a unique name.

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
        tag = f"#{k}" if suffixes is None else suffixes[k]
        for c in other.clips:
            renamed = copy.copy(c)  # (shares the arrays; the caller's clip keeps its name)
            renamed.name = f"{c.name}{tag}"
            clips.append(renamed)
    return ReferenceSet(clips, first.sensor_sites, first.insoles, source)


MIRROR_SUFFIX = "~mirror"
_M = np.array([-1.0, 1.0, 1.0])  # the reflection x -> -x (as grip.nn.symmetry.mirror_batch)
# per hinge: the angle about x keeps its sign under R -> M R M, those about y and z flip
_HINGE_SIGN = np.array([[1.0 if a == "x" else -1.0 for a in sk.HINGE_ORDERS[j]]
                        for j in range(1, sk.N_JOINTS)])  # fmt: skip


def mirror_reference_clip(clip: ReferenceClip, sites: Sequence[str], insoles: bool
                          ) -> ReferenceClip:  # fmt: skip
    """The left-right mirror image of a reference clip (ground truth, estimate and sensors).

    The world is reflected through ``x = 0`` and left and right swap, the convention of
    :func:`grip.nn.symmetry.mirror_batch`, which mirrors the sensor features and the
    estimate (its joints, 6D rotations and velocities are KinematicsNet's ``fp``, ``fa`` and
    ``lv`` targets). The ground-truth pose vector: the root position ``p -> M p``, the root
    quaternion ``(w, x, y, z) -> (w, x, -y, -z)`` (``R -> M R M``), hinge angles about x keep
    their sign and those about y and z flip, left and right swap. Scene meshes are reflected
    (faces reversed to keep their outward side). Exact for the mirror-symmetric body of
    :func:`grip.core.body.build_body` (subjects differ in height and mass only); the mirrored
    clip is named ``name + "~mirror"``.
    """
    import torch

    from grip.nn.symmetry import mirror_batch

    q = clip.gt_qpos
    hinges = q[:, 7:].reshape(-1, sk.N_JOINTS - 1, 3) * _HINGE_SIGN
    hinges = hinges[:, sk.MIRROR[1:] - 1]
    gt = np.concatenate([q[:, :3] * _M, q[:, 3:5], -q[:, 5:7], hinges.reshape(len(q), -1)], axis=1)

    def batch(a: np.ndarray) -> torch.Tensor:  # (T, ...) -> (1, T, F) float64
        return torch.from_numpy(np.asarray(a, dtype=np.float64).reshape(1, len(a), -1))

    est = {"fp": batch(clip.est_pos), "fa": batch(clip.est_rot6d), "lv": batch(clip.est_vel)}
    x, y = mirror_batch(batch(clip.sensor), est, tuple(sites), insoles)
    objects = None
    if clip.objects:
        objects = {n: (np.asarray(v, dtype=np.float64) * _M, np.asarray(f)[:, ::-1].copy())
                   for n, (v, f) in clip.objects.items()}  # fmt: skip
    return ReferenceClip(
        name=clip.name + MIRROR_SUFFIX, category=clip.category, fps=clip.fps, body=clip.body,
        gt_qpos=gt, est_pos=y["fp"][0].numpy().reshape(clip.est_pos.shape),
        est_rot6d=y["fa"][0].numpy().reshape(clip.est_rot6d.shape),
        est_vel=y["lv"][0].numpy().reshape(clip.est_vel.shape),
        sensor=x[0].numpy().astype(clip.sensor.dtype), objects=objects,
    )  # fmt: skip


def with_mirrored_clips(ref: ReferenceSet, source: str | None = None) -> ReferenceSet:
    """``ref``'s clips followed by the mirror image of each (:func:`mirror_reference_clip`):
    twice the motions for the controller, left and right balanced."""
    mirrored = [mirror_reference_clip(c, ref.sensor_sites, ref.insoles) for c in ref.clips]
    return ReferenceSet([*ref.clips, *mirrored], ref.sensor_sites, ref.insoles,
                        source or ref.source)  # fmt: skip
