"""Kinematics networks of the TransPose and PIP baselines, adapted to 4 IMUs (+ insoles).

BASELINES_AND_METRICS.md section 2. Both methods read, per frame, the world-frame free
accelerations of the 4 wearables divided by 30 (12 values) and their world orientations (36), plus
the 10 insole values in the "+I" variants: 48 / 58 inputs, standardised with the training-set
:class:`~grip.kinematics.dataset.Normalizer`. There is no pelvis IMU to express them in, so the
inputs stay in the world frame, training rotates every window about the vertical by a random angle
(:func:`~grip.nn.symmetry.rotate_batch`), and the rotation network outputs all 24 global
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

Training (:class:`~grip.kinematics.baseline_train.BaselineTrainer`) follows both papers in training
every net on its own, fed with the ground truth of the stages before it plus Gaussian noise
(TransPose: leaf 0.04 m for s2 and b1, joints 0.025 m for s3 and b2). All nets of a method are
updated in the same step from one batch; their parameters are disjoint and Adam scales each
parameter on its own, so this equals training them one after the other on the same windows. Losses:
L2 on positions and 6D rotations, binary cross-entropy on contacts, and TransPose's cumulative
velocity loss ``sum_n sum_m || sum_{t in block m of n frames} (v^ - v) ||^2`` (n = 1, 3, 9, 27) on
``b2`` and ``v_a``. ``b2`` learns only from windows in which some frame has no foot contact
(TransPose trained it on such clips), unless ``b2_flight_windows_only`` is off.

Inference (:class:`BaselineEstimator`): TransPose offline runs its bidirectional nets over the
whole sequence; its online mode runs them on a sliding window of 33 past + 1 + 8 future frames
(TransPose's 20 + 1 + 5 at 60 Hz; latency 80 ms) and ``b2`` causally over the sequence (the
reference online code instead re-runs ``b2`` on each window from a carried state). PIP's nets
are causal, so its offline and online outputs are the same.

Modules: :mod:`~grip.kinematics.baseline_config` (settings and input columns),
:mod:`~grip.kinematics.baseline_nets` (networks and losses),
:mod:`~grip.kinematics.baseline_train` (targets, data and trainer); this one holds the estimator
and the export.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import torch

from grip.core import skeleton as sk
from grip.core.body import build_body
from grip.core.fk import forward_kinematics
from grip.core.rotations import sixd_to_matrix
from grip.kinematics.baseline_config import (
    RunConfig,
    config_from_json,
    feature_config,
    input_columns,
)
from grip.kinematics.baseline_nets import (
    N_JOINTS_REL,
    N_LEAF,
    PipNets,
    TransPoseNets,
    _cat,
    build_nets,
)
from grip.kinematics.dataset import Normalizer
from grip.kinematics.features import (
    input_features,
    recording_body,
    recording_calibration,
    targets,
)
from grip.kinematics.train import export_for_inference
from grip.nn.weights import check_declared_network, load_checkpoint, unpack_weights


def export_baseline(src: str | os.PathLike, dst: str | os.PathLike, precision: str = "fp16") -> int:
    """Write a small inference-only copy of a baseline checkpoint (weights at ``precision``,
    :func:`grip.nn.weights.pack_weights`; no optimiser state). Returns the file size,
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
        check_declared_network(lambda: build_nets(cfg), ck["model"], str(path),
                               f"its config ({cfg.method}: {cfg.net})",
                               {"layers": cfg.net.layers})  # fmt: skip
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

    def first_quantities(self, rec, gt_init_velocity: bool, init: str = "truth"
                         ) -> tuple[torch.Tensor, torch.Tensor]:  # fmt: skip
        """PIP's learned-init inputs from a recording's first (ground-truth) frame, or with
        ``init="standing"`` from the standing calibration pose
        (:func:`grip.kinematics.features.standing_calibration`: no ground-truth pose read).

        Returns:
            ``(1, 15)`` leaf positions (root or world frame per ``init_leaf_frame``), m, and
            ``(1, 72)`` joint velocities in the root frame / vel_scale (zeros unless
            ``gt_init_velocity``; always zero standing, at rest).

        Raises:
            ValueError: ``init`` is not one of :data:`grip.kinematics.features.INITS`.
        """
        if init == "truth":
            t = targets(rec.slice_frames(0, 2) if rec.n_frames > 2 else rec)
            g_rot, pos, lp0 = t.global_rot, t.joint_pos + t.root_pos[:, None], t.leaf_pos[0]
        else:  # the calibration's two frames (the same pose: zero velocity)
            cal = recording_calibration(rec, self.features, init)
            offsets = build_body(recording_body(rec)).offsets
            g_rot, pos = forward_kinematics(cal.local_rot, cal.root_pos, offsets)
            lp0 = (pos[0] - pos[0, :1])[list(sk.LEAF_JOINTS)]
        if self.cfg.net.init_leaf_frame == "root":
            lp0 = lp0 @ g_rot[0, 0]  # R^T p for each row
        vel0 = np.zeros((sk.N_JOINTS, 3))
        if gt_init_velocity and rec.n_frames > 1:
            vel0 = (pos[1] - pos[0]) * float(rec.fps) @ g_rot[0, 0] / self.cfg.net.vel_scale
        return (torch.from_numpy(lp0.reshape(1, -1).astype(np.float32)),
                torch.from_numpy(vel0.reshape(1, -1).astype(np.float32)))  # fmt: skip

    def predict(
        self,
        recs,
        online: bool = False,
        gt_init_velocity: bool = False,
        insole_contact: bool = False,
        init: str = "truth",
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
            init: PIP: the learned initialisation from the first frame's ground truth
                (``"truth"``) or the standing calibration (``"standing"``,
                :meth:`first_quantities`); TransPose: no effect (no learned initialisation).

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
                    o = self.nets(x, *self.first_quantities(rec, gt_init_velocity, init))[0]
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
