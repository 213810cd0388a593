"""Fixtures shared across the test tree."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import pytest

TINY_POLICY = ["--set", "ppo.n_envs=2", "--set", "ppo.n_steps=32", "--set", "ppo.batch_size=64",
               "--set", "ppo.n_epochs=1", "--set", "ppo.net_arch=[16]", "--set", "amp.hidden=[16]",
               "--set", "amp.window=2", "--set", "amp.batch_size=16",
               "--set", "amp.replay_size=256", "--set", "stage1.timesteps=64",
               "--set", "stage1.categories=[]", "--set", "stage2.categories=[]",
               "--set", "stage2.timesteps=64"]  # fmt: skip
"""``grip policy train`` settings of a run of a few seconds."""

_WALK = ("cmu", "bvh", "07_05.bvh")


@pytest.fixture(autouse=True)
def _input_limits_restored(monkeypatch):
    """Every test starts with the input limits the suite was started with: a training command in a
    test raises ``max_total_bytes`` for its run's reference set (``$GRIP_LIMITS``,
    :func:`grip.cli.policy_runs.allow_reference_size`), which must not reach the next test."""
    import os

    from grip.cli import policy_runs
    from grip.core.limits import LIMITS_ENV

    monkeypatch.setenv(LIMITS_ENV, os.environ.get(LIMITS_ENV, ""))  # (restored after the test)
    monkeypatch.setattr(policy_runs, "_ONE_INPUT", {})


@pytest.fixture(scope="session")
def cmu_walk_or_none():
    """CMU 07_05 (a slow walk, 4.3 s) from the shared clips, retargeted onto the default body
    at 100 Hz, or ``None`` where the shared motion data is absent. Read-only: tests derive
    copies (``dataclasses.replace``)."""
    from grip.cli.paths import default_motions_dir
    from grip.motion.catalog import load_clip
    from grip.motion.retarget import retarget

    root = default_motions_dir()
    path = root.joinpath(*_WALK) if root else None
    if path is None or not path.is_file():
        return None
    return retarget(load_clip(str(path)))


@pytest.fixture(scope="session")
def cmu_walk(cmu_walk_or_none):
    """:func:`cmu_walk_or_none`, skipping the test where the shared data is absent."""
    if cmu_walk_or_none is None:
        pytest.skip("shared motion data (" + "/".join(_WALK) + ") not found")
    return cmu_walk_or_none


@pytest.fixture(scope="session")
def tiny_policy_settings() -> list[str]:
    """:data:`TINY_POLICY` (a copy)."""
    return list(TINY_POLICY)


@pytest.fixture(scope="session")
def tiny_policy_run(tmp_path_factory):
    """``(data, run)``: a dataset folder (its split only: the run's reference set is the bundled
    sample) and a tiny ``grip policy train`` run folder trained on it (:data:`TINY_POLICY`).
    Read-only: tests copy the run folder before changing it."""
    from envs.tracking_env import SAMPLE_REFERENCE
    from grip.cli.main import main

    root = tmp_path_factory.mktemp("tiny_policy")
    data = root / "data"
    data.mkdir()
    (data / "split.json").write_text(json.dumps({"train": ["s0"], "test": []}))
    run = root / "run"
    run.mkdir()
    shutil.copy(SAMPLE_REFERENCE, run / "reference_train.npz")  # (no KinematicsNet pass)
    argv = ["policy", "train", "--data", str(data), "--out", str(run), *TINY_POLICY]
    assert main(argv) == 0
    return data, run


@pytest.fixture(scope="session")
def ensemble_policy(tmp_path_factory) -> Path:
    """A policy file of three members in the layout written before version 2
    (``LEGACY_ENSEMBLE_FORMAT``, the layout of the ensemble shipped until 2026-12-06): the shipped
    policy and two copies of it with their actor weights and observation means moved by a few per
    cent (seeded), so that the three act differently. Read-only."""
    import torch

    from grip.assets import SHIPPED_POLICY
    from policies.runner import FORMAT, LEGACY_ENSEMBLE_FORMAT, read_policy_file

    members, _ = read_policy_file(SHIPPED_POLICY)
    base = dict(members[0])
    g = torch.Generator().manual_seed(0)

    def moved(d: dict, how) -> dict:
        return {k: how(v).to(v.dtype) for k, v in d.items()}

    out = []
    for i in range(ENSEMBLE_MEMBERS):
        m = {**base, "format": FORMAT, "version": 1}
        if i:  # (only the first member stores the discriminator)
            m.pop("disc", None)
            m["actor"] = moved(base["actor"], lambda v: v * (1.0 + 0.05 * torch.randn(
                v.shape, generator=g)))  # fmt: skip
            m["obs_mean"] = moved(base["obs_mean"], lambda v: v + 0.05 * torch.randn(
                v.shape, generator=g))  # fmt: skip
        out.append(m)
    path = tmp_path_factory.mktemp("ensemble") / "ensemble.pt"
    torch.save({"format": LEGACY_ENSEMBLE_FORMAT, "version": 1, "members": out,
                "names": json.dumps([f"m{i}" for i in range(ENSEMBLE_MEMBERS)])}, path)
    return path


ENSEMBLE_MEMBERS = 3
"""Members of :func:`ensemble_policy`."""


WALK_TAKES = {"take0": 230, "take1": 120, "take2": 160}
"""The takes of :func:`walk_takes` and their frame counts."""


@pytest.fixture(scope="session")
def walk_takes(tmp_path_factory):
    """A dataset folder of synthetic takes (:data:`WALK_TAKES`; seeds 0, 1, 2; category
    ``walk``), all in its test split. Read-only."""
    from prism_tools.chunking import make_split, save_split
    from prism_tools.io import save_recording
    from prism_tools.synthetic import make_recording

    root = tmp_path_factory.mktemp("walk_takes")
    for i, (name, n) in enumerate(WALK_TAKES.items()):
        rec = make_recording(n, seed=i)
        rec = dataclasses.replace(rec, extras={**rec.extras, "take_name": name,
                                               "category": "walk"})  # fmt: skip
        save_recording(rec, root / "sequences" / f"{name}.npz")
    save_split(make_split(list(WALK_TAKES), test_fraction=1.0), root / "split.json")
    return root
