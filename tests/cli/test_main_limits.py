"""``--input-limit`` holds for one command: a process that runs several keeps its own limits."""

from __future__ import annotations

import os

from grip.cli import main as cli_main
from grip.core.limits import LIMITS_ENV


def test_input_limit_does_not_outlive_its_command(tmp_path, monkeypatch) -> None:
    assert cli_main.LIMITS_ENV == LIMITS_ENV
    monkeypatch.delenv(LIMITS_ENV, raising=False)
    cli_main.main(["data", "info", str(tmp_path), "--input-limit", "max_duration_s=1"])
    assert LIMITS_ENV not in os.environ
    monkeypatch.setenv(LIMITS_ENV, "max_fps=500")
    cli_main.main(["data", "info", str(tmp_path), "--input-limit", "max_duration_s=1"])
    assert os.environ[LIMITS_ENV] == "max_fps=500"
