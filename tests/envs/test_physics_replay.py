"""The physics limit of benchmarks/policy_throughput.py: the states saved around a training's
steps replay bit for bit on their own subject's model, also when the humanoid switched
subjects in between (replayed on the last subject's model they would not: the benchmark
error behind the issue-48 "1.7x in-env physics")."""

from __future__ import annotations

import dataclasses
import importlib.util
from pathlib import Path

import numpy as np

from envs.tracking_env import GripTrackingEnv
from grip.core.body import BodyParams
from grip.core.reference import ReferenceSet
from grip.task.config import TrackingEnvConfig


def _benchmark(name: str):
    path = Path(__file__).resolve().parents[2] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"benchmarks_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_saved_states_replay_bit_for_bit_on_their_subjects(reference) -> None:
    tp = _benchmark("policy_throughput")
    base = reference.clip(0)
    bodies = (BodyParams(1.62, 58.0), BodyParams(1.88, 92.0))
    clips = [dataclasses.replace(base, name=f"b{k}", body=b) for k, b in enumerate(bodies)]
    ref = ReferenceSet(clips, reference.sensor_sites, reference.insoles)
    env = GripTrackingEnv(TrackingEnvConfig(random_start=False, termination_dist_m=0.0,
                                            amp_window=2), ref)  # fmt: skip
    rec = tp.PhysicsRecorder(every=2)
    rec.install()
    try:
        rng = np.random.default_rng(0)
        for clip in (0, 1, 0):  # (subjects switch in place on the one flat-floor humanoid)
            env.reset(options={"clip": clip, "start": 0})
            for _ in range(6):
                env.step(rng.uniform(-0.3, 0.3, 69))
    finally:
        rec.remove()
    assert len(rec.pending) == 2  # one humanoid, two subjects
    rec.replay()
    got = rec.figures()
    assert got["replayed_states"] == 9 and got["replay_identical_share"] == 1.0
    # (its sign is timing: 54 steps less a subtracted set-state loop can go either way on a busy
    # machine; the rate is the benchmark's to measure, not a test's)
    assert np.isfinite(got["raw_mj_steps_per_s"]) and rec.substeps == 36
    # the humanoid is left on the subject it was on
    assert env.humanoid.key == (bodies[0].height_m, bodies[0].mass_kg)
