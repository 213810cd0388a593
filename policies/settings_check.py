"""The ranges a policy file's settings must lie in: what the humanoid and the controller were
built and measured for, in one table.

A policy file carries the environment settings it was trained with
(:class:`grip.task.config.TrackingEnvConfig`), and every command that plays it rebuilds the
humanoid and the observations from them. A value the dataclass accepts can still be absurd
there: ``timestep_s = 1e-6`` gives a humanoid that never moves, ``substeps = 1e6`` a hang,
``heightmap_size = 1e5`` a ten-billion-sample height map. :func:`check_policy_settings` and
:func:`check_observations` refuse such a file when it is loaded
(:meth:`policies.runner.PolicyRunner.from_payload`, which every command uses), naming the file,
the setting and the allowed range.

:data:`ENV_RANGES` holds the ranges, by dotted setting name (``"mjcf.timestep_s"``, an element
of a tuple as ``"mjcf.contact_solref[0]"``). Settings it does not name (rewards, switches, and
any added to the dataclasses since) are not checked here; unknown keys in a file are refused
earlier, by :func:`policies.config.policy_config_from_dict`.

Imports :mod:`grip.task` and :mod:`grip.core` only.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from grip.task.config import TrackingEnvConfig
from grip.task.observations import SELF_DIM, kinematic_dim

__all__ = [
    "AMP_WINDOW",
    "CONTROL_RATE_HZ",
    "ENV_RANGES",
    "POLICY_OBS_KEYS",
    "Range",
    "check_env_settings",
    "check_observations",
    "check_policy_settings",
]


@dataclass(frozen=True)
class Range:
    """Allowed values of one setting, ``lo <= value <= hi``.

    Attributes:
        lo: Smallest allowed value.
        hi: Largest allowed value.
        why: What the setting is and why these bounds, for the message.
        unit: Unit of the values, for the message.
    """

    lo: float
    hi: float
    why: str
    unit: str = ""

    def text(self) -> str:
        return f"range {self.lo:g} to {self.hi:g}{(' ' + self.unit) if self.unit else ''}"


ENV_RANGES: dict[str, Range] = {
    # physics: the body model was measured stable at 2.5-5 ms steps (DESIGN.md)
    "mjcf.timestep_s": Range(5e-4, 0.01, "physics step; 5 ms is the measured stable step", "s"),
    "substeps": Range(1, 20, "physics steps per control step"),
    "mjcf.armature": Range(0.0, 10.0, "rotor inertia added to every hinge", "kg m^2"),
    "mjcf.joint_damping": Range(0.0, 100.0, "passive hinge damping", "N m s/rad"),
    "mjcf.friction": Range(0.0, 10.0, "sliding friction coefficient"),
    "mjcf.gain_scale": Range(0.05, 20.0, "factor on the body model's PD gains"),
    "mjcf.contact_solref[0]": Range(1e-3, 1.0, "contact time constant", "s"),
    "mjcf.contact_solref[1]": Range(0.05, 20.0, "contact damping ratio"),
    "mjcf.contact_solimp[0]": Range(0.0, 1.0, "contact impedance dmin"),
    "mjcf.contact_solimp[1]": Range(0.0, 1.0, "contact impedance dmax"),
    "mjcf.contact_solimp[2]": Range(0.0, 0.1, "contact impedance width", "m"),
    "mjcf.rest_clearance_m": Range(0.0, 0.1, "rest-pose clearance of excluded pairs", "m"),
    "mjcf.sole_pad_radius_m": Range(1e-3, 0.05, "radius of the sole pads", "m"),
    "mjcf.foot_box_clearance_m": Range(0.0, 0.05, "lift of the foot boxes", "m"),
    "mjcf.insole_site_half_height_m": Range(5e-4, 0.05, "half height of the insole cells", "m"),
    "mjcf.texture_px": Range(1, 4096, "skybox and floor texture size", "px"),
    # controller: actions, observations
    "action_scale": Range(0.0, 2.0, "fraction of the half hinge range an action of 1 moves"),
    "action_repeat": Range(1, 10, "frames an action is held"),
    "heightmap_size": Range(2, 64, "height-map samples per side"),
    "heightmap_extent_m": Range(0.1, 20.0, "side of the height map", "m"),
    "heightfield_cell_m": Range(5e-3, 0.5, "terrain height-field resolution", "m"),
    "amp_window": Range(0, 100, "AMP frames per discriminator window"),
    # episodes and safety bounds
    "termination_dist_m": Range(0.0, 10.0, "early-termination distance", "m"),
    "fall_height_m": Range(0.0, 2.0, "pelvis height of a fall", "m"),
    "fall_below_reference_m": Range(0.0, 2.0, "pelvis drop below the truth of a fall", "m"),
    "termination_root_gap_m": Range(0.0, 10.0, "pelvis gap that ends an episode", "m"),
    "max_episode_frames": Range(0, 10_000_000, "episode length limit", "frames"),
    "min_episode_frames": Range(1, 100_000, "frames a random start leaves", "frames"),
    "clip_index": Range(-1, 10_000_000, "clip played (-1: sampled)"),
    "blowup_lin_vel_mps": Range(1.0, 1000.0, "pelvis speed of a blow-up", "m/s"),
    "blowup_ang_vel_radps": Range(1.0, 10_000.0, "joint speed of a blow-up", "rad/s"),
    "blowup_height_m": Range(0.5, 100.0, "pelvis height of a blow-up", "m"),
    "blowup_depth_m": Range(0.1, 100.0, "depth below the floor of a blow-up", "m"),
}
"""Allowed range of each checked :class:`grip.task.config.TrackingEnvConfig` setting."""

CONTROL_RATE_HZ = Range(25.0, 500.0, "1 / (substeps x mjcf.timestep_s): the controller's "
                        "decisions per second; the shipped recipes run at 100", "Hz")  # fmt: skip
"""Allowed control rate, derived from two settings."""

AMP_WINDOW = Range(1, 100, "AMP frames per discriminator window")
"""Allowed ``amp.window`` of a policy file's AMP settings."""

POLICY_OBS_KEYS: tuple[str, ...] = ("sensor", "kinematic", "self", "environment")
"""The observation parts inference provides (:func:`grip.task.observations.observe`); a policy
file may read any of them, and nothing else."""

_INDEX = re.compile(r"^(?P<name>[\w.]+)\[(?P<i>\d+)\]$")


def _value(cfg: Any, dotted: str) -> tuple[bool, Any]:
    """``(found, value)`` of a dotted setting (``"mjcf.contact_solref[0]"``) of ``cfg``."""
    m = _INDEX.match(dotted)
    name, index = (m["name"], int(m["i"])) if m else (dotted, None)
    node = cfg
    for part in name.split("."):
        names = {f.name for f in dataclasses.fields(node)} if dataclasses.is_dataclass(node) else ()
        if part not in names:
            return False, None  # a setting this version no longer has (the tests notice)
        node = getattr(node, part)
    if index is not None:
        if not isinstance(node, Sequence) or index >= len(node):
            return True, node
        node = node[index]
    return True, node


def _refuse(where: str, setting: str, value: Any, rng: Range) -> ValueError:
    shown = f"{value:g}" if isinstance(value, float) else repr(value)
    return ValueError(f"{where}: {setting} = {shown} is outside the {rng.text()} the body and "
                      f"the controller were built for ({rng.why})")  # fmt: skip


def _in_range(value: Any, rng: Range) -> bool:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    return math.isfinite(value) and rng.lo <= value <= rng.hi


def check_env_settings(env: TrackingEnvConfig, where: str, prefix: str = "env.") -> None:
    """Refuse environment settings outside :data:`ENV_RANGES` or :data:`CONTROL_RATE_HZ`.

    Args:
        env: The settings (a subclass with more fields is fine: those are not checked).
        where: The file, for the message.
        prefix: How the message names the settings' section.

    Raises:
        ValueError: ``"{where}: env.mjcf.timestep_s = 1e-06 is outside the range 0.0005 to
            0.01 s the body and the controller were built for (...)"``.
    """
    for name, rng in ENV_RANGES.items():
        found, value = _value(env, name)
        if found and not _in_range(value, rng):
            raise _refuse(where, prefix + name, value, rng)
    rate = 1.0 / (env.substeps * env.mjcf.timestep_s)
    if not _in_range(rate, CONTROL_RATE_HZ):
        raise _refuse(where, f"control rate ({prefix}substeps = {env.substeps}, "
                      f"{prefix}mjcf.timestep_s = {env.mjcf.timestep_s:g})", rate,
                      CONTROL_RATE_HZ)  # fmt: skip
    timeconst = env.mjcf.contact_solref[0]
    if timeconst < 2 * env.mjcf.timestep_s:
        raise ValueError(f"{where}: {prefix}mjcf.contact_solref[0] = {timeconst:g} s is below "
                         f"twice {prefix}mjcf.timestep_s = {env.mjcf.timestep_s:g} s (MuJoCo's "
                         "contacts need a time constant of at least two steps)")  # fmt: skip


def check_policy_settings(cfg: Any, where: str) -> None:
    """:func:`check_env_settings` of a :class:`policies.config.PolicyRunConfig`'s ``env``, and
    its ``amp.window`` against :data:`AMP_WINDOW`.

    Raises:
        ValueError: naming ``where``, the setting and its range.
    """
    check_env_settings(cfg.env, where)
    if not _in_range(cfg.amp.window, AMP_WINDOW):
        raise _refuse(where, "amp.window", cfg.amp.window, AMP_WINDOW)


def check_observations(keys: Any, widths: Mapping[str, int], actor_inputs: int,
                       env: TrackingEnvConfig, where: str) -> None:  # fmt: skip
    """Refuse observation parts that inference does not provide or whose widths do not match
    the settings.

    Args:
        keys: The policy file's ``obs_keys`` (the order the network concatenates them).
        widths: Values per part in the file's normaliser (``obs_mean``).
        actor_inputs: The actor network's input width.
        env: The file's environment settings.
        where: The file, for the message.

    Raises:
        ValueError: naming ``where``: keys not a list of distinct known parts
            (:data:`POLICY_OBS_KEYS`), a normaliser without a key's statistics, a part whose
            width differs from what the settings give (``kinematic``, ``self``, the
            ``heightmap_size``-squared ``environment``), or widths that do not sum to the actor's
            input.
    """
    if not isinstance(keys, list | tuple) or not all(isinstance(k, str) for k in keys):
        raise ValueError(f"{where}: obs_keys is not a list of observation names")
    known = ", ".join(repr(k) for k in POLICY_OBS_KEYS)
    for k in keys:
        if k not in POLICY_OBS_KEYS:
            raise ValueError(f"{where}: observation key {k[:50]!r} is not one inference "
                             f"provides (known: {known})")  # fmt: skip
        if k not in widths:
            raise ValueError(f"{where}: observation key {k!r} has no normaliser statistics")
    if len(set(keys)) != len(keys):
        raise ValueError(f"{where}: obs_keys {list(keys)} names a part twice")
    expected = {"kinematic": (kinematic_dim(env.kinematic_obs),
                              f"env.kinematic_obs = {env.kinematic_obs!r}"),
                "self": (SELF_DIM, "the body's joints"),
                "environment": (env.heightmap_size**2,
                                f"env.heightmap_size = {env.heightmap_size}")}  # fmt: skip
    for k in keys:
        if k in expected and widths[k] != expected[k][0]:
            n, why = expected[k]
            raise ValueError(f"{where}: observation {k!r} of {widths[k]} values, but "
                             f"{why} gives {n}")  # fmt: skip
    total = sum(widths[k] for k in keys)
    if total != actor_inputs:
        raise ValueError(f"{where}: the actor takes {actor_inputs} inputs, the observations "
                         f"{list(keys)} hold {total}")  # fmt: skip
