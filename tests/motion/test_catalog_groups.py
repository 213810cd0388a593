"""Clip labels, shared categories (``configs/categories.toml``) and split groups of the catalog."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from grip.assets import REPO_ROOT
from grip.motion.catalog import (
    CategoryMap,
    clip_group,
    clip_person,
    clip_ref,
    find_clips,
    load_category_map,
)

DATA = REPO_ROOT.parent / "shared" / "data" / "motions"
CATEGORIES = REPO_ROOT / "configs" / "categories.toml"

# A BVH of one joint and two frames: enough for the catalog (it never parses motion data).
BVH = """HIERARCHY
ROOT Hips
{
\tOFFSET 0 0 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tEnd Site
\t{
\t\tOFFSET 0 50 0
\t}
}
MOTION
Frames: 2
Frame Time: 0.01
0 90 0 0 0 0
0 90 0 0 0 0
"""


@pytest.fixture(scope="module")
def cmap() -> CategoryMap:
    return load_category_map(CATEGORIES)


@pytest.mark.parametrize(
    ("clip_id", "stem", "person", "group"),
    [
        ("hdm05/HDM_bd_squat1Reps_001_120", "HDM_bd_squat1Reps_001_120", "bd", "hdm05/bd"),
        ("hdm05/HDM_mm_lieDownFloor_015_120", "HDM_mm_lieDownFloor_015_120", "mm", "hdm05/mm"),
        ("cmu/02_01", "02_01", "02", "cmu/02"),
        ("cmu/14_32", "14_32", "14", "cmu/14"),
        ("bandai_namco/dataset-2_run_active_001", "dataset-2_run_active_001", "",
         "bandai_namco/dataset-2/active"),
        ("bandai_namco/dataset-1_walk-back_not-confident_001",
         "dataset-1_walk-back_not-confident_001", "", "bandai_namco/dataset-1/not-confident"),
        ("bandai_namco/dataset-2_walk-turn-left_youthful_030",
         "dataset-2_walk-turn-left_youthful_030", "", "bandai_namco/dataset-2/youthful"),
        ("deepmimic/getup_faceup", "humanoid3d_getup_faceup", "", "deepmimic/getup_faceup"),
        ("mocap/my_take", "my_take", "", "mocap/my_take"),
    ],
)  # fmt: skip
def test_person_and_group_from_file_names(clip_id: str, stem: str, person: str,
                                          group: str) -> None:  # fmt: skip
    assert clip_person(stem) == person
    assert clip_group(clip_id, stem, clip_person(stem)) == group


def test_a_clips_csv_person_column_wins() -> None:
    assert clip_person("HDM_bd_squat1Reps_001_120", {"person": " alice "}) == "alice"
    assert clip_person("02_01", {"person": ""}) == "02"  # empty: the file name decides
    assert clip_group("mocap/walk_03", "walk_03", "alice") == "mocap/alice"


def test_category_map_translates_labels(cmap: CategoryMap) -> None:
    cases = {
        "walk-turn-left": "walk-turn",  # Bandai Namco content labels
        "dash": "run",
        "walk-left": "walk-side",
        "squat1Reps": "squat",  # HDM05 class, case-insensitive
        "SQUAT1REPS": "squat",
        "jogLeftCircle4StepsRstart": "run",
        "sit_stand (prop: low stepstool; repeated)": "sit-stand",  # CMU: the first item
        "jump_in_place; reach_up": "jump",
        "squat; jumping_jacks; calisthenics": "exercise",  # a whole label listed
        "getup_faceup": "floor",  # DeepMimic name
        "walk": "walk",
        "Walk-Back": "walk-back",  # a name of the vocabulary is itself
        "stairs (up)": "stairs",  # ... also as a first item
        "juggling": "unknown",  # not in the map
        "": "unknown",
    }
    assert {label: cmap.category(label) for label in cases} == cases
    assert "unknown" not in cmap.vocabulary
    for name in cmap.vocabulary:  # glob-friendly: lower case words joined by dashes
        assert name == name.lower() and " " not in name and "_" not in name


def test_every_label_of_the_shared_sources_has_a_category(cmap: CategoryMap) -> None:
    """The label files and clips.csv of the shared folders, read without loading any clip."""
    if not DATA.is_dir():
        pytest.skip("shared motion data not found")
    labels: set[str] = set()
    tables = sorted(DATA.rglob("clips.csv"))
    assert {t.parent.name for t in tables} >= {"cmu", "hdm05", "deepmimic", "ase_reallusion"}
    for table in tables:
        with table.open(encoding="utf-8") as fh:
            for row in csv.DictReader(fh):
                labels.add(next(row[c] for c in cmap.label_columns if row.get(c)))
    for cfg in DATA.glob("bandai_namco/**/cfg/content_label.txt"):
        labels |= {ln.strip().split("_", 1)[1] for ln in cfg.read_text().splitlines() if ln}
    labels |= {p.stem.removeprefix("humanoid3d_") for p in (DATA / "deepmimic").glob(
        "humanoid3d_*.txt") if "skeleton" not in p.name}  # fmt: skip
    unmapped = sorted(lb for lb in labels if cmap.category(lb) == "unknown")
    assert not unmapped


def test_category_map_file_errors(tmp_path: Path) -> None:
    bad = tmp_path / "c.toml"
    bad.write_text('vocabulary = ["walk"]\n[labels]\nstroll = "amble"\n')
    with pytest.raises(ValueError, match=r"c\.toml: label 'stroll' maps to 'amble'"):
        load_category_map(bad)
    bad.write_text('vocabulary = ["Walk Fast"]\n')
    with pytest.raises(ValueError, match="lower case words"):
        load_category_map(bad)
    bad.write_text('vocabulary = ["walk"]\ncolours = 1\n')
    with pytest.raises(ValueError, match="unknown key"):
        load_category_map(bad)
    bad.write_text('vocabulary = ["walk", "run"]\n[labels]\nJog = "run"\njog = "walk"\n')
    with pytest.raises(ValueError, match="mapped twice"):
        load_category_map(bad)
    bad.write_text("vocabulary = [")
    with pytest.raises(ValueError, match="not a readable TOML"):
        load_category_map(bad)
    with pytest.raises(FileNotFoundError):
        load_category_map(tmp_path / "none.toml")


def test_a_users_clips_csv_labels_and_groups_its_clips(tmp_path: Path, cmap: CategoryMap) -> None:
    root = tmp_path / "motions"
    takes = root / "lab" / "takes"
    takes.mkdir(parents=True)
    for name in ("a1", "a2", "b1", "c1", "d1"):
        (takes / f"{name}.bvh").write_text(BVH)
    (root / "lab" / "clips.csv").write_text(
        "file,category,person\n"
        "takes/a1.bvh,Walking,alice\n"
        "takes/a2.bvh,stairs (up and down),alice\n"
        "takes/b1.bvh,juggling,bob\n"
        "takes/c1.bvh,,\n"
    )  # d1 is not listed
    refs = {r.clip_id: r for r in find_clips(root, cmap)}
    got = {cid: (r.category, r.label, r.person, r.group) for cid, r in refs.items()}
    assert got == {
        "lab/a1": ("walk", "Walking", "alice", "lab/alice"),
        "lab/a2": ("stairs", "stairs (up and down)", "alice", "lab/alice"),
        "lab/b1": ("unknown", "juggling", "bob", "lab/bob"),
        "lab/c1": ("unknown", "", "", "lab/c1"),
        "lab/d1": ("unknown", "", "", "lab/d1"),
    }
    one = clip_ref(takes / "a2.bvh", cmap)  # a single file is named and grouped the same way
    assert (one.clip_id, one.category, one.group) == ("lab/a2", "stairs", "lab/alice")
    # without a map the categories stay as the labels give them
    assert {r.clip_id: r.category for r in find_clips(root)}["lab/a1"] == "walking"


def test_bandai_label_from_the_json_and_group_from_the_name(tmp_path: Path,
                                                            cmap: CategoryMap) -> None:  # fmt: skip
    ds = tmp_path / "motions" / "bandai" / "dataset-2"
    (ds / "cfg").mkdir(parents=True)
    (ds / "cfg" / "content_label.txt").write_text("dataset-2_walk\ndataset-2_walk-turn-left\n")
    (ds / "dataset-2_walk-turn-left_elderly_007.bvh").write_text(BVH)
    (ds / "dataset-2_walk-turn-left_elderly_007.json").write_text('{"content": 1, "style": 1}')
    (ds / "dataset-2_walk_normal_001.bvh").write_text(BVH)  # no JSON: no label
    refs = {r.clip_id: r for r in find_clips(tmp_path / "motions", cmap)}
    turn = refs["bandai/dataset-2_walk-turn-left_elderly_007"]
    assert (turn.label, turn.category, turn.group) == (
        "walk-turn-left", "walk-turn", "bandai/dataset-2/elderly")  # fmt: skip
    plain = refs["bandai/dataset-2_walk_normal_001"]
    assert (plain.label, plain.category, plain.group) == ("", "unknown", "bandai/dataset-2/normal")


def test_shared_corpus_groups_and_categories(cmap: CategoryMap) -> None:
    """The whole shared folder is searched (file names and labels only, about 0.5 s)."""
    if not DATA.is_dir():
        pytest.skip("shared motion data not found")
    refs = find_clips(DATA, cmap)
    assert all(r.category != "unknown" for r in refs)
    assert all(r.category in cmap.vocabulary for r in refs)
    groups: dict[str, set[str]] = {}
    for r in refs:
        groups.setdefault(r.clip_id.split("/")[0], set()).add(r.group)
    # Properties, not today's counts (the folder grows, issue 49): every clip has a group; a
    # clip whose performer is named is grouped by that performer; HDM05 and CMU by actor and
    # subject (BVH and ASF/AMC alike); Bandai Namco by dataset and style; a clip whose
    # performer nobody names is its own group.
    assert all(r.group for r in refs)
    for r in refs:
        top = r.clip_id.split("/")[0]
        if r.person:
            assert r.group == f"{top}/{r.person}", r.clip_id
    assert groups["hdm05"] == {f"hdm05/{p.name.split('_')[1]}"
                               for p in (DATA / "hdm05").rglob("HDM_*.amc")}  # fmt: skip
    cmu_files = [p for p in (DATA / "cmu").rglob("*") if p.suffix in (".bvh", ".amc")]
    assert {g.split("/")[1] for g in groups["cmu"]} == {p.stem.split("_")[0] for p in cmu_files}
    assert all(g.startswith(("bandai_namco/dataset-1/", "bandai_namco/dataset-2/"))
               and g.count("/") == 2 for g in groups["bandai_namco"])  # fmt: skip
    assert sum(g.startswith("bandai_namco/dataset-2/") for g in groups["bandai_namco"]) >= 2
    for r in refs:
        if r.clip_id.startswith("deepmimic/") and not r.person:
            assert r.group == r.clip_id
    # Performers named by a clips.csv person column: one Sony performer for the sie_* DeepMimic
    # clips, one Reallusion performer for the ASE clips (all poselib .npy files of the folder).
    sie = {r.group for r in refs if r.clip_id.startswith("deepmimic/sie_")}
    assert sie <= {"deepmimic/sie"}
    ase = [r for r in refs if r.clip_id.startswith("ase_reallusion/")]
    assert len(ase) == len(list((DATA / "ase_reallusion").glob("*.npy")))
    assert {(r.fmt, r.person, r.group) for r in ase} <= {
        ("poselib", "reallusion", "ase_reallusion/reallusion")}  # fmt: skip
    # CMU's ASF/AMC subjects are their own groups, as the BVH subjects are.
    for r in refs:
        if r.fmt == "asf_amc" and r.clip_id.startswith("cmu/"):
            assert r.group == f"cmu/{r.path.stem.split('_')[0]}", r.clip_id
    labels = {r.clip_id: r.label for r in refs}
    assert labels["hdm05/HDM_bd_squat1Reps_001_120"] == "squat1Reps"
    assert labels["bandai_namco/dataset-1_dash_active_001"] == "dash"
    assert json.dumps(sorted(cmap.vocabulary))  # plain strings


def test_clips_without_a_label_take_their_folders_name(tmp_path: Path, cmap: CategoryMap) -> None:
    """One's own clips sorted into folders by motion get categories without a clips.csv."""
    root = tmp_path / "mine"
    for rel in ("walk/subject01/t1.bvh", "Run/t2.bvh", "session/t3.bvh", "t4.bvh"):
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(BVH)
    got = {r.path.name: (r.category, r.label) for r in find_clips(root, cmap)}
    assert got == {"t1.bvh": ("walk", "walk"), "t2.bvh": ("run", "Run"),
                   "t3.bvh": ("unknown", ""), "t4.bvh": ("unknown", "")}  # fmt: skip
    # without a map a folder's name is no category (it may be "bvh" or "takes")
    assert {r.category for r in find_clips(root)} == {"unknown"}


def test_a_users_category_table_overrides_labels(tmp_path: Path, capsys,
                                                 cmap: CategoryMap) -> None:  # fmt: skip
    """``grip data build --categories FILE.csv``: clip -> category, matched by clip id, path,
    file name or stem; the map translates known names, others are kept; bad tables are named."""
    from grip.cli.data import scan_motions
    from grip.motion.catalog import load_clip_categories

    root = tmp_path / "mine"
    (root / "walk").mkdir(parents=True)
    for name in ("a", "b", "c", "d"):
        (root / "walk" / f"{name}.bvh").write_text(BVH)
    table_csv = tmp_path / "cats.csv"
    table_csv.write_text("clip,category\nwalk/a,Running\nwalk/b.bvh,sit-stand\n"
                         "c,Juggling Balls\nnowhere,walk\n")  # fmt: skip
    table = load_clip_categories(table_csv)
    clips, _ = scan_motions([root], None, cmap, table)
    got = {Path(c.path).stem: (c.category, c.label) for c in clips}
    assert got == {
        "a": ("run", "Running"),
        "b": ("sit-stand", "sit-stand"),
        "c": ("juggling-balls", "Juggling Balls"),
        "d": ("walk", "walk"),
    }
    assert "1 listed clip(s) not found" in capsys.readouterr().err
    for text, why in (("clip,label\nx,walk\n", "line 2"), ("clip,category\n", "no rows"),
                      ("clip,category\nx,walk\nx,run\n", "twice")):  # fmt: skip
        table_csv.write_text(text)
        with pytest.raises(ValueError, match=why):
            load_clip_categories(table_csv)
