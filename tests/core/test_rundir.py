"""The run folder every trainer shares: config.json, the checkpoint swap, the resume check."""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import pytest

from grip.core.checks import check, check_fields
from grip.core.rundir import RunDir
from grip.core.runs import SettingsMismatch, changed_settings, settings_diff


@dataclass(frozen=True)
class _Opt:
    lr: float = 1e-3
    arch: tuple[int, ...] = (8, 8)


@dataclass(frozen=True)
class _Cfg:
    steps: int = 10
    opt: _Opt = field(default_factory=_Opt)


def _save(run: RunDir, step: int) -> None:
    run.save_checkpoint(lambda d: (d / "w.txt").write_text(str(step)), {"step": step})


def test_config_json_records_settings_git_and_extras(tmp_path):
    run = RunDir(tmp_path / "r")
    run.write_config(_Cfg(), data="d", seed=3)
    rec = json.loads((tmp_path / "r" / "config.json").read_text())
    assert rec["config"] == {"steps": 10, "opt": {"lr": 1e-3, "arch": [8, 8]}}
    assert rec["data"] == "d" and rec["seed"] == 3 and isinstance(rec["git"], str)
    assert run.read_config() == rec
    assert RunDir(tmp_path / "none").read_config() is None


def test_checkpoint_is_swapped_whole_and_a_kill_between_renames_resumes(tmp_path):
    run = RunDir(tmp_path)
    assert run.read_state() is None and not run.has_checkpoint()
    _save(run, 1)
    _save(run, 2)
    assert run.read_state() == {"step": 2}
    assert (run.checkpoint_dir / "w.txt").read_text() == "2"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["checkpoint"]
    # killed after checkpoint/ became checkpoint.old/, before the new one was renamed in
    run.checkpoint_dir.rename(tmp_path / "checkpoint.old")
    (tmp_path / "checkpoint.tmp").mkdir()
    assert RunDir(tmp_path).read_state() == {"step": 2}
    _save(run, 3)
    assert run.read_state() == {"step": 3}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["checkpoint"]


def test_resume_refuses_changed_settings_except_those_that_may_change(tmp_path):
    run = RunDir(tmp_path, may_change=("steps", "opt.lr"))
    run.write_config(_Cfg(), teacher=["a"])
    wider = _Cfg(opt=_Opt(arch=(16,)))
    run.check_resume(wider)  # no checkpoint yet: nothing to resume, nothing checked
    _save(run, 1)
    run.check_resume(_Cfg(steps=20, opt=_Opt(lr=1.0)), recorded={"teacher": ["a"]})
    with pytest.raises(SettingsMismatch, match=r"opt\.arch: \[8, 8\] -> \[16\].*only steps, "
                       r"opt\.lr may change"):  # fmt: skip
        run.check_resume(wider)
    with pytest.raises(SettingsMismatch, match=r"teacher: \['a'\] -> \['b'\]"):
        run.check_resume(_Cfg(), recorded={"teacher": ["b"]})
    # a setting added since the run began counts as its default
    rec = json.loads(run.config_path.read_text())
    del rec["config"]["opt"]["arch"]
    run.config_path.write_text(json.dumps(rec))
    run.check_resume(_Cfg(), defaults=_Cfg())
    with pytest.raises(SettingsMismatch, match=r"opt\.arch: \(not set\) -> \[8, 8\]"):
        run.check_resume(_Cfg())
    run.config_path.write_text("[]")
    with pytest.raises(ValueError, match=r"config\.json: not a training run config"):
        run.check_resume(_Cfg())


def test_settings_diff_flattens_and_compares_common_keys():
    old, new = {"a": 1, "b": {"c": 2, "d": 3}}, {"a": 1, "b": {"c": 5}, "e": 0}
    assert changed_settings(old, new) == ["b.c", "b.d", "e"]
    assert changed_settings(old, new, common_only=True) == ["b.c"]
    assert changed_settings(old, new, may_change=("b.",)) == ["e"]
    assert settings_diff(old, new) == ["b.c: 2 -> 5", "b.d: 3 -> (not set)", "e: (not set) -> 0"]


def test_check_names_the_class_and_the_first_broken_rule():
    check(_Cfg(), (True, "fine"))
    with pytest.raises(ValueError, match=r"^_Cfg: second$"):
        check(_Cfg(), (True, "first"), (False, "second"), (False, "third"))
    check_fields(_Opt(), lambda v: v is not None, "must be set")
    with pytest.raises(ValueError, match=r"^_Opt\.arch must be a float, got \(8, 8\)$"):
        check_fields(_Opt(), lambda v: isinstance(v, float), "must be a float")
