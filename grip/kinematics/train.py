"""Training of KinematicsNet: stage-wise, then joint; checkpoints every epoch and resumes.

A run folder holds ``config.json`` (resolved settings, seed, git hash), ``last.pt`` (the latest
checkpoint, replaced atomically after every epoch), ``best.pt`` (lowest validation loss) and
TensorBoard event files. Checkpoints contain only tensors and plain containers, so they load
with ``torch.load(..., weights_only=True)`` (:func:`grip.nn.weights.load_checkpoint`).

Only training lives here: the run settings are :mod:`grip.kinematics.config`, the augmenting
symmetries :mod:`grip.nn.symmetry`, weight packing and checkpoint loading
:mod:`grip.nn.weights`, and the run folder (``config.json``, the resume check)
:mod:`grip.core.rundir`, so inference and the controller's code never import the trainer.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from grip.config import drop_removed
from grip.core import skeleton as sk
from grip.core.rotations import axis_angle_to_matrix
from grip.core.rundir import RunDir
from grip.core.runs import git_hash, history_wall_s, require_same_settings
from grip.kinematics.config import REMOVED_SETTINGS, KinematicsRunConfig, run_config_from_dict
from grip.kinematics.dataset import (
    TARGET_KEYS,
    Normalizer,
    SequenceArrays,
    sample_windows,
    training_weights,
)
from grip.kinematics.model import KinematicsNet
from grip.nn.symmetry import mirror_batch, mirror_site_order, rotate_batch, yaw_matrices
from grip.nn.weights import (
    CHECKPOINT_VERSION,
    load_checkpoint,
    pack_weights,
    save_checkpoint,
    unpack_weights,
)

RESUMABLE: tuple[str, ...] = ("train.joint_epochs",)
"""Settings a resumed run may change: the length of its last phase."""


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


_STANDING_ROT: np.ndarray | None = None


def standing_rotations() -> np.ndarray:
    """``(24, 3, 3)`` global joint rotations of the standing rest pose facing world +y
    (:func:`grip.core.mjcf.standing_qpos`; the same for every body)."""
    global _STANDING_ROT
    if _STANDING_ROT is None:
        from grip.core.fk import forward_kinematics
        from grip.core.mjcf import standing_qpos
        from grip.core.reference import local_rot_from_qpos

        q = standing_qpos()
        offsets = np.zeros((sk.N_JOINTS, 3))
        _STANDING_ROT = forward_kinematics(local_rot_from_qpos(q[None]), q[None, :3], offsets)[0][0]
    return _STANDING_ROT


def heading_of_feet(x_raw: torch.Tensor, sites: tuple[str, ...]) -> torch.Tensor:
    """``(B,)`` heading (rad about world z from facing +y) of each window's first frame from
    its foot IMUs, as :func:`grip.kinematics.features.sensor_heading` reads a recording without
    ground truth (raw, unnormalised features ``(B, T, F)``; other sites when there is no foot)."""
    from grip.kinematics.features import HEADING_SITES

    idx = [i for i, s in enumerate(sites) if s in HEADING_SITES] or list(range(len(sites)))
    imu = x_raw[:, 0, : 15 * len(sites)].reshape(x_raw.shape[0], len(sites), 15)[:, idx]
    fwd = imu[..., 6:15].reshape(*imu.shape[:2], 3, 3)[..., :, 2]  # canonical z in the world
    psi = torch.atan2(-fwd[..., 0], fwd[..., 1])
    return torch.atan2(torch.sin(psi).mean(1), torch.cos(psi).mean(1))


def standing_first(psi: torch.Tensor, offsets: torch.Tensor) -> dict[str, torch.Tensor]:
    """KinematicsNet's first-frame states ``{stage: (B, dim)}`` of the standing rest pose turned
    to ``psi (B,)``, at rest (:func:`grip.kinematics.features.first_state` of
    :func:`grip.kinematics.features.standing_calibration`, batched), for bodies ``offsets (B,
    24, 3)``."""
    c, s = torch.cos(psi), torch.sin(psi)
    z, o = torch.zeros_like(c), torch.ones_like(c)
    yaw = torch.stack([c, -s, z, s, c, z, z, z, o], -1).reshape(-1, 1, 3, 3)
    g = yaw @ torch.from_numpy(standing_rotations()).to(psi.dtype)  # (B, 24, 3, 3)
    fa = torch.cat([g[..., :, 0], g[..., :, 1]], -1).reshape(-1, 1, 24 * 6)
    fp = fk_positions(fa, offsets.to(psi.dtype))[:, 0]
    leaf = fp.reshape(-1, 24, 3)[:, list(sk.LEAF_JOINTS)].reshape(len(psi), -1)
    lv = torch.zeros(len(psi), 3 * len(sk.VELOCITY_JOINTS), dtype=psi.dtype)
    return {"lp": leaf, "fp": fp, "fa": fa[:, 0], "lv": lv}


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
                 val_seqs: list[SequenceArrays], run_dir: str | os.PathLike,
                 sources: Mapping[str, str] | None = None) -> None:  # fmt: skip
        """``sources``: training sequence name -> source, for ``train.source_balance``
        (:func:`grip.kinematics.dataset.sequence_sources`; default: every sequence its own)."""
        if not train_seqs:
            raise ValueError("no training sequences")
        self.cfg = cfg
        self.rundir = RunDir(run_dir, RESUMABLE, "'grip kin train' run")
        self.run_dir = self.rundir.path
        self.train_seqs = train_seqs
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
        self.weights = training_weights(train_seqs, sources or {}, cfg.train.source_balance,
                                        cfg.train.category_balance)  # fmt: skip
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
        if augment and self.cfg.train.standing_init > 0:
            yt = self._standing_starts(xt, yt)
        xt = (xt - torch.from_numpy(self.norm.mean)) / torch.from_numpy(self.norm.std)
        if augment and self.cfg.train.acc_noise > 0:
            idx = torch.tensor([s * 15 + k for s in range(n_sites) for k in range(3)])
            xt[..., idx] += self.cfg.train.acc_noise * torch.from_numpy(
                self.rng.standard_normal((*xt.shape[:2], len(idx))).astype(np.float32)
            )
        return xt, yt

    def _standing_starts(self, xt: torch.Tensor, yt: dict[str, torch.Tensor]):
        """A share ``train.standing_init`` of the windows starts its LSTMs from the standing
        pose at the heading of the foot IMUs instead of the first frame's ground truth (what
        ``--init standing`` and a recording without ground truth do), so that the network
        learns to converge from there: ``yt`` gains ``first/<stage>`` start states."""
        first = {k: yt[k][:, 0].clone() for k in TARGET_KEYS}
        pick = torch.from_numpy(self.rng.random(xt.shape[0]) < self.cfg.train.standing_init)
        if pick.any():
            stand = standing_first(heading_of_feet(xt[pick], self.cfg.features.sites),
                                   yt["offsets"][pick])  # fmt: skip
            for k in TARGET_KEYS:
                first[k][pick] = stand[k].to(first[k].dtype)
        return {**yt, **{f"first/{k}": v for k, v in first.items()}}

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
        first = {k: y.get(f"first/{k}", y[k][:, 0]) for k in TARGET_KEYS}
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
        x, y = sample_windows(self.train_seqs, tc.batch_size, tc.window_frames, self.rng,
                              self.weights, tc.first_frame_share)  # fmt: skip
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
        save_checkpoint(path, self.state())

    def load(self, path: Path) -> None:
        """Resume from a checkpoint of the same configuration.

        Only ``train.joint_epochs`` may differ (to extend or shorten a run's last phase), as
        long as the checkpoint is still in the stage-wise phase or within the new length.
        """
        ck = load_checkpoint(path)
        # settings added since the run began count as their defaults
        old = drop_removed(json.loads(ck["config"]), REMOVED_SETTINGS, str(path))
        require_same_settings(old, asdict(self.cfg), path, "",
                              may_change=self.rundir.may_change,
                              defaults=asdict(KinematicsRunConfig()),
                              what="checkpoint was trained with another configuration")  # fmt: skip
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
    return save_checkpoint(dst, out)


