"""GRIP's reconstruction loop: outputs, fall detection and history-buffer recovery.

A scripted policy stands in for a trained one: zero actions follow the KinematicsNet estimate
with the PD servos; actions of -1 make the humanoid collapse. A scripted discriminator decides
whether a low pelvis counts as a fall.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from envs.tracking_env import SAMPLE_REFERENCE
from grip.core.body import GRAVITY
from grip.core.reference import ReferenceSet
from grip.pipeline import GripPipeline, RecoveryConfig, kinematic_frames, start_from_clip
from grip.task.config import TrackingEnvConfig


class _Runner:
    """Policy stand-in: a constant action; ``prob`` is the discriminator's answer."""

    def __init__(self, action: float, prob: float | None = 0.0) -> None:
        self.action = action
        self.prob = prob
        self.disc = None if prob is None else object()
        self.env_cfg = TrackingEnvConfig(amp_window=2)

    def act(self, obs: dict) -> np.ndarray:
        return np.full(69, self.action)

    def fall_probability(self, amp_obs: np.ndarray) -> np.ndarray:
        return np.array([self.prob])


@pytest.fixture(scope="module")
def clip():
    return ReferenceSet.load(SAMPLE_REFERENCE).clip(0)


def simulate_clip(clip, runner, recovery: RecoveryConfig, stop_at_fall: bool = False):
    """The pipeline's player on a reference clip's estimate from its first frame (the player is
    left on ``runner.player`` for runners that reach into the simulation)."""
    pipe = GripPipeline(runner, None, recovery)
    player = runner.player = pipe.player(clip.body, clip.objects, stop_at_fall)
    player.start(clip, start_from_clip(clip), clip.name, clip.fps)
    while not player.advance():
        pass
    return player.reconstruction(1.0), {"blowups": player.blowups}


def test_following_the_estimate_gives_a_full_physical_reconstruction(clip) -> None:
    # PD servos alone on the estimate (no policy) keep a walk up for ~80 frames: look at those
    recon, info = simulate_clip(clip, _Runner(0.0), RecoveryConfig())
    assert recon.n_frames == clip.n_frames and recon.method == "grip" and info["blowups"] == 0
    np.testing.assert_allclose(recon.joint_pos[0], clip.gt_pos[0], atol=1e-6)  # GT start
    first = recon.falls[0, 0] if recon.fell else recon.n_frames
    assert first > 40
    recon = recon.slice_frames(0, first)
    assert recon.torques.shape == (first, 69) and np.isfinite(recon.torques).all()
    weight = clip.body.mass_kg * GRAVITY
    # over the clip the feet carry the body: mean total vertical force ~ body weight
    assert 0.7 * weight < np.nanmean(recon.grf[:, :, 2].sum(axis=1)) < 1.5 * weight
    # (the PD servos alone stumble: 80 % of the frames touch the floor on the bundled walk)
    assert recon.contacts.any(axis=1).mean() > 0.7
    on = recon.contacts[:, 0]
    assert np.isfinite(recon.cop[on, 0]).all()
    assert np.isnan(recon.cop[recon.grf[:, 0, 2] == 0, 0]).all()
    # CoP of a loaded foot lies under that foot (within its length)
    d = np.linalg.norm(recon.cop[on, 0, :2] - recon.joint_pos[on, 7, :2], axis=1)
    assert np.median(d) < 0.2
    assert recon.ms_per_frame > 0


def test_a_fall_is_recovered_from_the_history_buffer(clip) -> None:
    rec_cfg = RecoveryConfig(history_frames=20)
    recon, _ = simulate_clip(clip, _Runner(-1.0, prob=0.0), rec_cfg)
    assert recon.n_frames == clip.n_frames and recon.fell
    s, t = recon.falls[0]
    assert t - s == 20 and t > 0
    # the fall's frames are the buffered estimate on a root integrated from frame s
    pos, rot = kinematic_frames(clip, recon.joint_pos[s, 0], s, t)
    np.testing.assert_allclose(recon.joint_pos[s + 1 : t + 1], pos[1:], atol=1e-9)
    np.testing.assert_allclose(recon.global_rot[s : t + 1], rot, atol=1e-9)
    assert np.isnan(recon.torques[s : t + 1]).all() and not recon.contacts[s : t + 1].any()
    # right after the reset the body stands again, on the ground
    assert recon.joint_pos[t + 1, 0, 2] > rec_cfg.fall_height_m
    # the estimate's pelvis is kept where the episode started it: the recovery re-anchors what
    # the policy follows on the humanoid, not this record of the estimate (pace metrics)
    offset = start_from_clip(clip).qpos[:3] - clip.est_root_pos[0]
    np.testing.assert_allclose(recon.ref_root_pos, clip.est_root_pos + offset, atol=1e-12)


def test_a_human_looking_low_pelvis_is_not_a_fall(clip) -> None:
    # (lost off: the collapsed body, left behind by the estimate, would be recovered as lost)
    recon, _ = simulate_clip(clip, _Runner(-1.0, prob=0.9), RecoveryConfig(lost_gap_m=0.0))
    assert not recon.fell


def test_without_recovery_each_fall_is_reported_once_and_the_body_stays_down(clip) -> None:
    recon, _ = simulate_clip(clip, _Runner(-1.0, prob=0.0), RecoveryConfig(enabled=False))
    assert recon.falls.shape == (1, 2) and recon.falls[0, 0] == recon.falls[0, 1]
    assert recon.joint_pos[-1, 0, 2] < 0.3


def test_evaluation_mode_stops_at_the_first_fall(clip) -> None:
    recon, _ = simulate_clip(clip, _Runner(-1.0, prob=0.0), RecoveryConfig(enabled=False),
                             stop_at_fall=True)  # fmt: skip
    assert recon.falls.tolist() == [[recon.n_frames - 1] * 2]
    assert recon.joint_pos[-1, 0, 2] < 0.3 < recon.joint_pos[0, 0, 2]


def test_teleport_puts_the_body_on_the_ground(clip) -> None:
    h = GripPipeline(_Runner(0.0), None).humanoid(clip.body, None)
    h.reset(clip.gt_qpos[0], clip.gt_qvel[0])
    q = clip.gt_qpos[10].copy()
    q[2] += 0.5  # half a metre in the air
    h.teleport(q)
    assert abs(h.lowest_clearance()) < 1e-9
    pvw, rot = h.state()
    assert np.isfinite(pvw).all() and np.isfinite(rot).all()
    with pytest.raises(ValueError, match="teleport"):
        h.teleport(np.full(76, np.nan))


def test_recovery_config_is_checked() -> None:
    with pytest.raises(ValueError, match="history_frames"):
        dataclasses.replace(RecoveryConfig(), history_frames=0)


def test_reading_foot_forces_does_not_change_the_simulation(clip) -> None:
    h = GripPipeline(_Runner(0.0), None).humanoid(clip.body, None)
    final = []
    for read in (False, True):
        h.reset(clip.gt_qpos[0], clip.gt_qvel[0])
        for t in range(1, 41):
            h.set_targets(clip.est_hinge[t])
            h.step()
            if read:
                grf, _ = h.foot_forces()
                assert (grf[:, 2] >= 0).all()
        final.append(h.data.qpos.copy())
    np.testing.assert_array_equal(final[0], final[1])


def test_foot_force_sensors_give_the_contact_sums(clip) -> None:
    """The net contact-force sensors (C) and the loop over the contacts (Python) agree: the GRF
    to rounding, the CoP within a millimetre (the sensors' point has no horizontal moment; the
    loop weights the contact points by their normal forces, which differ where the points do
    not lie at one height)."""
    from grip.sim.model import FootContacts

    h = GripPipeline(_Runner(0.0), None).humanoid(clip.body, None)
    sensors, loop = FootContacts(h.model, h.index), FootContacts(h.model, h.index, loop=True)
    assert sensors._sensor_adr is not None and loop._sensor_adr is None
    h.reset(clip.gt_qpos[0], clip.gt_qvel[0])
    contact = 0
    for t in range(1, min(clip.n_frames, 150)):
        h.set_targets(clip.est_hinge[t])
        h.step()
        (g1, c1), (g2, c2) = sensors(h.data), loop(h.data)
        np.testing.assert_allclose(g1, g2, rtol=1e-9, atol=1e-9)
        np.testing.assert_array_equal(np.isnan(c1), np.isnan(c2))
        on = ~np.isnan(c2[:, 0])
        contact += int(on.sum())
        np.testing.assert_allclose(c1[on], c2[on], atol=1e-3)
    assert contact > 100  # (the feet were on the ground)


class _CountingRunner(_Runner):
    """Counts its decisions; a different action at each."""

    def __init__(self, repeat: int) -> None:
        super().__init__(0.0, prob=None)
        self.env_cfg = TrackingEnvConfig(amp_window=2, action_repeat=repeat)
        self.calls = 0

    def act(self, obs: dict) -> np.ndarray:
        self.calls += 1
        return np.full(69, 0.05 * (-1) ** self.calls)


def test_the_action_is_held_for_the_policys_action_repeat(clip) -> None:
    for repeat in (1, 3):
        runner = _CountingRunner(repeat)
        recon, _ = simulate_clip(clip, runner, RecoveryConfig(enabled=False))
        frames = clip.n_frames - 1
        assert runner.calls == -(-frames // repeat)  # one decision per `repeat` frames
        assert recon.n_frames == clip.n_frames  # and still one output per frame


class _BlowingRunner(_Runner):
    """Zero actions; before the steps to ``frames`` it writes ``qvel`` into the simulation: 1e3
    (an absurd state MuJoCo integrates without a warning: the body is km away within a few
    frames) or 1e12 (MuJoCo gives up and resets the state itself)."""

    def __init__(self, frames: tuple[int, ...], qvel: float) -> None:
        super().__init__(0.0, prob=None)
        self.frames, self.qvel = frames, qvel

    def act(self, obs: dict) -> np.ndarray:
        if self.player.t + 1 in self.frames:
            self.player.h.data.qvel[:] = self.qvel
        return np.zeros(69)


@pytest.mark.parametrize("qvel", [1e3, 1e12])
@pytest.mark.parametrize("enabled", [True, False])
@pytest.mark.parametrize("restart", ["simulated", "estimate"])
def test_a_blow_up_is_recovered_and_never_ends_the_recording(clip, qvel, enabled,
                                                             restart) -> None:  # fmt: skip
    frames = (60, 61, 150)  # 61: a second blow-up right after the first one's recovery
    runner = _BlowingRunner(frames, qvel)
    recon, info = simulate_clip(clip, runner, RecoveryConfig(history_frames=20, enabled=enabled,
                                                               restart=restart))  # fmt: skip
    assert recon.n_frames == clip.n_frames  # every input frame has an output frame
    assert info["blowups"] == recon.notes["blowups"] == 3
    assert recon.notes["blowup_frames"] == list(frames)
    assert {int(t) for t in recon.falls[:, 1]} >= set(frames)
    # no frame of a blown-up state in the output: every joint stays near the motion
    assert np.isfinite(recon.joint_pos).all()
    assert np.linalg.norm(recon.joint_pos - clip.gt_pos, axis=-1).max() < 3.0
    # the blown-up frames are the kinematic estimate: continuing the frame before (GRIP's
    # rule), or at the estimate's own pelvis
    for t in frames:
        assert np.isnan(recon.torques[t]).all()
        if restart == "simulated":
            step = np.linalg.norm(recon.joint_pos[t, 0] - recon.joint_pos[t - 1, 0])
            assert step < 0.1
        else:
            np.testing.assert_allclose(recon.joint_pos[t, 0, :2], recon.ref_root_pos[t, :2],
                                       atol=1e-6)  # fmt: skip


def test_evaluation_ends_a_segment_before_its_blow_up(clip) -> None:
    runner = _BlowingRunner((60,), 1e3)
    recon, info = simulate_clip(clip, runner, RecoveryConfig(enabled=False),
                                stop_at_fall=True)  # fmt: skip
    assert recon.n_frames == 60 and recon.fell and info["blowups"] == 1
    assert recon.falls.tolist() == [[59, 59]]
    assert recon.joint_pos[:, 0, 2].max() < 1.5  # the frame that flew off is not in it
