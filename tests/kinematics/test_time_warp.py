"""Time-warp augmentation of KinematicsNet's training windows (``train.time_warp``)."""

import dataclasses

import numpy as np
import pytest

from grip.kinematics.config import KinematicsRunConfig, TrainConfig
from grip.kinematics.dataset import sample_windows, sequence_arrays, time_warp_rates
from grip.kinematics.features import FeatureConfig
from grip.kinematics.train import Trainer
from grip.motion.motion import Motion
from prism_tools.synth import recording_from_motion
from prism_tools.synthetic import make_recording

CFG = FeatureConfig()
N_SITES = len(CFG.sites)


def _first(m: Motion, n: int = 300) -> Motion:
    assert m.fps == 100.0
    return dataclasses.replace(m, root_pos=m.root_pos[:n], local_quat=m.local_quat[:n])


def _played_at(m: Motion, speed: float) -> Motion:
    """The same motion played ``speed`` times faster, sampled at the same frame rate. Cubic
    splines (of the root and of the sign-continuous quaternions, renormalised): a piecewise
    linear resampling would put acceleration spikes at the original frames."""
    from scipy.interpolate import CubicSpline

    n = len(m.root_pos)
    t = np.arange(n) / m.fps
    new_t = speed * np.arange(int(np.floor((n - 1) / speed)) + 1) / m.fps
    # q and -q are the same rotation: keep neighbouring frames on one side before splining
    q = m.local_quat.copy()
    sign = np.where(np.sum(q[1:] * q[:-1], axis=-1) < 0, -1.0, 1.0)
    q[1:] *= np.cumprod(sign, axis=0)[..., None]
    q_new = CubicSpline(t, q, axis=0)(new_t)
    q_new /= np.linalg.norm(q_new, axis=-1, keepdims=True)
    return dataclasses.replace(m, root_pos=CubicSpline(t, m.root_pos, axis=0)(new_t),
                               local_quat=q_new)  # fmt: skip


def test_speed_one_reads_the_same_frames_as_whole_frame_sampling():
    seqs = [sequence_arrays(make_recording(150, seed=s), CFG) for s in (0, 1)]
    x0, y0 = sample_windows(seqs, 6, 80, np.random.default_rng(4))
    x1, y1 = sample_windows(seqs, 6, 80, np.random.default_rng(4), speeds=np.ones(6))
    np.testing.assert_array_equal(x0, x1)
    for k in y0:
        np.testing.assert_array_equal(y0[k], y1[k])
    with pytest.raises(ValueError, match="speeds"):
        sample_windows(seqs, 6, 80, np.random.default_rng(4), speeds=np.zeros(6))


@pytest.mark.parametrize("speed", [0.8, 1.25])
def test_warped_window_matches_the_sensors_of_the_motion_played_at_that_speed(speed, cmu_walk):
    # Synthesise clean sensors from a motion and from the same motion played faster or slower
    # (an independent path through the body model, IMU and insole synthesis): the time-warped
    # window of the first must match the second, and much better than with the rates unscaled.
    m = _first(cmu_walk)  # a real walk (CMU 07_05)
    a = sequence_arrays(recording_from_motion(m, noise=False), CFG)
    b = sequence_arrays(recording_from_motion(_played_at(m, speed), noise=False), CFG)
    n = len(b.x)
    x, y = sample_windows([a], 1, n, np.random.default_rng(0), speeds=np.array([speed]))
    xw, yw = time_warp_rates(x, y, np.array([speed]), N_SITES, True)
    inner = slice(15, n - 15)  # away from the low-pass filter's start and the ends

    def err(u, v):
        return float(np.abs(u[0, inner] - v[inner]).mean())

    imu = lambda arr, c: arr[..., : 15 * N_SITES].reshape(*arr.shape[:-1], N_SITES, 15)[..., c]  # noqa: E731
    # The synthesis smooths accelerations over a fixed time (a second difference over 7 frames,
    # then a low-pass; insole forces a 0.1 s Savitzky-Golay), which a warp of the recording
    # cannot reproduce at another speed: accelerations and forces get closer, not equal.
    for c, name, factor in ((slice(0, 3), "acc", 0.6), (slice(3, 6), "gyr", 0.1)):
        ours, plain = err(imu(xw, c), imu(b.x, c)), err(imu(x, c), imu(b.x, c))
        assert ours < factor * plain, (name, ours, plain)
    ori = slice(6, 15)
    assert err(imu(xw, ori), imu(b.x, ori)) < 0.01
    ours, plain = err(yw["lv"], b.y["lv"]), err(y["lv"], b.y["lv"])
    assert ours < 0.2 * plain and ours < 0.02, (ours, plain)
    for k in ("lp", "fp", "fa"):
        assert err(yw[k], b.y[k]) < 2e-3, k
    force = [15 * N_SITES, 15 * N_SITES + 5]
    assert err(xw[..., force], b.x[:, force]) < err(x[..., force], b.x[:, force])
    contacts = [15 * N_SITES + 3, 15 * N_SITES + 4, 15 * N_SITES + 8, 15 * N_SITES + 9]
    assert set(np.unique(xw[..., contacts])) <= {0.0, 1.0}
    # contact flags follow the (smoothed) forces, so a few frames at each transition differ
    assert np.mean(xw[0, inner][:, contacts] == b.x[inner][:, contacts]) > 0.8


def test_unknown_targets_and_bad_settings_are_refused():
    x = np.zeros((1, 5, 15 * N_SITES + 10), np.float32)
    with pytest.raises(ValueError, match="no rule"):
        time_warp_rates(x, {"other": np.zeros((1, 5, 3))}, np.ones(1), N_SITES, True)
    with pytest.raises(ValueError, match="time_warp"):
        TrainConfig(time_warp=-0.1)
    with pytest.raises(ValueError, match="category_balance"):
        TrainConfig(category_balance=2.0)


def test_training_with_time_warp_and_category_balance_lowers_the_loss(tmp_path):
    seqs = [sequence_arrays(make_recording(160, seed=s), CFG) for s in range(3)]
    cfg = KinematicsRunConfig(hidden=16, layers=1, init_hidden=16, train=TrainConfig(
        window_frames=40, batch_size=8, steps_per_epoch=1, stage_epochs=0, joint_epochs=1,
        time_warp=0.25, category_balance=0.5, val_windows=4))  # fmt: skip
    tr = Trainer(cfg, seqs, seqs[:1], tmp_path)
    assert tr.train_weights is not None and tr.train_weights.shape == (3,)
    first = [tr.train_step("joint", 3e-3)[1].item() for _ in range(3)]
    for _ in range(40):
        tr.train_step("joint", 3e-3)
    last = [tr.train_step("joint", 3e-3)[1].item() for _ in range(3)]
    assert np.mean(last) < np.mean(first)
