"""Motion categories: each source's labels translated into one shared vocabulary.

A :class:`CategoryMap` (``configs/categories.toml``, read by :func:`load_category_map`) maps a
source's own label of a clip (``"walk-turn-left"``, ``"squat1Reps"``, ``"sit_stand (prop: high
stool)"``) to one category name (``"walk-turn"``, ``"squat"``, ``"sit-stand"``), ``"unknown"``
where it has no entry. A user's table of clips and their categories (``grip data build
--categories FILE.csv``) is read by :func:`load_clip_categories` and looked up by
:func:`table_category`. Where clips get their labels from is :mod:`grip.motion.catalog`'s
business.
"""

from __future__ import annotations

import csv
import os
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

#: A category name: lower case words joined by dashes (glob-friendly: ``walk*`` selects them).
_CATEGORY_NAME = re.compile(r"^[a-z][a-z0-9]*(-[a-z0-9]+)*$")
UNKNOWN = "unknown"


@dataclass(frozen=True)
class CategoryMap:
    """Each source's motion labels translated into one shared vocabulary of categories.

    Attributes:
        vocabulary: The category names (lower case, words joined by ``-``), without
            ``"unknown"``, which every unmapped label gets.
        labels: Label (lower case, runs of white space as one space) -> category of
            ``vocabulary``.
        label_columns: The ``clips.csv`` columns that hold a clip's label; the first non-empty
            one wins.
        source: Where the map was read from (for messages).
    """

    vocabulary: tuple[str, ...]
    labels: Mapping[str, str] = field(default_factory=dict)
    label_columns: tuple[str, ...] = ("category",)
    source: str = ""

    def __post_init__(self) -> None:
        where = self.source or "category map"
        for name in self.vocabulary:
            if not isinstance(name, str) or not _CATEGORY_NAME.match(name) or name == UNKNOWN:
                raise ValueError(f"{where}: vocabulary name {name!r} must be lower case words "
                                 "joined by '-' (and not 'unknown')")  # fmt: skip
        vocab = set(self.vocabulary)
        for label, cat in self.labels.items():
            if cat not in vocab and cat != UNKNOWN:
                raise ValueError(f"{where}: label {label!r} maps to {cat!r}, which is not in "
                                 "the vocabulary")  # fmt: skip
        if not self.label_columns or not all(isinstance(c, str) for c in self.label_columns):
            raise ValueError(f"{where}: label_columns must be a non-empty list of column names")

    def category(self, label: str) -> str:
        """The category of a source label: the whole label, then its first item (text in
        parentheses removed, cut at ``;`` or ``/``), each looked up in :attr:`labels` and then
        in :attr:`vocabulary`, case-insensitively; ``"unknown"`` when nothing matches."""
        vocab = set(self.vocabulary)
        for key in _label_keys(label):
            if key in self.labels:
                return self.labels[key]
            if key in vocab:
                return key
        return UNKNOWN


def _label_key(text: str) -> str:
    return " ".join(text.lower().split())


def _first_item(text: str) -> str:
    text = re.sub(r"\([^)]*\)", " ", text)
    return " ".join(re.split(r"[;/]", text)[0].lower().split())


def _label_keys(label: str) -> list[str]:
    """The look-up keys of a label, most specific first (no duplicates, no empty ones)."""
    first = _first_item(label)
    keys = [_label_key(label), first, re.sub(r"[\s\-]+", "_", first).strip("_")]
    return [k for i, k in enumerate(keys) if k and k not in keys[:i]]


def load_clip_categories(path: str | os.PathLike) -> dict[str, str]:
    """A user's table of clips and their categories (``grip data build --categories FILE.csv``):
    a CSV with a ``clip`` or ``file`` column (a clip id such as ``mine/take1``, a file name, a
    stem, or a path relative to the searched root) and a ``category`` column.

    Raises:
        ValueError: Naming the file (and the line): unreadable, missing columns, an empty
            category, or a clip listed twice.
    """
    path = Path(path)
    try:
        with path.open(newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise ValueError(f"{path}: not a readable CSV ({e})") from e
    table: dict[str, str] = {}
    for line, row in enumerate(rows, start=2):
        key = (row.get("clip") or row.get("file") or "").strip()
        cat = (row.get("category") or "").strip()
        if not key or not cat:
            raise ValueError(f"{path}, line {line}: needs a 'clip' (or 'file') and a 'category' "
                             "value")  # fmt: skip
        if key in table:
            raise ValueError(f"{path}, line {line}: {key!r} is listed twice")
        table[key] = cat
    if not table:
        raise ValueError(f"{path}: no rows (columns 'clip' or 'file', and 'category')")
    return table


def table_category(table: Mapping[str, str], clip_id: str, path: Path, root: Path | None,
                   cmap: CategoryMap | None) -> tuple[str, str, str] | None:  # fmt: skip
    """``(label, category, key)`` of a clip from a :func:`load_clip_categories` table (matched
    by ``key``: clip id, path relative to ``root``, file name or stem), ``None`` when it is not
    listed. The
    value is the label; the map translates it, and a value the map does not know is kept as
    the category (lower case, spaces as ``-``)."""
    keys = [clip_id, path.name, path.stem]
    if root is not None:
        try:
            keys.insert(1, path.relative_to(root).as_posix())
        except ValueError:
            pass
    key = next((k for k in keys if k in table), None)
    if key is None:
        return None
    value = table[key]
    cat = cmap.category(value) if cmap is not None else UNKNOWN
    if cat == UNKNOWN:
        cat = "-".join(value.lower().split())
    return value, cat, key


def load_category_map(path: str | os.PathLike) -> CategoryMap:
    """Read a category map (``configs/categories.toml``: ``vocabulary``, ``label_columns`` and a
    ``[labels]`` table of label = category).

    Raises:
        FileNotFoundError: No such file.
        ValueError: Not valid TOML, an unknown key, a label mapped outside the vocabulary, or a
            vocabulary name that is not lower case words joined by ``-`` (the message names the
            file).
    """
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no such category map") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise ValueError(
            f"{path}: not a readable TOML category map ({type(e).__name__}: {str(e)[:200]})"
        ) from None
    unknown = sorted(set(data) - {"vocabulary", "labels", "label_columns"})
    if unknown:
        raise ValueError(f"{path}: unknown key(s) {unknown} (expected vocabulary, label_columns, "
                         "[labels])")  # fmt: skip
    vocab = data.get("vocabulary")
    labels = data.get("labels", {})
    columns = data.get("label_columns", ["category"])
    if not isinstance(vocab, list) or not vocab:
        raise ValueError(f"{path}: 'vocabulary' must be a non-empty list of category names")
    if not isinstance(labels, dict) or not all(isinstance(v, str) for v in labels.values()):
        raise ValueError(f"{path}: [labels] must map labels to category names (strings)")
    if not isinstance(columns, list):
        raise ValueError(f"{path}: 'label_columns' must be a list of column names")
    table: dict[str, str] = {}
    for label, cat in labels.items():
        if cat not in vocab and cat != UNKNOWN:
            raise ValueError(f"{path}: label {label!r} maps to {cat!r}, which is not in the "
                             "vocabulary")  # fmt: skip
        key = _label_key(label)
        if table.get(key, cat) != cat:
            raise ValueError(f"{path}: label {label!r} is mapped twice ({table[key]!r}, {cat!r}; "
                             "labels are compared case-insensitively)")  # fmt: skip
        table[key] = cat
    return CategoryMap(tuple(vocab), table, tuple(columns), str(path))


def norm_category(text: str) -> str:
    """A category without a map: the label's first item, spaces and dashes as ``_``."""
    first = re.sub(r"[\s\-]+", "_", _first_item(text)).strip("_")
    return first or UNKNOWN
