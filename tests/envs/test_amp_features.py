"""AMP observations: simulated and ground-truth frames agree, heading invariance, windows."""

from __future__ import annotations

import numpy as np
import pytest

from envs.tracking_env import GripTrackingEnv
from grip.core.rotations import axis_angle_to_matrix
from grip.task import amp as A
from grip.task.config import TrackingEnvConfig


def test_simulated_frame_matches_ground_truth_at_reset(reference):
    env = GripTrackingEnv(TrackingEnvConfig(amp_window=4), reference)
    _, info = env.reset(seed=0, options={"clip": 0, "start": 20})
    ref = A.reference_amp_features(env.clip)
    window = info["amp_obs"].reshape(4, A.FRAME_DIM)
    np.testing.assert_allclose(window, ref[17:21], atol=1e-5)  # ground-truth history
    sim = env._amp_frame(*env.humanoid.state())
    # the state is written from the ground truth: only finite-difference velocities differ
    np.testing.assert_allclose(sim, ref[20], atol=5e-3)
    _, _, _, _, info = env.step(np.zeros(env.action_space.shape))
    w = info["amp_obs"].reshape(4, A.FRAME_DIM)
    np.testing.assert_allclose(w[:3], window[1:], atol=1e-6)  # the window moved by one frame
    assert not np.allclose(w[3], window[3])


def test_features_ignore_heading_and_position():
    rng = np.random.default_rng(0)
    t = 5
    rot = axis_angle_to_matrix(rng.normal(size=(t, 3)))
    args = [
        rng.normal(size=(t, 3)),
        rot,
        rng.normal(size=(t, 3)),
        rng.normal(size=(t, 3)),
        rng.normal(size=(t, 69)),
        rng.normal(size=(t, 69)),
        rng.normal(size=(t, 4, 3)),
    ]
    f0 = A.amp_features(*args)
    yaw = axis_angle_to_matrix(np.array([0.0, 0.0, 1.3]))
    shift = np.array([4.0, -2.0, 0.0])
    moved = [
        args[0] @ yaw.T + shift,
        yaw @ rot,
        args[2] @ yaw.T,
        args[3] @ yaw.T,
        args[4],
        args[5],
        args[6] @ yaw.T + shift,
    ]
    np.testing.assert_allclose(A.amp_features(*moved), f0, atol=1e-9)
    assert f0.shape == (t, A.FRAME_DIM)


def test_windows_repeat_the_first_frame_and_history_rolls():
    frames = np.arange(4 * A.FRAME_DIM, dtype=float).reshape(4, A.FRAME_DIM)
    w = A.windows(frames, 3).reshape(4, 3, A.FRAME_DIM)
    np.testing.assert_array_equal(w[0], frames[[0, 0, 0]])
    np.testing.assert_array_equal(w[3], frames[[1, 2, 3]])
    h = A.AmpHistory(3)
    h.reset(frames[:2])
    np.testing.assert_array_equal(h.vector().reshape(3, -1), frames[[0, 0, 1]])
    h.push(frames[3])
    np.testing.assert_array_equal(h.vector().reshape(3, -1), frames[[0, 1, 3]])
    with pytest.raises(ValueError, match="window"):
        A.AmpHistory(0)


def test_amp_window_zero_leaves_it_out_and_fall_height_terminates(reference):
    env = GripTrackingEnv(TrackingEnvConfig(amp_window=0, fall_height_m=5.0,
                                            termination_dist_m=0.0), reference)  # fmt: skip
    _, info = env.reset(seed=0)
    assert "amp_obs" not in info and info["root_height_m"] > 0.5
    _, _, terminated, _, info = env.step(np.zeros(env.action_space.shape))
    assert terminated and "amp_obs" not in info  # the pelvis is always below 5 m
