"""``BatchedTrackingEnv``: N tracking environments stepped by one call (training throughput).

The N :class:`~envs.tracking_env.GripTrackingEnv` keep what an episode start needs (clip
sampling, scenes, subjects, per-clip arrays: ``reset`` is theirs); a step of all N runs here:
the PD targets, rewards, termination, AMP frames and observations of all environments are
computed at once with numpy on ``(N, ...)`` arrays, and the N MuJoCo models are stepped in a
thread pool (MuJoCo's bindings release the GIL, so the physics of several environments runs on
several cores while Python waits). An action is held for ``cfg.action_repeat`` frames, as
:class:`envs.wrappers.ActionRepeat` holds it, and observations are built once per decision
(the frames in between only need rewards and AMP frames).

The transitions are those of N ``GripTrackingEnv`` (wrapped in ``ActionRepeat`` when
``action_repeat > 1``) with the same seeds and actions: the physics bit for bit, observations,
rewards and AMP windows to float rounding (batched 3 x 3 products may sum in another order),
resets and early termination included (``tests/envs/test_batched.py``).

The API is Gymnasium-like, per batch: :meth:`step` takes ``(N, 69)`` actions and returns
``(N, ...)`` arrays and N info dicts, without resetting finished environments;
:meth:`reset` starts one environment's episode. ``policies.vec_env.BatchedVecEnv`` makes it an
SB3 ``VecEnv`` (auto-reset, ``terminal_observation``).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from envs import rewards as R
from envs.tracking_env import GripTrackingEnv
from grip.core import skeleton as sk
from grip.sim.humanoid import ROW, ROW_DIM, absurd_rows, body_state
from grip.task import amp as A
from grip.task import observations as O

_N_TERMS = len(R.TERMS)
_INFO_KEYS = tuple(f"reward/{k}" for k in R.TERMS)
_KEYS = (*_INFO_KEYS, "clip", "clip_index", "frame", "max_joint_err_m", "mpjpe_m", "sim_unstable",
         "blowups", "root_height_m", "amp_obs")  # fmt: skip
_HINGES = slice(ROW["hinge_q"].start, ROW["hinge_qd"].stop)
_TORQUE, _HQD = ROW["torque"], ROW["hinge_qd"]
_ROOT = O.OBS_ROW["est_root_pos"]
_ROOT_XY = slice(_ROOT.start, _ROOT.start + 2)
_TRACK = R.TRACKING_TERMS  # (the energy term follows the tracking terms)


def _play(sims: Sequence, targets: np.ndarray, rows: np.ndarray, warned: np.ndarray) -> None:
    """Step humanoids ``sims`` toward ``targets (n, 69)``; gather each state into ``rows (n,
    ROW_DIM)`` and note MuJoCo's blow-up warnings in ``warned (n,)`` (one thread's share)."""
    for j, s in enumerate(sims):
        s.ctrl[s.act] = targets[j]
        s.step()
        warned[j] = s.warned()
        s.gather(rows[j])


class BatchedTrackingEnv:
    """N tracking environments of one config, stepped together.

    Args:
        envs: The environments (same ``cfg``; each reset once, e.g. with its seed). They are
            reset through :meth:`reset` only: their own ``step`` must not be called meanwhile.
        threads: Threads stepping the physics (0: the cores this process may use).

    Attributes:
        num_envs: N.
        observation_space, action_space: Those of one environment.
    """

    def __init__(self, envs: Sequence[GripTrackingEnv], threads: int = 0) -> None:
        if not envs:
            raise ValueError("BatchedTrackingEnv needs at least one environment")
        cfg = envs[0].cfg
        for e in envs:
            if not isinstance(e, GripTrackingEnv):
                raise TypeError(f"BatchedTrackingEnv steps GripTrackingEnv, got {type(e)}")
            if e.cfg != cfg:
                raise ValueError("BatchedTrackingEnv: all environments need the same config")
        if cfg.pin_root:
            raise ValueError("BatchedTrackingEnv: pin_root is a physics check, not batched")
        if cfg.amp_window < 1:
            raise ValueError("BatchedTrackingEnv needs amp_window >= 1 (the AMP reward)")
        self.envs = list(envs)
        self.cfg = cfg
        self.num_envs = n = len(envs)
        self.k = cfg.action_repeat
        self.observation_space = envs[0].observation_space
        self.action_space = envs[0].action_space
        if threads <= 0:
            threads = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1
        self.threads = max(1, min(int(threads), n))
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None
        nj, nh = sk.N_JOINTS, A.N_HINGES
        self._relative = cfg.action_mode == "relative"
        self._w = np.array([float(getattr(cfg.reward.weights, k)) for k in R.TERMS])
        self._hist_n = cfg.reward.root_vel_window_frames + 1
        self._vel_s = cfg.reward.root_vel_window_frames * cfg.control_dt_s
        # per-environment episode state
        self._sims = [e.humanoid for e in envs]
        self._t = np.zeros(n, dtype=np.int64)
        self._steps = np.zeros(n, dtype=np.int64)
        self._n_frames = np.zeros(n, dtype=np.int64)
        self._gain = np.zeros((n, nh))
        self._lo, self._hi = np.zeros((n, nh)), np.zeros((n, nh))
        self._half = np.zeros((n, nh))
        self._root_offset = np.zeros((n, 3))
        self._root_offset_truth = np.zeros((n, 3))  # (cfg.teacher_obs)
        self._root_speed = np.ones(n)  # each episode's root-speed factor (cfg.root_speed_range)
        self._speed_on = tuple(cfg.root_speed_range) != (1.0, 1.0)
        self._lean_deg = np.zeros(n)  # each episode's lean of the followed trunk, deg
        self._lean_on = tuple(cfg.lean_range_deg) != (0.0, 0.0)
        self._hist = np.zeros((n, self._hist_n, 2))  # ring of pelvis xy, newest at _hist_pos - 1
        self._hist_pos = np.zeros(n, dtype=np.int64)
        self._hist_len = np.zeros(n, dtype=np.int64)
        self._amp = np.zeros((n, cfg.amp_window, A.FRAME_DIM))
        # the last state that did not blow up (what the observation is built from)
        self._good_pvw = np.zeros((n, 3, nj, 3))
        self._good_rot = np.zeros((n, nj, 3, 3))
        self._good_t = np.zeros(n, dtype=np.int64)
        self._z_range = np.zeros((n, 2))
        self._hcfg = self._sims[0].cfg
        # step buffers
        self._tgt = np.zeros((n, nh))
        self._rows = np.zeros((n, ROW_DIM))
        self._warned = np.zeros(n, dtype=bool)
        self._gt = np.zeros((n, envs[0]._gt_rows.shape[1]))
        self._ref_disp = np.zeros((n, 2))
        self._gap = np.zeros((n, 2))
        self._est_rows = np.zeros((n, O.OBS_ROW_DIM))
        self._hm = np.zeros(len(envs[0]._grid))
        for i in range(n):
            self._sync(i)

    # ------------------------------------------------------------------ episodes
    def _sync(self, i: int) -> None:
        """Take over environment ``i``'s episode state after its reset."""
        e = self.envs[i]
        sim = self._sims[i] = e.humanoid
        self._t[i] = self._good_t[i] = e._t
        self._steps[i] = 0
        self._n_frames[i] = e.clip.n_frames
        self._gain[i] = e._action_gain
        self._lo[i], self._hi[i], self._half[i] = sim.lo, sim.hi, sim.half
        self._z_range[i] = sim.z_range
        self._root_offset[i] = e._root_offset
        self._root_offset_truth[i] = e._root_offset_truth
        self._root_speed[i] = e._root_speed
        self._lean_deg[i] = e._lean_deg
        self._hist_len[i] = len(e._root_hist)
        self._hist[i, : self._hist_len[i]] = np.asarray(e._root_hist)
        self._hist_pos[i] = self._hist_len[i] % self._hist_n
        self._amp[i] = e._amp._buf
        self._good_pvw[i], self._good_rot[i] = sim.state()

    def reset(self, i: int, seed: int | None = None,
              options: dict | None = None) -> tuple[dict[str, np.ndarray], dict]:  # fmt: skip
        """Start environment ``i``'s next episode (:meth:`GripTrackingEnv.reset`)."""
        obs, info = self.envs[i].reset(seed=seed, options=options)
        self._sync(i)
        return obs, info

    # ------------------------------------------------------------------ stepping
    def step(self, actions: np.ndarray):
        """One decision of every environment: ``actions (N, 69)`` held for up to
        ``action_repeat`` frames (fewer where an episode ends).

        Returns:
            ``obs`` (dict of ``(N, ...)`` float32 arrays), ``reward (N,)`` (mean over the frames
            played), ``terminated (N,)``, ``truncated (N,)`` (bool) and N info dicts, as
            ``ActionRepeat(GripTrackingEnv)`` gives them. Finished environments are not reset.
        """
        n = self.num_envs
        a = np.asarray(actions, dtype=np.float64).reshape(n, -1)
        if a.shape[1] != self._gain.shape[1] or not np.isfinite(a).all():
            raise ValueError(f"actions must be ({n}, {self._gain.shape[1]}) finite values, got "
                             f"shape {np.shape(actions)}")  # fmt: skip
        a = np.minimum(np.maximum(a, -1.0), 1.0)
        active = np.ones(n, dtype=bool)
        frames = np.zeros(n, dtype=np.int64)
        sums = np.zeros((n, _N_TERMS))
        total = np.zeros(n)
        term, trunc, unstable = np.zeros(n, bool), np.zeros(n, bool), np.zeros(n, bool)
        err, mpjpe, height = np.zeros(n), np.zeros(n), np.zeros(n)
        for _ in range(self.k):
            idx = np.flatnonzero(active)
            if idx.size == 0:
                break
            frames[idx] += 1
            self._frame(idx, a, sums, total, term, trunc, unstable, err, mpjpe, height)
            active &= ~(term | trunc)
        trunc &= ~term
        obs = self._observe()
        amp = self._amp.reshape(n, -1).astype(np.float32)
        sums /= frames[:, None]
        reward = total / frames
        infos = []
        cols = zip(*sums.T.tolist(), self._t.tolist(), err.tolist(), mpjpe.tolist(),
                   unstable.tolist(), height.tolist(), amp, frames.tolist(),
                   strict=True)  # fmt: skip
        for e, (*terms, t, er, mp, un, z, am, fr) in zip(self.envs, cols, strict=True):
            info = dict(zip(_KEYS, (*terms, e._clip.name, e._clip_i, t, er, mp, un, e.blowups, z,
                                    am), strict=True))  # fmt: skip
            if self.k > 1:
                info["frames"] = fr
            infos.append(info)
        return obs, reward, term, trunc, infos

    def _frame(self, idx, a, sums, total, term, trunc, unstable, err, mpjpe, height) -> None:
        """Advance environments ``idx`` one frame; accumulate their rewards and info values."""
        cfg, sims, envs, t = self.cfg, self._sims, self.envs, self._t
        m = idx.size
        tn = t[idx] + 1
        tn_l = tn.tolist()
        idx_l = idx.tolist()
        tgt = self._tgt[:m]
        if self._relative:
            for j, (i, ti) in enumerate(zip(idx_l, tn_l, strict=True)):
                tgt[j] = envs[i]._est.target[ti]
            if self._lean_on:
                tgt += O.lean_hinges(*self._leans([envs[i]._est for i in idx_l], idx, tn_l))
            tgt += a[idx] * self._gain[idx]
        else:
            tgt[:] = self._lo[idx] + (a[idx] + 1.0) * self._half[idx]
        np.maximum(tgt, self._lo[idx], out=tgt)
        np.minimum(tgt, self._hi[idx], out=tgt)
        active = [sims[i] for i in idx_l]
        rows, warned = self._rows[:m], self._warned[:m]
        if self._pool is None or m == 1:
            _play(active, tgt, rows, warned)
        else:  # one task per thread, each a contiguous share of the environments
            c = -(-m // min(self.threads, m))
            shares = [slice(j, j + c) for j in range(0, m, c)]
            list(self._pool.map(_play, [active[sl] for sl in shares], [tgt[sl] for sl in shares],
                                [rows[sl] for sl in shares], [warned[sl] for sl in shares]))
        t[idx] = tn
        self._steps[idx] += 1
        blown = warned | absurd_rows(rows, self._hcfg, self._z_range[idx])
        if blown.any():
            bad = idx[blown]
            for i in bad.tolist():
                envs[i].blowups += 1
            term[bad] = unstable[bad] = True
            err[bad] = mpjpe[bad] = np.inf
            height[bad] = 0.0
            keep = ~blown
            idx, tn = idx[keep], tn[keep]
            if idx.size == 0:
                return
            rows = rows[keep]
            tn_l = tn.tolist()
        self._advance(idx, tn, tn_l, rows, sums, total, term, trunc, err, mpjpe, height, cfg)

    def _advance(self, idx, tn, tn_l, rows, sums, total, term, trunc, err, mpjpe, height, cfg):
        """Rewards, termination and AMP frames of the stable environments ``idx`` (their
        gathered states ``rows``)."""
        m = idx.size
        gt = self._gt[:m]
        pos_n = self._hist_len[idx]
        hn = self._hist_n
        h_len = np.minimum(pos_n + 1, hn)
        back = (tn - (h_len - 1)).tolist()
        ref_disp = self._ref_disp[:m]
        gap = self._gap[:m]
        for j, (i, ti) in enumerate(zip(idx.tolist(), tn_l, strict=True)):
            e = self.envs[i]
            gp = e._gt_rows
            gt[j] = gp[ti]
            ref_disp[j] = gp[ti, :2] - gp[back[j], :2]
            gap[j] = e._est.obs_rows[ti, _ROOT_XY]
        if self._speed_on:
            f = self._root_speed[idx, None]
            ref_disp *= f
            gap *= f
        gap += self._root_offset[idx, :2]
        pvw, rot = body_state(rows)
        pos = pvw[:, 0]
        # pelvis xy window
        ring = self._hist
        p = self._hist_pos[idx]
        ring[idx, p] = pos[:, 0, :2]
        self._hist_pos[idx] = (p + 1) % hn
        self._hist_len[idx] = h_len
        oldest = ring[idx, (p + 1 - h_len) % hn]
        terms = np.zeros((m, _N_TERMS))
        gap -= pos[:, 0, :2]
        terms[:, :_TRACK], sq = R.tracking_terms_rows(rows, gt, cfg.reward, cfg.align_root_xy,
                                                      pos[:, 0, :2] - oldest, ref_disp,
                                                      self._vel_s, gap)  # fmt: skip
        power = rows[:, _TORQUE] * rows[:, _HQD]
        terms[:, _TRACK] = np.where(self._steps[idx] > cfg.reward.energy_skip_frames,
                               np.abs(power, out=power).sum(axis=1), 0.0)  # fmt: skip
        reward = np.zeros(m)
        for c, wc in enumerate(self._w.tolist()):
            reward += wc * terms[:, c]
        dist = np.sqrt(sq[:, 0])
        e_max = dist.max(axis=1)
        tau_d = np.array([self.envs[i].termination_dist_m for i in idx.tolist()])
        z = pos[:, 0, 2]
        fell = (z < cfg.fall_height_m) & (z < gt[:, 2] - cfg.fall_below_reference_m)
        te = ((tau_d > 0) & (e_max > tau_d)) | fell
        if cfg.termination_root_gap_m > 0:
            te |= (gap * gap).sum(axis=1) > cfg.termination_root_gap_m**2
        tr = tn >= self._n_frames[idx] - 1
        if cfg.max_episode_frames > 0:
            tr |= self._steps[idx] >= cfg.max_episode_frames
        term[idx], trunc[idx] = te, tr
        sums[idx] += terms
        total[idx] += reward
        err[idx] = e_max
        mpjpe[idx] = dist.sum(axis=1) / dist.shape[1]
        height[idx] = z
        # AMP window
        h = O.heading_matrices(rot[:, 0])
        frame = A.amp_frames(pvw, rot, rows[:, _HINGES], h, np.empty((m, A.FRAME_DIM)))
        buf = self._amp
        buf[idx, :-1] = buf[idx, 1:]
        buf[idx, -1] = frame
        self._good_pvw[idx], self._good_rot[idx], self._good_t[idx] = pvw, rot, tn

    def _observe(self) -> dict[str, np.ndarray]:
        """Observations of every environment's last stable state against the estimate of the
        frame after it (:meth:`GripTrackingEnv._observe`)."""
        n, cfg = self.num_envs, self.cfg
        pvw, rot = self._good_pvw, self._good_rot
        t = np.minimum(self._good_t + 1, self._n_frames - 1).tolist()
        sensor = np.empty((n, self.observation_space["sensor"].shape[0]), np.float32)
        for i, e in enumerate(self.envs):
            sensor[i] = e._est.est.sensor[t[i]]
        h = O.heading_matrices(rot[:, 0])
        kin, self_vec = self._kinematic([e._est for e in self.envs], self._root_offset, t, h,
                                        lean=self._lean_on)  # fmt: skip
        z = pvw[:, 0, 0, 2]
        hm = np.repeat((-z)[:, None], self.observation_space["environment"].shape[0], axis=1)
        for i, e in enumerate(self.envs):
            terrain = self._sims[i].terrain
            if terrain is not None:
                rp = pvw[i, 0, 0]
                hm[i] = terrain(rp[:2], h[i, :2, :2], e._grid, self._hm) - rp[2]
        obs = {
            "sensor": sensor,
            "kinematic": kin,
            "self": self_vec,
            "environment": hm.astype(np.float32),
        }
        if cfg.sensor_context:  # (TrackingEnvConfig.sensor_context: a gate's context)
            obs["sensor_context"] = np.stack([
                O.sensor_context_at(e._est.est.sensor, t[i], cfg.sensor_context)
                for i, e in enumerate(self.envs)])  # fmt: skip
        if cfg.teacher_obs:  # a privileged teacher's inputs (TrackingEnvConfig.teacher_obs)
            truth = [e._truth for e in self.envs]
            est_root = cfg.teacher_root == "estimate"  # (TrackingEnvConfig.teacher_root)
            obs["teacher_kinematic"] = self._kinematic(
                truth, self._root_offset if est_root else self._root_offset_truth, t, h,
                [e._est for e in self.envs] if est_root else None)[0]  # fmt: skip
            shift = np.zeros((n, self._gain.shape[1]), np.float32)
            if self._relative:
                for i, (e, f) in enumerate(zip(self.envs, truth, strict=True)):
                    shift[i] = (f.target[t[i]] - e._est.target[t[i]]) / self._gain[i]
            obs["teacher_shift"] = shift
        return obs

    def _kinematic(self, frames: list, offset: np.ndarray, t: list[int], h: np.ndarray,
                   root_frames: list | None = None,
                   lean: bool = False) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
        """The kinematic and self observations of the last stable states against reference
        frames ``t`` of ``frames`` (one :class:`grip.task.observations.EstimateFrames` per
        environment; the root integrated from ``offset (N, 3)``, that of ``root_frames``
        when given; their upper bodies leaned by the episodes' leans where ``lean``)."""
        er = self._est_rows
        for i, f in enumerate(frames):
            er[i] = f.obs_rows[t[i]]
            if root_frames is not None:
                er[i, _ROOT] = root_frames[i].obs_rows[t[i], _ROOT]
        if lean:
            O.lean_rows(er, self._leans(frames, np.arange(self.num_envs), t)[1])
        if self._speed_on:
            O.scale_root_speed(er, self._root_speed)
        er[:, _ROOT] += offset
        n, space = self.num_envs, self.observation_space
        kin = np.empty((n, space["kinematic"].shape[0]), np.float32)
        self_vec = np.empty((n, space["self"].shape[0]), np.float32)
        O.observation_rows(self.cfg.kinematic_obs, h, self._good_pvw, self._good_rot, er, kin,
                           self_vec)  # fmt: skip
        return kin, self_vec

    def _leans(self, frames: list, idx: np.ndarray,
               t: list[int]) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
        """The global rotations ``(M, 24, 3, 3)`` of frames ``t`` of the estimates ``frames``
        (of environments ``idx``) and their episodes' leans ``(M, 3, 3)``
        (``cfg.lean_range_deg``)."""
        rot = np.stack([f.est.est_rot[ti] for f, ti in zip(frames, t, strict=True)])
        return rot, O.forward_lean(rot[:, 0], self._lean_deg[idx])

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None
        for e in self.envs:
            e.close()
