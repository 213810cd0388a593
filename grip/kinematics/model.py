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
        self.lstm = nn.LSTM(cfg.hidden, cfg.hidden, cfg.layers, batch_first=True)
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
        out, state = self.lstm(self.proj(x), state)
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
        inp = x
        frozen = only is not None
        for name in STAGES:
            if name == only:
                frozen = False
            # Stage-wise training: the stages before ``only`` run without gradients, so that
            # training one stage never changes the ones it reads from.
            with torch.set_grad_enabled(torch.is_grad_enabled() and not frozen):
                y, new_state[name] = self.stages[name](inp, state[name])
            outs[name] = y
            if name == only:
                break
            inp = torch.cat([inp, y], dim=-1)
        return outs, new_state
