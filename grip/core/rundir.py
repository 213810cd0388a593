"""The folder of one resumable training run (stdlib only), shared by every trainer.

A run folder holds ``config.json``: ``{"config": <resolved settings>, "git": <commit>, ...}``
with whatever else the command records (data, seed, the files it started from). Trainers
whose checkpoint is several files keep it in ``checkpoint/`` (``state.json`` holds the step
counters, the history and the wall time), written whole into ``checkpoint.tmp/`` and swapped
in by two renames (:meth:`RunDir.save_checkpoint`); trainers with a one-file checkpoint write
it atomically (:func:`grip.nn.weights.save_checkpoint`). Resuming with other settings than
the folder was made with is refused, except for the settings the trainer allows to change
(:meth:`RunDir.check_resume`, :func:`grip.core.runs.require_same_settings`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import shutil
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from grip.core.atomic import atomic_write_text
from grip.core.limits import read_json_file
from grip.core.runs import git_hash, require_same_settings

CONFIG_FILE = "config.json"
"""The resolved settings of a run, its git hash and what its command recorded."""
CHECKPOINT_DIR = "checkpoint"
"""The folder of a many-file checkpoint."""
STATE_FILE = "state.json"
"""Counters, history and wall time of a many-file checkpoint, inside :data:`CHECKPOINT_DIR`."""


def settings_dict(settings: Any) -> dict[str, Any]:
    """A config dataclass (or a mapping) as a plain dict, as ``config.json`` stores it."""
    if dataclasses.is_dataclass(settings) and not isinstance(settings, type):
        return dataclasses.asdict(settings)
    return dict(settings)


class RunDir:
    """One run folder: its ``config.json``, its checkpoint folder and its wall clock.

    Args:
        path: The folder (created by :meth:`write_config` or :meth:`save_checkpoint`).
        may_change: Dotted settings (prefixes) a resumed run may change
            (:func:`grip.core.runs.changed_settings`).
        what: What the folder is, for messages (``"'grip policy train' run"``).
    """

    def __init__(self, path: str | os.PathLike, may_change: tuple[str, ...] = (),
                 what: str = "training run") -> None:  # fmt: skip
        self.path = Path(path)
        self.may_change = tuple(may_change)
        self.what = what
        self.wall0_s = 0.0  # training seconds of the sittings before this one
        self._t0 = time.time()

    # ---------------------------------------------------------------------- config.json
    @property
    def config_path(self) -> Path:
        return self.path / CONFIG_FILE

    def read_config(self) -> dict | None:
        """``config.json`` (``None`` when there is none).

        Raises:
            ValueError: Naming the file, when it is not a JSON object.
        """
        if not self.config_path.is_file():
            return None
        return read_json_file(self.config_path, f"{self.what} config")

    def write_config(self, settings: Any, **extra: Any) -> None:
        """Write ``config.json`` atomically: the resolved ``settings`` (a config dataclass or a
        dict), the git hash and ``extra`` (JSON values: data folder, files started from)."""
        payload = {"config": settings_dict(settings), "git": git_hash(), **extra}
        self.path.mkdir(parents=True, exist_ok=True)
        atomic_write_text(self.config_path, json.dumps(payload, indent=1))

    def check_resume(self, settings: Any, defaults: Any = None,
                     recorded: Mapping[str, Any] | None = None,
                     upgrade: Callable[[dict, str], dict] | None = None) -> None:  # fmt: skip
        """Refuse to resume the checkpoint with other settings than ``config.json`` records.

        Nothing is checked when the folder has no checkpoint or no ``config.json``.

        Args:
            settings: This run's settings (a config dataclass or a dict).
            defaults: The current default settings: a setting missing from an older run's
                record counts as its default (:func:`grip.core.runs.changed_settings`).
            recorded: Top-level entries of ``config.json`` besides the settings that must be
                the same too (e.g. ``{"teacher": [...]}``).
            upgrade: ``upgrade(old_settings, where)``: an older run's recorded settings as this
                version writes them (settings since removed dropped when they were off; one that
                was on raises ``ValueError`` naming it), before they are compared.

        Raises:
            ValueError: A :class:`grip.core.runs.SettingsMismatch` naming every changed setting,
                or an unreadable ``config.json``.
        """
        if not self.has_checkpoint():
            return
        old = self.read_config()
        if old is None:
            return
        if not isinstance(old.get("config"), dict):
            raise ValueError(f"{self.config_path}: not a {self.what} config (no 'config' "
                             "object)")  # fmt: skip
        recorded = dict(recorded or {})
        old_cfg = old["config"] if upgrade is None else upgrade(old["config"],
                                                                 str(self.config_path))
        old_all = {**old_cfg, **{k: old.get(k) for k in recorded}}
        allowed = f"only {', '.join(self.may_change)} may change on resume; " if (
            self.may_change) else ""  # fmt: skip
        require_same_settings(old_all, {**settings_dict(settings), **recorded}, self.config_path,
                              f"{allowed}use another --out or the same settings",
                              may_change=self.may_change,
                              defaults=None if defaults is None else settings_dict(defaults),
                              what="resuming with different settings")  # fmt: skip

    # ---------------------------------------------------------------------- checkpoint/
    @property
    def checkpoint_dir(self) -> Path:
        return self.path / CHECKPOINT_DIR

    def _recover(self) -> None:
        """Put back the previous checkpoint of a run killed between the two renames of
        :meth:`save_checkpoint` (``checkpoint.old/`` left, no ``checkpoint/``)."""
        old = self.path / f"{CHECKPOINT_DIR}.old"
        if not self.checkpoint_dir.exists() and (old / STATE_FILE).is_file():
            old.rename(self.checkpoint_dir)

    def has_checkpoint(self) -> bool:
        """Whether the folder holds a checkpoint to resume (its ``state.json``)."""
        self._recover()
        return (self.checkpoint_dir / STATE_FILE).is_file()

    def read_state(self) -> dict | None:
        """``checkpoint/state.json`` (``None``: nothing to resume).

        Raises:
            ValueError: Naming the file, when it is not a JSON object.
        """
        if not self.has_checkpoint():
            return None
        return read_json_file(self.checkpoint_dir / STATE_FILE, "training state")

    def save_checkpoint(self, write: Callable[[Path], None], state: Mapping[str, Any]) -> None:
        """Replace ``checkpoint/`` atomically: ``write(folder)`` fills a fresh
        ``checkpoint.tmp/`` and ``state`` goes to its ``state.json``; the files are synced and
        the folder swapped in by renames, so a killed run resumes from the previous checkpoint
        or this one, never from a mix."""
        tmp = self.path / f"{CHECKPOINT_DIR}.tmp"
        old = self.path / f"{CHECKPOINT_DIR}.old"
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        write(tmp)
        (tmp / STATE_FILE).write_text(json.dumps(dict(state)))
        for f in tmp.iterdir():
            _fsync(f)
        _fsync(tmp)
        self._recover()
        shutil.rmtree(old, ignore_errors=True)
        if self.checkpoint_dir.exists():
            self.checkpoint_dir.rename(old)
        tmp.rename(self.checkpoint_dir)
        _fsync(self.path)
        shutil.rmtree(old, ignore_errors=True)

    # ---------------------------------------------------------------------- wall clock
    def wall_s(self) -> float:
        """Seconds of training over every sitting: those recorded before this one
        (:attr:`wall0_s`, from the checkpoint) plus this sitting's so far."""
        return self.wall0_s + time.time() - self._t0


def _fsync(path: Path) -> None:
    """Flush a file or a folder's entries to disk where the platform allows it."""
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
