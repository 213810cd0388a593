"""``GripTrackingEnv``: a torque-driven humanoid in MuJoCo follows a KinematicsNet estimate.

One control step (100 Hz by default) writes PD targets for the 69 hinges into MuJoCo's position
actuators (PD runs inside MuJoCo), advances the physics ``substeps`` times, and returns GRIP's
observations (sensor, kinematic = State Difference, self, environment = height map) and reward
terms (imitation against the ground truth, energy; AMP is filled by a wrapper).

Timing: after ``reset`` the simulation is at frame ``s`` of the clip (the ground-truth state).
The observation at frame ``t`` carries the estimate and sensors of frame ``t + 1`` (what the
next action aims at: with streaming sensors this is the newest frame); the step that follows
moves the simulation to ``t + 1``, whose state is rewarded against the ground truth of ``t + 1``.
"""

from __future__ import annotations

from collections import deque
from pathlib import Path
from typing import ClassVar

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from envs import rewards as R
from envs.clip_cache import GT_DIM, ClipArrays, ClipCache
from envs.scenes import humanoid_scenes
from grip.core import skeleton as sk
from grip.core.reference import ReferenceClip, ReferenceSet, ReferenceSource
from grip.core.reference_sets import clip_probabilities, start_bin_probabilities
from grip.sim.humanoid import ROW, ROW_DIM, Humanoid, body_state
from grip.task import amp as A
from grip.task import observations as O
from grip.task.config import TrackingEnvConfig
from grip.task.observations import heightmap_grid

SAMPLE_REFERENCE = Path(__file__).resolve().parent / "assets" / "sample_reference.npz"
"""The small bundled reference set used when the env is made without a reference."""

_INFO_KEYS = tuple(f"reward/{k}" for k in R.TERMS)
_HINGES = slice(ROW["hinge_q"].start, ROW["hinge_qd"].stop)  # (of a state row)
_TORQUE, _HQD = ROW["torque"], ROW["hinge_qd"]
_ROOT = O.OBS_ROW["est_root_pos"]


class GripTrackingEnv(gym.Env):
    """Track a reference clip with the simulated humanoid (Gymnasium API).

    Args:
        cfg: Settings (defaults: GRIP's stage-1 training setup on the bundled sample).
        reference: Clips to track; default: the file ``cfg.reference`` or the bundled sample.
        render_mode: ``None`` or ``"rgb_array"`` (needs an OpenGL backend, e.g.
            ``MUJOCO_GL=egl``).
        compiled_models: A cache of compiled models shared with environments of the same
            settings and reference (:class:`envs.scenes.HumanoidScenes`); ``None``: its own.
        clip_cache: The per-clip arrays, shared likewise (:class:`envs.clip_cache.ClipCache`);
            ``None``: its own.

    Observation: ``spaces.Dict`` with ``"sensor"`` (the KinematicsNet inputs of the next frame),
    ``"kinematic"`` (State Difference) and ``"self"`` (both
    :func:`grip.task.observations.observation_parts`) and ``"environment"`` (terrain height minus
    pelvis height on a heading-aligned ``heightmap_size``^2 grid). Action: ``(69,)`` in [-1, 1], see
    :attr:`TrackingEnvConfig.action_mode`.

    ``info`` holds every reward term as ``"reward/<name>"``, the clip name and frame,
    ``"max_joint_err_m"`` and ``"mpjpe_m"`` (against the ground truth), ``"sim_unstable"``
    (this step blew up), ``"blowups"`` (count over the env's life), ``"root_height_m"`` and,
    with ``cfg.amp_window > 0``, ``"amp_obs"``: the last ``amp_window`` AMP frames of the
    simulated humanoid (:mod:`grip.task.amp`; after a reset the window holds the ground truth of
    the frames before the start).
    """

    metadata: ClassVar[dict] = {"render_modes": ["rgb_array"], "render_fps": 100}

    def __init__(self, cfg: TrackingEnvConfig | None = None,
                 reference: ReferenceSource | None = None,
                 render_mode: str | None = None,
                 compiled_models: dict | None = None,
                 clip_cache: ClipCache | None = None) -> None:  # fmt: skip
        self.cfg = cfg = cfg or TrackingEnvConfig()
        if reference is None:
            reference = ReferenceSet.load(cfg.reference or SAMPLE_REFERENCE)
        if len(reference) == 0:
            raise ValueError("GripTrackingEnv: the reference source has no clips")
        self.reference = reference
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode {render_mode!r}: use None or 'rgb_array'")
        self.render_mode = render_mode
        fps = 1.0 / cfg.control_dt_s
        lengths = np.empty(len(reference))
        for i in range(len(reference)):
            c = reference.clip(i)
            if abs(c.fps - fps) > 1e-6 * fps:
                raise ValueError(f"clip {c.name!r} runs at {c.fps} Hz but the env controls at "
                                 f"{fps:g} Hz (substeps x timestep)")  # fmt: skip
            lengths[i] = c.n_frames
        self._clip_len = lengths
        self._clip_p = lengths / lengths.sum()  # random starts pick clips by length
        self._scenes = humanoid_scenes(cfg, compiled_models)
        self._grid = heightmap_grid(cfg.heightmap_size, cfg.heightmap_extent_m)
        self._hm = np.zeros(len(self._grid))
        clip0 = reference.clip(0)
        self._sim = self._humanoid_for(clip0, 0)
        sensor_dim = clip0.sensor.shape[1]
        box = lambda n: spaces.Box(-np.inf, np.inf, (n,), np.float32)  # noqa: E731
        self.observation_space = spaces.Dict({
            "sensor": box(sensor_dim),
            "kinematic": box(O.kinematic_dim(cfg.kinematic_obs)),
            "self": box(O.SELF_DIM),
            "environment": box(len(self._grid)),
        })  # fmt: skip
        if cfg.sensor_context:  # (TrackingEnvConfig.sensor_context: a gate's context)
            self.observation_space.spaces["sensor_context"] = box(2 * sensor_dim)
        if cfg.teacher_obs:  # (TrackingEnvConfig.teacher_obs: a privileged teacher's inputs)
            self.observation_space.spaces["teacher_kinematic"] = box(
                O.kinematic_dim(cfg.kinematic_obs))
            self.observation_space.spaces["teacher_shift"] = box(3 * (sk.N_JOINTS - 1))
        self.action_space = spaces.Box(-1.0, 1.0, (3 * (sk.N_JOINTS - 1),), np.float32)
        self.blowups = 0
        self._clip: ReferenceClip = clip0
        self._clip_i = 0
        self._next_clip = 0
        self._t = 0
        self._steps = 0
        self._last_obs: dict[str, np.ndarray] | None = None
        self._renderer = None
        self._renderer_model = None
        self._clips = clip_cache if clip_cache is not None else ClipCache()
        self._arrays: ClipArrays | None = None  # the episode's clip's
        self._gt_rows = np.zeros((0, GT_DIM))  # the episode's clip: ground-truth rows
        self._est = O.EstimateFrames()  # the estimate laid out for the step
        self._truth: O.EstimateFrames | None = None  # the ground truth so (teacher_obs)
        self._root_offset_truth = np.zeros(3)  # (as _root_offset, for the truth)
        self._self_scratch = np.empty((1, O.SELF_DIM), np.float32)
        self._action_gain = np.zeros(0)  # (69,) rad per unit of relative action
        self._root_offset = np.zeros(3)  # episode start: ground truth minus integrated estimate
        self._root_speed = 1.0  # the episode's root-speed factor (cfg.root_speed_range)
        self._lean_deg = 0.0  # the episode's lean of the followed trunk (cfg.lean_range_deg)
        self._root_hist: deque = deque(maxlen=1)  # simulated pelvis xy of the last frames
        self._amp = A.AmpHistory(cfg.amp_window) if cfg.amp_window > 0 else None
        self._amp_buf = np.empty(A.FRAME_DIM)  # (reused by every step)
        self._weights = tuple(float(getattr(cfg.reward.weights, k)) for k in R.TERMS)
        self._relative = cfg.action_mode == "relative"
        self._vel_s = cfg.reward.root_vel_window_frames * cfg.control_dt_s
        # step buffers (reused by every step)
        self._row = np.empty((1, ROW_DIM))  # the state (grip.sim.humanoid.ROW_PARTS)
        self._est_row = np.empty((1, O.OBS_ROW_DIM))
        self._amp_row = self._amp_buf[None]
        sizes = [int(sp.shape[0]) for sp in self.observation_space.spaces.values()]
        ends = np.cumsum(sizes)
        names = list(self.observation_space.spaces)
        self._obs_parts = tuple((k, slice(int(e) - n, int(e)))
                                for k, n, e in zip(names, sizes, ends, strict=True))  # fmt: skip
        self._obs_size = int(ends[-1])
        self.termination_dist_m = cfg.termination_dist_m
        self._clip_tau: np.ndarray | None = None  # (set_clip_termination_dists)
        self._start_bins: tuple[int, list] | None = None  # (set_start_bin_weights)

    def set_termination_dist(self, dist_m: float) -> None:
        """Change the early-termination distance (m, 0 = off) from the next step on: the
        training curriculum loosens it at first (:class:`policies.config.StageConfig`)."""
        if not dist_m >= 0:
            raise ValueError(f"termination distance must be >= 0 m, got {dist_m}")
        self.termination_dist_m = float(dist_m)

    def set_clip_weights(self, weights) -> None:
        """Random starts pick clip ``i`` with probability proportional to its length times
        ``weights[i]`` from the next reset on (all ones: by length, the default). The trainer's
        hard-clip mining (:class:`policies.mining.ClipFailureStats`) sets them."""
        self._clip_p = clip_probabilities(self._clip_len, weights)

    def set_start_bin_weights(self, bin_frames: int, weights) -> None:
        """Random starts within clip ``i`` pick a bin of ``bin_frames`` frames with probability
        its start frames times ``weights[i][b]``, then a frame uniformly in it
        (:func:`grip.core.reference_sets.start_bin_probabilities`), from the next reset on;
        ``weights`` ``None`` (the default) or a clip's ``None``: every start frame equally. The
        trainer's failure-weighted starts (:class:`policies.mining.StartBinStats`) set them."""
        if weights is not None and len(weights) != len(self.reference):
            raise ValueError(f"start bin weights: one entry per clip ({len(self.reference)}), "
                             f"got {len(weights)}")  # fmt: skip
        self._start_bins = None if weights is None else (int(bin_frames), list(weights))

    def set_clip_termination_dists(self, dists) -> None:
        """A termination distance per clip (m, 0 = off; ``None``: the env's one distance): the
        episode on clip ``i`` ends when a joint is farther than ``dists[i]``, from now on (the
        trainer's per-category termination, :class:`policies.curriculum.CategoryTermination`).
        """
        if dists is None:
            self._clip_tau = None
            return
        d = np.asarray(dists, dtype=np.float64)
        if d.shape != (len(self.reference),) or not (d >= 0).all():
            raise ValueError(f"clip termination distances must be {len(self.reference)} "
                             f"values >= 0 m, got shape {d.shape}")  # fmt: skip
        self._clip_tau = d
        self.termination_dist_m = float(d[self._clip_i])

    def _random_start(self, i: int, last_start: int) -> int:
        """A random start frame in ``0 .. last_start`` of clip ``i`` (by bin weight when
        :meth:`set_start_bin_weights` gave the clip some)."""
        w = None if self._start_bins is None else self._start_bins[1][i]
        if w is None:
            return int(self.np_random.integers(0, last_start + 1))
        f = self._start_bins[0]
        p = start_bin_probabilities(last_start, f, w)
        b = int(self.np_random.choice(len(p), p=p))
        return int(self.np_random.integers(b * f, min((b + 1) * f, last_start + 1)))

    # ------------------------------------------------------------------ models
    def _humanoid_for(self, clip: ReferenceClip, i: int) -> Humanoid:
        """The humanoid of the clip's subject in the clip's scene (:class:`envs.scenes.
        HumanoidScenes`: one model per scene, subjects switched in). The task reads none of
        its sensors, and one body tree needs no constraint islands: both are off (the same
        physics bit for bit, cheaper steps: :attr:`Humanoid.sensors`, :attr:`Humanoid.
        islands`)."""
        h = self._scenes.get(clip.body, clip.objects, i)
        h.sensors = h.islands = False
        return h

    @property
    def humanoid(self) -> Humanoid:
        """The simulated humanoid of the current episode."""
        return self._sim

    @property
    def model(self) -> mujoco.MjModel:
        """The MuJoCo model of the current episode."""
        return self._sim.model

    @property
    def data(self) -> mujoco.MjData:
        """The MuJoCo data of the current episode."""
        return self._sim.data

    @property
    def clip(self) -> ReferenceClip:
        """The reference clip of the current episode."""
        return self._clip

    @property
    def frame(self) -> int:
        """The clip frame the simulation is at."""
        return self._t

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode.

        ``options``: ``{"clip": i, "start": frame}`` pick the clip and start frame (otherwise
        ``cfg.clip_index``, random starts, or the clips in turn from frame 0).
        """
        super().reset(seed=seed)
        cfg = self.cfg
        options = options or {}
        n = len(self.reference)
        if "clip" in options:
            i = int(options["clip"])
        elif cfg.clip_index >= 0:
            i = cfg.clip_index
        elif cfg.random_start:
            i = int(self.np_random.choice(n, p=self._clip_p))
        else:
            i = self._next_clip
            self._next_clip = (self._next_clip + 1) % n
        if not 0 <= i < n:
            raise ValueError(f"clip index {i} outside 0..{n - 1}")
        clip = self.reference.clip(i)
        last_start = max(clip.n_frames - 1 - cfg.min_episode_frames, 0)
        if "start" in options:
            start = int(options["start"])
            if not 0 <= start < clip.n_frames - 1:
                raise ValueError(f"start frame {start} outside 0..{clip.n_frames - 2}")
        elif cfg.random_start:
            start = self._random_start(i, last_start)
        else:
            start = 0
        self._clip, self._clip_i = clip, i
        if self._clip_tau is not None:
            self.termination_dist_m = float(self._clip_tau[i])
        self._sim = self._humanoid_for(clip, i)
        self._t = start
        self._steps = 0
        self._sim.reset(clip.gt_qpos[start], clip.gt_qvel[start])
        lo, hi = cfg.root_speed_range
        self._root_speed = float(self.np_random.uniform(lo, hi)) if hi > lo else float(lo)
        lo, hi = cfg.lean_range_deg
        self._lean_deg = float(self.np_random.uniform(lo, hi)) if hi > lo else float(lo)
        # the estimated root is integrated from the clip's first frame; an episode follows it
        # from where the episode starts (the ground truth there), not with the drift before
        self._per_clip_arrays(clip, i)
        self._set_root_offsets(clip.gt_qpos[start, :3], start)
        pvw, rot = self._sim.state()
        window = cfg.reward.root_vel_window_frames + 1
        self._root_hist = deque([pvw[0, 0, :2].copy()], maxlen=window)
        obs = self._observe(pvw, rot)
        self._last_obs = obs
        info = {"clip": clip.name, "clip_index": i, "frame": start,
                "root_height_m": float(pvw[0, 0, 2])}  # fmt: skip
        if self._amp is not None:
            ref = self._arrays.amp
            self._amp.reset(ref[max(0, start - self._amp.window + 1) : start + 1])
            info["amp_obs"] = self._amp.vector()
        return obs, info

    def _set_root_offsets(self, pos: np.ndarray, t: int) -> None:
        """Follow the integrated roots (the estimate's and, for a teacher, the truth's) from
        ``pos`` at frame ``t``, at the episode's root speed."""
        f = self._root_speed
        self._root_offset = O.root_speed_offset(pos, self._clip.est_root_pos[t], f)
        if self._truth is not None:
            self._root_offset_truth = O.root_speed_offset(pos, self._truth.est.est_root_pos[t], f)

    def _followed_rows(self, frames: O.EstimateFrames, t: int, offset: np.ndarray,
                       out: np.ndarray) -> None:
        """``out (1, OBS_ROW_DIM)``: frame ``t`` of ``frames`` at the episode's root speed,
        its root offset by ``offset``."""
        out[0] = frames.obs_rows[t]
        if self._root_speed != 1.0:
            O.scale_root_speed(out, self._root_speed)
        out[0, _ROOT] += offset

    def _lean(self, t: int) -> np.ndarray | None:
        """``(3, 3)`` the episode's lean of frame ``t``'s followed upper body
        (``cfg.lean_range_deg``; None: upright)."""
        if self._lean_deg == 0.0:
            return None
        return O.forward_lean(self._est.est.est_rot[t, 0], self._lean_deg)

    def _amp_frame(self, pvw: np.ndarray, rot: np.ndarray) -> np.ndarray:
        """The AMP frame of the simulated state (:func:`grip.task.amp.amp_frame`)."""
        sim = self._sim
        return A.amp_frame(pvw, rot, sim.hinge_angles(), sim.hinge_velocities(), self._amp_buf)

    def _per_clip_arrays(self, clip: ReferenceClip, i: int) -> None:
        """Per-clip arrays laid out for the step (built once per clip and subject, kept in
        the cache shared with the other environments of a batch)."""
        sim, cfg = self._sim, self.cfg
        got = self._clips.get(i, sim.key, clip, sim.kd_over_kp, cfg.velocity_feedforward,
                              cfg.teacher_obs)  # fmt: skip
        self._arrays = got
        self._est, self._gt_rows, self._truth = got.est, got.gt, got.truth
        self._action_gain = cfg.action_scale * sim.half

    def _observe(self, pvw: np.ndarray, rot: np.ndarray,
                 h: np.ndarray | None = None) -> dict[str, np.ndarray]:  # fmt: skip
        """The observation of a state (``pvw (3, J, 3)``, ``rot (J, 3, 3)``; ``h (1, 3, 3)``
        its heading matrix when known) against the estimate of the next frame: the numbers
        of :meth:`grip.task.observations.EstimateFrames.observe`, as new float32 arrays (views of
        one block)."""
        t = min(self._t + 1, self._clip.n_frames - 1)
        est, cfg = self._est, self.cfg
        er = self._est_row
        self._followed_rows(est, t, self._root_offset, er)
        lean = self._lean(t)
        if lean is not None:
            O.lean_rows(er, lean[None])
        pvw, rot = pvw[None], rot[None]
        if h is None:
            h = O.heading_matrices(rot[:, 0])
        block = np.empty(self._obs_size, np.float32)
        obs = {k: block[sl] for k, sl in self._obs_parts}
        obs["sensor"][:] = est.est.sensor[t]
        if cfg.sensor_context:
            obs["sensor_context"][:] = O.sensor_context_at(est.est.sensor, t, cfg.sensor_context)
        O.observation_rows(cfg.kinematic_obs, h, pvw, rot, er, obs["kinematic"][None],
                           obs["self"][None])  # fmt: skip
        root = pvw[0, 0, 0]
        terrain = self._sim.terrain
        if terrain is None:  # flat floor: the height map is the pelvis height
            obs["environment"][:] = -root[2]
        else:
            obs["environment"][:] = terrain(root[:2], h[0, :2, :2], self._grid, self._hm) - root[2]
        if self._truth is not None:
            tr = self._truth
            if cfg.teacher_root == "estimate":  # keep the student's root (offset included)
                root = er[0, _ROOT].copy()
                self._followed_rows(tr, t, self._root_offset_truth, er)
                er[0, _ROOT] = root
            else:
                self._followed_rows(tr, t, self._root_offset_truth, er)
            O.observation_rows(cfg.kinematic_obs, h, pvw, rot, er,
                               obs["teacher_kinematic"][None], self._self_scratch)  # fmt: skip
            if self._relative:
                obs["teacher_shift"][:] = (tr.target[t] - est.target[t]) / self._action_gain
            else:  # (an absolute action is the same PD target whoever follows what)
                obs["teacher_shift"][:] = 0.0
        return obs

    def step(self, action):
        cfg, sim, clip = self.cfg, self._sim, self._clip
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != (A.N_HINGES,) or not np.isfinite(a).all():
            raise ValueError(f"action must be ({A.N_HINGES},) finite values, got shape "
                             f"{a.shape}")  # fmt: skip
        t = self._t + 1
        sim.set_targets(self._est.pd_target(a, t, self._relative, self._action_gain, sim.lo,
                                            sim.half, self._lean(t)))  # fmt: skip
        if cfg.pin_root:
            sim.step_pinned(clip.gt_qpos[t - 1], clip.gt_qpos[t], clip.gt_qvel[t, :6])
        else:
            sim.step()
        self._t = t
        self._steps += 1
        # A blow-up (Humanoid.blown_up) ends the episode; the state stays as it is until a reset
        # (its observation is the last good one)
        if sim.blown_up():
            self.blowups += 1
            info = dict.fromkeys(_INFO_KEYS, 0.0)
            info.update(clip=clip.name, clip_index=self._clip_i, frame=t, max_joint_err_m=np.inf,
                        mpjpe_m=np.inf, sim_unstable=True, blowups=self.blowups,
                        root_height_m=0.0)  # fmt: skip
            if self._amp is not None:
                info["amp_obs"] = self._amp.vector()
            return {k: v.copy() for k, v in self._last_obs.items()}, 0.0, True, False, info
        row = self._row
        sim.gather(row[0])
        pvw, rot = body_state(row)  # (1, 3, J, 3), (1, J, 3, 3) views of the row
        gt = self._gt_rows
        hist = self._root_hist
        hist.append(row[0, :2].copy())
        # displacements over the window's frames (fewer after a reset or teleport), divided by
        # the full window's length: millimetres over the first frames are not read as velocity
        ref_disp = (gt[t, :2] - gt[t - (len(hist) - 1), :2]) * self._root_speed
        # the pelvis the policy follows (the integrated root from where the episode started)
        gap = (self._est.obs_rows[t, _ROOT][:2] * self._root_speed + self._root_offset[:2]
               - row[0, :2])  # fmt: skip
        terms, sq = R.tracking_terms_rows(row, gt[t : t + 1], cfg.reward, cfg.align_root_xy,
                                          (hist[-1] - hist[0])[None], ref_disp[None],
                                          self._vel_s, gap[None])  # fmt: skip
        values = terms[0].tolist()
        if self._steps > cfg.reward.energy_skip_frames:
            values.append(R.mechanical_power(row[0, _TORQUE], row[0, _HQD]))
        else:
            values.append(0.0)
        values.append(0.0)  # amp (a wrapper fills it)
        reward = 0.0
        for wk, v in zip(self._weights, values, strict=True):
            reward += wk * v
        dist = np.sqrt(sq[0, 0])
        err = float(dist.max())  # (the unstable check above also makes this never NaN)
        z = float(row[0, 2])
        tau = self.termination_dist_m
        fell = z < cfg.fall_height_m and z < gt[t, 2] - cfg.fall_below_reference_m
        g_max = cfg.termination_root_gap_m
        strayed = g_max > 0 and float(gap @ gap) > g_max * g_max
        terminated = (tau > 0 and err > tau) or fell or strayed
        truncated = t >= clip.n_frames - 1 or (
            cfg.max_episode_frames > 0 and self._steps >= cfg.max_episode_frames
        )
        h = O.heading_matrices(rot[:, 0])
        obs = self._observe(pvw[0], rot[0], h)
        self._last_obs = obs
        info = dict(zip(_INFO_KEYS, values, strict=True))
        info.update(clip=clip.name, clip_index=self._clip_i, frame=t, max_joint_err_m=err,
                    mpjpe_m=float(dist.sum()) / dist.size, sim_unstable=False,
                    blowups=self.blowups, root_height_m=z)  # fmt: skip
        if self._amp is not None:
            A.amp_frames(pvw, rot, row[:, _HINGES], h, self._amp_row)
            self._amp.push(self._amp_buf)
            info["amp_obs"] = self._amp.vector()
        return obs, reward, bool(terminated), bool(truncated and not terminated), info

    def push_pelvis(self, force: np.ndarray) -> None:
        """Apply a world-frame force (N, ``(3,)``) at the pelvis' centre of mass for the
        following steps, until called again (zeros end it; a reset clears it): perturbations
        (``experiments/random_pushes.py``)."""
        f = np.asarray(force, dtype=np.float64).reshape(3)
        if not np.isfinite(f).all():
            raise ValueError(f"push force must be 3 finite values, got {force!r}")
        self._sim.push_pelvis(f)

    def teleport(self, qpos76: np.ndarray, qvel75: np.ndarray | None = None):
        """Put the humanoid in a new state at the current frame (:meth:`grip.sim.humanoid.
        Humanoid.teleport`: lifted onto the ground) and keep playing the clip from there: the
        episode's root offset, velocity window and AMP window restart from the new state.

        Returns:
            ``(obs, info)`` of the new state, as :meth:`reset` does.
        """
        sim, clip = self._sim, self._clip
        sim.teleport(qpos76, qvel75)
        r = sim.index.root_qpos_adr
        self._set_root_offsets(sim.qpos[r : r + 3], self._t)
        pvw, rot = sim.state()
        self._root_hist.clear()
        self._root_hist.append(pvw[0, 0, :2].copy())
        obs = self._observe(pvw, rot)
        self._last_obs = obs
        info = {"clip": clip.name, "clip_index": self._clip_i, "frame": self._t,
                "root_height_m": float(pvw[0, 0, 2])}  # fmt: skip
        if self._amp is not None:
            frame = self._amp_frame(pvw, rot).copy()
            self._amp.reset(np.repeat(frame[None], self._amp.window, axis=0))
            info["amp_obs"] = self._amp.vector()
        return obs, info

    # ------------------------------------------------------------------ rendering
    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self._renderer is None or self._renderer_model is not self.model:
            self._renderer = mujoco.Renderer(self.model, 480, 640)
            self._renderer_model = self.model
            self._camera = mujoco.MjvCamera()
            self._camera.type = mujoco.mjtCamera.mjCAMERA_TRACKING
            self._camera.trackbodyid = self._sim.pelvis_body
            self._camera.distance, self._camera.elevation = 3.5, -15.0
        self._renderer.update_scene(self.data, camera=self._camera)
        return self._renderer.render()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
