"""Config files: TOML overrides on top of frozen dataclass defaults (stdlib only).

``load_config(path, cls, overrides)`` reads a TOML file whose tables mirror the dataclass
nesting, applies dotted ``key=value`` overrides (``train.lr=3e-4``), and returns a new instance.
Unknown keys are errors that name the file and the key, and so are the rules each dataclass
checks in its ``__post_init__`` (:func:`grip.core.checks.check`).
"""

from __future__ import annotations

import dataclasses
import os
import tomllib
import typing
from collections.abc import Sequence
from pathlib import Path
from typing import Any


class ConfigError(ValueError):
    """A config file or override is invalid; the message names the file/key."""


def _coerce(value: Any, hint: Any, where: str) -> Any:
    origin = typing.get_origin(hint)
    if origin is tuple or hint is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        if typing.get_args(hint) == (str, Ellipsis) and not all(isinstance(v, str) for v in value):
            raise ConfigError(f"{where}: expected a list of strings, got {value!r}")
        return tuple(value)
    if hint is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if hint in (int, float, bool, str) and not isinstance(value, hint):
        raise ConfigError(f"{where}: expected {hint.__name__}, got {value!r}")
    return value


def apply_dict(obj: Any, data: dict, where: str) -> Any:
    """A copy of dataclass ``obj`` with the values of nested dict ``data``."""
    hints = typing.get_type_hints(type(obj))
    fields = {f.name: f for f in dataclasses.fields(obj)}
    changes = {}
    for key, value in data.items():
        if key not in fields:
            raise ConfigError(f"{where}: unknown key {key!r} (known: {', '.join(fields)})")
        current = getattr(obj, key)
        if dataclasses.is_dataclass(current):
            if not isinstance(value, dict):
                raise ConfigError(f"{where}.{key}: expected a table")
            changes[key] = apply_dict(current, value, f"{where}.{key}")
        else:
            changes[key] = _coerce(value, hints[key], f"{where}.{key}")
    try:
        return dataclasses.replace(obj, **changes)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{where}: {e}") from e


def parse_override(text: str) -> tuple[list[str], Any]:
    """``"train.lr=3e-4"`` -> (["train", "lr"], 0.0003); the value is parsed as TOML."""
    if "=" not in text:
        raise ConfigError(f"override {text!r}: expected KEY=VALUE")
    key, raw = text.split("=", 1)
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw  # bare strings
    return key.strip().split("."), value


def load_config(path: str | os.PathLike | None, default: Any,
                overrides: Sequence[str] = ()) -> Any:  # fmt: skip
    """``default`` updated by the TOML file at ``path`` (if any) and dotted overrides."""
    cfg = default
    if path is not None:
        p = Path(path)
        try:
            data = tomllib.loads(p.read_text())
        except OSError as e:
            raise ConfigError(f"{p}: cannot read config ({e})") from e
        except tomllib.TOMLDecodeError as e:
            raise ConfigError(f"{p}: invalid TOML ({e})") from e
        cfg = apply_dict(cfg, data, str(p))
    # all overrides at once: checks that tie several settings together see the final values
    nested: dict = {}
    for text in overrides:
        keys, value = parse_override(text)
        cur = nested
        for k in keys[:-1]:
            nxt = cur.setdefault(k, {})
            if not isinstance(nxt, dict):
                raise ConfigError(f"--set {text}: {k!r} is set as a value elsewhere")
            cur = nxt
        cur[keys[-1]] = value
    if nested:
        cfg = apply_dict(cfg, nested, "--set " + " ".join(overrides))
    return cfg


REMOVED_ANY_VALUE: Any = object()
"""``RemovedSetting.off`` of a setting that did nothing while its feature was off (any value)."""


@dataclasses.dataclass(frozen=True)
class RemovedSetting:
    """A setting that was deleted from a config and may still sit in stored configs.

    Attributes:
        key: Dotted path (``"ppo.target_kl"``).
        off: The value with which the feature was off (stored configs holding it load as if the
            key was absent); :data:`REMOVED_ANY_VALUE`: any value, for a companion setting
            without effect while another one kept the feature off.
        feature: What the setting turned on, for the refusal's message.
        commit: The commit that still has the feature.
    """

    key: str
    off: Any
    feature: str
    commit: str


def drop_removed(data: dict, removed: Sequence[RemovedSetting], where: str) -> dict:
    """A copy of the nested settings ``data`` without the ``removed`` settings.

    A removed key whose value is its ``off`` value is dropped silently; one that turned its
    feature on is refused: the settings cannot be reproduced by this version.

    Raises:
        ConfigError: Naming ``where``, the key, the feature and the commit that has it.
    """
    for r in removed:
        *parents, leaf = r.key.split(".")
        node: Any = data
        for p in parents:
            node = node.get(p) if isinstance(node, dict) else None
        if not isinstance(node, dict) or leaf not in node:
            continue
        value = node[leaf]
        if isinstance(value, list):  # JSON and TOML give lists where the field held a tuple
            value = tuple(value)
        if r.off is not REMOVED_ANY_VALUE and value != r.off:
            raise ConfigError(f"{where}: {r.key} = {node[leaf]!r} turns on {r.feature}, which "
                              f"was removed (commit {r.commit} has it)")  # fmt: skip
    return _without(data, [r.key for r in removed])


def _without(data: dict, keys: Sequence[str]) -> dict:
    out = dict(data)
    for key in keys:
        *parents, leaf = key.split(".")
        node = out
        for p in parents:
            child = node.get(p)
            if not isinstance(child, dict):
                node = None
                break
            node[p] = child = dict(child)
            node = child
        if node is not None:
            node.pop(leaf, None)
    return out
