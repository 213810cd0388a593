"""Several exported policies acting as one: the mean of their actions.

Unlike the weight average of :mod:`policies.average`, which only makes sense between exports of
one run, an ensemble may join policies trained apart: each member normalises the observation
with its own statistics and computes its own mean action, and the ensemble plays the mean of
those (each clipped to [-1, 1] as one policy's action is, then the mean). The members must
drive the humanoid the same way: the same observation parts and the same environment settings
(observation variant, action mode and scale, decision period, body and simulation); reward
settings, which inference never uses, may differ. GRIP's fall detector uses the first
member's discriminator.

An ensemble is stored as a policy file of several members (:mod:`policies.runner`), written by
``grip policy combine A.pt B.pt ... --out F.pt`` (:func:`policies.controller.combine` with
:func:`ensemble_members`: actors and observation normalisers, the first member's
discriminator, no value networks: an ensemble is for inference; fine-tune a member).
:func:`policies.controller.load_controller` reads one or several files as one controller.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from grip.task.config import TrackingEnvConfig
from policies.runner import PolicyRunner, read_policy_file

_DROPPED = ("critic", "critic_sizes")  # the value networks: training only
_DISC = ("disc", "amp_frame_dim")


def _driving_settings(cfg: TrackingEnvConfig) -> TrackingEnvConfig:
    """The settings that decide how a policy's actions move the humanoid (reward, reference
    file and the root-speed and lean augmentations blanked: inference builds its own
    reference, never computes a reward and follows the estimate as it is)."""
    d = TrackingEnvConfig()
    return dataclasses.replace(cfg, reward=d.reward, reference="",
                               root_speed_range=d.root_speed_range,
                               lean_range_deg=d.lean_range_deg)  # fmt: skip


def check_same_driving(policies: Sequence, names: Sequence[str]) -> None:
    """Refuse policies that do not drive the humanoid as the first one does: other observation
    parts or sizes, or other environment settings besides the reward and the reference file
    (:class:`PolicyEnsemble`'s members, :class:`policies.teachers.TeacherRouter`'s teachers).

    Raises:
        ValueError: naming the policy and what differs.
    """
    first, base = policies[0], _driving_settings(policies[0].env_cfg)
    for m, name in zip(policies[1:], names[1:], strict=True):
        if m.obs_keys != first.obs_keys:
            raise ValueError(f"{name}: observation parts {m.obs_keys} differ from "
                             f"{names[0]}'s {first.obs_keys}")  # fmt: skip
        if _obs_size(m) != _obs_size(first):
            raise ValueError(f"{name}: observations of {_obs_size(m)} values, {names[0]}'s "
                             f"of {_obs_size(first)} (another sensor set?)")  # fmt: skip
        mine = _driving_settings(m.env_cfg)
        if mine != base:
            diff = [f.name for f in dataclasses.fields(base)
                    if getattr(base, f.name) != getattr(mine, f.name)]  # fmt: skip
            raise ValueError(f"{name}: environment settings differ from {names[0]}'s "
                             f"({', '.join(diff)}): its actions mean something else")


def _obs_size(policy) -> int:
    """How many observation values ``policy`` (one policy or an ensemble) reads."""
    return int(getattr(policy, "members", [policy])[0]._mean.shape[-1])


class PolicyEnsemble:
    """The mean action of several :class:`policies.runner.PolicyRunner`: a
    :class:`policies.controller.Controller`.

    Args:
        members: The policies; the first one's settings, discriminator and notes are the
            ensemble's.
        names: What errors call each member (file names).

    Attributes:
        members: The policies, in the order given.
        env_cfg: The first member's environment settings.
        disc: The first member's discriminator (GRIP's fall detector), or None.
        info: The first member's notes, with ``holdout`` the clips held out of *every* member's
            training (a clip another member trained on validates nothing), and ``members``.

    Raises:
        ValueError: No member, or a member whose observations or environment settings differ
            from the first's (named, with the settings that differ).
    """

    def __init__(self, members: Sequence[PolicyRunner], names: Sequence[str] | None = None) -> None:
        if not members:
            raise ValueError("an ensemble needs at least one policy")
        names = list(names) if names is not None else [f"policy {i}" for i in range(len(members))]
        first = members[0]
        check_same_driving(members, names)
        self.members = list(members)
        self.obs_keys = list(first.obs_keys)
        self.env_cfg = first.env_cfg
        self.amp_window = first.amp_window
        self.disc = first.disc
        held = [set(m.info.get("holdout") or ()) for m in self.members]
        self.info = dict(first.info, holdout=sorted(set.intersection(*held)),
                         members=list(names))  # fmt: skip
        self._first = first
        self._stack = self._stacked_weights()

    def _stacked_weights(self):
        """Every member's normaliser and layers stacked (``(M, ...)``) when all members have
        the same layer sizes, activation and clipping; None otherwise (they then act in turn)."""
        from policies.runner import linear_layers

        nets = [linear_layers(m.actor) for m in self.members]
        shapes = {tuple(tuple(lin.weight.shape) for lin in net) for net in nets}
        acts = {tuple(type(mod) for mod in m.actor if not isinstance(mod, torch.nn.Linear))
                for m in self.members}  # fmt: skip
        clips = {m.clip_obs for m in self.members}
        if len(shapes) != 1 or len(acts) != 1 or len(clips) != 1:
            return None
        act_types = next(iter(acts))
        act_fn = act_types[0]() if act_types else (lambda h: h)
        layers = [(torch.stack([net[i].weight.detach().T for net in nets]).contiguous(),
                   torch.stack([net[i].bias.detach() for net in nets])[:, None, :])
                  for i in range(len(nets[0]))]  # fmt: skip
        means = np.stack([m._mean for m in self.members])
        stds = np.stack([m._std for m in self.members])
        return means, stds, clips.pop(), layers, act_fn

    def use_action_noise(self, scale: float, seed: int = 0) -> None:
        """Every member samples its action with its own noise (:meth:`PolicyRunner.
        use_action_noise`); the ensemble plays their mean."""
        for i, m in enumerate(self.members):
            m.use_action_noise(scale, seed + i)

    def act(self, obs: dict) -> np.ndarray:
        """The members' mean action (each clipped to [-1, 1])."""
        if self._stack is None or any(m._action_std is not None for m in self.members):
            return np.mean([m.act(obs) for m in self.members], axis=0)
        return self._stacked_act(obs)

    @torch.no_grad()
    def _stacked_act(self, obs: dict) -> np.ndarray:
        """:meth:`act` for members of one network shape: the observation is flattened once and
        every layer of all members is one batched product."""
        means, stds, clip, layers, act_fn = self._stack
        parts = [np.asarray(obs[k], np.float64) for k in self.obs_keys]
        x = np.concatenate([p.reshape(*p.shape[:-1], -1) for p in parts], axis=-1)
        single = x.ndim == 1
        x = np.atleast_2d(x)
        z = np.clip((x[None] - means[:, None]) / stds[:, None], -clip, clip)
        h = torch.from_numpy(z.astype(np.float32))
        for i, (w, b) in enumerate(layers):
            h = torch.baddbmm(b, h, w)
            if i < len(layers) - 1:
                h = act_fn(h)
        a = np.clip(h.numpy(), -1.0, 1.0).mean(0)
        return a[0] if single else a

    def fall_probability(self, amp_obs: np.ndarray) -> np.ndarray:
        """The first member's discriminator probability that AMP windows are real motion."""
        return self._first.fall_probability(amp_obs)


def ensemble_members(members: list[dict], names: list[str]) -> list[dict]:
    """The payloads an ensemble file stores of ``members`` (named ``names`` in errors): each
    without its value network, and every discriminator but the first member's (the fall
    detector).

    Raises:
        ValueError: Fewer than two members, or members that do not drive the humanoid alike
            (:class:`PolicyEnsemble`).
    """
    if len(members) < 2:
        raise ValueError("an ensemble needs at least two policies")
    PolicyEnsemble([PolicyRunner.from_payload(m, n) for m, n in zip(members, names, strict=True)],
                   names)  # refuses members that act differently  # fmt: skip
    return [{k: v for k, v in m.items() if k not in _DROPPED and (i == 0 or k not in _DISC)}
            for i, m in enumerate(members)]  # fmt: skip


def member_payload(path: str | os.PathLike, k: int) -> tuple[dict, str, int]:
    """Member ``k`` of a policy file as a single-policy payload (with the file's
    discriminator, which only the first member stores), its name, and the number of policies
    in the file.

    Raises:
        ValueError: naming the file, when it is no policy or holds no member ``k``.
    """
    members = member_payloads(path)
    if not 0 <= k < len(members):
        n = len(members)
        raise ValueError(f"{path}: no member {k} (the file holds {n} "
                         f"{'policies' if n > 1 else 'policy'}: 0..{n - 1})")  # fmt: skip
    return members[k][0], members[k][1], len(members)


def member_payloads(path: str | os.PathLike) -> list[tuple[dict, str]]:
    """Every member of a policy file as a single-policy payload (later members with the file's
    discriminator, which only the first stores) and its name (the file's name for a file of one
    member); the members are checked by loading them.

    Raises:
        FileNotFoundError: No such file.
        ValueError: naming the file, when it is no policy file or a member is broken.
    """
    path = Path(path)
    got, stored = read_policy_file(path)
    if len(got) == 1:
        PolicyRunner.from_payload(got[0], path)
        return [(got[0], str(path))]
    names = [f"{path} (member {i}: {n})" for i, n in enumerate(stored)]
    for m, n in zip(got, names, strict=True):
        PolicyRunner.from_payload(m, n)
    disc = {key: got[0][key] for key in _DISC if key in got[0]}
    return [({**m, **disc}, n) for m, n in zip(got, names, strict=True)]
