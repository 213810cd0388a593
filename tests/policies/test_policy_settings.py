"""A policy file's physics and observation settings are checked where they are used (issue 50,
item 3): ``timestep_s = 1e-6`` (a humanoid that never moves, exit 0), ``substeps = 1e6`` (a
hang), ``heightmap_size = 1e5`` or an observation key no inference provides (a traceback) are
refused at load, in every command, naming the file, the setting and the allowed range."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest
import torch

from grip.task.config import TrackingEnvConfig
from policies.config import PolicyRunConfig
from policies.runner import PolicyRunner, read_policy_file, write_policy_file
from policies.settings_check import (
    ENV_RANGES,
    check_env_settings,
    check_observations,
    check_policy_settings,
)

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ROOT / "grip" / "assets" / "policy_default.pt"
SAMPLE = ROOT / "grip" / "assets" / "sample_recording.npz"


def _member() -> dict:
    members, _ = read_policy_file(SHIPPED)
    return dict(members[0])


def _with(tmp_path: Path, env: dict | None = None, name: str = "bad.pt", **member) -> Path:
    """The shipped policy with some ``env`` settings (dotted: ``"mjcf.timestep_s"``) and
    member entries replaced."""
    m = _member()
    cfg = json.loads(m["config"])
    for key, value in (env or {}).items():
        node = cfg["env"]
        *parents, leaf = key.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = value
    m["config"] = json.dumps(cfg)
    m.update(member)
    path = tmp_path / name
    write_policy_file([m], ["bad"], path)
    return path


@pytest.mark.parametrize(("env", "setting", "shown"), [
    ({"mjcf.timestep_s": 1e-6}, "env.mjcf.timestep_s", "1e-06"),
    ({"substeps": 1_000_000}, "env.substeps", "1000000"),
    ({"heightmap_size": 100_000}, "env.heightmap_size", "100000"),
    ({"mjcf.texture_px": 100_000}, "env.mjcf.texture_px", "100000"),
    ({"mjcf.contact_solref": [1e9, 1.0]}, "env.mjcf.contact_solref[0]", "1e+09"),
    ({"substeps": 20, "mjcf.timestep_s": 0.01}, "control rate", "5"),
], ids=["timestep", "substeps", "heightmap", "texture", "solref", "control-rate"])  # fmt: skip
def test_physics_outside_the_ranges_is_refused_at_load(tmp_path, env, setting, shown) -> None:
    path = _with(tmp_path, env)
    with pytest.raises(ValueError) as ei:
        PolicyRunner.load(path)
    msg = str(ei.value)
    assert msg.startswith(str(path)) and setting in msg and shown in msg, msg
    assert "range" in msg, msg


def test_unknown_or_inconsistent_observations_are_refused_at_load(tmp_path) -> None:
    m = _member()
    mean, var = dict(m["obs_mean"]), dict(m["obs_var"])
    mean["lidar"], var["lidar"] = mean.pop("self"), var.pop("self")
    path = _with(tmp_path, obs_keys=["environment", "kinematic", "lidar", "sensor"],
                 obs_mean=mean, obs_var=var)  # fmt: skip
    with pytest.raises(ValueError, match=rf"{path.name}: observation key 'lidar'.*'self'"):
        PolicyRunner.load(path)
    mean = dict(m["obs_mean"], environment=torch.zeros(400))
    path = _with(tmp_path, obs_mean=mean, name="width.pt")
    with pytest.raises(ValueError, match=r"width\.pt: observation 'environment' of 400 values.*"
                                         r"heightmap_size = 25.*625"):  # fmt: skip
        PolicyRunner.load(path)


def test_unknown_keys_in_a_policy_file_are_errors(tmp_path) -> None:
    path = _with(tmp_path, {"mjcf.timestep_ms": 5})
    with pytest.raises(ValueError, match=rf"{path.name}.*timestep_ms"):
        PolicyRunner.load(path)


def test_shipped_policy_and_every_recipe_lie_in_the_ranges() -> None:
    from grip.config import load_config

    members, names = read_policy_file(SHIPPED)
    for m, n in zip(members, names, strict=True):
        check_env_settings(PolicyRunner.from_payload(m, n).env_cfg, n)

    distill = ("distill.toml", "student.toml")  # (DistillConfigs: a teacher's settings)
    recipes = [t for t in sorted((ROOT / "configs" / "policy").glob("*.toml"))
               if t.name not in distill]  # fmt: skip
    assert len(recipes) >= 3
    for toml in recipes:
        check_policy_settings(load_config(toml, PolicyRunConfig()), str(toml))


def test_the_table_names_real_settings_and_ignores_new_ones() -> None:
    """Every range names a setting of TrackingEnvConfig (a rename is noticed here); a setting
    the table does not know (one added since, with its default) is not checked."""
    cfg = TrackingEnvConfig()
    for name in ENV_RANGES:
        node = cfg
        for part in name.split("[")[0].split("."):
            assert hasattr(node, part), f"ENV_RANGES names {name!r}, not a setting"
            node = getattr(node, part)
    extended = dataclasses.make_dataclass(
        "Extended", [("new_knob_m", float, dataclasses.field(default=1e12))],
        bases=(TrackingEnvConfig,), frozen=True)  # fmt: skip
    check_env_settings(extended(), "extended")
    with pytest.raises(ValueError, match=r"where: env\.substeps = 25 .*range 1 to 20"):
        check_env_settings(dataclasses.replace(cfg, substeps=25), "where")


def test_observation_check_needs_the_sensor_part() -> None:
    m = _member()
    env = PolicyRunner.load(SHIPPED).env_cfg
    widths = {k: int(v.numel()) for k, v in m["obs_mean"].items()}
    total = sum(widths.values())
    check_observations(m["obs_keys"], widths, total, env, "ok")
    with pytest.raises(ValueError, match=rf"x: the actor takes 10 inputs.*{total}"):
        check_observations(m["obs_keys"], widths, 10, env, "x")
    with pytest.raises(ValueError, match="kinematic_obs"):  # (another variant's width)
        check_observations(m["obs_keys"], widths, total,
                           dataclasses.replace(env, kinematic_obs="OA"), "y")  # fmt: skip


def test_reconstruct_refuses_a_policy_with_absurd_physics_cleanly(tmp_path, capsys) -> None:
    from grip.cli.main import main

    path = _with(tmp_path, {"mjcf.timestep_s": 1e-6})
    rc = main(["reconstruct", str(SAMPLE), "--policy", str(path), "--out",
               str(tmp_path / "out"), "--max-frames", "20"])  # fmt: skip
    err = capsys.readouterr().err
    assert rc != 0 and "Traceback" not in err
    assert str(path) in err and "env.mjcf.timestep_s = 1e-06" in err, err
