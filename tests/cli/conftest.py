"""Fixtures of the command-line tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from grip.cli.main import main

MOTIONS = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "motions"
"""The shared motion clips (absent on a machine without the shared data)."""


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> Path:
    """``grip data build`` of three DeepMimic clips, two of them in test, built once per test
    module (the per-clip split: test_data_cli.py and test_policy_train_cli.py rely on a training
    split of one clip; the split by person is tested in test_data_split_cli.py, with its own
    ``built``)."""
    out = tmp_path_factory.mktemp("ds") / "dataset"
    rc = main(["data", "build", "--out", str(out), "--motions", str(MOTIONS / "deepmimic"),
               "--limit", "3", "--workers", "1", "--test-fraction", "0.34",
               "--split-by", "clip"])  # fmt: skip
    assert rc == 0
    return out
