"""Dependency rules of STYLE.md section 2, checked by importing each layer in a fresh process."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

FORBIDDEN = {
    "prism_tools": ("torch", "mujoco", "gymnasium", "stable_baselines3", "envs", "policies",
                    "grip.kinematics", "grip.motion", "grip.sim"),
    "prism_tools.synth": ("torch", "mujoco", "gymnasium", "stable_baselines3"),
    "grip": ("torch", "mujoco", "gymnasium", "stable_baselines3", "numpy"),
    "grip.core": ("torch", "mujoco", "gymnasium", "stable_baselines3"),
    "grip.core.mjcf": ("torch", "mujoco", "gymnasium", "stable_baselines3"),
    "grip.motion": ("torch", "mujoco", "gymnasium", "stable_baselines3"),
    "grip.config": ("numpy", "torch", "mujoco", "gymnasium", "stable_baselines3"),
    "grip.kinematics.features": ("torch", "mujoco", "envs", "policies"),
    "grip.export": ("torch", "stable_baselines3", "policies"),
    "grip.kinematics": ("mujoco", "envs", "policies", "gymnasium"),
    "grip.cli.main": ("torch", "mujoco", "gymnasium", "stable_baselines3"),
    "grip.core.reference": ("torch", "mujoco", "gymnasium", "stable_baselines3"),
    "grip.sim": ("torch", "gymnasium", "stable_baselines3", "envs", "policies"),
    "grip.baselines": ("torch", "stable_baselines3", "policies", "grip.kinematics"),
    "grip.baselines.pip_physics": ("torch", "stable_baselines3", "policies", "grip.kinematics"),
    "grip.baselines.transpose_translation": ("torch", "stable_baselines3", "policies",
                                             "grip.kinematics"),
    "envs": ("torch", "stable_baselines3", "policies", "grip.kinematics"),
    "envs.tracking_env": ("torch", "stable_baselines3", "policies", "grip.kinematics"),
    "envs.amp": ("torch", "mujoco", "stable_baselines3", "policies", "grip.kinematics"),
    "policies.amp": ("mujoco", "stable_baselines3", "grip.kinematics", "grip.eval"),
    "policies.runner": ("stable_baselines3", "grip.kinematics", "grip.eval"),
    "policies.train": ("grip.kinematics", "grip.eval"),
}  # fmt: skip

_PROBE = """
import importlib, json, sys
importlib.import_module({module!r})
for name in list({extra!r}):
    importlib.import_module(name)
print(json.dumps(sorted(sys.modules)))
"""


def _loaded(module: str, extra: tuple[str, ...] = ()) -> set[str]:
    out = subprocess.run(
        [sys.executable, "-c", _PROBE.format(module=module, extra=extra)],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    return set(json.loads(out.stdout))


def _submodules(package: str) -> tuple[str, ...]:
    import importlib
    import pkgutil

    pkg = importlib.import_module(package)
    return tuple(m.name for m in pkgutil.walk_packages(pkg.__path__, package + "."))


@pytest.mark.parametrize("layer", sorted(FORBIDDEN))
def test_layer_does_not_import_forbidden(layer: str) -> None:
    extra: tuple[str, ...] = ()
    if layer in ("prism_tools", "grip.core", "grip.export"):
        extra = _submodules(layer)  # every module of the layer, not just its __init__
    loaded = _loaded(layer, extra)
    bad = [
        f for f in FORBIDDEN[layer]
        if any(m == f or m.startswith(f + ".") for m in loaded)
    ]  # fmt: skip
    assert not bad, f"importing {layer} pulled in forbidden modules: {bad}"


def test_probe_detects_a_violation() -> None:
    """The checker itself can fail: importing numpy is visible in sys.modules."""
    assert "numpy" in _loaded("grip.core.rotations")
