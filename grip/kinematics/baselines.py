"""Kinematics networks of the TransPose and PIP baselines, adapted to 4 IMUs (+ insoles).

BASELINES_AND_METRICS.md section 2. Both methods read, per frame, the world-frame free
accelerations of the 4 wearables divided by 30 (12 values) and their world orientations (36), plus
the 10 insole values in the "+I" variants: 48 / 58 inputs, standardised with the training-set
:class:`~grip.kinematics.dataset.Normalizer`. There is no pelvis IMU to express them in, so the
inputs stay in the world frame, training rotates every window about the vertical by a random angle
(:func:`~grip.kinematics.train.rotate_batch`), and the rotation network outputs all 24 global
rotations (6D), the root's included. Positions are root-relative with world axes (GRIP's frame).

TransPose (TP-4), every net = input dropout -> Linear+ReLU -> 2-layer LSTM -> Linear:

====== ================== ============================================= ===== =====
net    input              output                                        width dir
====== ================== ============================================= ===== =====
s1     x                  leaf joints (wrists, ankles, head) 5x3        256   bi
s2     [leaf, x]          joints 1..23, 23x3                            64    bi
s3     [joints, x]        24 global rotations, 24x6D                    128   bi
b1     [leaf, x]          foot contact logits (L, R)                    64    bi
b2     [joints, x]        root velocity in the root frame, m/s / 3      256   uni
====== ================== ============================================= ===== =====

PIP (PIP-4): the same building block, unidirectional, width 256 (contact net 64), dropout 0.4:
``p_l`` x -> leaf (learned initial state from the first frame's leaf positions), ``p_a`` [leaf, x]
-> joints, ``r_a`` [joints, x] -> 24x6D, ``v_a`` [joints, x] -> the 24 joint velocities in the
root frame, m/s / 3 (learned initial state from the first frame's velocities; zeros at
inference), ``c_f`` [joints, x] -> contact logits. The learned initialisation is PIP's: a
fully connected net (widths ``w, w * layers, 2 * layers * w``) maps the first-frame quantity to
the LSTM's initial hidden and cell states.

Training (:class:`BaselineTrainer`) follows both papers in training every net on its own, fed
with the ground truth of the stages before it plus Gaussian noise (TransPose: leaf 0.04 m for s2
and b1, joints 0.025 m for s3 and b2). All nets of a method are updated in the same step from
one batch; their parameters are disjoint and Adam scales each parameter on its own, so this
equals training them one after the other on the same windows. Losses: L2 on positions and 6D
rotations, binary cross-entropy on contacts, and TransPose's cumulative velocity loss
``sum_n sum_m || sum_{t in block m of n frames} (v^ - v) ||^2`` (n = 1, 3, 9, 27) on ``b2`` and
``v_a``. ``b2`` learns only from windows in which some frame has no foot contact (TransPose trained
it on such clips), unless ``b2_flight_windows_only`` is off.

Inference (:class:`BaselineEstimator`): TransPose offline runs its bidirectional nets over the
whole sequence; its online mode runs them on a sliding window of 33 past + 1 + 8 future frames
(TransPose's 20 + 1 + 5 at 60 Hz; latency 80 ms) and ``b2`` causally over the sequence (the
reference online code instead re-runs ``b2`` on each window from a carried state). PIP's nets
are causal, so its offline and online outputs are the same.
"""

from __future__ import annotations

import dataclasses
import io
import json
import os
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from grip.config import ConfigError, apply_dict
from grip.core import skeleton as sk
from grip.core.atomic import atomic_write
from grip.core.metrics import contacts_from_motion
from grip.core.rotations import rot_z, sixd_to_matrix
from grip.kinematics.dataset import Normalizer, SequenceArrays, load_split_sequences, sample_windows
from grip.kinematics.features import DEFAULT_SITES, FeatureConfig, input_features, targets
from grip.kinematics.train import (
    export_for_inference,
    git_hash,
    history_wall_s,
    load_checkpoint,
    log_epoch,
    rotate_batch,
    unpack_weights,
)

METHODS: tuple[str, ...] = ("transpose", "pip")
CHECKPOINT_VERSION = 1
N_LEAF = len(sk.LEAF_JOINTS)
N_JOINTS_REL = sk.N_JOINTS - 1
"""Joints with a root-relative position (all but the pelvis)."""
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
        _check_sizes(self, ("s1_width", "s2_width", "s3_width", "b1_width", "b2_width", "layers"))
        if self.online_past_frames < 0 or self.online_future_frames < 0:
            raise ValueError("TransPoseConfig: online window frames must be >= 0")


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
        _check_sizes(self, ("width", "contact_width", "layers"))
        if self.init_leaf_frame not in ("root", "world"):
            raise ValueError(f"PipNetConfig.init_leaf_frame must be 'root' or 'world', got "
                             f"{self.init_leaf_frame!r}")  # fmt: skip


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
        _check_sizes(self, ("window_frames", "batch_size", "steps_per_epoch", "val_windows"))
        if self.epochs < 0:
            raise ValueError(f"BaselineTrainConfig.epochs must be >= 0, got {self.epochs}")
        if self.contact_labels not in ("insole", "motion"):
            raise ValueError("BaselineTrainConfig.contact_labels must be 'insole' or 'motion', "
                             f"got {self.contact_labels!r}")  # fmt: skip
        if not self.cumulative_blocks or min(self.cumulative_blocks) < 1:
            raise ValueError("BaselineTrainConfig.cumulative_blocks: need block lengths >= 1, "
                             f"got {self.cumulative_blocks}")  # fmt: skip


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


def _check_sizes(cfg, names: tuple[str, ...]) -> None:
    bad = [f"{n}={getattr(cfg, n)}" for n in names if getattr(cfg, n) < 1]
    if bad:
        raise ValueError(f"{type(cfg).__name__}: must be >= 1: {', '.join(bad)}")


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
    d = json.loads(text)
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


# ---------------------------------------------------------------------------- data
def add_baseline_targets(seq: SequenceArrays, n_sites: int, train: BaselineTrainConfig) -> None:
    """Add the targets the baselines need to ``seq.y`` (in place).

    - ``"jvel"`` ``(T, 72)``: velocities of the 24 joints in the root frame divided by 3,
      ``R_root^T (r_t - r_{t-1}) * fps / 3`` (frame 0 copies frame 1). Root-frame values do not
      change under the yaw augmentation.
    - ``"contact"`` ``(T, 2)``: left/right foot contact, 0/1, from the insoles (front or back
      contact; needs the insole columns in ``seq.x``) or from foot speed.

    Raises:
        ValueError: The insole rule is asked for but ``seq.x`` has no insole columns.
    """
    n = len(seq.x)
    pos = seq.y["fp"].reshape(n, sk.N_JOINTS, 3).astype(np.float64) + seq.root_pos[:, None]
    root_rot = sixd_to_matrix(seq.y["fa"].reshape(n, sk.N_JOINTS, 6)[:, 0])
    vel = np.zeros_like(pos)
    if n > 1:
        vel[1:] = np.diff(pos, axis=0) * seq.fps
        vel[0] = vel[1]
    local = np.einsum("tji,tkj->tki", root_rot, vel)  # R^T v
    seq.y["jvel"] = (local / 3.0).reshape(n, -1).astype(np.float32)
    if train.contact_labels == "insole":
        start = _IMU_FEATURES * n_sites
        if seq.x.shape[1] < start + _INSOLE_FEATURES:
            raise ValueError(f"sequence {seq.name}: insole contact labels need the insole "
                             "features (or set train.contact_labels = 'motion')")  # fmt: skip
        ins = seq.x[:, start : start + _INSOLE_FEATURES].reshape(n, 2, 5)
        contact = (ins[..., 3] > 0.5) | (ins[..., 4] > 0.5)
    elif n > 1:
        contact = contacts_from_motion(pos[:, list(sk.FOOT_JOINTS)], seq.fps,
                                       train.contact_speed_mps)  # fmt: skip
    else:
        contact = np.ones((n, 2), dtype=bool)
    seq.y["contact"] = contact.astype(np.float32)


def load_baseline_sequences(data_dir: str | os.PathLike, split: str, cfg: RunConfig,
                            limit: int | None = None) -> list[SequenceArrays]:  # fmt: skip
    """Features and targets of a dataset split for training a baseline.

    Features are loaded with the insole columns whenever the net reads them or the contact
    labels come from them; :func:`input_columns` picks the inputs later.

    Raises:
        FileNotFoundError / ValueError naming the folder, split file or recording.
    """
    insoles = cfg.net.insoles or cfg.train.contact_labels == "insole"
    seqs = load_split_sequences(data_dir, split, feature_config(cfg, insoles), limit)
    for s in seqs:
        add_baseline_targets(s, len(cfg.sites), cfg.train)
    return seqs


# ---------------------------------------------------------------------------- networks
class RecurrentNet(nn.Module):
    """Input dropout -> Linear+ReLU -> LSTM -> Linear, with an optional learned initial state.

    Args:
        n_in: Inputs per frame.
        n_out: Outputs per frame.
        width: Input-layer and LSTM width.
        layers: LSTM layers.
        bidirectional: Bidirectional LSTM (then no learned initial state).
        dropout: Dropout probability on the input.
        n_init: Size of the first-frame quantity that sets the initial state (0: zero state).
    """

    def __init__(
        self,
        n_in: int,
        n_out: int,
        width: int,
        layers: int = 2,
        bidirectional: bool = False,
        dropout: float = 0.0,
        n_init: int = 0,
    ) -> None:
        super().__init__()
        if n_init and bidirectional:
            raise ValueError("a learned initial state needs a unidirectional LSTM")
        self.width, self.layers = width, layers
        self.drop = nn.Dropout(dropout)
        self.inp = nn.Linear(n_in, width)
        self.lstm = nn.LSTM(width, width, layers, batch_first=True, bidirectional=bidirectional)
        self.out = nn.Linear(width * (2 if bidirectional else 1), n_out)
        self.init = None
        if n_init:
            self.init = nn.Sequential(
                nn.Linear(n_init, width), nn.ReLU(),
                nn.Linear(width, width * layers), nn.ReLU(),
                nn.Linear(width * layers, 2 * layers * width),
            )  # fmt: skip

    def initial_state(self, first: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(B, n_init)`` first-frame quantity -> ``(h0, c0)``, each ``(layers, B, width)``."""
        if self.init is None:
            raise ValueError("this net has no learned initial state")
        hc = self.init(first).view(first.shape[0], 2, self.layers, self.width)
        return hc[:, 0].transpose(0, 1).contiguous(), hc[:, 1].transpose(0, 1).contiguous()

    def forward(self, x: torch.Tensor, state: tuple[torch.Tensor, torch.Tensor] | None = None):
        """``(B, T, n_in)`` -> ``(B, T, n_out)`` and the final LSTM state."""
        h, state = self.lstm(torch.relu(self.inp(self.drop(x))), state)
        return self.out(h), state


def _cat(*parts: torch.Tensor) -> torch.Tensor:
    return torch.cat(parts, dim=-1)


class TransPoseNets(nn.Module):
    """The five TP-4 nets. Inputs are normalised features ``(B, T, n_inputs)``."""

    NETS: tuple[str, ...] = ("s1", "s2", "s3", "b1", "b2")

    def __init__(self, cfg: TransPoseConfig, n_in: int) -> None:
        super().__init__()
        self.cfg = cfg
        leaf, full, rot = 3 * N_LEAF, 3 * N_JOINTS_REL, 6 * sk.N_JOINTS
        kw = {"layers": cfg.layers, "dropout": cfg.dropout}
        self.nets = nn.ModuleDict({
            "s1": RecurrentNet(n_in, leaf, cfg.s1_width, bidirectional=True, **kw),
            "s2": RecurrentNet(leaf + n_in, full, cfg.s2_width, bidirectional=True, **kw),
            "s3": RecurrentNet(full + n_in, rot, cfg.s3_width, bidirectional=True, **kw),
            "b1": RecurrentNet(leaf + n_in, 2, cfg.b1_width, bidirectional=True, **kw),
            "b2": RecurrentNet(full + n_in, 3, cfg.b2_width, bidirectional=False, **kw),
        })  # fmt: skip

    def pose(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        """The bidirectional nets chained: ``lp (B,T,15)``, ``pall (B,T,69)``, ``fa (B,T,144)``,
        ``contact`` logits ``(B,T,2)``."""
        n = self.nets
        lp = n["s1"](x)[0]
        pall = n["s2"](_cat(lp, x))[0]
        return {"lp": lp, "pall": pall, "fa": n["s3"](_cat(pall, x))[0],
                "contact": n["b1"](_cat(lp, x))[0]}  # fmt: skip

    def forward(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        """All nets chained over whole sequences (offline); adds ``vel`` ``(B,T,3)``: root
        velocity in the root frame, m/s / vel_scale."""
        out = self.pose(x)
        out["vel"] = self.nets["b2"](_cat(out["pall"], x))[0]
        return out

    def losses(self, x: torch.Tensor, y: dict[str, torch.Tensor], noise: Callable,
               blocks: tuple[int, ...]) -> dict[str, torch.Tensor]:  # fmt: skip
        """Per-net training losses, each net fed the noisy ground truth of its inputs.

        Args:
            x: ``(B, T, n_inputs)`` normalised inputs.
            y: ``lp``, ``pall``, ``fa``, ``contact``, ``vel`` (root frame / vel_scale) targets.
            noise: ``noise(tensor, std_m)`` returns the tensor plus Gaussian noise.
            blocks: Block lengths of the cumulative velocity loss.
        """
        n, c = self.nets, self.cfg
        out = {
            "s1": F.mse_loss(n["s1"](x)[0], y["lp"]),
            "s2": F.mse_loss(n["s2"](_cat(noise(y["lp"], c.s2_noise_m), x))[0], y["pall"]),
            "s3": F.mse_loss(n["s3"](_cat(noise(y["pall"], c.s3_noise_m), x))[0], y["fa"]),
            "b1": F.binary_cross_entropy_with_logits(
                n["b1"](_cat(noise(y["lp"], c.b1_noise_m), x))[0], y["contact"]),
        }  # fmt: skip
        weight = None
        if c.b2_flight_windows_only:
            weight = (y["contact"].amax(-1).amin(-1) < 0.9).to(x.dtype)  # a frame without contact
        vel = n["b2"](_cat(noise(y["pall"], c.b2_noise_m), x))[0]
        out["b2"] = cumulative_loss(vel, y["vel"], blocks, weight)
        return out


class PipNets(nn.Module):
    """The five PIP-4 kinematics nets (all unidirectional, hence causal)."""

    NETS: tuple[str, ...] = ("p_l", "p_a", "r_a", "v_a", "c_f")

    def __init__(self, cfg: PipNetConfig, n_in: int) -> None:
        super().__init__()
        self.cfg = cfg
        leaf, full, rot, vel = 3 * N_LEAF, 3 * N_JOINTS_REL, 6 * sk.N_JOINTS, 3 * sk.N_JOINTS
        kw = {"layers": cfg.layers, "dropout": cfg.dropout}
        init = cfg.learned_init
        self.nets = nn.ModuleDict({
            "p_l": RecurrentNet(n_in, leaf, cfg.width, n_init=leaf if init else 0, **kw),
            "p_a": RecurrentNet(leaf + n_in, full, cfg.width, **kw),
            "r_a": RecurrentNet(full + n_in, rot, cfg.width, **kw),
            "v_a": RecurrentNet(full + n_in, vel, cfg.width, n_init=vel if init else 0, **kw),
            "c_f": RecurrentNet(full + n_in, 2, cfg.contact_width, **kw),
        })  # fmt: skip

    def initial_states(self, leaf0: torch.Tensor, vel0: torch.Tensor) -> dict:
        """LSTM states of P_L and V_A from the first frame (``None``: zero states).

        Args:
            leaf0: ``(B, 15)`` first-frame leaf positions (frame per ``init_leaf_frame``), m.
            vel0: ``(B, 72)`` first-frame joint velocities, root frame, m/s / vel_scale.
        """
        if not self.cfg.learned_init:
            return {"p_l": None, "v_a": None}
        return {"p_l": self.nets["p_l"].initial_state(leaf0),
                "v_a": self.nets["v_a"].initial_state(vel0)}  # fmt: skip

    def forward(self, x: torch.Tensor, leaf0: torch.Tensor, vel0: torch.Tensor,
                state: dict | None = None) -> tuple[dict[str, torch.Tensor], dict]:  # fmt: skip
        """All nets chained; ``state`` (from a previous call) continues a stream.

        Returns:
            ``lp (B,T,15)``, ``pall (B,T,69)``, ``fa (B,T,144)``, ``vel (B,T,72)`` (root frame,
            m/s / vel_scale), ``contact`` logits ``(B,T,2)``; and the LSTM states.
        """
        n = self.nets
        st = (
            dict(state)
            if state is not None
            else {**self.initial_states(leaf0, vel0), "p_a": None, "r_a": None, "c_f": None}
        )
        new = {}
        lp, new["p_l"] = n["p_l"](x, st["p_l"])
        pall, new["p_a"] = n["p_a"](_cat(lp, x), st["p_a"])
        xa = _cat(pall, x)
        fa, new["r_a"] = n["r_a"](xa, st["r_a"])
        vel, new["v_a"] = n["v_a"](xa, st["v_a"])
        contact, new["c_f"] = n["c_f"](xa, st["c_f"])
        return {"lp": lp, "pall": pall, "fa": fa, "vel": vel, "contact": contact}, new

    def losses(self, x: torch.Tensor, y: dict[str, torch.Tensor], noise: Callable,
               blocks: tuple[int, ...]) -> dict[str, torch.Tensor]:  # fmt: skip
        """Per-net training losses (see :meth:`TransPoseNets.losses`); ``y`` also holds
        ``leaf0`` and ``vel0``, the windows' first-frame quantities for the learned init."""
        n, c = self.nets, self.cfg
        st = self.initial_states(y["leaf0"], y["vel0"])
        leaf = noise(y["lp"], c.leaf_noise_m)
        joints = [_cat(noise(y["pall"], c.joint_noise_m), x) for _ in range(3)]
        return {
            "p_l": F.mse_loss(n["p_l"](x, st["p_l"])[0], y["lp"]),
            "p_a": F.mse_loss(n["p_a"](_cat(leaf, x))[0], y["pall"]),
            "r_a": F.mse_loss(n["r_a"](joints[0])[0], y["fa"]),
            "v_a": cumulative_loss(n["v_a"](joints[1], st["v_a"])[0], y["vel"], blocks),
            "c_f": F.binary_cross_entropy_with_logits(n["c_f"](joints[2])[0], y["contact"]),
        }


def build_nets(cfg: RunConfig) -> TransPoseNets | PipNets:
    """The nets of a run configuration, freshly initialised."""
    if cfg.method == "transpose":
        return TransPoseNets(cfg.net, n_inputs(cfg))
    return PipNets(cfg.net, n_inputs(cfg))


def cumulative_loss(pred: torch.Tensor, gt: torch.Tensor, blocks: tuple[int, ...],
                    weight: torch.Tensor | None = None) -> torch.Tensor:  # fmt: skip
    """TransPose's accumulated velocity loss (eq. 7-8).

    ``sum_n mean_m || sum_{t in block m of n frames} (pred - gt) ||^2``, averaged over windows
    (weighted by ``weight``); a window's tail shorter than a block is left out.

    Args:
        pred: ``(B, T, D)`` predicted velocities (any consistent unit).
        gt: ``(B, T, D)`` ground truth.
        blocks: Block lengths in frames, e.g. ``(1, 3, 9, 27)``.
        weight: Optional ``(B,)`` non-negative window weights (0 drops a window).
    """
    b, t, d = pred.shape
    diff = pred - gt
    per_window = torch.zeros(b, dtype=pred.dtype, device=pred.device)
    for n in blocks:
        m = t // n
        if m == 0:
            continue
        sums = diff[:, : m * n].reshape(b, m, n, d).sum(2)
        per_window = per_window + (sums**2).sum(-1).mean(1)
    if weight is None:
        return per_window.mean()
    return (per_window * weight).sum() / weight.sum().clamp_min(1.0)


def _sixd_to_matrix_t(d6: torch.Tensor) -> torch.Tensor:
    """Torch version of :func:`grip.core.rotations.sixd_to_matrix`, ``(..., 6) -> (..., 3, 3)``."""
    c0 = F.normalize(d6[..., :3], dim=-1)
    b = d6[..., 3:]
    c1 = F.normalize(b - (c0 * b).sum(-1, keepdim=True) * c0, dim=-1)
    return torch.stack([c0, c1, torch.linalg.cross(c0, c1, dim=-1)], dim=-1)


def leaf_in_root_frame(lp: torch.Tensor, root6d: torch.Tensor) -> torch.Tensor:
    """``(B, 15)`` world-axes leaf positions -> root frame (the root rotation set to identity)."""
    r = _sixd_to_matrix_t(root6d)  # (B, 3, 3)
    return torch.einsum("bji,bkj->bki", r, lp.reshape(-1, N_LEAF, 3)).reshape(lp.shape)


# ---------------------------------------------------------------------------- training
class BaselineTrainer:
    """Owns the nets, optimiser, data and run folder of one baseline training run.

    A run folder holds ``config.json`` (resolved settings, git hash), ``last.pt`` (replaced
    atomically after every epoch), ``best.pt`` and TensorBoard files. The nets are trained
    independently, so ``best.pt`` holds each net's weights from the epoch of its own lowest
    validation loss (their loss scales differ; one summed loss would let the velocity net pick
    the epoch for all). Checkpoints contain only tensors and plain containers
    (``torch.load(weights_only=True)``).
    """

    def __init__(self, cfg: RunConfig, train_seqs: list[SequenceArrays],
                 val_seqs: list[SequenceArrays], run_dir: str | os.PathLike) -> None:  # fmt: skip
        if not train_seqs:
            raise ValueError("no training sequences")
        for s in (*train_seqs, *val_seqs):
            if "jvel" not in s.y or "contact" not in s.y:
                raise ValueError(f"sequence {s.name}: missing baseline targets "
                                 "(load with load_baseline_sequences)")  # fmt: skip
        self.cfg = cfg
        self.run_dir = Path(run_dir)
        self.train_seqs = train_seqs
        self.val_seqs = val_seqs or train_seqs
        torch.manual_seed(cfg.train.seed)
        self.nets = build_nets(cfg)
        self.opt = torch.optim.Adam(self.nets.parameters(), lr=cfg.train.lr)
        self.n_sites = len(cfg.sites)
        cols = input_columns(self.n_sites, cfg.net.insoles)
        if train_seqs[0].x.shape[1] < cols.max() + 1:
            raise ValueError("training features lack the insole columns the +I variant reads")
        self.cols = torch.from_numpy(cols)
        full = Normalizer.fit(train_seqs)
        self.norm = Normalizer(full.mean[cols], full.std[cols])
        self.rng = np.random.default_rng(cfg.train.seed)
        self.epoch = 0
        self.best_val = {k: float("inf") for k in self.nets.NETS}
        self.best_model: dict[str, torch.Tensor] = {}
        self.history: list[dict] = []
        tc = cfg.train
        self.val_batch = sample_windows(self.val_seqs, tc.val_windows, tc.window_frames,
                                        np.random.default_rng(tc.seed + 1))  # fmt: skip

    # ------------------------------------------------------------------ batches
    def batch(self, x: np.ndarray, y: dict[str, np.ndarray], augment: bool):
        """Raw windows -> normalised net inputs ``(B, T, n_inputs)`` and the method's targets."""
        xt = torch.from_numpy(x)
        yt = {k: torch.from_numpy(v) for k, v in y.items()}
        if augment and self.cfg.train.yaw_augment:
            ang = self.rng.uniform(-np.pi, np.pi, x.shape[0])
            rot = torch.from_numpy(rot_z(ang).astype(np.float32))
            xt, yt = rotate_batch(xt, yt, rot, self.n_sites)
        xin = (xt[..., self.cols] - torch.from_numpy(self.norm.mean)) / torch.from_numpy(
            self.norm.std)  # fmt: skip
        out = {"lp": yt["lp"], "pall": yt["fp"][..., 3:], "fa": yt["fa"],
               "contact": yt["contact"]}  # fmt: skip
        scale = 3.0 / self.cfg.net.vel_scale  # stored targets are m/s / 3
        if self.cfg.method == "transpose":
            out["vel"] = yt["jvel"][..., :3] * scale
        else:
            out["vel"] = yt["jvel"] * scale
            lp0 = yt["lp"][:, 0]
            if self.cfg.net.init_leaf_frame == "root":
                lp0 = leaf_in_root_frame(lp0, yt["fa"][:, 0, :6])
            out["leaf0"], out["vel0"] = lp0, out["vel"][:, 0]
        return xin, out

    def _noise(self, t: torch.Tensor, std: float) -> torch.Tensor:
        if std <= 0:
            return t
        return t + torch.from_numpy(self.rng.normal(0.0, std, t.shape).astype(np.float32))

    def losses(self, x: torch.Tensor, y: dict[str, torch.Tensor],
               noisy: bool = True) -> dict[str, torch.Tensor]:  # fmt: skip
        """Per-net losses of a prepared batch (noise on the stage inputs when ``noisy``)."""
        noise = self._noise if noisy else (lambda t, std: t)
        return self.nets.losses(x, y, noise, self.cfg.train.cumulative_blocks)

    def validate(self) -> dict[str, float]:
        """Per-net losses on the fixed validation windows (no noise, no augmentation), their
        sum ``total``, and ``chain_pos_mm``: the mean joint position error of the nets run in
        a chain, mm (root-relative, as at inference)."""
        self.nets.eval()
        with torch.no_grad():
            x, y = self.batch(*self.val_batch, augment=False)
            out = {k: float(v) for k, v in self.losses(x, y, noisy=False).items()}
            if self.cfg.method == "transpose":
                chain = self.nets(x)
            else:
                chain = self.nets(x, y["leaf0"], torch.zeros_like(y["vel0"]))[0]
            err = (chain["pall"] - y["pall"]).reshape(*x.shape[:2], -1, 3).norm(dim=-1)
        self.nets.train()
        out["total"] = float(sum(out.values()))
        out["chain_pos_mm"] = float(err.mean()) * 1000.0
        return out

    # ------------------------------------------------------------------ loop
    def step(self) -> dict[str, float]:
        """One optimiser step on a fresh batch; returns the per-net losses."""
        tc = self.cfg.train
        x, y = sample_windows(self.train_seqs, tc.batch_size, tc.window_frames, self.rng)
        xt, yt = self.batch(x, y, augment=True)
        losses = self.losses(xt, yt)
        self.opt.zero_grad(set_to_none=True)
        sum(losses.values()).backward()
        for net in self.nets.nets.values():
            torch.nn.utils.clip_grad_norm_(net.parameters(), tc.grad_clip)
        self.opt.step()
        return {k: v.item() for k, v in losses.items()}

    def fit(self, writer=None, progress: Callable[[dict], object] | None = None) -> list[dict]:
        """Train until ``train.epochs``; checkpoints after each epoch (resumes from ``epoch``)."""
        tc = self.cfg.train
        self.nets.train()
        while self.epoch < tc.epochs:
            t0 = time.perf_counter()
            sums: dict[str, float] = {}
            for _ in range(tc.steps_per_epoch):
                losses = self.step()
                for k, v in losses.items():
                    sums[k] = sums.get(k, 0.0) + v
                if progress is not None:
                    progress({"epoch": self.epoch, "loss": sum(losses.values())})
            val = self.validate()
            record = {"epoch": self.epoch,
                      "train": {k: v / tc.steps_per_epoch for k, v in sums.items()},
                      "val": val, "wall_s": self.wall_s() + time.perf_counter() - t0}  # fmt: skip
            self.history.append(record)
            log_epoch(writer, record)
            self.epoch += 1
            self.update_best(val)
            self._write(self.run_dir / "best.pt", self.best_state())
            self._write(self.run_dir / "last.pt", self.state())
        return self.history

    def wall_s(self) -> float:
        return history_wall_s(self.history)

    def update_best(self, val: dict[str, float]) -> None:
        """Keep the current weights of every net whose validation loss in ``val`` is its lowest
        so far (they go into ``best.pt``)."""
        current = self.nets.state_dict()
        for name in self.nets.NETS:
            if val[name] < self.best_val[name]:
                self.best_val[name] = val[name]
                prefix = f"nets.{name}."
                self.best_model.update({k: v.detach().clone() for k, v in current.items()
                                        if k.startswith(prefix)})  # fmt: skip

    # ------------------------------------------------------------------ checkpoints
    def state(self) -> dict:
        return {
            "version": CHECKPOINT_VERSION,
            "config": config_to_json(self.cfg),
            "model": self.nets.state_dict(),
            "optimizer": self.opt.state_dict(),
            "norm_mean": torch.from_numpy(self.norm.mean),
            "norm_std": torch.from_numpy(self.norm.std),
            "epoch": self.epoch,
            "best_val": json.dumps(self.best_val),
            "best_model": self.best_model,
            "rng": json.dumps(self.rng.bit_generator.state),
            "history": json.dumps(self.history),
            "git": git_hash(),
        }

    def best_state(self) -> dict:
        """Inference checkpoint of the per-net best weights (current weights for a net that has
        not been validated yet)."""
        model = {**self.nets.state_dict(), **self.best_model}
        keep = ("version", "config", "norm_mean", "norm_std", "epoch", "best_val", "history", "git")
        return {**{k: v for k, v in self.state().items() if k in keep}, "model": model}

    @staticmethod
    def _write(path: str | os.PathLike, state: dict) -> None:
        buf = io.BytesIO()
        torch.save(state, buf)
        atomic_write(path, lambda f: f.write(buf.getvalue()))

    def save(self, path: str | os.PathLike) -> None:
        """Write a resumable checkpoint (weights, optimiser, RNG, history) atomically."""
        self._write(path, self.state())

    def load(self, path: str | os.PathLike) -> None:
        """Resume from a checkpoint of the same configuration (only ``train.epochs`` may
        differ, and not below the checkpoint's epoch).

        Raises:
            ValueError: Another method or configuration, or a checkpoint beyond ``epochs``.
        """
        ck = load_checkpoint(path)
        old = config_from_json(ck["config"], str(path))
        if old.method != self.cfg.method:
            raise ValueError(f"{path}: checkpoint of {old.method}, not {self.cfg.method}")
        a, b = asdict(old), asdict(self.cfg)
        a["train"].pop("epochs")
        b["train"].pop("epochs")
        if a != b:
            diff = sorted(k for k in a if a[k] != b[k])
            raise ValueError(f"{path}: checkpoint was trained with another configuration "
                             f"(differs in {', '.join(diff)})")  # fmt: skip
        if int(ck["epoch"]) > self.cfg.train.epochs:
            raise ValueError(f"{path}: checkpoint is at epoch {int(ck['epoch'])}, beyond the "
                             f"{self.cfg.train.epochs} epochs of this configuration")  # fmt: skip
        if "optimizer" not in ck or "best_model" not in ck:
            raise ValueError(f"{path}: not a resumable checkpoint (use RUN/last.pt)")
        self.nets.load_state_dict(ck["model"])
        self.opt.load_state_dict(ck["optimizer"])
        self.norm = Normalizer(ck["norm_mean"].numpy(), ck["norm_std"].numpy())
        self.epoch = int(ck["epoch"])
        self.best_val = json.loads(ck["best_val"])
        self.best_model = dict(ck["best_model"])
        self.rng.bit_generator.state = json.loads(ck["rng"])
        self.history = json.loads(ck["history"])


def replace_train(cfg: RunConfig, **kw) -> RunConfig:
    """Copy of ``cfg`` with some :class:`BaselineTrainConfig` fields replaced."""
    return dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, **kw))


def export_baseline(src: str | os.PathLike, dst: str | os.PathLike, precision: str = "fp16") -> int:
    """Write a small inference-only copy of a baseline checkpoint (weights at ``precision``,
    :func:`grip.kinematics.train.pack_weights`; no optimiser state). Returns the file size,
    bytes.

    Raises:
        ValueError: ``src`` is not a TransPose/PIP baseline checkpoint.
    """
    config_from_json(load_checkpoint(src)["config"], str(src))
    return export_for_inference(src, dst, precision=precision)


# ---------------------------------------------------------------------------- inference
@dataclass
class BaselineEstimate:
    """Kinematics of one recording from a baseline's nets (world axes, m, rad).

    Attributes:
        leaf_pos: ``(T, 5, 3)`` root-relative leaf joints (wrists, ankles, head).
        joint_pos: ``(T, 24, 3)`` root-relative joints as the position net estimates them
            (row 0 is zero).
        global_rot: ``(T, 24, 3, 3)`` global joint rotations (root included).
        contact_prob: ``(T, 2)`` left/right foot contact probabilities.
        root_vel: ``(T, 3)`` root velocity, world, m/s: Trans-B2 (TransPose) or V_A's pelvis
            row (PIP), rotated by the estimated root rotation.
        joint_vel: ``(T, 24, 3)`` world joint velocities, m/s (PIP; ``None`` for TransPose).
    """

    leaf_pos: np.ndarray
    joint_pos: np.ndarray
    global_rot: np.ndarray
    contact_prob: np.ndarray
    root_vel: np.ndarray
    joint_vel: np.ndarray | None = None


class BaselineEstimator:
    """Trained baseline nets with their normaliser and settings."""

    def __init__(self, nets: TransPoseNets | PipNets, norm: Normalizer, cfg: RunConfig) -> None:
        self.nets = nets.eval()
        self.norm = norm
        self.cfg = cfg
        self.method = cfg.method
        self.features = feature_config(cfg, cfg.net.insoles)
        self.cols = input_columns(len(cfg.sites), cfg.net.insoles)

    @classmethod
    def from_checkpoint(cls, path: str | os.PathLike) -> BaselineEstimator:
        """Load a training or exported checkpoint (``weights_only``; fp16 weights are cast)."""
        ck = load_checkpoint(path)
        cfg = config_from_json(ck["config"], str(path))
        nets = build_nets(cfg)
        try:
            nets.load_state_dict(unpack_weights(ck["model"]))
        except RuntimeError as e:
            raise ValueError(f"{path}: weights do not match the configuration ({e})") from e
        norm = Normalizer(ck["norm_mean"].float().numpy(), ck["norm_std"].float().numpy())
        return cls(nets, norm, cfg)

    def inputs(self, rec) -> np.ndarray:
        """``(T, n_inputs)`` normalised net inputs of a recording."""
        return self.norm(input_features(rec, self.features)[:, self.cols])

    def first_quantities(self, rec, gt_init_velocity: bool) -> tuple[torch.Tensor, torch.Tensor]:
        """PIP's learned-init inputs from a recording's first (ground-truth) frame.

        Returns:
            ``(1, 15)`` leaf positions (root or world frame per ``init_leaf_frame``), m, and
            ``(1, 72)`` joint velocities in the root frame / vel_scale (zeros unless
            ``gt_init_velocity``).
        """
        t = targets(rec.slice_frames(0, 2) if rec.n_frames > 2 else rec)
        lp0 = t.leaf_pos[0]
        if self.cfg.net.init_leaf_frame == "root":
            lp0 = lp0 @ t.global_rot[0, 0]  # R^T p for each row
        vel0 = np.zeros((sk.N_JOINTS, 3))
        if gt_init_velocity and rec.n_frames > 1:
            pos = t.joint_pos + t.root_pos[:, None]
            vel0 = (pos[1] - pos[0]) * float(rec.fps) @ t.global_rot[0, 0] / self.cfg.net.vel_scale
        return (torch.from_numpy(lp0.reshape(1, -1).astype(np.float32)),
                torch.from_numpy(vel0.reshape(1, -1).astype(np.float32)))  # fmt: skip

    def predict(
        self,
        recs,
        online: bool = False,
        gt_init_velocity: bool = False,
        insole_contact: bool = False,
    ) -> list[BaselineEstimate]:
        """Estimates for a list of recordings (each run on its own: bidirectional nets must
        not see padding).

        Args:
            recs: Recordings (their first frame is the ground-truth calibration pose).
            online: TransPose: sliding-window mode (33 past + 8 future frames); PIP: no
                effect (its nets are causal).
            gt_init_velocity: PIP: initialise V_A from the first frame's ground-truth joint
                velocities instead of zeros (PIP uses zeros).
            insole_contact: Replace the contact net's probabilities by the insole rule
                (1 where the front or back of the insole is in contact; section 2.4's
                "insole contact" rows).

        Raises:
            KeyError / ValueError naming the recording when a sensor is missing or non-finite.
        """
        out = []
        for rec in recs:
            x = torch.from_numpy(self.inputs(rec))[None]
            with torch.no_grad():
                if self.method == "transpose":
                    o = self.run_online(x) if online else self.nets(x)
                else:
                    o = self.nets(x, *self.first_quantities(rec, gt_init_velocity))[0]
            est = self._estimate({k: v[0].double().numpy() for k, v in o.items()})
            if insole_contact:
                est.contact_prob = insole_contact_prob(rec)
            out.append(est)
        return out

    def run_online(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        """TransPose's online mode on ``(1, T, n_inputs)`` normalised inputs: every frame from
        its own window of past and future frames (edges repeat the first / last frame); B2 runs
        causally over the sequence on the windowed joint estimates. Returns raw net outputs
        ``{key: (1, T, dim)}`` as :meth:`TransPoseNets.forward`."""
        c = self.cfg.net
        n = x.shape[1]
        offs = torch.arange(-c.online_past_frames, c.online_future_frames + 1)
        idx = (torch.arange(n)[:, None] + offs).clamp(0, n - 1)  # (T, W)
        win = self.nets.pose(x[0, idx])  # batch of T windows
        mid = c.online_past_frames
        o = {k: v[:, mid][None] for k, v in win.items()}
        o["vel"] = self.nets.nets["b2"](_cat(o["pall"], x))[0]
        return o

    def _estimate(self, o: dict[str, np.ndarray]) -> BaselineEstimate:
        n = o["lp"].shape[0]
        rot = sixd_to_matrix(o["fa"].reshape(n, sk.N_JOINTS, 6))
        joints = np.zeros((n, sk.N_JOINTS, 3))
        joints[:, 1:] = o["pall"].reshape(n, N_JOINTS_REL, 3)
        vel = o["vel"].reshape(n, -1, 3) * self.cfg.net.vel_scale
        vel_world = np.einsum("tij,tkj->tki", rot[:, 0], vel)
        return BaselineEstimate(
            leaf_pos=o["lp"].reshape(n, N_LEAF, 3),
            joint_pos=joints,
            global_rot=rot,
            contact_prob=1.0 / (1.0 + np.exp(-o["contact"])),
            root_vel=vel_world[:, 0],
            joint_vel=vel_world if self.method == "pip" else None,
        )


def insole_contact_prob(rec) -> np.ndarray:
    """``(T, 2)`` left/right contact "probabilities" from the insoles: 1.0 where the front or
    the back of the insole is in contact, else 0.0.

    Raises:
        KeyError: The recording has no insole for a foot (the message names it).
    """
    cols = []
    for foot in sk.FEET:
        if foot not in rec.insole:
            raise KeyError(f"recording {rec.name}: no insole for {foot!r}")
        cols.append(np.asarray(rec.insole[foot].contacts, dtype=bool).any(axis=1))
    return np.stack(cols, axis=1).astype(np.float64)
