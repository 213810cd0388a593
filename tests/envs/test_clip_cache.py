"""The per-clip arrays shared by a batch's environments: built once per clip and subject,
bounded in bytes, rebuilt for another clip object, and an episode on cached arrays is the
episode on fresh ones."""

from __future__ import annotations

import numpy as np
import pytest

from envs.clip_cache import GT_DIM, ClipCache, build_clip_arrays
from envs.tracking_env import GripTrackingEnv
from grip.core.reference import ReferenceSet
from grip.kinematics.reference import oracle_reference_clip
from grip.task.config import TrackingEnvConfig
from prism_tools.synthetic import make_recording

SITES = ("L_Foot", "R_Foot", "L_Wrist", "R_Wrist")


@pytest.fixture(scope="module")
def two_clips() -> ReferenceSet:
    clips = [oracle_reference_clip(make_recording(120, seed=s)) for s in (0, 1)]
    return ReferenceSet(clips, SITES, True)


def test_arrays_hold_the_clip(two_clips):
    clip = two_clips.clip(0)
    kd = np.full(69, 0.1)
    got = build_clip_arrays(clip, kd, True, teacher=True)
    t = clip.n_frames
    assert got.gt.shape == (t, GT_DIM)
    np.testing.assert_array_equal(got.gt[:, : 3 * 24 * 3].reshape(t, 3, 24, 3)[:, 0], clip.gt_pos)
    np.testing.assert_array_equal(got.gt[:, GT_DIM // 2 :].reshape(t, 24, 3, 3), clip.gt_rot)
    np.testing.assert_allclose(got.est.target, clip.est_hinge + kd * clip.est_hinge_vel)
    assert got.truth is not None and got.nbytes > got.gt.nbytes + got.amp.nbytes


def test_shared_hits_bounds_and_rebuilds(two_clips):
    cache = ClipCache()
    kd = np.zeros(69)
    a = cache.get(0, "s", two_clips.clip(0), kd, True, False)
    assert cache.get(0, "s", two_clips.clip(0), kd, True, False) is a
    assert cache.get(0, "other subject", two_clips.clip(0), kd, True, False) is not a
    assert (cache.hits, cache.misses) == (1, 2)
    # another clip object under the same index (a reloaded set) is not served stale arrays
    assert cache.get(0, "s", two_clips.clip(1), kd, True, False).clip is two_clips.clip(1)
    small = ClipCache(max_bytes=a.nbytes + 1)
    small.get(0, "s", two_clips.clip(0), kd, True, False)
    small.get(1, "s", two_clips.clip(1), kd, True, False)
    assert len(small) == 1 and small.nbytes <= a.nbytes + 1


def test_episodes_on_shared_arrays_equal_fresh_ones(two_clips):
    cfg = TrackingEnvConfig(amp_window=4)
    cache = ClipCache(max_bytes=1)  # (keeps one clip: every other reset rebuilds)
    shared = [GripTrackingEnv(cfg, two_clips, clip_cache=cache) for _ in range(2)]
    rng = np.random.default_rng(0)
    for k in range(4):
        opts = {"clip": k % 2, "start": 5 + k}
        fresh = GripTrackingEnv(cfg, two_clips)
        o_ref, i_ref = fresh.reset(seed=k, options=opts)
        o, i = shared[k % 2].reset(seed=k, options=opts)
        a = rng.uniform(-0.3, 0.3, 69)
        for key in o_ref:
            np.testing.assert_array_equal(o[key], o_ref[key])
        np.testing.assert_array_equal(i["amp_obs"], i_ref["amp_obs"])
        s_ref, s = fresh.step(a), shared[k % 2].step(a)
        assert s[1] == s_ref[1]
        for key in s_ref[0]:
            np.testing.assert_array_equal(s[0][key], s_ref[0][key])
    assert cache.misses >= 3
