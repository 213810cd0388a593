"""Helpers for resumable, parallel runs (stdlib only): settings that a resume must match,
worker processes that end with their parent, temporary files a killed run left behind, and
what every run folder records (:func:`git_hash`, :func:`history_wall_s`).

``grip data build``, ``grip reconstruct`` and every trainer's run folder
(:class:`grip.core.rundir.RunDir`) resume into an output folder. Each records the settings its
outputs were made with and refuses to go on with other ones, except those it lets change
(:func:`changed_settings`, :func:`require_same_settings`, :func:`record_settings`), so a folder
never mixes outputs of two settings. Worker pools start every worker with
:func:`exit_with_parent` (``fork``) or :func:`exit_with_process` (``forkserver``, ``spawn``),
and every pool of calls offers :class:`CallPool`.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

from grip.core.atomic import atomic_write_text

#: How often a worker checks that its parent still lives, s.
PARENT_POLL_S = 0.5
#: ``prctl`` option: signal sent to this process when its parent dies (Linux).
_PR_SET_PDEATHSIG = 1
#: Temporary files of :func:`grip.core.atomic.atomic_write`: ``.<name>.<8 random chars>.tmp``.
_TEMP_NAME = re.compile(r"^\..+\.[a-z0-9_]{8}\.tmp$")


class CallPool(Protocol):
    """What the commands need of a pool that runs their units of work elsewhere: worker
    processes of this machine (:class:`grip.eval.pool.WorkerPool`) or Ray tasks on a cluster
    (:class:`grip.cluster.RayPool`).

    Attributes:
        workers: How many calls run at once (what units of work are sized by).
    """

    workers: int

    def run(self, calls: Sequence[tuple[Callable, tuple]],
            done: Callable[[int, object], object]) -> list[int]:  # fmt: skip
        """Run ``fn(*args)`` of each call; ``done(index, result)`` here as each finishes (the
        result is the exception the call raised where it raised; if ``done`` raises, the calls
        not started are cancelled and the exception propagates). Returns the indices of the
        calls lost because the process running them died."""
        ...


def git_hash() -> str:
    """The repository's commit (``"unknown"`` outside a git checkout), recorded by every run."""
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                             cwd=Path(__file__).resolve().parent, timeout=5)  # fmt: skip
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def history_wall_s(history: list[dict]) -> float:
    """Seconds of training (epochs with their validation) over every sitting of a run, from its
    history's last ``wall_s``; epochs of checkpoints written before it was recorded count as 0."""
    return float(history[-1].get("wall_s", 0.0)) if history else 0.0


class SettingsMismatch(ValueError):
    """A resume was asked with other settings than the outputs already there were made with."""


def _normalised(settings: Mapping[str, Any]) -> dict[str, Any]:
    """``settings`` as JSON gives it back (tuples as lists, keys as strings)."""
    return json.loads(json.dumps(dict(settings)))


def flatten_settings(settings: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested settings as one level of dotted keys (``{"ppo": {"lr": 1}}`` ->
    ``{"ppo.lr": 1}``); lists and other values stay as they are."""
    out: dict[str, Any] = {}
    for k, v in settings.items():
        if isinstance(v, Mapping):
            out.update(flatten_settings(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def _compared(old: Mapping[str, Any], new: Mapping[str, Any], common_only: bool,
              may_change: tuple[str, ...],
              defaults: Mapping[str, Any] | None) -> tuple[dict, dict, list[str]]:  # fmt: skip
    """Both settings flattened (``old`` completed from ``defaults``) and the keys that differ."""
    a = flatten_settings(_normalised(old))
    b = flatten_settings(_normalised(new))
    if defaults is not None:
        a = {**{k: v for k, v in flatten_settings(_normalised(defaults)).items() if k not in a},
             **a}  # fmt: skip
    keys = set(a) & set(b) if common_only else set(a) | set(b)
    missing = object()
    changed = [k for k in sorted(keys) if a.get(k, missing) != b.get(k, missing)
               and not (may_change and k.startswith(may_change))]  # fmt: skip
    return a, b, changed


def changed_settings(old: Mapping[str, Any], new: Mapping[str, Any],
                     defaults: Mapping[str, Any] | None = None, may_change: tuple[str, ...] = (),
                     common_only: bool = False) -> list[str]:  # fmt: skip
    """The dotted keys whose values differ between two (nested) settings.

    Args:
        old: Settings recorded with the existing outputs.
        new: Settings of this run.
        defaults: The current default settings: a key missing from ``old`` (a setting added
            to the project after the outputs were made) takes its value from here, so a new
            setting left at its default does not block a resume.
        may_change: Dotted key prefixes that may differ (``"ppo.learning_rate"``, ``"stage2."``).
        common_only: Compare only keys both hold (outputs of an older version that recorded
            fewer settings).

    Returns:
        The differing keys, sorted.
    """
    return _compared(old, new, common_only, may_change, defaults)[2]


def settings_diff(old: Mapping[str, Any], new: Mapping[str, Any], common_only: bool = False,
                  may_change: tuple[str, ...] = (),
                  defaults: Mapping[str, Any] | None = None) -> list[str]:  # fmt: skip
    """``"key: old -> new"`` for every setting that differs (:func:`changed_settings`).

    Returns:
        One line per differing dotted key, sorted by key; empty when the settings agree.
    """
    a, b, changed = _compared(old, new, common_only, may_change, defaults)
    missing = "(not set)"
    return [f"{k}: {a.get(k, missing)} -> {b.get(k, missing)}" for k in changed]


def require_same_settings(old: Mapping[str, Any], new: Mapping[str, Any], where: str | Path,
                          hint: str, common_only: bool = False, *,
                          may_change: tuple[str, ...] = (),
                          defaults: Mapping[str, Any] | None = None,
                          what: str = "this folder was made with different settings",
                          ) -> None:  # fmt: skip
    """Refuse to resume with settings other than the recorded ones.

    Args:
        old: Settings recorded with the existing outputs.
        new: Settings of this run.
        where: The file that recorded ``old`` (named in the message).
        hint: What the user can do instead, e.g. ``"use another --out or the same options"``
            (empty: nothing is added).
        common_only, may_change, defaults: See :func:`changed_settings`.
        what: What the message says is wrong.

    Raises:
        SettingsMismatch: ``"{where}: {what} ({key: old -> new; ...}); {hint}"``.
    """
    diff = settings_diff(old, new, common_only, may_change, defaults)
    if diff:
        raise SettingsMismatch(f"{where}: {what} ({'; '.join(diff)})"
                               + (f"; {hint}" if hint else ""))  # fmt: skip


def record_settings(path: str | Path, settings: Mapping[str, Any], hint: str, *,
                    may_change: tuple[str, ...] = (),
                    defaults: Mapping[str, Any] | None = None) -> None:  # fmt: skip
    """Record a run's settings before its first output, or check them against the record.

    The first run writes ``path`` atomically; every later run (a resume, perhaps of a killed run
    that never wrote its summary) must bring the same settings.

    Args:
        path: The settings file (JSON).
        settings: JSON-serialisable settings of this run.
        hint: See :func:`require_same_settings`.
        may_change, defaults: See :func:`require_same_settings`; the record is rewritten when
            a setting that may change did.

    Raises:
        SettingsMismatch: ``path`` holds other settings.
        ValueError: ``path`` is not readable JSON (the message says to remove it).
    """
    path = Path(path)
    if path.is_file():
        try:
            old = json.loads(path.read_text(encoding="utf-8"))
            if not isinstance(old, dict):
                raise ValueError("not a JSON object")
        except (OSError, ValueError) as e:
            raise ValueError(f"{path}: corrupt settings file ({e}); remove it to start "
                             "over, or use another --out") from e  # fmt: skip
        require_same_settings(old, settings, path, hint, may_change=may_change,
                              defaults=defaults)  # fmt: skip
        if old == _normalised(settings):
            return
    atomic_write_text(path, json.dumps(_normalised(settings), indent=1, sort_keys=True))


def remove_stale_temps(folder: str | Path, recursive: bool = True) -> list[Path]:
    """Delete the temporary files an interrupted atomic write left in ``folder``.

    Only names of the form :func:`grip.core.atomic.atomic_write` uses are touched. Call it only
    while no other process writes into ``folder``.

    Returns:
        The files removed.
    """
    folder = Path(folder)
    if not folder.is_dir():
        return []
    removed = []
    for p in folder.rglob(".*.tmp") if recursive else folder.glob(".*.tmp"):
        if _TEMP_NAME.match(p.name) and p.is_file():
            with contextlib.suppress(OSError):
                p.unlink()
                removed.append(p)
    return removed


def exit_with_parent() -> None:
    """Initializer of a worker process: end it as soon as its parent process ends.

    A pool's workers otherwise outlive a parent killed with SIGKILL (they wait on a queue
    whose write end they hold themselves). On Linux the kernel sends SIGKILL on the parent's
    death (``prctl(PR_SET_PDEATHSIG)``); everywhere, a daemon thread checks every
    :data:`PARENT_POLL_S` seconds whether the parent process changed and exits if so.
    Pass it as ``initializer=`` of :class:`concurrent.futures.ProcessPoolExecutor` with the
    ``fork`` start method; with ``forkserver`` or ``spawn`` a worker's parent is not the
    process that made the pool: use :func:`exit_with_process` (:class:`grip.eval.pool.
    WorkerPool` does).
    """
    parent = os.getppid()
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
    if os.getppid() != parent:  # the parent died before the above took effect
        os._exit(1)
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True,
                     name="exit-with-parent").start()  # fmt: skip


def _watch_parent(parent: int) -> None:
    while True:
        time.sleep(PARENT_POLL_S)
        if os.getppid() != parent:
            os._exit(1)


def process_start(pid: int) -> str | None:
    """When process ``pid`` started (clock ticks since boot, from ``/proc``): with its pid,
    what names one process even after the pid is reused. ``None`` without ``/proc`` or when
    no such process runs."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return fields[19] if len(fields) > 19 and fields[0] not in "ZX" else None


def process_alive(pid: int, start: str | None = None) -> bool:
    """Whether process ``pid`` (started at ``start``, :func:`process_start`; ``None``: any)
    still runs; a zombie does not."""
    if start is not None or Path("/proc/self/stat").is_file():
        now = process_start(pid)
        return now is not None and (start is None or now == start)
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def exit_with_process(owner: int, owner_start: str | None = None) -> None:
    """Initializer of a worker process: end it as soon as process ``owner`` ends.

    The process that made a pool is not its workers' parent with the ``forkserver`` or
    ``spawn`` start methods (the forkserver is), so :func:`exit_with_parent` watches the wrong
    process: after ``kill -9`` of the command, its workers and the forkserver (which lives as
    long as a worker holds its pipe) lived on for hours. A daemon thread checks every
    :data:`PARENT_POLL_S` seconds that ``owner`` (the same process: ``owner_start``) still
    runs, and ends this worker when not.

    Args:
        owner: The process whose end ends this worker (the command's, ``os.getpid()`` where
            the pool is made).
        owner_start: Its :func:`process_start`, taken there (tells a reused pid).
    """
    if not process_alive(owner, owner_start):
        os._exit(1)
    threading.Thread(target=_watch_process, args=(owner, owner_start), daemon=True,
                     name="exit-with-owner").start()  # fmt: skip


def _watch_process(owner: int, owner_start: str | None) -> None:
    while True:
        time.sleep(PARENT_POLL_S)
        if not process_alive(owner, owner_start):
            os._exit(1)
