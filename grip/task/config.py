"""Settings of the tracking environment (frozen dataclasses; TOML files hold overrides only)."""

from __future__ import annotations

from dataclasses import dataclass, field

from grip.core.checks import check
from grip.core.mjcf import MjcfConfig

KINEMATIC_OBS: tuple[str, ...] = ("OA", "OAV", "OAV_Jglo", "OAV_Jrel", "OAV_Jrel_root")
"""State-difference variants of GRIP Table 4: D(O,A), D(O,A,V), D(O,A,V,J_glo), D(O,A,V,J_rel),
and D(O,A,V,J_rel) with the followed pelvis relative to the simulated one (not GRIP's: the
distance already lost to the estimate, which no velocity difference shows; docs/pace.md)."""

ACTION_MODES: tuple[str, ...] = ("relative", "absolute")
REWARD_FORMS: tuple[str, ...] = ("mean_sq", "norm")
TERRAINS: tuple[str, ...] = ("auto", "flat", "boxes", "stairs", "chair")
TEACHER_ROOTS: tuple[str, ...] = ("truth", "estimate")


@dataclass(frozen=True)
class RewardWeights:
    """Weight of each raw reward term; the term, its weight and its ``info`` key share a name.

    The defaults are GRIP's eq. 7 (0.5 r_amp + 0.5 r_imit + r_energy) with PHC's imitation
    weights (w_p, w_theta, w_v, w_omega = 0.5, 0.3, 0.1, 0.1) folded in.
    """

    imit_pos: float = 0.25  # 0.5 x w_p
    imit_rot: float = 0.15  # 0.5 x w_theta
    imit_vel: float = 0.05  # 0.5 x w_v
    imit_angvel: float = 0.05  # 0.5 x w_omega
    root_vel: float = 0.0  # not GRIP's: see RewardConfig.k_root_vel (0 = logged only)
    root_pos: float = 0.0  # not GRIP's: see RewardConfig.k_root_pos (0 = logged only)
    energy: float = -0.0005  # -alpha (GRIP eq. 9); the raw term is the mechanical power, W
    amp: float = 0.5  # the AMP term is 0 until a wrapper fills it (policies)


@dataclass(frozen=True)
class RewardConfig:
    """Imitation kernels (GRIP supplement eq. 8) and the energy penalty (eq. 9).

    Attributes:
        k_pos: Position kernel coefficient (1/m^2 with ``mean_sq``, 1/m with ``norm``).
        k_rot: Rotation kernel coefficient (1/rad^2 or 1/rad).
        k_vel: Linear-velocity kernel coefficient.
        k_angvel: Angular-velocity kernel coefficient.
        form: ``"mean_sq"``: exp(-k * mean over joints of the squared error) (PHC's code);
            ``"norm"``: exp(-k * norm of the stacked error) (GRIP's equation as printed).
        k_root_vel: Kernel coefficient of the ``root_vel`` term, 1/(m/s)^2: the horizontal
            pelvis velocity averaged over ``root_vel_window_frames`` against the ground
            truth's (:func:`envs.rewards.root_velocity_term`). Not one of GRIP's terms: with
            ``align_root_xy`` nothing else asks the body to cover the reference's ground.
        k_root_pos: Kernel coefficient of the ``root_pos`` term, 1/m^2: the horizontal distance
            between the simulated pelvis and the pelvis it follows (the estimate's integrated
            root from where the episode started; the truth's for a teacher)
            (:func:`envs.rewards.root_position_term`): 4 keeps 0.91 at 0.15 m, 0.37 at 0.5 m
            and still has slope at 1 m, where the imitation kernels (100/m^2) are flat.
        root_vel_window_frames: Frames of that average. Right after a reset or a teleport the
            window holds fewer frames and its displacement is still divided by the full
            window's length (a few millimetres over one frame are not read as a velocity).
        energy_skip_frames: The energy term is 0 for this many steps after a reset (GRIP).
        weights: Weight of each term.
    """

    k_pos: float = 100.0
    k_rot: float = 100.0
    k_vel: float = 10.0
    k_angvel: float = 0.1
    form: str = "mean_sq"
    k_root_vel: float = 10.0
    k_root_pos: float = 4.0
    root_vel_window_frames: int = 30
    energy_skip_frames: int = 3
    weights: RewardWeights = field(default_factory=RewardWeights)


@dataclass(frozen=True)
class TrackingEnvConfig:
    """Everything :class:`envs.tracking_env.GripTrackingEnv` needs.

    Attributes:
        reference: Reference-set file (``grip data reference``); empty = the bundled sample.
        substeps: Physics steps per control step (control rate = 1 / (substeps x timestep)).
        action_mode: ``"relative"``: PD target = the KinematicsNet pose of the next frame plus
            the action times ``action_scale`` x half the hinge range (an untrained policy
            already follows the estimate); ``"absolute"``: the action in [-1, 1] spans the
            hinge range.
        action_scale: Fraction of the half range that a relative action of 1 moves the target.
        velocity_feedforward: In relative mode, add ``kd/kp`` x the reference hinge velocity to
            the target, so that MuJoCo's ``kp (target - q) - kd qdot`` becomes
            ``kp (q_ref - q) + kd (qdot_ref - qdot)``: without it a PD servo lags a moving
            reference by ``kd/kp`` seconds (0.1 s here), 10 cm at the feet of a walk.
        kinematic_obs: State-difference variant (:data:`KINEMATIC_OBS`, GRIP Table 4).
        heightmap_size: Samples per side of the height map.
        heightmap_extent_m: Side of the square the height map covers, m.
        terrain: ``"auto"`` (a clip's scene objects, else flat), or a fixed scene for all clips.
        heightfield_cell_m: Resolution of the terrain height field, m.
        termination_dist_m: End an episode when any joint is farther than this from the ground
            truth, m (GRIP stage 1: 0.25); 0 turns early termination off (stage 2).
        fall_height_m: End an episode when the pelvis is below this height, m (0 = never).
        fall_below_reference_m: With ``fall_height_m``: a pelvis below that height ends the
            episode only when it is also this far below the ground truth's pelvis, m (0: always).
            A clip that lies, crawls or rolls on the floor keeps its pelvis below 0.3 m; the
            absolute rule ended every such episode at its first step (the teacher's stage 2:
            failure rate 1.00 on "floor").
        termination_root_gap_m: End an episode when the simulated pelvis is farther than this,
            horizontally, from the pelvis it follows (the integrated root of the reference the
            reward's ``root_pos`` term compares with: the estimate's, or the truth's for a
            teacher), m; 0 = off. Unlike ``termination_dist_m`` with ``align_root_xy`` (the pose
            only), it ends an episode that falls behind or strays sideways: PHC's world-frame
            termination, which makes keeping the reference's pace worth the whole future
            reward (docs/pace.md § Q2).
        root_speed_range: ``(lo, hi)``: each episode's followed root is carried over the ground
            ``f`` times as fast, ``f`` drawn uniformly from the range at every reset, while the
            pose, the sensors and the truth's pose stay: the integrated root's horizontal
            displacement from the episode's start and every velocity joint's horizontal
            velocity change by the pelvis' (:func:`grip.task.observations.scale_root_speed`),
            and the reward's root-velocity term compares with the truth's root displacement
            times ``f``. A controller trained on references whose root always agrees with the
            gait reads its pace from the pose and ignores the root (docs/pace.md § root speed);
            decorrelating the two makes covering the followed root's ground worth reading it.
        lean_range_deg: ``(lo, hi)``: each episode's followed upper body leans ``d`` degrees
            forward (negative: back) about the pelvis, across the estimated pelvis' facing
            direction, ``d`` drawn uniformly from the range at every reset, in the observation
            (:func:`grip.task.observations.lean_rows`) and in a relative action's PD target (the
            spine's hinges, :func:`grip.task.observations.lean_hinges`), while the truth the
            reward compares with and the followed root stay: the estimated trunk's lean sets the
            humanoid's pace (docs/pace.md § The trunk's lean), and an estimate's trunk leans a
            few degrees off the walker's; trained so, the pace is paid whatever the lean
            (docs/pace.md, hypothesis 12 b). Not with ``teacher_obs``.
            ``(1, 1)`` (the default): off.
        align_root_xy: Compare joint positions with the ground truth (imitation reward and
            termination) after shifting the simulated body horizontally so that its pelvis is
            over the ground truth's. The policy follows a root integrated from the estimated
            pelvis velocity, which drifts from the truth (median 0.20 m over 3 s on the training
            split); the controller cannot see, let alone fix, that drift. Heights, the pose and
            all velocities are still compared as they are. Off: GRIP's world-frame comparison.
        random_start: Reference state initialisation: start at a random frame of a random clip
            (training). Off: play one clip from its first frame (inference).
        clip_index: Play this clip (>= 0) instead of sampling one.
        max_episode_frames: Truncate episodes after this many steps (0: run to the clip's end).
        min_episode_frames: Random starts leave at least this many frames to play.
        amp_window: AMP frames in ``info["amp_obs"]`` (the discriminator's input, see
            :mod:`grip.task.amp`); 0 leaves it out.
        action_repeat: The controller's decision period in frames: a policy action is held for
            this many frames (the environment itself always advances one frame per step; the
            training wrapper :class:`envs.wrappers.ActionRepeat` and the inference loop
            :class:`grip.pipeline.Player` hold it). 1 = a decision every frame.
        blowup_lin_vel_mps: Pelvis speed above which the state counts as a simulation blow-up,
            m/s: a sprint is 10, a 10 m free fall ends at 14; the bundled clips under any action
            (zeros, -1, +1, random, bang-bang) stay below 5.
        blowup_ang_vel_radps: Angular speed of any joint (hinges and pelvis) above which the state
            counts as a blow-up, rad/s: the fastest human joint motion (a baseball pitch's shoulder
            rotation) reaches ~120; the bundled clips under any action stay below 30.
        blowup_height_m: The state counts as a blow-up when the pelvis is more than this above
            the highest terrain point, m (a jump lifts the pelvis ~1 m above standing).
        blowup_depth_m: ... or more than this below the floor (z = 0; the terrain is never
            lower), m: the body fell through the floor.
        pin_root: Drive the pelvis along the ground-truth root trajectory (position and
            orientation written before every substep): a physics check of the PD tracking, not
            a training mode.
        teacher_obs: Add the inputs of a privileged teacher to every observation (``grip policy
            distill`` from a policy trained with ``follow = "truth"``): ``teacher_kinematic``,
            the kinematic observation against the ground truth (as the teacher saw it in
            training), and ``teacher_shift`` (69), the relative action that moves the PD target
            from the estimate's to the truth's (a teacher action ``a`` is the student action
            ``a + teacher_shift``). Not a training setting: policies never see these keys.
        sensor_context: With ``W >= 2`` add the observation part ``sensor_context`` ``(2F)``:
            each sensor feature's mean and standard deviation over the clip's last ``W`` frames
            up to the observed one (:func:`grip.task.observations.sensor_context_at`), what a
            gate with context reads (:class:`policies.gate.GatedController` sets it from its
            gate); 0: off. Not a training setting: policies never see this key.
        teacher_root: With ``teacher_obs``: the pelvis position ``teacher_kinematic`` follows,
            ``"truth"`` (the truth's integrated root, as the teacher saw in training) or
            ``"estimate"`` (the root the student follows, the estimate's integrated one, with
            the truth's pose over it): the teacher then steers toward the pelvis the student is
            judged by, so its labels agree with what the student sees (only the pelvis gap of
            ``OAV_Jrel_root`` and the offsets of ``OAV_Jglo`` read it).
        mjcf: Humanoid and simulation options.
        reward: Reward settings.
    """

    reference: str = ""
    substeps: int = 2
    action_mode: str = "relative"
    action_scale: float = 0.5
    velocity_feedforward: bool = True
    kinematic_obs: str = "OAV_Jrel"
    heightmap_size: int = 25
    heightmap_extent_m: float = 1.5
    terrain: str = "auto"
    heightfield_cell_m: float = 0.02
    termination_dist_m: float = 0.25
    fall_height_m: float = 0.0
    fall_below_reference_m: float = 0.0
    termination_root_gap_m: float = 0.0
    root_speed_range: tuple[float, float] = (1.0, 1.0)
    lean_range_deg: tuple[float, float] = (0.0, 0.0)
    align_root_xy: bool = True
    random_start: bool = True
    clip_index: int = -1
    max_episode_frames: int = 0
    min_episode_frames: int = 10
    pin_root: bool = False
    blowup_lin_vel_mps: float = 50.0
    blowup_ang_vel_radps: float = 200.0
    blowup_height_m: float = 4.0
    blowup_depth_m: float = 1.0
    action_repeat: int = 1
    amp_window: int = 10
    teacher_obs: bool = False
    teacher_root: str = "truth"
    sensor_context: int = 0
    mjcf: MjcfConfig = field(default_factory=MjcfConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)

    def __post_init__(self) -> None:
        check(
            self,
            (self.action_mode in ACTION_MODES, f"action_mode must be one of {ACTION_MODES}"),
            (self.kinematic_obs in KINEMATIC_OBS, f"kinematic_obs must be one of {KINEMATIC_OBS}"),
            (self.reward.form in REWARD_FORMS, f"reward.form must be one of {REWARD_FORMS}"),
            (self.terrain in TERRAINS, f"terrain must be one of {TERRAINS}"),
            (self.substeps >= 1, "substeps must be >= 1"),
            (self.reward.root_vel_window_frames >= 1, "reward.root_vel_window_frames must be >= 1"),
            (self.action_repeat >= 1, "action_repeat must be >= 1"),
            (self.heightmap_size >= 1, "heightmap_size must be >= 1"),
            (self.min_episode_frames >= 1, "min_episode_frames must be >= 1"),
            (self.amp_window >= 0, "amp_window must be >= 0 (0 = no AMP observation)"),
            (self.termination_dist_m >= 0, "termination_dist_m must be >= 0 (0 = off)"),
            (self.fall_below_reference_m >= 0, "fall_below_reference_m must be >= 0 (0 = off)"),
            (self.termination_root_gap_m >= 0, "termination_root_gap_m must be >= 0 (0 = off)"),
            (len(self.root_speed_range) == 2
             and 0.5 <= self.root_speed_range[0] <= self.root_speed_range[1] <= 2.0,
             f"root_speed_range must be (lo, hi) with 0.5 <= lo <= hi <= 2, got "
             f"{self.root_speed_range}"),
            (len(self.lean_range_deg) == 2
             and -15.0 <= self.lean_range_deg[0] <= self.lean_range_deg[1] <= 15.0,
             f"lean_range_deg must be (lo, hi) with -15 <= lo <= hi <= 15, got "
             f"{self.lean_range_deg}"),
            (not self.teacher_obs or tuple(self.lean_range_deg) == (0.0, 0.0),
             "lean_range_deg leans the estimate a student follows: not with teacher_obs"),
            (self.sensor_context == 0 or self.sensor_context >= 2,
             "sensor_context must be 0 (off) or a window of >= 2 frames"),
            (self.teacher_root in TEACHER_ROOTS, f"teacher_root must be one of {TEACHER_ROOTS}"),
            (min(self.blowup_lin_vel_mps, self.blowup_ang_vel_radps, self.blowup_height_m,
                 self.blowup_depth_m) > 0, "the blowup_* bounds must be > 0"),
        )

    @property
    def control_dt_s(self) -> float:
        return self.substeps * self.mjcf.timestep_s
