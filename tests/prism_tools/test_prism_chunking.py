"""Tests for prism_tools.chunking: chunks, segments and split files."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from prism_tools import chunk_recording, make_split, validate
from prism_tools.chunking import load_split, save_split, segments
from prism_tools.synthetic import make_recording


def test_chunk_counts_and_names() -> None:
    rec = make_recording(2500, seed=2)
    rec = dataclasses.replace(
        rec,
        data_info=dataclasses.replace(
            rec.data_info, synth_imu_frames={"L_Wrist": np.array([10, 1500, 2400])}
        ),
    )
    chunks = chunk_recording(rec)
    assert [c.n_frames for c in chunks] == [1000, 1000]
    assert [c.extras["chunk_id"] for c in chunks] == [
        "subj002_take002_seq000",
        "subj002_take002_seq001",
    ]
    assert [c.name for c in chunks] == [c.extras["chunk_id"] for c in chunks]
    assert chunks[1].extras["chunk_start_frame"] == 1000
    assert chunks[1].take_name == "subj002_take002"
    assert chunks[1].category == "walk"
    np.testing.assert_array_equal(
        chunks[1].imu["Head"].acc_world_raw, rec.imu["Head"].acc_world_raw[1000:2000]
    )
    np.testing.assert_array_equal(chunks[0].data_info.synth_imu_frames["L_Wrist"], [10])
    np.testing.assert_array_equal(chunks[1].data_info.synth_imu_frames["L_Wrist"], [500])
    for c in chunks:
        validate(c)
    assert "chunk_id" not in rec.extras  # the parent is untouched

    tails = chunk_recording(rec, min_length=500)
    assert [c.n_frames for c in tails] == [1000, 1000, 500]
    assert len(chunk_recording(rec, min_length=501)) == 2
    assert [c.n_frames for c in chunk_recording(rec, 1000, min_length=1)] == [1000, 1000, 500]
    assert chunk_recording(make_recording(999, seed=0)) == []


def test_segments() -> None:
    assert segments(1000) == [slice(0, 500), slice(500, 1000)]
    assert segments(1200) == [slice(0, 500), slice(500, 1000), slice(1000, 1200)]
    assert segments(1200, min_length=500) == [slice(0, 500), slice(500, 1000)]
    assert segments(0) == []
    with pytest.raises(ValueError):
        segments(10, 0)
    # overlapping windows: a start every 100 frames, whole 500-frame windows only
    full = segments(1000, 500, min_length=500, stride=100)
    assert [(s.start, s.stop) for s in full] == [(k, k + 500) for k in range(0, 501, 100)]
    assert segments(1000, 500, stride=500) == segments(1000, 500)
    with pytest.raises(ValueError, match="stride"):
        segments(10, 5, stride=-1)


def _ids(n_takes: int = 30, n_chunks: int = 5) -> list[str]:
    return [f"subj{s:03d}_take{t:03d}_seq{c:03d}" for s in range(1, 4) for t in range(n_takes // 3)
            for c in range(n_chunks)]  # fmt: skip


def test_split_is_deterministic_and_honours_train_only() -> None:
    ids = _ids()
    forced = ids[:7]
    a = make_split(ids, seed=42, train_only=forced)
    b = make_split(list(reversed(ids)), seed=42, train_only=forced)
    assert a == b
    assert make_split(ids, seed=1, train_only=forced)["test"] != a["test"]
    assert set(a["train"]) | set(a["test"]) == set(ids)
    assert not set(a["train"]) & set(a["test"])
    assert set(forced) <= set(a["train"])
    assert len(a["test"]) == int(np.ceil(0.2 * (len(ids) - len(forced))))
    assert a["train"] == sorted(a["train"]) and a["test"] == sorted(a["test"])
    json.dumps(a)  # JSON-ready


def test_split_matches_prism_counts() -> None:
    ids = [f"c{i:04d}" for i in range(1275)]
    split = make_split(ids, train_only=ids[:5])
    assert (len(split["train"]), len(split["test"])) == (1021, 254)
    stats = split["stats"]
    assert stats["train"]["n_chunks"] == 1021 and stats["train"]["n_frames"] == 1021000
    assert stats["total"]["n_chunks"] == 1275


def test_split_stats_categories() -> None:
    ids = _ids()
    cats = {i: ("walk" if i.endswith("0") else "jump") for i in ids}
    split = make_split(ids, categories=cats, frames_per_chunk=500)
    for name in ("train", "test"):
        st = split["stats"][name]
        assert sum(st["categories"].values()) == st["n_chunks"] == len(split[name])
        assert st["n_frames"] == 500 * st["n_chunks"]
        assert set(st["categories"]) <= {"walk", "jump"}
    assert make_split(ids)["stats"]["train"]["categories"] == {
        "unknown": len(make_split(ids)["train"])
    }


def test_split_errors() -> None:
    with pytest.raises(ValueError, match="duplicate"):
        make_split(["a", "a"])
    with pytest.raises(ValueError, match="not in chunk_ids"):
        make_split(["a", "b"], train_only=["c"])


def test_save_load_split(tmp_path: Path) -> None:
    split = make_split(_ids(), train_only=_ids()[:3])
    path = tmp_path / "split.json"
    save_split(split, path)
    assert load_split(path) == split
    assert [p.name for p in tmp_path.iterdir()] == ["split.json"]
    (tmp_path / "bad.json").write_text('{"train": ["a"], "test": ["a"]}')
    with pytest.raises(ValueError, match="both train and test"):
        load_split(tmp_path / "bad.json")
    (tmp_path / "broken.json").write_text('{"train": [')
    with pytest.raises(ValueError, match=r"broken\.json: not a valid split JSON"):
        load_split(tmp_path / "broken.json")


# ------------------------------------------------------------------------- stratified split
def _grouped(sizes: dict[str, int]) -> tuple[list[str], dict[str, str], dict[str, str]]:
    """Chunk ids, chunk -> group and group -> stratum for groups ``"<stratum>/<name>"``."""
    ids, groups = [], {}
    for g, n in sizes.items():
        for k in range(n):
            ids.append(f"{g.replace('/', '__')}_seq{k:03d}")
            groups[ids[-1]] = g
    return ids, groups, {g: g.rsplit("/", 1)[0] for g in sizes}


# Roughly the shared corpus: 4 HDM05 actors, 7 + 15 Bandai styles, CMU subjects of very
# different sizes, one-clip DeepMimic groups, and a source of one group.
_HDM = dict(zip(("bd", "bk", "dg", "mm"), (52, 52, 47, 40), strict=True))
_BANDAI2 = dict(zip("abcdefg", (173, 106, 140, 134, 132, 113, 132), strict=True))
_CMU = dict(zip((2, 5, 6, 7, 8, 9, 10, 12, 13, 14), (3, 3, 1, 2, 3, 2, 2, 2, 25, 16), strict=True))
CORPUS = {
    **{f"hdm05/{a}": n for a, n in _HDM.items()},
    **{f"bandai2/{s}": n for s, n in _BANDAI2.items()},
    **{f"bandai1/s{k:02d}": 7 + (k == 0) * 6 for k in range(15)},
    **{f"cmu/{s:02d}": n for s, n in _CMU.items()},
    **{f"deepmimic/clip{k}": 1 for k in range(14)},
    "solo/only": 9,
}


def test_stratified_split_keeps_groups_whole_and_every_source_on_both_sides() -> None:
    ids, groups, strata = _grouped(CORPUS)
    split = make_split(ids, 0.2, seed=42, groups=groups, strata=strata)
    train_g, test_g = set(split["groups"]["train"]), set(split["groups"]["test"])
    assert not train_g & test_g and train_g | test_g == set(CORPUS)
    for chunk in split["test"]:
        assert groups[chunk] in test_g  # whole groups: every chunk of a test group is in test
    for stratum in {s for s in strata.values() if s != "solo"}:
        mine = {g for g in CORPUS if strata[g] == stratum}
        assert mine & train_g and mine & test_g, stratum
        share = sum(CORPUS[g] for g in mine & test_g) / sum(CORPUS[g] for g in mine)
        big = max(CORPUS[g] for g in mine) / sum(CORPUS[g] for g in mine)
        assert abs(share - 0.2) <= max(0.05, big / 2), (stratum, share)  # as near as sizes allow
    assert "solo/only" in train_g  # a source of one group cannot be split: it trains
    overall = len(split["test"]) / len(ids)
    assert abs(overall - 0.2) < 0.03
    assert split["stats"]["test"]["n_chunks"] == len(split["test"])


def test_stratified_split_is_deterministic_and_order_free() -> None:
    ids, groups, strata = _grouped(CORPUS)
    a = make_split(ids, 0.2, seed=7, groups=groups, strata=strata)
    assert make_split(list(reversed(ids)), 0.2, seed=7, groups=groups, strata=strata) == a
    others = {tuple(make_split(ids, 0.2, seed=s, groups=groups, strata=strata)["groups"]["test"])
              for s in range(8)}  # fmt: skip
    assert len(others) > 1  # the seed chooses among near-equal options
    none = make_split(ids, 0.0, seed=7, groups=groups, strata=strata)
    assert none["test"] == [] and none["groups"]["test"] == []


def test_stratified_split_of_two_unequal_groups_picks_the_nearer_one() -> None:
    from prism_tools.chunking import stratified_test_groups

    sizes = {"s/big": 90, "s/small": 10, "t/x": 5, "t/y": 5, "t/z": 5, "t/w": 5}
    strata = {g: g.split("/")[0] for g in sizes}
    for seed in range(5):
        test = stratified_test_groups(sizes, strata, 0.2, seed)
        assert "s/small" in test and "s/big" not in test
        assert sum(g.startswith("t/") for g in test) == 1  # 5 of 20 is nearest to 4
    # 0 and 1: everything on one side (grip data build --test-fraction 0|1), single-group
    # strata included
    assert stratified_test_groups(sizes | {"u/alone": 3}, strata | {"u/alone": "u"}, 0.0, 0) == []
    assert stratified_test_groups(sizes | {"u/alone": 3}, strata | {"u/alone": "u"}, 1.0, 0) \
        == sorted([*sizes, "u/alone"])  # fmt: skip
    with pytest.raises(ValueError, match="strata need groups"):
        make_split(["a"], strata={"a": "s"})


def test_named_test_groups_go_to_test_and_count_toward_the_fraction() -> None:
    ids = [f"c{i}" for i in range(20)]
    groups = {c: f"g{int(c[1:]) // 2}" for c in ids}  # ten groups of two chunks
    split = make_split(ids, 0.2, 0, groups=groups, test_groups=["g7"])
    assert "g7" in split["groups"]["test"] and {"c14", "c15"} <= set(split["test"])
    assert len(split["test"]) == 4  # g7 and one drawn group make the 20 %
    strata = {f"g{k}": "a" if k < 5 else "b" for k in range(10)}
    split = make_split(ids, 0.2, 0, groups=groups, strata=strata, test_groups=["g0"])
    assert "g0" in split["groups"]["test"] and any(g in split["groups"]["test"]
                                                   for g in ("g5", "g6", "g7", "g8", "g9"))
    with pytest.raises(ValueError, match="not groups"):
        make_split(ids, 0.2, 0, groups=groups, test_groups=["nope"])
    with pytest.raises(ValueError, match="need groups"):
        make_split(ids, 0.2, 0, test_groups=["g0"])
