"""Where the command line looks for things by default."""

from __future__ import annotations

import os
from pathlib import Path

from grip.assets import REPO_ROOT


def default_motions_dir() -> Path | None:
    """The shared motion clips: ``$GRIP_MOTIONS_DIR``, else ``../shared/data/motions`` next to
    the current folder or next to the repository checkout. ``None`` if none exists."""
    env = os.environ.get("GRIP_MOTIONS_DIR")
    candidates = [Path(env)] if env else []
    candidates += [Path.cwd().parent / "shared" / "data" / "motions",
                   REPO_ROOT.parent / "shared" / "data" / "motions"]  # fmt: skip
    for c in candidates:
        if c.is_dir():
            return c.resolve()
    return None


def load_run_config(path: Path | None, kind: str, default, overrides):
    """Settings of a run: ``default`` updated by the TOML at ``path`` (else
    ``configs/<kind>/default.toml`` when it exists) and ``--set`` overrides; errors become
    :class:`grip.cli.errors.CliError`."""
    from grip.cli.errors import CliError
    from grip.config import ConfigError, load_config

    if path is None:
        candidate = REPO_ROOT / "configs" / kind / "default.toml"
        path = candidate if candidate.is_file() else None
    try:
        return load_config(path, default, overrides)
    except (ConfigError, ValueError) as e:
        raise CliError(str(e)) from e
