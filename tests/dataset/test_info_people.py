"""``grip data info``: people (split groups) per category and split, from manifest and split."""

from __future__ import annotations

import json
from pathlib import Path

from grip.cli.main import main
from grip.dataset.info import dataset_summary, format_summary, people_per_category


def _clip(clip_id: str, group: str | None, category: str, n_seq: int = 1,
          status: str = "done") -> dict:  # fmt: skip
    c = {"clip_id": clip_id, "status": status, "category": category,
         "sequences": [f"{clip_id}_{k}" for k in range(n_seq)],
         "sequence_frames": [1000] * n_seq}  # fmt: skip
    if group is not None:
        c["group"] = group
    return c


CLIPS = [
    _clip("cmu/06_06", "cmu/06", "walk-back"),
    _clip("cmu/06_07", "cmu/06", "walk-back"),  # the same person twice: counted once
    _clip("ase/WalkLeft02", "ase/reallusion", "walk-back"),
    _clip("ase/WalkRight02", "ase/reallusion", "walk"),
    _clip("cmu/02_01", "cmu/02", "walk"),
    _clip("cmu/08_04", "cmu/08", "walk"),
    _clip("hdm05/short_hop", "hdm05/bd", "jump", n_seq=0),  # no sequence: nowhere
    _clip("hdm05/broken", "hdm05/dg", "jump", status="failed"),
]
SPLIT = {
    "split_by": "person",
    "groups": {"train": ["ase/reallusion", "cmu/02", "cmu/06"], "test": ["cmu/08"]},
    "members": {"ase/reallusion": ["ase/WalkLeft02", "ase/WalkRight02"], "cmu/02": ["cmu/02_01"],
                "cmu/06": ["cmu/06_06", "cmu/06_07"], "cmu/08": ["cmu/08_04"]},
    "stats": {"train": {"n_chunks": 5, "n_frames": 5000, "categories": {"walk": 2,
                                                                        "walk-back": 3}},
              "test": {"n_chunks": 1, "n_frames": 1000, "categories": {"walk": 1}}},
}  # fmt: skip


def test_people_per_category_counts_performers_not_clips() -> None:
    assert people_per_category(CLIPS, SPLIT) == {
        "walk": {"train": ["ase/reallusion", "cmu/02"], "test": ["cmu/08"]},
        "walk-back": {"train": ["ase/reallusion", "cmu/06"], "test": []},
    }


def test_a_split_by_clip_can_put_one_person_on_both_sides() -> None:
    by_clip = {"groups": {"train": ["cmu/06_06"], "test": ["cmu/06_07"]}}  # no members
    assert people_per_category(CLIPS, by_clip) == {
        "walk-back": {"train": ["cmu/06"], "test": ["cmu/06"]}}  # fmt: skip
    assert people_per_category(CLIPS, {"train": ["x"], "test": []}) == {}  # no groups recorded


def test_info_prints_and_writes_people_per_category(tmp_path: Path, capsys) -> None:
    root = tmp_path / "ds"
    root.mkdir()
    (root / "manifest.json").write_text(json.dumps({"config": {}, "clips": CLIPS}))
    (root / "split.json").write_text(json.dumps(SPLIT))
    s = dataset_summary(root)
    assert s["split_people"]["walk"] == {"train": ["ase/reallusion", "cmu/02"],
                                         "test": ["cmu/08"]}  # fmt: skip
    text = format_summary(s)
    assert "| category | train sequences | test sequences | train people | test people |" in text
    assert "| walk | 2 | 1 | 2 | 1 |" in text and "| walk-back | 3 | 0 | 2 | 0 |" in text
    js = tmp_path / "info.json"
    assert main(["data", "info", str(root), "--json", str(js)]) == 0
    assert "| walk-back | 3 | 0 | 2 | 0 |" in capsys.readouterr().out
    assert json.loads(js.read_text())["split_people"]["walk-back"]["train"] == [
        "ase/reallusion", "cmu/06"]  # fmt: skip
