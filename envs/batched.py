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

from envs import amp as A
from envs import observations as O
from envs import rewards as R
from envs.tracking_env import GripTrackingEnv
from grip.core import skeleton as sk

_C1, _C2 = np.array([1, 2, 0]), np.array([2, 0, 1])  # index permutations of a cross product
_KEY = np.array(A.KEY_JOINTS)
_N_TERMS = len(R.TERMS)
_INFO_KEYS = tuple(f"reward/{k}" for k in R.TERMS)


def _step_all(sims: Sequence) -> None:
    for s in sims:
        s.step()


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
        self._hist = np.zeros((n, self._hist_n, 2))  # ring of pelvis xy, newest at _hist_pos - 1
        self._hist_pos = np.zeros(n, dtype=np.int64)
        self._hist_len = np.zeros(n, dtype=np.int64)
        self._amp = np.zeros((n, cfg.amp_window, A.FRAME_DIM))
        # the last state that did not blow up (what the observation is built from)
        self._good_pvw = np.zeros((n, 3, nj, 3))
        self._good_rot = np.zeros((n, nj, 3, 3))
        self._good_t = np.zeros(n, dtype=np.int64)
        # step buffers
        self._tgt = np.zeros((n, nh))
        self._xpos, self._cvel = np.zeros((n, nj, 3)), np.zeros((n, nj, 6))
        self._xmat, self._com = np.zeros((n, nj, 9)), np.zeros((n, 3))
        self._hq, self._hqd, self._tau = np.zeros((n, nh)), np.zeros((n, nh)), np.zeros((n, nh))
        self._gt, self._gt_rot = np.zeros((n, 3, nj, 3)), np.zeros((n, nj, 3, 3))
        self._ref_disp = np.zeros((n, 2))
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
        self._root_offset[i] = e._root_offset
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
        sums_l, t_l = sums.tolist(), self._t.tolist()
        for i, e in enumerate(self.envs):
            info = dict(zip(_INFO_KEYS, sums_l[i], strict=True))
            info.update(clip=e.clip.name, clip_index=e._clip_i, frame=t_l[i],
                        max_joint_err_m=float(err[i]), mpjpe_m=float(mpjpe[i]),
                        sim_unstable=bool(unstable[i]), blowups=e.blowups,
                        root_height_m=float(height[i]), amp_obs=amp[i])  # fmt: skip
            if self.k > 1:
                info["frames"] = int(frames[i])
            infos.append(info)
        return obs, reward, term, trunc, infos

    def _frame(self, idx, a, sums, total, term, trunc, unstable, err, mpjpe, height) -> None:
        """Advance environments ``idx`` one frame; accumulate their rewards and info values."""
        cfg, sims, envs, t = self.cfg, self._sims, self.envs, self._t
        tn = t[idx] + 1
        if self._relative:
            tgt = self._tgt[: idx.size]
            for j, (i, ti) in enumerate(zip(idx.tolist(), tn.tolist(), strict=True)):
                tgt[j] = envs[i]._est.target[ti]
            tgt = tgt + a[idx] * self._gain[idx]
        else:
            tgt = self._lo[idx] + (a[idx] + 1.0) * self._half[idx]
        tgt = np.minimum(np.maximum(tgt, self._lo[idx]), self._hi[idx])
        active = [sims[i] for i in idx.tolist()]
        for j, s in enumerate(active):
            s.ctrl[s.act] = tgt[j]
        if self._pool is None or len(active) == 1:
            _step_all(active)
        else:
            m = self.threads
            list(self._pool.map(_step_all, [active[c::m] for c in range(m)]))
        t[idx] = tn
        self._steps[idx] += 1
        blown = np.array([s.blown_up() for s in active])
        if blown.any():
            bad = idx[blown]
            for i in bad.tolist():
                envs[i].blowups += 1
            term[bad] = unstable[bad] = True
            err[bad] = mpjpe[bad] = np.inf
            height[bad] = 0.0
            active = [s for s, b in zip(active, blown.tolist(), strict=True) if not b]
            idx, tn = idx[~blown], tn[~blown]
            if idx.size == 0:
                return
        self._advance(idx, tn, active, sums, total, term, trunc, err, mpjpe, height, cfg)

    def _advance(self, idx, tn, active, sums, total, term, trunc, err, mpjpe, height, cfg):
        """Rewards, termination and AMP frames of the stable environments ``idx``."""
        m = idx.size
        xpos, cvel, xmat, com = self._xpos[:m], self._cvel[:m], self._xmat[:m], self._com[:m]
        hq, hqd, tau, gt, gt_rot = self._hq[:m], self._hqd[:m], self._tau[:m], self._gt[:m], \
            self._gt_rot[:m]  # fmt: skip
        pos_n = self._hist_len[idx]
        hn = self._hist_n
        h_len = np.minimum(pos_n + 1, hn)
        back = (tn - (h_len - 1)).tolist()
        for j, (i, s, ti) in enumerate(zip(idx.tolist(), active, tn.tolist(), strict=True)):
            ids = s.index.body_ids
            xpos[j] = s.xpos[ids]
            cvel[j] = s.cvel[ids]
            xmat[j] = s.xmat[ids]
            com[j] = s.com
            hq[j] = s.hinge_angles()
            hqd[j] = s.hinge_velocities()
            tau[j] = s.torques()
            e = self.envs[i]
            gp = e._gt_pvw
            gt[j] = gp[ti]
            gt_rot[j] = e.clip.gt_rot[ti]
            self._ref_disp[j] = gp[ti, 0, 0, :2] - gp[back[j], 0, 0, :2]
        # Humanoid.state() for all of them
        pvw = np.empty((m, 3, sk.N_JOINTS, 3))
        pos = pvw[:, 0]
        pos[:] = xpos
        w = cvel[:, :, :3]
        pvw[:, 2] = w
        r = pos - com[:, None]
        pvw[:, 1] = cvel[:, :, 3:] + (w[..., _C1] * r[..., _C2] - w[..., _C2] * r[..., _C1])
        rot = xmat.reshape(m, -1, 3, 3)
        # pelvis xy window
        ring = self._hist
        p = self._hist_pos[idx]
        ring[idx, p] = pos[:, 0, :2]
        self._hist_pos[idx] = (p + 1) % hn
        self._hist_len[idx] = h_len
        oldest = ring[idx, (p + 1 - h_len) % hn]
        root_vel = R.root_velocity_terms(pos[:, 0, :2] - oldest, self._ref_disp[:m], self._vel_s,
                                         cfg.reward.k_root_vel)  # fmt: skip
        if cfg.align_root_xy:  # (the same shift and shift back as the env's, bit for bit)
            shift = gt[:, 0, 0, :2] - pos[:, 0, :2]
            pos[:, :, :2] += shift[:, None]
            imit, sq = R.imitation_terms_batch(pvw, rot, gt, gt_rot, cfg.reward)
            pos[:, :, :2] -= shift[:, None]
        else:
            imit, sq = R.imitation_terms_batch(pvw, rot, gt, gt_rot, cfg.reward)
        terms = np.zeros((m, _N_TERMS))
        terms[:, :4] = imit
        terms[:, 4] = root_vel
        power = np.abs(tau * hqd).sum(axis=1)
        terms[:, 5] = np.where(self._steps[idx] > cfg.reward.energy_skip_frames, power, 0.0)
        reward = np.zeros(m)
        for c, wc in enumerate(self._w.tolist()):
            reward += wc * terms[:, c]
        dist = np.sqrt(sq[:, 0])
        e_max = dist.max(axis=1)
        tau_d = np.array([self.envs[i].termination_dist_m for i in idx.tolist()])
        z = pos[:, 0, 2]
        te = ((tau_d > 0) & (e_max > tau_d)) | (z < cfg.fall_height_m)
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
        frame = A.amp_features(pos[:, 0], rot[:, 0], pvw[:, 1, 0], pvw[:, 2, 0], hq, hqd,
                               pos[:, _KEY])  # fmt: skip
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
        nj = sk.N_JOINTS
        est_pos, leaf_rot = np.empty((n, nj, 3)), np.empty((n, O._N_IMU, 3, 3))
        est_vel, leaf_w = np.empty((n, len(O._VEL), 3)), np.empty((n, O._N_IMU, 3))
        root = np.empty((n, 3))
        sensor = np.empty((n, self.observation_space["sensor"].shape[0]), np.float32)
        for i, e in enumerate(self.envs):
            f, ti = e._est, t[i]
            est = f.est
            est_pos[i] = est.est_pos[ti]
            leaf_rot[i] = f.leaf_rot[ti]
            est_vel[i] = est.est_vel[ti]
            leaf_w[i] = f.leaf_angvel[ti]
            root[i] = est.est_root_pos[ti]
            sensor[i] = est.sensor[ti]
        root += self._root_offset
        h = O.heading_matrices(rot[:, 0])
        kin, self_vec = O.observation_parts_batch(cfg.kinematic_obs, h, pvw, rot, est_pos,
                                                  leaf_rot, est_vel, leaf_w, root)  # fmt: skip
        z = pvw[:, 0, 0, 2]
        hm = np.repeat((-z)[:, None], self.observation_space["environment"].shape[0], axis=1)
        for i, e in enumerate(self.envs):
            terrain = self._sims[i].terrain
            if terrain is not None:
                rp = pvw[i, 0, 0]
                hm[i] = terrain(rp[:2], h[i, :2, :2], e._grid, self._hm) - rp[2]
        return {
            "sensor": sensor,
            "kinematic": kin.astype(np.float32),
            "self": self_vec.astype(np.float32),
            "environment": hm.astype(np.float32),
        }

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None
        for e in self.envs:
            e.close()
