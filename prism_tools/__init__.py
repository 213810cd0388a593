"""PRISM-format recordings: schema, validation, safe I/O, chunking and split files.

numpy (and, for :mod:`prism_tools.synthetic`, scipy) only: never imports torch, mujoco or
gymnasium. Importing the package does not import scipy.
"""

from prism_tools.chunking import chunk_recording, make_split
from prism_tools.errors import RecordingError
from prism_tools.io import load_recording, save_recording
from prism_tools.schema import Recording
from prism_tools.validation import validate

__all__ = [
    "Recording",
    "RecordingError",
    "chunk_recording",
    "load_recording",
    "make_split",
    "save_recording",
    "validate",
]
