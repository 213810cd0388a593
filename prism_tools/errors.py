"""Exceptions raised by :mod:`prism_tools`."""

from __future__ import annotations

__all__ = ["RecordingError"]


class RecordingError(ValueError):
    """A recording (file, dict or :class:`~prism_tools.schema.Recording`) is malformed.

    The message names the problem precisely: the key path inside the recording (for example
    ``"imu.L_Wrist.ori_world: expected shape (F, 3, 3) with F=1000, got (999, 3, 3)"``) and, when
    the recording came from a file, starts with the file path.
    """
