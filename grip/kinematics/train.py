"""Training of KinematicsNet: stage-wise, then joint; checkpoints every epoch and resumes.

A run folder holds ``config.json`` (resolved settings, seed, git hash), ``last.pt`` (the latest
checkpoint, replaced atomically after every epoch), ``best.pt`` (lowest validation loss) and
TensorBoard event files. Checkpoints contain only tensors and plain containers, so they load
with ``torch.load(..., weights_only=True)``.
"""

from __future__ import annotations

import dataclasses
import io
import json
import os
import subprocess
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from grip.core import skeleton as sk
from grip.core.atomic import atomic_write, atomic_write_text
from grip.core.loaderrors import describe_load_error
from grip.core.rotations import axis_angle_to_matrix
from grip.kinematics.dataset import (
    TARGET_KEYS,
    Normalizer,
    SequenceArrays,
    category_weights,
    sample_windows,
)
from grip.kinematics.features import FeatureConfig
from grip.kinematics.model import STAGES, KinematicsNet, KinematicsNetConfig

CHECKPOINT_VERSION = 1
VAL_SOURCES: tuple[str, ...] = ("test", "holdout")


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
        mirror_augment: Mirror half of the windows left-right (:func:`mirror_batch`); needs a
            sensor set that is its own mirror image (every left site with its right partner).
        category_balance: Even out the motion categories of the training windows
            (:func:`grip.kinematics.dataset.category_weights`): 0 samples frames uniformly
            (common motions dominate), 1 gives every category the same share.
        time_warp: Play each training window at a random speed ``s``, log-uniform in
            ``[1 / (1 + time_warp), 1 + time_warp]`` (0: off): frames are interpolated
            (:func:`grip.kinematics.dataset.sample_windows`) and the rates rescaled
            (:func:`time_warp_rates`), so the network sees the same motions faster and slower.
        lr_final: Learning rate at the end of the joint phase, reached by a cosine decay from
            ``lr`` over that phase (``None``: constant ``lr``). The stage-wise phases use ``lr``.
        val_windows: Validation windows (fixed draw) evaluated after every epoch.
        val_source: Where the validation windows (and so ``best.pt``) come from: ``"test"``,
            the dataset's test split (the runs of the shipped models), or ``"holdout"``, a
            fraction ``val_fraction`` of the training clips held out of training
            (:func:`grip.kinematics.dataset.holdout_split`), so that the test split stays
            unseen by model selection.
        val_fraction: Share of the training clips held out with ``val_source = "holdout"``.
        reverse_categories: Category globs (e.g. ``["walk"]``) of training clips whose
            motions, played backwards, join the training sequences as ``"<category>-reversed"``
            (:mod:`grip.dataset.augment`: a forward walk played backwards is a backward walk,
            its sensors synthesised as the dataset's); held-out clips do not contribute. Needs
            a ``grip data build`` folder. Empty: none.
        seed: Seed of windows, noise and initialisation.
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
    time_warp: float = 0.0
    category_balance: float = 0.0
    lr_final: float | None = None
    val_windows: int = 256
    val_source: str = "test"
    val_fraction: float = 0.1
    reverse_categories: tuple[str, ...] = ()
    seed: int = 0
    bf16: bool = False

    def __post_init__(self) -> None:
        if self.val_source not in VAL_SOURCES:
            raise ValueError(f"train.val_source must be one of {list(VAL_SOURCES)}, "
                             f"got {self.val_source!r}")  # fmt: skip
        if not 0.0 < self.val_fraction < 1.0:
            raise ValueError(f"train.val_fraction must be in (0, 1), got {self.val_fraction}")
        if not 0.0 <= self.category_balance <= 1.0:
            raise ValueError(f"train.category_balance must be in [0, 1], got "
                             f"{self.category_balance}")  # fmt: skip
        if not 0.0 <= self.time_warp <= 1.0:
            raise ValueError(f"train.time_warp must be in [0, 1], got {self.time_warp}")


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


def run_config_from_dict(d: dict) -> KinematicsRunConfig:
    """Inverse of ``asdict`` for :class:`KinematicsRunConfig` (unknown keys are errors)."""
    d = dict(d)
    feats = dict(d.pop("features", {}))
    if "sites" in feats:
        feats["sites"] = tuple(feats["sites"])
    train = TrainConfig(**d.pop("train", {}))
    return KinematicsRunConfig(features=FeatureConfig(**feats), train=train, **d)


def history_wall_s(history: list[dict]) -> float:
    """Seconds of training (epochs with their validation) over every sitting of a run, from its
    history's last ``wall_s``; epochs of checkpoints written before it was recorded count as 0."""
    return float(history[-1].get("wall_s", 0.0)) if history else 0.0


def git_hash() -> str:
    """The repository's commit (``"unknown"`` outside a git checkout)."""
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                             cwd=Path(__file__).resolve().parent, timeout=5)  # fmt: skip
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


# ---------------------------------------------------------------------------- augmentation
def yaw_matrices(angles: torch.Tensor) -> torch.Tensor:
    c, s = torch.cos(angles), torch.sin(angles)
    z, o = torch.zeros_like(c), torch.ones_like(c)
    return torch.stack([c, -s, z, s, c, z, z, z, o], -1).view(*angles.shape, 3, 3)


def rotate_batch(
    x: torch.Tensor, y: dict[str, torch.Tensor], rot: torch.Tensor, n_sites: int
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Rotate raw features and targets of each window by a world rotation ``rot (B, 3, 3)``.

    Accelerations, angular velocities, orientations, leaf/joint positions, 6D global rotations and
    velocities all rotate; insole values do not.
    """
    return rotate_features(x, rot, n_sites), rotate_targets(y, rot)


def rotate_features(x: torch.Tensor, rot: torch.Tensor, n_sites: int) -> torch.Tensor:
    """Raw features ``(B, T, F)`` of ``n_sites`` IMUs (and insoles) seen in a world turned by
    ``rot (B, 3, 3)`` (:func:`rotate_batch`'s rule for the inputs)."""
    b, t, _ = x.shape
    r = rot[:, None]  # (B, 1, 3, 3)
    imu = x[..., : 15 * n_sites].reshape(b, t, n_sites, 15)
    acc = torch.einsum("btij,btsj->btsi", r, imu[..., 0:3])
    gyr = torch.einsum("btij,btsj->btsi", r, imu[..., 3:6])
    ori = (r[:, :, None] @ imu[..., 6:15].reshape(b, t, n_sites, 3, 3)).reshape(b, t, n_sites, 9)
    return torch.cat([torch.cat([acc, gyr, ori], -1).reshape(b, t, -1), x[..., 15 * n_sites :]], -1)


def rotate_targets(y: dict[str, torch.Tensor], rot: torch.Tensor) -> dict[str, torch.Tensor]:
    """Targets or outputs ``{stage: (B, T, dim)}`` in a world turned by ``rot (B, 3, 3)``
    (:func:`rotate_batch`'s rule; other keys pass unchanged)."""
    r = rot[:, None]
    out = {}
    for k, v in y.items():
        b, t = v.shape[:2]
        if k in ("lp", "fp", "lv"):
            out[k] = torch.einsum("btij,btnj->btni", r, v.reshape(b, t, -1, 3)).reshape(b, t, -1)
        elif k == "fa":
            cols = v.reshape(b, t, 24, 2, 3)
            out[k] = torch.einsum("btij,btncj->btnci", r, cols).reshape(b, t, -1)
        else:
            out[k] = v
    return out


def mirror_site_order(sites: tuple[str, ...]) -> list[int]:
    """Index of each site's mirror partner in ``sites`` (``L_X`` <-> ``R_X``; ``Head`` and
    ``Pelvis`` are their own).

    Raises:
        ValueError: A site's partner is not in the set (such a set has no mirror image).
    """
    swap = {"L_": "R_", "R_": "L_"}
    partner = [swap.get(s[:2], s[:2]) + s[2:] for s in sites]
    missing = [p for p in partner if p not in sites]
    if missing:
        raise ValueError(f"mirror_augment needs every site's left/right partner; "
                         f"{list(sites)} lacks {missing}")  # fmt: skip
    return [sites.index(p) for p in partner]


_M = torch.tensor([-1.0, 1.0, 1.0])  # the reflection x -> -x, as a diagonal
_LEAF_MIRROR = [sk.LEAF_JOINTS.index(int(sk.MIRROR[j])) for j in sk.LEAF_JOINTS]
_VEL_MIRROR = [sk.VELOCITY_JOINTS.index(int(sk.MIRROR[j])) for j in sk.VELOCITY_JOINTS]


def mirror_batch(
    x: torch.Tensor, y: dict[str, torch.Tensor], sites: tuple[str, ...], insoles: bool
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Raw features and targets of the left-right mirror image of each window.

    The world is reflected through the plane ``x = 0`` (``M = diag(-1, 1, 1)``; with random yaw
    this covers every vertical mirror plane) and left and right swap: positions, velocities and
    accelerations map to ``M v``, world angular velocities (pseudo-vectors) to ``-M w``,
    rotations and IMU orientations to ``M R M``, the two insoles swap (their CoP is in the
    foot's own forward/medial frame, which the mirror keeps), and the rest offsets of the body
    map to ``M o``. Exact for a mirror-symmetric body with mirror-symmetric sensor mounts.

    Args:
        x: ``(B, T, F)`` raw (unnormalised) features of ``sites`` (and the insoles).
        y: Targets ``lp, fp, fa, lv`` ``(B, T, dim)`` and ``offsets (B, 24, 3)``.

    Raises:
        ValueError: ``sites`` is not closed under the mirror, or ``y`` has an unknown key.
    """
    return mirror_features(x, sites, insoles), mirror_targets(y)


def mirror_features(x: torch.Tensor, sites: tuple[str, ...], insoles: bool) -> torch.Tensor:
    """Raw features ``(B, T, F)`` of the mirror image (:func:`mirror_batch`'s rule for the
    inputs).

    Raises:
        ValueError: ``sites`` is not closed under the mirror.
    """
    order = mirror_site_order(tuple(sites))
    b, t, _ = x.shape
    n = len(sites)
    m = _M.to(x.dtype)
    imu = x[..., : 15 * n].reshape(b, t, n, 15)[:, :, order]
    acc = imu[..., 0:3] * m
    gyr = -imu[..., 3:6] * m
    ori = (imu[..., 6:15].reshape(b, t, n, 3, 3) * (m[:, None] * m[None, :])).reshape(b, t, n, 9)
    parts = [torch.cat([acc, gyr, ori], -1).reshape(b, t, -1)]
    if insoles:
        parts.append(x[..., 15 * n : 15 * n + 10].reshape(b, t, 2, 5).flip(2).reshape(b, t, 10))
    return torch.cat(parts, -1)


def mirror_targets(y: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Targets or outputs of the mirror image (:func:`mirror_batch`'s rule): ``lp, fp, fa,
    lv`` as ``(B, T, dim)``, ``offsets`` as ``(B, 24, 3)``. Mirroring twice is the identity.

    Raises:
        ValueError: ``y`` has a key without a mirror rule.
    """
    perm = torch.from_numpy(sk.MIRROR)
    out = {}
    for k, v in y.items():
        m = _M.to(v.dtype)
        if k in ("lp", "fp", "lv"):
            b, t = v.shape[:2]
            idx = {"lp": _LEAF_MIRROR, "fp": perm, "lv": _VEL_MIRROR}[k]
            out[k] = (v.reshape(b, t, -1, 3)[:, :, idx] * m).reshape(b, t, -1)
        elif k == "fa":
            # the columns c0, c1 of R become those of M R M: -M c0, M c1
            b, t = v.shape[:2]
            cols = v.reshape(b, t, 24, 2, 3)[:, :, perm]
            sign = torch.stack([-m, m])
            out[k] = (cols * sign).reshape(b, t, -1)
        elif k == "offsets":
            out[k] = v[:, perm] * m
        else:
            raise ValueError(f"mirror_batch: no mirror rule for target {k!r}")
    return out


def time_warp_rates(x: np.ndarray, y: dict[str, np.ndarray], speeds: np.ndarray, n_sites: int,
                    insoles: bool) -> tuple[np.ndarray, dict[str, np.ndarray]]:  # fmt: skip
    """Rescale the rates of windows resampled at playback ``speeds`` (``sample_windows(...,
    speeds=...)``) to what the sensors would read at that speed.

    A motion played ``s`` times faster has accelerations ``s^2`` and angular and linear
    velocities ``s`` times the original's at the same pose. So the IMUs' free accelerations
    scale by ``s^2``, their angular velocities and the leaf/pelvis velocity targets by ``s``;
    orientations, positions and rotations keep their values. The insoles' total vertical force
    (body weights) is one plus the centre of mass's vertical acceleration over g, so its
    deviation from 1 scales by ``s^2``, shared between the feet as recorded; the CoP keeps its
    value and the contact flags are rounded back to 0/1. The force rule is an approximation
    (it ignores how the stance phases themselves would change); the rest is exact up to the
    interpolation and the recording's low-pass filter.

    Args:
        x: ``(B, T, F)`` raw (unnormalised) features: 15 per IMU site, then 10 insole values.
        y: Targets ``lp, fp, fa, lv`` ``(B, T, dim)`` and ``offsets``.
        speeds: ``(B,)`` playback speeds.

    Raises:
        ValueError: ``y`` has a target without a known rule.
    """
    known = ("lp", "fp", "fa", "lv", "offsets")
    unknown = [k for k in y if k not in known]
    if unknown:
        raise ValueError(f"time_warp_rates: no rule for target(s) {unknown}")
    s = np.asarray(speeds, dtype=np.float64)[:, None, None]
    x = x.copy()
    b, t, _ = x.shape
    imu = x[..., : 15 * n_sites].reshape(b, t, n_sites, 15)
    imu[..., 0:3] *= (s**2)[..., None].astype(x.dtype)
    imu[..., 3:6] *= s[..., None].astype(x.dtype)
    x[..., : 15 * n_sites] = imu.reshape(b, t, -1)
    if insoles:
        ins = x[..., 15 * n_sites : 15 * n_sites + 10].reshape(b, t, 2, 5)
        force = ins[..., 0].astype(np.float64)
        total = force.sum(-1, keepdims=True)
        new_total = np.maximum(1.0 + s**2 * (total - 1.0), 0.0)
        share = np.divide(force, total, out=np.zeros_like(force), where=total > 1e-3)
        ins[..., 0] = np.where(total > 1e-3, share * new_total, force).astype(x.dtype)
        ins[..., 3:5] = np.round(ins[..., 3:5])
        x[..., 15 * n_sites : 15 * n_sites + 10] = ins.reshape(b, t, 10)
    y = dict(y)
    if "lv" in y:
        y["lv"] = (y["lv"] * s).astype(y["lv"].dtype)
    return x, y


def fk_positions(rot6d: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """Root-relative joint positions from global 6D rotations.

    Args:
        rot6d: ``(B, T, 144)`` global rotations (6D: first two columns).
        offsets: ``(B, 24, 3)`` rest offsets.

    Returns:
        ``(B, T, 72)`` positions with the root at the origin.
    """
    b, t, _ = rot6d.shape
    d = rot6d.reshape(b, t, 24, 6)
    a1, a2 = d[..., :3], d[..., 3:]
    c0 = torch.nn.functional.normalize(a1, dim=-1)
    c1 = torch.nn.functional.normalize(a2 - (c0 * a2).sum(-1, keepdim=True) * c0, dim=-1)
    c2 = torch.cross(c0, c1, dim=-1)
    mats = torch.stack([c0, c1, c2], dim=-1)  # (B, T, 24, 3, 3)
    pos = [torch.zeros(b, t, 3, dtype=rot6d.dtype, device=rot6d.device)]
    for j in range(1, 24):
        p = int(sk.PARENTS[j])
        pos.append(pos[p] + torch.einsum("btij,bj->bti", mats[:, :, p], offsets[:, j]))
    return torch.stack(pos, dim=2).reshape(b, t, 72)


# ---------------------------------------------------------------------------- training
def log_epoch(writer, record: dict) -> None:
    """Write an epoch's ``record["train"]`` and ``record["val"]`` losses to TensorBoard
    (``writer``: a ``SummaryWriter`` or ``None``)."""
    if writer is None:
        return
    for part in ("train", "val"):
        for k, v in record[part].items():
            writer.add_scalar(f"{part}/{k}", v, record["epoch"])
    writer.flush()


class Trainer:
    """Owns the model, optimiser, data and the run folder."""

    def __init__(self, cfg: KinematicsRunConfig, train_seqs: list[SequenceArrays],
                 val_seqs: list[SequenceArrays], run_dir: str | os.PathLike) -> None:  # fmt: skip
        if not train_seqs:
            raise ValueError("no training sequences")
        self.cfg = cfg
        self.run_dir = Path(run_dir)
        self.train_seqs = train_seqs
        self.train_weights = (category_weights(train_seqs, cfg.train.category_balance)
                              if cfg.train.category_balance > 0 else None)  # fmt: skip
        self.val_seqs = val_seqs or train_seqs
        torch.manual_seed(cfg.train.seed)
        if cfg.train.mirror_augment:
            mirror_site_order(tuple(cfg.features.sites))  # fails early on a one-sided sensor set
        self.model = KinematicsNet(cfg.net_config())
        if cfg.train.weight_decay > 0:
            self.opt = torch.optim.AdamW(self.model.parameters(), lr=cfg.train.lr,
                                         weight_decay=cfg.train.weight_decay)  # fmt: skip
        else:
            self.opt = torch.optim.Adam(self.model.parameters(), lr=cfg.train.lr)
        self.norm = Normalizer.fit(train_seqs)
        self.rng = np.random.default_rng(cfg.train.seed)
        self.epoch = 0
        self.best_val = float("inf")
        self.history: list[dict] = []
        vx, vy = sample_windows(self.val_seqs, cfg.train.val_windows, cfg.train.window_frames,
                                np.random.default_rng(cfg.train.seed + 1))  # fmt: skip
        self.val_batch = (vx, vy)

    # ------------------------------------------------------------------ batches
    def _tensors(self, x: np.ndarray, y: dict[str, np.ndarray], augment: bool):
        xt = torch.from_numpy(x)
        yt = {k: torch.from_numpy(v) for k, v in y.items()}
        n_sites = len(self.cfg.features.sites)
        if augment and self.cfg.train.mirror_augment:
            xt, yt = self._mirror_half(xt, yt)
        if augment and self.cfg.train.yaw_augment:
            ang = torch.from_numpy(self.rng.uniform(-np.pi, np.pi, x.shape[0]).astype(np.float32))
            xt, yt = rotate_batch(xt, yt, yaw_matrices(ang), n_sites)
        if augment and self.cfg.train.ori_noise_rad > 0:
            noise = self.rng.normal(0, self.cfg.train.ori_noise_rad, (x.shape[0], n_sites, 3))
            dr = torch.from_numpy(axis_angle_to_matrix(noise).astype(np.float32))  # (B, S, 3, 3)
            b, t = xt.shape[:2]
            imu = xt[..., : 15 * n_sites].reshape(b, t, n_sites, 15)
            ori = imu[..., 6:15].reshape(b, t, n_sites, 3, 3) @ dr[:, None]
            imu = torch.cat([imu[..., :6], ori.reshape(b, t, n_sites, 9)], -1)
            xt = torch.cat([imu.reshape(b, t, -1), xt[..., 15 * n_sites :]], -1)
        xt = (xt - torch.from_numpy(self.norm.mean)) / torch.from_numpy(self.norm.std)
        if augment and self.cfg.train.acc_noise > 0:
            idx = torch.tensor([s * 15 + k for s in range(n_sites) for k in range(3)])
            xt[..., idx] += self.cfg.train.acc_noise * torch.from_numpy(
                self.rng.standard_normal((*xt.shape[:2], len(idx))).astype(np.float32)
            )
        return xt, yt

    def _mirror_half(self, xt: torch.Tensor, yt: dict[str, torch.Tensor]):
        """Copies of a batch with a random half of its windows mirrored (:func:`mirror_batch`)."""
        flip = torch.from_numpy(self.rng.random(xt.shape[0]) < 0.5)
        if not flip.any():
            return xt, yt
        feats = self.cfg.features
        xm, ym = mirror_batch(xt[flip], {k: v[flip] for k, v in yt.items()}, feats.sites,
                              feats.insoles)  # fmt: skip
        xt, yt = xt.clone(), {k: v.clone() for k, v in yt.items()}  # the caller's arrays stay
        xt[flip] = xm
        for k, v in yt.items():
            v[flip] = ym[k]
        return xt, yt

    def losses(self, x: torch.Tensor, y: dict[str, torch.Tensor],
               only: str | None = None) -> dict[str, torch.Tensor]:  # fmt: skip
        first = {k: y[k][:, 0] for k in TARGET_KEYS}
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=self.cfg.train.bf16):
            out, _ = self.model(x, self.model.initial_state(first), only=only)
        out = {k: v.float() for k, v in out.items()}
        losses = {k: ((out[k] - y[k]) ** 2).mean() for k in out}
        if "fa" in out and self.cfg.train.fk_loss_weight > 0:
            losses["fk"] = ((fk_positions(out["fa"], y["offsets"]) - y["fp"]) ** 2).mean()
        return losses

    def _total(self, losses: dict[str, torch.Tensor], phase: str) -> torch.Tensor:
        if phase != "joint":
            keys = [phase] + (["fk"] if phase == "fa" else [])
        else:
            keys = list(losses)
        w = {"fk": self.cfg.train.fk_loss_weight}
        return sum(w.get(k, 1.0) * losses[k] for k in keys)

    def validate(self) -> dict[str, float]:
        self.model.eval()
        with torch.no_grad():
            x, y = self._tensors(*self.val_batch, augment=False)
            losses = self.losses(x, y)
        self.model.train()
        out = {k: float(v) for k, v in losses.items()}
        out["total"] = float(sum(out.values()))
        return out

    # ------------------------------------------------------------------ loop
    def phase_of(self, epoch: int) -> str:
        n = 0
        for phase, k in self.cfg.phases():
            n += k
            if epoch < n:
                return phase
        return "joint"

    def learning_rate(self, epoch: int, step: int) -> float:
        """The rate of optimiser step ``step`` of ``epoch``: ``lr``, decayed to ``lr_final`` by
        a half cosine over the joint phase when that is set."""
        tc = self.cfg.train
        start = self.cfg.total_epochs() - tc.joint_epochs
        if tc.lr_final is None or epoch < start or tc.joint_epochs == 0:
            return tc.lr
        done = ((epoch - start) * tc.steps_per_epoch + step) / (
            tc.joint_epochs * tc.steps_per_epoch
        )
        return float(
            tc.lr_final + 0.5 * (tc.lr - tc.lr_final) * (1.0 + np.cos(np.pi * min(done, 1.0)))
        )

    def init_from(self, path: str | os.PathLike) -> None:
        """Start from the weights and normaliser of another checkpoint (a training run's or an
        inference export) with the same network and sensor settings: fine-tuning with this
        run's data and schedule; the optimiser and the epoch count start afresh.

        Raises:
            ValueError: naming the file, when it is unreadable or its network differs.
        """
        ck = load_checkpoint(path)
        theirs = run_config_from_dict(json.loads(ck["config"]))
        if not theirs.same_network(self.cfg) or theirs.features != self.cfg.features:
            raise ValueError(f"{path}: its network or sensor settings differ from this run's "
                             f"({theirs.net_config()}, {theirs.features})")  # fmt: skip
        try:
            self.model.load_state_dict(unpack_weights(ck["model"]))
        except RuntimeError as e:
            raise ValueError(f"{path}: weights do not fit the network ({e})") from e
        self.norm = Normalizer(ck["norm_mean"].numpy(), ck["norm_std"].numpy())

    def train_step(self, phase: str, lr: float, clock: list[float] | None = None):
        """One optimiser step of ``phase`` on a fresh batch of augmented windows at rate ``lr``;
        returns the losses and their weighted total. With ``clock``, the
        ``time.perf_counter()`` after sampling, augmentation, forward pass, backward pass and
        optimiser step is appended (``benchmarks/kinematics_train_step.py``)."""
        tc = self.cfg.train
        tick = clock.append if clock is not None else lambda _t: None
        for group in self.opt.param_groups:
            group["lr"] = lr
        speeds = None
        if tc.time_warp > 0:
            speeds = np.exp(self.rng.uniform(-1.0, 1.0, tc.batch_size) * np.log1p(tc.time_warp))
        x, y = sample_windows(self.train_seqs, tc.batch_size, tc.window_frames, self.rng,
                              speeds=speeds, weights=self.train_weights)  # fmt: skip
        if speeds is not None:
            x, y = time_warp_rates(x, y, speeds, len(self.cfg.features.sites),
                                   self.cfg.features.insoles)  # fmt: skip
        tick(time.perf_counter())
        xt, yt = self._tensors(x, y, augment=True)
        tick(time.perf_counter())
        losses = self.losses(xt, yt, only=None if phase == "joint" else phase)
        total = self._total(losses, phase)
        tick(time.perf_counter())
        self.opt.zero_grad(set_to_none=True)
        total.backward()
        tick(time.perf_counter())
        torch.nn.utils.clip_grad_norm_(self.model.parameters(), tc.grad_clip)
        self.opt.step()
        tick(time.perf_counter())
        return losses, total

    def fit(self, writer=None, progress: Callable[[dict], object] | None = None) -> list[dict]:
        """Train until ``total_epochs``; checkpoints after each epoch (resumes from ``epoch``)."""
        tc = self.cfg.train
        self.model.train()
        while self.epoch < self.cfg.total_epochs():
            t0 = time.perf_counter()
            phase = self.phase_of(self.epoch)
            sums: dict[str, float] = {}
            for step in range(tc.steps_per_epoch):
                losses, total = self.train_step(phase, self.learning_rate(self.epoch, step))
                for k, v in losses.items():
                    sums[k] = sums.get(k, 0.0) + v.item()
                if progress is not None:
                    progress({"phase": phase, "loss": total.item()})
            val = self.validate()
            record = {
                "epoch": self.epoch,
                "phase": phase,
                "train": {k: v / tc.steps_per_epoch for k, v in sums.items()},
                "val": val,
                "wall_s": self.wall_s() + time.perf_counter() - t0,
            }
            self.history.append(record)
            log_epoch(writer, record)
            self.epoch += 1
            if phase == "joint" and val["total"] < self.best_val:
                self.best_val = val["total"]
                self.save(self.run_dir / "best.pt")
            self.save(self.run_dir / "last.pt")
        return self.history

    def wall_s(self) -> float:
        return history_wall_s(self.history)

    # ------------------------------------------------------------------ checkpoints
    def state(self) -> dict:
        return {
            "version": CHECKPOINT_VERSION,
            "config": json.dumps(asdict(self.cfg)),
            "model": self.model.state_dict(),
            "optimizer": self.opt.state_dict(),
            "norm_mean": torch.from_numpy(self.norm.mean),
            "norm_std": torch.from_numpy(self.norm.std),
            "epoch": self.epoch,
            "best_val": self.best_val,
            "rng": json.dumps(self.rng.bit_generator.state),
            "history": json.dumps(self.history),
            "git": git_hash(),
        }

    def save(self, path: Path) -> None:
        buf = io.BytesIO()
        torch.save(self.state(), buf)
        atomic_write(path, lambda f: f.write(buf.getvalue()))

    def load(self, path: Path) -> None:
        """Resume from a checkpoint of the same configuration.

        Only ``train.joint_epochs`` may differ (to extend or shorten a run's last phase), as
        long as the checkpoint is still in the stage-wise phase or within the new length.
        """
        ck = load_checkpoint(path)
        old = json.loads(ck["config"])
        new = json.loads(json.dumps(asdict(self.cfg)))
        old["train"].pop("joint_epochs")
        new["train"].pop("joint_epochs")
        defaults = asdict(KinematicsRunConfig())
        for k in set(new["train"]) - set(old["train"]):  # fields added since the run began
            if new["train"][k] == defaults["train"][k]:
                new["train"].pop(k)
        for k in set(new) - set(old):
            if new[k] == defaults[k]:
                new.pop(k)
        if old != new:
            diff = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
            raise ValueError(f"{path}: checkpoint was trained with another configuration "
                             f"(differs in {', '.join(diff)})")  # fmt: skip
        if int(ck["epoch"]) > self.cfg.total_epochs():
            raise ValueError(f"{path}: checkpoint is at epoch {int(ck['epoch'])}, beyond the "
                             f"{self.cfg.total_epochs()} epochs of this configuration")  # fmt: skip
        self.model.load_state_dict(ck["model"])
        self.opt.load_state_dict(ck["optimizer"])
        self.norm = Normalizer(ck["norm_mean"].numpy(), ck["norm_std"].numpy())
        self.epoch = int(ck["epoch"])
        self.best_val = float(ck["best_val"])
        self.rng.bit_generator.state = json.loads(ck["rng"])
        self.history = json.loads(ck["history"])


def load_checkpoint(path: str | os.PathLike) -> dict:
    """Load a checkpoint safely (``weights_only=True``); errors name the file."""
    path = Path(path)
    try:
        ck = torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise
    except Exception as e:  # torch raises many types for corrupt or hostile files
        raise ValueError(f"{path}: not a KinematicsNet checkpoint: {describe_load_error(e)}") from e
    missing = [k for k in ("version", "config", "model", "norm_mean", "norm_std") if k not in ck]
    if missing:
        raise ValueError(f"{path}: checkpoint lacks {missing}")
    return ck


PRECISIONS: tuple[str, ...] = ("fp32", "fp16", "int8")
"""Weight storage of inference exports (:func:`pack_weights`)."""

_SCALE = "@scale"


def pack_weights(state: dict[str, torch.Tensor], precision: str) -> dict[str, torch.Tensor]:
    """A state dict stored at ``precision``: ``"fp32"``, ``"fp16"``, or ``"int8"`` (every weight
    matrix of at least 256 entries as int8 with one float32 scale per row, under
    ``<name>@scale``, symmetric: ``w = q * scale``; the rest float16). :func:`unpack_weights`
    restores float32 tensors."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision {precision!r}: use one of {list(PRECISIONS)}")
    out: dict[str, torch.Tensor] = {}
    for k, v in state.items():
        if not v.is_floating_point() or precision == "fp32":
            out[k] = v
        elif precision == "int8" and v.dim() == 2 and v.numel() >= 256:
            w = v.float()
            scale = w.abs().amax(dim=1, keepdim=True) / 127.0
            scale[scale == 0] = 1.0
            out[k] = torch.round(w / scale).to(torch.int8)
            out[k + _SCALE] = scale
        else:
            out[k] = v.half()
    return out


def unpack_weights(state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Float32 tensors of a state dict written by :func:`pack_weights` (any precision)."""
    return {k: v.float() * state[k + _SCALE] if k + _SCALE in state else v.float()
            for k, v in state.items() if not k.endswith(_SCALE)}  # fmt: skip


def export_for_inference(src: str | os.PathLike, dst: str | os.PathLike,
                         precision: str = "fp16") -> int:  # fmt: skip
    """Write a small inference-only copy of a training checkpoint (no optimiser state).

    Weights are stored at ``precision`` (:func:`pack_weights`; float32 again on load); the
    normaliser, the configuration and the training history stay. Returns the file size, bytes.
    """
    ck = load_checkpoint(src)
    out = {k: ck[k] for k in ("version", "config", "norm_mean", "norm_std", "epoch", "history")
           if k in ck}  # fmt: skip
    out["model"] = pack_weights(ck["model"], precision)
    buf = io.BytesIO()
    torch.save(out, buf)
    atomic_write(dst, lambda f: f.write(buf.getvalue()))
    return len(buf.getvalue())


def write_run_config(run_dir: Path, cfg: KinematicsRunConfig, extra: dict) -> None:
    """``config.json`` with the resolved settings, the git hash and ``extra`` (data, command)."""
    payload = {"config": asdict(cfg), "git": git_hash(), **extra}
    atomic_write_text(run_dir / "config.json", json.dumps(payload, indent=1))


def replace_train(cfg: KinematicsRunConfig, **kw) -> KinematicsRunConfig:
    """Copy of ``cfg`` with some :class:`TrainConfig` fields replaced."""
    return dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, **kw))
