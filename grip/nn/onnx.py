"""ONNX files of the project's networks: one way to trace, annotate and write them.

:mod:`policies.onnx` (the controller) and :mod:`grip.kinematics.onnx` (KinematicsNet's
streaming step) build a plain ``nn.Module`` of what they export and hand it to
:func:`write_onnx`, which traces it with torch's TorchScript exporter (``dynamo=False``: it
needs no package beyond ``onnx``), stores the layout of the inputs and outputs as the model's
``metadata_props`` (string keys and values, JSON where structured), checks the graph with
``onnx.checker`` and writes the file atomically. :func:`read_metadata` reads the properties
back. Imports torch and :mod:`grip.core`; ``onnx`` only when called (a dev extra: ``pip install
onnx onnxruntime``).
"""

from __future__ import annotations

import io
import os
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path

import torch
from torch import nn

from grip.core.atomic import atomic_write

OPSET = 17
"""ONNX opset of every export (onnxruntime >= 1.11 runs it)."""

PRODUCER = "grip"
"""``producer_name`` of every export."""


def require_onnx():
    """The ``onnx`` package, or an :class:`ImportError` saying how to install it."""
    try:
        import onnx
    except ImportError as e:
        raise ImportError("ONNX export needs the 'onnx' package: pip install onnx onnxruntime "
                          "(or pip install -e '.[dev]')") from e  # fmt: skip
    return onnx


def onnx_bytes(module: nn.Module, inputs: tuple[torch.Tensor, ...], input_names: Sequence[str],
               output_names: Sequence[str], dynamic_axes: Mapping[str, Mapping[int, str]],
               metadata: Mapping[str, str], doc: str) -> bytes:  # fmt: skip
    """The serialised ONNX model of ``module`` traced on ``inputs`` (float32, CPU).

    Args:
        module: The network, in eval mode (it is traced, so its ``forward`` must not branch on
            values).
        inputs: Example inputs of the right shapes (any values).
        input_names, output_names: Names of the graph's inputs and outputs, in ``forward``'s
            order.
        dynamic_axes: ``{name: {axis: symbol}}`` of axes of any size (the batch).
        metadata: ``metadata_props`` of the model (strings).
        doc: The model's ``doc_string``.

    Raises:
        ImportError: ``onnx`` is not installed (:func:`require_onnx`).
        ValueError: A metadata value is not a string.
    """
    onnx = require_onnx()
    bad = sorted(k for k, v in metadata.items() if not isinstance(k, str) or not isinstance(v, str))
    if bad:
        raise ValueError(f"ONNX metadata values must be strings: {bad}")
    buf = io.BytesIO()
    with warnings.catch_warnings():
        # torch >= 2.9 announces that the TorchScript exporter will go; it needs no
        # onnxscript, which the dynamo exporter would
        warnings.simplefilter("ignore", DeprecationWarning)
        with torch.no_grad():
            torch.onnx.export(module.eval(), inputs, buf, dynamo=False, opset_version=OPSET,
                              input_names=list(input_names), output_names=list(output_names),
                              dynamic_axes={k: dict(v) for k, v in dynamic_axes.items()},
                              do_constant_folding=True)  # fmt: skip
    model = onnx.load_from_string(buf.getvalue())
    model.producer_name = PRODUCER
    model.doc_string = doc
    onnx.helper.set_model_props(model, dict(metadata))
    onnx.checker.check_model(model)
    return model.SerializeToString()


def write_onnx(path: str | os.PathLike, data: bytes) -> int:
    """Write a serialised model atomically (whole or not at all); returns its size, bytes.

    Raises:
        OSError: naming the file, when it cannot be written.
    """
    path = Path(path)
    try:
        atomic_write(path, lambda f: f.write(data))
    except OSError as e:
        raise OSError(f"{path}: cannot write ({e.strerror or e})") from e
    return len(data)


def read_metadata(path: str | os.PathLike) -> dict[str, str]:
    """The ``metadata_props`` of an ONNX file (its weights are not loaded).

    Raises:
        FileNotFoundError: No such file.
        ValueError: naming the file, when it is no ONNX model.
    """
    onnx = require_onnx()
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        model = onnx.load(str(path), load_external_data=False)
    except Exception as e:  # protobuf raises several types for a file that is no model
        raise ValueError(f"{path}: not an ONNX model ({type(e).__name__}: "
                         f"{str(e)[:200]})") from e  # fmt: skip
    return {p.key: p.value for p in model.metadata_props}
