"""``WarpTrackingEnv``: N tracking episodes on MuJoCo Warp, stepped together on one device.

The task is :class:`envs.batched.BatchedTrackingEnv`'s (the same MJCF, PD actuation through
MuJoCo's position actuators, observations, rewards, AMP windows, early termination and height
map, from the same :class:`grip.task.config.TrackingEnvConfig`), but the state never leaves the
device: MuJoCo Warp holds N worlds in warp arrays, the env reads them as torch tensors
(``wp.to_torch``, no copy) and computes everything with :mod:`envs.warp.torch_task`.

What differs from the CPU env, and why:

* The physics runs in float32 (MuJoCo Warp's precision); the CPU env runs MuJoCo C in float64.
  From the same state and controls the two agree to about 1e-6 m over 400 physics steps on flat
  ground; on a height field they drift apart faster (MuJoCo Warp keeps at most 4 contacts per
  geom-hfield pair where MuJoCo C keeps every prism's), see ``docs/gpu.md``.
* Subjects: every clip's body is compiled once (:mod:`envs.warp.build`); the model arrays that
  differ between subjects (segment lengths, masses, gains) are batched per world and written
  at each reset, so worlds of different subjects step together.
* Scenes: one model for all worlds, where the CPU env switches models. A fixed terrain
  (``cfg.terrain`` = ``"boxes"``, ``"stairs"``, ``"chair"``) or the flat floor is every world's
  scene. With ``"auto"``, clips with their own scene objects (props) each show theirs: the model
  holds every props clip's height field and overhang meshes, and each world points its
  ``terrain`` and ``overhang_<j>`` geoms at its clip's and places them as the clip's own CPU
  model does, or parks them far under the floor (per-world geom arrays written at each reset,
  :mod:`envs.warp.scenes`). The height map samples each world's field, and the blow-up height
  bound is above each world's own.
* Blow-ups: MuJoCo C resets a state it cannot integrate and warns; MuJoCo Warp does neither.
  A world is a blow-up when its state is non-finite or beyond the ``blowup_*`` bounds
  (:func:`grip.sim.humanoid.absurd_rows`' bounds, here in torch).
* Sensors are off (``mjDSBL_SENSOR``): the task reads no simulated sensor; the observation's
  ``"sensor"`` part is the clip's recorded KinematicsNet input, as on the CPU.
* Worlds whose episode ended within a decision keep stepping until the decision's last frame
  (all worlds step together); their rewards, AMP frames and observations stop at the end, as on
  the CPU, and :meth:`reset` gives them a new episode.

The API is :class:`envs.batched.BatchedTrackingEnv`'s, in tensors: :meth:`step` takes ``(N, 69)``
actions and returns ``obs`` (dict of ``(N, ...)`` float32 tensors), ``reward``, ``terminated``,
``truncated`` and one info dict of ``(N, ...)`` tensors; :meth:`reset` starts new episodes in
the worlds of a mask. Nothing is reset automatically. :meth:`set_termination_dist`,
:meth:`set_clip_weights` (hard-clip mining), :meth:`set_start_bin_weights` (failure-weighted
starts) and :meth:`set_clip_termination_dists` (per-category termination) are the CPU env's,
for the trainer's curricula.
"""

from __future__ import annotations

import mujoco_warp as mjw
import numpy as np
import torch
import warp as wp
from numpy.typing import ArrayLike

from envs import rewards as R
from envs.warp import torch_task as T
from envs.warp.build import Models, build_clips, build_models
from envs.warp.scenes import SLOT_FIELDS
from grip.core import skeleton as sk
from grip.core.reference import ReferenceSource
from grip.core.reference_sets import clip_probabilities, start_bin_table
from grip.task import amp as A
from grip.task import observations as O
from grip.task.config import TrackingEnvConfig

_NJ = sk.N_JOINTS
_N_TERMS = len(R.TERMS)
_ROOT = O.OBS_ROW["est_root_pos"]

NCONMAX, NJMAX = 64, 400
"""Contacts and constraint rows allocated per world on the flat floor."""
NCONMAX_TERRAIN, NJMAX_TERRAIN = 256, 1200
"""... where a scene has a height field or overhangs (the sole pads touch both the floor and the
field's flat part: 64 pairs standing, docs/gpu.md)."""


class WarpTrackingEnv:
    """N tracking episodes on MuJoCo Warp.

    Args:
        cfg: Settings (those of :class:`envs.tracking_env.GripTrackingEnv`; ``pin_root``,
            ``teacher_obs`` and ``sensor_context`` are not supported, ``amp_window`` must be >= 1).
        reference: The clips.
        num_envs: N, the worlds.
        device: A warp device name (``"cpu"``, ``"cuda"``, ``"cuda:0"``); torch tensors live on
            the same device.
        seed: Seed of the env's ``torch.Generator`` (clip and start draws).
        nconmax: Contacts allocated per world (MuJoCo Warp allocates N x nconmax); ``None``:
            :data:`NCONMAX` on the flat floor, :data:`NCONMAX_TERRAIN` where a scene has a
            height field or overhangs.
        njmax: Constraint rows allocated per world; ``None``: :data:`NJMAX` or
            :data:`NJMAX_TERRAIN` so.

    Attributes:
        num_envs: N.
        model, data: The MuJoCo Warp model and data (read-only for callers).
        clip_index, frame: ``(N,)`` each world's clip and the clip frame it is at.
        subject_models: The compiled MuJoCo model of each subject (of the clips' bodies), in
            the scene (with ``terrain = "auto"`` and props clips: the assets of every props
            clip's scene, :func:`envs.warp.scenes.scenes_xml`).
    """

    def __init__(self, cfg: TrackingEnvConfig, reference: ReferenceSource, num_envs: int,
                 device: str = "cpu", seed: int = 0, nconmax: int | None = None,
                 njmax: int | None = None) -> None:  # fmt: skip
        if (cfg.pin_root or cfg.teacher_obs or cfg.sensor_context
                or tuple(cfg.root_speed_range) != (1.0, 1.0)
                or tuple(cfg.lean_range_deg) != (0.0, 0.0)):
            raise ValueError("WarpTrackingEnv: pin_root, teacher_obs, sensor_context, "
                             "root_speed_range and lean_range_deg are CPU-only settings")
        if cfg.amp_window < 1:
            raise ValueError("WarpTrackingEnv needs amp_window >= 1 (the AMP reward)")
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        self.cfg, self.reference, self.num_envs = cfg, reference, n = cfg, reference, num_envs
        self.wp_device = wp.get_device(device)
        self.device = torch.device(wp.device_to_torch(self.wp_device))
        self.k = cfg.action_repeat
        self._gen = torch.Generator(device=self.device)
        self._gen.manual_seed(int(seed))
        self._relative = cfg.action_mode == "relative"
        self._hist_n = cfg.reward.root_vel_window_frames + 1
        self._vel_s = cfg.reward.root_vel_window_frames * cfg.control_dt_s
        self._w = torch.tensor([float(getattr(cfg.reward.weights, k)) for k in R.TERMS],
                               device=self.device)  # fmt: skip
        mo = build_models(cfg, reference, self.device)
        self.index, self.subject_models, self.mj_model = mo.index, mo.subject_models, mo.mj_model
        self._subject_fields, self._hf = mo.subject_fields, mo.heightfields
        self.clips, lengths = build_clips(cfg, reference, mo, self.device)
        self._action_tables(mo.lo, mo.hi, lengths)
        terrain = mo.has_terrain
        self._alloc_sim(
            mo,
            (NCONMAX_TERRAIN if terrain else NCONMAX) if nconmax is None else nconmax,
            (NJMAX_TERRAIN if terrain else NJMAX) if njmax is None else njmax,
        )
        self._alloc_episodes()
        self.reset(torch.ones(n, dtype=torch.bool, device=self.device))

    # ------------------------------------------------------------------ construction
    def _action_tables(self, lo: np.ndarray, hi: np.ndarray, lengths: np.ndarray) -> None:
        """The clip draw, the PD target range and the height map grid as tensors."""
        cfg, dev = self.cfg, self.device
        self._clip_len = lengths
        self._clip_p = torch.as_tensor(self._clip_len / self._clip_len.sum(), device=dev)
        f32 = dict(dtype=torch.float32, device=dev)
        self._lo = torch.as_tensor(lo, **f32)
        self._hi = torch.as_tensor(hi, **f32)
        half = 0.5 * (hi - lo)
        self._half = torch.as_tensor(half, **f32)
        self._gain = torch.as_tensor(cfg.action_scale * half, **f32)
        self._grid = torch.as_tensor(O.heightmap_grid(cfg.heightmap_size, cfg.heightmap_extent_m),
                                     **f32)  # fmt: skip

    def _alloc_sim(self, mo: Models, nconmax: int, njmax: int) -> None:
        """The warp model (subject arrays batched per world), data, and torch views of it."""
        n, ix = self.num_envs, self.index
        batched = set(self._subject_fields) | set(SLOT_FIELDS if mo.slots else ())
        with wp.ScopedDevice(self.wp_device):
            self.model = mjw.put_model(self.mj_model, batch_sizes=dict.fromkeys(batched, n))
            self.data = mjw.make_data(self.mj_model, nworld=n, nconmax=nconmax, njmax=njmax)
        m, d = self.model, self.data
        self._model_views = {k: wp.to_torch(getattr(m, k)) for k in batched}
        tt = wp.to_torch
        self._qpos, self._qvel, self._ctrl = tt(d.qpos), tt(d.qvel), tt(d.ctrl)
        self._xpos, self._xmat, self._cvel = tt(d.xpos), tt(d.xmat), tt(d.cvel)
        self._subtree_com, self._act_force = tt(d.subtree_com), tt(d.actuator_force)
        self._clear = [tt(getattr(d, k)) for k in ("qacc_warmstart", "act", "qfrc_applied",
                                                   "xfrc_applied", "time")]  # fmt: skip
        dev = self.device
        self._body = torch.as_tensor(ix.body_ids, device=dev)
        self._pelvis = int(ix.body_ids[0])
        self._act = torch.as_tensor(ix.actuator_ids, device=dev)
        self._hinge_q = torch.as_tensor(ix.hinge_qpos_adr, device=dev)
        self._hinge_qd = torch.as_tensor(ix.hinge_dof_adr, device=dev)
        rv = ix.root_dof_adr
        self._root_lin = slice(rv, rv + 3)
        ang = np.setdiff1d(np.arange(self.mj_model.nv), np.arange(rv, rv + 3))
        self._ang = torch.as_tensor(ang, device=dev)
        self._root_z = ix.root_qpos_adr + 2
        self._clip_field = torch.as_tensor(mo.clip_field, device=dev)
        self._clip_z_hi = torch.as_tensor(mo.clip_z_hi, dtype=torch.float32, device=dev)
        self._scene_tables = None
        if mo.slots is not None:
            sl = mo.slots
            # (a clip without objects, scene -1, reads the last rows: every slot parked)
            scene = np.where(mo.clip_scene >= 0, mo.clip_scene, len(sl.xpos) - 1)
            self._clip_scene = torch.as_tensor(scene, device=dev)
            self._slot_geoms = torch.as_tensor(sl.geoms, device=dev)
            self._scene_tables = {k: torch.as_tensor(v, device=dev) for k, v in sl.model.items()}
            self._scene_xpos = torch.as_tensor(sl.xpos, device=dev)
            self._scene_xmat = torch.as_tensor(sl.xmat, device=dev)
            self._geom_xpos, self._geom_xmat = tt(d.geom_xpos), tt(d.geom_xmat)

    def _alloc_episodes(self) -> None:
        n, dev, cfg = self.num_envs, self.device, self.cfg
        i64 = dict(dtype=torch.int64, device=dev)
        f32 = dict(dtype=torch.float32, device=dev)
        self.clip_index = torch.zeros(n, **i64)
        self.frame = torch.zeros(n, **i64)
        self._steps = torch.zeros(n, **i64)
        self._root_offset = torch.zeros(n, 3, **f32)
        self._hist = torch.zeros(n, self._hist_n, 2, **f32)
        self._hist_pos = torch.zeros(n, **i64)
        self._hist_len = torch.zeros(n, **i64)
        self._amp = torch.zeros(n, cfg.amp_window, A.FRAME_DIM, **f32)
        self._good_pvw = torch.zeros(n, 3, _NJ, 3, **f32)
        self._good_rot = torch.zeros(n, _NJ, 3, 3, **f32)
        self._good_t = torch.zeros(n, **i64)
        self.termination_dist_m = torch.full((n,), cfg.termination_dist_m, **f32)
        self._clip_tau: torch.Tensor | None = None  # (C,) per-clip distances, m
        self._start_p: torch.Tensor | None = None  # (C, B) start-bin probabilities
        self._start_bin_frames = 1
        self._field = torch.full((n,), -1, **i64)  # the height field each world's clip shows
        self._z_hi = torch.full((n,), cfg.blowup_height_m, **f32)  # highest pelvis allowed, m
        self.blowups = 0

    # ------------------------------------------------------------------ state
    def _physics(self, fn) -> None:
        """Run a MuJoCo Warp call on the env's device, ordered with torch's work there."""
        with wp.ScopedDevice(self.wp_device):
            if self.wp_device.is_cuda:
                with wp.ScopedStream(wp.stream_from_torch(torch.cuda.current_stream(self.device))):
                    fn(self.model, self.data)
            else:
                fn(self.model, self.data)

    @property
    def qpos(self) -> torch.Tensor:
        """``(N, nq)`` MuJoCo's ``qpos`` of every world (a view of the warp array)."""
        return self._qpos

    def body_state(self) -> tuple[torch.Tensor, torch.Tensor]:
        """``pvw (N, 3, J, 3)`` and ``rot (N, J, 3, 3)`` of every world, SMPL order (the
        numbers of :func:`grip.sim.humanoid.body_state`; body-origin velocities from ``cvel``,
        which MuJoCo gives at the pelvis subtree's centre of mass)."""
        b = self._body
        pos = self._xpos[:, b]
        cvel = self._cvel[:, b]
        w = cvel[..., :3]
        r = pos - self._subtree_com[:, self._pelvis, None]
        vel = cvel[..., 3:] + torch.linalg.cross(w, r)
        return torch.stack([pos, vel, w], dim=1), self._xmat[:, b]

    def _blown(self) -> torch.Tensor:
        """``(N,)`` bool: the state is non-finite or beyond the ``blowup_*`` bounds (the
        pelvis' height above the top of the world's scene, as on the CPU)."""
        cfg, q, v = self.cfg, self._qpos, self._qvel
        lin = v[:, self._root_lin]
        ok = (lin * lin).sum(dim=1) <= cfg.blowup_lin_vel_mps**2
        ok &= v[:, self._ang].abs().amax(dim=1) <= cfg.blowup_ang_vel_radps
        z = q[:, self._root_z]
        ok &= (z >= -cfg.blowup_depth_m) & (z <= self._z_hi)
        ok &= torch.isfinite(q).all(dim=1)
        return ~ok

    # ------------------------------------------------------------------ episodes
    def reset(self, mask: torch.Tensor, clip: torch.Tensor | None = None,
              start: torch.Tensor | None = None) -> None:  # fmt: skip
        """Start new episodes in the worlds of ``mask (N,)`` (bool).

        Args:
            mask: The worlds to reset.
            clip, start: ``(M,)`` int64 clip and start frame of each of the M masked worlds
                (as ``GripTrackingEnv.reset(options={"clip", "start"})``); drawn as
                ``GripTrackingEnv`` draws random starts (clips by length times the weights of
                :meth:`set_clip_weights`) when ``None``.
        """
        cfg, c = self.cfg, self.clips
        idx = torch.nonzero(mask.to(self.device), as_tuple=True)[0]
        m = idx.numel()
        if m == 0:
            return
        if clip is None:
            if cfg.clip_index >= 0:
                clip = torch.full((m,), cfg.clip_index, dtype=torch.int64, device=self.device)
            else:
                clip = torch.multinomial(self._clip_p, m, replacement=True, generator=self._gen)
        clip = clip.to(self.device, torch.int64)
        if start is None:
            last = (c.n_frames[clip] - 1 - cfg.min_episode_frames).clamp(min=0)
            if cfg.random_start and self._start_p is not None:
                start = self._draw_binned_starts(clip, last)
            elif cfg.random_start:
                u = torch.rand(m, generator=self._gen, device=self.device, dtype=torch.float64)
                start = (u * (last + 1)).long().minimum(last)
            else:
                start = torch.zeros(m, dtype=torch.int64, device=self.device)
        start = start.to(self.device, torch.int64)
        row = c.offset[clip] + start
        # the world's subject and state (Humanoid.reset: fresh data, PD targets at the pose)
        subj = c.subject[clip]
        for name, table in self._subject_fields.items():
            view = self._model_views[name]
            view[idx] = table[subj].to(view.dtype).reshape(m, *view.shape[1:])
        if self._scene_tables is not None:
            # the clip's scene: its slot geoms' model rows and poses (envs.warp.scenes)
            scene, g = self._clip_scene[clip], self._slot_geoms
            at = (idx[:, None], g[None, :])
            for name, table in self._scene_tables.items():
                view = self._model_views[name]
                view[at] = table[scene].to(view.dtype).reshape(m, g.numel(), *view.shape[2:])
            self._geom_xpos[at] = self._scene_xpos[scene].to(self._geom_xpos.dtype)
            self._geom_xmat[at] = (
                self._scene_xmat[scene].to(self._geom_xmat.dtype).reshape(m, g.numel(), 3, 3)
            )
        if self._clip_tau is not None:
            self.termination_dist_m[idx] = self._clip_tau[clip]
        self._field[idx] = self._clip_field[clip]
        self._z_hi[idx] = self._clip_z_hi[clip]
        for a in self._clear:
            a[idx] = 0
        self._qpos[idx] = c.qpos[row]
        self._qvel[idx] = c.qvel[row]
        ctrl = self._ctrl[idx]
        ctrl[:, self._act] = torch.minimum(torch.maximum(c.qpos[row][:, self._hinge_q], self._lo),
                                           self._hi)  # fmt: skip
        self._ctrl[idx] = ctrl
        # positions and velocities of the new states (of all worlds: recomputing the others'
        # changes nothing, MuJoCo Warp has no per-world call)
        self._physics(mjw.step1)
        self.clip_index[idx], self.frame[idx], self._good_t[idx] = clip, start, start
        self._steps[idx] = 0
        self._root_offset[idx] = c.qpos[row][:, :3] - c.est_root[row]
        pvw, rot = self.body_state()
        self._good_pvw[idx], self._good_rot[idx] = pvw[idx], rot[idx]
        self._hist[idx, 0] = pvw[idx, 0, 0, :2]
        self._hist_len[idx] = 1
        self._hist_pos[idx] = 1 % self._hist_n
        # AMP window: the ground truth of the frames before the start, the oldest repeated
        w = cfg.amp_window
        back = (start[:, None] + torch.arange(-w + 1, 1, device=self.device)).clamp(min=0)
        self._amp[idx] = c.amp[c.offset[clip][:, None] + back]

    def set_clip_weights(self, weights: ArrayLike) -> None:
        """Random starts pick clip ``i`` with probability proportional to its length times
        ``weights[i]`` from the next reset on (all ones: by length, the default), as
        :meth:`envs.tracking_env.GripTrackingEnv.set_clip_weights`. The trainer's hard-clip
        mining (:class:`policies.mining.ClipFailureStats`) sets them.

        Args:
            weights: ``(C,)`` finite values >= 0, one per clip, not all zero (host values:
                checked on the host, then copied to the device once).
        """
        self._clip_p = torch.as_tensor(clip_probabilities(self._clip_len, weights),
                                       device=self.device)  # fmt: skip

    def set_termination_dist(self, dist_m: float) -> None:
        """Early-termination distance of every world from the next step on (m, 0 = off)."""
        if not dist_m >= 0:
            raise ValueError(f"termination distance must be >= 0 m, got {dist_m}")
        self.termination_dist_m.fill_(float(dist_m))

    def set_clip_termination_dists(self, dists: ArrayLike | None) -> None:
        """A termination distance per clip (m, 0 = off), from now on and at every reset
        (:meth:`envs.tracking_env.GripTrackingEnv.set_clip_termination_dists`); ``None``: the
        env's one distance from the next :meth:`set_termination_dist`."""
        if dists is None:
            self._clip_tau = None
            return
        d = np.asarray(dists, dtype=np.float64)
        if d.shape != self._clip_len.shape or not (d >= 0).all():
            raise ValueError(f"clip termination distances must be {self._clip_len.size} "
                             f"values >= 0 m, got shape {d.shape}")  # fmt: skip
        self._clip_tau = torch.as_tensor(d, dtype=torch.float32, device=self.device)
        self.termination_dist_m.copy_(self._clip_tau[self.clip_index])

    def set_start_bin_weights(self, bin_frames: int, weights) -> None:
        """Random starts within clip ``i`` pick a bin of ``bin_frames`` frames by its start
        frames times ``weights[i][b]``, then a frame uniformly in it, from the next reset on
        (:meth:`envs.tracking_env.GripTrackingEnv.set_start_bin_weights`; a clip's ``None``:
        uniform); ``weights`` ``None``: every start frame equally. The probabilities are made
        on the host (:func:`grip.core.reference_sets.start_bin_probabilities`) and copied to the
        device once, as a ``(C, most bins)`` table."""
        if weights is None:
            self._start_p = None
            return
        n_clips = self._clip_len.size
        if len(weights) != n_clips:
            raise ValueError(f"start bin weights: one entry per clip ({n_clips}), got "
                             f"{len(weights)}")  # fmt: skip
        last = np.maximum(self._clip_len.astype(np.int64) - 1 - self.cfg.min_episode_frames, 0)
        self._start_bin_frames = int(bin_frames)
        self._start_p = torch.as_tensor(start_bin_table(last, int(bin_frames), weights),
                                        device=self.device)  # fmt: skip

    def _draw_binned_starts(self, clip: torch.Tensor, last: torch.Tensor) -> torch.Tensor:
        """``(M,)`` start frames of clips ``clip (M,)`` (last starts ``last (M,)``) drawn by the
        start-bin table of :meth:`set_start_bin_weights`."""
        f = self._start_bin_frames
        b = torch.multinomial(self._start_p[clip], 1, generator=self._gen).squeeze(1)
        lo = b * f
        n = torch.minimum(lo + f, last + 1) - lo
        u = torch.rand(clip.numel(), generator=self._gen, device=self.device,
                       dtype=torch.float64)  # fmt: skip
        return lo + (u * n).long().minimum(n - 1)

    # ------------------------------------------------------------------ stepping
    def step(self, actions: torch.Tensor):
        """One decision of every world: ``actions (N, 69)`` held for up to ``action_repeat``
        frames (fewer where an episode ends).

        Returns:
            ``obs`` (dict of ``(N, ...)`` float32 tensors), ``reward (N,)`` (mean over the
            frames played), ``terminated (N,)``, ``truncated (N,)`` (bool) and an info dict of
            ``(N, ...)`` tensors: ``reward/<term>`` (means), ``max_joint_err_m``, ``mpjpe_m``,
            ``sim_unstable``, ``root_height_m``, ``frame``, ``clip_index``, ``frames`` and
            ``amp_obs (N, amp_window * FRAME_DIM)``.
        """
        n, dev = self.num_envs, self.device
        a = torch.as_tensor(actions, dtype=torch.float32, device=dev).reshape(n, -1)
        if a.shape[1] != A.N_HINGES or not torch.isfinite(a).all():
            raise ValueError(f"actions must be ({n}, {A.N_HINGES}) finite values, got shape "
                             f"{tuple(actions.shape)}")  # fmt: skip
        a = a.clamp(-1.0, 1.0)
        f32 = dict(dtype=torch.float32, device=dev)
        active = torch.ones(n, dtype=torch.bool, device=dev)
        frames = torch.zeros(n, dtype=torch.int64, device=dev)
        sums = torch.zeros(n, _N_TERMS, **f32)
        total = torch.zeros(n, **f32)
        term = torch.zeros(n, dtype=torch.bool, device=dev)
        trunc, unstable = torch.zeros_like(term), torch.zeros_like(term)
        err, mpjpe, height = torch.zeros(n, **f32), torch.zeros(n, **f32), torch.zeros(n, **f32)
        for _ in range(self.k):
            frames += active
            self._frame(active, a, sums, total, term, trunc, unstable, err, mpjpe, height)
            active &= ~(term | trunc)
            if self.k > 1 and not bool(active.any()):
                break
        trunc &= ~term
        obs = self._observe()
        fr = frames.clamp(min=1).to(torch.float32)
        info = {f"reward/{k}": sums[:, i] / fr for i, k in enumerate(R.TERMS)}
        info.update(max_joint_err_m=err, mpjpe_m=mpjpe, sim_unstable=unstable,
                    root_height_m=height, frame=self.frame.clone(),
                    clip_index=self.clip_index.clone(), frames=frames,
                    amp_obs=self._amp.reshape(n, -1).clone())  # fmt: skip
        return obs, total / fr, term, trunc, info

    def _frame(self, active, a, sums, total, term, trunc, unstable, err, mpjpe, height) -> None:
        """Advance every world one frame; accumulate the rewards and info values of the
        ``active`` ones (those whose episode has not ended in this decision)."""
        cfg, c = self.cfg, self.clips
        tn = self.frame + 1
        # (worlds whose episode has ended may be at the clip's last frame: their rows are read
        # clamped and their results dropped)
        tn_c = torch.minimum(tn, c.n_frames[self.clip_index] - 1)
        row = c.offset[self.clip_index] + tn_c
        if self._relative:
            tgt = c.target[row] + a * self._gain
        else:
            tgt = self._lo + (a + 1.0) * self._half
        self._ctrl[:, self._act] = torch.minimum(torch.maximum(tgt, self._lo), self._hi)
        for _ in range(cfg.substeps):
            # (step2 then step1, as grip.sim.humanoid.Humanoid.step: the derived quantities of
            # the new state are ready when the step returns)
            self._physics(mjw.step2)
            self._physics(mjw.step1)
        self.frame = torch.where(active, tn, self.frame)
        self._steps += active
        blown = self._blown() & active
        if bool(blown.any()):
            self.blowups += int(blown.sum())
            term |= blown
            unstable |= blown
            err[blown] = mpjpe[blown] = float("inf")
            height[blown] = 0.0
        ok = active & ~blown
        pvw, rot = self.body_state()
        pos = pvw[:, 0]
        # pelvis xy window (a ring, newest at _hist_pos - 1)
        hn = self._hist_n
        p = self._hist_pos
        ar = torch.arange(self.num_envs, device=self.device)
        h_len = torch.minimum(self._hist_len + 1, torch.full_like(p, hn))
        ring = self._hist.clone()
        ring[ar, p] = pos[:, 0, :2]
        oldest = ring[ar, (p + 1 - h_len) % hn]
        back = c.offset[self.clip_index] + tn_c - (h_len - 1)
        ref_disp = c.gt_pvw[row, 0, 0, :2] - c.gt_pvw[back, 0, 0, :2]
        # the pelvis the policy follows: the integrated root from where the episode started
        gap = c.obs_rows[row][:, _ROOT][:, :2] + self._root_offset[:, :2] - pos[:, 0, :2]
        terms6, sq = T.tracking_terms(pvw, rot, c.gt_pvw[row], c.gt_rot[row], cfg.reward,
                                      cfg.align_root_xy, pos[:, 0, :2] - oldest, ref_disp,
                                      self._vel_s, gap)  # fmt: skip
        tau = self._act_force[:, self._act]
        qd = self._qvel[:, self._hinge_qd]
        energy = torch.where(self._steps > cfg.reward.energy_skip_frames,
                             (tau * qd).abs().sum(dim=1), torch.zeros_like(tau[:, 0]))  # fmt: skip
        terms = torch.cat([terms6, energy[:, None], torch.zeros_like(energy[:, None])], dim=1)
        reward = terms @ self._w
        dist = torch.sqrt(sq[:, 0])
        e_max = dist.amax(dim=1)
        z = pos[:, 0, 2]
        tau_d = self.termination_dist_m
        # (GripTrackingEnv's rule: a low pelvis is a fall only when it is also
        # fall_below_reference_m below the ground truth's, so clips on the floor are followed)
        fell = (z < cfg.fall_height_m) & (z < c.gt_pvw[row, 0, 0, 2] - cfg.fall_below_reference_m)
        te = ((tau_d > 0) & (e_max > tau_d)) | fell
        if cfg.termination_root_gap_m > 0:
            te |= (gap * gap).sum(dim=1) > cfg.termination_root_gap_m**2
        tr = tn >= c.n_frames[self.clip_index] - 1
        if cfg.max_episode_frames > 0:
            tr |= self._steps >= cfg.max_episode_frames
        okf = ok[:, None]
        self._hist = torch.where(okf[:, :, None], ring, self._hist)
        self._hist_pos = torch.where(ok, (p + 1) % hn, p)
        self._hist_len = torch.where(ok, h_len, self._hist_len)
        term |= ok & te
        trunc |= ok & tr
        sums += torch.where(okf, terms, torch.zeros_like(terms))
        total += torch.where(ok, reward, torch.zeros_like(reward))
        err.copy_(torch.where(ok, e_max, err))
        mpjpe.copy_(torch.where(ok, dist.sum(dim=1) / dist.shape[1], mpjpe))
        height.copy_(torch.where(ok, z, height))
        # AMP window and the last stable state
        h = T.heading_matrices(rot[:, 0])
        hinges = torch.cat([self._qpos[:, self._hinge_q], self._qvel[:, self._hinge_qd]], dim=1)
        frame = T.amp_frames(pvw, rot, hinges, h)
        shifted = torch.cat([self._amp[:, 1:], frame[:, None]], dim=1)
        self._amp = torch.where(okf[:, :, None], shifted, self._amp)
        self._good_pvw = torch.where(ok[:, None, None, None], pvw, self._good_pvw)
        self._good_rot = torch.where(ok[:, None, None, None], rot, self._good_rot)
        self._good_t = torch.where(ok, tn, self._good_t)

    def _observe(self) -> dict[str, torch.Tensor]:
        """Observations of every world's last stable state against the estimate of the frame
        after it (:meth:`envs.batched.BatchedTrackingEnv._observe`)."""
        c, cfg = self.clips, self.cfg
        pvw, rot = self._good_pvw, self._good_rot
        ci = self.clip_index
        row = c.offset[ci] + torch.minimum(self._good_t + 1, c.n_frames[ci] - 1)
        h = T.heading_matrices(rot[:, 0])
        est = c.obs_rows[row].clone()
        est[:, _ROOT] += self._root_offset
        kin, self_vec = T.observation_parts(cfg.kinematic_obs, h, pvw, rot, est)
        root = pvw[:, 0, 0]
        if self._hf is None:
            hm = (-root[:, 2:3]).expand(-1, self._grid.shape[0])
        else:
            hm = self._hf.around(root[:, :2], h, self._grid, self._field) - root[:, 2:3]
        return {"sensor": c.sensor[row], "kinematic": kin, "self": self_vec,
                "environment": hm.contiguous()}  # fmt: skip

    def observe(self) -> dict[str, torch.Tensor]:
        """The observations of the current states (after :meth:`reset`, before a step)."""
        return self._observe()

    def contact_depths(self) -> list[dict[tuple[int, int], float]]:
        """Per world, each contacting geom pair's smallest signed distance, m (host copies)."""
        d = self.data
        k = int(d.nacon.numpy()[0])
        geom, world = d.contact.geom.numpy()[:k], d.contact.worldid.numpy()[:k]
        dist = d.contact.dist.numpy()[:k]
        out: list[dict[tuple[int, int], float]] = [{} for _ in range(self.num_envs)]
        for g, w, dd in zip(geom.tolist(), world.tolist(), dist.tolist(), strict=True):
            key = (min(g), max(g))
            out[w][key] = min(out[w].get(key, np.inf), dd)
        return out

    def overflowed(self) -> bool:
        """Whether a world ran out of allocated contacts or constraint rows (then contacts are
        lost: raise ``nconmax`` / ``njmax``)."""
        d = self.data
        return int(d.nacon.numpy()[0]) > d.naconmax or int(d.nefc.numpy().max()) > d.njmax

    def close(self) -> None:
        """Release nothing (warp frees its arrays with the env); kept for the env API."""
