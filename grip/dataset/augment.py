"""Recordings made from a dataset's motions played backwards or faster (training augmentation).

``grip data build`` keeps every clip's retargeted motion (``DATA/motions/<clip>.npz``). Played
backwards (:meth:`grip.motion.motion.Motion.time_reversed`), a forward walk becomes a backward
walk of the same subject and style; its sensors are synthesised by the same physics and noise as
the dataset's (:func:`prism_tools.synth.recording_from_motion`) and chunked as the build chunks.
The distillation's reference set (``grip policy distill``, ``reverse_categories = ["walk"]``)
uses them to see many more backward walks than the few recorded ones. They are made in memory
from the clips of the given training sequences only, so a test clip never contributes.

Played faster (:meth:`grip.motion.motion.Motion.time_scaled`, ``speed_factors`` of ``grip
policy train``), a walk becomes a faster walk of the same person: the controller's training set
then covers the walking speeds it is asked for on other people (docs/pace.md).
"""

from __future__ import annotations

import fnmatch
import json
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

from grip.dataset.build import MANIFEST, BuildConfig, clip_seed, safe_name


def _manifest(data_dir: Path) -> dict:
    path = data_dir / MANIFEST
    try:
        m = json.loads(path.read_text())
        clips = m["clips"]
        cfg = BuildConfig(**{k: v for k, v in m.get("config", {}).items()
                             if k in BuildConfig.__dataclass_fields__})  # fmt: skip
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ValueError(f"{path}: cannot read the dataset manifest ({e}); time-reversed "
                         "recordings are made from a 'grip data build' folder") from e  # fmt: skip
    return {"clips": clips, "config": cfg}


def reversed_clip_ids(data_dir: str | Path, sequence_stems: Sequence[str],
                      categories: Sequence[str]) -> list[tuple[str, str]]:  # fmt: skip
    """``(clip_id, category)`` of the clips that own one of ``sequence_stems`` and whose category
    matches a glob of ``categories``, in manifest order."""
    man = _manifest(Path(data_dir))
    stems = set(sequence_stems)
    out = []
    for c in man["clips"]:
        cat = str(c.get("category") or "unknown")
        if c.get("status") != "done" or not any(fnmatch.fnmatchcase(cat, g) for g in categories):
            continue
        if stems.intersection(c.get("sequences") or ()):
            out.append((str(c["clip_id"]), cat))
    return out


def time_reversed_recordings(
    data_dir: str | Path,
    sequence_stems: Sequence[str],
    categories: Sequence[str],
    progress: Callable[[int], object] | None = None,
) -> list:
    """Recordings of the selected clips' motions played backwards (see the module docstring).

    Args:
        data_dir: A ``grip data build`` folder (``manifest.json``, ``motions/``).
        sequence_stems: The sequences allowed to contribute (e.g. the training split less any
            held-out clips); a clip contributes when one of its sequences is here.
        categories: Category globs of the clips to reverse, e.g. ``["walk"]``.
        progress: Called with 1 after each clip.

    Returns:
        PRISM-format recordings (category ``"<category>-reversed"``, names
        ``"<take>-reversed_seqNNN"``), chunked and stored as the build stores its own.

    Raises:
        ValueError: No manifest, or a selected clip's motion file is missing or unreadable (the
            message names the file).
    """
    return _variant_recordings(data_dir, sequence_stems, categories,
                               [("reversed", "-reversed", lambda m: m.time_reversed())],
                               progress)  # fmt: skip


def speed_suffix(factor: float) -> str:
    """The name suffix of a clip played ``factor`` times faster, e.g. ``"@x1.25"``."""
    return f"@x{float(factor):g}"


def time_scaled_recordings(
    data_dir: str | Path,
    sequence_stems: Sequence[str],
    categories: Sequence[str],
    factors: Sequence[float],
    progress: Callable[[int], object] | None = None,
) -> list:
    """Recordings of the selected clips' motions played ``factor`` times faster, one per clip
    and factor (the category unchanged, names ``"<take>@x<factor>_seqNNN"``); arguments and
    errors as :func:`time_reversed_recordings`'s, ``progress`` called once per clip and
    factor."""
    variants = [(f"x{float(f):g}", speed_suffix(f),
                 lambda m, f=float(f): m.time_scaled(f)) for f in factors]  # fmt: skip
    return _variant_recordings(data_dir, sequence_stems, categories, variants, progress)


def _variant_recordings(data_dir: str | Path, sequence_stems: Sequence[str],
                        categories: Sequence[str], variants: list[tuple[str, str, Callable]],
                        progress: Callable[[int], object] | None) -> list:  # fmt: skip
    """The recordings of every selected clip's motion under each ``(seed tag, name suffix,
    transform)`` of ``variants``, sensors synthesised as the build synthesises them."""
    from grip.motion.motion import Motion
    from prism_tools.chunking import chunk_recording
    from prism_tools.schema import recording_as_float32
    from prism_tools.synth import SynthConfig, recording_from_motion

    data_dir = Path(data_dir)
    cfg = _manifest(data_dir)["config"]
    recs: list = []
    for clip_id, _ in reversed_clip_ids(data_dir, sequence_stems, categories):
        path = data_dir / "motions" / f"{safe_name(clip_id)}.npz"
        if not path.is_file():
            raise ValueError(f"{path}: motion file of clip {clip_id!r} is missing (rebuild the "
                             "dataset with 'grip data build')")  # fmt: skip
        src = Motion.load(path)
        for tag, suffix, transform in variants:
            motion = replace(transform(src), name=f"{src.name}{suffix}")
            seed = clip_seed(f"{clip_id}/{tag}", cfg.seed)
            rec = recording_from_motion(motion, SynthConfig(), seed=seed, noise=True)
            if cfg.float32:
                rec = recording_as_float32(rec)
            recs += chunk_recording(rec, cfg.chunk_frames, min_length=cfg.min_chunk_frames)
            if progress is not None:
                progress(1)
    return recs
