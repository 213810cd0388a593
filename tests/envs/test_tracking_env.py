"""Environment contract (STYLE.md section 6) and physics sanity on a real walking clip."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers GripTracking-v0)
from envs.tracking_env import GripTrackingEnv
from grip.task.config import TrackingEnvConfig
from grip.task.observations import kinematic_dim


def _env(ref, **kw) -> GripTrackingEnv:
    return GripTrackingEnv(TrackingEnvConfig(**kw), reference=ref)


def test_gymnasium_and_sb3_check_env(reference) -> None:
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = _env(reference)
    check_env(env, skip_render_check=True)
    sb3_check_env(_env(reference), warn=True)


def test_make_with_no_arguments_uses_the_bundled_sample() -> None:
    env = gym.make("GripTracking-v0")
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    obs, r, _term, _trunc, info = env.step(env.action_space.sample())
    assert np.isfinite(r) and "reward/imit_pos" in info
    env.close()


def _rollout(env, seed: int, n: int = 15):
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    out = [obs]
    for _ in range(n):
        obs, r, term, trunc, _info = env.step(env.action_space.sample())
        out.append((obs, r, term, trunc))
        if term or trunc:
            break
    return out


def test_same_seed_gives_identical_trajectories(reference) -> None:
    a = _rollout(_env(reference), seed=7)
    b = _rollout(_env(reference), seed=7)
    assert len(a) == len(b)
    for x, y in zip(a[1:], b[1:], strict=True):
        for k in x[0]:
            np.testing.assert_array_equal(x[0][k], y[0][k])
        assert x[1:] == y[1:]
    c = _rollout(_env(reference), seed=8)
    assert any(not np.array_equal(a[0][k], c[0][k]) for k in a[0])  # random start differs


def test_observations_lie_in_the_space_and_share_no_memory(reference) -> None:
    env = _env(reference)
    obs0, _ = env.reset(seed=1)
    obs1, *_ = env.step(np.zeros(69, dtype=np.float32))
    for k, space in env.observation_space.spaces.items():
        assert obs1[k].shape == space.shape and obs1[k].dtype == space.dtype
        assert not np.shares_memory(obs0[k], obs1[k])
    before = {k: v.copy() for k, v in obs1.items()}
    obs1["self"][:] = 1e9  # scribbling on a returned obs must not leak into the env
    obs2, *_ = env.step(np.zeros(69, dtype=np.float32))
    assert env.observation_space.contains(obs2)
    assert not np.shares_memory(obs1["self"], obs2["self"])
    assert before["sensor"].shape == obs2["sensor"].shape


def test_reward_is_the_weighted_sum_of_its_terms(reference) -> None:
    env = _env(reference)
    env.reset(seed=2)
    w = env.cfg.reward.weights
    for _ in range(6):
        _, r, _term, _trunc, info = env.step(env.action_space.sample() * 0.1)
        terms = {k.split("/", 1)[1]: v for k, v in info.items() if k.startswith("reward/")}
        assert set(terms) == {f.name for f in dataclasses.fields(w)}
        assert r == pytest.approx(sum(getattr(w, k) * v for k, v in terms.items()))
    # the energy term is excluded for the first 3 steps after a reset
    env.reset(seed=2)
    energies = [env.step(np.zeros(69, np.float32))[4]["reward/energy"] for _ in range(5)]
    assert energies[:3] == [0.0, 0.0, 0.0] and energies[3] > 0


@pytest.mark.parametrize("variant", ["OA", "OAV", "OAV_Jglo", "OAV_Jrel", "OAV_Jrel_root"])
def test_ablation_flags_set_the_kinematic_observation(reference, variant) -> None:
    env = _env(reference, kinematic_obs=variant)
    obs, _ = env.reset(seed=0)
    assert obs["kinematic"].shape == (kinematic_dim(variant),)


def test_pinned_root_pd_tracking_follows_the_walk(walk_reference) -> None:
    """With the pelvis driven along the ground truth and the perfect estimate as PD target
    (relative action 0), the joints stay close to the ground truth for the whole clip
    (measured: MPJPE 8.9 mm, mean per-frame worst joint 3.3 cm)."""
    env = _env(walk_reference, pin_root=True, random_start=False, termination_dist_m=0.0)
    env.reset(seed=0)
    worst, mpjpe = [], []
    while True:
        _, _, term, trunc, info = env.step(np.zeros(69, np.float32))
        worst.append(info["max_joint_err_m"])
        mpjpe.append(info["mpjpe_m"])
        if term or trunc:
            break
    assert len(worst) == walk_reference.clip(0).n_frames - 1
    assert np.mean(mpjpe) < 0.02 and np.mean(worst) < 0.05
    # without the velocity feed-forward the PD servo lags by kd/kp = 0.1 s
    env = _env(walk_reference, pin_root=True, random_start=False, termination_dist_m=0.0,
               velocity_feedforward=False)  # fmt: skip
    env.reset(seed=0)
    lag = [env.step(np.zeros(69, np.float32))[4]["mpjpe_m"] for _ in range(200)]
    assert np.mean(lag) > 2 * np.mean(mpjpe[:200])


def test_without_a_policy_the_humanoid_falls(walk_reference) -> None:
    """Root free, PD targets = the reference pose with no balance control: it falls."""
    env = _env(walk_reference, random_start=False, termination_dist_m=0.0)
    env.reset(seed=0)
    heights = []
    for _ in range(400):
        _, _, term, trunc, _ = env.step(np.zeros(69, np.float32))
        heights.append(env.data.xpos[env.humanoid.pelvis_body][2])
        if term or trunc:
            break
    assert min(heights) < 0.5  # the standing pelvis is at ~0.9 m


def test_early_termination_and_truncation(reference) -> None:
    env = _env(reference, action_mode="absolute")
    env.reset(seed=0)
    for _ in range(200):
        _, _, term, trunc, info = env.step(np.ones(69, np.float32))  # limbs to their limits
        if term or trunc:
            break
    assert term and not trunc and info["max_joint_err_m"] > 0.25
    env = _env(reference, max_episode_frames=5, termination_dist_m=0.0)
    env.reset(seed=0)
    dones = [env.step(np.zeros(69, np.float32))[3] for _ in range(5)]
    assert dones == [False] * 4 + [True]


def test_bad_actions_are_refused(reference) -> None:
    env = _env(reference)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        env.step(np.full(69, np.nan, np.float32))
    with pytest.raises(ValueError, match="69"):
        env.step(np.zeros(68, np.float32))


def test_a_blow_up_ends_the_episode_cleanly_and_is_counted(reference) -> None:
    env = _env(reference)
    obs, _ = env.reset(seed=0)
    env.data.qvel[:] = 1e12  # a state MuJoCo cannot integrate
    obs, r, term, _trunc, info = env.step(np.zeros(69, np.float32))
    assert term and info["sim_unstable"] and info["blowups"] == 1 and r == 0.0
    assert all(np.isfinite(v).all() for v in obs.values())
    env.reset(seed=1)
    _, _, term, _, info = env.step(np.zeros(69, np.float32))
    assert not info["sim_unstable"] and info["blowups"] == 1


def test_every_blow_up_is_detected_also_without_a_reset(reference) -> None:
    # MuJoCo's reset zeroes its warning counters and counts the new warning: the count stays 1
    # from one blow-up to the next, so a count that must grow missed the second one
    env = _env(reference)
    env.reset(seed=0)
    for n in (1, 2, 3):
        env.data.qvel[:] = 1e12
        _, _, term, _, info = env.step(np.zeros(69, np.float32))
        assert term and info["sim_unstable"] and info["blowups"] == n


@pytest.mark.parametrize("what", ["pelvis_speed", "joint_speed", "below_floor", "nan"])
def test_an_absurd_state_is_a_blow_up_before_mujoco_notices(reference, what) -> None:
    # states MuJoCo integrates without a warning (its limit is 1e10) but no body can be in
    env = _env(reference, random_start=False)
    env.reset(seed=0)
    d, ix = env.data, env.humanoid.index
    if what == "pelvis_speed":
        d.qvel[ix.root_dof_adr + 2] = 1e3  # 10 m up in one step
    elif what == "joint_speed":
        d.qvel[ix.hinge_dof_adr[5]] = 1e4
    elif what == "below_floor":
        d.qpos[ix.root_qpos_adr + 2] = -3.0
    else:
        d.qvel[ix.hinge_dof_adr[5]] = np.nan
    _, r, term, _, info = env.step(np.zeros(69, np.float32))
    assert term and info["sim_unstable"] and info["blowups"] == 1 and r == 0.0
    # ordinary motion (the reset above, a step from it) is never one
    env.reset(seed=0)
    for _ in range(20):
        assert not env.step(np.ones(69, np.float32))[4]["sim_unstable"]


def test_stairs_show_up_in_the_height_map(reference) -> None:
    from grip.core.body import CANONICAL_TO_WORLD
    from grip.core.rotations import matrix_to_quat

    env = _env(reference, terrain="stairs", random_start=False)
    env.reset(seed=0)
    # put the pelvis above the second tread (y = 1.1-1.4 m, 0.3 m high), facing +y: up the stairs
    env.data.qpos[:3] = (0.0, 1.25, 1.3)
    env.data.qpos[3:7] = matrix_to_quat(CANONICAL_TO_WORLD)
    env.data.qvel[:] = 0.0
    obs, *_ = env.step(np.zeros(69, np.float32))
    pelvis_z = env.data.xpos[env.humanoid.pelvis_body][2]
    hm = obs["environment"].reshape(25, 25) + pelvis_z  # rows: left (y), columns: forward (x)
    np.testing.assert_allclose(hm[12, 12], 0.30, atol=0.02)  # under the pelvis
    assert hm[12, -1] > hm[12, 12] + 0.1 > hm[12, 0] + 0.2  # higher ahead, lower behind
    np.testing.assert_allclose(hm[0, 12], hm[-1, 12], atol=1e-6)  # level across the stairs


def test_split_substeps_follow_mj_step_bit_for_bit(reference) -> None:
    import mujoco

    env = _env(reference, random_start=False, termination_dist_m=0.0)
    env.reset(seed=0)
    m = env.model
    twin = mujoco.MjData(m)
    mujoco.mj_copyData(twin, m, env.data)
    rng = np.random.default_rng(0)
    for _ in range(50):
        env.step(rng.uniform(-0.2, 0.2, 69).astype(np.float32))
        twin.ctrl[:] = env.data.ctrl
        mujoco.mj_step(m, twin, nstep=2)
        np.testing.assert_array_equal(env.data.qpos, twin.qpos)
        np.testing.assert_array_equal(env.data.qvel, twin.qvel)


def test_an_episode_follows_the_estimated_root_from_its_own_start() -> None:
    env = GripTrackingEnv()  # bundled sample: KinematicsNet estimates, whose root drifts
    clip = env.reference.clip(0)
    start = clip.n_frames - 30
    env.reset(options={"clip": 0, "start": start})
    np.testing.assert_allclose(clip.est_root_pos[start] + env._root_offset, clip.gt_qpos[start, :3])


@pytest.mark.parametrize("align", [True, False])
def test_align_root_xy_ignores_a_horizontal_offset(align: bool) -> None:
    env = GripTrackingEnv(TrackingEnvConfig(align_root_xy=align, amp_window=0))
    rewards = []
    for dx in (0.0, 0.5):
        env.reset(options={"clip": 0, "start": 5})
        env.data.qpos[0] += dx  # the whole body half a metre to the side (flat floor)
        _, _, _, _, info = env.step(np.zeros(69))
        rewards.append(info["reward/imit_pos"])
    if align:
        assert rewards[1] == pytest.approx(rewards[0], rel=1e-6)
    else:
        assert rewards[1] < 0.01 * rewards[0]


def test_root_velocity_term_asks_the_body_to_cover_the_reference_ground(walk_reference) -> None:
    """Pelvis driven along the ground truth: the term stays near 1. Pelvis held at its start
    while the reference walks on: near 0 once the window is full. A teleport (fall recovery)
    restarts the window instead of counting the jump as velocity."""
    env = _env(walk_reference, pin_root=True, random_start=False, termination_dist_m=0.0)
    env.reset(seed=0)
    pinned = [env.step(np.zeros(69))[4]["reward/root_vel"] for _ in range(100)]
    assert min(pinned) > 0.9
    env = _env(walk_reference, random_start=False, termination_dist_m=0.0, amp_window=0)
    env.reset(seed=0)
    start = env.data.qpos[:2].copy()
    held = []
    for _ in range(60):
        env.data.qpos[:2] = start
        held.append(env.step(np.zeros(69))[4]["reward/root_vel"])
    assert np.mean(held[40:]) < 0.05
    env.reset(seed=0)
    for _ in range(20):
        env.step(np.zeros(69))
    q = env.clip.gt_qpos[env.frame].copy()
    q[0] += 1.0
    env.teleport(q)
    assert env.step(np.zeros(69))[4]["reward/root_vel"] > 0.5


def test_root_position_term_pays_a_body_left_behind_less_and_it_sees_the_gap(
        walk_reference) -> None:  # fmt: skip
    """A body held at its start while its reference walks away (issue 46): ``root_pos`` falls
    with the distance (it stays near 1 when the pelvis is driven along the reference), and the
    ``OAV_Jrel_root`` observation shows the followed pelvis ahead of it, up to the clip."""
    env = _env(walk_reference, pin_root=True, random_start=False, termination_dist_m=0.0,
               kinematic_obs="OAV_Jrel_root")  # fmt: skip
    env.reset(seed=0)
    pinned = [env.step(np.zeros(69))[4]["reward/root_pos"] for _ in range(100)]
    assert min(pinned) > 0.9  # (the estimate's integrated root is near the truth's)
    env = _env(walk_reference, random_start=False, termination_dist_m=0.0, amp_window=0,
               kinematic_obs="OAV_Jrel_root")  # fmt: skip
    env.reset(seed=0)
    start = env.data.qpos[:2].copy()
    terms, gaps = [], []
    for _ in range(150):
        env.data.qpos[:2] = start
        obs, _, _, _, info = env.step(np.zeros(69))
        terms.append(info["reward/root_pos"])
        gaps.append(float(np.hypot(*obs["kinematic"][-2:])))
    walked = float(np.linalg.norm(env.clip.est_root_pos[env.frame, :2]
                                  - env.clip.est_root_pos[0, :2]))  # fmt: skip
    assert walked > 0.5
    assert terms[-1] < np.exp(-4.0 * (walked - 0.1) ** 2) and terms[-1] < 0.5 * terms[5]
    assert gaps[-1] > 0.9 * min(walked, 1.0) and gaps[5] < gaps[-1]


def test_switching_subjects_equals_a_model_compiled_for_each(reference) -> None:
    """Clips of other subjects share one model per scene, their body arrays swapped in
    (ModelVariants): the simulation is the one on the subject's own compiled model."""
    from grip.core.body import BodyParams
    from grip.core.reference import ReferenceSet

    base = reference.clip(0)
    bodies = (BodyParams(1.62, 58.0), BodyParams(1.88, 92.0))
    clips = [dataclasses.replace(base, name=f"b{k}", body=b) for k, b in enumerate(bodies)]
    both = ReferenceSet([base, *clips], reference.sensor_sites, reference.insoles)
    cfg = TrackingEnvConfig(random_start=False, termination_dist_m=0.0, amp_window=2)
    actions = np.random.default_rng(0).uniform(-0.3, 0.3, size=(25, 69))

    def play(env, i):
        env.reset(options={"clip": i, "start": 0})
        for a in actions:
            env.step(a)
        return env.data.qpos.copy(), env.data.actuator_force.copy()

    shared = GripTrackingEnv(cfg, both)
    runs = [play(shared, i) for i in (1, 2, 0, 2)]  # switch to each body and back
    assert len(shared._scenes._scenes) == 1
    for (q, f), i in zip(runs, (1, 2, 0, 2), strict=True):
        own = GripTrackingEnv(cfg, ReferenceSet([both.clip(i)], both.sensor_sites, both.insoles))
        q_own, f_own = play(own, 0)
        np.testing.assert_array_equal(q, q_own)
        np.testing.assert_array_equal(f, f_own)


def test_a_faster_root_is_followed_with_the_same_pose(walk_reference) -> None:
    """``root_speed_range`` (issue 46): with the pelvis driven along the truth, a root carried
    1.3 times as fast runs ahead of it by 0.3 times the ground walked, the velocity joints'
    estimated velocities gain 0.3 times the pelvis', the pose observation stays, and the
    root-velocity term stops paying the truth's pace."""
    runs = {}
    for f in (1.0, 1.3):
        env = _env(walk_reference, pin_root=True, random_start=False, termination_dist_m=0.0,
                   kinematic_obs="OAV_Jrel_root", root_speed_range=(f, f))  # fmt: skip
        env.reset(seed=0)
        steps = [env.step(np.zeros(69)) for _ in range(120)]
        runs[f] = (steps, env)
    (slow, env1), (fast, _) = runs[1.0], runs[1.3]
    t = env1.frame
    clip = env1.clip
    walked = clip.est_root_pos[t, :2] - clip.est_root_pos[0, :2]
    assert np.linalg.norm(walked) > 0.5
    gap1, gap3 = (float(np.hypot(*s[-1][0]["kinematic"][-2:])) for s in (slow, fast))
    assert gap3 - gap1 == pytest.approx(min(0.3 * np.linalg.norm(walked), 1.0), abs=0.03)
    d_v = slice(60, 78)  # (the velocity rows after d_theta, theta_leaf and d_omega)
    dv = (fast[-1][0]["kinematic"][d_v] - slow[-1][0]["kinematic"][d_v]).reshape(6, 3)
    pelvis = clip.est_vel[min(t + 1, clip.n_frames - 1), -1, :2]  # (the observed frame)
    np.testing.assert_allclose(np.linalg.norm(dv, axis=1), 0.3 * np.linalg.norm(pelvis),
                               atol=1e-4)  # fmt: skip
    np.testing.assert_array_equal(fast[-1][0]["kinematic"][:60], slow[-1][0]["kinematic"][:60])
    np.testing.assert_array_equal(fast[-1][0]["kinematic"][78:-2],
                                  slow[-1][0]["kinematic"][78:-2])  # fmt: skip
    vel1 = np.mean([s[4]["reward/root_vel"] for s in slow[40:]])
    vel3 = np.mean([s[4]["reward/root_vel"] for s in fast[40:]])
    assert vel1 > 0.9 and vel3 < 0.8 * vel1


def test_a_random_root_speed_is_drawn_per_episode_and_checked() -> None:
    env = GripTrackingEnv(TrackingEnvConfig(root_speed_range=(0.85, 1.15), amp_window=0))
    drawn = set()
    for s in range(6):
        env.reset(seed=s)
        drawn.add(round(env._root_speed, 6))
    assert len(drawn) == 6 and all(0.85 <= f <= 1.15 for f in drawn)
    for bad in ((1.2, 1.1), (0.3, 1.0), (1.0, 2.5)):
        with pytest.raises(ValueError, match="root_speed_range"):
            TrackingEnvConfig(root_speed_range=bad)
