"""Speed-scaled training references (``speed_factors`` of ``grip policy train``): the training
clips played faster, so that the controller trains on walking speeds its training people never
walked (docs/pace.md)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from grip.core.reference import ReferenceSet


def _train_clip(built: Path) -> tuple[dict, dict]:
    manifest = json.loads((built / "manifest.json").read_text())
    split = json.loads((built / "split.json").read_text())
    clip = next(c for c in manifest["clips"] if len(c["sequences"]) == 1
                and c["sequences"][0] in split["train"])  # fmt: skip
    return clip, split


def test_a_time_scaled_motion_is_the_same_motion_faster(built: Path) -> None:
    from grip.dataset.build import safe_name
    from grip.motion.motion import Motion

    clip, _ = _train_clip(built)
    m = Motion.load(built / "motions" / f"{safe_name(clip['clip_id'])}.npz")
    f = 1.5
    fast = m.time_scaled(f)
    assert fast.fps == m.fps and fast.category == m.category
    assert fast.n_frames == int(np.floor((m.n_frames - 1) / f)) + 1
    assert fast.meta["time_scale"] == pytest.approx(f)
    # frame k of the fast motion is the original at time k f / fps: every second frame of the
    # fast one is every third of the original
    np.testing.assert_allclose(fast.root_pos[::2], m.root_pos[::3][: len(fast.root_pos[::2])],
                               atol=1e-9)  # fmt: skip
    dist = np.linalg.norm(np.diff(m.root_pos[:, :2], axis=0), axis=1).sum()
    dist_fast = np.linalg.norm(np.diff(fast.root_pos[:, :2], axis=0), axis=1).sum()
    speed, speed_fast = dist / m.duration_s, dist_fast / fast.duration_s
    assert speed_fast == pytest.approx(f * speed, rel=0.05)
    np.testing.assert_allclose(np.linalg.norm(fast.local_quat, axis=-1), 1.0, atol=1e-9)
    for bad in (0.4, 2.5, float("nan")):
        with pytest.raises(ValueError, match="time scale"):
            m.time_scaled(bad)


def test_speed_scaled_recordings_join_the_reference_set(built: Path, tmp_path: Path,
                                                        capsys) -> None:  # fmt: skip
    from grip.cli.errors import CliError
    from grip.cli.policy_runs import build_training_reference
    from grip.cli.recordings import kin_checkpoint, split_paths
    from grip.dataset.augment import time_scaled_recordings

    clip, split = _train_clip(built)
    cat = clip["category"]
    recs = time_scaled_recordings(built, split["train"], [cat], (1.25, 1.5))
    assert sorted({r.name.split("_seq")[0] for r in recs}) == [
        f"synthetic_{clip['clip_id']}@x1.25", f"synthetic_{clip['clip_id']}@x1.5"]
    assert all(r.category == cat for r in recs)  # the stages' category filters keep them
    # a test clip never contributes
    test_recs = time_scaled_recordings(built, split["test"], [cat], (1.5,))
    assert not any(clip["clip_id"] in r.name for r in test_recs)
    files, kin = split_paths(built, "train"), [kin_checkpoint(None)]
    ref_path = tmp_path / "speed.npz"
    build_training_reference(ref_path, built, files, kin, speed_factors=(1.25, 1.5),
                             speed_categories=(cat,))  # fmt: skip
    names = [c.name for c in ReferenceSet.load(ref_path).clips]
    assert len(names) == len(files) + len(recs)
    assert sum("@x" in n for n in names) == len(recs)
    assert "speed-scaled recordings" in capsys.readouterr().out
    # the same folder with other settings is refused, not silently reused
    with pytest.raises(CliError, match=r"speed_factors.*delete it"):
        build_training_reference(ref_path, built, files, kin, speed_factors=(1.5,),
                                 speed_categories=(cat,))  # fmt: skip
    build_training_reference(ref_path, built, files, kin, speed_factors=(1.25, 1.5),
                             speed_categories=(cat,))  # the same settings: kept  # fmt: skip
    with pytest.raises(CliError, match=r"speed_categories.*no training clip"):
        build_training_reference(tmp_path / "none.npz", built, files, kin, speed_factors=(1.5,),
                                 speed_categories=("no-such-category",))  # fmt: skip
    # a set made before its settings were recorded holds no speed-scaled clips: kept without
    # speed_factors, refused with them
    old_path = tmp_path / "old.npz"
    build_training_reference(old_path, built, files, kin)
    old_path.with_suffix(".json").unlink()
    build_training_reference(old_path, built, files, kin)
    with pytest.raises(CliError, match=r"speed_factors.*made before speed_factors existed"):
        build_training_reference(old_path, built, files, kin, speed_factors=(1.5,),
                                 speed_categories=(cat,))  # fmt: skip


def test_fold_models_make_one_cross_fitted_copy(built: Path, tmp_path: Path,
                                               monkeypatch) -> None:  # fmt: skip
    """``--kin F0 --kin F1`` of fold models: every training recording (speed-scaled ones too)
    once, estimated by the fold model that never saw its person; the set records it."""
    from grip.cli.errors import CliError
    from grip.cli.policy_runs import build_training_reference
    from grip.cli.recordings import kin_checkpoint, split_paths
    from grip.kinematics.dataset import dataset_groups, group_fold, sequence_group
    from grip.kinematics.features import targets
    from grip.kinematics.inference import KinematicsEstimator
    from prism_tools.io import load_recording
    from tests.kinematics.test_cross_fit import _FoldModel

    clip, _ = _train_clip(built)
    files = split_paths(built, "train")
    models = {"f0.pt": _FoldModel(0), "f1.pt": _FoldModel(1)}
    real = KinematicsEstimator.from_checkpoint
    monkeypatch.setattr(KinematicsEstimator, "from_checkpoint",
                        lambda p, tta="none": models.get(Path(p).name) or real(p))  # fmt: skip
    ref_path = tmp_path / "cross.npz"
    kins = [Path("f1.pt"), Path("f0.pt")]
    build_training_reference(ref_path, built, files, kins, speed_factors=(1.5,),
                             speed_categories=(clip["category"],))  # fmt: skip
    assert json.loads(ref_path.with_suffix(".json").read_text())["cross_fit"] == 2
    ref = ReferenceSet.load(ref_path)
    assert len(ref) == len(files) + sum(1 for c in ref.clips if "@x" in c.name)
    groups = dataset_groups(built)
    for f, c in zip(files, ref.clips, strict=False):  # (the recordings' order is kept)
        fold = group_fold(sequence_group(f.stem, groups), 2, 0)
        shift = c.est_pos - targets(load_recording(f)).joint_pos
        np.testing.assert_allclose(shift, 0.01 * (fold + 1), atol=1e-4)
    with pytest.raises(CliError, match=r"cross_fit.*delete it"):
        build_training_reference(ref_path, built, files, [kin_checkpoint(None)],
                                 speed_factors=(1.5,), speed_categories=(clip["category"],))
    with pytest.raises(CliError, match=r"f1.pt is the model of fold 1 of 2.*--kin F0 --kin F1"):
        build_training_reference(tmp_path / "one.npz", built, files, [Path("f1.pt")])
    build_training_reference(tmp_path / "truth.npz", built, files, [Path("f1.pt")],
                             follow="truth")  # (the truth needs only its feature settings)


def test_speed_factors_are_checked_and_old_configs_load() -> None:
    import dataclasses

    from policies.config import PolicyRunConfig, policy_config_from_dict

    assert PolicyRunConfig(speed_factors=(1.25, 1.5)).speed_categories == ("walk*",)
    for bad in ((1.0,), (2.5,), (1.25, 1.25), (0.3,)):
        with pytest.raises(ValueError, match="speed_factors"):
            PolicyRunConfig(speed_factors=bad)
    with pytest.raises(ValueError, match="speed_categories"):
        PolicyRunConfig(speed_factors=(1.5,), speed_categories=())
    old = dataclasses.asdict(PolicyRunConfig())
    del old["speed_factors"], old["speed_categories"]
    assert policy_config_from_dict(old, "old run").speed_factors == ()


def test_distill_takes_the_speed_settings_and_set_spells_them() -> None:
    import dataclasses

    from grip.cli.errors import CliError
    from grip.cli.paths import REPO_ROOT, load_run_config
    from grip.motion.motion import TIME_SCALE_RANGE
    from policies.config import SPEED_FACTOR_RANGE, PolicyRunConfig
    from policies.distill import DistillConfig

    assert SPEED_FACTOR_RANGE == TIME_SCALE_RANGE
    for cls, kind, toml in ((PolicyRunConfig, "policy", "finetune.toml"),
                            (DistillConfig, "distill", "distill.toml")):  # fmt: skip
        path = REPO_ROOT / "configs" / "policy" / toml
        cfg = load_run_config(path, kind, cls(), ["speed_factors=[1.25,1.5]"])
        assert cfg.speed_factors == (1.25, 1.5) and cfg.speed_categories == ("walk*",)
        cfg = load_run_config(path, kind, cls(), ['speed_factors=[2]',
                                                  'speed_categories=["walk*","run*"]'])  # fmt: skip
        assert cfg.speed_factors == (2,) and cfg.speed_categories == ("walk*", "run*")
        for bad in ("speed_factors=1.5", 'speed_factors=["1.5"]', "speed_factors=[true]",
                    "speed_factors=[1.5,1.50]", "speed_factors=[0.25]"):  # fmt: skip
            with pytest.raises(CliError, match="speed_factors"):
                load_run_config(path, kind, cls(), [bad])
    with pytest.raises(ValueError, match="speed_categories"):
        DistillConfig(speed_factors=(1.5,), speed_categories=())
    old = dataclasses.asdict(DistillConfig())
    del old["speed_factors"], old["speed_categories"]
    assert DistillConfig(**old).speed_factors == ()


def test_a_runs_own_reference_set_may_hold_several_copies(built: Path, tmp_path: Path,
                                                           monkeypatch) -> None:  # fmt: skip
    """``max_total_bytes`` is a limit for one input; a run's speed-scaled set holds three
    copies of the training walks (the whole corpus' set is 1.07 GB), and the run reads it back
    under that limit times the copies its settings make, however often the set is opened."""
    from grip.cli.policy_runs import build_training_reference, reference_copies
    from grip.cli.recordings import kin_checkpoint, split_paths
    from grip.core.limits import LIMITS_ENV, active_limits, check_npz
    from grip.core.reference import ReferenceError as RefError

    clip, _ = _train_clip(built)
    files, kin = split_paths(built, "train"), [kin_checkpoint(None)]
    ref_path = tmp_path / "speed.npz"
    build_training_reference(ref_path, built, files, kin, speed_factors=(1.25, 1.5),
                             speed_categories=(clip["category"],))  # fmt: skip
    size = sum(np.prod(s) * d.itemsize for s, d in check_npz(ref_path, active_limits()).values())
    one = int(size * 0.6)  # a limit the set is over, as the corpus' set is over 1 GiB
    monkeypatch.setenv(LIMITS_ENV, f"max_total_bytes={one}")
    monkeypatch.setattr("grip.cli.policy_runs._ONE_INPUT", {})
    with pytest.raises(RefError, match="max_total_bytes"):
        ReferenceSet.load(ref_path)
    for _ in range(2):  # the resumed run: the set is kept, the limit raised once, not twice
        build_training_reference(ref_path, built, files, kin, speed_factors=(1.25, 1.5),
                                 speed_categories=(clip["category"],))  # fmt: skip
        assert active_limits().max_total_bytes == 3 * one
    assert len(ReferenceSet.load(ref_path).clips) > len(files)
    made = {"follow": "estimate", "speed_factors": [1.5], "reverse_categories": ["walk"],
            "mirror": True}  # fmt: skip
    assert reference_copies(made, 1) == 6 and reference_copies(made, 2) == 12
    assert reference_copies({**made, "follow": "truth"}, 3) == 6
    assert reference_copies({**made, "follow": "both"}, 1) == 12
