"""Find motion clips in a folder tree, name, label, categorise and group them, and load them.

Supported clips: ``*.bvh``; ``*.amc`` (with their ASF, see
:func:`grip.motion.asf_amc.find_asf_for_amc` or a ``clips.csv`` ``asf`` column); DeepMimic
``*.txt``/``*.json`` files that are JSON objects with a ``"Frames"`` key (character files,
sidecars, licences and READMEs are skipped); AMASS-style ``*.npz`` holding ``poses`` and ``trans``;
poselib ``SkeletonMotion`` ``*.npy`` (NVIDIA ASE; pickled dicts read with the restricted
unpickler, :mod:`grip.motion.poselib`: a ``.npy`` naming any other global is reported, never run).

Clip ids are ``"<top folder>/<stem>"``, the top folder being the first folder below the searched
root (``cmu/02_01``, ``hdm05/HDM_bd_squat1Reps_001_120``,
``bandai_namco/dataset-1_walk_normal_001``, ``deepmimic/walk`` - DeepMimic's ``humanoid3d_``
prefix is dropped).

A clip's **label** is the source's own name for its motion:

* from a ``clips.csv`` (column ``file`` and the label columns of the :class:`CategoryMap`,
  ``category`` by default) in the clip's dataset folder or above;
* else a Bandai-Namco JSON sidecar ``{"content": id}`` indexing ``cfg/content_label.txt``
  (searched in the clip's folder and upwards), ``dataset-N_`` prefix removed (``"walk-back"``);
* else a DeepMimic clip's name (``"getup_faceup"``);
* else the name of a folder it sits in: the nearest one below the searched root whose name the
  category map knows (``walk/subject01/take.bvh`` -> ``walk``), so that one's own clips sorted
  into folders by motion get their categories;
* else none (``""``).

``grip data build --categories FILE.csv`` (clip -> category, :func:`load_clip_categories`)
overrides all of these for the clips it lists.

Its **category** is the label translated by a :class:`CategoryMap` (``configs/categories.toml``,
read by :func:`load_category_map`) into a vocabulary shared by every source, ``"unknown"`` where
the map has no entry. Without a map the category is the label's first item (text in parentheses
removed, cut at ``;`` or ``/``), lower case, spaces and dashes as ``_``
(``"jump_in_place; one_leg_balance"`` -> ``"jump_in_place"``), a Bandai Namco content label as it
is (``"walk-back"``) and a DeepMimic name's first word (``"getup"``).

Its **group** is what a split by person keeps on one side (:func:`clip_group`): the performer
where the source names one (a ``clips.csv`` ``person`` column; HDM05's actor in
``HDM_<actor>_...``; the CMU subject of ``<subject>_<trial>``), as ``"<top>/<person>"``
(``hdm05/bd``, ``cmu/02``); else the finest grouping the source allows: Bandai Namco's dataset and
acting style (``dataset-2_run_active_001`` -> ``bandai_namco/dataset-2/active``: its clips carry
no actor label, so that a style is never on both sides), and otherwise the clip itself (DeepMimic:
every clip a different skill, retargeted from unnamed CMU and SFU performers).

Files that look like clips but cannot be examined (an ``.npz`` that is not a readable zip, a
``.txt``/``.json`` starting with ``{`` that is not valid UTF-8 JSON, an unreadable ``clips.csv``
or ``content_label.txt``) are never fatal here: :func:`scan_clips` returns them with the reason
(:class:`SkippedFile`), and :func:`find_clips` leaves them out.
"""

from __future__ import annotations

import csv
import json
import re
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from grip.motion.amass import load_amass_npz
from grip.motion.asf_amc import find_asf_for_amc, load_amc
from grip.motion.bvh import load_bvh
from grip.motion.categories import (
    UNKNOWN,
    CategoryMap,
    load_category_map,
    load_clip_categories,
    norm_category,
    table_category,
)
from grip.motion.deepmimic import SKELETON_FILE, load_deepmimic
from grip.motion.poselib import is_poselib_npy, load_poselib
from grip.motion.source import MotionImportError, SourceMotion

__all__ = [
    "UNKNOWN",
    "CategoryMap",
    "ClipRef",
    "SkippedFile",
    "clip_group",
    "clip_person",
    "clip_ref",
    "find_clips",
    "load_category_map",
    "load_clip",
    "load_clip_categories",
    "scan_clips",
    "table_category",
]

_DATASET_MARKERS = ("SOURCE_AND_LICENSE.md", "clips.csv")
_DEEPMIMIC_PREFIX = "humanoid3d_"
_BANDAI_PREFIX = re.compile(r"^dataset-\d+_")
#: Bandai Namco file names: ``dataset-<N>_<content>_<style>_<take>`` (no ``_`` inside a label).
_BANDAI_NAME = re.compile(r"^(dataset-\d+)_[^_]+_([^_]+)_\d+$")
#: HDM05 file names: ``HDM_<actor>_<class>_<take>_<fps>``.
_HDM05_NAME = re.compile(r"^HDM_([A-Za-z]+)_")
#: CMU file names: ``<subject>_<trial>`` (``02_01``).
_CMU_NAME = re.compile(r"^(\d+)_\d+$")
#: Read at most this much of a .txt/.json to decide whether it is a DeepMimic clip.
_MAX_JSON_BYTES = 64 * 1024 * 1024
#: What examining a file may raise (beyond the importers' own errors): a hostile file must be
#: reported, never end the search.
_READ_ERRORS = (OSError, ValueError, EOFError, zipfile.BadZipFile, RecursionError, LookupError,
                MemoryError, OverflowError, csv.Error)  # fmt: skip


@dataclass(frozen=True)
class SkippedFile:
    """A file that looked like a clip (or clip metadata) but could not be examined.

    Attributes:
        path: The file.
        reason: Why, e.g. ``"not a readable npz (BadZipFile: File is not a zip file)"``.
    """

    path: Path
    reason: str


def _why(e: BaseException) -> str:
    return f"{type(e).__name__}: {str(e)[:200]}"


@dataclass(frozen=True)
class ClipRef:
    """A motion clip found on disk.

    Attributes:
        clip_id: Stable id, ``"<top folder>/<stem>"``.
        path: The clip's main file.
        fmt: ``"bvh" | "asf_amc" | "deepmimic" | "amass" | "poselib"``.
        category: Motion category (of the :class:`CategoryMap` given to the search) or
            ``"unknown"``.
        asf_path: The skeleton of an AMC clip (``None`` for other formats, or when it could not be
            found; :func:`load_clip` then raises a clear error).
        label: The source's own label of the motion, ``""`` when it has none (module docstring).
        person: The performer where the source names one (``"bd"``, ``"02"``), else ``""``.
        group: What a split by person keeps on one side: ``"<top>/<person>"``, Bandai Namco's
            ``"<top>/<dataset>/<style>"``, else the clip id (:func:`clip_group`).
    """

    clip_id: str
    path: Path
    fmt: str
    category: str = UNKNOWN
    asf_path: Path | None = None
    label: str = ""
    person: str = ""
    group: str = ""


def clip_person(stem: str, csv_row: Mapping[str, str] | None = None) -> str:
    """The performer of a clip where its source names one, else ``""``.

    A ``clips.csv`` ``person`` column wins; otherwise the file name: HDM05's
    ``HDM_<actor>_...`` (``HDM_bd_squat1Reps_001_120`` -> ``"bd"``) and CMU's
    ``<subject>_<trial>`` (``02_01`` -> ``"02"``).

    Args:
        stem: The clip file's name without its suffix.
        csv_row: The clip's ``clips.csv`` row, if any.
    """
    if csv_row is not None:
        person = csv_row.get("person")
        if isinstance(person, str) and person.strip():
            return person.strip()
    for pattern in (_HDM05_NAME, _CMU_NAME):
        m = pattern.match(stem)
        if m:
            return m.group(1)
    return ""


def clip_group(clip_id: str, stem: str, person: str = "") -> str:
    """The group a split by person keeps on one side (module docstring).

    Args:
        clip_id: ``"<top>/<name>"``.
        stem: The clip file's name without its suffix.
        person: :func:`clip_person`'s answer.

    Returns:
        ``"<top>/<person>"`` (``"hdm05/bd"``), Bandai Namco's ``"<top>/<dataset>/<style>"``
        (``"bandai_namco/dataset-2/active"``), else ``clip_id``.
    """
    top = clip_id.split("/")[0] if "/" in clip_id else ""
    prefix = f"{top}/" if top else ""
    if person:
        return f"{prefix}{person}"
    m = _BANDAI_NAME.match(stem)
    if m:
        return f"{prefix}{m.group(1)}/{m.group(2)}"
    return clip_id


def _dataset_root(path: Path, stop: Path | None) -> Path | None:
    """Nearest ancestor of ``path`` holding a dataset marker file, not above ``stop``."""
    for folder in path.parents:
        if any((folder / m).is_file() for m in _DATASET_MARKERS):
            return folder
        if stop is not None and folder == stop:
            break
    return None


class _CsvIndex:
    """Cached ``clips.csv`` look-ups: (resolved file path) -> row."""

    def __init__(self, problems: list[SkippedFile] | None = None) -> None:
        self._tables: dict[Path, dict[Path, dict[str, str]]] = {}
        self._problems = problems if problems is not None else []

    def row(self, clip: Path, stop: Path | None) -> tuple[Path, dict[str, str]] | None:
        for folder in clip.parents:
            csv_path = folder / "clips.csv"
            if csv_path.is_file():
                table = self._load(csv_path)
                hit = table.get(clip.resolve())
                if hit is not None:
                    return folder, hit
            if stop is not None and folder == stop:
                break
        return None

    def _load(self, csv_path: Path) -> dict[Path, dict[str, str]]:
        if csv_path not in self._tables:
            table: dict[Path, dict[str, str]] = {}
            try:
                with csv_path.open(newline="", encoding="utf-8-sig") as fh:
                    for row in csv.DictReader(fh):
                        if isinstance(row.get("file"), str) and row["file"]:
                            table[(csv_path.parent / row["file"]).resolve()] = row
            except _READ_ERRORS as e:  # categories (and ASF paths) of its clips stay unknown
                table = {}
                self._problems.append(
                    SkippedFile(
                        csv_path, f"not read, its clips get no category from it ({_why(e)})"
                    )
                )
            self._tables[csv_path] = table
        return self._tables[csv_path]


def _bandai_label(clip: Path, stop: Path | None) -> str | None:
    """The content label of a Bandai-Namco clip (its JSON sidecar's ``content`` id named by
    ``cfg/content_label.txt``, ``dataset-N_`` removed), or ``None``."""
    sidecar = clip.with_suffix(".json")
    if not sidecar.is_file():
        return None
    try:
        content = json.loads(sidecar.read_text(encoding="utf-8-sig"))["content"]
    except (*_READ_ERRORS, KeyError, TypeError):
        return None
    for folder in [clip.parent, *clip.parent.parents]:
        labels = folder / "cfg" / "content_label.txt"
        if labels.is_file():
            try:
                text = labels.read_text(encoding="utf-8-sig")
            except _READ_ERRORS:
                return None
            names = [ln.strip() for ln in text.splitlines()]
            names = [n for n in names if n]
            if isinstance(content, int) and 0 <= content < len(names):
                return _BANDAI_PREFIX.sub("", names[content])
            return None
        if stop is not None and folder == stop:
            break
    return None


class _NotExamined(Exception):
    """A candidate clip file could not be examined; the message says why."""


def _is_deepmimic_clip(path: Path) -> bool:
    if path.name == SKELETON_FILE:
        return False
    try:
        with path.open("rb") as fh:
            head = fh.read(256).removeprefix(b"\xef\xbb\xbf").lstrip()
    except OSError as e:
        raise _NotExamined(f"not readable ({_why(e)})") from e
    if not head.startswith(b"{"):
        return False  # a licence, a README, a label list: not JSON, not a clip
    try:
        size = path.stat().st_size
        if size > _MAX_JSON_BYTES:
            raise _NotExamined(f"JSON of {size} bytes, more than the {_MAX_JSON_BYTES} read")
        data = json.loads(path.read_text(encoding="utf-8-sig"))
    except _READ_ERRORS as e:
        raise _NotExamined(f"not valid UTF-8 JSON ({_why(e)})") from e
    return isinstance(data, dict) and "Frames" in data


def _is_amass_npz(path: Path) -> bool:
    try:
        with np.load(path, allow_pickle=False) as npz:
            return {"poses", "trans"} <= set(npz.files)
    except _READ_ERRORS as e:
        raise _NotExamined(f"not a readable npz ({_why(e)})") from e


def _is_poselib_npy(path: Path) -> bool:
    try:
        return is_poselib_npy(path)
    except MotionImportError as e:  # a refused global, a damaged pickle: reported, never run
        raise _NotExamined(e.problem) from e


def _detect_format(path: Path) -> str | None:
    """The clip format of ``path``, or ``None`` when it is not a clip.

    Raises:
        _NotExamined: A candidate (``.npz``, ``.npy``, or ``.txt``/``.json`` starting with
            ``{``) that cannot be read.
    """
    suffix = path.suffix.lower()
    if suffix == ".bvh":
        return "bvh"
    if suffix == ".amc":
        return "asf_amc"
    if suffix in (".txt", ".json") and _is_deepmimic_clip(path):
        return "deepmimic"
    if suffix == ".npz" and _is_amass_npz(path):
        return "amass"
    if suffix == ".npy" and _is_poselib_npy(path):
        return "poselib"
    return None


def _csv_label(row: Mapping[str, str], columns: tuple[str, ...]) -> str | None:
    for col in columns:
        value = row.get(col)
        if isinstance(value, str) and value.strip():
            return value.strip()
    return None


def _make_ref(path: Path, fmt: str, top: str, stop: Path | None, csvs: _CsvIndex,
              cmap: CategoryMap | None) -> ClipRef:  # fmt: skip
    stem = path.stem
    if fmt == "deepmimic":
        stem = stem.removeprefix(_DEEPMIMIC_PREFIX)
    clip_id = f"{top}/{stem}" if top else stem
    label: str | None = None
    row: dict[str, str] | None = None
    asf_path: Path | None = None
    hit = csvs.row(path, stop)
    if hit is not None:
        folder, row = hit
        label = _csv_label(row, cmap.label_columns if cmap is not None else ("category",))
        if fmt == "asf_amc" and row.get("asf"):
            cand = folder / row["asf"]
            asf_path = cand if cand.is_file() else None
    if fmt == "asf_amc" and asf_path is None:
        try:
            asf_path = find_asf_for_amc(path)
        except MotionImportError:
            asf_path = None
    from_csv = label is not None
    if label is None and fmt == "bvh":
        label = _bandai_label(path, stop)
    if label is None and fmt == "deepmimic":
        label = stem
    if label is None:
        label = _folder_label(path, stop, cmap)
        from_csv = bool(label)  # (a folder name is the user's own label, as a clips.csv one)
    label = label or ""
    if cmap is not None:
        category = cmap.category(label)
    elif not label:
        category = UNKNOWN
    elif from_csv:
        category = norm_category(label)
    elif fmt == "deepmimic":
        category = norm_category(stem.split("_")[0])
    else:  # a Bandai Namco content label, already one name
        category = label.lower()
    person = clip_person(path.stem, row)
    return ClipRef(clip_id=clip_id, path=path, fmt=fmt, category=category, asf_path=asf_path,
                   label=label, person=person,
                   group=clip_group(clip_id, path.stem, person))  # fmt: skip


def _folder_label(path: Path, stop: Path | None, cmap: CategoryMap | None) -> str | None:
    """A clip without a label anywhere else takes a folder's name as its label: the nearest
    folder between it and the searched root (the root itself excluded; a single file outside a
    search: its own folder) whose name the map knows (``walk/subject01/take.bvh`` -> ``walk``);
    ``None`` when there is none or no map (folder names such as ``bvh`` or ``takes`` are not
    categories)."""
    if cmap is None:
        return None
    if stop is None:
        folders = [path.parent]
    else:
        try:
            rel = path.parent.relative_to(stop)
        except ValueError:
            rel = Path()
        folders = [stop.joinpath(*rel.parts[:k]) for k in range(len(rel.parts), 0, -1)]
    for folder in folders:
        if cmap.category(folder.name) != UNKNOWN:
            return folder.name
    return None


def find_clips(root: str | Path, categories: CategoryMap | None = None) -> list[ClipRef]:
    """Every supported motion clip under ``root``, sorted by clip id.

    Hidden files and folders are skipped. Where two files would get the same id, the ids of both
    use their path relative to the top folder (without suffix) instead of the stem. Files that
    cannot be examined are left out; :func:`scan_clips` also says which and why.

    Args:
        root: Folder to search recursively.
        categories: Translates the sources' labels into categories (module docstring);
            ``None``: categories as the labels give them.

    Returns:
        The clips found (an empty list for an empty folder).

    Raises:
        FileNotFoundError: ``root`` is not a folder.
    """
    return scan_clips(root, categories)[0]


def scan_clips(root: str | Path, categories: CategoryMap | None = None
               ) -> tuple[list[ClipRef], list[SkippedFile]]:  # fmt: skip
    """Like :func:`find_clips`, and also the files it had to skip, with the reason.

    Args:
        root: Folder to search recursively.
        categories: See :func:`find_clips`.

    Returns:
        ``(clips, skipped)``: the clips sorted by clip id, and the candidate clip files or clip
        metadata (``clips.csv``) that could not be read, sorted by path.

    Raises:
        FileNotFoundError: ``root`` is not a folder.
    """
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: not a folder")
    skipped: list[SkippedFile] = []
    csvs = _CsvIndex(skipped)
    refs: list[ClipRef] = []
    for path in sorted(root.rglob("*")):
        rel = path.relative_to(root)
        if any(part.startswith(".") for part in rel.parts) or not path.is_file():
            continue
        try:
            fmt = _detect_format(path)
        except _NotExamined as e:
            skipped.append(SkippedFile(path, str(e)))
            continue
        if fmt is None:
            continue
        top = rel.parts[0] if len(rel.parts) > 1 else root.name
        try:
            refs.append(_make_ref(path, fmt, top, root, csvs, categories))
        except _READ_ERRORS as e:
            skipped.append(SkippedFile(path, f"not examined ({_why(e)})"))
    counts: dict[str, int] = {}
    for ref in refs:
        counts[ref.clip_id] = counts.get(ref.clip_id, 0) + 1
    if any(c > 1 for c in counts.values()):
        fixed = []
        for ref in refs:
            if counts[ref.clip_id] > 1:
                rel = ref.path.relative_to(root)
                inner = Path(*rel.parts[1:]) if len(rel.parts) > 1 else rel
                new_id = f"{ref.clip_id.split('/')[0]}/{inner.with_suffix('').as_posix()}"
                group = new_id if ref.group == ref.clip_id else ref.group
                ref = replace(ref, clip_id=new_id, group=group)
            fixed.append(ref)
        refs = fixed
    refs = sorted(refs, key=lambda r: (r.clip_id, str(r.path)))
    return refs, sorted(skipped, key=lambda s: str(s.path))


def clip_ref(path: str | Path, categories: CategoryMap | None = None) -> ClipRef:
    """A :class:`ClipRef` for a single file, as :func:`find_clips` would name it.

    The top folder is the dataset folder: the nearest ancestor holding ``SOURCE_AND_LICENSE.md``
    or ``clips.csv``, else the file's own folder. ``categories``: see :func:`find_clips`.

    Raises:
        MotionImportError: The file does not exist or is not a supported clip.
    """
    path = Path(path)
    if not path.is_file():
        raise MotionImportError(path, "no such file")
    try:
        fmt = _detect_format(path)
    except _NotExamined as e:
        raise MotionImportError(path, str(e)) from e
    if fmt is None:
        raise MotionImportError(
            path,
            "not a supported clip (.bvh, .amc, DeepMimic JSON with 'Frames', AMASS .npz, "
            "poselib SkeletonMotion .npy)",
        )
    dataset = _dataset_root(path, None)
    top = dataset.name if dataset is not None else path.parent.name
    return _make_ref(path, fmt, top, dataset, _CsvIndex(), categories)


def load_clip(ref_or_path: ClipRef | str | Path) -> SourceMotion:
    """Load a clip, dispatching on its format; name and category come from the :class:`ClipRef`.

    Args:
        ref_or_path: A :class:`ClipRef` from :func:`find_clips`, or a path (see :func:`clip_ref`).

    Raises:
        MotionImportError: The file is missing, unsupported or invalid.
    """
    ref = ref_or_path if isinstance(ref_or_path, ClipRef) else clip_ref(ref_or_path)
    if ref.fmt == "bvh":
        return load_bvh(ref.path, name=ref.clip_id, category=ref.category)
    if ref.fmt == "asf_amc":
        return load_amc(ref.path, ref.asf_path, name=ref.clip_id, category=ref.category)
    if ref.fmt == "deepmimic":
        return load_deepmimic(ref.path, name=ref.clip_id, category=ref.category)
    if ref.fmt == "amass":
        return load_amass_npz(ref.path, name=ref.clip_id, category=ref.category)
    if ref.fmt == "poselib":
        return load_poselib(ref.path, name=ref.clip_id, category=ref.category)
    raise MotionImportError(ref.path, f"unknown clip format {ref.fmt!r}")
