"""Settings of DynamicsNet training (frozen dataclasses; ``configs/policy/*.toml`` hold overrides).

GRIP's values (paper, supplement, BASELINES_AND_METRICS section 5) are noted where the CPU
default differs; the defaults were chosen by measurement on a 2-core machine.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from grip.config import REMOVED_ANY_VALUE, ConfigError, RemovedSetting, apply_dict, drop_removed
from grip.core.checks import check
from grip.task.config import TrackingEnvConfig

ACTIVATIONS: tuple[str, ...] = ("silu", "relu", "tanh", "elu")
AMP_LOSSES: tuple[str, ...] = ("lsgan", "bce")
REAL_SAMPLING: tuple[str, ...] = ("frames", "episodes")
"""How the discriminator's real windows are drawn (:attr:`AmpConfig.real_sampling`)."""
VEC_ENVS: tuple[str, ...] = ("subproc", "dummy", "batched")
FOLLOW: tuple[str, ...] = ("estimate", "truth", "both")
"""What a run's controller follows (:attr:`PolicyRunConfig.follow`)."""

SPEED_FACTOR_RANGE: tuple[float, float] = (0.5, 2.0)
"""The factors ``speed_factors`` accepts: :data:`grip.motion.motion.TIME_SCALE_RANGE`, which
the policies may not import."""

GRIP_NET_ARCH: tuple[int, ...] = (2048, 1536, 1024, 1024, 512, 512)
"""GRIP's policy MLP (8.6M parameters); ``--set ppo.net_arch=[2048,1536,1024,1024,512,512]``."""


def speed_rules(factors: tuple, categories: tuple) -> tuple[tuple[bool, str], ...]:
    """The :func:`grip.core.checks.check` rules of ``speed_factors`` and ``speed_categories``
    (:class:`PolicyRunConfig`'s and :class:`policies.distill.DistillConfig`'s).

    Args:
        factors: The speed factors: distinct numbers (as their clips' names write them, e.g.
            ``@x1.25``) in :data:`SPEED_FACTOR_RANGE`, none of them 1.
        categories: Category globs of the clips played faster; at least one with factors.

    Returns:
        ``(condition, message)`` pairs, the messages naming the setting and the values given.
    """
    lo, hi = SPEED_FACTOR_RANGE
    nums = [f for f in factors if isinstance(f, int | float) and not isinstance(f, bool)]
    ok = (len(nums) == len(factors) and all(lo <= f <= hi and f != 1 for f in nums)
          and len({f"{float(f):g}" for f in nums}) == len(nums))  # fmt: skip
    return (
        (ok, f"speed_factors must be distinct numbers in [{lo:g}, {hi:g}], none of them 1, got "
             f"{list(factors)}"),
        (not factors or len(categories) > 0,
         "speed_categories must name at least one category glob when speed_factors is set"),
    )  # fmt: skip


@dataclass(frozen=True)
class AmpConfig:
    """The AMP discriminator (BASELINES_AND_METRICS 5.2).

    Attributes:
        window: Consecutive AMP frames per sample (PHC: 10; the AMP paper: 2).
        hidden: Hidden layer sizes of the discriminator MLP (PHC: 1024, 512).
        loss: ``"lsgan"`` (the AMP paper: targets +-1, r = max(0, 1 - (D - 1)^2 / 4),
            probability rho = clip((D + 1) / 2, 0, 1)) or ``"bce"`` (PHC's code: logits,
            r = -log(max(1 - sigmoid(D), 1e-4)), rho = sigmoid(D)).
        grad_penalty: Weight of the gradient penalty on real samples (AMP paper: 10, applied
            as w / 2 E ||grad D||^2).
        logit_reg: Weight of the L2 penalty on the last layer's weights (PHC: 0.01).
        weight_decay: Adam weight decay (PHC: 1e-4).
        lr: Adam learning rate.
        batch_size: Real and fake samples per discriminator update (each).
        updates_per_rollout: Discriminator updates after each PPO rollout.
        replay_size: Policy samples kept for the discriminator (oldest replaced first).
        reward_scale: Multiplies the AMP reward before its weight (PHC: 2 with BCE).
        real_sampling: How real windows are drawn (:data:`REAL_SAMPLING`): ``"frames"``, every
            frame of every clip of the run's reference set equally (the AMP paper); or
            ``"episodes"``, a clip with the probability the environments start episodes on it
            (the stage's categories, the clips' lengths and hard-clip mining's weights,
            :func:`grip.core.reference_sets.clip_probabilities`, updated with them), then a
            frame uniformly within it (PHC draws its demonstrations as its episodes), so a
            category the policy plays often is as common among the real windows.
        A run without AMP sets ``env.reward.weights.amp = 0``: the discriminator is then
        neither run nor trained (:class:`policies.amp.AmpTrainer`, ``active``).
    """

    window: int = 10
    hidden: tuple[int, ...] = (512, 256)
    loss: str = "lsgan"
    grad_penalty: float = 10.0
    logit_reg: float = 0.01
    weight_decay: float = 1e-4
    lr: float = 1e-4
    batch_size: int = 512
    updates_per_rollout: int = 8
    replay_size: int = 20000
    reward_scale: float = 1.0
    real_sampling: str = "frames"


@dataclass(frozen=True)
class PPOConfig:
    """PPO (stable-baselines3) and the policy network.

    Attributes:
        net_arch: Hidden sizes of the policy MLP (the value MLP has the same); GRIP:
            :data:`GRIP_NET_ARCH`.
        activation: :data:`ACTIVATIONS` (GRIP: SiLU).
        log_std_init: Initial log standard deviation of the Gaussian actions (PHC: -2.9).
        n_envs: Environments; stepped in parallel processes with ``vec_env = "subproc"``.
        vec_env: ``"subproc"`` (one process per environment), ``"dummy"`` (all in the learner,
            one after the other) or ``"batched"`` (all in the learner, stepped by one call:
            numpy over all environments at once, the physics in ``env_threads`` threads; the
            same transitions as ``"dummy"``).
        n_steps: Steps per environment per rollout.
        batch_size: Minibatch size.
        n_epochs: Passes over each rollout.
        learning_rate: Adam learning rate.
        learning_rate_decay_steps: Anneal the learning rate over the last this many decisions
            of the final stage, linearly from ``learning_rate`` to ``learning_rate_final`` (0 =
            constant). Tied to the stage's end, so extending ``stage2.timesteps`` moves the
            decay to the new end. Against the swings of a long run's last exports.
        learning_rate_final: The learning rate at the end of the decay.
        gamma, gae_lambda, clip_range, ent_coef, vf_coef, max_grad_norm: PPO as in SB3.
        normalize_reward: Scale rewards by a running return std (SB3 VecNormalize).
        clip_obs: Normalised observations are clipped to +- this.
        critic_warmup_steps: Steps (decisions, counted from the start of the run) during which
            only the value network learns and the policy stays as it is: for a run warm-started
            from an exported policy without a value network (``grip policy train --init``),
            whose fresh critic would otherwise feed the policy meaningless advantages.
        threads: Torch threads of the learner (0: all cores).
        env_threads: Physics threads of the ``"batched"`` vector env (0: all cores).
        device: Torch device of the learner (``"cpu"``, ``"cuda"``, ``"auto"``).
    """

    net_arch: tuple[int, ...] = (512, 256, 256)
    activation: str = "silu"
    log_std_init: float = -1.6
    n_envs: int = 8
    vec_env: str = "subproc"
    n_steps: int = 256
    batch_size: int = 1024
    n_epochs: int = 5
    learning_rate: float = 2e-4
    learning_rate_decay_steps: int = 0
    learning_rate_final: float = 0.0
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 1.0
    normalize_reward: bool = True
    clip_obs: float = 10.0
    critic_warmup_steps: int = 0
    threads: int = 0
    env_threads: int = 0
    device: str = "cpu"


@dataclass(frozen=True)
class StageConfig:
    """One stage of GRIP's curriculum.

    Attributes:
        timesteps: Environment steps of this stage (all environments together).
        termination_dist_m: Early termination when any joint is this far from the ground
            truth (GRIP stage 1: 0.25 m; stage 2: off = 0).
        fall_height_m: End the episode when the pelvis is below this height, m (0: never); in
            stage 2 a fallen body otherwise lies on the floor until the clip ends.
        fall_below_reference_m: ... and also this far below the ground truth's pelvis (0:
            always; :attr:`grip.task.config.TrackingEnvConfig.fall_below_reference_m`): clips on
            the floor are followed, not ended.
        termination_root_gap_m: End the episode when the pelvis is this far, horizontally,
            from the pelvis it follows, m (0: never;
            :attr:`grip.task.config.TrackingEnvConfig.termination_root_gap_m`).
        max_episode_frames: Truncate episodes after this many steps (0: the clip's end).
        categories: Train on clips of these motion categories only (empty: all).
        termination_start_m: Termination curriculum: the stage starts with this (looser)
            distance and tightens it linearly to ``termination_dist_m`` over
            ``termination_anneal_steps``; 0 = no curriculum. Long episodes early on teach
            balance before precision (at 0.25 m an untrained controller's episodes end after
            about half a second).
        termination_anneal_steps: Steps of the stage over which the distance tightens.
        mining_mix: Hard-clip mining (:mod:`policies.mining`): share of episodes started on
            clips in proportion to their recent failure rate instead of by length alone
            (0 = off, 1 = all).
        mining_decay: Per-rollout decay of the mining counts (memory ``1 / (1 - decay)``
            rollouts).
        mining_prior: Episodes' worth of the overall failure rate in each clip's estimate
            (and of a clip's rate in each of its bins' estimates, ``mining_bins_mix``).
        mining_bins_mix: Failure-weighted starts within each clip
            (:class:`policies.mining.StartBinStats`): share of episode starts drawn in
            proportion to the recent failure rate of the clip's 1-second bins instead of
            uniformly over its frames (0 = off, 1 = all).
        mining_bins_memory: Episodes through an average bin that its failure estimate
            remembers: the bins' counts decay after each rollout by ``1 - v / memory``, ``v``
            the rollout's episodes per bin (the decay follows the number of environments and
            of bins).
        termination_category_min_m: Per-category termination distance
            (:class:`policies.curriculum.CategoryTermination`; 0 = off, the stage's one
            distance): each category's distance, kept within ``[min, max]``, tightens by
            ``termination_category_step`` after a rollout where most of its episodes reached
            their length limit and loosens where most ended early (PBHC, ASAP). It starts at
            the stage's distance (``termination_start_m`` or ``termination_dist_m``, the max
            when that is 0) and replaces the stage's distance and its curriculum.
        termination_category_max_m: The loosest per-category distance, m.
        termination_category_band: ``(low, high)`` share of a category's episodes that reach
            their limit (over about its last ten episodes): below ``low`` the distance
            loosens, above ``high`` it tightens.
        termination_category_step: Relative change of a category's distance per rollout.
    """

    timesteps: int = 0
    termination_dist_m: float = 0.25
    fall_height_m: float = 0.0
    fall_below_reference_m: float = 0.0
    termination_root_gap_m: float = 0.0
    max_episode_frames: int = 300
    categories: tuple[str, ...] = ()
    termination_start_m: float = 0.0
    termination_anneal_steps: int = 0
    mining_mix: float = 0.0
    mining_decay: float = 0.995
    mining_prior: float = 2.0
    mining_bins_mix: float = 0.0
    mining_bins_memory: float = 8.0
    termination_category_min_m: float = 0.0
    termination_category_max_m: float = 1.0
    termination_category_band: tuple[float, float] = (0.5, 0.8)
    termination_category_step: float = 0.02

    def __post_init__(self) -> None:
        lo_hi = self.termination_category_band
        check(
            self,
            (0.0 <= self.mining_bins_mix <= 1.0, "mining_bins_mix must be in [0, 1]"),
            (self.mining_bins_memory > 0, "mining_bins_memory must be > 0 episodes"),
            (self.termination_root_gap_m >= 0, "termination_root_gap_m must be >= 0 (0 = off)"),
            (self.termination_category_min_m >= 0,
             "termination_category_min_m must be >= 0 (0 = off)"),
            (self.termination_category_max_m >= self.termination_category_min_m,
             "termination_category_max_m must be >= termination_category_min_m"),
            (len(lo_hi) == 2 and 0.0 <= lo_hi[0] < lo_hi[1] <= 1.0,
             "termination_category_band must be (low, high) with 0 <= low < high <= 1"),
            (0.0 < self.termination_category_step < 1.0,
             "termination_category_step must be in (0, 1)"),
        )  # fmt: skip

    def termination_at(self, steps: int) -> float:
        """The termination distance after ``steps`` steps of this stage, m."""
        if self.termination_start_m <= 0 or self.termination_dist_m <= 0:
            return self.termination_dist_m
        n = self.termination_anneal_steps
        f = min(1.0, steps / n) if n > 0 else 1.0
        return self.termination_start_m + f * (self.termination_dist_m - self.termination_start_m)


@dataclass(frozen=True)
class PolicyRunConfig:
    """Everything ``grip policy train`` needs (written to ``config.json``)."""

    env: TrackingEnvConfig = field(default_factory=TrackingEnvConfig)
    ppo: PPOConfig = field(default_factory=PPOConfig)
    amp: AmpConfig = field(default_factory=AmpConfig)
    stage1: StageConfig = field(default_factory=lambda: StageConfig(timesteps=2_000_000))
    stage2: StageConfig = field(default_factory=lambda: StageConfig(
        timesteps=1_000_000, termination_dist_m=0.0, fall_height_m=0.3, max_episode_frames=1000,
    ))  # fmt: skip
    checkpoint_every: int = 10
    """Rollouts between checkpoints."""
    seed: int = 0
    mirror_references: bool = False
    """The run's reference set (``RUN/reference_train.npz``, built by ``grip policy train``)
    also holds the left-right mirror image of every clip
    (:func:`grip.kinematics.reference.with_mirrored_clips`): twice the motions, left and
    right balanced."""
    follow: str = "estimate"
    """What the controller learns to follow: ``"estimate"`` (GRIP's DynamicsNet: the
    KinematicsNet estimates of the training clips) or ``"truth"`` (a privileged tracker, the
    teacher of ``grip policy distill``: the reference set's "estimate" is the ground truth
    itself, :func:`grip.kinematics.reference.oracle_reference_clip`, with the sensor features
    of the ``--kin`` checkpoint so that teacher and student observe the same layout). Evaluate
    such a policy with ``grip policy eval --reference truth``. ``"both"``: every training clip
    twice, once with the estimates and once with the ground truth as the reference (named
    ``<clip>#truth``): a controller that tracks motion rather than one estimator's errors."""
    speed_factors: tuple[float, ...] = ()
    """The reference set also holds the training clips of ``speed_categories`` played each of
    these times faster (:meth:`grip.motion.motion.Motion.time_scaled`, sensors synthesised and
    estimated like the other clips; names ``<clip>@x<factor>``, categories unchanged): walking
    speeds the training people never walked (docs/pace.md). Each in [0.5, 2], not 1. Empty:
    none."""
    speed_categories: tuple[str, ...] = ("walk*",)
    """Category globs of the clips ``speed_factors`` plays faster."""
    holdout_fraction: float = 0.0
    """Share of the training split's clips (whole clips, all their chunks) kept out of the
    reference set, drawn with ``seed`` (:func:`grip.kinematics.dataset.holdout_names`): a
    validation split for choosing among a run's exports without looking at the test split
    (``grip policy eval --split holdout``). The names are in ``RUN/holdout.json`` and in every
    export's ``info``. 0 trains on every training clip."""

    def __post_init__(self) -> None:
        check(
            self,
            (self.ppo.activation in ACTIVATIONS, f"ppo.activation must be one of {ACTIVATIONS}"),
            (self.ppo.vec_env in VEC_ENVS, f"ppo.vec_env must be one of {VEC_ENVS}"),
            (self.amp.loss in AMP_LOSSES, f"amp.loss must be one of {AMP_LOSSES}"),
            (self.amp.real_sampling in REAL_SAMPLING,
             f"amp.real_sampling must be one of {REAL_SAMPLING}"),
            (self.amp.window >= 1, "amp.window must be >= 1"),
            (self.ppo.n_envs >= 1, "ppo.n_envs must be >= 1"),
            (self.ppo.env_threads >= 0, "ppo.env_threads must be >= 0 (0 = all cores)"),
            (self.ppo.n_steps * self.ppo.n_envs >= self.ppo.batch_size,
             "ppo.batch_size must not exceed ppo.n_steps x ppo.n_envs"),
            (self.checkpoint_every >= 1, "checkpoint_every must be >= 1"),
            (0.0 <= self.holdout_fraction < 1.0, "holdout_fraction must be in [0, 1)"),
            (self.follow in FOLLOW, f"follow must be one of {FOLLOW}"),
            *speed_rules(self.speed_factors, self.speed_categories),
            (self.ppo.learning_rate_decay_steps >= 0 and self.ppo.learning_rate_final >= 0,
             "ppo.learning_rate_decay_steps and ppo.learning_rate_final must be >= 0"),
        )  # fmt: skip

    def stages(self) -> list[tuple[str, StageConfig]]:
        return [("stage1", self.stage1), ("stage2", self.stage2)]

    def total_timesteps(self) -> int:
        return self.stage1.timesteps + self.stage2.timesteps

    def env_config(self, stage: StageConfig, reference: str = "") -> TrackingEnvConfig:
        """The environment settings of one stage (random starts, the stage's termination)."""
        return dataclasses.replace(
            self.env, reference=reference or self.env.reference, random_start=True,
            termination_dist_m=stage.termination_dist_m, fall_height_m=stage.fall_height_m,
            fall_below_reference_m=stage.fall_below_reference_m,
            termination_root_gap_m=stage.termination_root_gap_m,
            max_episode_frames=stage.max_episode_frames, amp_window=self.amp.window,
        )  # fmt: skip


REMOVED_IN = "42da3e6"
"""The last commit with the knobs of :data:`REMOVED_SETTINGS`."""

REMOVED_SETTINGS: tuple[RemovedSetting, ...] = (
    RemovedSetting("amp.from_init", True, "a fresh discriminator on --init", REMOVED_IN),
    RemovedSetting("ppo.fixed_std", False, "a fixed action std (ppo.fixed_std)", REMOVED_IN),
    RemovedSetting("ppo.target_kl", 0.0, "PPO's KL early stop (ppo.target_kl)", REMOVED_IN),
    RemovedSetting("reverse_categories", (), "time-reversed reference clips", REMOVED_IN),
    RemovedSetting("push_force_n", 0.0, "random pushes (experiments/random_pushes.py)",
                   REMOVED_IN),
    RemovedSetting("push_every_s", REMOVED_ANY_VALUE, "random pushes", REMOVED_IN),
    RemovedSetting("push_duration_s", REMOVED_ANY_VALUE, "random pushes", REMOVED_IN),
)  # fmt: skip
"""Training settings deleted from :class:`PolicyRunConfig` that configs stored in older policy
files and run folders may hold (:func:`policy_config_from_dict`)."""

REMOVED_KINEMATIC_OBS: tuple[str, ...] = ("OAV_Jhor",)
"""Observation variants deleted from ``grip.task.config.KINEMATIC_OBS`` (in :data:`REMOVED_IN`)."""


def policy_config_from_dict(data: dict, where: str, training: bool = False) -> PolicyRunConfig:
    """The :class:`PolicyRunConfig` of a stored config (a policy file's or a run folder's
    ``config.json``), written by this or an older version.

    Removed training settings (:data:`REMOVED_SETTINGS`) changed how a policy was trained, not
    what it does: reading a file to play it (``training`` false) drops them whatever their
    value. To train on (``training``), one that turned its feature on is refused, and one at
    its "off" value is dropped. A removed observation variant is refused either way.

    Raises:
        ConfigError: Naming ``where``: unknown keys, bad values, or a removed feature.
    """
    env = data.get("env") if isinstance(data, dict) else None
    obs = env.get("kinematic_obs") if isinstance(env, dict) else None
    if obs in REMOVED_KINEMATIC_OBS:
        raise ConfigError(f"{where}: env.kinematic_obs = {obs!r} was removed (commit "
                          f"{REMOVED_IN} has it)")  # fmt: skip
    removed = REMOVED_SETTINGS if training else tuple(
        dataclasses.replace(r, off=REMOVED_ANY_VALUE) for r in REMOVED_SETTINGS)
    return apply_dict(PolicyRunConfig(), drop_removed(data, removed, where), where)
