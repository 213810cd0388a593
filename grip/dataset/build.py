"""Build a PRISM-format dataset from motion clips: import, retarget, synthesise, chunk, split.

Layout of a dataset folder::

    DIR/
      settings.json              build settings, written before the first clip (resume check)
      manifest.json              build settings, one entry per clip (status, frames, files),
                                 the files under --motions that could not be read (skipped_files)
      split.json                 train/test lists of sequence ids + statistics (PRISM's shape)
      motions/<clip>.npz         retargeted ground-truth motion (grip.motion.Motion)
      sequences/<clip>_v<k>_seq<nnn>.npz   PRISM-format recordings, <= 1000 frames each
      done/<clip>.json           written last per clip: the clip is finished (resume marker)

Every file is written atomically, a clip is complete only when its ``done`` marker exists, and a
re-run skips complete clips, so an interrupted build resumes where it stopped. The settings are
recorded in ``settings.json`` before the first clip is written, and a re-run with other settings
is refused, so even a build killed before its manifest never mixes two settings. Temporary files
of a killed build are removed when it resumes, and its worker processes end with it.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from grip.core.atomic import atomic_write_text
from grip.core.runs import (
    exit_with_parent,
    record_settings,
    remove_stale_temps,
    require_same_settings,
)

MANIFEST = "manifest.json"
SPLIT = "split.json"
SETTINGS = "settings.json"
_RESUME_HINT = "use another --out or the same options"


@dataclass(frozen=True)
class BuildConfig:
    """Settings of one dataset build (stored in the manifest).

    Attributes:
        noise_variants: Recordings per clip with independent sensor-noise draws.
        clean_variant: Also write a noise-free recording (variant ``c``).
        vary_body: Draw a subject (height, mass) per variant instead of the default body.
        height_m: Body height when ``vary_body`` is off, m.
        mass_kg: Body mass when ``vary_body`` is off, kg.
        chunk_frames: Sequence length (PRISM: 1000 frames = 10 s).
        min_chunk_frames: Shortest tail (or whole short clip) kept as a sequence.
        float32: Store sensor and pose arrays as float32 (translations stay float64), as
            PRISM does for its poses; halves the dataset size.
        test_fraction: Share of clips in the test split (split by clip: all variants and
            chunks of a clip land in the same split, so no motion leaks across).
        split_seed: Seed of the split (PRISM used 42).
        seed: Base seed of noise and body draws; each clip derives its own from its id.
    """

    noise_variants: int = 1
    clean_variant: bool = False
    vary_body: bool = True
    height_m: float = 1.70
    mass_kg: float = 70.0
    chunk_frames: int = 1000
    min_chunk_frames: int = 100
    float32: bool = True
    test_fraction: float = 0.2
    split_seed: int = 42
    seed: int = 0


@dataclass
class ClipResult:
    """Outcome of one clip (JSON-serialisable)."""

    clip_id: str
    status: str  # "done" | "failed" | "skipped"
    category: str = "unknown"
    source: str = ""
    frames: int = 0
    sequences: list[str] = field(default_factory=list)
    sequence_frames: list[int] = field(default_factory=list)
    seconds: float = 0.0
    synth_frames: int = 0  # frames synthesised over all variants (before chunking)
    zmp_outside_frames: int = 0  # of those, frames whose ZMP lies > 3 cm outside the insole cells
    error: str = ""  # why it failed; always names the source file
    note: str = ""  # e.g. why a finished clip gave no sequence


def clip_seed(clip_id: str, base: int) -> int:
    """A stable per-clip seed from the clip id (independent of build order)."""
    h = hashlib.sha256(f"{base}:{clip_id}".encode()).digest()
    return int.from_bytes(h[:4], "little")


def subject_for(clip_id: str, variant: int, cfg: BuildConfig):
    """Body parameters of one recording: fixed, or drawn per (clip, variant) when ``vary_body``."""
    from grip.core.body import BodyParams

    if not cfg.vary_body:
        return BodyParams(height_m=cfg.height_m, mass_kg=cfg.mass_kg)
    rng = np.random.default_rng(clip_seed(f"{clip_id}/body/{variant}", cfg.seed))
    height = float(np.clip(rng.normal(1.72, 0.08), 1.52, 1.95))
    bmi = float(np.clip(rng.normal(23.5, 2.5), 18.5, 31.0))
    return BodyParams(height_m=round(height, 3), mass_kg=round(bmi * height**2, 1))


def safe_name(clip_id: str) -> str:
    """The file-name form of a clip id (``DATA/motions/<safe_name>.npz``)."""
    return clip_id.replace("/", "__")


def process_clip(clip_path: str, clip_id: str, category: str, out_dir: str,
                 cfg: BuildConfig) -> ClipResult:  # fmt: skip
    """Import, retarget, synthesise and chunk one clip; runs in a worker process."""
    from grip.motion.catalog import load_clip
    from grip.motion.retarget import retarget
    from prism_tools.chunking import chunk_recording
    from prism_tools.io import save_recording
    from prism_tools.schema import recording_as_float32
    from prism_tools.synth import SynthConfig, recording_from_motion

    t0 = time.perf_counter()
    out = Path(out_dir)
    name = safe_name(clip_id)
    res = ClipResult(clip_id=clip_id, status="failed", category=category, source=clip_path)
    try:
        src = load_clip(clip_path)
        variants: list[tuple[str, bool, int]] = [
            (f"v{k}", True, k) for k in range(cfg.noise_variants)
        ]
        if cfg.clean_variant:
            variants.append(("c", False, 0))
        seed = clip_seed(clip_id, cfg.seed)
        motions: dict[int, object] = {}
        for tag, noisy, k in variants:
            if k not in motions:
                motion = retarget(src, subject_for(clip_id, k, cfg))
                motions[k] = motion
                if k == 0:
                    motion.save(out / "motions" / f"{name}.npz")
            motion = motions[k]
            rec = recording_from_motion(motion, SynthConfig(), seed=seed + k, noise=noisy)
            res.synth_frames += rec.n_frames
            res.zmp_outside_frames += int(rec.extras.get("insole_zmp_outside_frames", 0))
            if cfg.float32:
                rec = recording_as_float32(rec)
            chunks = chunk_recording(rec, cfg.chunk_frames, min_length=cfg.min_chunk_frames)
            for i, chunk in enumerate(chunks):
                seq_id = f"{name}_{tag}_seq{i:03d}"
                save_recording(chunk, out / "sequences" / f"{seq_id}.npz")
                res.sequences.append(seq_id)
                res.sequence_frames.append(int(chunk.n_frames))
            res.frames = int(motion.n_frames)
        res.status = "done"
        if not res.sequences:
            res.note = (f"no sequence: {res.frames} frames at 100 Hz, fewer than the "
                        f"{cfg.min_chunk_frames} a sequence needs")  # fmt: skip
    except Exception as e:  # one bad clip must not stop the build (MemoryError, RecursionError..)
        res.error = _error_text(clip_path, e)
        if os.environ.get("GRIP_DEBUG"):
            res.error += "\n" + traceback.format_exc()
    res.seconds = time.perf_counter() - t0
    if res.status == "done":
        atomic_write_text(out / "done" / f"{name}.json", json.dumps(asdict(res), indent=1))
    return res


def _error_text(clip_path: str, e: BaseException) -> str:
    """``"<file>: <Type>: <message>"``, the file named once even where the message names it."""
    msg = f"{type(e).__name__}: {e}"
    return msg if clip_path in msg else f"{clip_path}: {msg}"


def _load_done(out: Path) -> dict[str, ClipResult]:
    done: dict[str, ClipResult] = {}
    for p in sorted((out / "done").glob("*.json")):
        try:
            d = json.loads(p.read_text())
            done[d["clip_id"]] = ClipResult(**d)
        except (OSError, ValueError, KeyError, TypeError):
            continue  # a damaged marker means: build that clip again
    return done


def dataset_split(results: Sequence[ClipResult], test_fraction: float, seed: int) -> dict:
    """Train/test split of the built sequences, whole clips at a time (PRISM statistics shape).

    All sequences of one clip (its noise variants and consecutive chunks) share a split, so a
    test motion is never seen in training.
    """
    from prism_tools.chunking import make_split

    groups, cats, frames = {}, {}, {}
    for r in results:
        if r.status != "done":
            continue
        for seq, n in zip(r.sequences, r.sequence_frames, strict=True):
            groups[seq], cats[seq], frames[seq] = r.clip_id, r.category, n
    return make_split(sorted(groups), test_fraction, seed, categories=cats,
                      frames_per_chunk=frames, groups=groups)  # fmt: skip


def build_dataset(
    clips: Iterable[tuple[str, str, str]],
    out_dir: str | os.PathLike,
    cfg: BuildConfig = BuildConfig(),
    workers: int = 0,
    progress: Callable[[int], object] | None = None,
    skipped_files: Sequence[tuple[str, str]] = (),
) -> list[ClipResult]:
    """Build (or resume) a dataset.

    Args:
        clips: ``(path, clip_id, category)`` triples.
        out_dir: Dataset folder; created if missing.
        cfg: Build settings, recorded in ``settings.json`` before the first clip. Resuming with
            different settings than that file (or the manifest) holds is refused.
        workers: Worker processes (0 = one per core). They end when this process ends.
        progress: Optional callback ``progress(n)`` after each finished clip (tqdm.update).
        skipped_files: ``(path, reason)`` of files the clip search could not read; listed in
            the manifest as ``skipped_files``.

    Returns:
        One :class:`ClipResult` per clip (resumed clips come back as ``done``).

    Raises:
        ValueError: Other settings than the folder's (a
            :class:`grip.core.runs.SettingsMismatch`), or a corrupt manifest/settings file.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    manifest_path = out / MANIFEST
    if manifest_path.exists():
        try:
            old = json.loads(manifest_path.read_text())
            if not isinstance(old, dict):
                raise ValueError("not a JSON object")
        except ValueError as e:
            raise ValueError(
                f"{manifest_path}: corrupt manifest ({e}); remove it to rebuild"
            ) from e
        require_same_settings(old.get("config") or {}, asdict(cfg), manifest_path, _RESUME_HINT)
    record_settings(out / SETTINGS, asdict(cfg), _RESUME_HINT)
    remove_stale_temps(out)  # of a killed build: atomic writes that never finished
    clips = list(clips)
    done = _load_done(out)
    todo = [c for c in clips if c[1] not in done]
    results: dict[str, ClipResult] = {c[1]: done[c[1]] for c in clips if c[1] in done}
    if progress is not None and results:
        progress(len(results))
    n_workers = workers or os.cpu_count() or 1
    if todo:
        if n_workers == 1:
            for path, cid, cat in todo:
                results[cid] = process_clip(path, cid, cat, str(out), cfg)
                if progress is not None:
                    progress(1)
        else:
            with ProcessPoolExecutor(max_workers=n_workers, initializer=exit_with_parent) as pool:
                futs = {pool.submit(process_clip, p, cid, cat, str(out), cfg): (p, cid, cat)
                        for p, cid, cat in todo}  # fmt: skip
                for fut in as_completed(futs):
                    path, cid, cat = futs[fut]
                    try:
                        results[cid] = fut.result()
                    except (BrokenProcessPool, OSError, MemoryError) as e:  # a worker died
                        results[cid] = ClipResult(
                            cid, "failed", cat, path,
                            error=f"{path}: worker process died ({type(e).__name__}: {e}); "
                            "run the build again to retry the clips it did not finish")  # fmt: skip
                    if progress is not None:
                        progress(1)
    ordered = [results[c[1]] for c in clips]
    manifest = {
        "format": "grip-prism-dataset/1",
        "config": asdict(cfg),
        "clips": [asdict(r) for r in ordered],
        "skipped_files": [{"file": str(f), "reason": why} for f, why in skipped_files],
    }
    atomic_write_text(manifest_path, json.dumps(manifest, indent=1))
    from prism_tools.chunking import save_split

    save_split(dataset_split(ordered, cfg.test_fraction, cfg.split_seed), out / SPLIT)
    return ordered
