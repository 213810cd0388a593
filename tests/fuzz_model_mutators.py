"""Mutators of :mod:`tests.test_fuzz_inputs` for what expands or declares (issue 50): zip members
that claim gigabytes, model files whose settings and declared sizes are extreme, and text
exports with a line of megabytes. Each keeps the file small; a loader that believed it would
allocate the claim."""

from __future__ import annotations

import io
import json
import re
import struct

import numpy as np

from tests.fuzz_mutators import flip

EXTREME_SETTINGS = (0, -1, 1e-6, 0.5, 1e6, 10**7, 2**62, 1e300, float("nan"), float("inf"))
_HUGE = 0xF0000000  # ~4 GB, below the zip64 marker 0xFFFFFFFF


def zip_size_lie(rng: np.random.Generator, b: bytes) -> bytes:
    """One zip member (central directory and local header) claiming ~4 GB uncompressed."""
    entries = [m.start() for m in re.finditer(rb"PK\x01\x02", b)]
    entries = [i for i in entries if len(b) >= i + 46
               and struct.unpack("<I", b[i + 24 : i + 28])[0] != 0xFFFFFFFF]  # fmt: skip
    if not entries:
        return flip(rng, b)
    i = entries[int(rng.integers(len(entries)))]
    out = bytearray(b)
    out[i + 24 : i + 28] = struct.pack("<I", _HUGE)
    local = struct.unpack("<I", b[i + 42 : i + 46])[0]
    if b[local : local + 4] == b"PK\x03\x04":
        out[local + 22 : local + 26] = struct.pack("<I", _HUGE)
    return bytes(out)


def _numeric_leaves(tree, path=()) -> list[tuple]:
    if isinstance(tree, dict):
        return [p for k, v in tree.items() for p in _numeric_leaves(v, (*path, k))]
    if isinstance(tree, list):
        return [p for i, v in enumerate(tree) for p in _numeric_leaves(v, (*path, i))]
    if isinstance(tree, int | float) and not isinstance(tree, bool):
        return [path]
    return []


def _extreme_config(rng: np.random.Generator, text: str) -> str:
    """One to three numbers of a JSON config replaced by extreme values."""
    tree = json.loads(text)
    leaves = _numeric_leaves(tree)
    for k in rng.choice(len(leaves), size=min(len(leaves), int(rng.integers(1, 4))),
                        replace=False):  # fmt: skip
        *parents, leaf = leaves[int(k)]
        node = tree
        for p in parents:
            node = node[p]
        node[leaf] = EXTREME_SETTINGS[int(rng.integers(len(EXTREME_SETTINGS)))]
    return json.dumps(tree)


def torch_settings(rng: np.random.Generator, b: bytes) -> bytes:
    """A KinematicsNet checkpoint or policy file (one of its members) with extreme settings:
    numbers of its config, and for a policy its declared layer sizes or observation keys."""
    import torch

    try:
        obj = torch.load(io.BytesIO(b), map_location="cpu", weights_only=True)
    except Exception:  # (not a torch file: a mutant of a mutant)
        return flip(rng, b)
    targets = [obj] if "config" in obj else list(obj.get("members", []))
    m = targets[int(rng.integers(len(targets)))]
    what = int(rng.integers(4)) if "actor_sizes" in m else 0
    if what <= 1:
        m["config"] = _extreme_config(rng, m["config"])
    elif what == 2:
        sizes = list(m["actor_sizes"])
        sizes[int(rng.integers(len(sizes)))] = [10**7, 0, 12_000, -5][int(rng.integers(4))]
        m["actor_sizes"] = sizes
    else:
        keys = list(m["obs_keys"])
        keys[int(rng.integers(len(keys)))] = ["lidar", keys[0], "teacher_shift"][
            int(rng.integers(3))]  # fmt: skip
        m["obs_keys"] = keys
    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def long_line(rng: np.random.Generator, b: bytes) -> bytes:
    """A line of a text export grown by 2 MiB of digits (past ``max_line_bytes``)."""
    ends = [m.start() for m in re.finditer(rb"\n", b)] or [len(b)]
    i = ends[int(rng.integers(len(ends)))]
    return b[:i] + b"1" * (2 * 2**20) + b[i:]
