"""Weight averaging of exported policies (``grip policy combine --average``).

PPO's exports swing from one checkpoint to the next; the average of a
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

import json

import numpy as np
import torch

_SAME = ("actor_sizes", "critic_sizes", "obs_keys", "clip_obs")
_NEEDED = ("config", "actor", "actor_sizes", "obs_keys", "obs_mean", "obs_var", "clip_obs")


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


def average_members(members: list[dict], names: list[str]) -> dict:
    """The weight average of policy payloads (members of policy files, named ``names`` in
    errors) as one payload: the last member's, with averaged networks.

    Raises:
        ValueError: Fewer than two members, or members whose networks, observations or
            settings differ (named).
    """
    if len(members) < 2:
        raise ValueError("policy averaging needs at least two policies")
    for ck, name in zip(members, names, strict=True):
        missing = [k for k in _NEEDED if k not in ck]
        if missing:
            raise ValueError(f"{name}: policy file lacks {missing}")
    cks, base, last = members, members[-1], names[-1]
    for p, ck in zip(names, cks, strict=True):
        for key in _SAME:
            if ck.get(key) != base.get(key):
                raise ValueError(f"{p}: {key} {ck.get(key)} differs from {last}'s {base.get(key)}")
        act, act_base = (json.loads(c["config"])["ppo"]["activation"] for c in (ck, base))
        if act != act_base:
            raise ValueError(f"{p}: activation {act} differs from {last}'s {act_base}")
        for part in ("actor", "critic"):
            if (part in ck) != (part in base):
                raise ValueError(f"{p}: has {'no ' if part not in ck else ''}{part} network, "
                                 f"unlike {last}")  # fmt: skip
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
    info["averaged"] = list(names)
    payload["info"] = json.dumps(info)
    return payload
