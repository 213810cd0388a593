"""Weight averaging of exported policies (``grip policy-average``).

PPO's exports swing from one checkpoint to the next (README, "DynamicsNet"); the average of a
run's late exports, like the stochastic weight averaging of supervised training, sits between
the swings. The files must come from one run or its continuations: the same network, the same
observations, and weights near each other. The last file is the base: its observation
normaliser, discriminator, settings and notes go into the result.

Each file normalises its observations with its own running statistics, so its first layers
are first rewritten for the base's normaliser: with ``z_i = (x - m_i) / s_i`` and the base's
``z = (x - m) / s``, ``W_i z_i + b_i = (W_i diag(s / s_i)) z + (b_i + W_i ((m - m_i) / s_i))``,
exact up to the clipping of normalised values. The other layers and the log standard
deviation are averaged as they are.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from grip.core.atomic import atomic_write
from policies.runner import ENSEMBLE_FORMAT, FORMAT, load_weights

_SAME = ("actor_sizes", "critic_sizes", "obs_keys", "clip_obs")


def _load(path: Path) -> dict:
    ck = load_weights(path, "policy file")
    if isinstance(ck, dict) and ck.get("format") == ENSEMBLE_FORMAT:
        raise ValueError(f"{path}: an ensemble file; weight averaging takes single policies of "
                         "one run (grip policy-ensemble joins policies of any runs)")
    if not isinstance(ck, dict) or ck.get("format") != FORMAT:
        raise ValueError(f"{path}: not a GRIP policy file (format {FORMAT!r} expected)")
    missing = [k for k in ("config", "actor", "actor_sizes", "obs_keys", "obs_mean", "obs_var",
                           "clip_obs") if k not in ck]  # fmt: skip
    if missing:
        raise ValueError(f"{path}: policy file lacks {missing}")
    return ck


def _norm(ck: dict) -> tuple[np.ndarray, np.ndarray]:
    keys = ck["obs_keys"]
    mean = np.concatenate([np.asarray(ck["obs_mean"][k], np.float64) for k in keys])
    var = np.concatenate([np.asarray(ck["obs_var"][k], np.float64) for k in keys])
    return mean, np.sqrt(var + 1e-8)  # as PolicyRunner normalises


def _average_mlp(cks: list[dict], part: str, mean: np.ndarray, std: np.ndarray) -> dict:
    """The averaged state dict of MLP ``part`` (``actor`` or ``critic``), first layers rewritten
    for the normaliser ``mean, std``."""
    first = sorted(k for k in cks[0][part] if k.endswith(".weight"))[0].split(".")[0]
    norms = [_norm(ck) for ck in cks]
    out: dict[str, torch.Tensor] = {}
    for key in cks[0][part]:
        acc = None
        for ck, (m_i, s_i) in zip(cks, norms, strict=True):
            v = ck[part][key].double().numpy()
            if key.startswith(first + "."):
                w = ck[part][f"{first}.weight"].double().numpy()
                v = (
                    w * (std / s_i)[None]
                    if key.endswith("weight")
                    else v + w @ ((mean - m_i) / s_i)
                )
            acc = v if acc is None else acc + v
        ref = cks[-1][part][key]
        out[key] = torch.from_numpy(acc / len(cks)).to(ref.dtype)
    return out


def average_policies(paths: Sequence[str | os.PathLike], out: str | os.PathLike) -> int:
    """Write the weight average of exported policies to ``out``; returns its size in bytes.

    Raises:
        ValueError: Fewer than two files, a file that is not a policy, or files whose networks,
            observations or settings differ (named).
    """
    paths = [Path(p) for p in paths]
    if len(paths) < 2:
        raise ValueError("policy averaging needs at least two policy files")
    cks = [_load(p) for p in paths]
    base = cks[-1]
    for p, ck in zip(paths, cks, strict=True):
        for key in _SAME:
            if ck[key] != base[key]:
                raise ValueError(f"{p}: {key} {ck[key]} differs from {paths[-1]}'s {base[key]}")
        act, act_base = (json.loads(c["config"])["ppo"]["activation"] for c in (ck, base))
        if act != act_base:
            raise ValueError(f"{p}: activation {act} differs from {paths[-1]}'s {act_base}")
        for part in ("actor", "critic"):
            if (part in ck) != (part in base):
                raise ValueError(f"{p}: has {'no ' if part not in ck else ''}{part} network, "
                                 f"unlike {paths[-1]}")  # fmt: skip
    mean, std = _norm(base)
    payload = dict(base)
    payload["actor"] = _average_mlp(cks, "actor", mean, std)
    if "critic" in base:
        payload["critic"] = _average_mlp(cks, "critic", mean, std)
    if all("log_std" in ck for ck in cks):
        payload["log_std"] = torch.stack([ck["log_std"].float() for ck in cks]).mean(0)
    info = json.loads(base.get("info", "{}"))
    holdouts = {json.dumps(json.loads(ck.get("info", "{}")).get("holdout")) for ck in cks}
    if len(holdouts) > 1:
        info.pop("holdout", None)  # no clip set is held out of every file's training
    info["averaged"] = [str(p) for p in paths]
    payload["info"] = json.dumps(info)
    buf = io.BytesIO()
    torch.save(payload, buf)
    atomic_write(out, lambda f: f.write(buf.getvalue()))
    return len(buf.getvalue())
