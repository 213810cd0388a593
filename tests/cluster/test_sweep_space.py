"""The parts of ``--ray`` and ``--tune`` that need no running Ray: the search-space file, the
trials it expands to, the ``--set`` values they pass, the results table, and the errors a user
meets (a bad space, a file taken as the address, Ray not installed); ``grip --help`` never
imports Ray."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from grip.cli.main import main
from grip.cluster import (
    SweepSpace,
    Trial,
    TrialResult,
    expand_trials,
    load_space,
    results_table,
)
from grip.cluster.sweep import flat_metrics, toml_literal
from grip.config import parse_override


def _space(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "space.toml"
    p.write_text(text)
    return p


def test_a_grid_is_every_combination_with_the_last_key_fastest(tmp_path) -> None:
    space = load_space(_space(tmp_path, 'metric = "val/fk"\n[set]\n"train.lr" = [1e-3, 3e-4]\n'
                              'hidden = [8, 16, 32]\n'))  # fmt: skip
    trials = expand_trials(space)
    assert space.mode == "grid" and space.metric == "val/fk" and space.goal is None
    assert [dict(t.values) for t in trials][:3] == [
        {"train.lr": 1e-3, "hidden": 8}, {"train.lr": 1e-3, "hidden": 16},
        {"train.lr": 1e-3, "hidden": 32}]  # fmt: skip
    assert len(trials) == 2 * 3 and len({t.name for t in trials}) == 6


def test_nested_tables_are_dotted_keys_and_names_ignore_the_order(tmp_path) -> None:
    a = load_space(_space(tmp_path, "[set]\ntrain.lr = [0.1]\nhidden = [8]\n"))
    b = load_space(_space(tmp_path, '[set]\nhidden = [8]\n"train.lr" = [0.1]\n'))
    (ta,), (tb,) = expand_trials(a), expand_trials(b)
    assert ta.sets() == ["train.lr=0.1", "hidden=8"] and tb.sets() == ["hidden=8", "train.lr=0.1"]
    assert ta.name == tb.name and ta.name.startswith("trial_") and len(ta.name) == 14


def test_random_draws_distinct_combinations_from_the_seed(tmp_path) -> None:
    text = 'mode = "random"\nsamples = 5\nseed = 3\n[set]\na = [1, 2, 3]\nb = ["x", "y", "z"]\n'
    space = load_space(_space(tmp_path, text))
    one, two = expand_trials(space), expand_trials(space)
    assert one == two and len({t.name for t in one}) == 5  # same draw, no repeats
    grid = {t.name for t in expand_trials(SweepSpace(space.choices))}
    assert {t.name for t in one} <= grid
    other = expand_trials(SweepSpace(space.choices, "random", 5, seed=4))
    assert [t.name for t in other] != [t.name for t in one]
    every = expand_trials(SweepSpace(space.choices, "random", 50, seed=3))
    assert {t.name for t in every} == grid  # more samples than combinations: all of them


@pytest.mark.parametrize(("text", "words"), [
    ("hidden = [8]\n", "unknown key(s) ['hidden']"),
    ("[set]\n", "no [set] table"),
    ("[set]\nhidden = 8\n", "hidden must be a non-empty list"),
    ("[set]\nhidden = []\n", "hidden must be a non-empty list"),
    ("[set]\nhidden = [8, 8]\n", "lists a value twice"),
    ('mode = "bayes"\n[set]\nhidden = [8]\n', "mode must be one of ['grid', 'random']"),
    ('mode = "random"\n[set]\nhidden = [8]\n', "needs samples >= 1"),
    ("samples = 3\n[set]\nhidden = [8]\n", "samples is for mode"),
    ('goal = "lowest"\n[set]\nhidden = [8]\n', "goal must be one of"),
    ("cpus_per_trial = 0\n[set]\nhidden = [8]\n", "cpus_per_trial must be a number > 0"),
    ("[set\n", "not a readable TOML file"),
])  # fmt: skip
def test_a_bad_space_is_refused_naming_the_file_and_the_problem(tmp_path, text, words) -> None:
    p = _space(tmp_path, text)
    with pytest.raises(ValueError) as e:
        load_space(p)
    assert str(p) in str(e.value) and words in str(e.value)


@pytest.mark.parametrize("value", [3, -2, 0.5, 3e-4, 1e22, True, False, "relu", 'a "b"\\c',
                                   [16, 16], [[1, 2], [3]], [], {"w_pose": 0.5, "x": "y"},
                                   float("inf")])  # fmt: skip
def test_values_pass_through_set_unchanged(value) -> None:
    key, got = parse_override(f"a.b={toml_literal(value)}")
    assert key == ["a", "b"] and got == value and type(got) is type(value)


def test_metrics_are_the_numbers_of_a_record_under_slashed_keys() -> None:
    record = {"epoch": 3, "phase": "joint", "val": {"total": 1.5, "fk": 0.2}, "ok": True}
    assert flat_metrics(record) == {"epoch": 3.0, "val/total": 1.5, "val/fk": 0.2}


def test_the_table_puts_the_best_first_and_failures_last() -> None:
    def result(h: int, status: str, loss: float | None, error: str = "") -> TrialResult:
        return TrialResult(Trial((("hidden", h),)), status,
                           {} if loss is None else {"val/total": loss}, error)  # fmt: skip

    results = [result(8, "done", 2.0), result(16, "failed", None, "bad | thing"),
               result(32, "kept", 1.0), result(64, "done", None)]  # fmt: skip
    rows = results_table(results, "val/total", "min").splitlines()
    assert rows[0] == "| trial | status | hidden | val/total (min) | error |"
    assert [r.split(" | ")[2] for r in rows[2:]] == ["32", "8", "64", "16"]
    assert rows[-1].endswith("| n/a | bad \\| thing |")
    rows = results_table(results, "val/total", "max").splitlines()
    assert [r.split(" | ")[2] for r in rows[2:]] == ["8", "32", "64", "16"]


def test_help_does_not_import_ray() -> None:
    code = ("import sys; from grip.cli.main import build_parser; build_parser(); "
            "import grip.cluster, grip.cli.cluster; print('ray' in sys.modules)")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout  # fmt: skip
    assert out.strip() == "False"


def test_without_ray_the_error_says_how_to_install_it(walk_takes, monkeypatch, capsys) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # (import ray raises ImportError)
    argv = ["kin", "eval", "--data", str(walk_takes), "--segment-frames", "100", "--ray"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Ray is not installed" in err and "pip install 'ray[tune]==" in err
    assert "Traceback" not in err


def test_command_line_mistakes_are_clean_errors(walk_takes, tmp_path, capsys) -> None:
    rec = sorted((walk_takes / "sequences").glob("*.npz"))[0]
    assert main(["reconstruct", str(rec), "--out", str(tmp_path / "r"), "--ray",
                 str(rec)]) == 2  # fmt: skip
    assert "took" in capsys.readouterr().err
    base = ["kin", "train", "--data", str(walk_takes), "--out", str(tmp_path / "k")]
    assert main([*base, "--ray"]) == 2
    assert "--ray runs the trials of --tune" in capsys.readouterr().err
    bad = _space(tmp_path, "[set]\nhiddn = [8, 16]\n")
    assert main([*base, "--tune", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "hiddn" in err and "Traceback" not in err
    assert main([*base, "--tune", str(bad), "--sweep"]) == 2
    assert "--sweep" in capsys.readouterr().err
    assert not (tmp_path / "k").exists()  # refused before anything ran


def test_sweep_results_file_lists_values_and_metrics(tmp_path) -> None:
    from grip.cluster import write_results

    results = [TrialResult(Trial((("hidden", 8),)), "done", {"val/total": 1.0})]
    table = write_results(tmp_path, results, "val/total", "min")
    assert (tmp_path / "sweep.md").read_text() == table + "\n"
    data = json.loads((tmp_path / "sweep.json").read_text())
    assert data["trials"][0]["values"] == {"hidden": 8} and data["metric"] == "val/total"
