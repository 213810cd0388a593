"""Weight storage shared by every network file: packed state dicts and safe checkpoint loading.

A state dict is stored at a precision (:func:`pack_weights`) and restored as float32
(:func:`unpack_weights`) by KinematicsNet exports, policy files and distilled students alike.
Checkpoints hold only tensors and plain containers, so :func:`load_checkpoint` reads them with
``torch.load(..., weights_only=True)``: a hostile file cannot run code; :func:`save_checkpoint`
writes one atomically. Imports torch and :mod:`grip.core` only.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import torch

from grip.core.atomic import atomic_write
from grip.core.loaderrors import describe_load_error

CHECKPOINT_VERSION = 1
"""Format version written into KinematicsNet checkpoints (``"version"``)."""

PRECISIONS: tuple[str, ...] = ("fp32", "fp16", "int8")
"""Weight storage of inference exports (:func:`pack_weights`)."""

_SCALE = "@scale"


def save_checkpoint(path: str | os.PathLike, obj: dict) -> int:
    """``torch.save(obj)`` written atomically to ``path`` (whole or not at all, even if the
    run is killed); returns the file size, bytes."""
    buf = io.BytesIO()
    torch.save(obj, buf)
    data = buf.getvalue()
    atomic_write(path, lambda f: f.write(data))
    return len(data)


def load_checkpoint(path: str | os.PathLike) -> dict:
    """Load a KinematicsNet checkpoint safely (``weights_only=True``); errors name the file.

    Raises:
        FileNotFoundError: ``path`` does not exist.
        ValueError: naming the file, when it is unreadable or lacks a checkpoint's keys.
    """
    path = Path(path)
    try:
        ck = torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise
    except Exception as e:  # torch raises many types for corrupt or hostile files
        raise ValueError(f"{path}: not a KinematicsNet checkpoint: {describe_load_error(e)}") from e
    missing = [k for k in ("version", "config", "model", "norm_mean", "norm_std") if k not in ck]
    if missing:
        raise ValueError(f"{path}: checkpoint lacks {missing}")
    return ck


def pack_weights(state: dict[str, torch.Tensor], precision: str) -> dict[str, torch.Tensor]:
    """A state dict stored at ``precision``: ``"fp32"``, ``"fp16"``, or ``"int8"`` (every weight
    matrix of at least 256 entries as int8 with one float32 scale per row, under
    ``<name>@scale``, symmetric: ``w = q * scale``; the rest float16). :func:`unpack_weights`
    restores float32 tensors."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision {precision!r}: use one of {list(PRECISIONS)}")
    out: dict[str, torch.Tensor] = {}
    for k, v in state.items():
        if not v.is_floating_point() or precision == "fp32":
            out[k] = v
        elif precision == "int8" and v.dim() == 2 and v.numel() >= 256:
            w = v.float()
            scale = w.abs().amax(dim=1, keepdim=True) / 127.0
            scale[scale == 0] = 1.0
            out[k] = torch.round(w / scale).to(torch.int8)
            out[k + _SCALE] = scale
        else:
            out[k] = v.half()
    return out


def unpack_weights(state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Float32 tensors of a state dict written by :func:`pack_weights` (any precision)."""
    return {k: v.float() * state[k + _SCALE] if k + _SCALE in state else v.float()
            for k, v in state.items() if not k.endswith(_SCALE)}  # fmt: skip
