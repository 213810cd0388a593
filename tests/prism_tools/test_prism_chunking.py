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
