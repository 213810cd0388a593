"""Build a PRISM-format dataset from motion clips: import, retarget, synthesise, chunk, split.

Layout of a dataset folder::

    DIR/
      settings.json              build settings, written before the first clip (resume check)
      manifest.json              build settings, one entry per clip (status, category, label,
                                 group, frames, files), the files under --motions that could not
                                 be read (skipped_files)
      split.json                 train/test lists of sequence ids + statistics (PRISM's shape),
                                 the split mode, its groups, their clips and a summary per source
      motions/<clip>.npz         retargeted ground-truth motion (grip.motion.Motion)
      sequences/<clip>_v<k>_seq<nnn>.npz   PRISM-format recordings, <= 1000 frames each
      done/<clip>.json           written last per clip: the clip is finished (resume marker)

Every file is written atomically, a clip is complete only when its ``done`` marker exists, and a
re-run skips complete clips, so an interrupted build resumes where it stopped. The settings are
recorded in ``settings.json`` before the first clip is written, and a re-run with settings that
change the clips is refused, so even a build killed before its manifest never mixes two
settings. Each ``done`` marker records what the clip's source files held, and a re-run refuses a
source replaced in place (:mod:`grip.dataset.resume`). Temporary files of a killed build are
removed when it resumes, and its worker processes end with it.

The split is computed from the finished clips at the end of every build, so a re-run with only
other split settings (:data:`SPLIT_SETTINGS`) splits the dataset again without building a clip.
A finished clip whose category or label no longer is what the clip search gives (the category
map was edited) is relabelled in place: its recordings and motion file get the new names, its
sensors are not synthesised again.
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
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np

from grip.core.atomic import atomic_write_text
from grip.core.runs import (
    CallPool,
    exit_with_parent,
    record_settings,
    remove_stale_temps,
    require_same_settings,
)
from prism_tools.chunking import group_source, safe_name

MANIFEST = "manifest.json"
SPLIT = "split.json"
SETTINGS = "settings.json"
_RESUME_HINT = "use another --out or the same options"
SPLIT_MODES = ("person", "clip")
"""``split_by`` values: whole groups (performers, else the source's finest grouping) or whole
clips per side."""
SPLIT_SETTINGS = ("test_fraction", "split_seed", "split_by", "test_groups")
PREDATED_SETTINGS: dict[str, object] = {"zmp_filter": False}
"""How a folder that predates a setting was built when that is not the setting's default now:
a folder built before ``zmp_filter`` existed holds unfiltered motions, so resuming it needs
``--no-zmp-filter``."""
"""The :class:`BuildConfig` fields that only choose the split; a finished dataset may be split
again with other values (its clips are kept)."""


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
        test_fraction: Share of the sequences in the test split (of each source's, with
            ``split_by="person"``).
        split_seed: Seed of the split (PRISM used 42).
        seed: Base seed of noise and body draws; each clip derives its own from its id.
        split_by: ``"person"``: whole groups per side, a group being a clip's performer where
            the source names one, else the source's finest grouping
            (:func:`grip.motion.catalog.clip_group`), chosen within each source
            (:func:`dataset_split`); ``"clip"``: whole clips per side, drawn as before split
            modes existed. Either way all variants and chunks of a clip share a side.
        zmp_filter: Run the dynamic filter (:func:`grip.dataset.zmp_filter.zmp_filter`, default
            settings) on every retargeted motion before it is stored and synthesised: a
            horizontal pelvis shift of a few millimetres, feet kept, that brings the ZMP onto
            the feet where they alone carry the body (docs/insoles_zmp.md). On by default
            since the corpus was rebuilt with it; a folder that predates the setting was
            built without it (:data:`PREDATED_SETTINGS`).
        test_groups: Groups put in the test split whatever the draw (``split_by="person"``:
            e.g. ``cmu/14``, a performer whose clips have props; ``"clip"``: clip ids); the
            draw picks the rest as usual.
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
    split_by: str = "person"
    zmp_filter: bool = True
    test_groups: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.split_by not in SPLIT_MODES:
            raise ValueError(f"split_by must be one of {SPLIT_MODES}, got {self.split_by!r}")


class ClipSpec(NamedTuple):
    """One clip to build: where it is and what the clip search says about it.

    Attributes:
        path: The clip's file.
        clip_id: ``"<top folder>/<name>"``.
        category: Shared category (``configs/categories.toml``) or ``"unknown"``.
        label: The source's own label, ``""`` when none.
        group: The clip's group in a split by person (``""``: the clip itself).
    """

    path: str
    clip_id: str
    category: str = "unknown"
    label: str = ""
    group: str = ""


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
    label: str = ""  # the source's own label of the motion
    group: str = ""  # its group in a split by person ("": the clip itself)
    props: list[dict] = field(default_factory=list)  # boxes it stands or sits on (variant 0)
    # what its source files held when it was built ({"clip"|"skeleton": {"path", sha256, ...}},
    # grip.dataset.resume): a resume refuses a source replaced in place
    inputs: dict[str, dict] = field(default_factory=dict)


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


def process_clip(clip: ClipSpec, out_dir: str, cfg: BuildConfig) -> ClipResult:
    """Import, retarget, synthesise and chunk one clip; runs in a worker process.

    The recordings and the motion file carry ``clip.category`` (recordings also
    ``extras["label"]``), whatever a search of the clip's file alone would say.
    """
    from grip.dataset.resume import source_records
    from grip.dataset.zmp_filter import inferred_ground, zmp_filter
    from grip.motion.catalog import clip_ref, load_clip
    from grip.motion.retarget import retarget
    from prism_tools.chunking import chunk_recording
    from prism_tools.io import save_recording
    from prism_tools.schema import recording_as_float32
    from prism_tools.synth import SynthConfig, recording_from_motion

    t0 = time.perf_counter()
    out = Path(out_dir)
    clip_id = clip.clip_id
    name = safe_name(clip_id)
    res = ClipResult(clip_id=clip_id, status="failed", category=clip.category, source=clip.path,
                     label=clip.label, group=clip.group)  # fmt: skip
    try:
        ref = replace(clip_ref(clip.path), clip_id=clip_id, category=clip.category)
        res.inputs = source_records({"clip": ref.path, "skeleton": ref.asf_path})
        src = load_clip(ref)
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
                if cfg.zmp_filter:
                    motion = zmp_filter(motion, synth_cfg=SynthConfig().insole,
                                        ground=inferred_ground(motion)).motion  # fmt: skip
                motions[k] = motion
                if k == 0:
                    motion.save(out / "motions" / f"{name}.npz")
            motion = motions[k]
            rec = recording_from_motion(motion, SynthConfig(), seed=seed + k, noise=noisy)
            rec.extras["label"] = clip.label
            if k == 0:  # (every variant of the same motion stands on the same props)
                res.props = json.loads(rec.extras.get("props") or "[]")
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
        res.error = _error_text(clip.path, e)
        if os.environ.get("GRIP_DEBUG"):
            res.error += "\n" + traceback.format_exc()
    res.seconds = time.perf_counter() - t0
    if res.status == "done":
        _write_done(out, res)
    return res


def _write_done(out: Path, res: ClipResult) -> None:
    from grip.dataset.resume import done_marker

    atomic_write_text(done_marker(out, res.clip_id), json.dumps(asdict(res), indent=1))


def relabel_clip(out_dir: str | os.PathLike, res: ClipResult, category: str,
                 label: str) -> ClipResult:  # fmt: skip
    """Give a finished clip another category and label without building it again.

    Its recordings (``extras["category"]``, ``extras["label"]``, ``data_info.trial_name``) and
    its motion file are rewritten (atomically), then its ``done`` marker.

    Args:
        out_dir: The dataset folder.
        res: The clip as its ``done`` marker has it.
        category: The new category.
        label: The new label.

    Returns:
        ``res`` with the new category and label.

    Raises:
        OSError, ValueError: A file of the clip is missing or unreadable (the message names it).
    """
    from grip.motion.motion import Motion
    from prism_tools.io import load_recording, save_recording

    out = Path(out_dir)
    for seq in res.sequences:
        path = out / "sequences" / f"{seq}.npz"
        rec = load_recording(path)
        info = replace(rec.data_info, trial_name=category)
        rec = replace(rec, data_info=info, extras={**rec.extras, "category": category,
                                                   "label": label})  # fmt: skip
        save_recording(rec, path)
    motion_path = out / "motions" / f"{safe_name(res.clip_id)}.npz"
    if motion_path.is_file():
        replace(Motion.load(motion_path), category=category).save(motion_path)
    new = replace(res, category=category, label=label)
    _write_done(out, new)
    return new


def _error_text(clip_path: str, e: BaseException) -> str:
    """``"<file>: <Type>: <message>"``, the file named once even where the message names it."""
    msg = f"{type(e).__name__}: {e}"
    return msg if clip_path in msg else f"{clip_path}: {msg}"


def _unfinished(spec: ClipSpec, why: str) -> ClipResult:
    """The result of a clip whose worker gave none (it died, or its call failed outside
    :func:`process_clip`'s guard)."""
    return ClipResult(spec.clip_id, "failed", spec.category, spec.path,
                      error=f"{spec.path}: {why}; run the build again to retry the clips it "
                      "did not finish", label=spec.label, group=spec.group)  # fmt: skip


def _load_done(out: Path) -> dict[str, ClipResult]:
    done: dict[str, ClipResult] = {}
    for p in sorted((out / "done").glob("*.json")):
        try:
            d = json.loads(p.read_text())
            done[d["clip_id"]] = ClipResult(**d)
        except (OSError, ValueError, KeyError, TypeError):
            continue  # a damaged marker means: build that clip again
    return done


def dataset_split(results: Sequence[ClipResult], test_fraction: float, seed: int,
                  split_by: str = "person", test_groups: Sequence[str] = ()) -> dict:  # fmt: skip
    """Train/test split of the built sequences, whole groups at a time (PRISM statistics shape).

    All sequences of one clip (its noise variants and consecutive chunks) share a split, so a
    test motion is never seen in training. ``split_by="person"``: all clips of a group
    (:attr:`ClipResult.group`: a performer, or the source's finest grouping) share a split, and
    the test groups are chosen within each source (:func:`group_source`) so that every source of
    two or more groups has about ``test_fraction`` of its sequences in test and a group on each
    side (:func:`prism_tools.chunking.stratified_test_groups`). ``split_by="clip"``: clips are
    drawn at random until the test split holds ``test_fraction`` of the sequences (the split of
    datasets built before split modes existed, reproduced exactly).

    Returns:
        :func:`prism_tools.chunking.make_split`'s dict plus ``"split_by"``, ``"members"`` (group
        -> its clip ids) and ``"sources"`` (source -> ``{"train"|"test": {"groups": [...],
        "clips", "sequences", "frames"}}``).
    """
    from prism_tools.chunking import make_split

    if split_by not in SPLIT_MODES:
        raise ValueError(f"split_by must be one of {SPLIT_MODES}, got {split_by!r}")
    groups, cats, frames = {}, {}, {}
    clip_group, clip_source = {}, {}
    for r in results:
        if r.status != "done" or not r.sequences:
            continue
        person = r.group or r.clip_id
        clip_group[r.clip_id] = r.clip_id if split_by == "clip" else person
        clip_source[r.clip_id] = group_source(person)
        for seq, n in zip(r.sequences, r.sequence_frames, strict=True):
            groups[seq], cats[seq], frames[seq] = clip_group[r.clip_id], r.category, n
    strata = None
    if split_by == "person":
        strata = {clip_group[c]: clip_source[c] for c in clip_group}
    split = make_split(sorted(groups), test_fraction, seed, categories=cats,
                       frames_per_chunk=frames, groups=groups, strata=strata,
                       test_groups=test_groups)  # fmt: skip
    test_groups = set(split["groups"]["test"])
    members: dict[str, list[str]] = {}
    sources: dict[str, dict] = {}
    for r in results:
        if r.clip_id not in clip_group:
            continue
        g = clip_group[r.clip_id]
        members.setdefault(g, []).append(r.clip_id)
        part = "test" if g in test_groups else "train"
        src = sources.setdefault(clip_source[r.clip_id], {
            p: {"groups": set(), "clips": 0, "sequences": 0, "frames": 0}
            for p in ("train", "test")})  # fmt: skip
        src[part]["groups"].add(g)
        src[part]["clips"] += 1
        src[part]["sequences"] += len(r.sequences)
        src[part]["frames"] += int(sum(r.sequence_frames))
    for src in sources.values():
        for part in src.values():
            part["groups"] = sorted(part["groups"])
    split["split_by"] = split_by
    split["members"] = {g: sorted(m) for g, m in sorted(members.items())}
    split["sources"] = dict(sorted(sources.items()))
    return split


def _settings_check(out: Path, cfg: BuildConfig) -> None:
    """Refuse settings that change the clips against the folder's manifest and settings file,
    then record this build's settings (the split settings may differ, :data:`SPLIT_SETTINGS`;
    settings a folder predates take their defaults)."""
    new = asdict(cfg)
    defaults = {**asdict(BuildConfig()), **PREDATED_SETTINGS}
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
        require_same_settings(old.get("config") or {}, new, manifest_path, _RESUME_HINT,
                              may_change=SPLIT_SETTINGS, defaults=defaults)  # fmt: skip
    record_settings(out / SETTINGS, new, _RESUME_HINT, may_change=SPLIT_SETTINGS,
                    defaults=defaults)  # fmt: skip


def build_dataset(
    clips: Iterable[ClipSpec | tuple[str, str, str]],
    out_dir: str | os.PathLike,
    cfg: BuildConfig = BuildConfig(),
    workers: int = 0,
    progress: Callable[[int], object] | None = None,
    skipped_files: Sequence[tuple[str, str]] = (),
    counts: dict[str, int] | None = None,
    pool: CallPool | None = None,
) -> list[ClipResult]:
    """Build (or resume, relabel or split again) a dataset.

    Clips with a ``done`` marker are not built again. One whose category or label differs from
    its :class:`ClipSpec` is relabelled in place (:func:`relabel_clip`; where that fails, it is
    built again), one whose group differs only gets the new group. The split is computed last,
    from the finished clips (:func:`dataset_split`), so a re-run of a finished folder with other
    :data:`SPLIT_SETTINGS` only writes a new ``split.json`` (and ``settings.json``,
    ``manifest.json``).

    Args:
        clips: :class:`ClipSpec` s, or ``(path, clip_id, category)`` triples.
        out_dir: Dataset folder; created if missing.
        cfg: Build settings, recorded in ``settings.json`` before the first clip. Resuming with
            settings that change the clips (all but :data:`SPLIT_SETTINGS`) other than that file
            (or the manifest) holds is refused.
        workers: Worker processes (0 = one per core). They end when this process ends.
        progress: Optional callback ``progress(n)`` after each finished clip (tqdm.update).
        skipped_files: ``(path, reason)`` of files the clip search could not read; listed in
            the manifest as ``skipped_files``.
        counts: Optional dict that receives how many clips were ``"built"`` (or tried) in this
            run, ``"resumed"`` (finished before) and, of those, ``"relabelled"`` and
            ``"unrecorded"`` (their markers, of an older version, had no record of the sources'
            contents: :mod:`grip.dataset.resume`).
        pool: Runs the clips instead of ``workers`` local processes (a
            :class:`grip.cluster.RayPool`: ``grip data build --ray``; its workers write into
            ``out_dir``, so on several machines it must be a shared folder).

    Returns:
        One :class:`ClipResult` per clip (resumed clips come back as ``done``).

    Raises:
        ValueError: Other settings than the folder's (a
            :class:`grip.core.runs.SettingsMismatch`), a corrupt manifest/settings file, or a
            finished clip's source replaced in place (:func:`grip.dataset.resume.check_sources`).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    _settings_check(out, cfg)
    remove_stale_temps(out)  # of a killed build: atomic writes that never finished
    specs = [c if isinstance(c, ClipSpec) else ClipSpec(*c) for c in clips]
    done = _load_done(out)
    from grip.dataset.resume import check_sources

    # (before anything is changed: a source replaced in place refuses the whole resume)
    updated, unrecorded = check_sources(out, [(s, done[s.clip_id]) for s in specs
                                              if s.clip_id in done])  # fmt: skip
    done.update(updated)
    results: dict[str, ClipResult] = {}
    unchanged = relabelled = 0
    for spec in specs:
        res = done.get(spec.clip_id)
        if res is None:
            continue
        if (res.category, res.label) != (spec.category, spec.label):
            try:
                res = relabel_clip(out, res, spec.category, spec.label)
            except (OSError, ValueError):  # a file of the clip is damaged: build it again
                continue
            relabelled += 1
            if progress is not None:
                progress(1)
        else:
            unchanged += 1
        if res.group != spec.group:
            res = replace(res, group=spec.group)
            _write_done(out, res)
        results[spec.clip_id] = res
    if progress is not None and unchanged:
        progress(unchanged)
    todo = [c for c in specs if c.clip_id not in results]
    if counts is not None:
        counts.update(built=len(todo), resumed=len(results), relabelled=relabelled,
                      unrecorded=unrecorded)
    n_workers = workers or os.cpu_count() or 1
    if todo and pool is not None:
        calls = [(process_clip, (spec, str(out.absolute()), cfg)) for spec in todo]

        def finished(k: int, res: object) -> None:
            spec = todo[k]
            if isinstance(res, BaseException):
                res = _unfinished(spec, f"its task failed ({type(res).__name__}: {res})")
            results[spec.clip_id] = res
            if progress is not None:
                progress(1)

        for k in pool.run(calls, finished):
            results[todo[k].clip_id] = _unfinished(todo[k], "its worker process died (a crash "
                                                   "or out of memory)")  # fmt: skip
            if progress is not None:
                progress(1)
    elif todo:
        if n_workers == 1:
            for spec in todo:
                results[spec.clip_id] = process_clip(spec, str(out), cfg)
                if progress is not None:
                    progress(1)
        else:
            with ProcessPoolExecutor(max_workers=n_workers, initializer=exit_with_parent) as pool:
                futs = {pool.submit(process_clip, spec, str(out), cfg): spec for spec in todo}
                for fut in as_completed(futs):
                    spec = futs[fut]
                    try:
                        results[spec.clip_id] = fut.result()
                    except (BrokenProcessPool, OSError, MemoryError) as e:  # a worker died
                        results[spec.clip_id] = _unfinished(
                            spec, f"worker process died ({type(e).__name__}: {e})")
                    if progress is not None:
                        progress(1)
    ordered = [results[c.clip_id] for c in specs]
    manifest = {
        "format": "grip-prism-dataset/1",
        "config": asdict(cfg),
        "clips": [asdict(r) for r in ordered],
        "skipped_files": [{"file": str(f), "reason": why} for f, why in skipped_files],
    }
    atomic_write_text(out / MANIFEST, json.dumps(manifest, indent=1))
    from prism_tools.chunking import save_split

    split = dataset_split(ordered, cfg.test_fraction, cfg.split_seed, cfg.split_by,
                          cfg.test_groups)  # fmt: skip
    save_split(split, out / SPLIT)
    return ordered
