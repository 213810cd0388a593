"""The one validator of the config dataclasses (stdlib only).

Each config's ``__post_init__`` lists its rules as ``(condition, message)`` pairs and calls
:func:`check`, which raises the first broken one as a ``ValueError`` naming the class
(``"PolicyRunConfig: ppo.n_envs must be >= 1"``); :func:`check_fields` applies one rule to every
field. :func:`grip.config.load_config` turns these errors into messages that name the file or
the ``--set`` override. It lives in :mod:`grip.core` so that every layer's configs may use it,
the numpy core's and ``prism_tools``' included.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any


def check(obj: object, *rules: tuple[bool, str]) -> None:
    """Raise the first broken rule of a config.

    Args:
        obj: The config (its class names the error).
        rules: ``(condition, message)`` pairs; a false condition is broken.

    Raises:
        ValueError: ``"<Class>: <message>"`` of the first broken rule.
    """
    for ok, msg in rules:
        if not ok:
            raise ValueError(f"{type(obj).__name__}: {msg}")


def check_fields(obj: object, ok: Callable[[Any], bool], rule: str) -> None:
    """Apply one rule to every field of a dataclass.

    Args:
        obj: The config dataclass.
        ok: Whether a field's value keeps the rule.
        rule: The rule as the message says it (``"must be >= 0"``).

    Raises:
        ValueError: ``"<Class>.<field> <rule>, got <value>"`` of the first field that breaks it.
    """
    for f in dataclasses.fields(obj):  # type: ignore[arg-type]
        v = getattr(obj, f.name)
        if not ok(v):
            raise ValueError(f"{type(obj).__name__}.{f.name} {rule}, got {v!r}")
