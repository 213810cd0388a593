"""Distillation from one teacher per motion family (``grip policy distill --specialist``,
:mod:`policies.teachers`): each environment's label comes from the specialist of its clip's
category, every other clip's from the default teacher."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from envs.factory import make_tracking_env
from envs.tracking_env import SAMPLE_REFERENCE
from grip.assets import SHIPPED_POLICY
from policies.distill import DistillConfig, Distiller
from policies.teachers import Specialist


def _still_policy(out: Path) -> Path:
    """The shipped policy's first member with its output layer zeroed: it always acts 0."""
    from grip.nn.weights import pack_weights
    from policies.runner import PolicyRunner, read_policy_file, write_policy_file

    members, _names = read_policy_file(SHIPPED_POLICY)
    payload = dict(members[0])
    runner = PolicyRunner.from_payload(payload, "member 0")
    last = [m for m in runner.actor if isinstance(m, torch.nn.Linear)][-1]
    with torch.no_grad():
        last.weight.zero_()
        last.bias.zero_()
    payload["actor"] = pack_weights(runner.actor.state_dict(), "fp32")
    write_policy_file([payload], ["still"], out)
    return out


def _distiller(tmp_path: Path, specialists, name: str = "run") -> Distiller:
    cfg = DistillConfig(iterations=1, decisions_per_iteration=60, n_envs=3, max_samples=64,
                        categories=(), reverse_categories=(), mirror_references=False,
                        max_episode_frames=4)  # fmt: skip
    return Distiller(cfg, [SHIPPED_POLICY], tmp_path / name, SAMPLE_REFERENCE, make_tracking_env,
                     specialists=specialists)  # fmt: skip


def test_each_clip_learns_from_its_familys_specialist(tmp_path: Path) -> None:
    still = _still_policy(tmp_path / "still.pt")
    dist = _distiller(tmp_path, [Specialist.parse(f"run,jump*={still}")])
    assert dist.router.family("run") == 0 and dist.router.family("walk") == -1
    _x, y, stats = dist.collect()
    on_run, default = stats["taught"]
    # short episodes on both clips: both teachers labelled, every decision counted once
    assert on_run > 0 and default > 0 and on_run + default == len(y) == stats["decisions"]
    # the specialist's labels are its constant 0, the default teacher's are not
    still_rows = np.all(y == 0, axis=1)
    assert still_rows.sum() == on_run
    # without the specialist the same rollouts are labelled by the default teacher alone
    _x0, y0, stats0 = _distiller(tmp_path, [], "plain").collect()
    assert "taught" not in stats0 and not np.all(y0 == 0, axis=1).any()


def test_specialists_are_checked(tmp_path: Path) -> None:
    for bad in ("run", "=x.pt", "run=", " , =x.pt"):
        with pytest.raises(ValueError, match="CATEGORY"):
            Specialist.parse(bad)
    assert Specialist.parse(" walk-back , walk-side = a.pt ") == Specialist(
        ("walk-back", "walk-side"), "a.pt")
    with pytest.raises(ValueError, match=r"none\.pt: no such policy file"):
        _distiller(tmp_path, [Specialist(("run",), str(tmp_path / "none.pt"))])
    # a specialist whose actions mean something else (another decision period) is refused
    from policies.runner import read_policy_file, write_policy_file

    members, _ = read_policy_file(SHIPPED_POLICY)
    other = dict(members[0])
    config = json.loads(other["config"])
    config["env"]["action_repeat"] = int(config["env"]["action_repeat"]) + 1
    other["config"] = json.dumps(config)
    write_policy_file([other], ["other"], tmp_path / "other.pt")
    with pytest.raises(ValueError, match="action_repeat"):
        _distiller(tmp_path, [Specialist(("run",), str(tmp_path / "other.pt"))])
    # ... but one trained with another root-speed augmentation drives the humanoid alike
    config = json.loads(members[0]["config"])
    config["env"]["root_speed_range"] = [0.8, 1.2]
    write_policy_file([{**members[0], "config": json.dumps(config)}], ["aug"],
                      tmp_path / "aug.pt")  # fmt: skip
    _distiller(tmp_path, [Specialist(("run",), str(tmp_path / "aug.pt"))], "aug")
    # a resumed run keeps its specialists
    still = _still_policy(tmp_path / "still.pt")
    dist = _distiller(tmp_path, [Specialist(("run",), str(still))], "resumed")
    dist.run()
    dist.rundir.write_config(dist.cfg, teacher=dist.teacher_resolved,
                             specialists=dist.specialists_resolved)  # fmt: skip
    with pytest.raises(ValueError, match="specialists"):
        _distiller(tmp_path, [], "resumed")
