"""The trained controller for inference: a plain torch MLP, its observation normaliser and the
AMP discriminator, and the policy file that holds them (no stable-baselines3 pickle at load time).

A policy file is a list of one or more members (a single policy is an ensemble of one):
``{"format": "grip-policy", "version": 2, "members": [member, ...], "names": "[...]"}``, each
member the weights and settings of one policy. :func:`read_policy_file` also reads the layouts
written before: a single policy at the top level (version 1) and ``"grip-policy-ensemble"``.
``export_policy(run_dir, out)`` writes the file of a training run's checkpoint, read without
unpickling anything (:mod:`policies.checkpoint`); everything is read with
``torch.load(weights_only=True)``.
"""

from __future__ import annotations

import dataclasses
import io
import json
import os
from pathlib import Path

import numpy as np
import torch
from torch import nn

from grip.core.atomic import atomic_write
from grip.core.limits import active_limits, read_json_file, safe_json_loads
from grip.nn.weights import check_declared_network
from grip.task.amp import FRAME_DIM
from grip.task.config import TrackingEnvConfig
from policies.amp import Discriminator
from policies.checkpoint import load_weights
from policies.config import policy_config_from_dict
from policies.settings_check import check_observations, check_policy_settings

FORMAT = "grip-policy"
VERSION = 2
"""Version 2: a list of members; version 1 stored one policy at the top level."""
LEGACY_ENSEMBLE_FORMAT = "grip-policy-ensemble"
"""Several policies in one file, as written before version 2 (two or more members)."""
MEMBER_KEYS: tuple[str, ...] = ("config", "actor", "obs_keys", "obs_mean", "obs_var")
"""What every member of a policy file holds at the least."""
ACTIVATION_FNS: dict[str, type[nn.Module]] = {
    "silu": nn.SiLU, "relu": nn.ReLU, "tanh": nn.Tanh, "elu": nn.ELU,
}  # fmt: skip
"""The activations of :data:`policies.config.ACTIVATIONS`."""


def mlp(sizes: list[int], activation: str) -> nn.Sequential:
    """A plain MLP of layer ``sizes`` (inputs, hidden..., outputs) with ``activation`` between
    its linear layers (none after the last): the networks of a policy file."""
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(ACTIVATION_FNS[activation]())
    return nn.Sequential(*layers)


def linear_layers(body: nn.Sequential, head: nn.Linear | None = None) -> list[nn.Linear]:
    """The linear layers of an MLP in order (an SB3 network body and its output layer, or one of
    this module's plain MLPs)."""
    return [m for m in body if isinstance(m, nn.Linear)] + ([head] if head is not None else [])


def _mlp_from_state(state: dict, body: str, head: str, activation: str,
                    path: Path) -> tuple[list[int], nn.Sequential]:  # fmt: skip
    """A plain MLP (:func:`mlp`) with the weights of an SB3 network body and its output layer,
    taken from a policy state dict (keys ``{body}{i}.weight``, ``{head}weight``, ...); returns
    its layer sizes and the MLP.

    Raises:
        ValueError: naming ``path``, when the layers are missing or do not chain.
    """
    try:
        idx = sorted(int(k[len(body) :].split(".")[0]) for k in state
                     if k.startswith(body) and k.endswith(".weight"))  # fmt: skip
        names = [f"{body}{i}." for i in idx] + [head]
        weights = [state[n + "weight"] for n in names]
        sizes = [int(weights[0].shape[1])] + [int(w.shape[0]) for w in weights]
        net = mlp(sizes, activation)
        for dst, n in zip(linear_layers(net), names, strict=True):
            dst.load_state_dict({"weight": state[n + "weight"], "bias": state[n + "bias"]})
    except (KeyError, IndexError, RuntimeError, ValueError) as e:
        raise ValueError(f"{path}: no {body.rstrip('.')} -> {head.rstrip('.')} network in its "
                         f"policy state ({str(e)[:200]})") from e  # fmt: skip
    return sizes, net


_DISC_NET = ("trunk", "head")
"""Prefixes of the discriminator's network weights (the rest: its input normaliser)."""


def _disc_state(state: dict) -> dict:
    """A stored discriminator state as float32 (its network may be fp16 or int8)."""
    from grip.nn.weights import unpack_weights

    net = {k: v for k, v in state.items() if k.startswith(_DISC_NET)}
    return {**{k: v for k, v in state.items() if k not in net}, **unpack_weights(net)}


def pack_disc(state: dict, precision: str) -> dict:
    """The discriminator's network weights at ``precision`` (:func:`grip.nn.weights.
    pack_weights`); its input normaliser as stored."""
    from grip.nn.weights import pack_weights, unpack_weights

    net = {k: v for k, v in state.items() if k.startswith(_DISC_NET)}
    return {**{k: v for k, v in state.items() if k not in net},
            **pack_weights(unpack_weights(net), precision)}  # fmt: skip


def _declared_sizes(ck: dict, part: str, path: Path, activation: str) -> list[int]:
    """The layer sizes a policy member declares for ``part`` (``"actor"``, ``"critic"``),
    checked against the weights it holds before anything is built
    (:func:`grip.nn.weights.check_declared_network`).

    Raises:
        ValueError: naming ``path``: not a list of positive integers, or sizes that do not fit
            the weights (a file declaring 12,000-wide layers around small weights).
    """
    raw = ck[f"{part}_sizes"]
    ok = isinstance(raw, list | tuple) and len(raw) >= 2
    if not ok or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in raw):
        raise ValueError(f"{path}: {part}_sizes = {str(raw)[:100]} is not a list of layer "
                         "sizes (positive integers)")  # fmt: skip
    sizes = [int(v) for v in raw]
    check_declared_network(lambda: mlp(sizes, activation), ck[part], str(path),
                           f"{part}_sizes {sizes}", {f"{part}_sizes": len(sizes) - 1})  # fmt: skip
    return sizes


def _load_mlp(sizes, state: dict, activation: str) -> nn.Sequential:
    from grip.nn.weights import unpack_weights  # fp32, fp16 or int8 (pack_weights)

    net = mlp([int(s) for s in sizes], activation)
    net.load_state_dict(unpack_weights(state))
    return net


class PolicyRunner:
    """Actions of a trained DynamicsNet (the Gaussian's mean unless :meth:`use_action_noise`),
    and the discriminator's probability: a :class:`policies.controller.Controller`.

    Attributes:
        env_cfg: The environment settings the policy was trained with (observation variant,
            action mode, gains...): build the inference environment from them.
        obs_keys: Observation parts in the order the network concatenates them.
    """

    def __init__(self, actor: nn.Sequential, obs_keys: list[str], obs_mean: dict, obs_var: dict,
                 clip_obs: float, env_cfg: TrackingEnvConfig, disc: Discriminator | None,
                 amp_window: int, info: dict | None = None, critic: nn.Sequential | None = None,
                 log_std: torch.Tensor | None = None,
                 obs_count: float | None = None) -> None:  # fmt: skip
        self.actor = actor.eval()
        self.obs_keys = list(obs_keys)
        self.obs_mean = {k: np.asarray(obs_mean[k], np.float64) for k in obs_keys}
        self.obs_var = {k: np.asarray(obs_var[k], np.float64) for k in obs_keys}
        self.obs_count = obs_count
        self.critic = critic.eval() if critic is not None else None
        self.log_std = log_std
        self._mean = np.concatenate([np.asarray(obs_mean[k], np.float64) for k in obs_keys])
        self._std = np.sqrt(np.concatenate([np.asarray(obs_var[k], np.float64) for k in obs_keys])
                            + 1e-8)  # fmt: skip
        self.clip_obs = clip_obs
        self.env_cfg = env_cfg
        self.disc = disc.eval() if disc is not None else None
        self.amp_window = amp_window
        self.info = info or {}
        self._action_std: np.ndarray | None = None  # set by use_action_noise
        self._rng = np.random.default_rng(0)

    def use_action_noise(self, scale: float, seed: int = 0) -> None:
        """Sample actions from the policy's Gaussian with its trained standard deviation times
        ``scale`` (1: the exploration noise of training; 0: the mean action, the default), then
        clip them to [-1, 1] as training does. For diagnostics: does the policy fare differently
        with the noise it was trained with?"""
        if not np.isfinite(scale) or scale < 0:
            raise ValueError(f"action noise scale must be finite and >= 0, got {scale}")
        if scale > 0 and self.log_std is None:
            raise ValueError("this policy file has no log_std (exported before it was kept): "
                             "no action noise to sample")  # fmt: skip
        self._action_std = (np.exp(self.log_std.numpy()).astype(np.float32) * np.float32(scale)
                            if scale > 0 else None)  # fmt: skip
        self._rng = np.random.default_rng(seed)

    def _flat(self, obs: dict) -> np.ndarray:
        parts = [np.asarray(obs[k], np.float64) for k in self.obs_keys]
        x = np.concatenate([p.reshape(*p.shape[:-1], -1) for p in parts], axis=-1)
        return np.clip((x - self._mean) / self._std, -self.clip_obs, self.clip_obs)

    @torch.no_grad()
    def act(self, obs: dict) -> np.ndarray:
        """Action(s) in [-1, 1] for one observation dict (or a batch with a leading axis)."""
        x = torch.as_tensor(self._flat(obs), dtype=torch.float32)
        a = self.actor(x).numpy()
        if self._action_std is not None:
            a = a + self._action_std * self._rng.standard_normal(a.shape, dtype=np.float32)
        return np.clip(a, -1.0, 1.0)

    def fall_probability(self, amp_obs: np.ndarray) -> np.ndarray:
        """The discriminator's probability that AMP windows are real motion."""
        if self.disc is None:
            raise ValueError("this policy file has no discriminator")
        return self.disc.probability(np.atleast_2d(amp_obs))

    # ------------------------------------------------------------------ file
    @classmethod
    def load(cls, path: str | os.PathLike) -> PolicyRunner:
        """Read a one-member policy file; errors name the file and the problem (several
        members: :func:`policies.controller.load_controller`)."""
        path = Path(path)
        members, _ = read_policy_file(path)
        if len(members) != 1:
            raise ValueError(f"{path}: an ensemble of {len(members)} policies, not one policy "
                             "(policies.controller.load_controller reads it)")  # fmt: skip
        return cls.from_payload(members[0], path)

    @classmethod
    def from_payload(cls, ck: object, path: str | os.PathLike) -> PolicyRunner:
        """The policy of one member of a policy file (``path`` names it in errors).

        Its settings are checked against the ranges the body and the controller were built
        for, its observation parts against what inference provides
        (:mod:`policies.settings_check`), and the network sizes it declares against its
        weights before anything is built.

        Raises:
            ValueError: naming ``path``, for any of these or an inconsistent file.
        """
        if not isinstance(ck, dict):
            raise ValueError(f"{path}: not a GRIP policy file (format {FORMAT!r} expected)")
        missing = [k for k in MEMBER_KEYS if k not in ck]
        if missing:
            raise ValueError(f"{path}: policy file lacks {missing}")
        try:
            stored = safe_json_loads(ck["config"], active_limits(), "its config")
            cfg = policy_config_from_dict(stored, f"{path}: config")
            check_policy_settings(cfg, str(path))
            act = cfg.ppo.activation
            sizes = _declared_sizes(ck, "actor", path, act)
            if not isinstance(ck["obs_mean"], dict) or not isinstance(ck["obs_var"], dict):
                raise ValueError(f"{path}: obs_mean/obs_var are not per-part statistics")
            widths = {k: int(v.numel()) for k, v in ck["obs_mean"].items()
                      if isinstance(k, str) and torch.is_tensor(v)}  # fmt: skip
            check_observations(ck["obs_keys"], widths, sizes[0], cfg.env, str(path))
            actor = _load_mlp(sizes, ck["actor"], act)
            critic = None
            if "critic" in ck:  # files written since the value network is exported
                critic = _load_mlp(_declared_sizes(ck, "critic", path, act), ck["critic"], act)
            log_std = ck["log_std"].float() if "log_std" in ck else None
            disc = None
            if "disc" in ck:
                in_dim = cfg.amp.window * int(ck["amp_frame_dim"])
                hidden = [int(h) for h in cfg.amp.hidden]
                check_declared_network(
                    lambda: Discriminator(in_dim, hidden, cfg.amp.loss), ck["disc"], str(path),
                    f"its config's amp.window = {cfg.amp.window} x amp_frame_dim = "
                    f"{ck['amp_frame_dim']} inputs, amp.hidden = {hidden}",
                    {"amp.hidden": len(hidden)})  # fmt: skip
                disc = Discriminator(in_dim, hidden, cfg.amp.loss)
                disc.load_state_dict(_disc_state(ck["disc"]))
        except ValueError as e:
            if str(e).startswith(str(path)):
                raise
            raise ValueError(f"{path}: inconsistent policy file ({e})") from e
        except (KeyError, RuntimeError, TypeError, AttributeError) as e:
            raise ValueError(f"{path}: inconsistent policy file ({e})") from e
        env_cfg = dataclasses.replace(cfg.env, amp_window=cfg.amp.window)
        count = float(ck["obs_count"]) if "obs_count" in ck else None
        return cls(actor, ck["obs_keys"], ck["obs_mean"], ck["obs_var"], float(ck["clip_obs"]),
                   env_cfg, disc, cfg.amp.window, json.loads(ck.get("info", "{}")),
                   critic=critic, log_std=log_std, obs_count=count)  # fmt: skip


def export_policy(run_dir: str | os.PathLike, out: str | os.PathLike, half: bool = True,
                  info: dict | None = None, precision: str | None = None) -> int:  # fmt: skip
    """Write the inference file of a training run's checkpoint; returns its size in bytes.

    Weights are float16 with ``half`` (cast back on load), float32 without; ``precision``
    (``"fp32"``, ``"fp16"`` or ``"int8"``, :func:`grip.nn.weights.pack_weights`: one
    float32 scale per weight row) overrides ``half`` and applies to the policy, value and
    discriminator networks alike. Normaliser statistics and the log std stay as they are.
    ``info`` (JSON) is kept in the file; the run's held-out sequences (``RUN/holdout.json``)
    join it as ``info["holdout"]``, for ``grip policy eval --split holdout``. The networks come
    from the state dicts of ``checkpoint/model.zip``, never from its pickled entries
    (:func:`policies.checkpoint.read_ppo_zip`), built as the run's config says.

    Raises:
        FileNotFoundError: ``run_dir`` is no 'grip policy train' run folder.
        ValueError: naming the file, for a corrupt or hostile checkpoint file (nothing in it
            runs) or one that does not fit the others.
    """
    from grip.nn.weights import pack_weights
    from policies.checkpoint import read_ppo_zip, read_vecnorm

    run_dir = Path(run_dir)
    ck_dir = run_dir / "checkpoint"
    cfg_path = run_dir / "config.json"
    if not (ck_dir / "model.zip").is_file() or not cfg_path.is_file():
        raise FileNotFoundError(f"{run_dir}: no checkpoint/model.zip and config.json (a "
                                "'grip policy train' run folder expected)")  # fmt: skip
    cfg_d = read_json_file(cfg_path, "'grip policy train' run config").get("config")
    if not isinstance(cfg_d, dict):
        raise ValueError(f"{cfg_path}: not a 'grip policy train' run config (no 'config' object)")
    try:
        cfg = policy_config_from_dict(cfg_d, str(cfg_path))
    except (TypeError, KeyError, AttributeError) as e:
        raise ValueError(f"{cfg_path}: not a 'grip policy train' run config ({e})") from e
    check_policy_settings(cfg, str(cfg_path))
    ppo = read_ppo_zip(ck_dir / "model.zip")  # (never unpickled: policies.checkpoint)
    act, zpath = cfg.ppo.activation, ppo.path
    sizes, actor = _mlp_from_state(ppo.policy, "mlp_extractor.policy_net.", "action_net.", act,
                                   zpath)  # fmt: skip
    critic_sizes, critic = _mlp_from_state(ppo.policy, "mlp_extractor.value_net.",
                                           "value_net.", act, zpath)  # fmt: skip
    if "log_std" not in ppo.policy:
        raise ValueError(f"{zpath}: no log_std in its policy state")
    precision = precision or ("fp16" if half else "fp32")
    info = dict(info or {})
    if cfg.follow != "estimate":  # a privileged tracker (grip policy eval says how to judge it)
        info["follow"] = cfg.follow
    holdout = run_dir / "holdout.json"  # grip policy train's held-out clips (holdout_fraction)
    if holdout.is_file():
        seqs = read_json_file(holdout, "held-out sequence list").get("sequences")
        if not isinstance(seqs, list) or not all(isinstance(q, str) for q in seqs):
            raise ValueError(f"{holdout}: not a held-out sequence list (no 'sequences' names)")
        info["holdout"] = seqs
    norm_path = ck_dir / "vecnorm.npz"
    norm = read_vecnorm(norm_path)
    # the observation parts in the order of the network's input (the order they were saved in)
    keys = [k[len("obs/") : -len("/mean")] for k in norm
            if k.startswith("obs/") and k.endswith("/mean")]  # fmt: skip
    try:
        obs_mean = {k: torch.as_tensor(norm[f"obs/{k}/mean"]) for k in keys}
        obs_var = {k: torch.as_tensor(norm[f"obs/{k}/var"]) for k in keys}
        count = float(norm[f"obs/{keys[0]}/count"])
    except (KeyError, IndexError, TypeError, ValueError) as e:
        raise ValueError(f"{norm_path}: incomplete observation statistics ({e})") from e
    width = sum(m.numel() for m in obs_mean.values())
    if width != sizes[0] or width != critic_sizes[0]:
        raise ValueError(f"{norm_path}: observations of {width} values, but the networks of "
                         f"{zpath} take {sizes[0]}")  # fmt: skip
    amp_ck = load_weights(ck_dir / "amp.pt", "discriminator checkpoint")
    payload = {
        "config": json.dumps(cfg_d),
        "actor_sizes": sizes, "actor": pack_weights(actor.state_dict(), precision),
        "obs_keys": keys,
        "obs_mean": obs_mean, "obs_var": obs_var, "obs_count": count,
        "log_std": ppo.policy["log_std"].detach().clone(),
        "critic_sizes": critic_sizes,
        "critic": pack_weights(critic.state_dict(), precision),
        "clip_obs": cfg.ppo.clip_obs, "amp_frame_dim": FRAME_DIM,
        "disc": pack_disc(amp_ck["disc"], precision),
        "info": json.dumps(info),
    }  # fmt: skip
    return write_policy_file([payload], [str(run_dir)], out)


def read_policy_file(path: str | os.PathLike) -> tuple[list[dict], list[str]]:
    """The members of a policy file and the names stored with them, in any layout ever written:
    version 2 (a list of members), version 1 (one policy at the top level; named after the file)
    and :data:`LEGACY_ENSEMBLE_FORMAT`. Only the first member of a file of several stores the
    discriminator; the members are not checked further (:meth:`PolicyRunner.from_payload`).

    Raises:
        FileNotFoundError: No such file.
        ValueError: naming the file, when it is no policy file or its list of members is
            missing or unreadable.
    """
    members, names, _ = read_policy_parts(path)
    return members, names


def read_policy_parts(path: str | os.PathLike) -> tuple[list[dict], list[str], dict | None]:
    """:func:`read_policy_file`'s members and names, and the gate stored beside them
    (:mod:`policies.gate`; None: the file has none), from one read of the file."""
    path = Path(path)
    ck = load_weights(path, "policy file")
    fmt = ck.get("format") if isinstance(ck, dict) else None
    if fmt == FORMAT and "members" not in ck:
        return [ck], [str(path)], None
    if fmt not in (FORMAT, LEGACY_ENSEMBLE_FORMAT):
        raise ValueError(f"{path}: not a GRIP policy file (format {FORMAT!r} expected)")
    members = ck.get("members")
    least = 2 if fmt == LEGACY_ENSEMBLE_FORMAT else 1
    if not isinstance(members, list) or len(members) < least:
        raise ValueError(f"{path}: policy file without its list of member policies")
    try:
        names = [str(n) for n in json.loads(ck.get("names", "[]"))]
    except (ValueError, TypeError) as e:
        raise ValueError(f"{path}: policy file with unreadable member names ({e})") from e
    if len(names) != len(members):
        names = [f"member {i}" for i in range(len(members))]
    return members, names, ck.get("gate")


def write_policy_file(members: list[dict], names: list[str], out: str | os.PathLike,
                      gate: dict | None = None) -> int:  # fmt: skip
    """Write ``members`` (policy payloads, as :func:`read_policy_file` returns them) and their
    ``names`` as one policy file, atomically, with ``gate`` (:func:`policies.gate.gate_payload`)
    beside them if given; returns its size in bytes."""
    if not members or len(names) != len(members):
        raise ValueError(f"{out}: a policy file needs one name per member, at least one member")
    kept = [{k: v for k, v in m.items() if k not in ("format", "version")} for m in members]
    payload = {"format": FORMAT, "version": VERSION, "members": kept,
               "names": json.dumps(list(names))}  # fmt: skip
    if gate is not None:
        payload["gate"] = gate
    buf = io.BytesIO()
    torch.save(payload, buf)
    atomic_write(out, lambda f: f.write(buf.getvalue()))
    return len(buf.getvalue())


def repack(member: dict, precision: str) -> dict:
    """``member`` with its actor, value network and discriminator networks stored at
    ``precision`` (:func:`grip.nn.weights.pack_weights`); normalisers as they are."""
    from grip.nn.weights import pack_weights, unpack_weights

    out = dict(member)
    for part in ("actor", "critic"):
        if part in out:
            out[part] = pack_weights(unpack_weights(out[part]), precision)
    if "disc" in out:
        out["disc"] = pack_disc(out["disc"], precision)
    return out
