"""The shared evaluation pieces: one segment lister (stride, limit, short tails), one in-process
runner, one aggregation and table writer, and ``grip kin eval``'s report over segment rows."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from grip.eval import report
from grip.eval.runner import play_segments
from grip.eval.segments import BenchError, list_segments, split_files
from prism_tools.chunking import make_split, save_split
from prism_tools.io import save_recording
from prism_tools.synthetic import make_recording


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> list[Path]:
    root = tmp_path_factory.mktemp("h")
    out = []
    for i, (n, cat) in enumerate(((250, "walk"), (125, "run"))):
        rec = make_recording(n, seed=i)
        rec = dataclasses.replace(rec, extras={**rec.extras, "take_name": f"t{i}",
                                               "category": cat})  # fmt: skip
        out.append(root / "sequences" / f"t{i}.npz")
        save_recording(rec, out[-1])
    save_split(make_split(["t0", "t1"], test_fraction=0.5), root / "split.json")
    return out


def test_segments_stride_limit_and_short_tails(files) -> None:
    plain = list_segments(files, 100)
    assert [(s.path.stem, s.start, s.stop) for s in plain] == [
        ("t0", 0, 100), ("t0", 100, 200), ("t1", 0, 100)]  # fmt: skip
    tails = list_segments(files, 100, min_frames=10)
    assert [(s.start, s.stop) for s in tails if s.path.stem == "t0"][-1] == (200, 250)
    assert [(s.start, s.stop) for s in tails if s.path.stem == "t1"][-1] == (100, 125)
    assert len(list_segments(files, 100, stride=50)) == 4 + 1
    assert [s.id for s in list_segments(files, 100, limit=2)] == [s.id for s in plain[:2]]
    assert {s.category for s in list_segments(files, 100, ["r*"])} == {"run"}
    with pytest.raises(BenchError, match="no 300-frame segment"):
        list_segments(files, 300)


def test_holdout_split_is_the_held_training_files(files) -> None:
    data = files[0].parents[1]
    train = split_files(data, "train")
    held = split_files(data, "holdout", {train[0].stem})
    assert held == train[:1] and split_files(data, "holdout", ()) == []


def test_play_segments_batches_in_order_with_segment_keys(files) -> None:
    segs = list_segments(files, 100)
    seen: list[int] = []

    def score(recs):
        seen.append(len(recs))
        return [{"n": r.n_frames, "category": "x"} for r in recs]

    done: list[int] = []
    rows = play_segments(segs, score, batch=2, progress=done.append)
    assert seen == [2, 1] and done == [2, 1]
    assert [r["segment"] for r in rows] == [s.id for s in segs]
    assert rows[0]["frames"] == rows[0]["n"] == 100 and rows[0]["category"] == "x"


def test_weighted_means_categories_and_tables() -> None:
    rows = [{"category": "b", "frames": 1, "e": 1.0}, {"category": "a", "frames": 3, "e": 3.0},
            {"category": "a", "frames": 1, "e": float("nan")}]  # fmt: skip
    assert report.weighted_means(rows, ["e"])["e"] == pytest.approx(2.5)
    assert np.isnan(report.weighted_means(rows, ["e"], skip_nan=False)["e"])
    s = report.category_summary(rows, lambda rs: {"n": len(rs)})
    assert s == {"overall": {"n": 3}, "categories": {"a": {"n": 2}, "b": {"n": 1}}}
    assert report.markdown_table(["k", "v"], [["x", report.cell(float("nan"), "{:.1f}")]]) == (
        "| k | v |\n|---|---:|\n| x | n/a |")
    spread = report.replay_spread([[{"fell": False}], [{"fell": True}]])
    assert spread["success_rate_replays"] == [100.0, 0.0] and spread["success_rate_mean"] == 50


def test_kin_eval_over_segments_matches_recordings(files) -> None:
    from grip.assets import SHIPPED_KIN
    from grip.eval.kinematics import MIN_SEGMENT_FRAMES, aggregate, evaluate_segments
    from grip.kinematics.evaluate import evaluate_recordings
    from grip.kinematics.inference import KinematicsEstimator
    from prism_tools.io import load_recording

    est = KinematicsEstimator.from_checkpoint(SHIPPED_KIN)
    segs = list_segments(files, 100, min_frames=MIN_SEGMENT_FRAMES)
    rows = evaluate_segments(est, segs)
    old = evaluate_recordings(est, [load_recording(f) for f in files], 100)

    def comparable(x):  # NaN (no settled frames in a 1 s segment) equals NaN here
        if isinstance(x, dict):
            return {k: comparable(v) for k, v in x.items()}
        return "nan" if isinstance(x, float) and x != x else x

    assert comparable(aggregate(rows)) == comparable(aggregate(old))
