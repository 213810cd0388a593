"""GRIP's offline reconstruction: KinematicsNet, then the policy drives the simulated humanoid,
with GRIP's fall recovery (``grip reconstruct``).

Per recording: KinematicsNet runs once over the whole sequence (batched over recordings); the
humanoid starts from the recording's first (calibration) frame and the policy follows the
estimate in MuJoCo. Every frame records the simulated joints, the ground reaction force and
centre of pressure of each foot (MuJoCo's contact forces), the actuator torques and the foot
contact states.

Fall recovery (GRIP Sec. 3.4, BASELINES_AND_METRICS 5.4): a fall is the pelvis below
``fall_height_m`` (0.30 m) while the AMP discriminator's probability that the recent motion is
human is below ``fall_probability`` (0.7), or a simulation blow-up (:meth:`envs.tracking_env.
GripTrackingEnv.step`: MuJoCo's bad-state warnings, or a non-finite or absurd state: the pelvis
faster than 50 m/s, a joint faster than 200 rad/s, the pelvis 4 m above the terrain or below the
floor). The history buffer holds the
last ``history_frames`` (N = 30) KinematicsNet outputs. On a fall at frame t the simulated root is
put at its position of frame t - N plus the estimated pelvis velocity integrated over the N
frames, the joints at the FA estimate of frame t (velocities: the estimated pelvis velocity,
joints at rest), the body lowered or lifted onto the ground, and the simulation resumes. Output
frames t - N .. t are replaced by the buffered kinematic estimate on the same integrated root;
their forces and torques are NaN and their contacts False. Each event is reported as
``[t - N, t]`` in :attr:`grip.core.reconstruction.Reconstruction.falls`.

Blow-ups: the frame of a blown-up state never enters the output; it is recovered like a fall
(history buffer included) and the recording goes on to its last frame. With recovery off a
blow-up still restores the humanoid at the kinematic estimate of that frame (there is no state
to stay in), or, in evaluation (``stop_at_fall``), ends the episode before that frame as a
failure. ``Reconstruction.notes`` counts them: ``"blowups"`` and ``"blowup_frames"``.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from envs.tracking_env import GripTrackingEnv
from grip.core import skeleton as sk
from grip.core.metrics import global_to_local_rot
from grip.core.reconstruction import Reconstruction
from grip.core.reference import ReferenceClip, ReferenceSet, pose_vector
from grip.sim.model import FootContacts

CONTACT_FORCE_N = 20.0
"""A foot is in contact when the vertical ground reaction force on it exceeds this (the same
threshold as the insole contact labels, PRISM_FORMAT.md)."""


@dataclass(frozen=True)
class RecoveryConfig:
    """GRIP's fall detector and history-buffer recovery.

    Attributes:
        enabled: Recover from falls (off: the humanoid stays down; each fall is still reported).
        history_frames: N, KinematicsNet outputs kept in the history buffer (0.3 s at 100 Hz).
        fall_height_m: Pelvis height below which a fall is possible, m.
        fall_probability: Discriminator probability below which a low pelvis is a fall.
    """

    enabled: bool = True
    history_frames: int = 30
    fall_height_m: float = 0.30
    fall_probability: float = 0.7

    def __post_init__(self) -> None:
        if self.history_frames < 1:
            raise ValueError("RecoveryConfig.history_frames must be >= 1")


class _Trace:
    """Per-frame output arrays of one simulated recording (grown by doubling when a stream
    outruns them)."""

    def __init__(self, n: int) -> None:
        self.pos = np.full((n, sk.N_JOINTS, 3), np.nan)
        self.rot = np.full((n, sk.N_JOINTS, 3, 3), np.nan)
        self.grf = np.full((n, 2, 3), np.nan)
        self.cop = np.full((n, 2, 3), np.nan)
        self.torques = np.full((n, 3 * (sk.N_JOINTS - 1)), np.nan)
        self.contacts = np.zeros((n, 2), dtype=bool)

    def ensure(self, t: int) -> None:
        """Make room for frame ``t``."""
        n = self.pos.shape[0]
        if t < n:
            return
        grown = _Trace(max(2 * n, t + 1))
        for k, a in vars(self).items():
            getattr(grown, k)[:n] = a
        vars(self).update(vars(grown))


class ClipPlayer:
    """Plays one clip of an inference env with the policy and GRIP's fall recovery, one control
    step at a time: the loop of :func:`simulate_clip` and of
    :class:`grip.eval.stream.GripStream`.

    Args:
        env: An inference env (:func:`inference_env`).
        runner: A :class:`policies.runner.PolicyRunner` or an ensemble of them
            (:class:`policies.ensemble.PolicyEnsemble`).
        recovery: Fall detection and recovery settings.
        stop_at_fall: End at the first fall that is not recovered.

    After :meth:`start`, :attr:`obs` is the observation the next action is computed from (a
    stream replaces it when its clip grows, :meth:`envs.tracking_env.GripTrackingEnv.
    refresh_reference`), :attr:`t` the frame the simulation is at, :attr:`trace` the outputs.
    """

    def __init__(self, env: GripTrackingEnv, runner, recovery: RecoveryConfig = RecoveryConfig(),
                 stop_at_fall: bool = False) -> None:  # fmt: skip
        self.env, self.runner, self.recovery = env, runner, recovery
        self.stop_at_fall = stop_at_fall
        self.obs: dict | None = None
        self.t = self.last = 0
        self.done = False
        self.falls: list[tuple[int, int]] = []

    def start(self, clip_index: int, frames_hint: int | None = None) -> None:
        """Reset the env to the clip's first frame (its ground truth) and record it."""
        env = self.env
        self.obs, _ = env.reset(options={"clip": clip_index, "start": 0})
        self.clip: ReferenceClip = env.clip
        sim = env._sim
        self._ix = sim.index
        self._feet = FootContacts(sim.model, self._ix)
        self.trace = _Trace(frames_hint or self.clip.n_frames)
        self._floor = 0  # frames before this were replaced by a recovery: the buffer starts after
        self._down = False  # (recovery off) the humanoid is down: one fall until it is up
        self.t = self.last = 0
        self.done = False
        self.falls = []
        self.blowup_frames: list[int] = []
        self._action: np.ndarray | None = None
        self._held = 0  # frames the current action has been played (env_cfg.action_repeat)
        self._record(0)

    @property
    def blowups(self) -> int:
        """Simulation blow-ups since :meth:`start`."""
        return len(self.blowup_frames)

    def _record(self, t: int) -> None:
        d, ix, tr = self.env.data, self._ix, self.trace
        tr.ensure(t)
        tr.pos[t] = d.xpos[ix.body_ids]
        tr.rot[t] = d.xmat[ix.body_ids].reshape(-1, 3, 3)
        tr.grf[t], tr.cop[t] = self._feet(d)
        tr.torques[t] = d.actuator_force[ix.actuator_ids]
        tr.contacts[t] = tr.grf[t, :, 2] > CONTACT_FORCE_N

    def advance(self) -> bool:
        """One control step with fall detection and recovery; returns whether the clip is over
        (its last frame, or a fall or blow-up with ``stop_at_fall`` and recovery off)."""
        env, rec = self.env, self.recovery
        if self._action is None or self._held >= self.runner.env_cfg.action_repeat:
            self._action, self._held = self.runner.act(self.obs), 0
        self._held += 1
        obs, _, terminated, truncated, info = env.step(self._action)
        self.obs = obs
        t = self.t = info["frame"]
        if info.get("sim_unstable"):
            return self._blown_up(t)
        self._record(t)
        self.last = t
        low = info["root_height_m"] < rec.fall_height_m
        fell = low and (
            self.runner.disc is None
            or self.runner.fall_probability(info["amp_obs"])[0] < rec.fall_probability
        )
        end = False
        if fell and rec.enabled:
            s = max(self._floor, t - rec.history_frames, 0)
            self.obs = _recover(env, self.clip, self.trace, s, t)
            self._action = None  # a new decision from the restored state
            self.falls.append((s, t))
            self._floor = t + 1
        elif fell and not self._down:
            self.falls.append((t, t))
            end = self.stop_at_fall
        if not rec.enabled:
            self._down = low
        end = end or t >= self.clip.n_frames - 1 or terminated or truncated
        self.done = end
        return end

    def resume(self, t: int) -> None:
        """Put the humanoid at the kinematic estimate of frame ``t`` (its root: where the last
        frame played left it) and play on from there: a stream after a gap it did not fill."""
        clip, tr = self.clip, self.trace
        pos, rot = kinematic_frames(clip, tr.pos[self.last, 0], t, t)
        qvel = np.zeros(75)
        qvel[:3] = clip.est_vel[t, -1]
        self.obs, _ = self.env.teleport(pose_vector(global_to_local_rot(rot[-1]), pos[-1, 0]),
                                        qvel, frame=t)  # fmt: skip
        self.t = self.last = self._floor = t
        self._action, self._held, self._down = None, 0, False
        self.done = t >= clip.n_frames - 1
        self._record(t)

    def _blown_up(self, t: int) -> bool:
        """The step to ``t`` blew up (the env's ``sim_unstable``): frame ``t`` is not recorded;
        recover (with recovery off: frame ``t`` only) or, evaluating, end before ``t``."""
        rec = self.recovery
        self.blowup_frames.append(t)
        if self.stop_at_fall and not rec.enabled:  # evaluation: a failure, the frames before
            if not self._down:
                self.falls.append((t, t))
            self.last = t - 1
            self.done = True
            return True
        s = max(self._floor, t - rec.history_frames, 0) if rec.enabled else t
        self.obs = _recover(self.env, self.clip, self.trace, s, t, s_valid=s < t)
        self._action = None
        self.falls.append((s, t))
        self._floor = t + 1
        self._down = False
        self.last = t
        self.done = t >= self.clip.n_frames - 1
        return self.done

    def reconstruction(self, ms_per_frame: float = float("nan")) -> Reconstruction:
        """The frames played so far (method ``"grip"``)."""
        tr, last, clip = self.trace, self.last, self.clip
        sl = slice(0, last + 1)
        return Reconstruction(
            name=clip.name, method="grip", fps=clip.fps,
            joint_pos=tr.pos[sl].copy(), global_rot=tr.rot[sl].copy(), grf=tr.grf[sl].copy(),
            cop=tr.cop[sl].copy(), torques=tr.torques[sl].copy(),
            contacts=tr.contacts[sl].copy(),
            falls=np.minimum(np.array(self.falls, dtype=np.int64).reshape(-1, 2), last),
            ms_per_frame=ms_per_frame,
            notes={"blowups": self.blowups, "blowup_frames": list(self.blowup_frames),
                   "recovery": self.recovery.enabled},
        )  # fmt: skip


def simulate_clip(
    env: GripTrackingEnv,
    runner,
    clip_index: int,
    recovery: RecoveryConfig = RecoveryConfig(),
    stop_at_fall: bool = False,
) -> tuple[Reconstruction, dict]:
    """Play one reference clip from its first frame with the policy and fall recovery.

    Args:
        env: An inference env (no random start, no termination) holding the clip.
        runner: A :class:`policies.runner.PolicyRunner` or an ensemble of them
            (:class:`policies.ensemble.PolicyEnsemble`).
        clip_index: Clip of ``env.reference`` to play.
        recovery: Fall detection and recovery settings.
        stop_at_fall: End at the first fall that is not recovered (``grip eval-policy``: a fall
            fails the segment and the metrics cover the frames until then).

    Returns:
        The reconstruction (method ``"grip"``, forces and torques from the simulation) and
        ``{"blowups": int, "sim_s": float}``.
    """
    t0 = time.perf_counter()
    player = ClipPlayer(env, runner, recovery, stop_at_fall)
    player.start(clip_index)
    while not player.advance():
        pass
    sim_s = time.perf_counter() - t0
    recon = player.reconstruction(1e3 * sim_s / max(player.last + 1, 1))
    return recon, {"blowups": player.blowups, "sim_s": sim_s}


def kinematic_frames(clip: ReferenceClip, root0: np.ndarray, s: int, t: int):
    """The buffered KinematicsNet estimate of frames ``s..t`` on a root integrated from
    ``root0`` (the position at frame ``s``) with the estimated pelvis velocity.

    Returns:
        ``pos (t-s+1, 24, 3)`` world joints and ``rot (t-s+1, 24, 3, 3)`` global rotations.
    """
    root = root0 + (clip.est_root_pos[s : t + 1] - clip.est_root_pos[s])
    rel = clip.est_pos[s : t + 1] - clip.est_pos[s : t + 1, :1]  # (FP's pelvis is not exactly 0)
    return rel + root[:, None], clip.est_rot[s : t + 1]


def _recover(env: GripTrackingEnv, clip: ReferenceClip, tr: _Trace, s: int, t: int,
             s_valid: bool = True):  # fmt: skip
    """Reset the humanoid after a fall at ``t`` (history starts at ``s``); fill ``s..t``.

    ``s_valid``: frame ``s`` holds a pose to start the root from; ``False`` (a blow-up at ``s``
    = ``t``, whose frame was never recorded): start from frame ``s - 1`` plus the estimated
    root displacement."""
    root0 = tr.pos[s, 0] if s_valid else (tr.pos[s - 1, 0] + clip.est_root_pos[s]
                                          - clip.est_root_pos[s - 1])  # fmt: skip
    pos, rot = kinematic_frames(clip, root0, s, t)
    tr.pos[s : t + 1], tr.rot[s : t + 1] = pos, rot
    tr.grf[s : t + 1] = tr.cop[s : t + 1] = tr.torques[s : t + 1] = np.nan
    tr.contacts[s : t + 1] = False
    local = global_to_local_rot(rot[-1])
    qpos = pose_vector(local, pos[-1, 0])
    qvel = np.zeros(75)
    qvel[:3] = clip.est_vel[t, -1]
    obs, _ = env.teleport(qpos, qvel)
    return obs


def inference_env(runner, reference: ReferenceSet) -> GripTrackingEnv:
    """The policy's env settings for inference: clips play from frame 0 to their end."""
    cfg = dataclasses.replace(runner.env_cfg, random_start=False, termination_dist_m=0.0,
                              fall_height_m=0.0, max_episode_frames=0, clip_index=-1)  # fmt: skip
    return GripTrackingEnv(cfg, reference)


class GripReconstructor:
    """KinematicsNet + policy + fall recovery over PRISM-format recordings.

    Args:
        runner: A :class:`policies.runner.PolicyRunner` or :class:`policies.ensemble.
            PolicyEnsemble` (its env settings and sensor features
            must match the estimator's).
        estimator: A :class:`grip.kinematics.inference.KinematicsEstimator`.
        recovery: Fall detection and recovery settings.
    """

    def __init__(self, runner, estimator, recovery: RecoveryConfig = RecoveryConfig()) -> None:
        self.runner = runner
        self.estimator = estimator
        self.recovery = recovery

    @classmethod
    def from_files(cls, policy, kin, recovery: RecoveryConfig = RecoveryConfig()):
        """Load a policy export (``grip policy-export``, or an ensemble of them, ``grip
        policy-ensemble``) and a KinematicsNet checkpoint."""
        from grip.kinematics.inference import KinematicsEstimator
        from policies.ensemble import load_policy

        return cls(load_policy(policy), KinematicsEstimator.from_checkpoint(kin), recovery)

    def stream(self, calibration):
        """A :class:`grip.eval.stream.GripStream` (one frame in, one frame out) with these
        models, starting from ``calibration``: a recording's first frames with ground truth."""
        from grip.eval.stream import GripStream

        return GripStream(self.runner, self.estimator, calibration, self.recovery)

    def reconstruct(
        self, recs: Sequence, progress: Callable[[int], object] | None = None, batch: int = 16
    ) -> list[Reconstruction]:
        """One :class:`Reconstruction` per recording, in order."""
        from grip.kinematics.reference import build_reference_set

        out: list[Reconstruction] = []
        for i in range(0, len(recs), batch):
            part = list(recs[i : i + batch])
            t0 = time.perf_counter()
            ref = build_reference_set(part, self.estimator, batch=batch)
            kin_ms = 1e3 * (time.perf_counter() - t0) / max(ref.total_frames, 1)
            env = inference_env(self.runner, ref)
            try:
                for k in range(len(part)):
                    recon, _ = simulate_clip(env, self.runner, k, self.recovery)
                    recon.ms_per_frame += kin_ms
                    recon.notes["kinematics_ms_per_frame"] = kin_ms
                    out.append(recon)
                    if progress is not None:
                        progress(1)
            finally:
                env.close()
        return out
