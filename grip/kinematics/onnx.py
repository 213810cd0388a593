"""KinematicsNet as two ONNX graphs for streaming outside Python: the step and its start.

* **Step** (``FILE.onnx``): one frame in, one frame out, LSTM states carried by the caller.
  Inputs ``features (B, F)`` (raw sensor features of one frame, the layout of
  :func:`grip.kinematics.features.input_features`; the checkpoint's normaliser ``(x - mean) /
  std`` is inside the graph), ``h (4 L, B, H)`` and ``c (4 L, B, H)``; outputs ``outputs (B,
  249)``, ``h_out`` and ``c_out``. It is :class:`grip.kinematics.model.FrameStep`'s
  computation, what :meth:`grip.kinematics.inference.StreamingEstimator.step` runs.
* **Start** (``FILE_init.onnx``): ``first_state (B, 249)`` -> ``h (4 L, B, H)``, ``c (4 L, B,
  H)``: the learned initial states from the calibration pose
  (:meth:`grip.kinematics.model.KinematicsNet.initial_state`), run once per recording.

Layouts (also in each file's ``metadata_props``, JSON where structured):

* ``outputs`` and ``first_state`` share one row layout: the stages side by side, ``lp`` 0:15
  (root-relative leaf joints, m), ``fp`` 15:87 (root-relative joints, m), ``fa`` 87:231 (global
  joint rotations as 6D: the first two columns of each matrix), ``lv`` 231:249 (world velocities
  of the leaves and the pelvis, m/s). The first state is the calibration pose in that layout
  with its velocities (zero for a standing start; :func:`grip.kinematics.features.first_state`).
* State row ``k = stage * L + layer`` (stages in the order lp, fp, fa, lv) holds that LSTM
  layer's hidden (``h``) or cell (``c``) state.

Test-time augmentation (``--tta``) is not part of the graphs: they are the plain network.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from grip.kinematics.model import STAGE_DIMS, STAGES, KinematicsNet
from grip.nn.onnx import onnx_bytes, write_onnx

FORMAT = "grip-kinematics-onnx"
VERSION = 1
N_OUT = sum(STAGE_DIMS.values())
"""Width of an output (and first-state) row: 249."""


def init_path(out: str | os.PathLike) -> Path:
    """Where the start graph of step file ``out`` goes: ``STEM_init.onnx`` beside it."""
    out = Path(out)
    return out.with_name(f"{out.stem}_init.onnx")


class KinematicsStep(nn.Module):
    """One frame of KinematicsNet with its input normaliser, states as two stacked tensors.

    Args:
        net: The network (its weights are shared, not copied).
        mean, std: ``(F,)`` the checkpoint's input normaliser.
    """

    def __init__(self, net: KinematicsNet, mean: torch.Tensor, std: torch.Tensor) -> None:
        super().__init__()
        self.net = net.eval()
        self.layers = net.cfg.layers
        self.register_buffer("mean", mean.float().reshape(-1))
        self.register_buffer("std", std.float().reshape(-1))

    def forward(self, features: torch.Tensor, h: torch.Tensor, c: torch.Tensor):
        """``(B, F)`` raw features and ``(4 L, B, H)`` states -> ``(B, 249)`` outputs and the
        new states."""
        x = (features - self.mean) / self.std
        inp = x
        hs, cs = [], []
        for j, name in enumerate(STAGES):
            stage = self.net.stages[name]
            a = torch.relu(stage.proj[0](inp))
            for i in range(self.layers):
                k = j * self.layers + i
                w_ih, w_hh, b_ih, b_hh = (getattr(stage.lstm, f"{n}_l{i}") for n in
                                          ("weight_ih", "weight_hh", "bias_ih", "bias_hh"))
                gates = F.linear(a, w_ih, b_ih) + F.linear(h[k], w_hh, b_hh)
                gi, gf, gg, go = gates.chunk(4, dim=1)  # torch's gate order: i, f, g, o
                c_new = torch.sigmoid(gf) * c[k] + torch.sigmoid(gi) * torch.tanh(gg)
                a = torch.sigmoid(go) * torch.tanh(c_new)
                hs.append(a)
                cs.append(c_new)
            inp = torch.cat([inp, stage.head(a)], dim=1)
        return inp[:, x.shape[1] :], torch.stack(hs), torch.stack(cs)


class KinematicsStart(nn.Module):
    """The learned initial LSTM states of a first-frame state row ``(B, 249)``."""

    def __init__(self, net: KinematicsNet) -> None:
        super().__init__()
        self.net = net.eval()

    def forward(self, first_state: torch.Tensor):
        """``(B, 249)`` -> ``h``, ``c`` of ``(4 L, B, H)``."""
        hs, cs = [], []
        start = 0
        for name in STAGES:
            dim = STAGE_DIMS[name]
            h, c = self.net.stages[name].initial_state(first_state[:, start : start + dim])
            hs.append(h)
            cs.append(c)
            start += dim
        return torch.cat(hs), torch.cat(cs)


def kinematics_metadata(est, source: str) -> dict[str, str]:
    """The ``metadata_props`` both graphs of an estimator's network carry."""
    cfg = est.model.cfg
    slices, start = {}, 0
    for name in STAGES:
        slices[name] = [start, start + STAGE_DIMS[name]]
        start += STAGE_DIMS[name]
    feats = est.cfg.features
    layout = [f"{s}: acc/{feats.acc_scale:g} (3), angular velocity rad/s (3), orientation "
              "row-major (9)" for s in feats.sites]  # fmt: skip
    if feats.insoles:
        layout.append("insoles: per foot L, R [force (body weights), CoP x, CoP y (m), front, "
                      "back contact] (10)")  # fmt: skip
    return {
        "format": FORMAT,
        "version": str(VERSION),
        "source": source,
        "n_features": str(feats.n_features),
        "feature_layout": json.dumps(layout),
        "feature_config": json.dumps(dataclasses.asdict(feats)),
        "hidden": str(cfg.hidden),
        "layers": str(cfg.layers),
        "stages": json.dumps(list(STAGES)),
        "state_rows": f"{len(STAGES) * cfg.layers}: row stage * {cfg.layers} + layer, stages in "
                      "'stages' order",
        "output_slices": json.dumps(slices),
        "normalised_inside": "true",
    }  # fmt: skip


def export_kinematics_onnx(checkpoint: str | os.PathLike, out: str | os.PathLike
                           ) -> tuple[tuple[Path, int], tuple[Path, int]]:  # fmt: skip
    """Write the step graph of a KinematicsNet checkpoint to ``out`` and its start graph to
    :func:`init_path` of ``out``.

    Returns:
        ``(path, bytes)`` of the step file and of the start file.

    Raises:
        FileNotFoundError: No such checkpoint.
        ValueError: naming the file, when it is no KinematicsNet checkpoint (a baseline's
            networks are not exported to ONNX).
        ImportError: ``onnx`` is not installed.
        OSError: A file cannot be written.
    """
    from grip.kinematics.inference import KinematicsEstimator
    from grip.nn.weights import load_checkpoint

    checkpoint = Path(checkpoint)
    ck = load_checkpoint(checkpoint)
    try:
        cfg_d = json.loads(ck["config"])
    except (TypeError, ValueError) as e:
        raise ValueError(f"{checkpoint}: unreadable config ({e})") from e
    if isinstance(cfg_d, dict) and "method" in cfg_d:
        raise ValueError(f"{checkpoint}: a {cfg_d['method']} baseline checkpoint; only "
                         "KinematicsNet is exported to ONNX")  # fmt: skip
    try:
        est = KinematicsEstimator.from_checkpoint(checkpoint)
    except (KeyError, TypeError, RuntimeError) as e:
        raise ValueError(f"{checkpoint}: not a KinematicsNet checkpoint ({e})") from e
    net, n_f = est.model, est.cfg.features.n_features
    rows, hid = len(STAGES) * net.cfg.layers, net.cfg.hidden
    meta = kinematics_metadata(est, str(checkpoint))
    step = onnx_bytes(
        KinematicsStep(net, torch.from_numpy(est.norm.mean), torch.from_numpy(est.norm.std)),
        (torch.zeros(1, n_f), torch.zeros(rows, 1, hid), torch.zeros(rows, 1, hid)),
        ["features", "h", "c"], ["outputs", "h_out", "c_out"],
        {"features": {0: "batch"}, "h": {1: "batch"}, "c": {1: "batch"},
         "outputs": {0: "batch"}, "h_out": {1: "batch"}, "c_out": {1: "batch"}},
        {**meta, "graph": "step"},
        "GRIP KinematicsNet, one frame: raw features + LSTM states -> outputs + states; "
        "start the states with the _init graph",
    )  # fmt: skip
    start = onnx_bytes(
        KinematicsStart(net), (torch.zeros(1, N_OUT),), ["first_state"], ["h", "c"],
        {"first_state": {0: "batch"}, "h": {1: "batch"}, "c": {1: "batch"}},
        {**meta, "graph": "init"},
        "GRIP KinematicsNet, start: the calibration pose as a first-state row -> initial LSTM "
        "states",
    )  # fmt: skip
    out, first = Path(out), init_path(out)
    return (out, write_onnx(out, step)), (first, write_onnx(first, start))
