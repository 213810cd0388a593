"""What the command modules share: a command group with its actions (``grip kin train|eval|
export``), and for every command that writes a model file (``grip kin export``, ``grip policy
export|combine``) the ``--out`` and ``--precision`` options and one way to write, report and
refuse."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path

from grip.cli.errors import CliError

PRECISIONS: tuple[str, ...] = ("fp32", "fp16", "int8")
"""Weight storage (:func:`grip.nn.weights.pack_weights`)."""


def positive_float(text: str) -> float:
    """An argparse ``type``: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value) or value <= 0.0:
        raise argparse.ArgumentTypeError(f"{text} must be a positive number")
    return value


def add_group(sub: argparse._SubParsersAction, name: str, help: str,
              description: str) -> argparse._SubParsersAction:  # fmt: skip
    """Register command group ``name`` (``grip NAME <action>``); returns the subparsers its
    actions are added to (an action is required)."""
    p = sub.add_parser(name, help=help, description=description)
    actions = p.add_subparsers(dest=f"{name}_command", metavar="<action>")
    actions.required = True
    return actions


def add_output_arguments(p: argparse.ArgumentParser, precision_default: str | None,
                         precision_help: str) -> None:  # fmt: skip
    """``--out FILE`` (required) and ``--precision {fp32,fp16,int8}``."""
    p.add_argument("--out", required=True, type=Path, help="output .pt (written atomically)")
    p.add_argument("--precision", choices=PRECISIONS, default=precision_default,
                   help=precision_help)  # fmt: skip


def write_artifact(out: Path, write: Callable[[], int | tuple[int, str]]) -> int:
    """Run ``write`` (it writes ``out`` atomically and returns its size in bytes, or the size and
    a note for the report line); print ``wrote OUT (N MB)``; a missing, refused or unwritable
    file becomes a :class:`CliError`. Returns the exit status, 0."""
    try:
        got = write()
    except (FileNotFoundError, ValueError, OSError) as e:
        raise CliError(str(e)) from e
    size, note = got if isinstance(got, tuple) else (got, "")
    print(f"wrote {out} ({size / 1e6:.1f} MB){note}")
    return 0
