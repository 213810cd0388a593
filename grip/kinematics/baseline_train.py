"""Training of the TransPose and PIP kinematics baselines (:mod:`grip.kinematics.baselines`):
their extra targets, the training data and the trainer with its checkpoints."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from dataclasses import asdict

import numpy as np
import torch

from grip.core import skeleton as sk
from grip.core.metrics import contacts_from_motion
from grip.core.rotations import rot_z, sixd_to_matrix
from grip.core.rundir import RunDir
from grip.core.runs import git_hash, history_wall_s, require_same_settings
from grip.kinematics.baseline_config import (
    _IMU_FEATURES,
    _INSOLE_FEATURES,
    BaselineTrainConfig,
    RunConfig,
    config_from_json,
    config_to_json,
    feature_config,
    input_columns,
)
from grip.kinematics.baseline_nets import build_nets, leaf_in_root_frame
from grip.kinematics.dataset import Normalizer, SequenceArrays, load_split_sequences, sample_windows
from grip.kinematics.train import log_epoch
from grip.nn.symmetry import rotate_batch
from grip.nn.weights import load_checkpoint, save_checkpoint

CHECKPOINT_VERSION = 1
RESUMABLE: tuple[str, ...] = ("train.epochs",)
"""Settings a resumed run may change: its length."""


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
        self.rundir = RunDir(run_dir, RESUMABLE, "'grip kin train --baseline' run")
        self.run_dir = self.rundir.path
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
            save_checkpoint(self.run_dir / "best.pt", self.best_state())
            save_checkpoint(self.run_dir / "last.pt", self.state())
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

    def save(self, path: str | os.PathLike) -> None:
        """Write a resumable checkpoint (weights, optimiser, RNG, history) atomically."""
        save_checkpoint(path, self.state())

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
        require_same_settings(asdict(old), asdict(self.cfg), path, "",
                              may_change=self.rundir.may_change,
                              what="checkpoint was trained with another configuration")  # fmt: skip
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
