"""Run folders written before settings were removed still resume, unless they used one."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from grip.cli.main import main


def _with_settings(run: Path, tmp_path: Path, **ppo) -> Path:
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    cfg_path = copy / "config.json"
    d = json.loads(cfg_path.read_text())
    d["config"]["ppo"].update(ppo)
    cfg_path.write_text(json.dumps(d))
    return copy


@pytest.mark.parametrize(("ppo", "ok"), [({"fixed_std": False, "target_kl": 0.0}, True),
                                         ({"target_kl": 0.05}, False)])  # fmt: skip
def test_a_run_recorded_with_removed_settings(tiny_policy_run, tiny_policy_settings, tmp_path,
                                              capsys, ppo, ok) -> None:  # fmt: skip
    data, run = tiny_policy_run
    old = _with_settings(run, tmp_path, **ppo)
    argv = ["policy", "train", "--data", str(data), "--out", str(old), *tiny_policy_settings,
            "--set", "stage2.timesteps=128"]  # fmt: skip
    rc = main(argv)
    err = capsys.readouterr().err
    if ok:  # removed settings at their "off" values: the run resumes
        assert rc == 0, err
    else:  # one that was on cannot be reproduced: refused, naming it and the commit
        assert rc == 2 and "ppo.target_kl" in err and "42da3e6" in err, err
