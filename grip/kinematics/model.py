"""KinematicsNet: four unidirectional LSTM stages (LP -> FP -> FA -> LV), GRIP Sec. 3.2.

- LP: root-relative positions of the 5 leaf joints (wrists, ankles, head), ``5 x 3``.
- FP: root-relative positions of all 24 joints, ``24 x 3``.
- FA: global rotations of the 24 joints, 6D, ``24 x 6``.
- LV: world velocities of the leaves and the pelvis, ``6 x 3``.

Each stage sees the sensor features and the outputs of the stages before it. As in PIP, a small
network maps each stage's first-frame ground-truth state (at inference: the calibration pose) to
the initial hidden and cell states of its LSTM ("learning-based initialisation").
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

STAGES: tuple[str, ...] = ("lp", "fp", "fa", "lv")
STAGE_DIMS: dict[str, int] = {"lp": 15, "fp": 72, "fa": 144, "lv": 18}


@dataclass(frozen=True)
class KinematicsNetConfig:
    """Network sizes.

    Attributes:
        n_inputs: Sensor features per frame (``FeatureConfig.n_features``).
        hidden: LSTM width of every stage (GRIP: 512).
        layers: LSTM layers per stage (GRIP: 3).
        init_hidden: Width of the initial-state networks.
        dropout: Dropout on each stage's input projection.
    """

    n_inputs: int
    hidden: int = 256
    layers: int = 2
    init_hidden: int = 256
    dropout: float = 0.0


State = dict[str, tuple[torch.Tensor, torch.Tensor]]


class _Stage(nn.Module):
    def __init__(self, n_in: int, n_out: int, cfg: KinematicsNetConfig) -> None:
        super().__init__()
        self.layers, self.hidden = cfg.layers, cfg.hidden
        self.proj = nn.Sequential(nn.Linear(n_in, cfg.hidden), nn.ReLU(), nn.Dropout(cfg.dropout))
        # time-major: KinematicsNet.forward transposes its input once for all the stages
        # instead of nn.LSTM copying it to and from time-major in every stage
        self.lstm = nn.LSTM(cfg.hidden, cfg.hidden, cfg.layers)
        self.head = nn.Linear(cfg.hidden, n_out)
        self.init = nn.Sequential(
            nn.Linear(n_out, cfg.init_hidden), nn.ReLU(),
            nn.Linear(cfg.init_hidden, 2 * cfg.layers * cfg.hidden),
        )  # fmt: skip

    def initial_state(self, y0: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(B, n_out)`` first-frame state -> ``(h0, c0)``, each ``(layers, B, hidden)``."""
        hc = self.init(y0).view(y0.shape[0], 2, self.layers, self.hidden)
        return hc[:, 0].transpose(0, 1).contiguous(), hc[:, 1].transpose(0, 1).contiguous()

    def forward(self, x: torch.Tensor, state: tuple[torch.Tensor, torch.Tensor]):
        """``(T, B, n_in)`` time-major inputs -> ``(T, B, n_out)`` outputs and the new state."""
        lin, drop = self.proj[0], self.proj[2]
        # (the ReLU in place: one pass over the projection less; autograd keeps its result)
        a = drop(torch.relu_(F.linear(x, lin.weight, lin.bias)))
        out, state = self.lstm(a, state)
        return self.head(out), state


class KinematicsNet(nn.Module):
    """The four-stage estimator. Inputs are normalised features ``(B, T, n_inputs)``."""

    def __init__(self, cfg: KinematicsNetConfig) -> None:
        super().__init__()
        self.cfg = cfg
        n_in = cfg.n_inputs
        stages = {}
        for name in STAGES:
            stages[name] = _Stage(n_in, STAGE_DIMS[name], cfg)
            n_in += STAGE_DIMS[name]
        self.stages = nn.ModuleDict(stages)

    def initial_state(self, first: dict[str, torch.Tensor]) -> State:
        """Initial LSTM states from first-frame ground truth ``{stage: (B, dim)}``."""
        return {n: self.stages[n].initial_state(first[n]) for n in STAGES}

    def forward(
        self, x: torch.Tensor, state: State, only: str | None = None
    ) -> tuple[dict[str, torch.Tensor], State]:
        """Run the stages over a sequence (or one frame with ``T = 1``).

        Args:
            x: ``(B, T, n_inputs)`` normalised features.
            state: Per-stage ``(h, c)`` from :meth:`initial_state` or a previous call.
            only: Stop after this stage (stage-wise training); the stages before it are run
                without gradients.

        Returns:
            ``{stage: (B, T, dim)}`` outputs and the new states.
        """
        outs: dict[str, torch.Tensor] = {}
        new_state: State = {}
        inp = x.transpose(0, 1).contiguous()  # time-major for the LSTMs
        frozen = only is not None
        for name in STAGES:
            if name == only:
                frozen = False
            # Stage-wise training: the stages before ``only`` run without gradients, so that
            # training one stage never changes the ones it reads from.
            with torch.set_grad_enabled(torch.is_grad_enabled() and not frozen):
                y, new_state[name] = self.stages[name](inp, state[name])
            outs[name] = y.transpose(0, 1).contiguous()
            if name == only:
                break
            inp = torch.cat([inp, y], dim=-1)
        return outs, new_state


class FrameStep:
    """:meth:`KinematicsNet.forward` for one frame, without module dispatch: the streaming path.

    Streaming runs the network once per frame at batch 1, where the per-call overhead of the
    modules (a ``Sequential`` per projection, ``nn.LSTM``'s checks and layout changes, a
    ``torch.cat`` per stage) costs several times the arithmetic. This keeps the weights
    pre-transposed and calls each LSTM layer's cell (``torch._VF.lstm_cell``, ``nn.LSTMCell``'s
    kernel) directly; the state is a flat list of per-layer tensors. The outputs equal
    :meth:`KinematicsNet.forward` on a ``T = 1`` sequence up to float rounding.

    Args:
        net: The network; its weights are copied (after training it further, build another).
    """

    def __init__(self, net: KinematicsNet) -> None:
        self.layers = net.cfg.layers
        self._stages = []
        for name in STAGES:
            s = net.stages[name]
            lin = s.proj[0]
            # each weight (4 hidden, n) as a transposed view of its (n, 4 hidden) copy: the
            # cell's ``x @ w.T`` then reads the weight row by row, ~1.6x faster at batch 1
            cells = [(*(getattr(s.lstm, f"{w}_l{i}").detach().T.contiguous().T
                        for w in ("weight_ih", "weight_hh")),
                      *(getattr(s.lstm, f"{b}_l{i}").detach() for b in ("bias_ih", "bias_hh")))
                     for i in range(self.layers)]  # fmt: skip
            self._stages.append(
                (
                    lin.weight.detach().T.contiguous(),
                    lin.bias.detach(),
                    cells,
                    s.head.weight.detach().T.contiguous(),
                    s.head.bias.detach(),
                )
            )
        self.n_out = sum(STAGE_DIMS.values())

    def flat_state(self, state: State) -> list[torch.Tensor]:
        """Per-stage ``(h, c)`` of ``(layers, B, hidden)`` -> the flat list this step carries:
        ``[h, c]`` of ``(B, hidden)`` per layer, stage after stage."""
        return [t[i].contiguous() for n in STAGES for i in range(self.layers) for t in state[n]]

    def state(self, flat: list[torch.Tensor]) -> State:
        """The flat state back as per-stage ``(h, c)`` of ``(layers, B, hidden)``."""
        out: State = {}
        k = 2 * self.layers
        for j, name in enumerate(STAGES):
            part = flat[j * k : (j + 1) * k]
            out[name] = (torch.stack(part[0::2]), torch.stack(part[1::2]))
        return out

    def __call__(self, x: torch.Tensor, flat: list[torch.Tensor]) -> torch.Tensor:
        """One frame.

        Args:
            x: ``(B, n_inputs)`` normalised features.
            flat: The state (:meth:`flat_state`), updated in place (its entries are replaced).

        Returns:
            ``(B, 249)``: the stages' outputs side by side in :data:`STAGES` order.
        """
        inp = x
        lstm_cell = torch._VF.lstm_cell
        k = 0
        for w_p, b_p, cells, w_h, b_h in self._stages:
            a = torch.addmm(b_p, inp, w_p).relu_()
            for cell in cells:
                a, c = lstm_cell(a, (flat[k], flat[k + 1]), *cell)
                flat[k], flat[k + 1] = a, c
                k += 2
            inp = torch.cat((inp, torch.addmm(b_h, a, w_h)), 1)
        return inp[:, x.shape[1] :]
