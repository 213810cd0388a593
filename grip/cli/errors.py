"""The command line's one error type (a module of its own, so that every command module can
import it without importing the entry point that registers them)."""

from __future__ import annotations


class CliError(Exception):
    """A user-facing error: printed as ``grip: error: ...`` with exit code 2, no traceback."""
