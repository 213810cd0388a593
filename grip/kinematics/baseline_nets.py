"""Networks of the TransPose and PIP kinematics baselines (:mod:`grip.kinematics.baselines`)
and their losses."""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import nn
from torch.nn import functional as F

from grip.core import skeleton as sk
from grip.kinematics.baseline_config import PipNetConfig, RunConfig, TransPoseConfig, n_inputs

N_LEAF = len(sk.LEAF_JOINTS)
N_JOINTS_REL = sk.N_JOINTS - 1
"""Joints with a root-relative position (all but the pelvis)."""


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
