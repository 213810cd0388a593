"""``--batch N`` (segments or recordings played side by side) on ``grip policy eval``,
``grip bench`` and ``grip reconstruct``: the same rows as one after another, in the same order."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from grip.cli.main import main

LENGTHS = {"take0": 230, "take1": 120, "take2": 160}  # the takes of walk_takes (conftest.py)


@pytest.fixture(scope="module")
def dataset(walk_takes) -> Path:
    return walk_takes


def test_policy_eval_batch(dataset: Path, tmp_path: Path) -> None:
    base = ["policy", "eval", "--data", str(dataset), "--segment-frames", "60"]
    rows = {}
    for batch in (1, 4):
        out = tmp_path / f"b{batch}"
        assert main([*base, "--batch", str(batch), "--out", str(out)]) == 0
        rows[batch] = (out / "segments.csv").read_text().splitlines()
    assert len(rows[4]) == len(rows[1]) == 1 + 230 // 60 + 120 // 60 + 160 // 60
    names = [[r.split(",")[0] for r in rows[b]] for b in (1, 4)]
    assert names[0] == names[1]  # one row per segment, in order
    assert main([*base, "--batch", "0"]) == 2


def test_bench_grip_batch(dataset: Path, tmp_path: Path) -> None:
    base = ["bench", "--data", str(dataset), "--methods", "grip", "--segment-frames", "60",
            "--workers", "1", "--segments", "3"]  # fmt: skip
    got = {}
    for batch in (1, 3):
        out = tmp_path / f"b{batch}"
        assert main([*base, "--batch", str(batch), "--out", str(out)]) == 0
        got[batch] = json.loads((out / "results.json").read_text())["grip"]
    assert got[3]["segments"] == got[1]["segments"] == 3 and got[3]["failed"] == 0
    assert main([*base, "--batch", "0", "--out", str(tmp_path / "x")]) == 2


def test_reconstruct_batch(dataset: Path, tmp_path: Path) -> None:
    files = sorted(str(p) for p in (dataset / "sequences").glob("*.npz"))
    out = {}
    for batch in (1, 2):
        out[batch] = tmp_path / f"b{batch}"
        assert main(["reconstruct", *files, "--out", str(out[batch]), "--batch",
                     str(batch)]) == 0  # fmt: skip
    s1, s2 = (json.loads((out[b] / "summary.json").read_text()) for b in (1, 2))
    assert [r["file"] for r in s2["recordings"]] == [r["file"] for r in s1["recordings"]]
    assert [r["frames"] for r in s2["recordings"]] == list(LENGTHS.values())
    for name in LENGTHS:
        with np.load(out[1] / f"{name}.npz") as a, np.load(out[2] / f"{name}.npz") as b:
            assert a["joint_pos"].shape == b["joint_pos"].shape
    assert main(["reconstruct", files[0], "--out", str(tmp_path / "m"), "--batch", "0"]) == 2
