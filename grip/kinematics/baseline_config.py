"""Settings of the TransPose and PIP kinematics baselines (:mod:`grip.kinematics.baselines`):
network sizes, training, run configurations, their JSON form and the input columns."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import asdict, dataclass, field

import numpy as np

from grip.config import ConfigError, apply_dict
from grip.core.checks import check
from grip.core.limits import active_limits, safe_json_loads
from grip.kinematics.features import DEFAULT_SITES, FeatureConfig

METHODS: tuple[str, ...] = ("transpose", "pip")
_IMU_FEATURES = 15  # per site in input_features: acc 3, angular velocity 3, orientation 9
_INSOLE_FEATURES = 10


# ---------------------------------------------------------------------------- configs
@dataclass(frozen=True)
class TransPoseConfig:
    """TP-4 network sizes and training noise (TransPose Tab. 7 and code).

    Attributes:
        insoles: "+I" variant: append the 10 insole values to every net's input.
        s1_width: LSTM width of Pose-S1 (leaf joints).
        s2_width: LSTM width of Pose-S2 (all joints).
        s3_width: LSTM width of Pose-S3 (rotations).
        b1_width: LSTM width of Trans-B1 (contacts).
        b2_width: LSTM width of Trans-B2 (root velocity; unidirectional).
        layers: LSTM layers per net.
        dropout: Dropout on each net's input.
        s2_noise_m: Std of the noise on S2's ground-truth leaf input during training, m.
        s3_noise_m: Std of the noise on S3's ground-truth joint input, m.
        b1_noise_m: Std of the noise on B1's ground-truth leaf input, m.
        b2_noise_m: Std of the noise on B2's ground-truth joint input, m.
        vel_scale: B2 outputs root velocity (m/s) divided by this.
        b2_flight_windows_only: Train B2 only on windows with a frame without foot contact.
        online_past_frames: Past frames of the online sliding window (20 at 60 Hz).
        online_future_frames: Future frames of the online sliding window (5 at 60 Hz).
    """

    insoles: bool = False
    s1_width: int = 256
    s2_width: int = 64
    s3_width: int = 128
    b1_width: int = 64
    b2_width: int = 256
    layers: int = 2
    dropout: float = 0.2
    s2_noise_m: float = 0.04
    s3_noise_m: float = 0.025
    b1_noise_m: float = 0.04
    b2_noise_m: float = 0.025
    vel_scale: float = 3.0
    b2_flight_windows_only: bool = True
    online_past_frames: int = 33
    online_future_frames: int = 8

    def __post_init__(self) -> None:
        check(
            self,
            _sizes_rule(self, ("s1_width", "s2_width", "s3_width", "b1_width", "b2_width",
                               "layers")),
            (self.online_past_frames >= 0 and self.online_future_frames >= 0,
             "online window frames must be >= 0"),
        )  # fmt: skip


@dataclass(frozen=True)
class PipNetConfig:
    """PIP-4 kinematics network sizes (PIP supp. and code).

    Attributes:
        insoles: "+I" variant: append the 10 insole values to every net's input.
        width: LSTM width of P_L, P_A, R_A and V_A.
        contact_width: LSTM width of C_F (code: 64; the paper says 256).
        layers: LSTM layers per net.
        dropout: Dropout on each net's input.
        learned_init: Initialise P_L and V_A from the first frame (off: zero states, the
            "w/o learning-init" ablation of PIP Tab. 2).
        init_leaf_frame: First-frame leaf positions fed to P_L's initialiser: ``"root"`` (in the
            root frame, i.e. the pose with the root rotation set to identity, as PIP) or
            ``"world"`` (world axes, the frame of P_L's output).
        leaf_noise_m: Std of the noise on P_A's ground-truth leaf input during training, m.
        joint_noise_m: Std of the noise on the ground-truth joint input of R_A, V_A, C_F, m.
        vel_scale: V_A outputs joint velocities (m/s, root frame) divided by this.
    """

    insoles: bool = False
    width: int = 256
    contact_width: int = 64
    layers: int = 2
    dropout: float = 0.4
    learned_init: bool = True
    init_leaf_frame: str = "root"
    leaf_noise_m: float = 0.04
    joint_noise_m: float = 0.025
    vel_scale: float = 3.0

    def __post_init__(self) -> None:
        check(
            self,
            _sizes_rule(self, ("width", "contact_width", "layers")),
            (self.init_leaf_frame in ("root", "world"),
             f"init_leaf_frame must be 'root' or 'world', got {self.init_leaf_frame!r}"),
        )  # fmt: skip


@dataclass(frozen=True)
class BaselineTrainConfig:
    """Optimisation settings (both papers: Adam, lr 1e-3, batch 256).

    Attributes:
        window_frames: Frames per training window (TransPose B2: 300 at 60 Hz = 500 at 100 Hz;
            PIP: 200 at 60 Hz = 333 at 100 Hz).
        batch_size: Windows per step.
        steps_per_epoch: Optimiser steps per epoch (a checkpoint after each epoch).
        epochs: Epochs of the run.
        lr: Adam learning rate.
        grad_clip: Gradient-norm clip, per net.
        yaw_augment: Rotate each window about the vertical axis by a random angle.
        contact_labels: Ground-truth foot contact: ``"insole"`` (front or back insole contact)
            or ``"motion"`` (foot joint slower than ``contact_speed_mps``, TransPose's rule).
        contact_speed_mps: Speed threshold of the motion rule (0.008 m/frame at 60 Hz).
        cumulative_blocks: Block lengths (frames) of the cumulative velocity loss.
        val_windows: Validation windows (fixed draw from the test split) after every epoch.
        seed: Seed of windows, augmentation, noise and initialisation.
    """

    window_frames: int = 333
    batch_size: int = 256
    steps_per_epoch: int = 100
    epochs: int = 20
    lr: float = 1e-3
    grad_clip: float = 1.0
    yaw_augment: bool = True
    contact_labels: str = "insole"
    contact_speed_mps: float = 0.48
    cumulative_blocks: tuple[int, ...] = (1, 3, 9, 27)
    val_windows: int = 64
    seed: int = 0

    def __post_init__(self) -> None:
        check(
            self,
            _sizes_rule(self, ("window_frames", "batch_size", "steps_per_epoch", "val_windows")),
            (self.epochs >= 0, f"epochs must be >= 0, got {self.epochs}"),
            (self.contact_labels in ("insole", "motion"),
             f"contact_labels must be 'insole' or 'motion', got {self.contact_labels!r}"),
            (bool(self.cumulative_blocks) and min(self.cumulative_blocks) >= 1,
             f"cumulative_blocks: need block lengths >= 1, got {self.cumulative_blocks}"),
        )  # fmt: skip


@dataclass(frozen=True)
class TransPoseRunConfig:
    """Everything a TP-4 training run needs (written to ``config.json`` and checkpoints)."""

    net: TransPoseConfig = field(default_factory=TransPoseConfig)
    train: BaselineTrainConfig = field(
        default_factory=lambda: BaselineTrainConfig(window_frames=500)
    )
    sites: tuple[str, ...] = DEFAULT_SITES
    use_filtered_acc: bool = True

    method = "transpose"  # not a field: fixed per class


@dataclass(frozen=True)
class PipRunConfig:
    """Everything a PIP-4 training run needs (written to ``config.json`` and checkpoints)."""

    net: PipNetConfig = field(default_factory=PipNetConfig)
    train: BaselineTrainConfig = field(default_factory=BaselineTrainConfig)
    sites: tuple[str, ...] = DEFAULT_SITES
    use_filtered_acc: bool = True

    method = "pip"


RunConfig = TransPoseRunConfig | PipRunConfig


def _sizes_rule(cfg, names: tuple[str, ...]) -> tuple[bool, str]:
    """The rule of :func:`grip.core.checks.check` that the sizes ``names`` of ``cfg`` are >= 1."""
    bad = [f"{n}={getattr(cfg, n)}" for n in names if getattr(cfg, n) < 1]
    return not bad, f"must be >= 1: {', '.join(bad)}"


def default_run_config(method: str) -> RunConfig:
    """The default run configuration of ``method`` ("transpose" or "pip").

    Raises:
        ValueError: Unknown method (the message lists the known ones).
    """
    if method == "transpose":
        return TransPoseRunConfig()
    if method == "pip":
        return PipRunConfig()
    raise ValueError(f"unknown baseline {method!r}; choose from {', '.join(METHODS)}")


def config_to_json(cfg: RunConfig) -> str:
    """JSON of a run configuration with its method name (stored in checkpoints)."""
    return json.dumps({"method": cfg.method, **asdict(cfg)})


def config_from_json(text: str, where: str) -> RunConfig:
    """Inverse of :func:`config_to_json`.

    Raises:
        ValueError: Not a baseline configuration, or unknown keys (the message names ``where``).
    """
    try:
        d = safe_json_loads(text, active_limits(), "its config")
    except (TypeError, ValueError) as e:
        raise ValueError(f"{where}: not a TransPose/PIP baseline checkpoint (its config: "
                         f"{str(e)[:200]})") from None  # fmt: skip
    method = d.pop("method", None) if isinstance(d, dict) else None
    if method not in METHODS:
        raise ValueError(f"{where}: not a TransPose/PIP baseline checkpoint (method {method!r})")
    try:
        return apply_dict(default_run_config(method), d, where)
    except ConfigError as e:
        raise ValueError(str(e)) from e


def feature_config(cfg: RunConfig, insoles: bool) -> FeatureConfig:
    """The project's feature settings these baselines read (acc / 30, first-frame alignment)."""
    return FeatureConfig(sites=cfg.sites, insoles=insoles, use_filtered_acc=cfg.use_filtered_acc)


def input_columns(n_sites: int, insoles: bool) -> np.ndarray:
    """Columns of :func:`~grip.kinematics.features.input_features` the baselines use.

    Args:
        n_sites: IMU sites in the feature layout (15 values each, then the insoles).
        insoles: Append the 10 insole columns (the layout must contain them).

    Returns:
        ``(12 * n_sites [+ 10],)`` indices: all accelerations, then all orientations, then the
        insole values (section 2.1's ``[A_t / 30, vec(R_t), I_t]``).
    """
    base = np.arange(n_sites)[:, None] * _IMU_FEATURES
    acc = (base + np.arange(3)).reshape(-1)
    ori = (base + 6 + np.arange(9)).reshape(-1)
    ins = np.arange(_INSOLE_FEATURES) + _IMU_FEATURES * n_sites if insoles else np.arange(0)
    return np.concatenate([acc, ori, ins])


def n_inputs(cfg: RunConfig) -> int:
    """Per-frame input size of the nets (48 / 58 for 4 IMUs without / with insoles)."""
    return len(input_columns(len(cfg.sites), cfg.net.insoles))


def replace_train(cfg: RunConfig, **kw) -> RunConfig:
    """Copy of ``cfg`` with some :class:`BaselineTrainConfig` fields replaced."""
    return dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, **kw))
