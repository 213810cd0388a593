"""What inference asks of a trained controller, and the one way to get one from policy files.

:class:`Controller` is the interface that :mod:`grip.eval` (the clip player, the streaming
reconstructor, ``grip policy eval``) and the benchmarks use: one trained policy
(:class:`policies.runner.PolicyRunner`), the mean of several (:class:`policies.ensemble.
PolicyEnsemble`) and the left-right mirror average of either (:class:`policies.symmetry.
MirrorAveragedPolicy`) all provide it, structurally (``isinstance(x, Controller)`` holds for
each; they do not import this module, which loads them).

A policy file holds a list of one or more members (:func:`policies.runner.read_policy_file`); a
single policy is an ensemble of one. :func:`load_controller` reads one or several files as one
controller; :func:`combine` writes new files from the members of others (an ensemble, a weight
average, or one member on its own).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Literal, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from grip.task.config import TrackingEnvConfig
    from policies.amp import Discriminator

COMBINE_HOW: tuple[str, ...] = ("ensemble", "average")
"""How :func:`combine` joins several members into one file."""


@runtime_checkable
class Controller(Protocol):
    """A trained controller as inference uses it.

    Attributes:
        env_cfg: The environment settings it was trained with (observation variant, action
            mode and scale, decision period ``action_repeat``, AMP window): build the inference
            environment from them.
        obs_keys: The observation parts it reads, in the order it concatenates them.
        disc: The AMP discriminator behind :meth:`fall_probability`, or None when the file
            stores none (then no fall is detected).
        info: Notes of the file (``holdout``: clips held out of training; ``members``: the
            names of an ensemble's members; ...).
    """

    env_cfg: TrackingEnvConfig
    obs_keys: list[str]
    disc: Discriminator | None
    info: dict

    def act(self, obs: dict) -> np.ndarray:
        """Action(s) in [-1, 1], ``(A,)`` for one observation dict of the tracking env's parts
        (or ``(B, A)`` for a batch with a leading axis)."""
        ...

    def fall_probability(self, amp_obs: np.ndarray) -> np.ndarray:
        """The discriminator's probability ``(B,)`` that AMP windows ``(B, W * F)`` (or one,
        ``(W * F,)``) are real motion: GRIP's fall detector."""
        ...

    def use_action_noise(self, scale: float, seed: int = 0) -> None:
        """Sample actions with the trained standard deviation times ``scale`` (0: the mean
        action) from a generator seeded with ``seed``."""
        ...


PathLike = str | os.PathLike


def _paths(files: PathLike | Sequence[PathLike]) -> list[Path]:
    got = [files] if isinstance(files, str | os.PathLike) else list(files)
    if not got:
        raise ValueError("no policy file given")
    return [Path(p) for p in got]


def load_controller(files: PathLike | Sequence[PathLike],
                    mirror: tuple[Sequence[str], bool] | None = None) -> Controller:  # fmt: skip
    """The controller of one or several policy files: the policy of a one-member file, the
    gate over its members of a gated file (:class:`policies.gate.GatedController`), else the
    mean action of every member of every file (:class:`policies.ensemble.PolicyEnsemble`).

    Args:
        files: Policy files, in any layout ever written (:func:`policies.runner.
            read_policy_file`).
        mirror: ``(sites, insoles)`` of the KinematicsNet whose features fill the ``sensor``
            observation part: average each action with the mirror image of the action on the
            mirrored observation (:class:`policies.symmetry.MirrorAveragedPolicy`). None: no
            mirror averaging.

    Raises:
        FileNotFoundError: A file does not exist.
        ValueError: naming the file, when it is no policy file, or its members do not drive the
            humanoid alike.
    """
    from policies.ensemble import PolicyEnsemble
    from policies.runner import PolicyRunner, read_policy_parts

    paths = _paths(files)
    runners: list[PolicyRunner] = []
    names: list[str] = []
    gate = None
    for p in paths:
        members, stored, gate = read_policy_parts(p)
        if gate is not None and len(paths) > 1:
            raise ValueError(f"{p}: a gated policy file drives alone (no ensemble with "
                             "other files)")  # fmt: skip
        labels = [f"{p} (member {i}: {n})" for i, n in enumerate(stored)]
        if len(members) == 1:
            runners.append(PolicyRunner.from_payload(members[0], p))
            names.append(str(p))
            continue
        runners += [PolicyRunner.from_payload(m, lab)
                    for m, lab in zip(members, labels, strict=True)]  # fmt: skip
        names += labels if len(paths) == 1 else [f"{p} [{i}]" for i in range(len(members))]
    ctrl: Controller
    if gate is not None:
        from policies.gate import GatedController, gate_from_payload

        try:
            ctrl = GatedController(runners, names, gate_from_payload(gate, str(paths[0])))
        except ValueError as e:
            raise ValueError(e if str(e).startswith(str(paths[0])) else f"{paths[0]}: {e}") from e
    elif len(runners) == 1:
        ctrl = runners[0]
    else:
        try:
            ctrl = PolicyEnsemble(runners, names)
        except ValueError as e:
            raise ValueError(f"{paths[0]}: {e}" if len(paths) == 1 else str(e)) from e
    if mirror is not None:
        from policies.symmetry import MirrorAveragedPolicy

        ctrl = MirrorAveragedPolicy(ctrl, tuple(mirror[0]), bool(mirror[1]))
    return ctrl


def combine(files: PathLike | Sequence[PathLike], out: PathLike,
            how: Literal["ensemble", "average"] = "ensemble", member: int | None = None,
            precision: str | None = None) -> tuple[int, int]:  # fmt: skip
    """Write one policy file from the members of ``files``; returns its size in bytes and its
    number of members.

    Args:
        files: Policy files; their members are taken in order.
        out: The file to write (atomically).
        how: ``"ensemble"``: every member, acting as their mean action (actors and
            normalisers kept, value networks and all but the first discriminator left out:
            :func:`policies.ensemble.ensemble_members`); ``"average"``: one member, the weight
            average of all (:func:`policies.average.average_members`; exports of one run).
        member: Take only member ``member`` (0 = the first) of all those of ``files``: its actor
            as stored, its normaliser, its file's discriminator, no value network.
        precision: ``"fp32"``, ``"fp16"`` or ``"int8"`` (:func:`grip.nn.weights.
            pack_weights`) for the actors and the kept discriminator; None: int8 for an
            ensemble, as stored otherwise.

    Raises:
        FileNotFoundError: A file does not exist.
        ValueError: naming the file, when it is no policy file, ``member`` is not one, fewer
            than two members are to be joined, or they do not fit together.
    """
    from policies.ensemble import ensemble_members, member_payloads
    from policies.runner import repack, write_policy_file

    if how not in COMBINE_HOW:
        raise ValueError(f"how={how!r}: use one of {list(COMBINE_HOW)}")
    paths = _paths(files)
    members: list[dict] = []
    names: list[str] = []
    for p in paths:
        got = member_payloads(p)
        members += [m for m, _ in got]
        names += [str(p)] if len(got) == 1 else [f"{p} [{i}]" for i in range(len(got))]
    if member is not None:
        if not 0 <= member < len(members):
            n = len(members)
            raise ValueError(f"{', '.join(map(str, paths))}: no member {member} (they hold {n} "
                             f"{'policies' if n > 1 else 'policy'}: 0..{n - 1})")  # fmt: skip
        kept = [{k: v for k, v in members[member].items() if k not in ("critic", "critic_sizes")}]
        kept_names = [names[member]]
    elif how == "average":
        from policies.average import average_members

        kept, kept_names = [average_members(members, names)], [names[-1]]
    else:
        kept, kept_names = ensemble_members(members, names), names
        precision = precision or "int8"
    if precision is not None:
        kept = [repack(m, precision) for m in kept]
    return write_policy_file(kept, kept_names, out), len(kept)
