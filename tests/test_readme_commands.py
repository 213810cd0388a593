"""The README's command table stays in step with ``--help``: every command and action of the
CLI has a row, every option a row names exists on that command, and every value it lists for
an option with fixed choices is one of them."""

from __future__ import annotations

import argparse
import re

from grip.assets import REPO_ROOT
from grip.cli.main import build_parser

README = REPO_ROOT / "README.md"


def _commands() -> dict[str, argparse.ArgumentParser]:
    """``"data build"``, ``"bench"``, ... -> the parser of that command."""
    out: dict[str, argparse.ArgumentParser] = {}

    def walk(parser: argparse.ArgumentParser, prefix: str) -> None:
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not subs:
            out[prefix] = parser
            return
        for name, child in subs[0].choices.items():
            walk(child, f"{prefix} {name}".strip())

    walk(build_parser(), "")
    return out


def _rows() -> list[str]:
    """The first cell of every row of the README's command table."""
    text = README.read_text(encoding="utf-8")
    section = text.split("## Command line", 1)[1].split("\n## ", 1)[0]
    return [m.group(1) for m in re.finditer(r"^\| `(grip [^`]+)` \|", section, re.M)]


def test_every_command_has_a_row_and_every_row_names_real_options() -> None:
    commands = _commands()
    rows = _rows()
    assert len(rows) >= 15
    seen = set()
    for row in rows:
        words = row.split()[1:]
        name = next((n for n in sorted(commands, key=len, reverse=True)
                     if words[: len(n.split())] == n.split()), None)  # fmt: skip
        assert name is not None, f"README row names no command: {row}"
        seen.add(name)
        parser = commands[name]
        options = {o: a for a in parser._actions for o in a.option_strings}
        for opt in re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", row):
            assert opt in options, f"README: 'grip {name}' has no option {opt} ({row})"
        for opt, values in re.findall(r"(--[a-z][a-z0-9-]*) ([a-z0-9+-]+(?:\\\|[a-z0-9+-]+)+)",
                                      row):  # fmt: skip
            choices = options[opt].choices
            if choices is not None:
                for v in values.split("\\|"):
                    assert v in choices, f"README: {opt} {v} is not a choice of 'grip {name}'"
    missing = sorted(set(commands) - seen)
    assert not missing, f"commands without a README row: {missing}"
