"""Cross-fitted training estimates (docs/pace.md, E3): fold models of a split by person, and the
reference set whose every clip is estimated by the model that never saw its person."""

import dataclasses
import json
from types import SimpleNamespace

import numpy as np
import pytest

from grip.kinematics.config import KinematicsRunConfig, replace_train
from grip.kinematics.dataset import (
    clip_of,
    dataset_groups,
    fold_split,
    group_fold,
    recording_group,
    sequence_group,
)
from grip.kinematics.features import targets
from grip.kinematics.reference import (
    build_cross_fitted_reference_set,
    fold_model_chooser,
    fold_partition,
)
from prism_tools.synthetic import make_recording


def _groups(tmp_path, people: int = 10, clips: int = 3) -> dict[str, str]:
    members = {f"src/p{p}": [f"src/p{p}_clip{c}" for c in range(clips)] for p in range(people)}
    (tmp_path / "split.json").write_text(json.dumps(
        {"format": "grip-prism-split", "version": 1, "train": [], "test": [],
         "split_by": "person", "members": members}))  # fmt: skip
    return dataset_groups(tmp_path)


def test_folds_hold_out_whole_people_and_together_cover_everyone(tmp_path) -> None:
    groups = _groups(tmp_path)
    seqs = [SimpleNamespace(name=f"src__p{p}_clip{c}_v0_seq{i:03d}")
            for p in range(10) for c in range(3) for i in range(2)]  # fmt: skip
    held = []
    for k in range(3):
        train, val = fold_split(seqs, 3, k, seed=0, groups=groups)
        people = {groups[clip_of(s.name)] for s in val}
        assert people and not people & {groups[clip_of(s.name)] for s in train}
        assert len(val) == 6 * len(people)  # every clip and chunk of a held-out person
        held.append(people)
    assert set().union(*held) == set(groups.values()) and sum(map(len, held)) == 10
    # a person's fold is its own: the same whichever other people the data holds
    assert all(group_fold(f"src/p{p}", 3, 0) == k for k, ps in enumerate(held)
               for p in range(10) if f"src/p{p}" in ps)  # fmt: skip
    with pytest.raises(ValueError, match="nothing to train or validate"):
        fold_split(seqs[:6], 2, 0, seed=0, groups=groups)  # one person: one side empty


def test_augmented_clips_belong_to_their_source_clips_person(tmp_path) -> None:
    groups = _groups(tmp_path)
    assert sequence_group("src__p3_clip1_v0_seq002", groups) == "src/p3"
    rec = make_recording(30, seed=1)
    for clip in ("src/p3_clip1", "src/p3_clip1@x1.25", "src/p3_clip1-reversed"):
        rec.extras["source_clip"] = clip
        assert recording_group(rec, groups) == "src/p3"
    rec.extras["source_clip"] = "src/nobody_clip0"
    with pytest.raises(ValueError, match="no group"):
        recording_group(rec, groups)


class _FoldModel:
    """An estimator stand-in: the truth, shifted up by ``fold + 1`` cm, so that each clip of a
    set tells which fold model estimated it."""

    def __init__(self, fold: int, folds: int = 2, seed: int = 0, val_source: str = "fold"):
        self.cfg = replace_train(KinematicsRunConfig(), val_source=val_source, fold=fold,
                                 folds=folds, seed=seed)  # fmt: skip
        self.fold = fold

    def predict(self, recs):
        out = []
        for r in recs:
            t = targets(r)
            out.append(SimpleNamespace(joint_pos=t.joint_pos + 0.01 * (self.fold + 1),
                                       global_rot=t.global_rot, velocity=t.velocity))
        return out


def test_each_clip_is_estimated_by_the_model_that_never_saw_its_person(tmp_path) -> None:
    groups = _groups(tmp_path)
    recs = []
    for p in range(10):
        rec = make_recording(40, seed=p)
        rec.extras["source_clip"] = f"src/p{p}_clip0@x1.5" if p % 2 else f"src/p{p}_clip0"
        recs.append(rec)
    models = [_FoldModel(1), _FoldModel(0)]  # (any order)
    ref = build_cross_fitted_reference_set(recs, fold_model_chooser(models, groups, ["b", "a"]))
    assert len(ref) == 10
    for p, (rec, clip) in enumerate(zip(recs, ref.clips, strict=True)):
        assert clip.name == rec.name  # the recordings' order is kept
        fold = group_fold(f"src/p{p}", 2, 0)
        shift = clip.est_pos - targets(rec).joint_pos
        np.testing.assert_allclose(shift, 0.01 * (fold + 1), atol=1e-6)
    assert {group_fold(f"src/p{p}", 2, 0) for p in range(10)} == {0, 1}  # both models used


def test_fold_models_must_be_one_whole_partition() -> None:
    assert fold_partition([_FoldModel(0), _FoldModel(1)], ["a", "b"]) == (2, 0)
    plain = _FoldModel(0, val_source="test")
    assert fold_partition([plain, plain], ["a", "b"]) is None  # (merged, not cross-fitted)
    with pytest.raises(ValueError, match="a, b: not fold models"):
        fold_model_chooser([plain, plain], {}, ["a", "b"])
    with pytest.raises(ValueError, match="some are fold models"):
        fold_partition([_FoldModel(0), plain], ["a", "b"])
    with pytest.raises(ValueError, match=r"each fold 0.*once"):
        fold_partition([_FoldModel(0), _FoldModel(0)], ["a", "b"])
    with pytest.raises(ValueError, match=r"each fold 0.*once"):
        fold_partition([_FoldModel(0), _FoldModel(1, seed=5)], ["a", "b"])
    other = _FoldModel(1)
    other.cfg = dataclasses.replace(other.cfg, features=dataclasses.replace(
        other.cfg.features, insoles=not other.cfg.features.insoles))  # fmt: skip
    with pytest.raises(ValueError, match="different sensor features"):
        fold_partition([_FoldModel(0), other], ["a", "b"])
