"""A policy file as one ONNX graph: flat observation in, deterministic action out.

The graph computes what :meth:`policies.runner.PolicyRunner.act` computes without action
noise, and for a file of several members what :class:`policies.ensemble.PolicyEnsemble` does:

* input ``obs`` ``(B, N)`` float32: the observation parts of the tracking env concatenated in
  the order of ``obs_keys`` (each part flattened, as the policy reads it);
* per member: ``z = clip((obs - mean) / std, -clip_obs, clip_obs)`` with the member's own
  normaliser (``std = sqrt(var + 1e-8)``), then its actor MLP, then ``clip(., -1, 1)``;
* output ``action`` ``(B, A)`` float32 in [-1, 1]: the mean over the members.

The model's ``metadata_props`` (strings; JSON where structured) say how to build the input and
read the output: ``obs_keys``, ``obs_sizes`` and ``obs_slices`` (each part's columns),
``action_names`` (the humanoid's hinges, :func:`grip.core.mjcf.hinge_names`), ``env_config``
(the :class:`grip.task.config.TrackingEnvConfig` the policy was trained with: observation
variant, action mode and scale, decision period), ``members``, ``clip_obs`` and ``source``.
The discriminator (GRIP's fall detector) and the value networks are not exported. Mirror
averaging (``grip policy eval --mirror``) is not part of the graph.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Sequence

import numpy as np
import torch
from torch import nn

from grip.core.mjcf import hinge_names
from grip.nn.onnx import onnx_bytes, write_onnx

FORMAT = "grip-policy-onnx"
VERSION = 1
INPUT = "obs"
OUTPUT = "action"


class PolicyGraph(nn.Module):
    """The deterministic action of one or several policies as one traceable module.

    Args:
        members: :class:`policies.runner.PolicyRunner` objects (one, or an ensemble's
            ``members``); they must read the same observation parts.

    Raises:
        ValueError: No member, or members whose observations differ.
    """

    def __init__(self, members: Sequence) -> None:
        super().__init__()
        if not members:
            raise ValueError("no policy to export")
        first = members[0]
        for i, m in enumerate(members[1:], 1):
            if list(m.obs_keys) != list(first.obs_keys) or m._mean.shape != first._mean.shape:
                raise ValueError(f"member {i} reads other observations ({m.obs_keys}, "
                                 f"{m._mean.size} values) than member 0 ({first.obs_keys}, "
                                 f"{first._mean.size})")  # fmt: skip
        self.actors = nn.ModuleList([m.actor for m in members])
        self.register_buffer("mean", torch.from_numpy(
            np.stack([m._mean for m in members]).astype(np.float32)))  # fmt: skip
        self.register_buffer("std", torch.from_numpy(
            np.stack([m._std for m in members]).astype(np.float32)))  # fmt: skip
        self.clips = [float(m.clip_obs) for m in members]

    @property
    def n_obs(self) -> int:
        return int(self.mean.shape[1])

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """``(B, N)`` flat observations -> ``(B, A)`` mean action in [-1, 1]."""
        acts = []
        for i, actor in enumerate(self.actors):
            z = torch.clamp((obs - self.mean[i]) / self.std[i], -self.clips[i], self.clips[i])
            acts.append(torch.clamp(actor(z), -1.0, 1.0))
        if len(acts) == 1:
            return acts[0]
        return torch.stack(acts).mean(dim=0)


def _members(controller) -> list:
    """The :class:`~policies.runner.PolicyRunner` objects behind a controller."""
    members = getattr(controller, "members", None)
    return list(members) if members is not None else [controller]


def policy_metadata(controller, source: str) -> dict[str, str]:
    """The ``metadata_props`` of the ONNX file of ``controller`` (the module docstring)."""
    members = _members(controller)
    sizes = {k: int(np.asarray(members[0].obs_mean[k]).size) for k in controller.obs_keys}
    starts = np.concatenate([[0], np.cumsum(list(sizes.values()))]).tolist()
    slices = {k: [int(starts[i]), int(starts[i + 1])] for i, k in enumerate(sizes)}
    n_act = int(members[0].actor[-1].out_features)
    names = hinge_names()
    return {
        "format": FORMAT,
        "version": str(VERSION),
        "source": source,
        "input": f"{INPUT}: (B, {starts[-1]}) float32, the observation parts concatenated in "
                 "obs_keys order (obs_slices: each part's columns)",
        "output": f"{OUTPUT}: (B, {n_act}) float32 in [-1, 1], the deterministic action (the "
                  "mean over the members); env_config's action_mode and action_scale turn it "
                  "into PD targets of the hinges action_names",
        "obs_keys": json.dumps(list(controller.obs_keys)),
        "obs_sizes": json.dumps(sizes),
        "obs_slices": json.dumps(slices),
        "action_names": json.dumps(names if len(names) == n_act else []),
        "members": str(len(members)),
        "clip_obs": json.dumps([float(m.clip_obs) for m in members]),
        "env_config": json.dumps(dataclasses.asdict(controller.env_cfg)),
    }  # fmt: skip


def export_policy_onnx(files: str | os.PathLike | Sequence[str | os.PathLike],
                       out: str | os.PathLike,
                       source: str | None = None) -> tuple[int, int]:  # fmt: skip
    """Write the ONNX graph of one or several policy files (their members' mean action, as
    :func:`policies.controller.load_controller` plays them); returns the file's size in bytes
    and the number of members.

    Args:
        files: Policy files.
        out: The ``.onnx`` file to write (atomically).
        source: What the metadata names as the source (default: the files).

    Raises:
        FileNotFoundError: A policy file does not exist.
        ValueError: naming the file, when it is no policy file, a gated one, or its members do
            not fit.
        ImportError: ``onnx`` is not installed.
        OSError: ``out`` cannot be written.
    """
    from policies.controller import load_controller

    ctrl = load_controller(files)
    if getattr(ctrl, "gate", None) is not None:  # (policies.gate.GatedController)
        raise ValueError(f"{files}: a gated policy file (a classifier of the wearables picks "
                         "one member every frame), which the graph, one policy or an ensemble's "
                         "mean, cannot play: export one member (grip policy combine FILE "
                         "--member K --out M.pt)")  # fmt: skip
    graph = PolicyGraph(_members(ctrl))
    src = source or (files if isinstance(files, str | os.PathLike)
                     else ", ".join(map(str, files)))  # fmt: skip
    data = onnx_bytes(graph, (torch.zeros(1, graph.n_obs),), [INPUT], [OUTPUT],
                      {INPUT: {0: "batch"}, OUTPUT: {0: "batch"}},
                      policy_metadata(ctrl, str(src)),
                      "GRIP controller (DynamicsNet): flat observation -> deterministic action; "
                      "metadata_props say the layout")  # fmt: skip
    return write_onnx(out, data), len(graph.actors)
