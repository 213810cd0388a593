"""DynamicsNet training: PPO (stable-baselines3) with the AMP style reward, GRIP's two stages.

A run folder holds::

    config.json            resolved settings, git hash, data and KinematicsNet paths
    reference_train.npz    the training motions with KinematicsNet estimates (made once)
    checkpoint/            model.zip (SB3), vecnorm.npz, amp.pt, state.json (atomic swap)
    policy.pt              the inference export (:mod:`policies.runner`), after training
    tb/                    TensorBoard scalars
    curves.png             learning curves

Running the same command again resumes from ``checkpoint/`` (stage, steps, optimiser,
normaliser and discriminator; only the settings of :data:`RESUMABLE` may change, and the folder
is a :class:`grip.core.rundir.RunDir`); the replay buffer of policy samples is not saved (it refills
within a few rollouts). ``model.zip`` is written by stable-baselines3 but never loaded by it:
a resumed run builds its PPO from the config and takes the zip's state dicts and step counters
(:mod:`policies.checkpoint`), so nothing pickled in the folder runs.

Like SB3's ``PPO(policy, env)``, the trainer receives its environment: a constructor
(:class:`policies.vec_env.EnvMaker`) that the edge passes in (``grip policy train`` passes
:func:`envs.factory.make_tracking_env`); no tracking-env module is imported here.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections import defaultdict
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize
from tqdm import tqdm

from grip.config import drop_removed
from grip.core.reference_sets import load_reference, select_clip_indices
from grip.core.rundir import RunDir
from grip.task import amp as A
from policies.amp import AmpTrainer, RealSampler
from policies.checkpoint import load_weights, read_ppo_zip, read_vecnorm
from policies.config import REMOVED_SETTINGS, PolicyRunConfig, StageConfig
from policies.curriculum import StageCurriculum
from policies.mining import ClipFailureStats
from policies.runner import ACTIVATION_FNS, linear_layers
from policies.vec_env import (
    AmpReward,
    EnvMaker,
    load_vecnorm_state,
    make_vec_env,
    vecnorm_state,
)

INFO_TERMS = ("imit_pos", "imit_rot", "imit_vel", "imit_angvel", "root_vel", "root_pos", "energy",
              "amp")

GROWN_OBS: frozenset[tuple[str, str]] = frozenset({("OAV_Jrel", "OAV_Jrel_root")})
"""(theirs, ours) ``env.kinematic_obs`` pairs a warm start bridges: ours is theirs with inputs
appended to the ``kinematic`` part, which start with weights 0 (the policy acts as before) and
a normaliser variance of :data:`GROWN_OBS_VAR`."""
GROWN_OBS_VAR = 0.09
"""Normaliser variance of the appended inputs: the followed pelvis' offset, (0.3 m)^2."""

RESUMABLE: tuple[str, ...] = (
    "stage2.", "stage1.termination_", "checkpoint_every", "ppo.threads", "ppo.env_threads",
    "ppo.device",
    "ppo.n_envs", "ppo.learning_rate", "ppo.n_steps", "ppo.batch_size", "ppo.n_epochs",
    "ppo.gae_lambda", "ppo.clip_range", "ppo.ent_coef", "ppo.vf_coef", "ppo.max_grad_norm",
    "ppo.critic_warmup_steps", "amp.real_sampling", "env.reward.weights.amp",
    "env.root_speed_range", "env.lean_range_deg",
)  # fmt: skip
"""Settings (dotted prefixes) that may differ when a run is resumed: the optimiser's and the
rollout's layout (a resumed run takes them from the config, not from its checkpoint), the
threads of the update and of the physics (a run moved to a machine with more cores), the
termination curriculum, stage 2, and how the style reward is made (the real windows' sampler,
AMP on or off: a fork of a run's checkpoint may A/B them), and the root-speed and lean
augmentations."""


def episodes_by_category(counts: Iterable[tuple[str, int, int]]) -> dict[str, list[int]]:
    """A history row's ``"by_category"``: ``{category: [episodes, failures]}`` that ended in
    the rollout, summed over ``(category, episodes, failures)`` (one per episode, or per clip),
    categories in the order first seen."""
    out: dict[str, list[int]] = {}
    for cat, n, fails in counts:
        acc = out.setdefault(cat, [0, 0])
        acc[0] += int(n)
        acc[1] += int(fails)
    return out


# ------------------------------------------------------------------------ callback
class ConstantLearningRate:
    """An SB3 learning-rate schedule that returns one value (picklable, unlike a lambda in
    some pickle protocols); the callback replaces it after every rollout."""

    def __init__(self, value: float) -> None:
        self.value = float(value)

    def __call__(self, _progress_remaining: float) -> float:
        return self.value


class TrainingCallback(BaseCallback):
    """Discriminator updates, logging, progress bar and checkpoints of a training run."""

    def __init__(self, trainer: PolicyTrainer, stage_name: str, stage: StageConfig,
                 bar) -> None:  # fmt: skip
        super().__init__()
        self.trainer, self.stage_name, self.stage, self.bar = trainer, stage_name, stage, bar
        self.termination_m = stage.termination_dist_m
        self.sums: dict[str, float] = defaultdict(float)
        self.n = 0
        self.episodes: list[tuple[bool, float, int]] = []  # (success, mean MPJPE m, frames)
        self.ep_err = np.zeros(0)  # sum over the episode's decisions of the MPJPE, m
        self.ep_err_n = np.zeros(0)  # decisions with a finite MPJPE (a blow-up has none)
        self.ep_frames = np.zeros(0)  # frames played (decisions x action repeat)
        self.rollouts = 0
        self.start_steps = 0

    def _on_training_start(self) -> None:
        n = self.training_env.num_envs
        self.ep_err, self.ep_err_n, self.ep_frames = np.zeros(n), np.zeros(n), np.zeros(n)
        self.start_steps = self.num_timesteps
        self._set_termination()
        self._push_curriculum()
        self._set_learning_rate()
        self.trainer.set_actor_frozen(self.trainer.in_critic_warmup())

    def _set_learning_rate(self) -> None:
        """The learning rate of the next update (``ppo.learning_rate_decay_steps``)."""
        self.model.lr_schedule = ConstantLearningRate(self.trainer.learning_rate_now())

    def _set_termination(self) -> None:
        """The termination curriculum: the stage's distance after the steps done so far (with
        per-category distances, :meth:`_push_curriculum` sets them; their mean is logged)."""
        per_category = self.trainer.curriculum.termination_m()
        if per_category is not None:
            self.termination_m = per_category
            return
        tau = self.stage.termination_at(self.trainer.stage_done)
        if tau != self.termination_m or self.rollouts == 0:
            self.training_env.env_method("set_termination_dist", tau)
            self.termination_m = tau

    def _push_curriculum(self) -> None:
        """The stage's curricula to the environments (clip weights, start bins, per-category
        distances; :meth:`policies.curriculum.StageCurriculum.push`) and the real windows'
        clip probabilities (``amp.real_sampling = "episodes"``)."""
        env = self.training_env
        self.trainer.curriculum.push(lambda name, *args: env.env_method(name, *args))
        self.trainer.set_real_probabilities()

    def _on_step(self) -> bool:
        infos, dones = self.locals["infos"], self.locals["dones"]
        for i, (info, done) in enumerate(zip(infos, dones, strict=True)):
            for k in INFO_TERMS:
                self.sums[k] += info.get(f"reward/{k}", 0.0)
            err = info.get("mpjpe_m", np.inf)
            if np.isfinite(err):
                self.ep_err[i] += err
                self.ep_err_n[i] += 1
            self.ep_frames[i] += info.get("frames", 1)
            if done:
                ok = bool(info.get("TimeLimit.truncated", False))
                if "clip_index" in info:  # (the episode started ep_frames before its end)
                    end = int(info.get("frame", 0))
                    self.trainer.curriculum.add(int(info["clip_index"]),
                                                end - int(self.ep_frames[i]), end,
                                                not ok)  # fmt: skip
                mean_err = self.ep_err[i] / max(self.ep_err_n[i], 1)
                cat = self.trainer.clip_categories.get(info.get("clip"), "unknown")
                self.episodes.append((ok, mean_err, int(self.ep_frames[i]), cat))
                self.ep_err[i] = self.ep_err_n[i] = self.ep_frames[i] = 0
        self.n += len(infos)
        self.bar.update(len(infos))
        self.trainer.stage_done = self.num_timesteps - self.start_steps + self.trainer.stage_done0
        return True

    def _on_rollout_end(self) -> None:
        tr = self.trainer
        stats = tr.amp.update(tr.amp_wrapper.pop_samples())
        log = self.logger.record
        for k, v in stats.items():
            log(f"amp/{k}", v)
        for k in INFO_TERMS:
            log(f"reward/{k}", self.sums[k] / max(self.n, 1))
        if self.episodes:
            ok = np.array([e[0] for e in self.episodes])
            log("episode/success_rate", float(ok.mean()))
            log("episode/mpjpe_mm", 1000 * float(np.mean([e[1] for e in self.episodes])))
            log("episode/count", len(self.episodes))
            log("episode/frames", float(np.mean([e[2] for e in self.episodes])))
        log("episode/termination_m", self.termination_m)
        by_cat = tr.curriculum.termination_by_category()  # (this rollout's, for its row)
        for k, v in tr.curriculum.end_rollout().items():
            log(k, v)
        self._push_curriculum()
        self._set_learning_rate()
        row = {"timesteps": int(tr.total_done()),
               "frames": int(tr.total_done()) * tr.cfg.env.action_repeat, "stage": self.stage_name,
               "wall_s": tr.wall_s(), "termination_m": self.termination_m,
               "learning_rate": self.model.lr_schedule(1.0),
               **{f"reward/{k}": self.sums[k] / max(self.n, 1) for k in INFO_TERMS},
               **{f"amp/{k}": v for k, v in stats.items()}, "episodes": len(self.episodes)}
        if self.episodes:
            row["success_rate"] = float(np.mean([e[0] for e in self.episodes]))
            row["mpjpe_mm"] = 1000 * float(np.mean([e[1] for e in self.episodes]))
            row["ep_len"] = float(np.mean([e[2] for e in self.episodes]))
            row["by_category"] = episodes_by_category(
                (cat, 1, not ok_) for ok_, _, _, cat in self.episodes
            )
        if by_cat is not None:
            row["termination_by_category"] = by_cat
        tr.history.append(row)
        d_acc = (stats["acc_real"] + stats["acc_fake"]) / 2
        succ, err = row.get("success_rate", 0.0), row.get("mpjpe_mm", 0.0)
        self.bar.set_postfix(stage=self.stage_name, succ=f"{succ:.2f}", mpjpe=f"{err:.0f}mm",
                             d_acc=f"{d_acc:.2f}")  # fmt: skip
        self.sums.clear()
        self.n = 0
        self.episodes = []
        self.rollouts += 1
        self._set_termination()
        # the update that follows this rollout trains the value network only during warm-up
        warm = tr.in_critic_warmup()
        tr.set_actor_frozen(warm)
        log("train/critic_warmup", float(warm))
        if self.rollouts % tr.cfg.checkpoint_every == 0:
            tr.save_checkpoint()


# ------------------------------------------------------------------------ trainer
def _upgrade_settings(old: dict, where: str) -> dict:
    """An older run folder's recorded settings without those removed since (off: dropped; on:
    refused, :func:`grip.config.drop_removed`)."""
    return drop_removed(old, REMOVED_SETTINGS, where)


class PolicyTrainer:
    """A resumable DynamicsNet training run in ``run_dir``.

    Args:
        cfg: Settings.
        run_dir: Run folder (created or resumed).
        reference: Training reference set (``.npz``); copied into the run on first use.
        make_env: The environment constructor (:class:`EnvMaker`; the edge passes
            :func:`envs.factory.make_tracking_env`).
        progress: tqdm-like factory ``progress(total=..., initial=...)`` (None: no bar).
        init: An exported policy (``policy.pt``) to start from instead of random weights
            (:meth:`warm_start`); ignored when the run resumes from its own checkpoint.
        init_member: Which member of an ensemble ``init`` to start from (0, the first, by
            default). Members after the first carry no discriminator of their own: the file's
            (the first member's) is taken.

    Raises:
        ValueError: naming the file, when ``init`` is not a policy, or ``init_member`` is not
            one of its members, or when ``run_dir`` holds a checkpoint of other settings than
            ``cfg`` (besides :data:`RESUMABLE`).
    """

    def __init__(self, cfg: PolicyRunConfig, run_dir: str | os.PathLike,
                 reference: str | os.PathLike, make_env: EnvMaker,
                 progress: Callable | None = None, init: str | os.PathLike | None = None,
                 init_member: int = 0) -> None:  # fmt: skip
        self.cfg = cfg
        self.rundir = RunDir(run_dir, RESUMABLE, "'grip policy train' run")
        self.rundir.check_resume(cfg, defaults=PolicyRunConfig(), upgrade=_upgrade_settings)
        self.run_dir = self.rundir.path
        self.reference = str(reference)
        self.make_env = make_env
        self.progress = progress
        self.init = init
        self._init_runner = None
        self.init_members = 1  # policies in the --init file (an ensemble starts from its first)
        self.init_name = str(init)  # the policy started from (an ensemble's member by name)
        if init is not None:
            from policies.ensemble import member_payload
            from policies.runner import PolicyRunner

            ck, self.init_name, self.init_members = member_payload(init, init_member)
            pol = PolicyRunner.from_payload(ck, self.init_name)  # (ensembles keep no critic)
            self._init_runner = pol
        self.stage_index = 0
        self.stage_done = 0
        self.stage_done0 = 0
        self.history: list[dict] = []
        self.model: PPO | None = None
        self.venv: VecNormalize | None = None
        self.amp_wrapper: AmpReward | None = None
        ref = load_reference(self.reference)
        real = RealSampler([A.reference_amp_features(c) for c in ref.clips], cfg.amp.window)
        # (AMP off, weight 0: the discriminator is neither run nor trained)
        self.amp = AmpTrainer(cfg.amp, real, seed=cfg.seed,
                              active=cfg.env.reward.weights.amp != 0)  # fmt: skip
        self.curriculum: StageCurriculum | None = None  # the current stage's clip curricula
        self.clip_categories: dict[str, str] = {}  # clip name -> category, of the stage's clips
        self._saved_state: dict | None = None  # the checkpoint's state, until its stage runs

    # -------------------------------------------------------------- bookkeeping
    @property
    def mining(self) -> ClipFailureStats | None:
        """The current stage's hard-clip mining (``None`` unless its ``mining_mix > 0``)."""
        return None if self.curriculum is None else self.curriculum.mining

    @property
    def ckpt_dir(self) -> Path:
        return self.rundir.checkpoint_dir

    def wall_s(self) -> float:
        return self.rundir.wall_s()

    def total_done(self) -> int:
        stages = self.cfg.stages()
        return sum(s.timesteps for _, s in stages[: self.stage_index]) + self.stage_done

    def save_checkpoint(self) -> None:
        """Write ``checkpoint/`` atomically (:meth:`grip.core.rundir.RunDir.save_checkpoint`):
        ``model.zip``, ``vecnorm.npz``, ``amp.pt`` and ``state.json``."""

        def write(tmp: Path) -> None:
            self.model.save(tmp / "model.zip")
            np.savez(tmp / "vecnorm.npz", **vecnorm_state(self.venv))
            amp_state = self.amp.state_dict()
            amp_state["rng"] = json.dumps(amp_state["rng"])  # (weights_only loads plain types)
            torch.save(amp_state, tmp / "amp.pt")

        state = {"stage_index": self.stage_index, "stage_done": self.stage_done,
                 "wall_s": self.wall_s(), "history": self.history}  # fmt: skip
        if self.curriculum is not None:
            state.update(self.curriculum.state(self.stage_index))
        self.rundir.save_checkpoint(write, state)

    # -------------------------------------------------------------- model
    def _policy_kwargs(self) -> dict:
        p = self.cfg.ppo
        arch = list(p.net_arch)
        # SB3's Adam (its eps of 1e-5) over all tensors at once: the numbers of its default
        # loop over the tensors, bit for bit, ~30 % faster (benchmarks/ppo_update.py)
        return {"net_arch": {"pi": arch, "vf": arch}, "activation_fn": ACTIVATION_FNS[p.activation],
                "log_std_init": p.log_std_init,
                "optimizer_kwargs": {"eps": 1e-5, "foreach": True}}  # fmt: skip

    def _build_env(self, stage: StageConfig) -> VecNormalize:
        p = self.cfg.ppo
        seed = self.cfg.seed + 7919 * self.stage_index + self.stage_done
        base = make_vec_env(self.cfg, stage, self.reference, seed, self.make_env)
        self.amp_wrapper = AmpReward(base, self.amp, self.cfg.env.reward.weights.amp)
        mon = VecMonitor(self.amp_wrapper)
        return VecNormalize(mon, norm_obs=True, norm_reward=p.normalize_reward,
                            clip_obs=p.clip_obs, gamma=p.gamma)  # fmt: skip

    def _ppo_settings(self) -> dict:
        """The PPO settings of the config that a resumed run takes over from the config, not
        from the checkpoint (so ``--set ppo.learning_rate=...`` applies to a resumed run)."""
        p = self.cfg.ppo
        return {"learning_rate": p.learning_rate, "n_steps": p.n_steps,
                "batch_size": p.batch_size, "n_epochs": p.n_epochs, "gae_lambda": p.gae_lambda,
                "clip_range": p.clip_range, "ent_coef": p.ent_coef, "vf_coef": p.vf_coef,
                "max_grad_norm": p.max_grad_norm}  # fmt: skip

    def _new_model(self, venv: VecNormalize) -> PPO:
        p = self.cfg.ppo
        return PPO("MultiInputPolicy", venv, gamma=p.gamma, policy_kwargs=self._policy_kwargs(),
                   tensorboard_log=str(self.run_dir / "tb"), seed=self.cfg.seed,
                   device=p.device, verbose=0, **self._ppo_settings())  # fmt: skip

    def _restore_model(self) -> None:
        """The model and normaliser of ``checkpoint/``, for a resumed run: a PPO built from the
        config (:meth:`_new_model`) that takes the checkpoint's network weights, optimiser state
        and step counters; nothing pickled in ``model.zip`` is loaded
        (:func:`policies.checkpoint.read_ppo_zip`).

        Raises:
            ValueError: naming the file, for a corrupt or hostile checkpoint file or one that
                does not fit the run's settings.
        """
        ck = read_ppo_zip(self.ckpt_dir / "model.zip")
        norm_path = self.ckpt_dir / "vecnorm.npz"
        norm = read_vecnorm(norm_path)
        try:
            load_vecnorm_state(self.venv, norm)
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"{norm_path}: does not fit this run's observations ({e})") from e
        self.model = self._new_model(self.venv)
        ck.restore(self.model)

    def _actor_params(self) -> list[torch.nn.Parameter]:
        pol = self.model.policy
        params = [*pol.mlp_extractor.policy_net.parameters(), *pol.action_net.parameters()]
        return [*params, pol.log_std]

    def set_actor_frozen(self, frozen: bool) -> None:
        """Freeze the policy (mean network and log std) so that a PPO update trains only the
        value network (``ppo.critic_warmup_steps``); Adam skips parameters without gradients."""
        for prm in self._actor_params():
            prm.requires_grad_(not frozen)

    def learning_rate_now(self) -> float:
        """``ppo.learning_rate``, annealed linearly to ``ppo.learning_rate_final`` over the
        last ``ppo.learning_rate_decay_steps`` decisions of the final stage."""
        p = self.cfg.ppo
        stages = self.cfg.stages()
        if p.learning_rate_decay_steps <= 0 or self.stage_index != len(stages) - 1:
            return p.learning_rate
        start = stages[-1][1].timesteps - p.learning_rate_decay_steps
        frac = float(np.clip((self.stage_done - start) / p.learning_rate_decay_steps, 0.0, 1.0))
        return p.learning_rate + frac * (p.learning_rate_final - p.learning_rate)

    def in_critic_warmup(self) -> bool:
        return self.total_done() < self.cfg.ppo.critic_warmup_steps

    def warm_start(self, runner) -> None:
        """Start from an exported policy (:class:`policies.runner.PolicyRunner`): its policy
        network and log std, its value network when the file has one, its observation
        normaliser and its discriminator. PPO's optimiser, the return normaliser and the
        discriminator's optimiser start afresh.

        Raises:
            ValueError: naming the file, when its networks or observations do not fit this
                run's settings.
        """
        src = self.init
        pol = self.model.policy
        spaces = self.model.observation_space.spaces
        if list(runner.obs_keys) != list(spaces):
            raise ValueError(f"{src}: observation parts {runner.obs_keys} differ from this "
                             f"run's {list(spaces)}")  # fmt: skip
        theirs, ours = runner.env_cfg.kinematic_obs, self.cfg.env.kinematic_obs
        grown = (theirs, ours) in GROWN_OBS
        if theirs != ours and not grown:  # their inputs mean different things at the same places
            raise ValueError(f"{src}: trained with env.kinematic_obs={theirs!r}, this run has "
                             f"{ours!r}")  # fmt: skip
        extra = {k: space.shape[0] - runner.obs_mean[k].shape[0] for k, space in spaces.items()}
        for k, space in spaces.items():
            shape = runner.obs_mean[k].shape
            if shape != space.shape and not (grown and k == "kinematic" and len(shape) == 1
                                             and extra[k] > 0):  # fmt: skip
                raise ValueError(f"{src}: observation {k!r} has shape {shape}, this run's "
                                 f"{space.shape}")  # fmt: skip
        # this run's input column of each of theirs (new inputs end their part, weights 0)
        cols, at = [], 0
        for k in spaces:
            n = runner.obs_mean[k].shape[0]
            cols += range(at, at + n)
            at += n + extra[k]
        cols_t = torch.as_tensor(cols)

        def load(mlp, body, head, what: str) -> None:
            ours, theirs = linear_layers(body, head), linear_layers(mlp)
            shapes = [tuple(m.weight.shape) for m in ours]
            want = [tuple(m.weight.shape) for m in theirs]
            want[0] = (want[0][0], at)
            if shapes != want:
                raise ValueError(f"{src}: its {what} network has layers "
                                 f"{[tuple(m.weight.shape) for m in theirs]}, this run's "
                                 f"{shapes} (set ppo.net_arch to match)")  # fmt: skip
            with torch.no_grad():
                for i, (dst, s) in enumerate(zip(ours, theirs, strict=True)):
                    if i == 0:
                        dst.weight.zero_()
                        dst.weight[:, cols_t] = s.weight
                    else:
                        dst.weight.copy_(s.weight)
                    dst.bias.copy_(s.bias)

        load(runner.actor, pol.mlp_extractor.policy_net, pol.action_net, "policy")
        if runner.critic is not None:
            load(runner.critic, pol.mlp_extractor.value_net, pol.value_net, "value")
        if runner.log_std is not None:
            with torch.no_grad():
                pol.log_std.copy_(runner.log_std)
        count = runner.obs_count if runner.obs_count is not None else 1e6
        for k, rms in self.venv.obs_rms.items():
            e = extra[k]
            rms.mean = np.concatenate([runner.obs_mean[k], np.zeros(e)])
            rms.var = np.concatenate([runner.obs_var[k], np.full(e, GROWN_OBS_VAR)])
            rms.count = count
        if runner.disc is not None:
            try:
                self.amp.disc.load_state_dict(runner.disc.state_dict())
            except RuntimeError as e:
                raise ValueError(f"{src}: its discriminator does not fit this run's amp "
                                 f"settings ({e})") from e

    # -------------------------------------------------------------- run
    def train(self) -> None:
        """Train (or resume) both stages, checkpointing as configured; then export."""
        self.run_dir.mkdir(parents=True, exist_ok=True)
        if self.cfg.ppo.threads:
            torch.set_num_threads(self.cfg.ppo.threads)
        state = self.rundir.read_state()
        if state is not None:
            self.stage_index, self.stage_done = state["stage_index"], state["stage_done"]
            self.rundir.wall0_s, self.history = state["wall_s"], state["history"]
            self._saved_state = state
            ck = load_weights(self.ckpt_dir / "amp.pt", "discriminator checkpoint")
            ck["rng"] = json.loads(ck["rng"])
            self.amp.load_state_dict(ck)
        stages = self.cfg.stages()
        bar = None
        if self.progress is not None:
            bar = self.progress(total=self.cfg.total_timesteps(), initial=self.total_done(),
                                unit="step", smoothing=0.05)  # fmt: skip
        try:
            while self.stage_index < len(stages):
                name, stage = stages[self.stage_index]
                remaining = stage.timesteps - self.stage_done
                if remaining > 0:
                    self._run_stage(name, stage, remaining, state, bar)
                    state = None
                    self.save_checkpoint()
                if self.stage_index == len(stages) - 1:
                    break  # the last stage stays current, so a longer one can resume
                self.stage_index += 1
                self.stage_done = 0
        finally:
            if bar is not None:
                bar.close()
            if self.venv is not None:
                self.venv.close()

    def _begin_stage_clips(self, stage: StageConfig) -> list[str]:
        """The stage's clip bookkeeping: :attr:`clip_categories` and the curricula
        :attr:`curriculum` (hard-clip mining, start bins, per-category termination; their
        counts restored from the checkpoint when they are this stage's), and the real windows'
        clip probabilities.

        Returns:
            ``(C,)`` the category of each of the stage's clips, in the environments' clip order.
        """
        ref = load_reference(self.reference)
        index = select_clip_indices(ref, stage.categories)
        clips = [ref.clips[i] for i in index]
        self.clip_categories = {c.name: c.category for c in clips}
        self.curriculum = StageCurriculum(stage, clips, index, len(ref.clips),
                                          1.0 / self.cfg.env.control_dt_s,
                                          stage.termination_at(self.stage_done))  # fmt: skip
        self.curriculum.restore(self._saved_state, self.stage_index)
        self._saved_state = None
        self.set_real_probabilities()
        return [c.category for c in clips]

    def set_real_probabilities(self) -> None:
        """``amp.real_sampling = "episodes"``: the real windows' clips drawn as the episodes'
        (:meth:`policies.curriculum.StageCurriculum.real_probabilities`)."""
        if self.cfg.amp.real_sampling == "episodes" and self.curriculum is not None:
            self.amp.set_real_clip_probabilities(self.curriculum.real_probabilities())

    def _run_stage(self, name: str, stage: StageConfig, remaining: int, state: dict | None,
                   bar) -> None:  # fmt: skip
        old_norm = vecnorm_state(self.venv) if self.venv is not None else None
        if self.venv is not None:
            self.venv.close()
        self.venv = self._build_env(stage)
        if state is not None and (self.ckpt_dir / "model.zip").is_file():
            self._restore_model()
        elif self.model is None:
            self.model = self._new_model(self.venv)
            if self._init_runner is not None:
                self.warm_start(self._init_runner)
        else:
            load_vecnorm_state(self.venv, old_norm)
            self.model.set_env(self.venv)
        self.stage_done0 = self.stage_done
        self._begin_stage_clips(stage)
        cb = TrainingCallback(self, name, stage, bar if bar is not None else tqdm(disable=True))
        self.model.learn(total_timesteps=remaining, callback=cb, reset_num_timesteps=False,
                         tb_log_name="ppo", progress_bar=False)  # fmt: skip
        self.stage_done = stage.timesteps


def run_config_dict(cfg: PolicyRunConfig) -> dict:
    return dataclasses.asdict(cfg)
