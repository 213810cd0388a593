"""``grip data build``'s split by person, re-split and relabelling without building a clip again,
and ``grip data info``'s groups, on a small copy of four shared sources (15 short clips)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from grip.assets import REPO_ROOT
from grip.cli.main import main

MOTIONS = REPO_ROOT.parent / "shared" / "data" / "motions"
pytestmark = pytest.mark.skipif(not MOTIONS.is_dir(), reason="shared motion clips not found")

_HDM05 = [
    "HDM_bd_squat1Reps_003_120",
    "HDM_bd_squat1Reps_009_120",
    "HDM_bk_elbowToKnee1RepsLelbowStart_011_120",
    "HDM_bk_rotateArmsBothBackward1Reps_005_120",
    "HDM_dg_hopBothLegs1hops_022_120",
    "HDM_dg_hopBothLegs1hops_023_120",
    "HDM_mm_kickLFront1Reps_023_120",
]
_CMU = ["02_01", "07_04", "08_07"]
_BANDAI = ["dataset-2_run_active_048", "dataset-2_run_normal_014"]
_DEEPMIMIC = ["walk", "kick"]


def _corpus(root: Path) -> Path:
    """Copies of a few clips of HDM05, CMU, Bandai Namco dataset-2 and DeepMimic, laid out as in
    the shared folder (with their clips.csv, ASF files and label files)."""
    hdm = root / "hdm05"
    shutil.copytree(MOTIONS / "hdm05" / "asf", hdm / "asf")
    shutil.copy(MOTIONS / "hdm05" / "clips.csv", hdm / "clips.csv")
    (hdm / "amc").mkdir()
    for name in _HDM05:
        shutil.copy(MOTIONS / "hdm05" / "amc" / f"{name}.amc", hdm / "amc")
    (root / "cmu" / "bvh").mkdir(parents=True)
    shutil.copy(MOTIONS / "cmu" / "clips.csv", root / "cmu" / "clips.csv")
    for name in _CMU:
        shutil.copy(MOTIONS / "cmu" / "bvh" / f"{name}.bvh", root / "cmu" / "bvh")
    src = MOTIONS / "bandai_namco" / "dataset-2"
    dst = root / "bandai_namco" / "dataset-2"
    shutil.copytree(src / "cfg", dst / "cfg")
    for name in _BANDAI:
        for suffix in (".bvh", ".json"):
            shutil.copy(src / f"{name}{suffix}", dst)
    (root / "deepmimic").mkdir()
    for name in ("character_skeleton", *_DEEPMIMIC):
        shutil.copy(MOTIONS / "deepmimic" / f"humanoid3d_{name}.txt", root / "deepmimic")
    for p in root.rglob("*"):  # the shared files are read-only; the copies may be replaced
        p.chmod(0o755 if p.is_dir() else 0o644)
    return root


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Path:
    return _corpus(tmp_path_factory.mktemp("motions"))


@pytest.fixture(scope="module")
def built(tmp_path_factory, corpus: Path) -> Path:
    out = tmp_path_factory.mktemp("ds") / "dataset"
    assert main(["data", "build", "--out", str(out), "--motions", str(corpus),
                 "--workers", "1"]) == 0  # fmt: skip
    return out


def _build(out: Path, corpus: Path, *extra: str) -> int:
    return main(["data", "build", "--out", str(out), "--motions", str(corpus), "--workers", "1",
                 *extra])  # fmt: skip


def _stamps(folder: Path) -> dict[str, int]:
    files = [p for sub in ("sequences", "motions", "done") for p in (folder / sub).iterdir()]
    return {str(p.relative_to(folder)): p.stat().st_mtime_ns for p in files}


def test_build_splits_by_person_within_each_source(built: Path) -> None:
    split = json.loads((built / "split.json").read_text())
    manifest = json.loads((built / "manifest.json").read_text())
    assert split["split_by"] == "person" and manifest["config"]["split_by"] == "person"
    train, test = set(split["groups"]["train"]), set(split["groups"]["test"])
    assert not train & test
    clips = {c["clip_id"]: c for c in manifest["clips"]}
    assert clips["hdm05/HDM_bd_squat1Reps_003_120"]["group"] == "hdm05/bd"
    assert clips["cmu/07_04"]["group"] == "cmu/07"
    assert clips["bandai_namco/dataset-2_run_normal_014"]["group"] == \
        "bandai_namco/dataset-2/normal"  # fmt: skip
    assert clips["deepmimic/walk"]["group"] == "deepmimic/walk"
    for cid, c in clips.items():  # every clip's sequences are on its group's side
        if c["sequences"]:
            side = "test" if c["group"] in test else "train"
            assert set(c["sequences"]) <= set(split[side]), cid
            assert cid in split["members"][c["group"]]
    for source in ("hdm05", "cmu", "bandai_namco/dataset-2", "deepmimic"):
        parts = split["sources"][source]
        assert parts["train"]["groups"] and parts["test"]["groups"], source
    assert split["sources"]["hdm05"]["test"]["groups"] in (["hdm05/bd"], ["hdm05/bk"],
                                                           ["hdm05/dg"], ["hdm05/mm"])  # fmt: skip
    squat = clips["hdm05/HDM_bd_squat1Reps_003_120"]
    assert (squat["category"], squat["label"]) == ("squat", "squat1Reps")
    assert clips["bandai_namco/dataset-2_run_active_048"]["category"] == "run"
    from prism_tools.io import load_recording

    seq = clips["cmu/02_01"]["sequences"][0]
    rec = load_recording(built / "sequences" / f"{seq}.npz")
    assert rec.category == "walk" and rec.extras["label"] == "walking_variety"


def test_info_prints_the_groups_per_split(built: Path, tmp_path: Path, capsys) -> None:
    js = tmp_path / "info.json"
    assert main(["data", "info", str(built), "--json", str(js)]) == 0
    out = capsys.readouterr().out
    assert "split by person" in out and "groups per split:" in out
    assert "| source | train groups | test groups |" in out and "| hdm05 | 3 | 1 |" in out
    assert "| category | train sequences | test sequences |" in out
    info = json.loads(js.read_text())
    groups = info["split_groups"]
    for actor in ("bd", "bk", "dg", "mm"):
        side = "test" if f"hdm05/{actor}" in groups["test"] else "train"
        line = next(ln for ln in out.splitlines() if ln.startswith(f"- hdm05 {side} ("))
        assert actor in line
    assert info["splits"]["test"]["groups"] == len(groups["test"])
    manifest = json.loads((built / "manifest.json").read_text())
    with_sequences = sum(1 for c in manifest["clips"] if c["sequences"])
    assert info["splits"]["train"]["clips"] + info["splits"]["test"]["clips"] == with_sequences


def test_a_finished_dataset_is_split_again_without_building_a_clip(
    built: Path, corpus: Path, tmp_path: Path, capsys
) -> None:
    out = tmp_path / "copy"
    shutil.copytree(built, out)
    before = _stamps(out)
    person = json.loads((out / "split.json").read_text())
    capsys.readouterr()
    assert _build(out, corpus, "--split-by", "clip", "--split-seed", "3") == 0
    assert "0 built in this run" in capsys.readouterr().out
    assert _stamps(out) == before  # no recording, motion or done marker was written
    split = json.loads((out / "split.json").read_text())
    assert split["split_by"] == "clip" and split["seed"] == 3
    assert all(len(m) == 1 for m in split["members"].values())  # a group per clip
    settings = json.loads((out / "settings.json").read_text())
    assert (settings["split_by"], settings["split_seed"]) == ("clip", 3)
    assert _build(out, corpus) == 0  # back to the defaults: the same split as the first build
    assert json.loads((out / "split.json").read_text()) == person
    assert _stamps(out) == before
    assert _build(out, corpus, "--seed", "1") == 2  # a setting that changes the clips: refused
    assert "different settings" in capsys.readouterr().err
    # a group named on the command line goes to test whatever the draw, again without a build
    train_groups = person["groups"]["train"]
    pick = next(g for g in train_groups if g.startswith("cmu/"))
    assert _build(out, corpus, "--test-group", pick) == 0
    split = json.loads((out / "split.json").read_text())
    assert pick in split["groups"]["test"] and pick not in split["groups"]["train"]
    others = lambda sp: {g for g in sp["groups"]["test"] if not g.startswith("cmu/")}  # noqa: E731
    assert others(split) == others(person)  # the other sources' draws are unchanged
    assert _stamps(out) == before
    assert _build(out, corpus, "--test-group", "cmu/none") == 2
    assert "cmu/none" in capsys.readouterr().err


def test_an_edited_category_map_relabels_the_recordings(
    built: Path, corpus: Path, tmp_path: Path, capsys
) -> None:
    from grip.motion.motion import Motion
    from prism_tools.io import load_recording

    out = tmp_path / "copy"
    shutil.copytree(built, out)
    before = _stamps(out)
    cats = tmp_path / "cats.toml"
    text = (REPO_ROOT / "configs" / "categories.toml").read_text()
    cats.write_text(text.replace('squat1Reps = "squat"', 'squat1Reps = "exercise"'))
    seqs = [p for p in (out / "sequences").glob("hdm05__HDM_bd_squat1Reps_*.npz")]
    old = {p.name: load_recording(p) for p in seqs}
    capsys.readouterr()
    assert _build(out, corpus, "--categories", str(cats)) == 0
    assert "(2 relabelled), 0 built" in capsys.readouterr().out
    after = _stamps(out)
    changed = sorted(k for k in after if after[k] != before[k])
    assert changed == sorted([*(f"sequences/{p.name}" for p in seqs),
                              *(f"{d}/hdm05__HDM_bd_squat1Reps_00{k}_120.{e}" for k in (3, 9)
                                for d, e in (("motions", "npz"), ("done", "json")))])  # fmt: skip
    for p in seqs:
        rec = load_recording(p)
        assert (rec.category, rec.extras["label"]) == ("exercise", "squat1Reps")
        np.testing.assert_array_equal(rec.imu["L_Foot"].acc_world_raw,
                                      old[p.name].imu["L_Foot"].acc_world_raw)  # fmt: skip
    motion = Motion.load(out / "motions" / "hdm05__HDM_bd_squat1Reps_003_120.npz")
    assert motion.category == "exercise"
    split = json.loads((out / "split.json").read_text())
    assert "squat" not in split["stats"]["total"]["categories"]
    bad = tmp_path / "bad.toml"
    bad.write_text('vocabulary = ["walk"]\n[labels]\nsquat1Reps = "crouch"\n')
    assert _build(out, corpus, "--categories", str(bad)) == 2
    assert "bad.toml: label 'squat1Reps' maps to 'crouch'" in capsys.readouterr().err


def test_a_dataset_built_before_split_modes_still_works(
    built: Path, corpus: Path, tmp_path: Path, capsys
) -> None:
    from grip.kinematics.dataset import split_files

    out = tmp_path / "old"
    shutil.copytree(built, out)
    # as the build wrote them before: no split mode, labels or groups; clip groups in the split
    manifest = json.loads((out / "manifest.json").read_text())
    del manifest["config"]["split_by"]
    for c in manifest["clips"]:
        del c["label"], c["group"]
    (out / "manifest.json").write_text(json.dumps(manifest))
    for p in (out / "done").glob("*.json"):
        d = json.loads(p.read_text())
        del d["label"], d["group"]
        p.write_text(json.dumps(d))
    settings = json.loads((out / "settings.json").read_text())
    del settings["split_by"]
    (out / "settings.json").write_text(json.dumps(settings))
    from grip.dataset.build import ClipResult, dataset_split

    old = dataset_split([ClipResult(**c) for c in manifest["clips"]], 0.2, 42, "clip")
    for key in ("split_by", "members", "sources"):
        del old[key]
    (out / "split.json").write_text(json.dumps(old))
    capsys.readouterr()
    assert main(["data", "info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "split by clip" in text and "| train |" in text
    assert len(split_files(out, "test")) == len(old["test"])
    assert _build(out, corpus) == 0  # resumes: relabelled (labels added), split by person
    split = json.loads((out / "split.json").read_text())
    assert split["split_by"] == "person" and "hdm05/bd" in split["members"]
    assert "0 built in this run" in capsys.readouterr().out


def test_fold_models_train_on_the_other_people_and_score_their_own(built: Path, tmp_path: Path,
                                                                   capsys) -> None:  # fmt: skip
    """``train.val_source=fold``: each fold model validates on the training people of its fold,
    and ``grip kin eval --split held-out`` scores exactly those people's segments."""
    from grip.kinematics.dataset import dataset_groups, group_fold, sequence_group

    small = ["--threads", "1", "--set", "hidden=16", "--set", "layers=1", "--set",
             "init_hidden=8", "--set", "train.window_frames=30", "--set", "train.batch_size=2",
             "--set", "train.steps_per_epoch=1", "--set", "train.stage_epochs=0",
             "--set", "train.joint_epochs=1", "--set", "train.val_windows=2",
             "--set", "train.val_source=fold", "--set", "train.seed=1"]  # fmt: skip
    groups = dataset_groups(built)
    split = json.loads((built / "split.json").read_text())
    stems = sorted(split["train"])
    for k in (0, 1):
        run = tmp_path / f"fold{k}"
        assert main(["kin", "train", "--data", str(built), "--out", str(run), *small,
                     "--set", f"train.fold={k}"]) == 0  # fmt: skip
        held = [s for s in stems if group_fold(sequence_group(s, groups), 2, 1) == k]
        assert f"{len(stems) - len(held)} train / {len(held)} validation (fold {k} of 2)" in \
            capsys.readouterr().out
        js = tmp_path / f"held{k}.json"
        assert main(["kin", "eval", "--model", str(run / "last.pt"), "--data", str(built),
                     "--split", "held-out", "--segment-frames", "100000",
                     "--json", str(js)]) == 0  # fmt: skip
        assert json.loads(js.read_text())["segments"] == len(held)  # one per file
    assert main(["kin", "eval", "--data", str(built), "--split", "held-out"]) == 2
    assert "needs a fold model" in capsys.readouterr().err
