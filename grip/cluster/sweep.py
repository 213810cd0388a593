"""Hyper-parameter sweeps of a training command through Ray Tune, one trial per run folder.

The search space is a TOML file of choices over the command's ``--set`` keys::

    mode = "grid"             # every combination ("random": `samples` of them, drawn)
    samples = 4               # random only: how many distinct combinations
    seed = 0                  # random only: seed of the draw
    metric = "val/total"      # what the results table sorts by (a key the trials report)
    goal = "min"              # or "max"
    cpus_per_trial = 1        # CPUs Ray reserves for each trial

    [set]                     # dotted --set keys -> the values to try
    "train.lr" = [1e-3, 3e-4]
    hidden = [64, 128]

Only ``[set]`` is required. Each trial is the command's ordinary run in ``OUT/<trial name>``
with the trial's values appended to the command's own ``--set`` options, so a trial is one run
folder as without a sweep: it resumes from its checkpoint. A trial's name is a hash of its
values (the same values, the same folder, whatever the order of the file or the other trials).
A finished trial writes ``trial.json`` (its values and the metrics it reported) last; running
the sweep again skips the finished trials and runs the others, which resume from their folders.
``OUT/sweep.md`` and ``OUT/sweep.json`` hold the results table of every trial of the space.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import random
import tomllib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from grip.cluster.ray_pool import connect, import_ray
from grip.core.atomic import atomic_write_text

__all__ = ["GOALS", "MARKER", "MODES", "SweepSpace", "Trial", "TrialFailed", "TrialResult",
           "expand_trials", "flat_metrics", "load_space", "results_table", "run_sweep",
           "toml_literal", "write_results"]  # fmt: skip

MODES: tuple[str, ...] = ("grid", "random")
GOALS: tuple[str, ...] = ("min", "max")
MARKER = "trial.json"
"""Written last into a trial's folder: the trial finished (its values and metrics)."""
TABLE, RESULTS = "sweep.md", "sweep.json"
_TOP_KEYS = ("mode", "samples", "seed", "metric", "goal", "cpus_per_trial", "set")


class TrialFailed(RuntimeError):
    """A trial's run ended with an error (the message says which and where its log is)."""


@dataclass(frozen=True)
class SweepSpace:
    """A search space (:func:`load_space`).

    Attributes:
        choices: ``(dotted --set key, values to try)`` in the file's order.
        mode: ``"grid"`` (every combination) or ``"random"`` (``samples`` distinct ones).
        samples: Combinations drawn in random mode.
        seed: Seed of the random draw.
        metric: Reported key the table sorts by (``None``: the command's default).
        goal: ``"min"`` or ``"max"`` (``None``: the command's default).
        cpus_per_trial: CPUs Ray reserves for each trial.
    """

    choices: tuple[tuple[str, tuple[Any, ...]], ...]
    mode: str = "grid"
    samples: int = 0
    seed: int = 0
    metric: str | None = None
    goal: str | None = None
    cpus_per_trial: float = 1.0


@dataclass(frozen=True)
class Trial:
    """One point of a space: ``(dotted key, value)`` pairs in the space's key order."""

    values: tuple[tuple[str, Any], ...]

    @property
    def name(self) -> str:
        """``trial_`` and 8 hex digits of a hash of the values (order-independent)."""
        text = json.dumps(sorted([k, v] for k, v in self.values), sort_keys=True)
        return "trial_" + hashlib.sha256(text.encode()).hexdigest()[:8]

    def sets(self) -> list[str]:
        """The ``--set KEY=VALUE`` arguments (values as TOML literals)."""
        return [f"{k}={toml_literal(v)}" for k, v in self.values]


@dataclass
class TrialResult:
    """What one trial gave.

    Attributes:
        trial: The trial.
        status: ``"done"`` (this sitting), ``"kept"`` (finished before) or ``"failed"``.
        metrics: The numbers it reported (:func:`flat_metrics` of its run's last record).
        error: Why it failed.
    """

    trial: Trial
    status: str
    metrics: dict[str, float] = field(default_factory=dict)
    error: str = ""


def _flat_keys(table: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in table.items():
        if isinstance(v, Mapping):
            out.update(_flat_keys(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def load_space(path: str | Path) -> SweepSpace:
    """Read a search space (the module docstring's format).

    Raises:
        ValueError: Naming the file and what is wrong (unreadable TOML, an unknown key, a
            ``[set]`` entry that is not a non-empty list, a bad mode, goal or count).
    """
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise ValueError(f"{path}: not a readable TOML file ({e})") from e
    unknown = sorted(set(data) - set(_TOP_KEYS))
    if unknown:
        raise ValueError(f"{path}: unknown key(s) {unknown}; a space has {list(_TOP_KEYS)} "
                         "(the values to try go under [set])")  # fmt: skip
    sets = data.get("set")
    if not isinstance(sets, dict) or not sets:
        raise ValueError(f"{path}: no [set] table of --set keys and the values to try, e.g. "
                         "[set] \"train.lr\" = [1e-3, 3e-4]")  # fmt: skip
    choices = []
    for key, values in _flat_keys(sets).items():
        if not isinstance(values, list) or not values:
            raise ValueError(f"{path}: [set] {key} must be a non-empty list of the values to "
                             f"try, got {values!r}")  # fmt: skip
        if any(a == b for a, b in itertools.combinations(values, 2)):
            raise ValueError(f"{path}: [set] {key} lists a value twice: {values!r}")
        choices.append((key, tuple(values)))
    mode = data.get("mode", "grid")
    if mode not in MODES:
        raise ValueError(f"{path}: mode must be one of {list(MODES)}, got {mode!r}")
    samples = data.get("samples", 0)
    if mode == "random" and (not isinstance(samples, int) or samples < 1):
        raise ValueError(f"{path}: mode = \"random\" needs samples >= 1, got {samples!r}")
    if mode == "grid" and "samples" in data:
        raise ValueError(f"{path}: samples is for mode = \"random\"; a grid tries every "
                         "combination")  # fmt: skip
    goal = data.get("goal")
    if goal is not None and goal not in GOALS:
        raise ValueError(f"{path}: goal must be one of {list(GOALS)}, got {goal!r}")
    metric = data.get("metric")
    if metric is not None and (not isinstance(metric, str) or not metric):
        raise ValueError(f"{path}: metric must be a reported key such as \"val/total\"")
    cpus = data.get("cpus_per_trial", 1)
    if isinstance(cpus, bool) or not isinstance(cpus, int | float) or not cpus > 0:
        raise ValueError(f"{path}: cpus_per_trial must be a number > 0, got {cpus!r}")
    seed = data.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise ValueError(f"{path}: seed must be an integer, got {seed!r}")
    return SweepSpace(tuple(choices), mode, samples, seed, metric, goal, float(cpus))


def expand_trials(space: SweepSpace) -> list[Trial]:
    """The trials of a space: every combination (grid, the last key varying fastest), or
    ``samples`` distinct combinations drawn without replacement from a generator seeded with
    ``space.seed`` (random; all of them when there are fewer)."""
    keys = [k for k, _ in space.choices]
    lists = [v for _, v in space.choices]
    if space.mode == "grid":
        return [Trial(tuple(zip(keys, combo, strict=True))) for combo in itertools.product(*lists)]
    total = math.prod(len(v) for v in lists)
    picks = random.Random(space.seed).sample(range(total), min(space.samples, total))
    trials = []
    for i in picks:  # mixed-radix digits of i, the last key the fastest, as in the grid
        combo = []
        for values in reversed(lists):
            i, j = divmod(i, len(values))
            combo.append(values[j])
        trials.append(Trial(tuple(zip(keys, reversed(combo), strict=True))))
    return trials


def toml_literal(value: Any) -> str:
    """``value`` as a TOML literal, as ``--set KEY=VALUE`` parses it
    (:func:`grip.config.parse_override`)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        return ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_literal(v) for v in value) + "]"
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{json.dumps(str(k))} = {toml_literal(v)}"
                               for k, v in value.items()) + "}"  # fmt: skip
    raise ValueError(f"a TOML value cannot hold {type(value).__name__} ({value!r})")


def flat_metrics(record: Mapping[str, Any], prefix: str = "") -> dict[str, float]:
    """The numbers of a (nested) history record under ``/``-joined keys
    (``{"val": {"total": 1.0}}`` -> ``{"val/total": 1.0}``); other values are left out."""
    out: dict[str, float] = {}
    for k, v in record.items():
        if isinstance(v, Mapping):
            out.update(flat_metrics(v, f"{prefix}{k}/"))
        elif isinstance(v, int | float) and not isinstance(v, bool):
            out[f"{prefix}{k}"] = float(v)
    return out


def _read_marker(folder: Path, trial: Trial) -> dict[str, float] | None:
    """The metrics of a finished trial (``None``: not finished, or a marker of other values)."""
    try:
        data = json.loads((folder / MARKER).read_text(encoding="utf-8"))
        if data["name"] != trial.name or data["sets"] != trial.sets():
            return None
        return {str(k): float(v) for k, v in data["metrics"].items()}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None


def _tune_trial(config: dict, run_trial: Callable[[Path, list[str]], Mapping]) -> None:
    """Ray Tune's function of one trial: the run, then its marker, then the report."""
    from ray import tune

    spec = config["trial"]
    folder = Path(spec["folder"])
    metrics = flat_metrics(run_trial(folder, list(spec["sets"])))
    atomic_write_text(folder / MARKER, json.dumps({"name": spec["name"], "sets": spec["sets"],
                                                   "metrics": metrics}, indent=1))  # fmt: skip
    tune.report({**metrics, "finished": 1.0})


def _trial_name(trial) -> str:
    return trial.config["trial"]["name"]


def _error_text(error: BaseException | None) -> str:
    """The message of the exception a trial raised (its :class:`TrialFailed` where it is one),
    not Ray's wrapping of it."""
    if error is None:
        return "no result"
    text = str(error)
    marker = f"{TrialFailed.__name__}: "
    if marker in text:
        return text.rsplit(marker, 1)[1].strip().splitlines()[0]
    lines = [ln for ln in text.strip().splitlines() if ln.strip()]
    return lines[-1].strip() if lines else type(error).__name__


def run_sweep(trials: Sequence[Trial], out_dir: str | Path,
              run_trial: Callable[[Path, list[str]], Mapping], *, address: str | None = None,
              cpus_per_trial: float = 1.0) -> list[TrialResult]:  # fmt: skip
    """Run the unfinished trials through Ray Tune and collect every trial's result.

    Args:
        trials: The space's trials (:func:`expand_trials`).
        out_dir: The sweep folder; trial ``t`` runs in ``out_dir / t.name`` (on a cluster of
            several machines, a folder every node mounts at the same path).
        run_trial: ``run_trial(folder, sets)`` runs the command in ``folder`` with the extra
            ``--set`` arguments ``sets`` (resuming what the folder holds) and returns the
            numbers to report (a nested record is flattened, :func:`flat_metrics`); raises
            (:class:`TrialFailed`) when the run fails. Picklable: it runs in a Ray actor.
        address: The Ray cluster (:func:`grip.cluster.ray_pool.connect`).
        cpus_per_trial: CPUs Ray reserves for each trial.

    Prints a line when a trial finishes or fails.

    Returns:
        One result per trial, in the order of ``trials``.

    Raises:
        RayUnavailable: Ray is missing or the cluster cannot be reached.
        ValueError: Two trials with the same values.
    """
    out = Path(out_dir).absolute()
    names = [t.name for t in trials]
    if len(set(names)) != len(names):
        raise ValueError("two trials of the sweep have the same values")
    results: dict[str, TrialResult] = {}
    todo = []
    for t in trials:
        kept = _read_marker(out / t.name, t)
        if kept is not None:
            results[t.name] = TrialResult(t, "kept", kept)
        else:
            todo.append(t)
    if results:
        print(f"{len(results)} finished trial(s) kept, {len(todo)} to run")
    if todo:
        ray = import_ray()
        owned = connect(address)
        try:
            _fit(todo, out, run_trial, cpus_per_trial, results)
        finally:
            if owned:
                ray.shutdown()
    return [results[n] for n in names]


def _fit(todo: Sequence[Trial], out: Path, run_trial, cpus: float,
         results: dict[str, TrialResult]) -> None:  # fmt: skip
    """Ray Tune over ``todo`` (one grid point per trial); fills ``results``."""
    from ray import tune

    by_name = {t.name: t for t in todo}
    specs = [{"name": t.name, "folder": str(out / t.name), "sets": t.sets()} for t in todo]
    n = len(todo)

    class _Progress(tune.Callback):  # (Tune pickles its callbacks: no captured functions)
        def __init__(self) -> None:
            self.ended = 0

        def on_trial_complete(self, iteration, trials, trial, **info) -> None:
            self.ended += 1
            print(f"[{self.ended}/{n}] {_trial_name(trial)} finished", flush=True)

        def on_trial_error(self, iteration, trials, trial, **info) -> None:
            self.ended += 1
            print(f"[{self.ended}/{n}] {_trial_name(trial)} failed", flush=True)

    trainable = tune.with_resources(tune.with_parameters(_tune_trial, run_trial=run_trial),
                                    {"cpu": cpus})  # fmt: skip
    names = tune.TuneConfig(trial_name_creator=_trial_name, trial_dirname_creator=_trial_name)
    runs = tune.RunConfig(name="tune", storage_path=str(out / ".tune"), verbose=0,
                          callbacks=[_Progress()])  # fmt: skip
    tuner = tune.Tuner(trainable, param_space={"trial": tune.grid_search(specs)},
                       tune_config=names, run_config=runs)  # fmt: skip
    grid = tuner.fit()
    for k in range(len(grid)):
        res = grid[k]
        name = res.config["trial"]["name"]
        if res.error is None and res.metrics and res.metrics.get("finished"):
            metrics = _read_marker(out / name, by_name[name])
            if metrics is None:
                results[name] = TrialResult(by_name[name], "failed", error=(
                    f"finished, but {out / name / MARKER} is not visible here: the sweep "
                    "folder must be on a file system every node mounts at the same path"))
            else:
                results[name] = TrialResult(by_name[name], "done", metrics)
        else:
            results[name] = TrialResult(by_name[name], "failed", error=_error_text(res.error))
    for t in todo:  # (a trial Tune never reported on)
        results.setdefault(t.name, TrialResult(t, "failed", error="no result from Ray Tune"))


def results_table(results: Sequence[TrialResult], metric: str, goal: str) -> str:
    """A Markdown table of the trials, best ``metric`` first (failures and trials without the
    metric last): trial, status, one column per swept key, the metric, and the error."""
    keys = list(dict.fromkeys(k for r in results for k, _ in r.trial.values))
    sign = 1.0 if goal == "min" else -1.0

    def order(r: TrialResult) -> tuple:
        v = r.metrics.get(metric)
        ok = v is not None and math.isfinite(v)
        return (r.status == "failed", not ok, sign * v if ok else 0.0)

    head = ["trial", "status", *keys, f"{metric} ({goal})", "error"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in sorted(results, key=order):
        vals = dict(r.trial.values)
        v = r.metrics.get(metric)
        cells = [r.trial.name, r.status,
                 *(toml_literal(vals[k]) if k in vals else "" for k in keys),
                 "n/a" if v is None else f"{v:.6g}", r.error.replace("|", "\\|")]  # fmt: skip
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_results(out_dir: str | Path, results: Sequence[TrialResult], metric: str,
                  goal: str) -> str:  # fmt: skip
    """Write ``sweep.md`` (:func:`results_table`) and ``sweep.json`` into the sweep folder;
    returns the table."""
    out = Path(out_dir)
    table = results_table(results, metric, goal)
    atomic_write_text(out / TABLE, table + "\n")
    rows = [{"trial": r.trial.name, "status": r.status, "values": dict(r.trial.values),
             "metrics": r.metrics, "error": r.error} for r in results]  # fmt: skip
    atomic_write_text(out / RESULTS, json.dumps({"metric": metric, "goal": goal, "trials": rows},
                                                indent=1))  # fmt: skip
    return table
