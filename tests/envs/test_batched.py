"""The batched vector env gives the transitions of N separate environments (same seeds and
actions), resets and early termination included: the physics bit for bit; observations,
rewards and infos bit for bit on the machine this was written on (the tolerances leave room for
a BLAS that sums the batched 3 x 3 products in another order)."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
from stable_baselines3.common.vec_env import DummyVecEnv

from envs.batched import BatchedTrackingEnv
from envs.clip_cache import ClipCache
from envs.tracking_env import GripTrackingEnv
from envs.wrappers import ActionRepeat
from grip.task.config import RewardConfig, RewardWeights, TrackingEnvConfig
from policies.vec_env import BatchedVecEnv

N = 3


def _single(cfg, reference, seed):
    env = GripTrackingEnv(cfg, reference)
    if cfg.action_repeat > 1:
        env = ActionRepeat(env, cfg.action_repeat)
    env.reset(seed=seed)
    return env


def _batched(cfg, reference, seeds, threads):
    envs, compiled, clips = [], {}, ClipCache()  # (shared as the factory shares them)
    for s in seeds:
        e = GripTrackingEnv(cfg, reference, compiled_models=compiled, clip_cache=clips)
        e.reset(seed=s)
        envs.append(e)
    return BatchedVecEnv(BatchedTrackingEnv(envs, threads))


@pytest.mark.parametrize(("repeat", "threads", "align", "variant"),
                         [(3, 2, True, "OAV_Jrel_root"), (1, 1, False, "OAV_Jrel"),
                          (3, 1, True, "OAV_Jrel_root@speed"),
                          (2, 2, True, "OAV_Jrel_root@speed,lean")])
def test_batched_matches_separate_envs(reference, repeat, threads, align, variant):
    weights = RewardWeights(root_vel=0.05, root_pos=0.1)  # (the pace terms count)
    # "@speed": a random root speed per episode; "lean": a random lean of the followed trunk
    variant, tags = variant.partition("@")[::2]
    cfg = TrackingEnvConfig(
        root_speed_range=(0.8, 1.25) if "speed" in tags else (1.0, 1.0),
        lean_range_deg=(-8.0, 8.0) if "lean" in tags else (0.0, 0.0),
        action_repeat=repeat,
        termination_dist_m=0.15,
        max_episode_frames=40,
        min_episode_frames=20,
        align_root_xy=align,
        kinematic_obs=variant,
        reward=RewardConfig(weights=weights),
    )
    seeds = [7 + 1000 * i for i in range(N)]
    ref = DummyVecEnv([functools.partial(_single, cfg, reference, s) for s in seeds])
    bat = _batched(cfg, reference, seeds, threads)
    ref.seed(3)
    bat.seed(3)
    o1, o2 = ref.reset(), bat.reset()
    for k in o1:
        np.testing.assert_allclose(o2[k], o1[k], rtol=1e-6, atol=1e-6)
    rng = np.random.default_rng(0)
    dones = 0
    unstable = 0
    for step in range(60):
        a = rng.uniform(-1, 1, (N, 69)).astype(np.float32) * (0.2 if step % 7 else 1.0)
        if step == 20:  # a blow-up (pelvis far above the blow-up speed) ends an episode
            for venv in (ref, bat):
                venv.env_method("push_pelvis", np.array([0.0, 0.0, 1e6]), indices=[1])
        o1, r1, d1, i1 = ref.step(a)
        o2, r2, d2, i2 = bat.step(a)
        np.testing.assert_array_equal(d2, d1)
        dones += int(d1.sum())
        np.testing.assert_allclose(r2, r1, rtol=1e-6, atol=1e-7)
        for k in o1:
            np.testing.assert_allclose(o2[k], o1[k], rtol=1e-6, atol=1e-6, err_msg=k)
        for a1, a2 in zip(i1, i2, strict=True):
            unstable += a1["sim_unstable"]
            assert a1.keys() == a2.keys()
            for key, v in a1.items():
                if key == "terminal_observation":
                    for kk in v:
                        np.testing.assert_allclose(a2[key][kk], v[kk], rtol=1e-6, atol=1e-6)
                elif isinstance(v, (float, np.ndarray)):
                    np.testing.assert_allclose(a2[key], v, rtol=1e-6, atol=1e-6, err_msg=key)
                else:
                    assert a2[key] == v, key
    assert dones >= 2 and unstable == 1  # resets and the blow-up path were exercised
    # the physics itself is bit for bit the same
    for e1, e2 in zip(ref.envs, bat.envs, strict=True):
        np.testing.assert_array_equal(e2.data.qpos, e1.unwrapped.data.qpos)
    assert bat.env_method("set_termination_dist", 0.3) == [None] * N
    assert bat.get_attr("termination_dist_m") == [0.3] * N
    bat.close()


def test_batched_refuses_mixed_configs(reference):
    a = GripTrackingEnv(TrackingEnvConfig(), reference)
    b = GripTrackingEnv(dataclasses.replace(TrackingEnvConfig(), action_scale=0.3), reference)
    with pytest.raises(ValueError, match="same config"):
        BatchedTrackingEnv([a, b])


@pytest.mark.parametrize("below", [0.0, 1.0])
def test_a_low_pelvis_is_a_fall_only_below_the_reference(reference, below):
    """``fall_below_reference_m``: without it a pelvis below ``fall_height_m`` ends the episode;
    with 1 m it must also lie 1 m under the truth's standing pelvis (~0.9 m), which it never
    does, so a floor clip's low pelvis would be followed. Batched and separate agree."""
    cfg = TrackingEnvConfig(termination_dist_m=0.0, fall_height_m=0.8,
                            fall_below_reference_m=below, max_episode_frames=200,
                            random_start=False)  # fmt: skip
    seeds = [7 + 1000 * i for i in range(N)]
    ref = DummyVecEnv([functools.partial(_single, cfg, reference, s) for s in seeds])
    bat = _batched(cfg, reference, seeds, 1)
    ref.reset(), bat.reset()
    fell = np.zeros(N, dtype=bool)
    lowest = np.full(N, np.inf)
    for _ in range(150):  # no balance: the body sinks below 0.8 m within the first steps
        a = np.zeros((N, 69), np.float32)
        _, _, d1, i1 = ref.step(a)
        _, _, d2, _ = bat.step(a)
        np.testing.assert_array_equal(d2, d1)
        for k, info in enumerate(i1):
            lowest[k] = min(lowest[k], info["root_height_m"])
            fell[k] |= d1[k] and not info.get("TimeLimit.truncated", False)
    assert (lowest < 0.8).all()  # the pelvis went below fall_height_m in every env
    assert fell.all() if below == 0.0 else not fell.any()
    bat.close()


@pytest.mark.parametrize("limit", [0.0, 0.3])
def test_an_episode_ends_when_the_pelvis_strays_from_the_one_it_follows(reference, limit):
    """``termination_root_gap_m``: a body that does not walk (zero actions: it sinks where it
    stands) while its reference walks on ends its episode at the first step whose horizontal
    pelvis gap (read back from the ``root_pos`` kernel, exp(-k g^2)) exceeds the limit, not
    before; off (0), the same episodes run on. Batched and separate agree."""
    cfg = TrackingEnvConfig(termination_dist_m=0.0, termination_root_gap_m=limit,
                            max_episode_frames=200, random_start=False)  # fmt: skip
    k = cfg.reward.k_root_pos
    seeds = [7 + 1000 * i for i in range(N)]
    ref = DummyVecEnv([functools.partial(_single, cfg, reference, s) for s in seeds])
    bat = _batched(cfg, reference, seeds, 1)
    ref.reset(), bat.reset()
    ended = np.zeros(N, dtype=bool)
    widest = np.zeros(N)
    for _ in range(150):
        a = np.zeros((N, 69), np.float32)
        _, _, d1, i1 = ref.step(a)
        _, _, d2, _ = bat.step(a)
        np.testing.assert_array_equal(d2, d1)
        for j, info in enumerate(i1):
            if ended[j]:
                continue
            gap = np.sqrt(-np.log(info["reward/root_pos"]) / k)
            widest[j] = max(widest[j], gap)
            done = d1[j] and not info.get("TimeLimit.truncated", False)
            if limit > 0:
                assert done == (gap > limit), (j, gap)
            ended[j] |= done
    assert (widest > 0.3).all()  # the reference walked away from every body
    assert ended.all() if limit > 0 else not ended.any()
    bat.close()
