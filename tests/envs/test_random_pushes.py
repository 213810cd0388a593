"""experiments/random_pushes.py: training perturbations on the pelvis (not a library setting)."""

from __future__ import annotations

import dataclasses
import functools
import importlib.util

import mujoco
import numpy as np
import pytest

from envs.tracking_env import GripTrackingEnv
from envs.wrappers import ActionRepeat
from grip.assets import REPO_ROOT
from grip.task.config import TrackingEnvConfig


def _load():
    spec = importlib.util.spec_from_file_location(
        "random_pushes", REPO_ROOT / "experiments" / "random_pushes.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


P = _load()
RandomPushes = P.RandomPushes


def _env(reference, **kw) -> GripTrackingEnv:
    cfg = dataclasses.replace(TrackingEnvConfig(), random_start=False, clip_index=0, **kw)
    return GripTrackingEnv(cfg, reference)


def test_a_push_moves_the_pelvis_along_its_force_by_its_impulse(reference) -> None:
    plain = _env(reference, termination_dist_m=0.0)
    pushed = RandomPushes(_env(reference, termination_dist_m=0.0), force_n=300.0, every_s=1e-9,
                          duration_s=0.1, seed=3)  # fmt: skip
    plain.reset(seed=0)
    pushed.reset(seed=0)
    m, d = plain.model, plain.data
    pelvis = plain.humanoid.pelvis_body
    mass = float(m.body_subtreemass[pelvis])
    forces = []
    for _ in range(10):  # 0.1 s at 100 Hz: the whole first push
        plain.step(np.zeros(69))
        _, _, _, _, info = pushed.step(np.zeros(69))
        forces.append(pushed.unwrapped.data.xfrc_applied[pelvis, :3].copy())
        assert info["push_n"] == pytest.approx(np.linalg.norm(forces[-1]))
    f = forces[0]
    assert 150.0 <= np.linalg.norm(f) <= 300.0 and f[2] == 0.0
    np.testing.assert_array_equal(forces, np.tile(f, (10, 1)))  # one constant push
    # the whole body's momentum changes by the push's impulse (contacts act on both twins)
    d2 = pushed.unwrapped.data
    for data in (d, d2):
        mujoco.mj_subtreeVel(m, data)  # the whole body's centre-of-mass velocity
    dv = d2.subtree_linvel[pelvis] - d.subtree_linvel[pelvis]
    expected = f * 0.1 / mass
    assert np.dot(dv[:2], expected[:2]) / np.dot(expected[:2], expected[:2]) == (
        pytest.approx(1.0, abs=0.35))


def test_between_pushes_the_environment_is_untouched(reference) -> None:
    plain = _env(reference)
    rare = RandomPushes(_env(reference), force_n=300.0, every_s=1e6, duration_s=0.2, seed=0)
    plain.reset(seed=0)
    rare.reset(seed=0)
    rng = np.random.default_rng(1)
    for _ in range(20):
        a = rng.uniform(-0.3, 0.3, 69)
        obs_p, *_ = plain.step(a)
        obs_r, _, _, _, info = rare.step(a)
        assert info["push_n"] == 0.0
        for k in obs_p:
            np.testing.assert_array_equal(obs_r[k], obs_p[k])


def test_pushes_need_positive_settings(reference) -> None:
    with pytest.raises(ValueError, match="force_n, every_s and duration_s must be > 0"):
        RandomPushes(_env(reference), force_n=0.0, every_s=1.0, duration_s=0.2)


def test_the_script_hands_the_command_a_pushed_constructor(tmp_path, monkeypatch) -> None:
    import envs.factory
    from envs.tracking_env import SAMPLE_REFERENCE

    seen = []
    monkeypatch.setattr(envs.factory, "make_tracking_env", envs.factory.make_tracking_env)
    monkeypatch.setattr("grip.cli.main.main", lambda argv: seen.append(argv) or 0)
    assert P.main(["--force-n", "120", "--every-s", "1.5", "--duration-s", "0.1", "--",
                   "policy", "train", "--out", str(tmp_path)]) == 0  # fmt: skip
    assert seen == [["policy", "train", "--out", str(tmp_path)]]
    make = envs.factory.make_tracking_env
    assert isinstance(make, functools.partial) and make.keywords == {"push": (120.0, 1.5, 0.1)}
    cfg = dataclasses.replace(TrackingEnvConfig(), reference=str(SAMPLE_REFERENCE),
                              action_repeat=3)  # fmt: skip
    env = make(cfg, (), 0)
    assert type(env) is ActionRepeat and type(env.env) is RandomPushes  # frames, not decisions
    assert env.env.force_n == 120.0 and env.env._frames == 10
    with pytest.raises(SystemExit):
        P.main(["--", "kin", "train"])
