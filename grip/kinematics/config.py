"""Settings of a KinematicsNet training run (written to its ``config.json`` and checkpoints).

:class:`KinematicsRunConfig` holds the sensor features, the network size and the optimisation
settings (:class:`TrainConfig`); ``configs/kinematics/*.toml`` override its defaults. Training
(:mod:`grip.kinematics.train`) and inference (:mod:`grip.kinematics.inference`) both read it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from grip.config import REMOVED_ANY_VALUE, RemovedSetting, drop_removed
from grip.core.checks import check
from grip.kinematics.features import FeatureConfig
from grip.kinematics.model import STAGES, KinematicsNetConfig

VAL_SOURCES: tuple[str, ...] = ("test", "holdout", "fold")


@dataclass(frozen=True)
class TrainConfig:
    """Optimisation settings (GRIP: Adam, batch 256, 100 Hz).

    Attributes:
        window_frames: Frames per training window.
        batch_size: Windows per step.
        steps_per_epoch: Optimiser steps per epoch.
        stage_epochs: Epochs per stage in the stage-wise phase (LP, then FP, FA, LV).
        joint_epochs: Epochs of joint training of all stages.
        lr: Adam learning rate.
        weight_decay: Decoupled weight decay (AdamW); 0 keeps plain Adam.
        grad_clip: Gradient-norm clip.
        fk_loss_weight: Weight of the forward-kinematics joint-position loss on FA's rotations.
        acc_noise: Std of Gaussian noise added to normalised acceleration features.
        ori_noise_rad: Std of random rotation noise (rad) applied to IMU orientations.
        yaw_augment: Rotate each window about the vertical axis by a random angle.
        mirror_augment: Mirror half of the windows left-right
            (:func:`grip.nn.symmetry.mirror_batch`); needs a
            sensor set that is its own mirror image (every left site with its right partner).
        lr_final: Learning rate at the end of the joint phase, reached by a cosine decay from
            ``lr`` over that phase (``None``: constant ``lr``). The stage-wise phases use ``lr``.
        val_windows: Validation windows (fixed draw) evaluated after every epoch.
        val_source: Where the validation windows (and so ``best.pt``) come from: ``"test"``,
            the dataset's test split (the runs of the shipped models), or ``"holdout"``, a
            fraction ``val_fraction`` of the training clips held out of training
            (:func:`grip.kinematics.dataset.holdout_split`; whole people in a folder split by
            person), so that the test split stays unseen by model selection; or ``"fold"``,
            fold ``fold`` of a ``folds``-fold split of the training people
            (:func:`grip.kinematics.dataset.fold_split`): a fold model, one of the K whose
            estimates of each training clip come from the model that never saw its person
            (``grip policy train --kin FOLD0 --kin FOLD1 ...``, docs/pace.md).
        val_fraction: Share of the training clips held out with ``val_source = "holdout"``.
        folds: Number of folds of ``val_source = "fold"``.
        fold: The fold held out with ``val_source = "fold"`` (``0 .. folds - 1``).
        seed: Seed of windows, noise and initialisation.
        standing_init: Share of the training windows whose LSTMs start from the standing rest
            pose at the heading of the foot IMUs (no ground truth, as ``--init standing`` and
            recordings without ground truth start) instead of the first frame's ground truth.
        source_balance: Even out the sources of the training windows
            (:func:`grip.kinematics.dataset.source_weights`): 0 draws frames uniformly (in the
            whole shared corpus Bandai Namco dataset-2's locomotion is 76 % of them), 0.5 gives
            each source a share in proportion to the square root of its frames, 1 the same share.
        category_balance: The same for the motion categories
            (:func:`grip.kinematics.dataset.training_weights`): 0 draws frames uniformly
            (walking and running are most of them), 0.5 gives each category a share in
            proportion to the square root of its frames; multiplies with ``source_balance``.
        first_frame_share: Share of the training windows that start at their sequence's
            first frame (a clip's first sequence: the mover setting off, as the walks of the
            test split by person start) instead of anywhere in it
            (:func:`grip.kinematics.dataset.sample_windows`).
        bf16: Run the network's forward (and so its backward) pass under bfloat16 autocast
            (weights, losses and the optimiser stay float32). On a CPU with AMX or
            AVX512-BF16 the LSTMs run several times faster
            (``benchmarks/kinematics_train_step.py --bf16``); elsewhere it may be slower.
            Inference stays float32.
    """

    window_frames: int = 200
    batch_size: int = 64
    steps_per_epoch: int = 200
    stage_epochs: int = 2
    joint_epochs: int = 10
    lr: float = 1e-3
    weight_decay: float = 0.0
    grad_clip: float = 1.0
    fk_loss_weight: float = 1.0
    acc_noise: float = 0.05
    ori_noise_rad: float = 0.02
    yaw_augment: bool = True
    mirror_augment: bool = False
    lr_final: float | None = None
    val_windows: int = 256
    val_source: str = "test"
    val_fraction: float = 0.1
    folds: int = 2
    fold: int = 0
    seed: int = 0
    bf16: bool = False
    standing_init: float = 0.25
    source_balance: float = 0.0
    category_balance: float = 0.0
    first_frame_share: float = 0.0

    def __post_init__(self) -> None:
        check(
            self,
            (0.0 <= self.source_balance <= 1.0,
             f"train.source_balance must be in [0, 1], got {self.source_balance}"),
            (0.0 <= self.category_balance <= 1.0,
             f"train.category_balance must be in [0, 1], got {self.category_balance}"),
            (0.0 <= self.first_frame_share <= 1.0,
             f"train.first_frame_share must be in [0, 1], got {self.first_frame_share}"),
            (0.0 <= self.standing_init <= 1.0,
             f"train.standing_init must be in [0, 1], got {self.standing_init}"),
            (self.val_source in VAL_SOURCES, f"train.val_source must be one of "
             f"{list(VAL_SOURCES)}, got {self.val_source!r}"),
            (0.0 < self.val_fraction < 1.0,
             f"train.val_fraction must be in (0, 1), got {self.val_fraction}"),
            (self.folds >= 2 and 0 <= self.fold < self.folds,
             f"train.folds must be >= 2 and train.fold in [0, folds), got {self.folds} and "
             f"{self.fold}"),
        )  # fmt: skip


@dataclass(frozen=True)
class KinematicsRunConfig:
    """Everything a training run needs (written to ``config.json``).

    ``dropout`` is applied to every stage's LSTM input in training (PIP: 0.4 on its nets' inputs).
    """

    features: FeatureConfig = field(default_factory=FeatureConfig)
    hidden: int = 192
    layers: int = 2
    init_hidden: int = 256
    dropout: float = 0.0
    train: TrainConfig = field(default_factory=TrainConfig)

    def net_config(self) -> KinematicsNetConfig:
        return KinematicsNetConfig(n_inputs=self.features.n_features, hidden=self.hidden,
                                   layers=self.layers, init_hidden=self.init_hidden,
                                   dropout=self.dropout)  # fmt: skip

    def same_network(self, other: KinematicsRunConfig) -> bool:
        """Whether ``other``'s weights fit this network (dropout, which has none, may differ)."""
        mine, theirs = self.net_config(), other.net_config()
        return dataclasses.replace(mine, dropout=0.0) == dataclasses.replace(theirs, dropout=0.0)

    def phases(self) -> list[tuple[str, int]]:
        """``(phase, epochs)``: one phase per stage, then ``"joint"``."""
        return [(s, self.train.stage_epochs) for s in STAGES] + [("joint", self.train.joint_epochs)]

    def total_epochs(self) -> int:
        return sum(n for _, n in self.phases())


REMOVED_IN = "42da3e6"
"""The last commit with the knobs of :data:`REMOVED_SETTINGS`."""

REMOVED_SETTINGS: tuple[RemovedSetting, ...] = (
    RemovedSetting("train.time_warp", 0.0, "time-warp augmentation", REMOVED_IN),
    RemovedSetting("train.reverse_categories", (), "time-reversed training clips", REMOVED_IN),
    RemovedSetting("train.speed_augment", 0.0, "speed augmentation", "b92f8c9"),
)
"""Training settings deleted from :class:`TrainConfig` that older checkpoints may hold."""


def run_config_from_dict(d: dict, where: str = "config", training: bool = False,
                         ) -> KinematicsRunConfig:  # fmt: skip
    """Inverse of ``asdict`` for :class:`KinematicsRunConfig` (unknown keys are errors), for
    configs written by this or an older version.

    Removed training settings (:data:`REMOVED_SETTINGS`) changed how a network was trained,
    not what it does: reading a checkpoint to run it (``training`` false) drops them whatever
    their value (a fine-tuning's ``--init`` takes only weights); to resume (``training``), one
    that turned its feature on is refused, one at its "off" value is dropped.

    Raises:
        ConfigError: Naming ``where`` and the removed feature that ``d`` turned on.
    """
    removed = REMOVED_SETTINGS if training else tuple(
        dataclasses.replace(r, off=REMOVED_ANY_VALUE) for r in REMOVED_SETTINGS)
    d = drop_removed(dict(d), removed, where)
    feats = dict(d.pop("features", {}))
    if "sites" in feats:
        feats["sites"] = tuple(feats["sites"])
    train = TrainConfig(**d.pop("train", {}))
    return KinematicsRunConfig(features=FeatureConfig(**feats), train=train, **d)


def replace_train(cfg: KinematicsRunConfig, **kw) -> KinematicsRunConfig:
    """Copy of ``cfg`` with some :class:`TrainConfig` fields replaced."""
    return dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, **kw))
