"""The seeded mutators of :mod:`tests.test_fuzz_inputs`: bytes, text formats, ``.npz`` members,
JSON metadata, and lone surrogates in the strings of a recording or a reconstruction."""

from __future__ import annotations

import io
import json
import pickle
import zipfile

import numpy as np

EXTREMES = ("nan", "inf", "-inf", "1e308", "1e30", "-1e30", "0", "-0", "1800", "1e-9",
            "9" * 5000, "1e-320", "abc", "", "0x10", "-1")  # fmt: skip


def flip(rng: np.random.Generator, b: bytes) -> bytes:
    a = bytearray(b)
    for i in rng.integers(0, len(a), size=int(rng.integers(1, 9))):
        a[i] = int(rng.integers(0, 256))
    return bytes(a)


def cut(rng: np.random.Generator, b: bytes) -> bytes:
    return b[: int(rng.integers(0, len(b)))]


def delete(rng: np.random.Generator, b: bytes) -> bytes:
    i = int(rng.integers(0, len(b)))
    return b[:i] + b[i + int(rng.integers(1, 200)) :]


def repeat(rng: np.random.Generator, b: bytes) -> bytes:
    i = int(rng.integers(0, len(b)))
    chunk = b[i : i + int(rng.integers(1, 200))]
    return b[:i] + chunk * int(rng.integers(2, 50)) + b[i:]


def insert(rng: np.random.Generator, b: bytes) -> bytes:
    i = int(rng.integers(0, len(b)))
    return (
        b[:i]
        + rng.integers(0, 256, size=int(rng.integers(1, 64))).astype(np.uint8).tobytes()
        + b[i:]
    )


BYTE_MUTATORS = (flip, cut, delete, repeat, insert)


def text_number(rng: np.random.Generator, b: bytes) -> bytes:
    """Replace one to three numeric tokens by extreme or malformed values."""
    toks = b.split(b" ")
    numeric = [i for i, t in enumerate(toks) if t.strip()[:1] in b"-0123456789"]
    if not numeric:
        return flip(rng, b)
    for i in rng.choice(numeric, size=min(len(numeric), int(rng.integers(1, 4))), replace=False):
        tail = b"\n" if toks[i].endswith(b"\n") else b""
        toks[i] = EXTREMES[int(rng.integers(len(EXTREMES)))].encode() + tail
    return b" ".join(toks)


def text_lines(rng: np.random.Generator, b: bytes) -> bytes:
    """Delete, repeat or swap lines."""
    lines = b.split(b"\n")
    i, j = (int(x) for x in rng.integers(0, len(lines), size=2))
    op = int(rng.integers(3))
    if op == 0:
        del lines[i]
    elif op == 1:
        lines[i:i] = [lines[i]] * int(rng.integers(2, 400))
    else:
        lines[i], lines[j] = lines[j], lines[i]
    return b"\n".join(lines)


TEXT_MUTATORS = (*BYTE_MUTATORS, text_number, text_number, text_lines, text_lines)


def npz_members(b: bytes) -> dict[str, bytes]:
    with zipfile.ZipFile(io.BytesIO(b)) as z:
        return {n: z.read(n) for n in z.namelist()}


def npz_bytes(members: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for n, data in members.items():
            z.writestr(n, data)
    return buf.getvalue()


def npy(arr: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, arr, allow_pickle=False)
    return buf.getvalue()


def lying_header(shape: tuple[int, ...]) -> bytes:
    """An ``.npy`` whose header claims ``shape`` (float64) but holds a few bytes: a bomb."""
    header = repr({"descr": "<f8", "fortran_order": False, "shape": shape}).encode()
    header += b" " * (63 - (len(header) + 10) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header + b"\0" * 64


def deep(depth: int) -> str:
    return "[" * depth + "]" * depth


def mutate_json_text(rng: np.random.Generator, text: str) -> str:
    op = int(rng.integers(5))
    if op == 0:
        return deep(int(rng.choice([1000, 200_000])))
    if op == 1:
        return text.replace(":", ": " + "9" * 5000 + ', "x":', 1)
    if op == 2:
        try:
            d = json.loads(text)
        except ValueError:
            return text[: len(text) // 2]
        if isinstance(d, dict) and d:
            k = list(d)[int(rng.integers(len(d)))]
            d[k] = [None, "x", -1, 1e308, {}, [], True][int(rng.integers(7))]
        return json.dumps(d)
    if op == 3:
        return '{"a": ' + deep(50_000) + "}"
    return text[: int(rng.integers(0, len(text) + 1))]


def npz_structured(rng: np.random.Generator, b: bytes) -> bytes:
    """Replace, reshape, retype or delete one member, lie in a header or break the metadata."""
    members = npz_members(b)
    names = list(members)
    name = names[int(rng.integers(len(names)))]
    meta = [n for n in names if "meta" in n]
    op = int(rng.integers(7))
    if op == 0 and meta:
        m = meta[0]
        arr = np.load(io.BytesIO(members[m]), allow_pickle=False)
        members[m] = npy(np.array(mutate_json_text(rng, str(arr))))
        return npz_bytes(members)
    arr = np.load(io.BytesIO(members[name]), allow_pickle=False)
    if op == 1:
        del members[name]
    elif op == 2 and arr.dtype.kind == "f" and arr.size:
        bad = arr.copy()
        flat = bad.reshape(-1)
        idx = rng.integers(0, flat.size, size=max(1, flat.size // 50))
        flat[idx] = [np.nan, np.inf, 1e30, -1e30, 0.0][int(rng.integers(5))]
        members[name] = npy(bad if rng.random() < 0.5 else arr * 1000.0)
    elif op == 3 and arr.ndim:
        members[name] = npy(arr[:-1] if rng.random() < 0.5 else arr.reshape(-1))
    elif op == 4 and arr.dtype.kind in "fiub":
        dtype = [np.int8, np.bool_, np.float16, "U3"][int(rng.integers(4))]
        members[name] = npy(arr.astype(dtype))
    elif op == 5:
        members[name] = lying_header((200_000, 10_000))
    else:
        members[name] = npy(np.zeros((0, *arr.shape[1:]), dtype=arr.dtype))
    return npz_bytes(members)


def surrogate_in(rng: np.random.Generator, tree):
    """``tree`` (JSON-like) with a lone surrogate (``os.fsdecode(b"\\xff")``) put into one of its
    strings, a value or a key."""
    spots = []  # (container, key, whether the key itself is the string)
    stack = [tree]
    while stack:
        node = stack.pop()
        pairs = node.items() if isinstance(node, dict) else enumerate(node)
        for k, v in list(pairs):
            if isinstance(node, dict) and isinstance(k, str):
                spots.append((node, k, True))
            if isinstance(v, str):
                spots.append((node, k, False))
            elif isinstance(v, dict | list):
                stack.append(v)
    if spots:
        node, k, is_key = spots[int(rng.integers(len(spots)))]
        if is_key:
            node[k[:1] + "\udcff" + k[1:]] = node.pop(k)
        else:
            node[k] = node[k][:1] + "\udcff" + node[k][1:]
    return tree


def npz_surrogates(rng: np.random.Generator, b: bytes) -> bytes:
    """A lone surrogate in one string of the JSON metadata (as a ``"\\udcff"`` escape)."""
    members = npz_members(b)
    meta = next((n for n in members if "meta" in n), None)
    if meta is None:  # (an AMASS clip: no strings of ours)
        return npz_structured(rng, b)
    arr = np.load(io.BytesIO(members[meta]), allow_pickle=False)
    members[meta] = npy(np.array(json.dumps(surrogate_in(rng, json.loads(str(arr))))))
    return npz_bytes(members)


def pickle_surrogates(rng: np.random.Generator, b: bytes) -> bytes:
    """A lone surrogate in one string of a (trusted, seed) pickle."""
    return pickle.dumps(surrogate_in(rng, pickle.loads(b)), protocol=4)


NPZ_MUTATORS = (*BYTE_MUTATORS, npz_structured, npz_structured, npz_structured,
                npz_surrogates)  # fmt: skip
PKL_MUTATORS = (*BYTE_MUTATORS, pickle_surrogates)
