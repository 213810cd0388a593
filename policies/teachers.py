"""The teachers of a distillation: one per motion family (issue 47, part 4).

A specialist is a policy fine-tuned on one family of motions (``grip policy train`` with
``stage2.categories``; docs/teacher_student.md); the student of ``grip policy distill`` learns
each clip's actions from the specialist of its family and every other clip's from the default
teacher (the locomotion teacher, or an ensemble). :class:`TeacherRouter` picks the teacher of
every environment by the category of the clip it plays and returns the actions in the
student's terms: a privileged teacher (``follow = "truth"``) acts on the observation against the
ground truth, and its action is shifted to the estimate the student follows
(:attr:`grip.task.config.TrackingEnvConfig.teacher_obs`).

Every teacher must drive the humanoid as the default one does (observation parts and
environment settings, :func:`policies.ensemble.check_same_driving`): a label means one PD target.
"""

from __future__ import annotations

import fnmatch
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

SPECIALIST_SYNTAX = "CATEGORY[,CATEGORY...]=POLICY"
"""How ``--specialist`` is spelt: category globs of the family, then the policy file."""


@dataclass(frozen=True)
class Specialist:
    """One family's teacher: the clips whose category matches one of ``categories`` (globs)
    learn from ``policy`` (a policy or ensemble file)."""

    categories: tuple[str, ...]
    policy: str

    @classmethod
    def parse(cls, text: str) -> Specialist:
        """``"walk-back,walk-side=runs/spec/policy.pt"`` -> a :class:`Specialist`.

        Raises:
            ValueError: Not of the form :data:`SPECIALIST_SYNTAX` (the message shows it).
        """
        cats, sep, policy = text.partition("=")
        globs = tuple(c.strip() for c in cats.split(",") if c.strip())
        if not sep or not globs or not policy.strip():
            raise ValueError(f"--specialist {text!r}: expected {SPECIALIST_SYNTAX}, e.g. "
                             "walk-back,walk-side=runs/spec_walkbs/policy.pt")  # fmt: skip
        return cls(globs, policy.strip())

    def matches(self, category: str) -> bool:
        return any(fnmatch.fnmatch(category, g) for g in self.categories)


@dataclass
class LoadedTeacher:
    """Policy or ensemble files read as one teacher (:func:`load_teacher`).

    Attributes:
        controller: One :class:`policies.runner.PolicyRunner` or a
            :class:`policies.ensemble.PolicyEnsemble` of every member.
        privileged: Its members follow the ground truth (``follow = "truth"``).
        payloads: Every member's single-policy payload, in order.
        names: Every member's name, in order.
    """

    controller: object
    privileged: bool
    payloads: list[dict]
    names: list[str]


def load_teacher(paths: Sequence[str | os.PathLike]) -> LoadedTeacher:
    """The members of the policy or ensemble files ``paths`` as one teacher (their mean action).

    Raises:
        FileNotFoundError: A file is missing.
        ValueError: naming the files, when one is not a policy file, or the members follow
            different references or drive the humanoid differently.
    """
    from policies.ensemble import PolicyEnsemble, member_payloads
    from policies.runner import PolicyRunner

    members = [m for p in paths for m in member_payloads(p)]
    payloads, names = [ck for ck, _ in members], [n for _, n in members]
    runners = [PolicyRunner.from_payload(ck, n) for ck, n in members]
    follows = {r.info.get("follow", "estimate") for r in runners}
    if len(follows) > 1:
        raise ValueError(f"{', '.join(str(p) for p in paths)}: the teacher's members follow "
                         "different references (some the ground truth, some the estimate)")
    controller = runners[0] if len(runners) == 1 else PolicyEnsemble(runners, names)
    return LoadedTeacher(controller, follows == {"truth"}, payloads, names)


class TeacherRouter:
    """The default teacher and the specialists, each environment's action from the teacher of
    its clip's family (the first specialist whose globs match, else the default).

    Args:
        default: The default teacher (a :class:`policies.runner.PolicyRunner` or ensemble).
        default_privileged: It follows the ground truth.
        specialists: The families and their policy files.

    Attributes:
        privileged: Some teacher follows the ground truth: the rollouts need the teacher's
            observation keys (``teacher_obs``).

    Raises:
        ValueError: naming the file, when a specialist cannot be read, mixes references or
            drives the humanoid otherwise than the default teacher.
    """

    def __init__(self, default, default_privileged: bool,
                 specialists: Sequence[Specialist] = ()) -> None:  # fmt: skip
        from policies.ensemble import check_same_driving

        self.default = default
        self.specialists = list(specialists)
        self._teachers = []  # (controller, privileged), one per specialist
        for s in self.specialists:
            if not Path(s.policy).is_file():
                raise ValueError(f"{s.policy}: no such policy file (--specialist)")
            t = load_teacher([s.policy])
            check_same_driving([default, t.controller], ["the default teacher", s.policy])
            self._teachers.append((t.controller, t.privileged))
        self._default_privileged = default_privileged
        self.privileged = default_privileged or any(p for _, p in self._teachers)

    def family(self, category: str) -> int:
        """The index of the specialist that teaches clips of ``category``; -1: the default."""
        for i, s in enumerate(self.specialists):
            if s.matches(category):
                return i
        return -1

    def act(self, obs: dict, families: np.ndarray) -> np.ndarray:
        """The teachers' actions in the student's terms for a batch ``obs`` whose row ``i``
        plays a clip of family ``families[i]`` (:meth:`family`)."""
        out = None
        for f in np.unique(families):
            teacher, priv = ((self.default, self._default_privileged) if f < 0
                             else self._teachers[int(f)])  # fmt: skip
            rows = np.flatnonzero(families == f)
            sub = {k: v[rows] for k, v in obs.items()}
            a = _student_action(teacher, priv, sub)
            if out is None:
                out = np.empty((len(families), a.shape[1]), a.dtype)
            out[rows] = a
        return out


def _student_action(teacher, privileged: bool, obs: dict) -> np.ndarray:
    """``teacher``'s action in the student's terms: a privileged teacher acts on the
    observation against the ground truth, and its action (relative to the truth) becomes the
    student's (relative to the estimate) with the environment's ``teacher_shift``."""
    if not privileged:
        return teacher.act(obs)
    a = teacher.act({**obs, "kinematic": obs["teacher_kinematic"]})
    return np.clip(a + obs["teacher_shift"], -1.0, 1.0)
