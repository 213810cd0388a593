"""``--ray [ADDRESS]`` and ``--tune SPACE.toml``: what the commands share to run their work on
a Ray cluster (:mod:`grip.cluster`; Ray is imported only when one of them is given).

Each command keeps its own units of work and output files; it only chooses the pool that runs
the units (:func:`ray_pool`, :func:`command_pool`). ``grip kin train`` and ``grip policy train``
run a sweep of ordinary runs, one per trial (:func:`tune_train`).
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import functools
import json
import os
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

from grip.cli.errors import CliError

RAY_TAKES_PATHS = (".npz", ".pkl", ".toml", ".pt", ".json", ".csv")
"""Suffixes of files, never of a Ray address: ``--ray take.npz`` took a recording as the
address."""


def add_ray_argument(p: argparse.ArgumentParser, units: str) -> None:
    """``--ray [ADDRESS]``: the command's ``units`` as Ray tasks (:func:`ray_pool`)."""
    p.add_argument("--ray", nargs="?", const="", default=None, metavar="ADDRESS",
                   help=f"run the {units} as Ray tasks instead of local worker processes "
                   "(--workers is then not used): on the cluster at ADDRESS (HOST:6379, auto, "
                   "ray://HOST:10001), or without ADDRESS on a Ray started on this machine for "
                   "the command; the same output files, resume and failure reports. Give it "
                   "after the positional arguments, or as --ray=ADDRESS. On several machines "
                   "the data and output folders must be shared (docs/cluster.md)")  # fmt: skip


def add_tune_arguments(p: argparse.ArgumentParser) -> None:
    """``--tune SPACE.toml`` and the ``--ray [ADDRESS]`` of its trials (:func:`tune_train`)."""
    p.add_argument("--tune", type=Path, default=None, metavar="SPACE.toml",
                   help="a hyper-parameter sweep through Ray Tune: one run per combination (grid) "
                   "or per drawn combination (random) of the --set values listed in SPACE.toml, "
                   "each in its own run folder OUT/trial_<hash>; running it again skips the "
                   "finished trials and resumes the others; the results table is "
                   "OUT/sweep.md (format: docs/cluster.md)")  # fmt: skip
    p.add_argument("--ray", nargs="?", const="", default=None, metavar="ADDRESS",
                   help="with --tune: run the trials on the Ray cluster at ADDRESS (default: a "
                   "Ray started on this machine)")  # fmt: skip


def _absolute(p: Path) -> Path:
    return Path(os.path.abspath(p))


def ray_args(args: argparse.Namespace) -> None:
    """With ``--ray`` or ``--tune``: check ``--ray``'s address and make every path argument
    absolute (Ray's workers and Tune's trials do not run in this folder). Without: nothing.

    Raises:
        CliError: ``--ray`` took a file as its address.
    """
    address, tune = getattr(args, "ray", None), getattr(args, "tune", None)
    if address is None and tune is None:
        return
    if address and (Path(address).exists() or address.lower().endswith(RAY_TAKES_PATHS)):
        raise CliError(f"--ray took {address!r} as the Ray cluster's address; give --ray after "
                       "the positional arguments, or write --ray=ADDRESS")  # fmt: skip
    for k, v in vars(args).items():
        if isinstance(v, Path):
            setattr(args, k, _absolute(v))
        elif isinstance(v, list) and v and all(isinstance(x, Path) for x in v):
            setattr(args, k, [_absolute(x) for x in v])


@contextlib.contextmanager
def ray_pool(args: argparse.Namespace) -> Iterator:
    """A :class:`grip.cluster.RayPool` on ``args.ray``'s cluster, or ``None`` without
    ``--ray``.

    Raises:
        CliError: Ray is not installed (how to install it), or the cluster cannot be reached.
    """
    if getattr(args, "ray", None) is None:
        yield None
        return
    from grip.cluster import RayPool, RayUnavailable

    try:
        with RayPool(args.ray or None) as pool:
            yield pool
    except RayUnavailable as e:
        raise CliError(f"--ray: {e}") from e


@contextlib.contextmanager
def command_pool(args: argparse.Namespace, workers: int,
                 initializer: Callable[[], object] | None = None) -> Iterator:  # fmt: skip
    """The pool of a command that runs its units in this process without one: Ray's with
    ``--ray`` (:func:`ray_pool`), else ``workers`` local processes
    (:class:`grip.eval.pool.WorkerPool`) when more than one, else ``None`` (in this process)."""
    if getattr(args, "ray", None) is not None:
        with ray_pool(args) as pool:
            yield pool
    elif workers > 1:
        from grip.eval.pool import WorkerPool

        with WorkerPool(workers, initializer) as pool:
            yield pool
    else:
        yield None


# ------------------------------------------------------------------------------- --tune
def kin_metrics(folder: Path) -> dict:
    """The last epoch record of a ``grip kin train`` run (KinematicsNet or a baseline):
    ``epoch``, ``train``, ``val`` (``val/total`` the validation loss)."""
    from grip.cluster import TrialFailed
    from grip.nn.weights import load_checkpoint

    try:
        history = json.loads(load_checkpoint(folder / "last.pt")["history"])
    except (OSError, ValueError, KeyError) as e:
        raise TrialFailed(f"{folder / 'last.pt'}: no training history ({e})") from e
    if not history:
        raise TrialFailed(f"{folder / 'last.pt'}: no finished epoch")
    return history[-1]


def policy_metrics(folder: Path) -> dict:
    """The last rollout record of a ``grip policy train`` run (``timesteps``, ``reward/...``,
    ``amp/...``, and ``success_rate``, ``mpjpe_mm`` where episodes ended)."""
    from grip.cluster import TrialFailed
    from grip.core.limits import read_json_file

    path = folder / "checkpoint" / "state.json"
    try:
        history = read_json_file(path, "training state").get("history")
    except ValueError as e:
        raise TrialFailed(str(e)) from e
    if not isinstance(history, list) or not history or not isinstance(history[-1], dict):
        raise TrialFailed(f"{path}: no rollout in the training history")
    return history[-1]


def _run_trial(args: argparse.Namespace, read_metrics: Callable[[Path], dict], folder: Path,
               sets: list[str]) -> dict:  # fmt: skip
    """One trial (in a Ray Tune actor): the command with ``--out folder`` and ``sets`` after its
    own ``--set`` options, its output in ``folder/trial.log``; its run's last record."""
    from grip.cluster import TrialFailed

    trial = copy.copy(args)
    trial.out, trial.set, trial.tune, trial.ray = folder, [*args.set, *sets], None, None
    folder.mkdir(parents=True, exist_ok=True)
    log = folder / "trial.log"
    with open(log, "a", encoding="utf-8") as f, contextlib.redirect_stdout(f), \
            contextlib.redirect_stderr(f):  # fmt: skip
        try:
            rc = int(args.func(trial) or 0)
        except CliError as e:
            print(f"grip: error: {e}")
            raise TrialFailed(f"{e} (log: {log})") from None
    if rc != 0:
        raise TrialFailed(f"the run exited with status {rc} (log: {log})")
    return read_metrics(folder)


def tune_train(args: argparse.Namespace, check: Callable[[list[str]], object],
               read_metrics: Callable[[Path], dict], metric: str, goal: str) -> int:  # fmt: skip
    """``grip kin train|policy train --tune SPACE.toml [--ray [ADDRESS]]``: every trial of the
    space (:func:`grip.cluster.expand_trials`) as the command's ordinary run in
    ``OUT/<trial>``, through Ray Tune (:func:`grip.cluster.run_sweep`), then the results table.

    Args:
        args: The command's arguments (``args.func`` runs one trial).
        check: ``check(sets)`` loads the settings of a run with the extra ``--set`` arguments
            ``sets`` and raises :class:`CliError` on a bad key or value: every trial is checked
            before Ray starts.
        read_metrics: A run folder -> its last history record (the trial's report).
        metric, goal: What the table sorts by when the space names none.

    Returns:
        0, or 1 when a trial failed (each is named on stderr with its error).
    """
    from grip.cluster import RayUnavailable, expand_trials, load_space, run_sweep, write_results

    ray_args(args)
    if args.tune is None:
        raise CliError("--ray runs the trials of --tune SPACE.toml; one run trains in this "
                       "process (give --tune, or leave out --ray)")  # fmt: skip
    try:
        space = load_space(args.tune)
    except ValueError as e:
        raise CliError(f"--tune: {e}") from e
    trials = expand_trials(space)
    for t in trials:
        try:
            check(t.sets())
        except CliError as e:
            raise CliError(f"{args.tune}: the trial {' '.join(t.sets())}: {e}") from e
    metric, goal = space.metric or metric, space.goal or goal
    where = f"the Ray cluster at {args.ray}" if args.ray else "a local Ray"
    print(f"{len(trials)} trial(s) of {args.tune} ({space.mode}) on {where} -> "
          f"{args.out}/trial_*")  # fmt: skip
    run = functools.partial(_run_trial, args, read_metrics)
    try:
        results = run_sweep(trials, args.out, run, address=args.ray or None,
                            cpus_per_trial=space.cpus_per_trial)  # fmt: skip
    except RayUnavailable as e:
        raise CliError(f"--tune: {e}") from e
    print(write_results(args.out, results, metric, goal))
    failed = [r for r in results if r.status == "failed"]
    for r in failed:
        print(f"grip: error: {r.trial.name} ({' '.join(r.trial.sets())}): {r.error}",
              file=sys.stderr)  # fmt: skip
    print(f"wrote {args.out / 'sweep.md'} and {args.out / 'sweep.json'}")
    return 1 if failed else 0
