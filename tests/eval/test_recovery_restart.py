"""Where the humanoid restarts after a fall (issue 46, part 4): GRIP's rule (the simulated
pelvis before the fall plus the estimated displacement) or the estimate's own pelvis."""

from __future__ import annotations

import numpy as np
import pytest

from envs.tracking_env import SAMPLE_REFERENCE
from grip.core.reference import ReferenceSet
from grip.pipeline import GripPipeline, RecoveryConfig, kinematic_frames, start_from_clip
from grip.task.config import TrackingEnvConfig


class _Collapse:
    """A policy that drops the humanoid (actions -1) and a discriminator that calls it a fall;
    before frame ``drag_until`` it also holds the pelvis back horizontally, so the humanoid
    falls behind the estimate first."""

    def __init__(self, drag_until: int) -> None:
        self.disc, self.env_cfg = object(), TrackingEnvConfig(amp_window=2)
        self.drag_until, self.player = drag_until, None

    def act(self, obs: dict) -> np.ndarray:
        p = self.player
        if p is not None and p.t < self.drag_until:
            p.h.qvel[:2] = 0.0  # (standing still while the estimate walks on)
            return np.zeros(69)
        return np.full(69, -1.0)

    def fall_probability(self, amp_obs):
        return np.array([0.0])


@pytest.fixture(scope="module")
def clip():
    return ReferenceSet.load(SAMPLE_REFERENCE).clip(0)


def _play(clip, restart: str):
    runner = _Collapse(drag_until=40)
    pipe = GripPipeline(runner, None, RecoveryConfig(history_frames=10, restart=restart))
    player = runner.player = pipe.player(clip.body, clip.objects)
    player.start(clip, start_from_clip(clip), clip.name, clip.fps)
    while not player.advance():
        pass
    return player.reconstruction(1.0)


@pytest.mark.parametrize("restart", ["simulated", "estimate"])
def test_the_restart_puts_the_root_where_it_says(clip, restart) -> None:
    recon = _play(clip, restart)
    assert recon.fell
    s, t = recon.falls[0]
    est = recon.ref_root_pos  # the estimate's own pelvis
    root0 = recon.joint_pos[s, 0] if restart == "simulated" else est[s]
    pos, _ = kinematic_frames(clip, root0, s, t)
    np.testing.assert_allclose(recon.joint_pos[s : t + 1], pos, atol=1e-9)
    behind = float(np.linalg.norm(recon.joint_pos[t, 0, :2] - est[t, :2]))
    if restart == "estimate":  # no distance lost before the fall is kept
        assert behind < 1e-6
    else:  # the humanoid had been held back: GRIP's rule keeps that gap
        assert behind > 0.1


def test_an_unknown_restart_is_refused() -> None:
    with pytest.raises(ValueError, match="restart"):
        RecoveryConfig(restart="teleport")


class _StandStill(_Collapse):
    """Holds the pelvis still (the estimate walks on) and never falls: the discriminator calls
    every low pelvis human."""

    def __init__(self) -> None:
        super().__init__(drag_until=10**9)

    def fall_probability(self, amp_obs):
        return np.array([1.0])


def _stand(clip, lost_gap_m: float):
    runner = _StandStill()
    pipe = GripPipeline(runner, None, RecoveryConfig(history_frames=10, lost_gap_m=lost_gap_m))
    player = runner.player = pipe.player(clip.body, clip.objects)
    player.start(clip, start_from_clip(clip), clip.name, clip.fps)
    while not player.advance():
        pass
    recon = player.reconstruction(1.0)
    gap = np.linalg.norm(recon.joint_pos[:, 0, :2] - recon.ref_root_pos[:, :2], axis=1)
    return recon, gap


def test_a_humanoid_left_behind_is_lost_and_recovered_at_the_estimate(clip) -> None:
    recon, gap = _stand(clip, 0.0)  # off: it stands while the estimate walks away
    assert recon.notes["lost"] == 0 and not recon.fell and gap[-1] > 0.5
    recon, gap = _stand(clip, 0.3)
    n = recon.notes["lost"]
    assert n >= 1 and recon.falls.shape[0] == n  # each one an event, reported as a fall
    s, t = recon.falls[0]
    assert gap[t - 1] < 0.3 + 0.05 and gap[t] < 1e-6  # put back on the estimate's pelvis
    pos, _ = kinematic_frames(clip, recon.ref_root_pos[s], s, t)
    np.testing.assert_allclose(recon.joint_pos[s : t + 1], pos, atol=1e-9)  # the buffer
    assert gap.max() < 0.3 + 0.05  # never farther than the threshold (one frame's walk)


def test_the_bench_and_the_player_default_alike() -> None:
    from grip.eval.methods import MethodOptions

    assert MethodOptions().recovery() == RecoveryConfig()


def test_a_negative_lost_gap_is_refused() -> None:
    with pytest.raises(ValueError, match="lost_gap_m"):
        RecoveryConfig(lost_gap_m=-0.1)


def test_bench_and_reconstruct_refuse_a_negative_lost_gap(tmp_path, capsys) -> None:
    from grip.assets import SAMPLE_RECORDING
    from grip.cli.main import main

    assert main(["reconstruct", str(SAMPLE_RECORDING), "--out", str(tmp_path / "r"),
                 "--lost-gap", "-1"]) == 2  # fmt: skip
    assert "--lost-gap must be >= 0" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()
    assert main(["bench", "--data", str(tmp_path), "--methods", "grip", "--out",
                 str(tmp_path / "b"), "--lost-gap", "-1"]) == 2  # fmt: skip
    assert "--lost-gap must be >= 0" in capsys.readouterr().err
