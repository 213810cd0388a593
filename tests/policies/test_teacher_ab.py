"""benchmarks/teacher_ab.py: ``--stage2`` trains the recipe's stage 2 after stage 1."""

from __future__ import annotations

from envs.tracking_env import SAMPLE_REFERENCE
from tests.cli.test_data_cli import _benchmark
from tests.policies.test_train_profile import TINY

P = _benchmark("teacher_ab")


def test_stage2_follows_stage1(tmp_path):
    out = tmp_path / "ab"
    sets = [a for t in TINY for a in ("--set", t)] + ["--set", "checkpoint_every=1"]
    assert P.main(["train", "--out", str(out), "--reference", str(SAMPLE_REFERENCE),
                   "--decisions", "64", "--stage2", "128", *sets]) == 0  # fmt: skip
    stages = [row["stage"] for row in P.history(out)]
    assert stages[0] == "stage1" and stages[-1] == "stage2"
    assert P.history(out)[-1]["timesteps"] == 192
