"""Training data for KinematicsNet: a dataset folder's split -> arrays -> random windows.

Features and targets of every sequence of a split are computed once (numpy) and kept in memory
as float32; a typical dataset built from the shared clips (~125k frames) takes ~120 MB. Windows
may be drawn at other playback speeds (:func:`sample_windows`), their rates rescaled to match
(:func:`time_warp_rates`).
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
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


def sequence_arrays(rec, cfg: FeatureConfig) -> SequenceArrays:
    """Features and flattened stage targets of one recording."""
    t = targets(rec)
    n = rec.n_frames
    y = {
        "lp": t.leaf_pos.reshape(n, -1),
        "fp": t.joint_pos.reshape(n, -1),
        "fa": t.rot6d.reshape(n, -1),
        "lv": t.velocity.reshape(n, -1),
    }
    return SequenceArrays(
        name=rec.name,
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
    """All sequences of ``split`` ("train" or "test") of a ``grip data build`` folder.

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
            out.append(sequence_arrays(load_recording(path), cfg))
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


def holdout_names(names: Sequence[str], fraction: float, seed: int) -> set[str]:
    """The sequence names that :func:`holdout_split` holds out (whole clips, :func:`clip_of`)."""
    from prism_tools.chunking import make_split

    names = list(names)
    return set(make_split(names, fraction, seed, groups={n: clip_of(n) for n in names})["test"])


def holdout_split(
    seqs: list[SequenceArrays], fraction: float, seed: int
) -> tuple[list[SequenceArrays], list[SequenceArrays]]:
    """``(train, held_out)``: whole clips (:func:`clip_of`; all their chunks and noise variants)
    held out until they hold ``fraction`` of the sequences, drawn as ``grip data build`` draws
    its test split (:func:`prism_tools.chunking.make_split` with clip groups).

    Raises:
        ValueError: nothing would be left on one of the two sides (fewer than two clips, or a
            fraction that takes them all).
    """
    names = [s.name for s in seqs]
    held = holdout_names(names, fraction, seed)
    train = [s for s in seqs if s.name not in held]
    val = [s for s in seqs if s.name in held]
    if not train or not val:
        clips = sorted({clip_of(n) for n in names})
        raise ValueError(f"holding out {fraction} of {len(clips)} clip(s) {clips[:5]} leaves "
                         "nothing to train or validate on (it needs at least 2 clips)")  # fmt: skip
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


def category_weights(seqs: list[SequenceArrays], balance: float) -> np.ndarray:
    """Sampling weights of sequences that even out their motion categories.

    A sequence weighs its length times ``F_c ** -balance``, ``F_c`` the frames of its category
    (``SequenceArrays.category``): ``balance = 0`` samples frames uniformly (each category in
    proportion to its frames), ``1`` gives every category the same share, values between
    interpolate (0.5: a category's share grows as the square root of its frames).
    """
    if not 0.0 <= balance <= 1.0:
        raise ValueError(f"category balance must be in [0, 1], got {balance}")
    lens = np.array([len(s.x) for s in seqs], dtype=np.float64)
    frames: dict[str, float] = {}
    for s, n in zip(seqs, lens, strict=True):
        frames[s.category] = frames.get(s.category, 0.0) + n
    return lens * np.array([frames[s.category] ** -balance for s in seqs])


def sample_windows(
    seqs: list[SequenceArrays], n: int, length: int, rng: np.random.Generator,
    speeds: np.ndarray | None = None, weights: np.ndarray | None = None,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:  # fmt: skip
    """``n`` random windows of ``length`` frames (shorter sequences are padded by repeating
    their last frame; a window never crosses sequences), weighted by sequence length.

    Args:
        speeds: ``(n,)`` playback speeds: window ``i`` reads its sequence at the fractional
            frames ``start + speeds[i] * k`` (``k < length``), every feature and target linearly
            interpolated between the two nearest frames. Only the sampling: scaling the rates
            (accelerations, velocities) to the new speed is the caller's
            (:func:`time_warp_rates`). ``None``: whole frames, speed 1.
        weights: ``(len(seqs),)`` sampling weights of the sequences instead of their lengths
            (e.g. :func:`category_weights`).

    Returns:
        ``x (n, length, F)`` and ``{key: (n, length, dim)}`` for every target key of the
        sequences (``TARGET_KEYS`` plus any the caller added to ``SequenceArrays.y``), plus
        ``"offsets": (n, 24, 3)``.
    """
    if speeds is not None:
        speeds = np.asarray(speeds, dtype=np.float64)
        if speeds.shape != (n,) or not np.all(np.isfinite(speeds)) or np.any(speeds <= 0):
            raise ValueError(f"speeds must be {n} finite positive values, got shape "
                             f"{speeds.shape}")  # fmt: skip
    if weights is None:
        weights = np.array([len(s.x) for s in seqs], dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    valid = np.all(np.isfinite(weights)) and np.all(weights >= 0) and weights.sum() > 0
    if weights.shape != (len(seqs),) or not valid:
        raise ValueError(f"weights must be {len(seqs)} finite non-negative values with a "
                         f"positive sum, got shape {weights.shape}")  # fmt: skip
    pick = rng.choice(len(seqs), size=n, p=weights / weights.sum())
    keys = tuple(seqs[0].y)
    xs, offs, ys = [], [], {k: [] for k in keys}
    for w, i in enumerate(pick):
        s = seqs[i]
        t = len(s.x)
        if speeds is None:
            start = int(rng.integers(0, max(t - length, 0) + 1))
            idx = np.minimum(np.arange(start, start + length), t - 1)
            xs.append(s.x[idx])
            for k in keys:
                ys[k].append(s.y[k][idx])
        else:
            span = speeds[w] * (length - 1)
            start = int(rng.integers(0, max(int(np.floor(t - 1 - span)), 0) + 1))
            pos = np.minimum(start + speeds[w] * np.arange(length), t - 1)
            i0 = np.floor(pos).astype(np.int64)
            i1 = np.minimum(i0 + 1, t - 1)
            frac = (pos - i0)[:, None]

            def lerp(a: np.ndarray, i0=i0, i1=i1, frac=frac) -> np.ndarray:
                return (a[i0] * (1 - frac) + a[i1] * frac).astype(a.dtype)

            xs.append(lerp(s.x))
            for k in keys:
                ys[k].append(lerp(s.y[k]))
        offs.append(s.offsets)
    out = {k: np.stack(v) for k, v in ys.items()}
    out["offsets"] = np.stack(offs)
    return np.stack(xs), out


def time_warp_rates(x: np.ndarray, y: dict[str, np.ndarray], speeds: np.ndarray, n_sites: int,
                    insoles: bool) -> tuple[np.ndarray, dict[str, np.ndarray]]:  # fmt: skip
    """Rescale the rates of windows resampled at playback ``speeds`` (``sample_windows(...,
    speeds=...)``) to what the sensors would read at that speed.

    A motion played ``s`` times faster has accelerations ``s^2`` and angular and linear
    velocities ``s`` times the original's at the same pose. So the IMUs' free accelerations
    scale by ``s^2``, their angular velocities and the leaf/pelvis velocity targets by ``s``;
    orientations, positions and rotations keep their values. The insoles' total vertical force
    (body weights) is one plus the centre of mass's vertical acceleration over g, so its
    deviation from 1 scales by ``s^2``, shared between the feet as recorded; the CoP keeps its
    value and the contact flags are rounded back to 0/1. The force rule is an approximation
    (it ignores how the stance phases themselves would change); the rest is exact up to the
    interpolation and the recording's low-pass filter.

    Args:
        x: ``(B, T, F)`` raw (unnormalised) features: 15 per IMU site, then 10 insole values.
        y: Targets ``lp, fp, fa, lv`` ``(B, T, dim)`` and ``offsets``.
        speeds: ``(B,)`` playback speeds.

    Raises:
        ValueError: ``y`` has a target without a known rule.
    """
    known = ("lp", "fp", "fa", "lv", "offsets")
    unknown = [k for k in y if k not in known]
    if unknown:
        raise ValueError(f"time_warp_rates: no rule for target(s) {unknown}")
    s = np.asarray(speeds, dtype=np.float64)[:, None, None]
    x = x.copy()
    b, t, _ = x.shape
    imu = x[..., : 15 * n_sites].reshape(b, t, n_sites, 15)
    imu[..., 0:3] *= (s**2)[..., None].astype(x.dtype)
    imu[..., 3:6] *= s[..., None].astype(x.dtype)
    x[..., : 15 * n_sites] = imu.reshape(b, t, -1)
    if insoles:
        ins = x[..., 15 * n_sites : 15 * n_sites + 10].reshape(b, t, 2, 5)
        force = ins[..., 0].astype(np.float64)
        total = force.sum(-1, keepdims=True)
        new_total = np.maximum(1.0 + s**2 * (total - 1.0), 0.0)
        share = np.divide(force, total, out=np.zeros_like(force), where=total > 1e-3)
        ins[..., 0] = np.where(total > 1e-3, share * new_total, force).astype(x.dtype)
        ins[..., 3:5] = np.round(ins[..., 3:5])
        x[..., 15 * n_sites : 15 * n_sites + 10] = ins.reshape(b, t, 10)
    y = dict(y)
    if "lv" in y:
        y["lv"] = (y["lv"] * s).astype(y["lv"].dtype)
    return x, y
