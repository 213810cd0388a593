"""DynamicsNet training on one torch device: :class:`policies.train.PolicyTrainer`'s run (stages,
termination curriculum, learning-rate decay, critic warm-up, checkpoints, resume, warm start,
export) with the rollout collected from a batched tensor env (MuJoCo Warp) and PPO + AMP updated
where the env's tensors live.

What is the CPU trainer's, unchanged: the run folder and its checkpoint files (``model.zip``
written by SB3's ``PPO.save``, ``vecnorm.npz``, ``amp.pt``, ``state.json``), so
:func:`policies.runner.export_policy` writes the same policy file; the policy network (SB3's
``MultiInputPolicy``) and SB3's ``PPO.train()`` update; :meth:`PolicyTrainer.warm_start` from a
policy file; the history rows and their keys.

What is the device's: the rollout buffer (:class:`policies.warp.rollout.DeviceRolloutBuffer`),
the observation and return normaliser (:class:`policies.warp.rollout.DeviceVecNormalize`, the
formulas of SB3's ``VecNormalize``), the AMP discriminator's replay buffer, real windows and
update (:class:`policies.warp.amp.DeviceAmpTrainer`) and the collect loop (auto-reset, the
time-limit bootstrap of SB3's ``collect_rollouts``, episode statistics, and each clip's ended
and failed episodes, copied to the host once per rollout).

The stage's curricula are the CPU trainer's (:class:`policies.curriculum.StageCurriculum`:
hard-clip mining, failure-weighted starts, per-category termination, the real windows'
clip probabilities), built and restored from the checkpoint by
:meth:`PolicyTrainer._begin_stage_clips` and saved by :meth:`PolicyTrainer.save_checkpoint`;
after each rollout they take the per-clip counts (and, for start bins and per-category
termination, each ended episode's clip, start and end frame, copied to the host with them),
decay, and go to the env (``set_clip_weights``, ``set_start_bin_weights``,
``set_clip_termination_dists``). History rows carry the CPU rows' ``"by_category"`` counts
(:func:`policies.train.episodes_by_category`). With ``env.reward.weights.amp = 0`` the
discriminator is neither run nor trained.

The ``amp.pt`` of a device run keeps a torch generator state, so a run folder is resumed by the
backend that started it (``config.json`` records ``"backend": "warp"``). Clips with their own
scene objects (props) run in the same batch as flat ones (:class:`envs.warp.env.WarpTrackingEnv`
selects each world's height field and overhang meshes), so the teacher's recipe
(``configs/policy/teacher.toml``) trains here as on the CPU.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.logger import configure

from grip.task import amp as A
from policies.config import PolicyRunConfig, StageConfig
from policies.train import (
    INFO_TERMS,
    ConstantLearningRate,
    PolicyTrainer,
    _upgrade_settings,
    episodes_by_category,
)
from policies.vec_env import load_vecnorm_state, vecnorm_state
from policies.warp.amp import DeviceAmpTrainer
from policies.warp.rollout import DeviceRolloutBuffer, DeviceVecNormalize

BACKEND = "warp"
"""What ``config.json`` records as ``"backend"`` for a run of this trainer."""


class TensorEnvMaker(Protocol):
    """The batched env constructor the device trainer receives from the edge
    (``envs.warp.factory.make_warp_tracking_env``).

    ``make_env(env_cfg, categories, num_envs, device, seed)`` returns an env of ``num_envs``
    episodes on ``device`` (a torch/warp device name) that tracks the clips of ``categories``
    (all when empty), with ``num_envs``, ``observe() -> dict of (N, ...) tensors``,
    ``step(actions (N, A)) -> (obs, reward, terminated, truncated, info)`` (tensors; ``info``
    holds ``reward/<term>``, ``mpjpe_m``, ``frames``, ``clip_index`` and ``amp_obs``),
    ``reset(mask)``, ``set_termination_dist(m)``, ``set_clip_weights(w (C,))`` (clips in the
    order of :func:`grip.core.reference_sets.select_clips`) and ``close()``
    (:class:`envs.warp.env.WarpTrackingEnv`).
    """

    def __call__(self, env_cfg: Any, categories: tuple[str, ...], num_envs: int, device: str,
                 seed: int) -> Any: ...  # fmt: skip


def resolve_device(name: str) -> torch.device:
    """``ppo.device`` as a torch device (``"auto"``: CUDA where there is one)."""
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    return torch.device(name)


class WarpPolicyTrainer(PolicyTrainer):
    """A resumable DynamicsNet training run whose rollouts, normaliser, PPO and AMP updates stay
    on ``cfg.ppo.device`` (``cfg.ppo.n_envs`` environments in one batched env).

    Args:
        cfg: Settings (``ppo.vec_env``, ``ppo.threads`` and ``ppo.env_threads`` are the CPU
            env's and are not used).
        run_dir, reference, progress, init, init_member: As :class:`PolicyTrainer`.
        make_env: The batched env constructor (:class:`TensorEnvMaker`).

    Raises:
        ValueError: As :class:`PolicyTrainer`; also naming ``backend`` when ``run_dir`` holds a
            checkpoint of the CPU trainer.
    """

    def __init__(self, cfg: PolicyRunConfig, run_dir: str | os.PathLike,
                 reference: str | os.PathLike, make_env: TensorEnvMaker,
                 progress: Callable | None = None, init: str | os.PathLike | None = None,
                 init_member: int = 0) -> None:  # fmt: skip
        super().__init__(cfg, run_dir, reference, make_env, progress, init, init_member)
        self.rundir.check_resume(cfg, defaults=PolicyRunConfig(), recorded={"backend": BACKEND},
                                 upgrade=_upgrade_settings)  # fmt: skip
        self.device = resolve_device(cfg.ppo.device)
        self.amp = DeviceAmpTrainer.from_cpu(self.amp, self.device, cfg.seed)
        self.env: Any = None
        self.venv: DeviceVecNormalize | None = None
        self.obs_space: spaces.Dict | None = None
        self.action_space = spaces.Box(-1.0, 1.0, (A.N_HINGES,), np.float32)
        self.stage_clip_categories: list[str] = []  # (C,) the category of each env clip

    # -------------------------------------------------------------- env and model
    def _build_env(self, stage: StageConfig) -> DeviceVecNormalize:
        """The stage's batched env (``self.env``) and a fresh normaliser for it."""
        p = self.cfg.ppo
        seed = self.cfg.seed + 7919 * self.stage_index + self.stage_done
        if self.env is not None:
            self.env.close()
            self.env = None  # (frees the previous stage's device arrays first)
        env_cfg = self.cfg.env_config(stage, self.reference)
        self.env = self.make_env(env_cfg, stage.categories, p.n_envs, str(self.device), seed)
        obs = self.env.observe()
        box = {k: spaces.Box(-np.inf, np.inf, tuple(v.shape[1:]), np.float32)
               for k, v in obs.items()}  # fmt: skip
        self.obs_space = spaces.Dict(box)
        shapes = {k: s.shape for k, s in self.obs_space.spaces.items()}
        return DeviceVecNormalize(shapes, self.env.num_envs, self.device, p.normalize_reward,
                                  p.clip_obs, p.gamma)  # fmt: skip

    def _new_model(self, venv: DeviceVecNormalize | None = None) -> PPO:
        """SB3's PPO (``MultiInputPolicy``) on the device, without a VecEnv: the spaces and the
        number of environments are set before its networks are built, as ``PPO.load`` does;
        its rollout buffer is a :class:`DeviceRolloutBuffer`."""
        p = self.cfg.ppo
        model = PPO("MultiInputPolicy", None, gamma=p.gamma, policy_kwargs=self._policy_kwargs(),
                    seed=self.cfg.seed, device=self.device, verbose=0,
                    rollout_buffer_class=DeviceRolloutBuffer, _init_setup_model=False,
                    **self._ppo_settings())  # fmt: skip
        model.observation_space, model.action_space = self.obs_space, self.action_space
        model.n_envs = self.env.num_envs
        model._setup_model()
        model.rollout_buffer.seed(self.cfg.seed)
        model.set_logger(configure(str(self.run_dir / "tb" / BACKEND), ["tensorboard"]))
        return model

    def prepare_stage(self, stage: StageConfig, state: dict | None = None) -> None:
        """Build the stage's env and normaliser, and the model: restored from ``checkpoint/``
        when ``state`` (a resumed run's) is given, warm-started from ``init`` on a first
        stage, else the previous stage's model with its normaliser statistics; then the
        stage's clip categories and hard-clip miner (:meth:`PolicyTrainer._begin_stage_clips`,
        the miner's counts restored from the checkpoint)."""
        old_norm = vecnorm_state(self.venv) if self.venv is not None else None
        self.venv = self._build_env(stage)
        if state is not None and (self.ckpt_dir / "model.zip").is_file():
            self._restore_model()
        elif self.model is None:
            self.model = self._new_model(self.venv)
            if self._init_runner is not None:
                self.warm_start(self._init_runner)
        else:
            load_vecnorm_state(self.venv, old_norm)
        self.model.rollout_buffer.reset()
        self.stage_clip_categories = self._begin_stage_clips(stage)

    @torch.no_grad()
    def act(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        """``(N, A)`` the policy's mean actions for raw observations (normalised with the
        current statistics, clipped to [-1, 1]): what an exported file's runner computes."""
        self.model.policy.set_training_mode(False)
        a, _, _ = self.model.policy(self.venv.normalize_obs(obs), deterministic=True)
        return a.clamp(-1.0, 1.0)

    # -------------------------------------------------------------- run
    def train(self) -> None:
        """As :meth:`PolicyTrainer.train`; the env is closed at the end."""
        try:
            super().train()
        finally:
            if self.env is not None:
                self.env.close()
                self.env = None

    def _run_stage(self, name: str, stage: StageConfig, remaining: int, state: dict | None,
                   bar) -> None:  # fmt: skip
        self.prepare_stage(stage, state)
        self.stage_done0 = self.stage_done
        self._learn(name, stage, bar)
        self.stage_done = stage.timesteps

    def _learn(self, name: str, stage: StageConfig, bar) -> None:
        """Rollouts and updates until the stage's steps are done (SB3's ``learn`` loop with the
        CPU trainer's callback folded in)."""
        model, env, norm = self.model, self.env, self.venv
        n, dev = env.num_envs, self.device
        start = model.num_timesteps
        cur = self.curriculum
        tau = stage.termination_at(self.stage_done)
        env.set_termination_dist(tau)
        model.lr_schedule = ConstantLearningRate(self.learning_rate_now())
        self.set_actor_frozen(self.in_critic_warmup())
        # (a resumed run's counts apply from its first rollout; per-category distances replace
        # the stage's one)
        cur.push(lambda method, *args: getattr(env, method)(*args))
        if cur.termination is not None:
            tau = cur.termination_m()
        obs = env.observe()
        norm.returns.zero_()
        norm.update_obs(obs)
        last = norm.normalize_obs(obs)
        starts = torch.ones(n, dtype=torch.bool, device=dev)
        ep = torch.zeros(3, n, dtype=torch.float64, device=dev)  # MPJPE sum, its count, frames
        rollouts = 0
        while self.stage_done < stage.timesteps:
            last, starts, stats = self._collect(last, starts, ep, bar, start)
            amp_stats = self.amp.update(stats.pop("amp_windows"))
            self._end_rollout_curricula(stats)
            row = self._log_rollout(name, tau, stats, amp_stats)
            if bar is not None:
                d_acc = (amp_stats["acc_real"] + amp_stats["acc_fake"]) / 2
                bar.set_postfix(stage=name, succ=f"{row.get('success_rate', 0.0):.2f}",
                                mpjpe=f"{row.get('mpjpe_mm', 0.0):.0f}mm",
                                d_acc=f"{d_acc:.2f}")  # fmt: skip
            rollouts += 1
            new_tau = stage.termination_at(self.stage_done)
            if cur.termination is not None:
                tau = cur.termination_m()
            elif new_tau != tau:
                env.set_termination_dist(new_tau)
                tau = new_tau
            model.lr_schedule = ConstantLearningRate(self.learning_rate_now())
            warm = self.in_critic_warmup()
            self.set_actor_frozen(warm)
            model.logger.record("train/critic_warmup", float(warm))
            if rollouts % self.cfg.checkpoint_every == 0:
                self.save_checkpoint()
            model.train()
            model.logger.dump(step=model.num_timesteps)

    @torch.no_grad()
    def _collect(self, last: dict[str, torch.Tensor], starts: torch.Tensor, ep: torch.Tensor,
                 bar, start: int) -> tuple[dict, torch.Tensor, dict]:  # fmt: skip
        """One rollout of ``ppo.n_steps`` decisions into the model's buffer (SB3's
        ``collect_rollouts`` + ``VecNormalize`` + ``AmpReward`` on tensors).

        Returns the last normalised observations, the episode-start flags and the rollout's
        sums (reward terms, episodes; ``"clips"``: the episodes that ended and the failures,
        per clip) with its AMP windows (``"amp_windows"``).
        """
        model, env, norm, amp = self.model, self.env, self.venv, self.amp
        buf, pol, p = model.rollout_buffer, model.policy, self.cfg.ppo
        n, dev = env.num_envs, self.device
        w_amp = float(self.cfg.env.reward.weights.amp)
        pol.set_training_mode(False)
        buf.reset()
        terms = torch.zeros(len(INFO_TERMS), dtype=torch.float64, device=dev)
        episodes = torch.zeros(4, dtype=torch.float64, device=dev)  # count, ok, MPJPE, frames
        n_clips = len(self.stage_clip_categories)
        per_clip = torch.zeros(2, n_clips, dtype=torch.float64, device=dev)  # ended, failed
        windows, ended = [], []  # AMP windows; (clip, start, end, failed) of ended episodes
        keep_episodes = self.curriculum.needs_episodes
        done = torch.zeros(n, dtype=torch.bool, device=dev)
        for _ in range(p.n_steps):
            actions, values, log_probs = pol(last)
            raw, rew, term, trunc, info = env.step(actions.clamp(-1.0, 1.0))
            done = term | trunc
            x = info["amp_obs"]
            r_amp = amp.reward(x)
            if amp.active:
                windows.append(x)
            terms += torch.stack([info[f"reward/{k}"].to(torch.float64) for k in INFO_TERMS[:-1]]
                                 + [r_amp.to(torch.float64)]).sum(dim=1)  # fmt: skip
            err = info["mpjpe_m"].to(torch.float64)
            fin = torch.isfinite(err)
            ep[0] += torch.where(fin, err, torch.zeros_like(err))
            ep[1] += fin
            ep[2] += info["frames"]
            ok = trunc & ~term
            if keep_episodes:  # (each episode started the frames it played before its end)
                end_frame = info["frame"]
                rec = torch.stack([info["clip_index"], end_frame - ep[2].long(), end_frame,
                                   (done & ~ok).long()])  # fmt: skip
            d = done.to(torch.float64)
            episodes += torch.stack([d.sum(), (ok & done).to(torch.float64).sum(),
                                     (d * ep[0] / ep[1].clamp(min=1)).sum(),
                                     (d * ep[2]).sum()])  # fmt: skip
            ep *= 1.0 - d
            ci = info["clip_index"]  # (the clip of the episode that ended: before the reset)
            per_clip[0].index_add_(0, ci, d)
            per_clip[1].index_add_(0, ci, (done & ~ok).to(torch.float64))
            if bool(done.any()):
                if keep_episodes:
                    ended.append(rec[:, done])
                env.reset(done)
                nxt = env.observe()
            else:
                nxt = raw
            norm.update_obs(nxt)
            r = norm.normalize_reward(rew + w_amp * r_amp, done)
            # SB3's time-limit bootstrap: a truncated episode's reward gets gamma x the value of
            # its last observation (computed for all, kept where truncated: no host sync)
            v_end = pol.predict_values(norm.normalize_obs(raw)).reshape(-1)
            r = r + p.gamma * torch.where(ok, v_end, torch.zeros_like(v_end))
            buf.add(last, actions, r, starts, values, log_probs)
            last, starts = norm.normalize_obs(nxt), done
            model.num_timesteps += n
            self.stage_done = model.num_timesteps - start + self.stage_done0
            if bar is not None:
                bar.update(n)
        buf.compute_returns_and_advantage(pol.predict_values(last), done)
        host = torch.cat([terms, episodes, per_clip.reshape(-1)]).cpu().numpy()  # (one copy)
        k = len(INFO_TERMS)
        fake = torch.cat(windows) if windows else torch.zeros(0, amp.disc.in_dim, device=dev)
        ends = torch.cat(ended, dim=1).cpu().numpy() if ended else np.zeros((4, 0), np.int64)
        stats = {"terms": host[:k].tolist(), "episodes": host[k : k + 4].tolist(),
                 "clips": host[k + 4 :].reshape(2, n_clips), "decisions": p.n_steps * n,
                 "amp_windows": fake, "ended": ends}  # fmt: skip
        return last, starts, stats

    def _end_rollout_curricula(self, stats: dict) -> None:
        """The stage's curricula after a rollout (the CPU trainer's ``TrainingCallback``): count
        the episodes that ended (mining per clip; start bins and per-category termination per
        episode), decay, and give the env and the real windows the new settings.

        Args:
            stats: :meth:`_collect`'s: ``"clips"``, ``(2, C)`` the ended and failed episodes of
                each clip; ``"ended"``, ``(4, E)`` each ended episode's clip, start and end
                frame, and whether it failed (when the curricula need them).
        """
        cur, env = self.curriculum, self.env
        cur.add_clip_counts(*stats["clips"])  # (all of them come before end_rollout)
        clip, start, end, failed = stats["ended"]
        if clip.size:
            cur.add(clip, start, end, failed.astype(bool), mining=False)
        if cur.termination is not None:  # (the distances of this rollout, for its row)
            stats["termination_by_category"] = cur.termination_by_category()
        for k, v in cur.end_rollout().items():
            self.model.logger.record(k, v)
        cur.push(lambda method, *args: getattr(env, method)(*args))
        self.set_real_probabilities()

    def _log_rollout(self, name: str, tau: float, stats: dict, amp_stats: dict) -> dict:
        """TensorBoard scalars and the history row of a rollout (the CPU trainer's keys)."""
        log = self.model.logger.record
        steps = max(stats["decisions"], 1)
        rewards = {f"reward/{k}": v / steps for k, v in zip(INFO_TERMS, stats["terms"],
                                                             strict=True)}  # fmt: skip
        count, ok, err, frames = stats["episodes"]
        for k, v in amp_stats.items():
            log(f"amp/{k}", v)
        for k, v in rewards.items():
            log(k, v)
        row = {"timesteps": int(self.total_done()),
               "frames": int(self.total_done()) * self.cfg.env.action_repeat, "stage": name,
               "wall_s": self.wall_s(), "termination_m": tau,
               "learning_rate": self.model.lr_schedule(1.0), **rewards,
               **{f"amp/{k}": v for k, v in amp_stats.items()}, "episodes": int(count)}  # fmt: skip
        if count > 0:
            row["success_rate"] = ok / count
            row["mpjpe_mm"] = 1000 * err / count
            row["ep_len"] = frames / count
            ended, failed = stats["clips"]  # [episodes, failures] per category, as on the CPU
            cats = self.stage_clip_categories
            row["by_category"] = episodes_by_category(
                (c, e, f) for c, e, f in zip(cats, ended, failed, strict=True) if e > 0
            )
        if "termination_by_category" in stats:
            row["termination_by_category"] = stats["termination_by_category"]
            log("episode/success_rate", row["success_rate"])
            log("episode/mpjpe_mm", row["mpjpe_mm"])
            log("episode/count", int(count))
            log("episode/frames", row["ep_len"])
        log("episode/termination_m", tau)
        self.history.append(row)
        return row
