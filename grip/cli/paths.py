"""Where the command line looks for things by default."""

from __future__ import annotations

import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]


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
