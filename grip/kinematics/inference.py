"""KinematicsNet inference: offline (whole sequences, batched) and streaming (one frame)."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass

import numpy as np
import torch

from grip.core.body import build_body
from grip.core.fk import integrate_root, joints_from_global
from grip.core.rotations import sixd_to_matrix
from grip.kinematics.dataset import TARGET_KEYS, Normalizer
from grip.kinematics.features import input_features, recording_body, targets
from grip.kinematics.model import KinematicsNet
from grip.kinematics.train import load_checkpoint, run_config_from_dict, unpack_weights


@dataclass
class KinematicEstimate:
    """KinematicsNet output for one recording (world axes, m, rad).

    Attributes:
        leaf_pos: ``(T, 5, 3)`` root-relative leaf joints (the LP stage).
        joint_pos: ``(T, 24, 3)`` root-relative joints of the estimated pose: forward
            kinematics of ``global_rot`` on the subject's body, as TransPose and PIP evaluate
            their poses (posed SMPL with the true shape); closer to the truth than the FP
            stage's own joints (``grip eval-kin --joints fp`` measures those; README, issue 3).
        global_rot: ``(T, 24, 3, 3)`` global joint rotations (the FA stage).
        velocity: ``(T, 6, 3)`` world velocities of the leaves and the pelvis, m/s (LV).
        root_pos: ``(T, 3)`` pelvis trajectory integrated from the estimated pelvis velocity,
            starting at the first frame's ground-truth root position.
        fp_joint_pos: ``(T, 24, 3)`` root-relative joints as the FP stage estimates them (an
            intermediate the later stages read; not constrained to the body's bone lengths).
    """

    leaf_pos: np.ndarray
    joint_pos: np.ndarray
    global_rot: np.ndarray
    velocity: np.ndarray
    root_pos: np.ndarray
    fp_joint_pos: np.ndarray


def decode_outputs(o: dict[str, np.ndarray], n: int, offsets: np.ndarray) -> tuple[np.ndarray, ...]:
    """KinematicsNet outputs of ``n`` frames (``(n, dim)`` or flat, float64) on a body with
    rest ``offsets (24, 3)`` -> root-relative joints ``(n, 24, 3)`` (forward kinematics of the
    rotations), global rotations ``(n, 24, 3, 3)`` and the velocities of the velocity joints
    ``(n, 6, 3)``: what offline and streaming inference hand on."""
    rot = sixd_to_matrix(o["fa"].reshape(n, 24, 6))
    return joints_from_global(rot, offsets), rot, o["lv"].reshape(n, 6, 3)


class KinematicsEstimator:
    """A trained KinematicsNet with its normaliser and feature settings."""

    def __init__(self, model: KinematicsNet, norm: Normalizer, cfg) -> None:
        self.model = model.eval()
        self.norm = norm
        self.cfg = cfg

    @classmethod
    def from_checkpoint(cls, path: str | os.PathLike) -> KinematicsEstimator:
        ck = load_checkpoint(path)
        cfg = run_config_from_dict(json.loads(ck["config"]))
        model = KinematicsNet(cfg.net_config())
        model.load_state_dict(unpack_weights(ck["model"]))
        norm = Normalizer(ck["norm_mean"].float().numpy(), ck["norm_std"].float().numpy())
        return cls(model, norm, cfg)

    # ------------------------------------------------------------------ offline
    def _first(self, recs) -> dict[str, torch.Tensor]:
        firsts = []
        for rec in recs:
            t = targets(rec.slice_frames(0, 2) if rec.n_frames > 2 else rec)
            firsts.append({
                "lp": t.leaf_pos[0].reshape(-1), "fp": t.joint_pos[0].reshape(-1),
                "fa": t.rot6d[0].reshape(-1), "lv": t.velocity[0].reshape(-1) * 0.0,
            })  # fmt: skip
        return {k: torch.from_numpy(np.stack([f[k] for f in firsts]).astype(np.float32))
                for k in TARGET_KEYS}  # fmt: skip

    def predict(self, recs) -> list[KinematicEstimate]:
        """Estimates for a list of recordings, run as one padded batch per call.

        The first frame's ground truth (the calibration pose) initialises the LSTMs; the initial
        velocities are taken as zero, as at the start of a real recording.
        """
        feats = [self.norm(input_features(r, self.cfg.features)) for r in recs]
        t_max = max(len(f) for f in feats)
        x = np.zeros((len(feats), t_max, feats[0].shape[1]), dtype=np.float32)
        for i, f in enumerate(feats):
            x[i, : len(f)] = f
            x[i, len(f) :] = f[-1]  # causal model: padding never affects earlier frames
        with torch.no_grad():
            out, _ = self.model(torch.from_numpy(x), self.model.initial_state(self._first(recs)))
        res = []
        for i, rec in enumerate(recs):
            n = rec.n_frames
            o = {k: v[i, :n].numpy().astype(np.float64) for k, v in out.items()}
            res.append(self._estimate(o, rec, n))
        return res

    def _estimate(self, o: dict[str, np.ndarray], rec, n: int) -> KinematicEstimate:
        joint_pos, global_rot, vel = decode_outputs(o, n, build_body(recording_body(rec)).offsets)
        root0 = np.asarray(rec.smpl_params.trans[0], dtype=np.float64) + np.asarray(
            rec.smpl_params.root_offset, dtype=np.float64)  # fmt: skip
        return KinematicEstimate(
            leaf_pos=o["lp"].reshape(n, 5, 3),
            joint_pos=joint_pos,
            global_rot=global_rot,
            velocity=vel,
            root_pos=integrate_root(root0, vel[:, -1], rec.fps),
            fp_joint_pos=o["fp"].reshape(n, 24, 3),
        )

    # ------------------------------------------------------------------ streaming
    def stream(self, rec_first_frame):
        """A :class:`StreamingEstimator` initialised from a recording's first frame."""
        return StreamingEstimator(self, self._first([rec_first_frame]))


class StreamingEstimator:
    """One frame in, one frame out, LSTM state carried between calls.

    Feed it normalised-ready raw feature rows (``input_features`` of one frame). Batch-1 LSTM
    steps run with oneDNN disabled, which DESIGN.md measured ~5x faster on this CPU.
    """

    def __init__(self, est: KinematicsEstimator, first: dict[str, torch.Tensor]) -> None:
        self.est = est
        with torch.no_grad():
            self.state = est.model.initial_state(first)
        self.mean = torch.from_numpy(est.norm.mean)
        self.std = torch.from_numpy(est.norm.std)

    def step(self, feature_row: np.ndarray) -> dict[str, np.ndarray]:
        """``(F,)`` raw features of one frame -> ``{stage: (dim,)}``."""
        x = (torch.from_numpy(np.asarray(feature_row, dtype=np.float32)) - self.mean) / self.std
        prev = torch.backends.mkldnn.set_flags(False)  # (the flags() context warns per call)
        try:
            with torch.no_grad():
                out, self.state = self.est.model(x.view(1, 1, -1), self.state)
        finally:
            torch.backends.mkldnn.set_flags(prev[0])
        return {k: v[0, 0].numpy() for k, v in out.items()}
