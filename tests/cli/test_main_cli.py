"""The shape of the ``grip`` command line: a few groups, and old command names that say where
they went."""

from __future__ import annotations

import argparse

import pytest

from grip.cli.main import RENAMED, build_parser, main


def _leaves(parser: argparse.ArgumentParser, prefix: str = "grip") -> list[str]:
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        return [prefix]
    return [leaf for name, p in subs[0].choices.items() for leaf in _leaves(p, f"{prefix} {name}")]


def test_the_command_line_has_few_leaf_commands() -> None:
    leaves = _leaves(build_parser())
    assert len(leaves) <= 20, leaves  # (17 after issue 31; issue 35: grip view, grip data import;
    # issue 34: grip data cut, the demo's held-out clip with props)
    for cmd in ("grip policy export", "grip policy combine", "grip kin export", "grip kin train"):
        assert cmd in leaves


@pytest.mark.parametrize("old", sorted(RENAMED))
def test_an_old_command_name_names_its_replacement(old: str, capsys) -> None:
    assert main([old, "--help"]) == 2
    err = capsys.readouterr().err
    assert f"'grip {old}'" in err and RENAMED[old] in err
    assert old not in _leaves(build_parser())


def test_combine_refuses_unknown_members_without_writing(tmp_path, capsys) -> None:
    from grip.assets import SHIPPED_POLICY

    out = tmp_path / "m.pt"
    assert main(["policy", "combine", str(SHIPPED_POLICY), "--member", "9", "--out",
                 str(out)]) == 2  # fmt: skip
    assert "no member 9" in capsys.readouterr().err and not out.exists()
    assert main(["policy", "combine", str(SHIPPED_POLICY), "--member", "0", "--out",
                 str(out)]) == 0  # fmt: skip
    assert "member 0 of" in capsys.readouterr().out and out.is_file()
