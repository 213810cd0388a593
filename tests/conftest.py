"""Fixtures shared across the test tree."""

from __future__ import annotations

import json
import shutil

import pytest

TINY_POLICY = ["--set", "ppo.n_envs=2", "--set", "ppo.n_steps=32", "--set", "ppo.batch_size=64",
               "--set", "ppo.n_epochs=1", "--set", "ppo.net_arch=[16]", "--set", "amp.hidden=[16]",
               "--set", "amp.window=2", "--set", "amp.batch_size=16",
               "--set", "amp.replay_size=256", "--set", "stage1.timesteps=64",
               "--set", "stage1.categories=[]", "--set", "stage2.categories=[]",
               "--set", "stage2.timesteps=64"]  # fmt: skip
"""``grip policy train`` settings of a run of a few seconds."""

_WALK = ("cmu", "bvh", "07_05.bvh")


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
