"""The lean keeper (docs/pace.md, hypothesis 12): the followed upper body leans forward by gain
x the humanoid's lag behind the estimate along the travel, in what the controller observes and
in the spine's PD target (on by default: 20 deg per metre)."""

from __future__ import annotations

import numpy as np
import pytest

from envs.tracking_env import SAMPLE_REFERENCE
from grip.core.reference import ReferenceSet, hinge_angles
from grip.pipeline import GripPipeline, PaceKeeper, RecoveryConfig, start_from_clip
from grip.task.config import TrackingEnvConfig
from grip.task.observations import UPPER_BODY, lean_hinges, leaned


def _angle_deg(r: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0))))


def test_the_lean_is_gain_times_the_lag_along_the_travel_capped() -> None:
    fwd = np.array([0.0, 1.3])  # the estimate walks along +y
    assert PaceKeeper(lean_gain_deg=0.0).lean([0.0, 1.0], np.zeros(2), fwd) is None  # off
    keeper = PaceKeeper(lean_gain_deg=20.0, lean_max_deg=5.0)
    assert keeper.lean([0.0, -0.2], np.zeros(2), fwd) is None  # the humanoid is ahead
    assert keeper.lean([0.0, 0.2], np.zeros(2), [0.05, 0.0]) is None  # the estimate stands
    r = keeper.lean([0.3, 0.1], np.zeros(2), fwd)  # 0.1 m behind along y (the 0.3 across: none)
    assert _angle_deg(r) == pytest.approx(2.0, abs=1e-9)
    up = r @ np.array([0.0, 0.0, 1.0])
    assert up[1] > 0 and abs(up[0]) < 1e-12  # the vertical turns towards the travel
    assert _angle_deg(keeper.lean([0.0, 3.0], np.zeros(2), fwd)) == pytest.approx(5.0)
    with pytest.raises(ValueError, match="lean_gain_deg"):
        PaceKeeper(lean_gain_deg=-1.0)


@pytest.fixture(scope="module")
def clip():
    return ReferenceSet.load(SAMPLE_REFERENCE).clip(0)


def test_a_leaned_frame_turns_the_upper_body_and_the_spine_hinges_alone(clip) -> None:
    from grip.core.rotations import axis_angle_to_matrix

    t, lean = 40, axis_angle_to_matrix(np.array([0.0, 1.0, 0.0]) * np.radians(4.0))
    pos, rot, vel = leaned(clip.est_pos[t], clip.est_rot[t], clip.est_vel[t], lean)
    up, legs = list(UPPER_BODY), [0, 1, 2, 4, 5, 7, 8, 10, 11]
    np.testing.assert_allclose(pos[up], clip.est_pos[t, up] @ lean.T)
    np.testing.assert_array_equal(pos[legs], clip.est_pos[t, legs])
    np.testing.assert_allclose(rot[up], lean @ clip.est_rot[t, up])
    np.testing.assert_array_equal(rot[legs], clip.est_rot[t, legs])
    np.testing.assert_array_equal(vel[-1], clip.est_vel[t, -1])  # the pelvis' velocity
    rel = clip.est_vel[t, 0] - clip.est_vel[t, -1]  # (a wrist's, relative to the pelvis')
    np.testing.assert_allclose(vel[0] - vel[-1], rel @ lean.T)
    np.testing.assert_array_equal(vel[2], clip.est_vel[t, 2])  # (an ankle's)
    # all frames at once, each its own lean: the same as frame by frame
    leans = np.stack([lean, lean.T])
    many = leaned(clip.est_pos[t : t + 2], clip.est_rot[t : t + 2], clip.est_vel[t : t + 2], leans)
    np.testing.assert_allclose(many[0][0], pos)
    np.testing.assert_allclose(many[1][1], leaned(clip.est_pos[t + 1], clip.est_rot[t + 1],
                                                  clip.est_vel[t + 1], lean.T)[1])  # fmt: skip
    # the hinge change is what the whole pose's hinges say, and only the spine's first joint's
    glob = clip.est_rot[t - 1 : t + 1].copy()
    turned = glob.copy()
    turned[:, up] = lean @ glob[:, up]
    want = hinge_angles(turned)[-1] - hinge_angles(glob)[-1]
    got = lean_hinges(clip.est_rot[t], lean)
    np.testing.assert_allclose(got, np.angle(np.exp(1j * want)), atol=1e-9)
    assert np.count_nonzero(np.abs(got) > 1e-12) <= 3 and np.abs(got[6:9]).max() > 0.01


class _StandStill:
    """Holds the humanoid's pelvis still horizontally (the estimate walks away) and records the
    observations' followed joints and the spine's PD targets."""

    def __init__(self) -> None:
        self.disc, self.env_cfg = None, TrackingEnvConfig(kinematic_obs="OAV_Jrel_root",
                                                          amp_window=0)  # fmt: skip
        self.player, self.obs = None, []

    def act(self, obs: dict) -> np.ndarray:
        self.obs.append(np.array(obs["kinematic"], dtype=np.float64))
        self.player.h.qvel[:2] = 0.0
        return np.zeros(69)


def _play(clip, pace: PaceKeeper, frames: int = 60):
    runner = _StandStill()
    pipe = GripPipeline(runner, None, RecoveryConfig(enabled=False), pace)
    player = runner.player = pipe.player(clip.body, clip.objects)
    player.start(clip, start_from_clip(clip), clip.name, clip.fps)
    targets = []
    h = player.h
    set_targets = h.set_targets

    def record(q):
        targets.append(np.array(q, dtype=np.float64))
        set_targets(q)

    h.set_targets = record
    while player.t < frames and not player.advance():
        pass
    return np.array(runner.obs), np.array(targets)


def test_a_humanoid_left_behind_follows_a_leaned_trunk(clip) -> None:
    obs_off, tgt_off = _play(clip, PaceKeeper(gain=0.0, lean_gain_deg=0.0))
    obs_on, tgt_on = _play(clip, PaceKeeper(gain=0.0, lean_gain_deg=20.0, lean_max_deg=5.0))
    spine = slice(6, 9)  # (joint 3's hinges)
    assert np.abs(tgt_on[:, spine] - tgt_off[:, spine]).max() > np.radians(0.5)
    n = min(len(tgt_on), len(tgt_off))
    legs = [k for k in range(69) if k // 3 + 1 in (1, 2, 4, 5, 7, 8, 10, 11)]
    np.testing.assert_allclose(tgt_on[:n, legs], tgt_off[:n, legs], atol=1e-9)
    assert not np.allclose(obs_on, obs_off)


def test_bench_refuses_a_bad_lean_by_name(walk_takes, tmp_path, capsys) -> None:
    from grip.cli.main import main

    assert main(["bench", "--data", str(walk_takes), "--methods", "grip", "--out",
                 str(tmp_path / "b"), "--lean-gain", "-1"]) == 2  # fmt: skip
    assert "--lean-gain -1" in capsys.readouterr().err
