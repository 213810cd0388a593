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

import types
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from envs import amp as A
from envs import observations as O
from envs import rewards as R
from envs.config import TrackingEnvConfig
from envs.terrain import (
    HeightField,
    add_heightfield,
    heightmap_grid,
    make_scene,
    rasterize,
    sample_heightmap,
)
from grip.core import skeleton as sk
from grip.core.body import BodyParams
from grip.core.mjcf import build_mjcf
from grip.core.reference import ReferenceClip, ReferenceSet, ReferenceSource
from grip.sim.model import (
    HumanoidIndex,
    ModelVariants,
    write_pose_vector,
    write_velocity_vector,
)

SAMPLE_REFERENCE = Path(__file__).resolve().parent / "assets" / "sample_reference.npz"
"""The small bundled reference set used when the env is made without a reference."""

_UNSTABLE = np.array([int(w) for w in (mujoco.mjtWarning.mjWARN_BADQPOS,
                                       mujoco.mjtWarning.mjWARN_BADQVEL,
                                       mujoco.mjtWarning.mjWARN_BADQACC)])  # fmt: skip
"""MuJoCo's warnings for a state it could not integrate (it then resets ``MjData`` itself, which
also zeroes the counters, and counts the warning: a second blow-up leaves the count at 1)."""
_W_QPOS, _W_QVEL, _W_QACC = (int(w) for w in _UNSTABLE)


def _as_slice(idx: np.ndarray) -> slice | np.ndarray:
    """A slice for consecutive indices (basic indexing is cheaper than fancy indexing)."""
    if idx.size and np.array_equal(idx, np.arange(idx[0], idx[0] + idx.size)):
        return slice(int(idx[0]), int(idx[0]) + idx.size)
    return idx


_INFO_KEYS = tuple((k, f"reward/{k}") for k in R.TERMS)

_KEY = np.array(A.KEY_JOINTS)
_AMP_PARTS = tuple(A.PARTS.values())  # (envs.amp.amp_features' layout, in order)
_C1, _C2 = np.array([1, 2, 0]), np.array([2, 0, 1])  # index permutations of a cross product


@dataclass(eq=False)
class _Sim:
    """A compiled humanoid (one scene; the subject's body switched in by ``variants``) with
    its data and index arrays."""

    model: mujoco.MjModel
    data: mujoco.MjData
    index: HumanoidIndex
    hfield: HeightField | None
    lo: np.ndarray  # (69,) hinge lower limits, SMPL order
    hi: np.ndarray
    pelvis_body: int
    kd_over_kp: np.ndarray  # (69,) s
    half: np.ndarray  # (69,) half the hinge ranges, rad
    # views of MjData arrays, taken once (attribute access through the bindings is slow)
    xpos: np.ndarray
    xmat: np.ndarray
    cvel: np.ndarray
    com: np.ndarray  # (3,) subtree COM of the pelvis
    ctrl: np.ndarray
    qvel: np.ndarray
    qpos: np.ndarray
    act_force: np.ndarray
    warnings: np.ndarray  # live view of MjData.warning.number
    act: slice | np.ndarray  # actuator_ids, as a slice when they are 0..68 in order
    variants: ModelVariants  # the bodies of the clips played on this scene
    lin: slice  # qvel of the pelvis' linear velocity
    ang: slice | np.ndarray  # qvel of every angular velocity (pelvis and hinges)
    root_z: int  # qpos address of the pelvis height
    z_range: tuple[float, float]  # pelvis heights outside this are a blow-up, m


class GripTrackingEnv(gym.Env):
    """Track a reference clip with the simulated humanoid (Gymnasium API).

    Args:
        cfg: Settings (defaults: GRIP's stage-1 training setup on the bundled sample).
        reference: Clips to track; default: the file ``cfg.reference`` or the bundled sample.
        render_mode: ``None`` or ``"rgb_array"`` (needs an OpenGL backend, e.g.
            ``MUJOCO_GL=egl``).

    Observation: ``spaces.Dict`` with ``"sensor"`` (the KinematicsNet inputs of the next frame),
    ``"kinematic"`` (State Difference, :func:`envs.observations.state_difference`), ``"self"``
    (:func:`envs.observations.self_obs`) and ``"environment"`` (terrain height minus pelvis
    height on a heading-aligned ``heightmap_size``^2 grid). Action: ``(69,)`` in [-1, 1], see
    :attr:`TrackingEnvConfig.action_mode`.

    ``info`` holds every reward term as ``"reward/<name>"``, the clip name and frame,
    ``"max_joint_err_m"`` and ``"mpjpe_m"`` (against the ground truth), ``"sim_unstable"``
    (this step blew up), ``"blowups"`` (count over the env's life), ``"root_height_m"`` and,
    with ``cfg.amp_window > 0``, ``"amp_obs"``: the last ``amp_window`` AMP frames of the
    simulated humanoid (:mod:`envs.amp`; after a reset the window holds the ground truth of
    the frames before the start).
    """

    metadata: ClassVar[dict] = {"render_modes": ["rgb_array"], "render_fps": 100}

    def __init__(self, cfg: TrackingEnvConfig | None = None,
                 reference: ReferenceSource | None = None,
                 render_mode: str | None = None) -> None:  # fmt: skip
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
        self._sims: dict[tuple, _Sim] = {}
        self._grid = heightmap_grid(cfg.heightmap_size, cfg.heightmap_extent_m)
        self._hm = np.zeros(len(self._grid))
        clip0 = reference.clip(0)
        self._sim = self._sim_for(clip0, 0)
        sensor_dim = clip0.sensor.shape[1]
        box = lambda n: spaces.Box(-np.inf, np.inf, (n,), np.float32)  # noqa: E731
        self.observation_space = spaces.Dict({
            "sensor": box(sensor_dim),
            "kinematic": box(O.kinematic_dim(cfg.kinematic_obs)),
            "self": box(O.SELF_DIM),
            "environment": box(len(self._grid)),
        })  # fmt: skip
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
        self._cache_key: tuple | None = None  # (clip, sim) of the per-clip arrays below
        self._gt_pvw = np.zeros(0)  # (T, 3, J, 3) ground-truth positions and velocities
        self._est_leaf_rot = np.zeros(0)  # (T, 4, 3, 3) estimated rotations of the IMU bodies
        self._est_leaf_angvel = np.zeros(0)  # (T, 4, 3)
        self._ref_target = np.zeros(0)  # (T, 69) relative-action reference (+ feed-forward)
        self._action_gain = np.zeros(0)  # (69,) rad per unit of relative action
        self._root_offset = np.zeros(3)  # episode start: ground truth minus integrated estimate
        self._root_hist: deque = deque(maxlen=1)  # simulated pelvis xy of the last frames
        self._amp = A.AmpHistory(cfg.amp_window) if cfg.amp_window > 0 else None
        self._amp_buf = np.empty(A.FRAME_DIM)
        self._amp_ref: dict[int, np.ndarray] = {}  # clip index -> ground-truth AMP frames
        self._weights = tuple((k, float(getattr(cfg.reward.weights, k))) for k in R.TERMS)
        self.termination_dist_m = cfg.termination_dist_m

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
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != self._clip_len.shape or not np.isfinite(w).all() or (w < 0).any():
            raise ValueError(f"clip weights must be {self._clip_len.size} finite values >= 0, "
                             f"got shape {w.shape}")  # fmt: skip
        p = self._clip_len * w
        if p.sum() <= 0:
            raise ValueError("clip weights are all zero: no clip could be picked")
        self._clip_p = p / p.sum()

    # ------------------------------------------------------------------ models
    def _scene_key(self, clip: ReferenceClip, i: int) -> tuple:
        if self.cfg.terrain == "auto":
            return ("objects", i) if clip.objects else ("flat",)
        return (self.cfg.terrain,)

    def _compile(self, clip: ReferenceClip, i: int) -> tuple[mujoco.MjModel, HeightField | None]:
        """The humanoid of the clip's subject in the clip's scene, compiled."""
        kind = self._scene_key(clip, i)[0]
        if kind == "objects":
            objs = {n: types.SimpleNamespace(vertices=v, faces=f)
                    for n, (v, f) in clip.objects.items()}  # fmt: skip
            scene = make_scene("objects", objects=objs)
        else:
            scene = make_scene(kind)
        xml = build_mjcf(clip.body, self.cfg.mjcf)
        hf = None if scene.is_flat else rasterize(scene, self.cfg.heightfield_cell_m)
        if hf is not None:
            xml = add_heightfield(xml, hf)
        return mujoco.MjModel.from_xml_string(xml), hf

    def _sim_for(self, clip: ReferenceClip, i: int) -> _Sim:
        """The simulation of the clip's scene with the clip's subject switched in: one model
        per scene; a new subject is compiled once and then swapped in by copying arrays
        (:class:`grip.sim.model.ModelVariants`), so that resets across the many subjects of a
        training set do not compile models."""
        body: BodyParams = clip.body
        skey, bkey = self._scene_key(clip, i), (body.height_m, body.mass_kg)
        sim = self._sims.get(skey)
        if sim is not None:
            if sim.variants.key != bkey:
                if bkey not in sim.variants:
                    sim.variants.add(bkey, self._compile(clip, i)[0])
                sim.variants.switch(bkey)
                sim.kd_over_kp = self._kd_over_kp(sim.model, sim.index)
            return sim
        model, hf = self._compile(clip, i)
        index = HumanoidIndex.from_model(model)
        act = index.actuator_ids
        rng = model.actuator_ctrlrange[act]
        d = mujoco.MjData(model)
        pelvis = int(index.body_ids[0])
        rv = index.root_dof_adr
        ang = np.setdiff1d(np.arange(model.nv), np.arange(rv, rv + 3))
        top = 0.0 if hf is None else float(hf.heights.max())
        sim = _Sim(model, d, index, hf, rng[:, 0].copy(), rng[:, 1].copy(), pelvis,
                   self._kd_over_kp(model, index), 0.5 * (rng[:, 1] - rng[:, 0]),
                   d.xpos, d.xmat, d.cvel, d.subtree_com[pelvis], d.ctrl, d.qvel, d.qpos,
                   d.actuator_force, d.warning.number, _as_slice(act),
                   ModelVariants(model, bkey), slice(rv, rv + 3), _as_slice(ang),
                   index.root_qpos_adr + 2,
                   (-self.cfg.blowup_depth_m, top + self.cfg.blowup_height_m))  # fmt: skip
        if len(self._sims) >= 16:  # bounded cache: drop the oldest scene
            self._sims.pop(next(iter(self._sims)))
        self._sims[skey] = sim
        return sim

    @staticmethod
    def _kd_over_kp(model: mujoco.MjModel, index: HumanoidIndex) -> np.ndarray:
        act = index.actuator_ids
        return -model.actuator_biasprm[act, 2] / model.actuator_gainprm[act, 0]

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
            start = int(self.np_random.integers(0, last_start + 1))
        else:
            start = 0
        self._clip, self._clip_i = clip, i
        self._sim = self._sim_for(clip, i)
        self._t = start
        self._steps = 0
        self._set_state(clip, start)
        # the estimated root is integrated from the clip's first frame; an episode follows it
        # from where the episode starts (the ground truth there), not with the drift before
        self._root_offset = clip.gt_qpos[start, :3] - clip.est_root_pos[start]
        self._per_clip_arrays(clip)
        pvw, rot = self._sim_state()
        window = cfg.reward.root_vel_window_frames + 1
        self._root_hist = deque([pvw[0, 0, :2].copy()], maxlen=window)
        obs = self._observe(pvw, rot)
        self._last_obs = obs
        info = {"clip": clip.name, "clip_index": i, "frame": start,
                "root_height_m": float(pvw[0, 0, 2])}  # fmt: skip
        if self._amp is not None:
            ref = self._amp_ref.get(i)
            if ref is None:
                if len(self._amp_ref) >= 64:
                    self._amp_ref.pop(next(iter(self._amp_ref)))
                ref = self._amp_ref[i] = A.reference_amp_features(clip)
            self._amp.reset(ref[max(0, start - self._amp.window + 1) : start + 1])
            info["amp_obs"] = self._amp.vector()
        return obs, info

    def _amp_frame(self, pvw: np.ndarray, rot: np.ndarray) -> np.ndarray:
        """The AMP frame of the simulated state: :func:`envs.amp.amp_features` for one frame,
        written out (the batched version's einsums cost more than the physics of a step)."""
        sim = self._sim
        ix = sim.index
        h = O.heading_matrix(rot[0])
        f = self._amp_buf
        height, root_rot, root_vel, root_angvel, hinge_q, hinge_qd, key_pos = _AMP_PARTS
        f[height] = pvw[0, 0, 2]
        f[root_rot] = (h.T @ rot[0])[:, :2].T.reshape(6)
        f[root_vel] = pvw[1, 0] @ h
        f[root_angvel] = pvw[2, 0] @ h
        f[hinge_q] = sim.data.qpos[ix.hinge_qpos_adr]
        f[hinge_qd] = sim.qvel[ix.hinge_dof_adr]
        f[key_pos] = ((pvw[0, _KEY] - pvw[0, 0]) @ h).reshape(-1)
        return f

    def _per_clip_arrays(self, clip: ReferenceClip, start: int = 0) -> None:
        """Per-clip arrays laid out for the step (gathered once per episode, not per step);
        ``start``: only frames from there on changed (a growing
        :class:`grip.core.reference.LiveClip`)."""
        sim, cfg = self._sim, self.cfg
        rows = len(clip.gt_qpos)  # a live clip's capacity, else its length
        if self._cache_key != (clip, sim) or len(self._ref_target) != rows:
            self._cache_key = (clip, sim)
            start = 0
            n_imu = len(O.IMU_JOINTS)
            self._gt_pvw = np.empty((rows, 3, sk.N_JOINTS, 3))
            self._est_leaf_rot = np.empty((rows, n_imu, 3, 3))
            self._est_leaf_angvel = np.empty((rows, n_imu, 3))
            self._ref_target = np.empty((rows, 3 * (sk.N_JOINTS - 1)))
            self._action_gain = cfg.action_scale * sim.half
        sl = slice(start, clip.n_frames)
        for k, key in enumerate(("gt_pos", "gt_vel", "gt_angvel")):
            self._gt_pvw[sl, k] = getattr(clip, key)[sl]
        self._est_leaf_rot[sl] = clip.est_rot[sl, O.IMU_JOINTS]
        self._est_leaf_angvel[sl] = clip.est_angvel[sl, O.IMU_JOINTS]
        ref = self._ref_target[sl]  # PD target of a relative action of 0
        ref[:] = clip.est_hinge[sl]
        if cfg.velocity_feedforward:
            ref += sim.kd_over_kp * clip.est_hinge_vel[sl]

    def refresh_reference(self, start: int = 0) -> dict[str, np.ndarray]:
        """The current clip changed from frame ``start`` on (a streaming
        :class:`grip.core.reference.LiveClip` grew by a frame): update the env's copies of it
        and return the observation of the current state against it, which replaces the one
        the last :meth:`reset`, :meth:`step` or :meth:`teleport` returned."""
        self._per_clip_arrays(self._clip, start)
        pvw, rot = self._sim_state()
        obs = self._observe(pvw, rot)
        self._last_obs = obs
        return obs

    def _set_state(self, clip: ReferenceClip, t: int) -> None:
        sim = self._sim
        m, d, ix = sim.model, sim.data, sim.index
        mujoco.mj_resetData(m, d)
        q = clip.gt_qpos[t]
        write_pose_vector(q, ix, d.qpos)
        write_velocity_vector(clip.gt_qvel[t], ix, d.qvel)
        d.ctrl[ix.actuator_ids] = np.clip(q[7:], sim.lo, sim.hi)
        mujoco.mj_forward(m, d)
        sim.warnings[_UNSTABLE] = 0

    def _blown_up(self) -> bool:
        """Whether the state after a step is a simulation blow-up: MuJoCo could not integrate
        it (its bad-qpos/qvel/qacc warnings, counted since the last check), or it is absurd
        before MuJoCo's own limit (1e10) is reached: non-finite, the pelvis faster than
        ``cfg.blowup_lin_vel_mps``, any joint turning faster than ``cfg.blowup_ang_vel_radps``,
        or the pelvis more than ``cfg.blowup_depth_m`` below the floor or ``cfg.blowup_height_m``
        above the terrain.
        Costs ~3 us; runs after every step."""
        sim, cfg = self._sim, self.cfg
        w = sim.warnings
        if w[_W_QPOS] or w[_W_QVEL] or w[_W_QACC]:  # (scalar reads: cheaper than w[_UNSTABLE])
            w[_UNSTABLE] = 0
            return True
        v = sim.qvel
        lin = v[sim.lin]
        z = sim.qpos[sim.root_z]
        lo, hi = sim.z_range
        # (written so that NaN fails every comparison and counts as a blow-up)
        ok = (float(lin @ lin) <= cfg.blowup_lin_vel_mps**2
              and float(np.abs(v[sim.ang]).max()) <= cfg.blowup_ang_vel_radps
              and lo <= z <= hi)  # fmt: skip
        return not ok

    def _sim_state(self) -> tuple[np.ndarray, np.ndarray]:
        """World state of the 24 bodies: ``pvw (3, J, 3)`` = positions (m), linear (m/s) and
        angular (rad/s) velocities, and rotations ``(J, 3, 3)``."""
        sim = self._sim
        ids = sim.index.body_ids
        pvw = np.empty((3, sk.N_JOINTS, 3))
        pos = pvw[0]
        pos[:] = sim.xpos[ids]
        cvel = sim.cvel[ids]
        w = cvel[:, :3]
        pvw[2] = w
        r = pos - sim.com
        # cvel is the velocity at the subtree COM; move it to each body origin: v + w x r
        pvw[1] = cvel[:, 3:] + (w[:, _C1] * r[:, _C2] - w[:, _C2] * r[:, _C1])
        return pvw, sim.xmat[ids].reshape(-1, 3, 3)

    def _observe(self, pvw: np.ndarray, rot: np.ndarray) -> dict[str, np.ndarray]:
        cfg, clip = self.cfg, self._clip
        t = min(self._t + 1, clip.n_frames - 1)
        root = pvw[0, 0]
        h = O.heading_matrix(rot[0])
        kin, self_vec = O.observation_parts(
            cfg.kinematic_obs, h, pvw, rot, clip.est_pos[t], self._est_leaf_rot[t],
            clip.est_vel[t], self._est_leaf_angvel[t], clip.est_root_pos[t] + self._root_offset,
        )  # fmt: skip
        if self._sim.hfield is None:  # flat floor: the height map is the pelvis height
            hm = np.full(self._grid.shape[0], -root[2], dtype=np.float32)
        else:
            hf = sample_heightmap(self._sim.hfield, root[:2], h[:2, :2], self._grid, out=self._hm)
            hm = (hf - root[2]).astype(np.float32)
        return {
            "sensor": clip.sensor[t].astype(np.float32),
            "kinematic": kin.astype(np.float32),
            "self": self_vec.astype(np.float32),
            "environment": hm,
        }

    def step(self, action):
        cfg, sim, clip = self.cfg, self._sim, self._clip
        m, d, ix = sim.model, sim.data, sim.index
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != (ix.actuator_ids.size,) or not np.isfinite(a).all():
            raise ValueError(f"action must be ({ix.actuator_ids.size},) finite values, got "
                             f"shape {a.shape}")  # fmt: skip
        a = np.minimum(np.maximum(a, -1.0), 1.0)  # (np.clip's dispatch costs more per step)
        t = self._t + 1
        if cfg.action_mode == "relative":
            target = self._ref_target[t] + a * self._action_gain
        else:
            target = sim.lo + (a + 1.0) * sim.half
        sim.ctrl[sim.act] = np.minimum(np.maximum(target, sim.lo), sim.hi)
        if cfg.pin_root:
            self._step_pinned(t)
        else:
            # mj_step = mj_step1 (positions, velocities) + mj_step2 (forces, integration). Run
            # them as step2 + step1 so that positions and velocities of the new state are
            # computed once, by the step itself (same trajectory as mj_step, bit for bit).
            for _ in range(cfg.substeps):
                mujoco.mj_step2(m, d)
                mujoco.mj_step1(m, d)
        self._t = t
        self._steps += 1
        # A blow-up (MuJoCo's warnings, or an absurd state, see _blown_up) ends the episode; the
        # state stays as it is until a reset or teleport (its observation is the last good one)
        if self._blown_up():
            self.blowups += 1
            info = {f"reward/{k}": 0.0 for k in R.TERMS}
            info.update(clip=clip.name, clip_index=self._clip_i, frame=t, max_joint_err_m=np.inf,
                        mpjpe_m=np.inf, sim_unstable=True, blowups=self.blowups,
                        root_height_m=0.0)  # fmt: skip
            if self._amp is not None:
                info["amp_obs"] = self._amp.vector()
            return {k: v.copy() for k, v in self._last_obs.items()}, 0.0, True, False, info
        pvw, rot = self._sim_state()
        gt = self._gt_pvw[t]
        hist = self._root_hist
        hist.append(pvw[0, 0, :2].copy())
        # displacements over the window's frames (fewer after a reset or teleport), divided by
        # the full window's length: millimetres over the first frames are not read as velocity
        ref_disp = gt[0, 0, :2] - self._gt_pvw[t - (len(hist) - 1), 0, 0, :2]
        root_vel = R.root_velocity_term(hist[-1] - hist[0], ref_disp,
                                        cfg.reward.root_vel_window_frames * cfg.control_dt_s,
                                        cfg.reward.k_root_vel)  # fmt: skip
        if cfg.align_root_xy:  # compare with the pelvis over the ground truth's (see config)
            shift = gt[0, 0, :2] - pvw[0, 0, :2]
            pvw[0, :, :2] += shift
            terms, sq = R.imitation_terms(pvw, rot, gt, clip.gt_rot[t], cfg.reward)
            pvw[0, :, :2] -= shift
        else:
            terms, sq = R.imitation_terms(pvw, rot, gt, clip.gt_rot[t], cfg.reward)
        power = R.mechanical_power(sim.act_force[sim.act], sim.qvel[ix.hinge_dof_adr])
        terms["root_vel"] = root_vel
        terms["energy"] = power if self._steps > cfg.reward.energy_skip_frames else 0.0
        terms["amp"] = 0.0
        reward = 0.0
        for k, wk in self._weights:
            reward += wk * terms[k]
        dist = np.sqrt(sq[0])
        err = float(dist.max())  # (the unstable check above also makes this never NaN)
        tau = self.termination_dist_m
        terminated = (tau > 0 and err > tau) or (pvw[0, 0, 2] < cfg.fall_height_m)
        truncated = t >= clip.n_frames - 1 or (
            cfg.max_episode_frames > 0 and self._steps >= cfg.max_episode_frames
        )
        obs = self._observe(pvw, rot)
        self._last_obs = obs
        info = {key: terms[k] for k, key in _INFO_KEYS}
        info.update(clip=clip.name, clip_index=self._clip_i, frame=t, max_joint_err_m=err,
                    mpjpe_m=float(dist.sum()) / dist.size, sim_unstable=False,
                    blowups=self.blowups, root_height_m=float(pvw[0, 0, 2]))  # fmt: skip
        if self._amp is not None:
            self._amp.push(self._amp_frame(pvw, rot))
            info["amp_obs"] = self._amp.vector()
        return obs, reward, bool(terminated), bool(truncated and not terminated), info

    def push_pelvis(self, force: np.ndarray) -> None:
        """Apply a world-frame force (N, ``(3,)``) at the pelvis' centre of mass for the
        following steps, until called again (zeros end it; a reset clears it). Training
        perturbations (:class:`envs.wrappers.RandomPushes`)."""
        f = np.asarray(force, dtype=np.float64).reshape(3)
        if not np.isfinite(f).all():
            raise ValueError(f"push force must be 3 finite values, got {force!r}")
        self._sim.data.xfrc_applied[self._sim.pelvis_body, :3] = f

    def teleport(self, qpos76: np.ndarray, qvel75: np.ndarray | None = None,
                 frame: int | None = None):  # fmt: skip
        """Put the humanoid in a new state at the current frame and keep playing the clip
        (GRIP's fall recovery): ``qpos76`` is a pose vector (:func:`grip.core.reference.
        pose_vector`), ``qvel75`` a velocity vector (zeros if ``None``). The body is lifted so
        that its lowest geom touches the ground, the AMP window restarts from the new state.
        ``frame``: move to this frame of the clip first (a stream resuming after a gap).

        Returns:
            ``(obs, info)`` of the new state, as :meth:`reset` does.
        """
        sim = self._sim
        m, d, ix = sim.model, sim.data, sim.index
        q = np.asarray(qpos76, dtype=np.float64).reshape(-1)
        v = np.zeros(75) if qvel75 is None else np.asarray(qvel75, dtype=np.float64).reshape(-1)
        finite = np.isfinite(q).all() and np.isfinite(v).all()
        if q.shape != (76,) or v.shape != (75,) or not finite:
            raise ValueError(f"teleport needs finite (76,) qpos and (75,) qvel, got {q.shape}, "
                             f"{v.shape}")  # fmt: skip
        if frame is not None:
            if not 0 <= frame < self._clip.n_frames:
                raise ValueError(f"teleport: frame {frame} outside 0..{self._clip.n_frames - 1}")
            self._t = int(frame)
        q = q.copy()
        q[7:] = np.clip(q[7:], sim.lo, sim.hi)
        write_pose_vector(q, ix, d.qpos)
        write_velocity_vector(v, ix, d.qvel)
        d.ctrl[ix.actuator_ids] = q[7:]
        mujoco.mj_forward(m, d)
        # lift (or lower) the body so that its lowest geom rests on the terrain under it
        r = ix.root_qpos_adr
        gap = self._lowest_clearance()
        d.qpos[r + 2] -= gap
        mujoco.mj_forward(m, d)
        self._root_offset = d.qpos[r : r + 3] - self._clip.est_root_pos[self._t]
        sim.warnings[_UNSTABLE] = 0
        pvw, rot = self._sim_state()
        self._root_hist.clear()
        self._root_hist.append(pvw[0, 0, :2].copy())
        obs = self._observe(pvw, rot)
        self._last_obs = obs
        info = {"clip": self._clip.name, "clip_index": self._clip_i, "frame": self._t,
                "root_height_m": float(pvw[0, 0, 2])}  # fmt: skip
        if self._amp is not None:
            frame = self._amp_frame(pvw, rot).copy()
            self._amp.reset(np.repeat(frame[None], self._amp.window, axis=0))
            info["amp_obs"] = self._amp.vector()
        return obs, info

    def _lowest_clearance(self) -> float:
        """Height of the humanoid's lowest geom point (bounding box corner) above the terrain
        under it, m."""
        sim = self._sim
        m, d = sim.model, sim.data
        g = np.flatnonzero(m.geom_bodyid > 0)
        rot = d.geom_xmat[g].reshape(-1, 3, 3)
        centre = d.geom_xpos[g] + np.einsum("gij,gj->gi", rot, m.geom_aabb[g, :3])
        z = centre[:, 2] - np.einsum("gj,gj->g", np.abs(rot[:, 2]), m.geom_aabb[g, 3:])
        ground = sample_heightmap(sim.hfield, centre[:, :2].mean(axis=0), np.eye(2),
                                  centre[:, :2] - centre[:, :2].mean(axis=0))  # fmt: skip
        return float((z - ground).min())

    def _step_pinned(self, t: int) -> None:
        """Substeps with the root written from the ground truth before each (``pin_root``)."""
        m, d, ix, clip = self._sim.model, self._sim.data, self._sim.index, self._clip
        r, rv, n = ix.root_qpos_adr, ix.root_dof_adr, self.cfg.substeps
        for k in range(n):
            f = (k + 1) / n
            d.qpos[r : r + 3] = (1 - f) * clip.gt_qpos[t - 1, :3] + f * clip.gt_qpos[t, :3]
            d.qpos[r + 3 : r + 7] = clip.gt_qpos[t if f >= 0.5 else t - 1, 3:7]
            d.qvel[rv : rv + 6] = clip.gt_qvel[t, :6]
            mujoco.mj_step(m, d)
        mujoco.mj_step1(m, d)  # derived quantities of the final state (see step())

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
