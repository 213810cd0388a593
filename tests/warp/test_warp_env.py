"""``WarpTrackingEnv`` on MuJoCo Warp's CPU device against the CPU env (MuJoCo C) from the same
states and actions.

Both play the same episodes of the bundled sample (two subjects, so the per-world subject
arrays are exercised) under the same random actions, resets included, and must agree:

* physics: ``qpos`` within :data:`QPOS_ATOL` (MuJoCo Warp runs in float32, MuJoCo C in float64;
  the measured gap over 300 physics steps is about 1e-5, docs/gpu.md);
* contacts: the same geom pairs, except grazing ones (a pair closer than
  :data:`GRAZING_M` to the surface on the side that has it, which float32 rounding decides);
* terminations and truncations identical;
* observations, rewards, reward terms and AMP windows within the tolerances below.

Compiling MuJoCo Warp's kernels for the CPU takes about a minute on a cold cache
(``~/.cache/warp``), so these tests are ``slow``; they skip where the ``gpu`` extra is absent.
"""

from __future__ import annotations

import numpy as np
import pytest

from envs.warp import warp_available

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not warp_available(), reason="needs mujoco-warp (pip install -e .[gpu])"),
]

N_DECISIONS = 150  # x 2 substeps = 300 physics steps per world
QPOS_ATOL = 1e-3  # rad and m (measured: 3e-6; chaotic growth allowed for)
OBS_ATOL = {"sensor": 0.0, "kinematic": 2e-3, "self": 2e-3, "environment": 1e-5}  # (4e-4, 8e-7)
REWARD_ATOL = 2e-4  # (3e-5)
AMP_ATOL = 2e-3  # (3e-4)
GRAZING_M = 1e-3
STARTS = ((0, 0), (1, 20), (0, 120), (1, 150))


@pytest.fixture(scope="module")
def pair():
    import torch
    import warp as wp

    from envs.batched import BatchedTrackingEnv
    from envs.tracking_env import SAMPLE_REFERENCE, GripTrackingEnv
    from envs.warp.env import WarpTrackingEnv
    from grip.core.reference import ReferenceSet
    from grip.task.config import TrackingEnvConfig

    wp.config.quiet = True
    ref = ReferenceSet.load(SAMPLE_REFERENCE)
    cfg = TrackingEnvConfig()
    envs = [GripTrackingEnv(cfg, ref) for _ in STARTS]
    for e in envs:
        e.reset(seed=0)
    cpu = BatchedTrackingEnv(envs, threads=1)
    gpu = WarpTrackingEnv(cfg, ref, len(STARTS), device="cpu")
    for i, (c, s) in enumerate(STARTS):
        cpu.reset(i, options={"clip": c, "start": s})
    gpu.reset(torch.ones(len(STARTS), dtype=torch.bool), torch.tensor([c for c, _ in STARTS]),
              torch.tensor([s for _, s in STARTS]))  # fmt: skip
    yield cpu, gpu, torch
    cpu.close()


def _qpos_cpu(cpu) -> np.ndarray:
    return np.stack([e.humanoid.data.qpos for e in cpu.envs])


def _contacts_cpu(env) -> dict[tuple[int, int], float]:
    d = env.humanoid.data
    out: dict[tuple[int, int], float] = {}
    for c in d.contact[: d.ncon]:
        key = (int(min(c.geom)), int(max(c.geom)))
        out[key] = min(out.get(key, np.inf), float(c.dist))
    return out


def _unmatched_depth(a: dict, b: dict) -> float:
    """The deepest penetration (m, >= 0) of a geom pair in contact on one side only."""
    extra = [v for k, v in a.items() if k not in b] + [v for k, v in b.items() if k not in a]
    return max([0.0, *(-v for v in extra)])


def test_warp_env_matches_cpu_env(pair):
    cpu, gpu, torch = pair
    n = cpu.num_envs
    rng = np.random.default_rng(0)
    worst = dict.fromkeys(("qpos", "reward", "amp", "unmatched_contact_m", *OBS_ATOL), 0.0)
    ends = contacts_checked = 0
    for step in range(N_DECISIONS):
        act = np.clip(0.3 * rng.normal(size=(n, 69)), -1, 1).astype(np.float32)
        o_c, r_c, te_c, tr_c, info_c = cpu.step(act)
        o_g, r_g, te_g, tr_g, info_g = gpu.step(torch.as_tensor(act))
        np.testing.assert_array_equal(te_g.numpy(), te_c, err_msg=f"terminated, step {step}")
        np.testing.assert_array_equal(tr_g.numpy(), tr_c, err_msg=f"truncated, step {step}")
        dq = np.abs(gpu.qpos.numpy() - _qpos_cpu(cpu)).max()
        assert dq < QPOS_ATOL, f"qpos differs by {dq} at step {step}"
        worst["qpos"] = max(worst["qpos"], dq)
        for k, tol in OBS_ATOL.items():
            d = np.abs(o_g[k].numpy() - o_c[k]).max()
            assert d <= tol, f"obs {k} differs by {d} at step {step}"
            worst[k] = max(worst[k], d)
        d = np.abs(r_g.numpy() - r_c).max()
        assert d < REWARD_ATOL, f"reward differs by {d} at step {step}"
        worst["reward"] = max(worst["reward"], d)
        for key in info_c[0]:
            if key.startswith("reward/"):
                # (energy is a power in W, thousands under random actions: compared relatively)
                np.testing.assert_allclose(info_g[key].numpy(), [i[key] for i in info_c],
                                           rtol=1e-4, atol=REWARD_ATOL, err_msg=key)  # fmt: skip
        amp_c = np.stack([i["amp_obs"] for i in info_c])
        d = np.abs(info_g["amp_obs"].numpy() - amp_c).max()
        assert d < AMP_ATOL, f"AMP window differs by {d} at step {step}"
        worst["amp"] = max(worst["amp"], d)
        depths = gpu.contact_depths()
        for i in range(n):
            if not (te_c[i] or tr_c[i]):
                c_i = _contacts_cpu(cpu.envs[i])
                d = _unmatched_depth(depths[i], c_i)
                assert d < GRAZING_M, f"contacts of world {i}, step {step}: {depths[i]}, C {c_i}"
                worst["unmatched_contact_m"] = max(worst["unmatched_contact_m"], d)
                contacts_checked += len(depths[i]) > 0
        done = te_c | tr_c
        if done.any():  # the same new episodes on both sides
            ends += int(done.sum())
            idx = np.flatnonzero(done)
            clips = rng.integers(0, 2, size=idx.size)
            starts = rng.integers(0, 200, size=idx.size)
            for i, c, s in zip(idx, clips, starts, strict=True):
                cpu.reset(int(i), options={"clip": int(c), "start": int(s)})
            mask = torch.zeros(n, dtype=torch.bool)
            mask[torch.as_tensor(idx)] = True
            gpu.reset(mask, torch.as_tensor(clips), torch.as_tensor(starts))
            # (the reset states: the clip's ground truth, rounded to float32)
            np.testing.assert_allclose(gpu.qpos.numpy()[idx], _qpos_cpu(cpu)[idx], atol=1e-6)
    print("largest differences:", {k: f"{v:.2e}" for k, v in worst.items()}, "episode ends:", ends)
    assert ends > 0  # (resets and terminations were exercised)
    assert contacts_checked > N_DECISIONS  # (contacts were compared, not empty sets)


def test_observe_after_reset_matches_cpu_env(pair):
    cpu, gpu, torch = pair
    for i, (c, s) in enumerate(STARTS):
        obs_c, _ = cpu.reset(i, options={"clip": c, "start": s})
        gpu.reset(torch.arange(cpu.num_envs) == i, torch.tensor([c]), torch.tensor([s]))
        obs_g = gpu.observe()
        for k, tol in OBS_ATOL.items():
            np.testing.assert_allclose(obs_g[k][i].numpy(), obs_c[k], atol=max(tol, 1e-5),
                                       err_msg=k)  # fmt: skip


def test_height_map_on_stairs_matches_cpu_env():
    """The height-map observation on a height-field scene (the stairs ahead of the run's late
    frames), from reset states: MuJoCo Warp's height-field contacts differ from MuJoCo C's
    (docs/gpu.md), so the physics on terrain is not compared step by step here."""
    import torch
    import warp as wp

    from envs.tracking_env import SAMPLE_REFERENCE, GripTrackingEnv
    from envs.warp.env import WarpTrackingEnv
    from grip.core.reference import ReferenceSet
    from grip.task.config import TrackingEnvConfig

    wp.config.quiet = True
    ref = ReferenceSet.load(SAMPLE_REFERENCE)
    cfg = TrackingEnvConfig(terrain="stairs")
    starts = torch.tensor([170, 185, 200])
    gpu = WarpTrackingEnv(cfg, ref, len(starts), nconmax=256, njmax=1200)
    gpu.reset(torch.ones(len(starts), dtype=torch.bool), torch.ones(len(starts), dtype=torch.int64),
              starts)  # fmt: skip
    obs_g = gpu.observe()
    cpu = GripTrackingEnv(cfg, ref)
    for i, s in enumerate(starts.tolist()):
        obs_c, _ = cpu.reset(options={"clip": 1, "start": s})
        assert np.ptp(obs_c["environment"]) > 0.1  # (a stair edge is in view)
        for k, tol in OBS_ATOL.items():
            np.testing.assert_allclose(obs_g[k][i].numpy(), obs_c[k], atol=max(tol, 1e-5),
                                       err_msg=k)  # fmt: skip


def test_each_world_has_its_subjects_model():
    """Every array of the batched warp model, read at a world, equals that of ``put_model`` of
    the world's own subject (up to the three arrays a step with sensors off never reads)."""
    import copy
    import dataclasses

    import mujoco
    import mujoco_warp as mjw
    import torch
    import warp as wp

    from envs.tracking_env import SAMPLE_REFERENCE
    from envs.warp.build import UNBATCHED_OK
    from envs.warp.env import WarpTrackingEnv
    from grip.core.reference import ReferenceSet
    from grip.task.config import TrackingEnvConfig

    wp.config.quiet = True
    env = WarpTrackingEnv(TrackingEnvConfig(), ReferenceSet.load(SAMPLE_REFERENCE), 2)
    env.reset(torch.ones(2, dtype=torch.bool), torch.tensor([1, 0]), torch.tensor([0, 0]))
    assert len(env.subject_models) == 2
    assert env.model.body_mass.shape[0] == 2  # (the subjects differ in masses: batched per world)
    for world, subject in ((0, 1), (1, 0)):
        own = copy.copy(env.subject_models[subject])
        own.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_SENSOR)
        with wp.ScopedDevice("cpu"):
            ref = mjw.put_model(own)
        differ = []
        for f in dataclasses.fields(mjw.Model):
            a, b = getattr(ref, f.name, None), getattr(env.model, f.name, None)
            if not isinstance(a, wp.array):
                continue
            want, got = a.numpy(), b.numpy()
            if got.shape[0] == 2 and want.shape[0] == 1 and got.shape[1:] == want.shape[1:]:
                got = got[world : world + 1]
            if want.shape != got.shape or not np.allclose(want, got, atol=1e-6, equal_nan=True):
                differ.append(f.name)
        assert set(differ) <= UNBATCHED_OK, differ


FALL_STARTS = ((0, 30), (1, 20), (0, 120), (1, 150))
FALL_DECISIONS = 30
LIFT_M = 0.1


@pytest.mark.parametrize(("below_m", "falls"), [(0.2, False), (0.0, True)])
def test_fall_below_reference_matches_cpu_env(below_m, falls):
    """``fall_below_reference_m``: terminations equal the CPU env's where the setting decides.

    The ground truth of both clips is lifted 0.1 m (it floats), and ``fall_height_m`` = 1.5 m
    is above both pelvises: every pelvis is "low" and so is its reference, as on a clip on the
    floor under the teacher's 0.3 m. The simulated body starts at the truth and drops onto the
    floor, so its pelvis is 0 to 0.2 m below the truth's for the whole test: with the setting
    at 0.2 m no world falls, with 0 every world falls at its first decision. The pelvis stays at
    least 0.5 mm away from the threshold (checked), far beyond float32 rounding.
    """
    import dataclasses

    import torch
    import warp as wp

    from envs.tracking_env import SAMPLE_REFERENCE
    from grip.core.reference import ReferenceSet
    from grip.task.config import TrackingEnvConfig

    wp.config.quiet = True
    sample = ReferenceSet.load(SAMPLE_REFERENCE)
    clips = []
    for c in sample.clips:
        q = c.gt_qpos.copy()
        q[:, 2] += LIFT_M
        clips.append(dataclasses.replace(c, gt_qpos=q))
    ref = ReferenceSet(clips, sample.sensor_sites, sample.insoles)
    cfg = TrackingEnvConfig(termination_dist_m=0.0, fall_height_m=1.5,
                            fall_below_reference_m=below_m)  # fmt: skip
    cpu, gpu, n = _cpu_and_warp_at_fall_starts(cfg, ref)
    first_fall = np.full(n, -1)
    try:
        for step in range(FALL_DECISIONS):
            act = np.zeros((n, 69), np.float32)
            _, _, te_c, tr_c, info_c = cpu.step(act)
            _, _, te_g, tr_g, info_g = gpu.step(torch.as_tensor(act))
            np.testing.assert_array_equal(te_g.numpy(), te_c, err_msg=f"terminated, step {step}")
            np.testing.assert_array_equal(tr_g.numpy(), tr_c, err_msg=f"truncated, step {step}")
            z = np.array([i["root_height_m"] for i in info_c])
            np.testing.assert_allclose(info_g["root_height_m"].numpy(), z, atol=1e-4)
            gt_z = np.array([ref.clip(i["clip_index"]).gt_pos[i["frame"], 0, 2] for i in info_c])
            assert np.all(z < cfg.fall_height_m) and np.all((z < gt_z) & (z > gt_z - 0.2))
            assert np.abs(z - (gt_z - below_m)).min() > 5e-4, "too close to the threshold"
            first_fall[(first_fall < 0) & te_c] = step
            if te_c.any():
                break  # (a finished episode is not stepped on)
    finally:
        cpu.close()
    if falls:
        np.testing.assert_array_equal(first_fall, 0)
    else:
        np.testing.assert_array_equal(first_fall, -1)
        assert step == FALL_DECISIONS - 1


GAP_LIMIT_M = 0.1


def test_pelvis_gap_termination_matches_cpu_env():
    """``termination_root_gap_m``: a body given zero actions sinks where it stands while its
    reference moves on; the Warp env ends the same episodes at the same decision as the CPU
    env, until the first one ends (at least one does; the gaps, read back from the CPU env's
    ``root_pos`` kernel, stay 0.5 mm away from the limit, beyond float32 rounding)."""
    import torch
    import warp as wp

    from envs.tracking_env import SAMPLE_REFERENCE
    from grip.core.reference import ReferenceSet
    from grip.task.config import TrackingEnvConfig

    wp.config.quiet = True
    ref = ReferenceSet.load(SAMPLE_REFERENCE)
    cfg = TrackingEnvConfig(termination_dist_m=0.0, termination_root_gap_m=GAP_LIMIT_M)
    cpu, gpu, n = _cpu_and_warp_at_fall_starts(cfg, ref)
    k = cfg.reward.k_root_pos
    ended = False
    try:
        for step in range(FALL_DECISIONS):
            act = np.zeros((n, 69), np.float32)
            _, _, te_c, _, info_c = cpu.step(act)
            _, _, te_g, _, _ = gpu.step(torch.as_tensor(act))
            gap = np.sqrt(-np.log([i["reward/root_pos"] for i in info_c]) / k)
            assert np.abs(gap - GAP_LIMIT_M).min() > 5e-4, "too close to the limit"
            np.testing.assert_array_equal(te_c, gap > GAP_LIMIT_M)
            np.testing.assert_array_equal(te_g.numpy(), te_c, err_msg=f"terminated, step {step}")
            if te_c.any():
                ended = True
                break  # (a finished episode is not stepped on)
    finally:
        cpu.close()
    assert ended


def test_clip_weights_choose_the_clips_drawn():
    """``set_clip_weights`` (hard-clip mining): a reset draws clips by length times the
    weights, so a clip of weight 0 is never drawn; bad weights are refused as on the CPU."""
    import torch
    import warp as wp

    from envs.tracking_env import SAMPLE_REFERENCE
    from envs.warp.env import WarpTrackingEnv
    from grip.core.reference import ReferenceSet
    from grip.task.config import TrackingEnvConfig

    wp.config.quiet = True
    n = 16
    env = WarpTrackingEnv(TrackingEnvConfig(), ReferenceSet.load(SAMPLE_REFERENCE), n, seed=3)
    everyone = torch.ones(n, dtype=torch.bool)
    assert set(env.clip_index.tolist()) == {0, 1}  # (by length: both clips are 250 frames)
    for only in (0, 1):
        w = np.zeros(2)
        w[only] = 2.5
        env.set_clip_weights(w)
        for _ in range(3):
            env.reset(everyone)
            np.testing.assert_array_equal(env.clip_index.numpy(), only)
    env.set_clip_weights([1.0, 1.0])
    env.reset(everyone)
    assert set(env.clip_index.tolist()) == {0, 1}
    for bad in ([1.0], [1.0, -0.5], [1.0, np.nan], [0.0, 0.0]):
        with pytest.raises(ValueError, match="clip weights"):
            env.set_clip_weights(bad)


def test_start_bins_and_clip_termination_distances():
    """``set_start_bin_weights``: resets draw their start frames in the weighted bins (clip 0
    only in its second second, clip 1 only in its third), ``None`` restores the uniform draw;
    ``set_clip_termination_dists``: every world's distance is its clip's, now and after each
    reset (the CPU env's hooks, for failure-weighted starts and per-category termination)."""
    import torch
    import warp as wp

    from envs.tracking_env import SAMPLE_REFERENCE
    from envs.warp.env import WarpTrackingEnv
    from grip.core.reference import ReferenceSet
    from grip.task.config import TrackingEnvConfig

    wp.config.quiet = True
    n = 16
    env = WarpTrackingEnv(TrackingEnvConfig(), ReferenceSet.load(SAMPLE_REFERENCE), n, seed=5)
    everyone = torch.ones(n, dtype=torch.bool)
    env.set_start_bin_weights(100, [np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 3.0])])
    for _ in range(3):
        env.reset(everyone)
        clip, frame = env.clip_index.numpy(), env.frame.numpy()
        lo = np.where(clip == 0, 100, 200)
        assert ((frame >= lo) & (frame < lo + 100) & (frame <= 239)).all(), (clip, frame)
    env.set_start_bin_weights(100, None)
    env.reset(everyone)
    assert (env.frame.numpy() < 100).any()
    env.set_clip_termination_dists([0.3, 0.0])
    np.testing.assert_allclose(env.termination_dist_m.numpy(),
                               np.where(env.clip_index.numpy() == 0, 0.3, 0.0))  # fmt: skip
    env.set_clip_termination_dists([0.0, 0.7])
    env.reset(everyone)
    np.testing.assert_allclose(env.termination_dist_m.numpy(),
                               np.where(env.clip_index.numpy() == 0, 0.0, 0.7),
                               rtol=1e-6)  # fmt: skip
    with pytest.raises(ValueError, match="clip termination"):
        env.set_clip_termination_dists([0.1])
    with pytest.raises(ValueError, match="one entry per clip"):
        env.set_start_bin_weights(100, [np.ones(3)])


def _cpu_and_warp_at_fall_starts(cfg, ref):
    """The batched CPU env and the Warp env (on the CPU device) of ``cfg`` and ``ref``, one
    environment per :data:`FALL_STARTS` entry, each reset to its clip and start frame."""
    import torch

    from envs.batched import BatchedTrackingEnv
    from envs.tracking_env import GripTrackingEnv
    from envs.warp.env import WarpTrackingEnv

    n = len(FALL_STARTS)
    envs = [GripTrackingEnv(cfg, ref) for _ in FALL_STARTS]
    for e in envs:
        e.reset(seed=0)
    cpu = BatchedTrackingEnv(envs, threads=1)
    gpu = WarpTrackingEnv(cfg, ref, n, device="cpu")
    for i, (c, s) in enumerate(FALL_STARTS):
        cpu.reset(i, options={"clip": c, "start": s})
    gpu.reset(torch.ones(n, dtype=torch.bool), torch.tensor([c for c, _ in FALL_STARTS]),
              torch.tensor([s for _, s in FALL_STARTS]))  # fmt: skip
    return cpu, gpu, n
