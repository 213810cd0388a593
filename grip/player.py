"""One episode of GRIP's inference: :class:`Player` steps a :class:`grip.sim.humanoid.Humanoid`
one control step at a time, following a KinematicsNet estimate with the controller, from a
:class:`StartState` (:func:`start_from_calibration`, :func:`start_from_clip`). No ground truth and
no reward. :mod:`grip.pipeline` runs players offline, side by side and streaming.

Fall recovery (GRIP Sec. 3.4, BASELINES_AND_METRICS 5.4): a fall is the pelvis below
``fall_height_m`` (0.30 m) while the AMP discriminator's probability that the recent motion is
human is below ``fall_probability`` (0.7), or a simulation blow-up
(:meth:`grip.sim.humanoid.Humanoid.blown_up`). The history buffer holds the last
``history_frames`` (N = 30) KinematicsNet outputs. On a fall at frame t the simulated root is
put at its position of frame t - N plus the estimated pelvis velocity integrated over the N
frames, the joints at the FA estimate of frame t (velocities: the estimated pelvis velocity,
joints at rest), the body lowered or lifted onto the ground, and the simulation resumes. Output
frames t - N .. t are replaced by the buffered kinematic estimate on the same integrated root;
their forces and torques are NaN and their contacts False. Each event is reported as
``[t - N, t]`` in :attr:`grip.core.reconstruction.Reconstruction.falls`. A humanoid that stays up
but loses the pelvis it follows by more than ``lost_gap_m`` (0.5 m) is recovered the same way
(:class:`RecoveryConfig`).

Blow-ups: the frame of a blown-up state never enters the output; it is recovered like a fall
(history buffer included) and the recording goes on to its last frame. With recovery off a
blow-up still restores the humanoid at the kinematic estimate of that frame (there is no state
to stay in), or, in evaluation (``stop_at_fall``), ends the episode before that frame as a
failure. ``Reconstruction.notes`` counts them: ``"blowups"`` and ``"blowup_frames"``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from grip.core import skeleton as sk
from grip.core.body import BodyParams
from grip.core.checks import check
from grip.core.metrics import global_to_local_rot
from grip.core.reconstruction import Reconstruction
from grip.core.reference import ground_truth_arrays, pose_vector
from grip.kinematics.features import Calibration
from grip.sim.humanoid import Humanoid
from grip.task import amp as A
from grip.task.observations import EstimateFrames, heightmap_grid, lean_towards, sensor_context_at

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
        restart: Where the humanoid's root restarts after a fall (:data:`RESTARTS`):
            ``"simulated"``, GRIP's rule (the simulated pelvis N frames before the fall plus
            the estimated displacement since: a body that had fallen behind stays behind);
            ``"estimate"`` (the default), the estimate's own pelvis (its root integrated from
            the start, the pelvis the controller follows), so a fall does not inherit the
            distance lost before it: on the 90 test segments of the split by person GRIP's
            MPJPE fell from 1,020 to 775 mm with the shipped policy (docs/pace.md, "Recovery").
        lost_gap_m: A humanoid whose pelvis is horizontally farther than this from the pelvis
            it follows is lost and recovered like a fall (an event in ``falls``, counted in the
            reconstruction's ``notes["lost"]``); 0: off, only falls are recovered. The default,
            0.5 m, is where the shipped controller's training episodes end
            (``stage2.termination_root_gap_m``): it has never acted beyond it. With the shipped
            models it cut GRIP's MPJPE on the test split by person from 437 to 342 mm (below the
            kinematic estimate's 356) at the same success on the walks (docs/pace.md, "Lost").
    """

    enabled: bool = True
    history_frames: int = 30
    fall_height_m: float = 0.30
    fall_probability: float = 0.7
    restart: str = "estimate"
    lost_gap_m: float = 0.5

    def __post_init__(self) -> None:
        check(self, (self.history_frames >= 1, "history_frames must be >= 1"),
              (self.restart in RESTARTS, f"restart must be one of {RESTARTS}"),
              (self.lost_gap_m >= 0.0, "lost_gap_m must be >= 0 (0 = off)"))  # fmt: skip


RESTARTS: tuple[str, ...] = ("simulated", "estimate")
"""Where a recovery puts the root (:attr:`RecoveryConfig.restart`)."""


@dataclass(frozen=True)
class PaceKeeper:
    """An outer feedback loop on the followed pelvis (docs/pace.md, "pace keeper"): the pelvis
    the controller is shown (``OAV_Jrel_root``'s gap, the root of ``OAV_Jglo``) leads the
    estimate's by ``gain`` times the humanoid's horizontal gap to it, at most ``lead_max_m``, so
    that a humanoid falling behind is asked to hurry and one that keeps pace sees the estimate
    as it is. The physics, the PD targets and the reconstruction's reference are untouched.
    Only controllers that read the followed pelvis' position (``env.kinematic_obs``
    ``OAV_Jrel_root`` and ``OAV_Jglo``) see it.

    Attributes:
        gain: k, the lead per metre of gap (0: off). The default, 1, was chosen on the
            training people following estimates of KinematicsNets that never saw them (the gap
            at 5 s a third shorter, as many walks kept; 2 kept fewer); on the test people it
            halved the shipped controller's gap at 5 s and cut GRIP's MPJPE in ``grip bench``
            from 459 to 414 mm (docs/pace.md, "The pace keeper measured").
        lead_max_m: The longest lead, m.
        lean_gain_deg: The lean keeper (docs/pace.md, hypothesis 12): the followed upper body
            (spine, neck, head, arms: the controller's observation of it and the spine's PD
            target) leans this many degrees further forward per metre that the humanoid's
            pelvis is behind the estimate's along the direction of travel (0: off). The
            estimated trunk's lean sets the humanoid's pace (docs/pace.md, "The trunk's lean
            sets the pace"). The default, 20, was chosen on the training people following
            estimates of KinematicsNets that never saw them (among 0, 10, 20, 40: the gap at 5 s
            shortest, one walk fewer kept); on the test people it took GRIP's MPJPE in ``grip
            bench`` from 342 to 332 mm, below the kinematic estimate on locomotion (302 against
            308 mm), at two locomotion segments fewer kept (docs/pace.md, "The lean keeper
            measured").
        lean_max_deg: The largest lean the keeper adds, deg.
    """

    gain: float = 1.0
    lead_max_m: float = 0.5
    lean_gain_deg: float = 20.0
    lean_max_deg: float = 5.0

    def __post_init__(self) -> None:
        check(self, (self.gain >= 0.0, "gain must be >= 0"),
              (self.lead_max_m > 0.0, "lead_max_m must be > 0"),
              (self.lean_gain_deg >= 0.0, "lean_gain_deg must be >= 0"),
              (self.lean_max_deg > 0.0, "lean_max_deg must be > 0"))  # fmt: skip

    def lean(self, followed_xy: np.ndarray, sim_xy: np.ndarray,
             forward_xy: np.ndarray) -> np.ndarray | None:  # fmt: skip
        """``(3, 3)`` the rotation that leans the followed upper body forward about the pelvis
        (towards ``forward_xy``, the followed pelvis' horizontal velocity), or None where the
        keeper is off, the humanoid is not behind or the estimate stands (under 0.1 m/s)."""
        if self.lean_gain_deg <= 0.0:
            return None
        speed = float(np.hypot(forward_xy[0], forward_xy[1]))
        if speed < 0.1:
            return None
        f = np.asarray(forward_xy, dtype=np.float64) / speed
        behind = float((np.asarray(followed_xy, dtype=np.float64) - sim_xy) @ f)
        deg = min(self.lean_gain_deg * behind, self.lean_max_deg)
        if deg <= 0.0:
            return None
        return lean_towards(f, deg)

    def lead(self, followed_xy: np.ndarray, sim_xy: np.ndarray) -> np.ndarray:
        """``(2,)`` the lead added to the followed pelvis' horizontal position, m."""
        d = self.gain * (np.asarray(followed_xy, dtype=np.float64) - sim_xy)
        n = float(np.hypot(d[0], d[1]))
        return d * (self.lead_max_m / n) if n > self.lead_max_m else d


@dataclass(frozen=True, eq=False)
class StartState:
    """Where the humanoid starts: ``qpos (76,)`` pose vector, ``qvel (75,)`` velocity vector
    and ``amp (FRAME_DIM,)`` the AMP frame of that state (the discriminator's history before
    the first step)."""

    qpos: np.ndarray
    qvel: np.ndarray
    amp: np.ndarray
    warmup_frames: int = 0
    """Frames played as the kinematic estimate before the humanoid starts, at the estimate's
    pose of the last of them (:data:`STANDING_WARMUP_S` after a standing calibration); 0: the
    humanoid starts at ``qpos`` at frame 0. Not a fall."""


STANDING_WARMUP_S = 1.0
"""After a standing calibration (no ground truth), the humanoid starts this late, at the
estimate: KinematicsNet, started from the standing pose, converges within the first second
(``grip kin eval --init standing``: within 0.3 % of a ground-truth start after it), and a
recording that does not begin standing still makes the estimate snap to the motion in its first
frames, which threw the humanoid in 95 % of the test segments started mid-motion. A recording
that begins as GRIP's calibration asks, standing still, loses nothing: that second is the
standing pose either way. A live stream (:class:`grip.eval.stream.GripStream`) starts at frame 0."""


def _start(q: np.ndarray, g: dict[str, np.ndarray]) -> StartState:
    amp = A.amp_features(g["gt_pos"][:1, 0], g["gt_rot"][:1, 0], g["gt_vel"][:1, 0],
                         g["gt_angvel"][:1, 0], q[:1, 7:], g["gt_qvel"][:1, 6:],
                         g["gt_pos"][:1, list(A.KEY_JOINTS)])[0]  # fmt: skip
    return StartState(q[0].copy(), g["gt_qvel"][0].copy(), amp)


def start_from_calibration(cal: Calibration, body: BodyParams, fps: float,
                           warmup: bool = True) -> StartState:  # fmt: skip
    """The calibration pose at rest-to-frame-1 velocity (finite differences of its two frames);
    after a standing calibration (``cal.measured`` false) with ``warmup``, the humanoid starts
    :data:`STANDING_WARMUP_S` later, at the estimate."""
    q = pose_vector(cal.local_rot, cal.root_pos)
    start = _start(q, ground_truth_arrays(q, body, fps))
    if warmup and not cal.measured:
        start = dataclasses.replace(start, warmup_frames=round(STANDING_WARMUP_S * fps))
    return start


def start_from_clip(clip) -> StartState:
    """A :class:`grip.core.reference.ReferenceClip`'s first frame (``grip policy eval``)."""
    amp = A.reference_amp_features(clip)[0]  # (the whole clip's, as the training task does)
    return StartState(clip.gt_qpos[0].copy(), clip.gt_qvel[0].copy(), amp)


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

    def replace(self, s: int, t: int, pos: np.ndarray, rot: np.ndarray) -> None:
        """Frames ``s..t`` become a kinematic estimate (no forces, no contacts)."""
        self.ensure(t)
        self.pos[s : t + 1], self.rot[s : t + 1] = pos, rot
        self.grf[s : t + 1] = self.cop[s : t + 1] = self.torques[s : t + 1] = np.nan
        self.contacts[s : t + 1] = False


def kinematic_frames(est, root0: np.ndarray, s: int, t: int) -> tuple[np.ndarray, np.ndarray]:
    """The buffered KinematicsNet estimate of frames ``s..t`` on a root integrated from
    ``root0`` (the position at frame ``s``) with the estimated pelvis velocity.

    Returns:
        ``pos (t-s+1, 24, 3)`` world joints and ``rot (t-s+1, 24, 3, 3)`` global rotations.
    """
    root = root0 + (est.est_root_pos[s : t + 1] - est.est_root_pos[s])
    rel = est.est_pos[s : t + 1] - est.est_pos[s : t + 1, :1]  # (FP's pelvis is not exactly 0)
    return rel + root[:, None], est.est_rot[s : t + 1]


class Player:
    """The policy drives a humanoid along an estimate, with GRIP's fall recovery, one control
    step at a time (offline and streaming alike).

    Args:
        runner: A :class:`policies.runner.PolicyRunner` or an ensemble of them: ``act(obs)``,
            ``fall_probability(amp_obs)``, ``disc`` and ``env_cfg`` (the observation and action
            settings it was trained with).
        humanoid: The subject's humanoid in its scene.
        recovery: Fall detection and recovery settings.
        stop_at_fall: End at the first fall that is not recovered (evaluation).
        pace: The pace keeper (:class:`PaceKeeper`): where the controller is shown the pelvis
            it follows.

    After :meth:`start`, :attr:`obs` is the observation the next action is computed from,
    :attr:`t` the frame the simulation is at, :attr:`last` the last frame in the output,
    :attr:`trace` the outputs.
    """

    def __init__(self, runner, humanoid: Humanoid, recovery: RecoveryConfig = RecoveryConfig(),
                 stop_at_fall: bool = False, pace: PaceKeeper = PaceKeeper()) -> None:  # fmt: skip
        cfg = runner.env_cfg
        self.runner, self.h, self.recovery, self.stop_at_fall = runner, humanoid, recovery, \
            stop_at_fall  # fmt: skip
        self.pace = pace
        self._variant, self._relative = cfg.kinematic_obs, cfg.action_mode == "relative"
        self._feedforward, self._repeat = cfg.velocity_feedforward, cfg.action_repeat
        self._context = cfg.sensor_context  # (a gate's window, TrackingEnvConfig.sensor_context)
        self._grid = heightmap_grid(cfg.heightmap_size, cfg.heightmap_extent_m)
        self._hm = np.zeros(len(self._grid))
        self._amp = A.AmpHistory(cfg.amp_window) if cfg.amp_window > 0 else None
        self._amp_buf = np.empty(A.FRAME_DIM)
        self._frames = EstimateFrames()
        self._gain = cfg.action_scale * humanoid.half
        self._obs: dict | None = None
        self._state: tuple[np.ndarray, np.ndarray] | None = None  # (pvw, rot) not yet observed
        self.t = self.last = self.warmup = 0
        self.done = False
        self.falls: list[tuple[int, int]] = []
        self.blowup_frames: list[int] = []
        self.lost_frames: list[int] = []

    # ------------------------------------------------------------------ episode
    def start(self, est, start: StartState, name: str, fps: float,
              frames_hint: int | None = None) -> None:  # fmt: skip
        """Put the humanoid in ``start`` at frame 0 of ``est`` (an :class:`grip.core.reference.
        Estimate`, a growing :class:`grip.core.reference.LiveEstimate` or a reference clip) and
        record that frame."""
        h = self.h
        self.est, self.name, self.fps = est, name, float(fps)
        h.reset(start.qpos, start.qvel)
        self._root_offset = start.qpos[:3] - est.est_root_pos[0]
        self._ref_offset = self._root_offset.copy()  # (recoveries move _root_offset, not this)
        self._frames.update(est, h.kd_over_kp, self._feedforward)
        if self._amp is not None:
            self._amp.reset(start.amp[None])
        self.trace = _Trace(frames_hint or est.n_frames)
        self._floor = 0  # frames before this were replaced by a recovery: the buffer starts after
        self._down = False  # (recovery off) the humanoid is down: one fall until it is up
        self.t = self.last = self.warmup = 0
        self.done = False
        self.falls, self.blowup_frames, self.lost_frames = [], [], []
        self._action: np.ndarray | None = None
        self._held = 0  # frames the current action has been played (env_cfg.action_repeat)
        self._obs = self._observe(*h.state())
        self._record(0)
        k = start.warmup_frames
        if 0 < k < est.n_frames - 1:  # the first k frames: the kinematic estimate, as a
            self.t = k  # recovery fills them (not counted as a fall)
            self._recover(0, k)
            self.last = self._floor = k
            self._record(k)
        self.warmup = self.t

    def refresh(self, start: int) -> None:
        """The estimate changed from frame ``start`` on (a stream's newest frames): observe the
        current state against it again."""
        self._frames.update(self.est, self.h.kd_over_kp, self._feedforward, start)
        self._obs = self._observe(*self.h.state())

    @property
    def obs(self) -> dict | None:
        """The observation the next action is computed from (built when first asked for after
        a step: the frames that hold an action (``env_cfg.action_repeat``) need none)."""
        if self._obs is None and self._state is not None:
            self._obs = self._observe(*self._state)
        return self._obs

    @property
    def blowups(self) -> int:
        """Simulation blow-ups since :meth:`start`."""
        return len(self.blowup_frames)

    def _observe(self, pvw: np.ndarray, rot: np.ndarray) -> dict[str, np.ndarray]:
        t = min(self.t + 1, self.est.n_frames - 1)
        off = self._root_offset
        if self.pace.gain > 0.0:
            off = off.copy()
            off[:2] += self.pace.lead(self.est.est_root_pos[t, :2] + off[:2], pvw[0, 0, :2])
        obs = self._frames.observe(t, self._variant, pvw, rot, off, self._grid, self.h.terrain,
                                   self._hm, self._lean(t, pvw))  # fmt: skip
        if self._context:
            obs["sensor_context"] = sensor_context_at(self.est.sensor, t, self._context)
        return obs

    def _lean(self, t: int, pvw: np.ndarray) -> np.ndarray | None:
        """The lean keeper's rotation of frame ``t``'s followed upper body (None: none)."""
        if self.pace.lean_gain_deg <= 0.0:
            return None
        e = self.est
        return self.pace.lean(e.est_root_pos[t, :2] + self._root_offset[:2], pvw[0, 0, :2],
                              e.est_vel[t, -1, :2])  # fmt: skip

    def _record(self, t: int) -> None:
        h, tr = self.h, self.trace
        tr.ensure(t)
        ids = h.index.body_ids
        tr.pos[t] = h.xpos[ids]
        tr.rot[t] = h.xmat[ids].reshape(-1, 3, 3)
        tr.grf[t], tr.cop[t] = h.foot_forces()
        tr.torques[t] = h.torques()
        tr.contacts[t] = tr.grf[t, :, 2] > CONTACT_FORCE_N

    # ------------------------------------------------------------------ stepping
    def needs_action(self) -> bool:
        """Whether the next control step starts a new decision: :meth:`step` then takes the
        controller's action for :attr:`obs` (the last one is held ``env_cfg.action_repeat``
        frames)."""
        return self._action is None or self._held >= self._repeat

    def advance(self) -> bool:
        """One control step with fall detection and recovery, the controller deciding here;
        returns whether the recording is over (its last frame, the pelvis under the floor, or a
        fall or blow-up with ``stop_at_fall`` and recovery off)."""
        return self.step(self.runner.act(self.obs) if self.needs_action() else None)

    def step(self, action: np.ndarray | None) -> bool:
        """:meth:`advance` with the decision made elsewhere (:class:`BatchedPlayer`: one
        controller forward over the observations of several players).

        Args:
            action: ``(69,)`` the controller's action for :attr:`obs` when
                :meth:`needs_action`, else None (the held action plays on).

        Raises:
            ValueError: An action where none is due or none where one is, or an action that is
                not 69 finite values.
        """
        if self.needs_action() != (action is not None):
            raise ValueError("step takes an action exactly when needs_action() is true")
        h, rec = self.h, self.recovery
        if action is not None:
            self._action, self._held = action, 0
        self._held += 1
        a = np.asarray(self._action, dtype=np.float64).reshape(-1)
        if a.shape != (69,) or not np.isfinite(a).all():
            raise ValueError(f"action must be (69,) finite values, got shape {a.shape}")
        t = self.t = self.t + 1
        lean = None if self._state is None else self._lean(t, self._state[0])
        h.set_targets(self._frames.pd_target(a, t, self._relative, self._gain, h.lo, h.half,
                                             lean))  # fmt: skip
        h.step()
        if h.blown_up():
            return self._blown_up(t)
        pvw, rot = h.state()
        self._obs, self._state = None, (pvw, rot)
        if self._amp is not None:
            self._amp.push(A.amp_frame(pvw, rot, h.hinge_angles(), h.hinge_velocities(),
                                       self._amp_buf))  # fmt: skip
        self._record(t)
        self.last = t
        height = float(pvw[0, 0, 2])
        low = height < rec.fall_height_m
        fell = low and (self.runner.disc is None or self.runner.fall_probability(
            None if self._amp is None else self._amp.vector())[0] < rec.fall_probability)
        lost = not fell and rec.enabled and rec.lost_gap_m > 0.0 and self.gap(t, pvw) > \
            rec.lost_gap_m  # fmt: skip
        end = False
        if lost:
            self.lost_frames.append(t)
        if (fell or lost) and rec.enabled:
            s = max(self._floor, t - rec.history_frames, 0)
            self._recover(s, t)
            self.falls.append((s, t))
            self._floor = t + 1
        elif fell and not self._down:
            self.falls.append((t, t))
            end = self.stop_at_fall
        if not rec.enabled:
            self._down = low
        # (a pelvis under the floor, not yet a blow-up, ends the recording: the training
        # task's fall termination at a height of 0)
        end = end or t >= self.est.n_frames - 1 or height < 0.0
        self.done = end
        return end

    def gap(self, t: int, pvw: np.ndarray) -> float:
        """Horizontal distance, m, of the simulated pelvis (``pvw[0, 0]``) at frame ``t`` from
        the pelvis the controller follows there (the estimate's, re-anchored by recoveries;
        without the pace keeper's lead)."""
        d = pvw[0, 0, :2] - (self.est.est_root_pos[t, :2] + self._root_offset[:2])
        return float(np.hypot(d[0], d[1]))

    def resume(self, t: int) -> None:
        """Put the humanoid at the kinematic estimate of frame ``t`` (its root: where the last
        frame played left it) and play on from there: a stream after a gap it did not fill."""
        est = self.est
        pos, rot = kinematic_frames(est, self.trace.pos[self.last, 0], t, t)
        qvel = np.zeros(75)
        qvel[:3] = est.est_vel[t, -1]
        self.t = t
        self._teleport(pose_vector(global_to_local_rot(rot[-1]), pos[-1, 0]), qvel)
        self.last = self._floor = t
        self._down = False
        self.done = t >= est.n_frames - 1
        self._record(t)

    def _teleport(self, qpos: np.ndarray, qvel: np.ndarray) -> None:
        """The humanoid to a new state at frame :attr:`t`, lifted onto the ground; the root
        offset and the AMP history restart from it."""
        h = self.h
        h.teleport(qpos, qvel)
        r = h.index.root_qpos_adr
        self._root_offset = h.qpos[r : r + 3] - self.est.est_root_pos[self.t]
        pvw, rot = h.state()
        self._obs = self._observe(pvw, rot)
        if self._amp is not None:
            frame = A.amp_frame(pvw, rot, h.hinge_angles(), h.hinge_velocities(),
                                self._amp_buf).copy()  # fmt: skip
            self._amp.reset(np.repeat(frame[None], self._amp.window, axis=0))
        self._action = None  # a new decision from the restored state
        self._held = 0

    def _recover(self, s: int, t: int, s_valid: bool = True) -> None:
        """Restart the humanoid after a fall at ``t`` (history from ``s``); fill ``s..t``.

        The root of the filled frames starts at frame ``s``'s simulated pelvis (GRIP) or at
        the estimate's own pelvis (:attr:`RecoveryConfig.restart`). ``s_valid``: frame ``s``
        holds a pose to start the root from; ``False`` (a blow-up at ``s`` = ``t``, whose frame
        was never recorded): GRIP's rule starts from frame ``s - 1`` plus the estimated root
        displacement."""
        est, tr = self.est, self.trace
        if self.recovery.restart == "estimate":
            root0 = est.est_root_pos[s] + self._ref_offset
        else:  # GRIP: p_sim(t - N) + the estimated displacement
            root0 = tr.pos[s, 0] if s_valid else (tr.pos[s - 1, 0] + est.est_root_pos[s]
                                                  - est.est_root_pos[s - 1])  # fmt: skip
        pos, rot = kinematic_frames(est, root0, s, t)
        tr.replace(s, t, pos, rot)
        qvel = np.zeros(75)
        qvel[:3] = est.est_vel[t, -1]
        self._teleport(pose_vector(global_to_local_rot(rot[-1]), pos[-1, 0]), qvel)

    def _blown_up(self, t: int) -> bool:
        """The step to ``t`` blew up: frame ``t`` is not recorded; recover (with recovery off:
        frame ``t`` only) or, evaluating, end before ``t``."""
        rec = self.recovery
        self.blowup_frames.append(t)
        if self.stop_at_fall and not rec.enabled:  # evaluation: a failure, the frames before
            if not self._down:
                self.falls.append((t, t))
            self.last = t - 1
            self.done = True
            return True
        s = max(self._floor, t - rec.history_frames, 0) if rec.enabled else t
        self._recover(s, t, s_valid=s < t)
        self.falls.append((s, t))
        self._floor = t + 1
        self._down = False
        self.last = t
        self.done = t >= self.est.n_frames - 1
        return self.done

    def reconstruction(self, ms_per_frame: float = float("nan")) -> Reconstruction:
        """The frames played so far (method ``"grip"``); ``ref_root_pos``: the estimate's
        integrated pelvis where the episode started it (what the policy follows until a
        recovery re-anchors it on the humanoid)."""
        tr, last = self.trace, self.last
        sl = slice(0, last + 1)
        return Reconstruction(
            name=self.name, method="grip", fps=self.fps,
            joint_pos=tr.pos[sl].copy(), global_rot=tr.rot[sl].copy(), grf=tr.grf[sl].copy(),
            cop=tr.cop[sl].copy(), torques=tr.torques[sl].copy(),
            contacts=tr.contacts[sl].copy(),
            ref_root_pos=self.est.est_root_pos[sl] + self._ref_offset,
            falls=np.minimum(np.array(self.falls, dtype=np.int64).reshape(-1, 2), last),
            ms_per_frame=ms_per_frame,
            notes={"blowups": self.blowups, "blowup_frames": list(self.blowup_frames),
                   "lost": len(self.lost_frames), "recovery": self.recovery.enabled,
                   "warmup_frames": int(self.warmup)},
        )  # fmt: skip
