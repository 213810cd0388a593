"""Training data for KinematicsNet: a dataset folder's split -> arrays -> random windows.

Features and targets of every sequence of a split are computed once (numpy) and kept in memory
as float32; a typical dataset built from the shared clips (~125k frames) takes ~120 MB.
"""

from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from grip.core.body import build_body
from grip.kinematics.features import FeatureConfig, input_features, recording_body, targets

TARGET_KEYS: tuple[str, ...] = ("lp", "fp", "fa", "lv")


@dataclass
class SequenceArrays:
    """One sequence: inputs ``(T, F)`` and stage targets ``{stage: (T, dim)}`` (float32)."""

    name: str
    category: str
    x: np.ndarray
    y: dict[str, np.ndarray]
    root_pos: np.ndarray
    offsets: np.ndarray  # (24, 3) rest offsets of the subject's body model, m
    fps: float = 100.0  # frame rate of the recording, Hz


def sequence_arrays(rec, cfg: FeatureConfig, name: str | None = None) -> SequenceArrays:
    """Features and flattened stage targets of one recording (named ``name``, default the
    recording's own name)."""
    t = targets(rec)
    n = rec.n_frames
    y = {
        "lp": t.leaf_pos.reshape(n, -1),
        "fp": t.joint_pos.reshape(n, -1),
        "fa": t.rot6d.reshape(n, -1),
        "lv": t.velocity.reshape(n, -1),
    }
    return SequenceArrays(
        name=rec.name if name is None else name,
        category=rec.category or "unknown",
        x=input_features(rec, cfg),
        y={k: v.astype(np.float32) for k, v in y.items()},
        root_pos=t.root_pos.astype(np.float32),
        offsets=build_body(recording_body(rec)).offsets.astype(np.float32),
        fps=float(rec.fps),
    )


def split_files(data_dir: str | os.PathLike, split: str) -> list[Path]:
    """Recording files of ``split`` ("train", "test" or "all") of a ``grip data build`` folder.

    Raises:
        FileNotFoundError / ValueError naming the folder or the split file.
    """
    from prism_tools.chunking import load_split

    root = Path(data_dir)
    split_path = root / "split.json"
    if not split_path.is_file():
        raise FileNotFoundError(f"{root}: no split.json (build the folder with 'grip data build')")
    lists = load_split(split_path)
    if split not in ("train", "test", "all"):
        raise ValueError(f"split must be 'train', 'test' or 'all', got {split!r}")
    ids = lists["train"] + lists["test"] if split == "all" else lists[split]
    return [root / "sequences" / f"{sid}.npz" for sid in ids]


def load_split_sequences(
    data_dir: str | os.PathLike, split: str, cfg: FeatureConfig, limit: int | None = None
) -> list[SequenceArrays]:
    """All sequences of ``split`` ("train" or "test") of a ``grip data build`` folder, each
    named by its sequence id (the file stem, which :func:`clip_of` and the split's groups know;
    a recording's own name may differ, e.g. ``synthetic_<clip id>``).

    Raises:
        FileNotFoundError / ValueError naming the folder, the split file or the bad recording.
    """
    from prism_tools.io import load_recording

    files = split_files(data_dir, split)
    if limit is not None:
        files = files[:limit]
    out = []
    for path in files:
        try:
            out.append(sequence_arrays(load_recording(path), cfg, name=path.stem))
        except (KeyError, ValueError) as e:
            raise ValueError(f"{path}: {e}") from e
    return out


_CHUNK = re.compile(r"^(?P<clip>.+?)(?:_(?:v\d+|c))?_seq\d+$")


def clip_of(sequence_name: str) -> str:
    """The clip (or take) a sequence was cut from: ``<clip>_v0_seq003`` (``grip data build``:
    noise variant and chunk) and ``subj001_take002_seq003`` (PRISM) lose their suffixes; other
    names are their own clip."""
    m = _CHUNK.match(sequence_name)
    return m.group("clip") if m else sequence_name


def dataset_groups(data_dir: str | os.PathLike) -> dict[str, str]:
    """Clip (:func:`clip_of` of its sequences) -> group (performer, or the source's finest
    grouping) of a ``grip data build`` folder split by person; ``{}`` for a folder split by clip
    or built before groups were recorded (every clip is then its own group)."""
    from prism_tools.chunking import load_split, safe_name

    split = load_split(Path(data_dir) / "split.json")
    if split.get("split_by") != "person":
        return {}
    return {safe_name(c): g for g, clips in split.get("members", {}).items() for c in clips}


def group_fold(group: str, folds: int, seed: int) -> int:
    """The fold (``0 .. folds - 1``) of a group of clips (a person) in a K-fold split by person
    (``train.val_source = "fold"``): a hash of the group's name and ``seed``, so that a group's
    fold does not depend on which other groups a dataset holds (a controller's reference set
    finds the fold model that never saw a clip's person by the same rule,
    :func:`grip.kinematics.reference.build_cross_fitted_reference_set`)."""
    digest = hashlib.sha256(f"{seed}:{group}".encode()).digest()
    return int.from_bytes(digest[:8], "little") % folds


_VARIANT = re.compile(r"(?:@x[0-9.]+|-reversed)$")


def _clip_key(sequence_name: str) -> str:
    """The clip of a sequence or recording name in the keys' form of :func:`dataset_groups`:
    :func:`clip_of`, less the ``@x<factor>`` and ``-reversed`` of speed-scaled and
    time-reversed training clips, in the clip id's file-name form."""
    return _VARIANT.sub("", clip_of(sequence_name)).replace("/", "__")


def sequence_group(sequence_name: str, groups: Mapping[str, str]) -> str:
    """The group (person) of a sequence or recording name (its clip, :func:`_clip_key`,
    looked up in ``groups``, :func:`dataset_groups`); a clip that is not there is its own
    group."""
    clip = _clip_key(sequence_name)
    return groups.get(clip, clip)


def recording_group(rec, groups: Mapping[str, str]) -> str:
    """The group (person) of a recording of a ``grip data build`` folder: that of its source
    clip (``extras["source_clip"]``, the clip id the build and the augmentations record), or
    of its name when it has none (:func:`sequence_group`).

    Raises:
        ValueError: ``groups`` is not empty (a folder split by person) and does not know the
            recording's clip.
    """
    clip = rec.extras.get("source_clip") if isinstance(rec.extras, dict) else None
    name = clip if isinstance(clip, str) and clip else rec.name
    if groups and _clip_key(name) not in groups:
        raise ValueError(f"{rec.name}: its clip is in no group of the dataset's split by person, "
                         "so the model that never saw its person cannot be told")  # fmt: skip
    return sequence_group(name, groups)


def fold_split(
    seqs: list[SequenceArrays], folds: int, fold: int, seed: int,
    groups: Mapping[str, str] | None = None,
) -> tuple[list[SequenceArrays], list[SequenceArrays]]:  # fmt: skip
    """``(train, held_out)`` of fold ``fold`` of a K-fold split by person: the sequences whose
    group (:func:`sequence_group`) falls in that fold (:func:`group_fold`) are held out.

    Raises:
        ValueError: one side is empty (too few groups for ``folds``).
    """
    groups = groups or {}
    in_fold = [group_fold(sequence_group(s.name, groups), folds, seed) == fold for s in seqs]
    held = [s for s, h in zip(seqs, in_fold, strict=True) if h]
    train = [s for s, h in zip(seqs, in_fold, strict=True) if not h]
    if not train or not held:
        n = len({sequence_group(s.name, groups) for s in seqs})
        raise ValueError(f"fold {fold} of {folds} (seed {seed}) over {n} clip group(s) leaves "
                         "nothing to train or validate on")  # fmt: skip
    return train, held


def holdout_names(names: Sequence[str], fraction: float, seed: int,
                  groups: Mapping[str, str] | None = None) -> set[str]:  # fmt: skip
    """The sequence names that :func:`holdout_split` holds out (whole groups of clips)."""
    from prism_tools.chunking import make_split

    names = list(names)
    groups = groups or {}
    of = {n: groups.get(clip_of(n), clip_of(n)) for n in names}
    return set(make_split(names, fraction, seed, groups=of)["test"])


def holdout_split(
    seqs: list[SequenceArrays], fraction: float, seed: int,
    groups: Mapping[str, str] | None = None,
) -> tuple[list[SequenceArrays], list[SequenceArrays]]:  # fmt: skip
    """``(train, held_out)``: whole clips (:func:`clip_of`; all their chunks and noise variants)
    held out until they hold ``fraction`` of the sequences, drawn as ``grip data build`` draws
    its test split (:func:`prism_tools.chunking.make_split` with clip groups).

    Args:
        groups: Clip -> group (:func:`dataset_groups`): every clip of a held-out group is held
            out, so that validation, like the test split, has people never trained on. Clips
            not in it are their own group.

    Raises:
        ValueError: nothing would be left on one of the two sides (fewer than two groups, or a
            fraction that takes them all).
    """
    names = [s.name for s in seqs]
    held = holdout_names(names, fraction, seed, groups)
    train = [s for s in seqs if s.name not in held]
    val = [s for s in seqs if s.name in held]
    if not train or not val:
        groups = groups or {}
        units = sorted({groups.get(clip_of(n), clip_of(n)) for n in names})
        raise ValueError(f"holding out {fraction} of {len(units)} clip group(s) {units[:5]} "
                         "leaves nothing to train or validate on (it needs at least 2 clips "
                         "or groups)")  # fmt: skip
    return train, val


@dataclass(frozen=True)
class Normalizer:
    """Per-feature mean and standard deviation of the training inputs (saved in checkpoints)."""

    mean: np.ndarray
    std: np.ndarray

    @classmethod
    def fit(cls, seqs: list[SequenceArrays], min_std: float = 1e-3) -> Normalizer:
        x = np.concatenate([s.x for s in seqs], axis=0).astype(np.float64)
        return cls(x.mean(0).astype(np.float32), np.maximum(x.std(0), min_std).astype(np.float32))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return ((x - self.mean) / self.std).astype(np.float32)


def source_weights(seqs: Sequence[SequenceArrays], sources: Mapping[str, str],
                   balance: float) -> np.ndarray:  # fmt: skip
    """Sampling weight of each sequence: its length times its source's total frames to the
    power ``-balance`` (``sources``: sequence name -> source; sequences not in it are one source
    of their own name). 0 draws frames uniformly (a large source dominates), 0.5 gives each source
    a share in proportion to the square root of its frames, 1 the same share to every source.

    Returns:
        ``(len(seqs),)`` weights summing to 1.
    """
    if not 0.0 <= balance <= 1.0:
        raise ValueError(f"source balance must be in [0, 1], got {balance}")
    lengths = np.array([len(s.x) for s in seqs], dtype=np.float64)
    of = [sources.get(s.name, s.name) for s in seqs]
    total: dict[str, float] = {}
    for src, n in zip(of, lengths, strict=True):
        total[src] = total.get(src, 0.0) + n
    w = lengths * np.array([total[src] for src in of]) ** -balance
    return w / w.sum()


def training_weights(seqs: Sequence[SequenceArrays], sources: Mapping[str, str],
                     source_balance: float, category_balance: float) -> np.ndarray:
    """Sampling weight of each training sequence with both balances: its length times its
    source's total frames to the power ``-source_balance`` times its category's total frames
    to the power ``-category_balance`` (:func:`source_weights` for each, the categories read
    from ``SequenceArrays.category``). Both 0: frames drawn uniformly.

    Returns:
        ``(len(seqs),)`` weights summing to 1.
    """
    w = source_weights(seqs, sources, source_balance)
    if category_balance > 0:
        by_cat = source_weights(seqs, {s.name: s.category for s in seqs}, category_balance)
        lengths = np.array([len(s.x) for s in seqs], dtype=np.float64)
        w = w * by_cat / lengths
    return w / w.sum()


def sequence_sources(seqs: Sequence[SequenceArrays], groups: Mapping[str, str]) -> dict[str, str]:
    """Sequence name -> source (:func:`prism_tools.chunking.clip_source` of its clip, with
    ``groups`` from :func:`dataset_groups`)."""
    from prism_tools.chunking import clip_source

    return {s.name: clip_source(clip_of(s.name), groups.get(clip_of(s.name))) for s in seqs}


def sample_windows(
    seqs: list[SequenceArrays], n: int, length: int, rng: np.random.Generator,
    weights: np.ndarray | None = None, first_share: float = 0.0,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:  # fmt: skip
    """``n`` random windows of ``length`` frames (shorter sequences are padded by repeating
    their last frame; a window never crosses sequences), drawn with probabilities ``weights``
    (``(len(seqs),)`` summing to 1; default: in proportion to sequence length). A share
    ``first_share`` of the windows starts at its sequence's first frame (a clip's first
    sequence: the mover setting off), the others anywhere.

    Returns:
        ``x (n, length, F)`` and ``{key: (n, length, dim)}`` for every target key of the
        sequences (``TARGET_KEYS`` plus any the caller added to ``SequenceArrays.y``), plus
        ``"offsets": (n, 24, 3)``.
    """
    if weights is None:
        weights = np.array([len(s.x) for s in seqs], dtype=np.float64)
        weights = weights / weights.sum()
    pick = rng.choice(len(seqs), size=n, p=weights)
    keys = tuple(seqs[0].y)
    xs, offs, ys = [], [], {k: [] for k in keys}
    for i in pick:
        s = seqs[i]
        t = len(s.x)
        start = int(rng.integers(0, max(t - length, 0) + 1))
        if first_share > 0 and rng.random() < first_share:
            start = 0
        idx = np.minimum(np.arange(start, start + length), t - 1)
        xs.append(s.x[idx])
        for k in keys:
            ys[k].append(s.y[k][idx])
        offs.append(s.offsets)
    out = {k: np.stack(v) for k, v in ys.items()}
    out["offsets"] = np.stack(offs)
    return np.stack(xs), out

