"""Text read from files, made safe to write anywhere.

A string read from a file can hold code points no encoder accepts: a lone surrogate
(``"\\udcff"``, what :func:`os.fsdecode` gives for an undecodable byte of a file name, or what a
pickle or a JSON ``"\\udcff"`` escape yields). Printed to a UTF-8 terminal or written to a UTF-8
file it raises :class:`UnicodeEncodeError`, so one such name once ended a whole batch after its
work was done. The rule: strings are cleaned where recordings and reconstructions are read
(:func:`prism_tools.io.load_recording`, :meth:`grip.core.reconstruction.Reconstruction.load`),
once, and every writer downstream can rely on them: each unencodable code point becomes U+FFFD
(a surrogate pair given as two halves becomes the character it encodes).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["REPLACEMENT", "clean_strings", "clean_text"]

REPLACEMENT = "\ufffd"
"""What an unencodable code point becomes."""

_SURROGATES = (0xD800, 0xDFFF)


def _encodable(text: str) -> bool:
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def clean_text(text: str) -> str:
    """``text`` with every code point UTF-8 cannot encode (a lone surrogate) replaced by U+FFFD.

    Returns ``text`` itself when there is nothing to replace.
    """
    if text.isascii() or _encodable(text):
        return text
    # UTF-16 joins a pair of halves into its character and turns each lone one into U+FFFD
    return text.encode("utf-16-le", "surrogatepass").decode("utf-16-le", "replace")


def _clean_array(a: np.ndarray) -> np.ndarray:
    """A text array (dtype ``U``) with its strings cleaned; ``a`` itself when they are clean."""
    flat = np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("=")).reshape(-1)
    if flat.size == 0 or flat.dtype.itemsize == 0:
        return a
    codes = flat.view(np.uint32)
    if not ((codes >= _SURROGATES[0]) & (codes <= _SURROGATES[1])).any():
        return a
    return np.array([clean_text(str(s)) for s in flat], dtype=str).reshape(a.shape)


def clean_strings(tree: Any) -> Any:
    """``tree`` with every string cleaned (:func:`clean_text`): values and dict keys, inside
    dicts, lists and tuples, and the strings of text arrays. Other values are kept as they are.

    The input is never changed; containers holding nothing to clean come back as the same
    objects.

    Raises:
        ValueError: Two keys of one dict become the same once cleaned (the message names them).
    """
    if isinstance(tree, str):
        return clean_text(tree)
    if isinstance(tree, np.ndarray):
        return _clean_array(tree) if tree.dtype.kind == "U" else tree
    if isinstance(tree, dict):
        out: dict = {}
        changed = False
        for k, v in tree.items():
            ck = clean_text(k) if isinstance(k, str) else k
            if ck in out:
                raise ValueError(f"two keys {k!r} and another become {ck!r} once their "
                                 "unencodable characters are replaced")  # fmt: skip
            out[ck] = cv = clean_strings(v)
            changed = changed or ck is not k or cv is not v
        return out if changed else tree
    if isinstance(tree, list | tuple):
        items = [clean_strings(v) for v in tree]
        if all(a is b for a, b in zip(items, tree, strict=True)):
            return tree
        return items if isinstance(tree, list) else tuple(items)
    return tree
