"""The ``grip`` command: one entry point with subcommands.

Each subcommand lives in its own module exposing ``add_parser(subparsers)``; the module registers
its arguments and sets ``func`` (called with the parsed namespace, returns an exit code).
Heavy imports happen inside the subcommand functions so ``grip --help`` stays instant.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from grip.cli import bench, body, data, demo, export, kinematics, policy, view
from grip.cli import reconstruct as reconstruct_cmd
from grip.cli.errors import CliError

LIMITS_ENV = "GRIP_LIMITS"
"""As :data:`grip.core.limits.LIMITS_ENV` (not imported here: that loads numpy)."""

RENAMED: dict[str, str] = {
    "train-kin": "grip kin train",
    "eval-kin": "grip kin eval",
    "kin-export": "grip kin export",
    "train-baseline": "grip kin train --baseline NAME",
    "baseline-export": "grip kin export",
    "train-policy": "grip policy train",
    "eval-policy": "grip policy eval",
    "policy-export": "grip policy export",
    "policy-ensemble": "grip policy combine",
    "policy-average": "grip policy combine --average",
    "policy-member": "grip policy combine --member K",
    "distill-policy": "grip policy distill",
    "bench-env": "python benchmarks/env_steps.py",
}
"""Commands of earlier versions and what replaced them (named in the error for the old name)."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="grip",
        description=(
            "GRIP: physically plausible full-body motion from 4 IMUs and pressure insoles. "
            "Build PRISM-format datasets from mocap, export the MuJoCo body, and run the demo."
        ),
        epilog="Run 'grip <command> --help' for the options of one command.",
    )
    sub = parser.add_subparsers(dest="command", metavar="<command>")
    sub.required = True
    for module in (data, body, kinematics, policy, reconstruct_cmd, bench, demo, export, view):
        module.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] in RENAMED:
        print(f"grip: error: 'grip {argv[0]}' is now '{RENAMED[argv[0]]}' (see "
              f"'grip --help')", file=sys.stderr)  # fmt: skip
        return 2
    parser = build_parser()
    args = parser.parse_args(argv)
    # --input-limit sets $GRIP_LIMITS for the command and its workers; a caller that runs
    # several commands in one process (tests, notebooks) gets its own value back afterwards
    saved_limits = os.environ.get(LIMITS_ENV)
    try:
        return int(args.func(args) or 0)
    except CliError as e:
        print(f"grip: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("grip: interrupted (finished files are kept; run the same command to resume)",
              file=sys.stderr)  # fmt: skip
        return 130
    finally:
        if saved_limits is None:
            os.environ.pop(LIMITS_ENV, None)
        else:
            os.environ[LIMITS_ENV] = saved_limits


if __name__ == "__main__":
    sys.exit(main())
