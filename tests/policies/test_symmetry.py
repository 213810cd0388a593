"""The controller's mirror: what the mirrored humanoid on the mirrored clip observes and does."""

from __future__ import annotations

import numpy as np
import pytest

from envs.tracking_env import SAMPLE_REFERENCE, GripTrackingEnv
from grip.core.reference import ReferenceSet
from grip.kinematics.reference import with_mirrored_clips
from grip.task.config import TrackingEnvConfig
from grip.task.observations import heightmap_grid
from policies.symmetry import MirrorAveragedPolicy, ObservationMirror


@pytest.fixture(scope="module", params=["OAV_Jrel", "OAV_Jrel_root"])
def mirrored(request):
    ref = ReferenceSet.load(SAMPLE_REFERENCE)
    both = with_mirrored_clips(ref)
    cfg = TrackingEnvConfig(random_start=False, termination_dist_m=0.0,
                            kinematic_obs=request.param)  # fmt: skip
    return cfg, both, len(ref.clips), ObservationMirror(cfg, ref.sensor_sites, ref.insoles)


def test_mirrored_observation_is_what_the_mirrored_humanoid_observes(mirrored):
    cfg, both, n, mir = mirrored
    env, twin = GripTrackingEnv(cfg, both), GripTrackingEnv(cfg, both)
    o1, _ = env.reset(options={"clip": 0, "start": 5})
    o2, _ = twin.reset(options={"clip": n, "start": 5})  # the mirror image of clip 0
    rng = np.random.default_rng(0)
    for step in range(11):
        m = mir.observation(o1)
        for k in ("sensor", "kinematic", "self"):
            assert np.abs(o1[k] - o2[k]).max() > 0.1, k  # (the two do differ)
            np.testing.assert_allclose(m[k], o2[k], atol=1e-4, err_msg=f"{k} at step {step}")
        # a random action here, its mirror image there: the twins stay mirror images
        a = rng.uniform(-0.5, 0.5, 69)
        o1, *_ = env.step(a)
        o2, *_ = twin.step(mir.action(a))
    if cfg.kinematic_obs == "OAV_Jrel_root":  # (the gap had grown: its mirror was checked)
        assert np.abs(o1["kinematic"][-2:]).max() > 0.005


def test_mirror_twice_is_the_identity_and_the_height_map_flips(mirrored):
    cfg, both, _, mir = mirrored
    obs, _ = GripTrackingEnv(cfg, both).reset(options={"clip": 0, "start": 5})
    back = mir.observation(mir.observation(obs))
    for k in obs:
        np.testing.assert_allclose(back[k], obs[k], atol=1e-6)
    a = np.random.default_rng(1).uniform(-1, 1, (3, 69))
    np.testing.assert_array_equal(mir.action(mir.action(a)), a)
    grid = heightmap_grid(cfg.heightmap_size, cfg.heightmap_extent_m)
    hm = {"environment": grid[:, 1] + 10 * grid[:, 0]}  # height = left offset + 10 x forward
    np.testing.assert_allclose(mir.observation(hm)["environment"], -grid[:, 1] + 10 * grid[:, 0])
    with pytest.raises(ValueError, match="partner"):
        ObservationMirror(cfg, ("L_Wrist", "Head"), False)


class _Linear:
    """A deliberately lopsided policy: a fixed random linear map of the observation."""

    def __init__(self, cfg, obs):
        rng = np.random.default_rng(2)
        self.obs_keys = list(obs)
        self.w = {k: rng.standard_normal((np.size(v), 69)) * 0.01 for k, v in obs.items()}
        self.env_cfg, self.amp_window, self.disc, self.info = cfg, 10, None, {}

    def act(self, obs):
        return np.tanh(sum(np.asarray(obs[k], np.float64) @ self.w[k] for k in self.obs_keys))


def test_mirror_averaged_policy_is_left_right_symmetric(mirrored):
    cfg, both, _, mir = mirrored
    obs, _ = GripTrackingEnv(cfg, both).reset(options={"clip": 0, "start": 5})
    base = _Linear(cfg, obs)
    sym = MirrorAveragedPolicy(base, mir.sites, mir.insoles)
    mobs = mir.observation(obs)
    # the mirrored situation gets the mirrored action; the bare policy does not
    np.testing.assert_allclose(sym.act(mobs), mir.action(sym.act(obs)), atol=1e-6)
    assert np.abs(base.act(mobs) - mir.action(base.act(obs))).max() > 1e-2
    np.testing.assert_allclose(sym.act(obs), 0.5 * (base.act(obs) + mir.action(base.act(mobs))))
