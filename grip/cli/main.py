"""The ``grip`` command: one entry point with subcommands.

Each subcommand lives in its own module exposing ``add_parser(subparsers)``; the module registers
its arguments and sets ``func`` (called with the parsed namespace, returns an exit code).
Heavy imports happen inside the subcommand functions so ``grip --help`` stays instant.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from grip.cli import (
    baselines,
    bench,
    bench_env,
    body,
    data,
    demo,
    distill,
    export,
    kinematics,
    policy,
)
from grip.cli import reconstruct as reconstruct_cmd
from grip.cli.errors import CliError


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
    for module in (data, body, kinematics, baselines, policy, distill, reconstruct_cmd, bench,
                   bench_env, demo, export):  # fmt: skip
        module.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except CliError as e:
        print(f"grip: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("grip: interrupted (finished files are kept; run the same command to resume)",
              file=sys.stderr)  # fmt: skip
        return 130


if __name__ == "__main__":
    sys.exit(main())
