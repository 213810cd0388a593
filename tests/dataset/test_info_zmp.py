"""``grip data info``: the share of ZMP-outside frames per source, from a manifest's clips."""

from __future__ import annotations

import json
from pathlib import Path

from grip.dataset.info import clip_source, dataset_summary, format_summary, zmp_outside_by_source
from prism_tools.synth.recording import ZMP_OUTSIDE_M


def _clip(clip_id: str, group: str | None, synth: int, outside: int, status: str = "done") -> dict:
    c = {
        "clip_id": clip_id,
        "status": status,
        "category": "walk",
        "sequences": ["s"],
        "sequence_frames": [synth],
        "synth_frames": synth,
        "zmp_outside_frames": outside,
    }
    if group is not None:
        c["group"] = group
    return c


def _write(root: Path, clips: list[dict]) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    (root / "manifest.json").write_text(json.dumps({"config": {}, "clips": clips}))
    return root


def test_clip_source_from_group_else_clip_id() -> None:
    assert clip_source({"clip_id": "hdm05/x", "group": "hdm05/bd"}) == "hdm05"
    assert (
        clip_source(
            {
                "clip_id": "bandai_namco/dataset-2_walk_active_001",
                "group": "bandai_namco/dataset-2/active",
            }
        )
        == "bandai_namco/dataset-2"
    )
    assert clip_source({"clip_id": "cmu/02_01", "group": ""}) == "cmu"
    assert clip_source({"clip_id": "cmu/02_01"}) == "cmu"  # manifest without groups


def test_share_per_source_in_summary_and_table(tmp_path: Path) -> None:
    clips = [
        _clip("cmu/02_01", "cmu/02", 100, 30),
        _clip("cmu/07_04", "cmu/07", 300, 10),
        _clip("hdm05/a", "hdm05/bd", 200, 100),
        _clip("hdm05/b", "hdm05/dg", 50, 50, status="failed"),  # failed clips do not count
        _clip("deepmimic/walk", "deepmimic/walk", 0, 0),
    ]
    s = dataset_summary(_write(tmp_path / "d", clips))
    by = s["insole_zmp_outside_by_source"]
    assert list(by) == ["cmu", "deepmimic", "hdm05"]
    assert by["cmu"] == {"clips": 2, "synth_frames": 400, "zmp_outside_frames": 40, "fraction": 0.1}
    assert by["hdm05"]["fraction"] == 0.5
    assert by["deepmimic"]["fraction"] is None
    assert abs(s["insole_zmp_outside_fraction"] - 140 / 600) < 1e-12
    text = format_summary(s)
    assert f"ZMP outside the insole cells per source (> {100 * ZMP_OUTSIDE_M:g} cm" in text
    assert "| cmu | 2 | 400 | 40 | 10.0 % |" in text
    assert "| hdm05 | 1 | 200 | 100 | 50.0 % |" in text
    assert "| deepmimic | 1 | 0 | 0 | - |" in text
    # The headline share and the table name the same threshold as the synthesis counts with.
    assert f"ZMP lies > {100 * ZMP_OUTSIDE_M:g} cm outside" in text


def test_manifest_without_groups_or_counts(tmp_path: Path) -> None:
    old = [
        {
            "clip_id": "cmu/02_01",
            "status": "done",
            "category": "walk",
            "sequences": ["s"],
            "sequence_frames": [10],
        }
    ]
    s = dataset_summary(_write(tmp_path / "old", old))
    assert s["insole_zmp_outside_by_source"] == {
        "cmu": {"clips": 1, "synth_frames": 0, "zmp_outside_frames": 0, "fraction": None}
    }
    assert "| cmu | 1 | 0 | 0 | - |" in format_summary(s)
    empty = dataset_summary(_write(tmp_path / "empty", []))
    assert zmp_outside_by_source([]) == {}
    assert "per source" not in format_summary(empty)


def test_info_lists_the_props_per_source(tmp_path) -> None:
    stairs = _clip("cmu/14_21", "cmu/14", 1000, 100)
    stairs["props"] = [{"kind": "step", "height_m": 0.216}, {"kind": "step", "height_m": 0.391}]
    stool = _clip("cmu/14_31", "cmu/14", 1000, 100)
    stool["props"] = [{"kind": "seat", "height_m": 0.356}]
    root = _write(tmp_path / "d", [stairs, stool, _clip("cmu/07_05", "cmu/07", 500, 50)])
    s = dataset_summary(root)
    assert s["props"]["clips"] == 2 and s["props"]["props"] == 3
    assert s["props"]["by_source"] == {"cmu": {"clips": 2, "steps": 2, "seats": 1}}
    text = format_summary(s)
    assert "| cmu | 2 | 2 | 1 |" in text
    assert "- cmu/14_21: step 0.22 m, step 0.39 m" in text and "cmu/07_05" not in text
    flat = format_summary(dataset_summary(_write(tmp_path / "f", [_clip("a/b", None, 10, 1)])))
    assert "Props" not in flat


def test_the_plot_draws_the_props(tmp_path) -> None:
    import dataclasses

    from grip.dataset.plot import plot_recording
    from prism_tools.streams import box_object
    from prism_tools.synthetic import make_recording

    box = box_object([0.5, 0.0, 0.2], [0.4, 0.3, 0.4])
    rec = dataclasses.replace(make_recording(60, seed=0), objects={"prop_00": box})
    out = plot_recording(rec, tmp_path / "r.png")
    assert out.is_file() and out.stat().st_size > 10_000
