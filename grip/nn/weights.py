"""Weight storage shared by every network file: packed state dicts and safe checkpoint loading.

A state dict is stored at a precision (:func:`pack_weights`) and restored as float32
(:func:`unpack_weights`) by KinematicsNet exports, policy files and distilled students alike.
Checkpoints hold only tensors and plain containers, so :func:`load_checkpoint` reads them with
``torch.load(..., weights_only=True)``: a hostile file cannot run code; :func:`save_checkpoint`
writes one atomically. Every torch file is read by :func:`load_torch_file`, which bounds what
it expands to before torch inflates it, and a network is built from the sizes a file declares
only after :func:`check_declared_network` compared them with its weights. Imports torch and
:mod:`grip.core` only.
"""

from __future__ import annotations

import io
import os
import zipfile
from collections.abc import Callable, Mapping
from pathlib import Path

import torch
from torch import nn

from grip.core.atomic import atomic_write
from grip.core.limits import (
    InputLimits,
    LimitExceeded,
    active_limits,
    check_file_size,
    check_tree,
    check_zip,
)
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


def load_torch_file(source: str | os.PathLike | bytes, what: str, name: str | None = None,
                    limits: InputLimits | None = None) -> object:  # fmt: skip
    """``torch.load(source, weights_only=True)`` on the CPU, with what the file expands to
    bounded before torch inflates any of it.

    A torch file is a zip; torch's reader allocates each member's declared size, deflated or
    not (a 400 kB file of deflated zeros asks for 400 MB). The file size, its members' declared
    sizes (:func:`grip.core.limits.check_zip`) and, once loaded, the tensors it holds (each
    counted at its logical size, every time it is referenced: a one-element storage viewed as
    10^9 elements counts 4 GB) are checked against the limits. The legacy (pre-zip) format,
    whose reader allocates what its pickle declares, is refused.

    Args:
        source: A path, or the bytes of a torch file (a member of another zip).
        what: What the file should be, for messages (``"policy file"``).
        name: How messages name the file (default: ``source``, a path).
        limits: Default :func:`grip.core.limits.active_limits`.

    Raises:
        FileNotFoundError: No such file.
        ValueError: ``"{name}: not a {what}: ..."`` for a corrupt file or one holding pickled
            Python objects (never executed), ``"{name}: ... the limit NAME=..."`` for one that
            would expand beyond a limit.
    """
    limits = limits or active_limits()
    label = name or str(source)
    data = io.BytesIO(source) if isinstance(source, bytes | bytearray) else source
    try:
        if not isinstance(data, io.BytesIO):
            check_file_size(data, limits)
        check_zip(data, limits, what)
        if isinstance(data, io.BytesIO):
            data.seek(0)
        obj = torch.load(data, map_location="cpu", weights_only=True)
        check_tree(obj, limits, "its content")
    except FileNotFoundError:
        raise
    except LimitExceeded as e:
        raise ValueError(f"{label}: {e}") from None
    except zipfile.BadZipFile:
        raise ValueError(f"{label}: not a {what}: corrupt or not a torch file (not a zip; the "
                         "legacy torch format is not read)") from None  # fmt: skip
    except Exception as e:  # torch raises many types for corrupt or hostile files
        raise ValueError(f"{label}: not a {what}: {describe_load_error(e)}") from e
    return obj


def check_declared_network(build: Callable[[], nn.Module], state: Mapping[str, object],
                           where: str, declared: str, counts: Mapping[str, int] | None = None,
                           limits: InputLimits | None = None) -> None:  # fmt: skip
    """Refuse a network whose declared sizes do not fit the weights a file holds, before it
    is built: ``build`` runs on torch's ``meta`` device (no memory), its parameter count is
    checked against ``max_model_params`` and its state dict's shapes against ``state``'s.

    Args:
        build: Builds the network from the sizes the file declares.
        state: The state dict the file holds (``<name>@scale`` entries of
            :func:`pack_weights` aside).
        where: The file, for messages.
        declared: What declared the sizes, for messages (``"actor_sizes [1275, 512, 69]"``).
        counts: Declared numbers of layers (name -> value), checked first: each layer holds
            at least one tensor, so none may exceed the tensors held (``layers = 10**7`` would
            take minutes to even describe on the meta device).
        limits: Default :func:`grip.core.limits.active_limits`.

    Raises:
        ValueError: ``"{where}: {declared}: ..."``: a layer count above what the file holds,
            too many parameters, or shapes (or names) that differ from the weights held.
    """
    limits = limits or active_limits()
    for name, value in (counts or {}).items():
        if not 0 <= value <= len(state):
            raise ValueError(f"{where}: {declared}: {name}={value} layers, but the file holds "
                             f"{len(state)} weight tensors in all")  # fmt: skip
    try:
        with torch.device("meta"):
            net = build()
    except (RuntimeError, ValueError, TypeError, OverflowError) as e:
        raise ValueError(f"{where}: {declared} does not describe a network ({e})") from None
    n = sum(p.numel() for p in net.parameters())
    try:
        limits.check("max_model_params", n, f"{declared}: a network of", " parameters")
    except LimitExceeded as e:
        raise ValueError(f"{where}: {e}") from None
    want = {k: tuple(v.shape) for k, v in net.state_dict().items()}
    have = {k: tuple(getattr(v, "shape", ())) for k, v in state.items()
            if not k.endswith(_SCALE)}  # fmt: skip
    if want.keys() != have.keys():
        extra, missing = sorted(have.keys() - want.keys()), sorted(want.keys() - have.keys())
        raise ValueError(f"{where}: {declared} does not fit the weights the file holds (missing "
                         f"{missing[:3]}, unexpected {extra[:3]})")  # fmt: skip
    bad = [k for k in want if want[k] != have[k]]
    if bad:
        k = bad[0]
        raise ValueError(f"{where}: {declared} does not fit the weights the file holds ({k}: "
                         f"declared {list(want[k])}, held {list(have[k])})")  # fmt: skip


def load_checkpoint(path: str | os.PathLike) -> dict:
    """Load a KinematicsNet checkpoint safely (:func:`load_torch_file`: ``weights_only=True``,
    its expansion bounded); errors name the file.

    Raises:
        FileNotFoundError: ``path`` does not exist.
        ValueError: naming the file, when it is unreadable, too large or lacks a checkpoint's
            keys.
    """
    path = Path(path)
    ck = load_torch_file(path, "KinematicsNet checkpoint")
    if not isinstance(ck, dict):
        raise ValueError(f"{path}: not a KinematicsNet checkpoint (a {type(ck).__name__})")
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
