"""Benchmark runner of ``grip bench``: every method on the same test segments, GRIP's metrics.

Protocol (GRIP; BASELINES_AND_METRICS 4.1): the recordings of a dataset split are cut into
consecutive ``segment_frames``-frame segments (500 by default; shorter tails are left out), every
method reconstructs every segment starting from the ground truth at its first frame, the metrics
of :mod:`grip.core.metrics` are computed per segment and averaged over the segments.

Metric keys (per segment and in ``results.json``):

================  =====  ==========================================================================
key               unit   definition
================  =====  ==========================================================================
MPJPE_mm          mm     world joint position error (:func:`~grip.core.metrics.mpjpe`)
PEL_MPJPE_mm      mm     pelvis-relative joint position error (:func:`~grip.core.metrics.pel_mpjpe`)
PA_MPJPE_mm       mm     Procrustes-aligned error per frame (:func:`~grip.core.metrics.pa_mpjpe`)
MPJRE_deg         deg    global joint rotation error (:func:`~grip.core.metrics.mpjre`)
Acc_mps2          m/s^2  acceleration error (:func:`~grip.core.metrics.acceleration_error`)
FS_mps            m/s    foot sliding over the ground-truth contact frames: the insole's (front
                         or back) where both insoles exist, else contacts from the true motion
FP_mm             mm     sole penetration below the floor, on the subject's body model
vGRF_N            N      vertical force error per foot vs the insole (body weights x m g); NaN
                         for methods without forces
success_rate      %      segments without a detected fall; NaN for methods that cannot fall
ms_per_frame      ms     wall time of ``reconstruct`` per frame, measured by the runner
================  =====  ==========================================================================

``results.json`` also counts ``blowups``: simulation blow-ups over the segments (a method's
``Reconstruction.notes["blowups"]``; GRIP recovers each like a fall, so its frames are never
in the metrics; 0 for methods without a simulation); each segment's row carries its own.

Output folder (``OUT``)::

    segments/<label>/method.json        the method's name and options (checked on resume)
    segments/<label>/<segment>.json     one finished segment (written atomically)
    recons/<label>/<segment>.npz        reconstructions (--save-recons; always the sample's)
    results.json, results.csv           {label: {metric: value}} (null / empty for NaN)
    segments.csv                        one row per method and segment
    table.md                            the GRIP Table 1 layout, runtime, failures, categories
    per_joint.png, trajectory.png, grf.png

A *label* is the method name, with ``@<sensors>`` for a sensor configuration of a sweep
(``kinematics@imu4_press``). Finished segments are kept: running the same command again only
runs what is missing. A segment whose method raised is finished with ``"status": "error"``
(shown as a failure in the table; ``retry_failed`` runs it again). A worker process that dies
(segfault, out of memory) is replaced; a segment that kills its worker when run alone is
recorded as an error.
"""

from __future__ import annotations

import csv
import fnmatch
import io
import json
import math
import multiprocessing as mp
import os
import sys
import time
import traceback
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from grip.core import metrics as M
from grip.core import skeleton as sk
from grip.core.atomic import atomic_write_text
from grip.core.body import BodyParams, build_body
from grip.core.fk import sole_points
from grip.core.reconstruction import Reconstruction
from grip.eval.methods import METHODS, Method, MethodFactory, MethodOptions, make_method
from grip.kinematics.features import GroundTruth, ground_truth

__all__ = [
    "METRIC_KEYS",
    "PER_JOINT_KEYS",
    "RESULT_KEYS",
    "BenchError",
    "GroundTruth",
    "MethodRun",
    "Segment",
    "aggregate",
    "evaluate_segment",
    "foot_penetration_mm",
    "foot_sliding_mps",
    "ground_truth",
    "list_segments",
    "load_rows",
    "markdown_table",
    "prepare_runs",
    "run_bench",
    "segment_metrics",
    "select_segments",
    "vgrf_error_n",
    "write_outputs",
]

METRIC_KEYS: tuple[str, ...] = (
    "MPJPE_mm", "PEL_MPJPE_mm", "PA_MPJPE_mm", "MPJRE_deg", "Acc_mps2", "FS_mps", "FP_mm",
    "vGRF_N", "success_rate", "ms_per_frame",
)  # fmt: skip
RESULT_KEYS: tuple[str, ...] = (*METRIC_KEYS, "segments", "blowups")
"""Keys of each method's entry in ``results.json`` (plus ``failed``: segments that raised)."""
PER_JOINT_KEYS: tuple[str, ...] = ("MPJPE_mm", "PEL_MPJPE_mm", "MPJRE_deg")

_TABLE_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("MPJPE_mm", "MPJPE (mm)", "{:.2f}"), ("PEL_MPJPE_mm", "PEL-MPJPE (mm)", "{:.2f}"),
    ("PA_MPJPE_mm", "PA-MPJPE (mm)", "{:.2f}"), ("MPJRE_deg", "MPJRE (deg)", "{:.2f}"),
    ("Acc_mps2", "Acc (m/s²)", "{:.2f}"), ("FS_mps", "FS (m/s)", "{:.2f}"),
    ("FP_mm", "FP (mm)", "{:.2f}"), ("vGRF_N", "vGRF (N)", "{:.2f}"),
    ("success_rate", "Succ. (%)", "{:.2f}"), ("ms_per_frame", "ms/frame", "{:.3g}"),
)  # fmt: skip
_FEET = sk.FEET


class BenchError(ValueError):
    """A benchmark cannot run as asked (bad data, settings that differ from a previous run)."""


# ------------------------------------------------------------------ metric pieces (shared)
def foot_sliding_mps(pos: np.ndarray, contacts: np.ndarray, fps: float) -> float:
    """Foot sliding (m/s) of the predicted feet over ``contacts`` frames; NaN under 2 frames.

    Args:
        pos: ``(T, 24, 3)`` predicted joint positions, world, m.
        contacts: ``(T, 2)`` bool ground-truth contacts (``GroundTruth.foot_contacts``).
        fps: Frame rate, Hz.
    """
    if len(pos) < 2:
        return float("nan")
    return float(M.foot_sliding(pos, contacts, fps))


def foot_penetration_mm(rot: np.ndarray, pos: np.ndarray, body: BodyParams) -> float:
    """Foot penetration (mm) of the sole points of ``body`` posed by ``rot`` ``(T, 24, 3, 3)``
    and ``pos`` ``(T, 24, 3)`` (world, m), against the floor ``z = 0``."""
    return float(M.foot_penetration(sole_points(rot, pos, build_body(body))))


def vgrf_error_n(pred_fz_n: np.ndarray | None, insole_fz_n: np.ndarray | None) -> float:
    """Vertical GRF error, N: :func:`grip.core.metrics.vgrf_error` of ``(T, 2)`` forces.

    Frames whose predicted force is not finite are left out (GRIP's fall recovery replaces
    the frames of a fall by the kinematic estimate, which has no forces). NaN when the method
    has no forces, the recording no insoles, or no frame has a finite prediction.
    """
    if pred_fz_n is None or insole_fz_n is None:
        return float("nan")
    return M.vgrf_error(pred_fz_n, insole_fz_n)


# ------------------------------------------------------------------ one segment's metrics
def segment_metrics(
    recon: Reconstruction, gt: GroundTruth, can_fall: bool
) -> tuple[dict[str, float], dict[str, np.ndarray]]:
    """Metrics of one reconstruction against its segment's ground truth.

    Args:
        recon: The method's output, as many frames as ``gt``.
        gt: :func:`ground_truth` of the segment.
        can_fall: The method can fall; otherwise ``success_rate`` is NaN.

    Returns:
        ``{key: value}`` for :data:`METRIC_KEYS` except ``ms_per_frame`` (units in the module
        docstring), and ``{key: (24,) per-joint means}`` for :data:`PER_JOINT_KEYS`.
    """
    if recon.n_frames != len(gt.joint_pos):
        raise ValueError(f"reconstruction has {recon.n_frames} frames, ground truth "
                         f"{len(gt.joint_pos)}")  # fmt: skip
    pos, rot, fps = recon.joint_pos, recon.global_rot, gt.fps
    nan = float("nan")
    out = {
        "MPJPE_mm": float(M.mpjpe(pos, gt.joint_pos)),
        "PEL_MPJPE_mm": float(M.pel_mpjpe(pos, gt.joint_pos)),
        "PA_MPJPE_mm": float(M.pa_mpjpe(pos, gt.joint_pos)),
        "MPJRE_deg": float(M.mpjre(rot, gt.global_rot)),
        "Acc_mps2": float(M.acceleration_error(pos, gt.joint_pos, fps)) if len(pos) >= 3 else nan,
        "FS_mps": foot_sliding_mps(pos, gt.foot_contacts, fps),
        "FP_mm": foot_penetration_mm(rot, pos, gt.body),
        "vGRF_N": vgrf_error_n(None if recon.grf is None else recon.grf[..., 2], gt.insole_force_n),
        "success_rate": M.success_rate([recon.fell]) if can_fall else nan,
    }
    per_joint = {
        "MPJPE_mm": M.mpjpe(pos, gt.joint_pos, per_joint=True),
        "PEL_MPJPE_mm": M.pel_mpjpe(pos, gt.joint_pos, per_joint=True),
        "MPJRE_deg": M.mpjre(rot, gt.global_rot, per_joint=True),
    }
    return out, per_joint


# ------------------------------------------------------------------------------ segments
@dataclass(frozen=True)
class Segment:
    """Frames ``[start, stop)`` of one recording file.

    Attributes:
        id: ``<file stem>_f<start>`` (unique within a dataset, safe as a file name).
        path: Recording file.
        start, stop: Frame range.
        category: The recording's motion category (``"unknown"`` when it has none).
    """

    id: str
    path: Path
    start: int
    stop: int
    category: str

    @property
    def n_frames(self) -> int:
        return self.stop - self.start


def list_segments(
    files: Sequence[str | os.PathLike], segment_frames: int = 500, categories: Sequence[str] = (),
    errors: list[tuple[str, str]] | None = None,
) -> list[Segment]:
    """Consecutive ``segment_frames``-frame segments of recording files (tails left out).

    Args:
        files: Recording files (a dataset split).
        segment_frames: Segment length, frames.
        categories: Keep recordings whose category matches one of these globs (all if empty).
        errors: If given, a file that cannot be read is skipped and ``(file, reason)`` appended
            here instead of raising.

    Raises:
        BenchError: A file cannot be read and ``errors`` is ``None`` (the message names it), or
            no segment results.
    """
    from prism_tools.chunking import segments
    from prism_tools.io import load_recording

    if segment_frames < 3:
        raise BenchError(f"segment_frames must be >= 3, got {segment_frames}")
    out: list[Segment] = []
    for f in files:
        path = Path(f)
        try:
            rec = load_recording(path)
        except (OSError, ValueError) as e:
            if errors is None:
                raise BenchError(f"{path}: {e}" if str(path) not in str(e) else str(e)) from e
            text = str(e)
            errors.append((str(path), text.removeprefix(f"{path}:").strip()))
            continue
        cat = rec.category or "unknown"
        if categories and not any(fnmatch.fnmatch(cat, c) for c in categories):
            continue
        for sl in segments(rec.n_frames, segment_frames, min_length=segment_frames):
            out.append(Segment(f"{path.stem}_f{sl.start:06d}", path, sl.start, sl.stop, cat))
    if not out:
        what = f" of categories {list(categories)}" if categories else ""
        raise BenchError(f"no {segment_frames}-frame segment in {len(files)} recording(s){what}")
    return out


def select_segments(segments: Sequence[Segment], n: int) -> list[Segment]:
    """At most ``n`` segments (all if ``n <= 0``), spread over the categories.

    Categories are visited in sorted order, taking each one's next segment in turn, so every
    category is represented before any gets a second segment. Deterministic; the result keeps
    the input order.
    """
    if n <= 0 or n >= len(segments):
        return list(segments)
    by_cat: dict[str, list[int]] = {}
    for i, s in enumerate(segments):
        by_cat.setdefault(s.category, []).append(i)
    chosen: list[int] = []
    rank = 0
    while len(chosen) < n:
        for cat in sorted(by_cat):
            if rank < len(by_cat[cat]) and len(chosen) < n:
                chosen.append(by_cat[cat][rank])
        rank += 1
    return [segments[i] for i in sorted(chosen)]


# -------------------------------------------------------------------------------- methods
@dataclass(frozen=True)
class MethodRun:
    """One column of the benchmark: a method with its options.

    Attributes:
        label: Name in the results (``"kinematics"``, ``"kinematics@imu4_press"``).
        name: Registry name.
        factory: Builds the method from ``options`` (module-level, so workers can import it).
        options: Handed to the factory.
    """

    label: str
    name: str
    factory: MethodFactory
    options: MethodOptions = field(default_factory=MethodOptions)

    def describe(self) -> dict:
        """What identifies this run's results (stored in ``method.json``)."""
        return {"label": self.label, "name": self.name, "options": self.options.to_dict()}

    def build(self) -> Method:
        return make_method(self.name, self.options, {self.name: self.factory})


def prepare_runs(
    names: Sequence[str],
    options: MethodOptions,
    sensors: Sequence[str] = (),
    registry: Mapping[str, MethodFactory] = METHODS,
    log: Callable[[str], object] = print,
) -> tuple[list[MethodRun], dict[str, Method]]:
    """Build every method once (so a bad checkpoint fails here, before any segment runs).

    Args:
        names: Registry names.
        options: Options for every method (``sensors`` is set per run).
        sensors: Sensor configurations: each method that supports them runs once per
            configuration (label ``name@sensors``); the others are skipped with a message.
        registry: Name -> factory.
        log: Where skip messages go.

    Returns:
        The runs and ``{label: built method}`` (reused when the benchmark runs in-process).

    Raises:
        UnknownMethodError / ValueError from the registry or a factory.
    """
    import dataclasses

    runs: list[MethodRun] = []
    built: dict[str, Method] = {}
    for name in names:
        if name not in registry:
            make_method(name, options, registry)  # raises the listing error
        factory = registry[name]
        if not sensors:
            built[name] = make_method(name, options, registry)
            runs.append(MethodRun(name, name, factory, options))
            continue
        for s in sensors:
            opt = dataclasses.replace(options, sensors=s)
            method = make_method(name, opt, registry)
            if not method.supports_sensors:
                log(f"{name}: does not support --sensors; skipped")
                break
            label = f"{name}@{s}"
            built[label] = method
            runs.append(MethodRun(label, name, factory, opt))
    if not runs:
        raise BenchError("no method to run (none of them supports the requested sensors)")
    return runs, built


# ------------------------------------------------------------------------- running segments
def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, np.generic):
        return _jsonable(x.item())
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if x is None or isinstance(x, bool | int | str):
        return x
    return str(x)


def _nan_floats(d: Mapping) -> dict:
    return {k: (float("nan") if v is None else v) for k, v in d.items()}


def _base_row(label: str, seg: Segment) -> dict:
    return {"method": label, "segment": seg.id, "file": str(Path(seg.path).resolve()),
            "start": seg.start, "stop": seg.stop, "category": seg.category}  # fmt: skip


def _error_row(label: str, seg: Segment, error: str, tb: str = "") -> dict:
    return {**_base_row(label, seg), "status": "error", "error": error, "traceback": tb,
            "metrics": {}, "per_joint": {}}  # fmt: skip


def evaluate_segment(
    method: Method, rec, label: str, seg: Segment
) -> tuple[dict, Reconstruction | None]:
    """Run ``method`` on one segment recording and score it; exceptions become an error row.

    Returns:
        The row (``status`` "ok" with ``metrics``, ``per_joint``, ``frames``, ``falls``,
        ``can_fall``, ``notes``; or "error" with ``error`` and ``traceback``) and the
        reconstruction (``None`` on error).
    """
    try:
        t0 = time.perf_counter()
        recon = method.reconstruct(rec)
        wall_s = time.perf_counter() - t0
        if not isinstance(recon, Reconstruction):
            raise TypeError(f"{method.name}.reconstruct returned {type(recon).__name__}, "
                            "not a Reconstruction")  # fmt: skip
        if recon.n_frames != rec.n_frames or not np.isclose(recon.fps, float(rec.fps)):
            raise ValueError(f"{method.name}: returned {recon.n_frames} frames at "
                             f"{recon.fps} fps for a {rec.n_frames}-frame segment at "
                             f"{rec.fps} fps")  # fmt: skip
        metrics, per_joint = segment_metrics(recon, ground_truth(rec), bool(method.can_fall))
    except Exception as e:
        tb = "".join(traceback.format_exception(e)[-12:])
        return _error_row(label, seg, f"{type(e).__name__}: {e}", tb), None
    metrics["ms_per_frame"] = 1000.0 * wall_s / rec.n_frames
    row = {**_base_row(label, seg), "status": "ok", "frames": recon.n_frames,
           "can_fall": bool(method.can_fall), "falls": int(recon.falls.shape[0]),
           "blowups": int(recon.notes.get("blowups", 0)),
           "metrics": metrics, "per_joint": per_joint,
           "method_ms_per_frame": float(recon.ms_per_frame), "notes": recon.notes}  # fmt: skip
    return row, recon


def _segment_file(out_dir: Path, label: str, seg_id: str) -> Path:
    return out_dir / "segments" / label / f"{seg_id}.json"


def _recon_file(out_dir: Path, label: str, seg_id: str) -> Path:
    return out_dir / "recons" / label / f"{seg_id}.npz"


def _marker(out_dir: Path, label: str, seg_id: str) -> Path:
    return out_dir / "segments" / label / f"{seg_id}.running"


def _write_row(out_dir: Path, row: dict) -> None:
    text = json.dumps(_jsonable(row), indent=1, allow_nan=False)
    atomic_write_text(_segment_file(out_dir, row["method"], row["segment"]), text + "\n")


def _read_row(path: Path, seg: Segment) -> dict:
    """A finished segment's row (NaN restored); errors if it belongs to other data."""
    try:
        row = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as e:
        raise BenchError(
            f"{path}: unreadable segment result ({e}); delete it to run it again"
        ) from e
    want = _base_row(row.get("method", ""), seg)
    diff = [k for k in ("file", "start", "stop") if row.get(k) != want[k]]
    if diff:
        raise BenchError(f"{path}: computed on other data ({', '.join(diff)} differ: "
                         f"{[row.get(k) for k in diff]} vs {[want[k] for k in diff]}); use "
                         "another output folder")  # fmt: skip
    row["metrics"] = _nan_floats(row.get("metrics", {}))
    row["per_joint"] = {k: np.array([np.nan if v is None else v for v in vals], dtype=float)
                        for k, vals in row.get("per_joint", {}).items()}  # fmt: skip
    return row


class _State:
    """Per-process cache: methods built once, the last recording file loaded."""

    def __init__(self, built: Mapping[str, Method] | None = None, one_thread: bool = False):
        self.methods: dict[str, Method] = dict(built or {})
        self.one_thread = one_thread
        self._path: Path | None = None
        self._rec = None

    def method(self, run: MethodRun) -> Method:
        if run.label not in self.methods:
            self.methods[run.label] = run.build()
            if self.one_thread and "torch" in sys.modules:
                sys.modules["torch"].set_num_threads(1)
        return self.methods[run.label]

    def segment(self, seg: Segment):
        from prism_tools.io import load_recording

        if self._path != seg.path:
            self._rec, self._path = load_recording(seg.path), seg.path
        return self._rec.slice_frames(seg.start, seg.stop)


_WORKER_STATE: _State | None = None


_THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


def _init_worker() -> None:
    """Worker process set-up (the BLAS thread count comes from :func:`_pool_round`'s
    environment: a worker has imported numpy before its initializer runs)."""
    global _WORKER_STATE
    _WORKER_STATE = _State(one_thread=True)


def _run_task(run: MethodRun, seg: Segment, out_dir: Path, save_recon: bool,
              state: _State | None = None) -> dict:  # fmt: skip
    """Run one (method, segment) task and store its row (and reconstruction)."""
    state = state or _WORKER_STATE
    if state is None:
        raise RuntimeError("_run_task outside a worker needs a state")
    marker = _marker(out_dir, run.label, seg.id)
    marker.parent.mkdir(parents=True, exist_ok=True)
    marker.touch()
    method = state.method(run)
    try:
        rec = state.segment(seg)
    except Exception as e:
        row, recon = _error_row(run.label, seg, f"{type(e).__name__}: {e}"), None
    else:
        row, recon = evaluate_segment(method, rec, run.label, seg)
    if recon is not None and save_recon:
        recon.name = seg.id
        recon.save(_recon_file(out_dir, run.label, seg.id))
    _write_row(out_dir, row)
    marker.unlink(missing_ok=True)
    return row


def _check_method_settings(out_dir: Path, run: MethodRun) -> None:
    path = out_dir / "segments" / run.label / "method.json"
    want = _jsonable(run.describe())
    if path.is_file():
        try:
            have = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as e:
            raise BenchError(f"{path}: unreadable ({e})") from e
        if have != want:
            raise BenchError(f"{path.parent}: results of {run.label} with other settings "
                             f"({have} vs now {want}); use another output folder")  # fmt: skip
    else:
        atomic_write_text(path, json.dumps(want, indent=1) + "\n")


def _start_method() -> str:
    return "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"


def run_bench(
    runs: Sequence[MethodRun],
    segments: Sequence[Segment],
    out_dir: str | os.PathLike,
    *,
    workers: int = 1,
    save_recons: bool = False,
    retry_failed: bool = False,
    built: Mapping[str, Method] | None = None,
    progress: Callable[[dict], object] | None = None,
    log: Callable[[str], object] = print,
) -> list[dict]:
    """Run every method on every segment, keeping what a previous run finished.

    Args:
        runs: The methods (:func:`prepare_runs`).
        segments: The segments (the first is the sample segment of the plots; its
            reconstructions are always saved).
        out_dir: Output folder (created; resumed when it exists).
        workers: Processes (``1``: in this process). Each worker builds each method once and
            runs torch with one thread (in-process too, for comparable runtimes).
        save_recons: Save every reconstruction under ``out_dir/recons``.
        retry_failed: Run segments that finished with an error again.
        built: ``{label: method}`` already built here (reused when ``workers == 1``).
        progress: Called with each newly finished row.
        log: Messages (resumed and failed counts).

    Returns:
        One row per (run, segment), in segment-major order.

    Raises:
        BenchError: Results in ``out_dir`` from other settings, or workers that keep dying.
    """
    out_dir = Path(out_dir)
    if not runs or not segments:
        raise BenchError("nothing to run: no method or no segment")
    labels = [r.label for r in runs]
    if len(set(labels)) != len(labels):
        raise BenchError(f"method labels given twice: {labels}")
    for run in runs:
        _check_method_settings(out_dir, run)
        for m in (out_dir / "segments" / run.label).glob("*.running"):
            m.unlink(missing_ok=True)  # left by an interrupted run
    sample = segments[0].id
    rows: dict[tuple[str, str], dict] = {}
    tasks: list[tuple[MethodRun, Segment]] = []
    kept_errors = 0
    for seg in segments:
        for run in runs:
            path = _segment_file(out_dir, run.label, seg.id)
            if path.is_file():
                row = _read_row(path, seg)
                recon = _recon_file(out_dir, run.label, seg.id)
                missing_recon = row["status"] == "ok" and seg.id == sample and not recon.is_file()
                if not missing_recon and (row["status"] == "ok" or not retry_failed):
                    rows[(run.label, seg.id)] = row
                    kept_errors += row["status"] != "ok"
                    continue
            tasks.append((run, seg))
    if rows:
        log(f"resuming: {len(rows)} finished segment result(s) kept"
            + (f", {kept_errors} of them failed (--retry-failed runs those again)"
               if kept_errors else ""))  # fmt: skip

    def save(seg: Segment) -> bool:
        return save_recons or seg.id == sample

    def done(row: dict) -> None:
        rows[(row["method"], row["segment"])] = row
        if progress is not None:
            progress(row)

    if workers <= 1:
        # One thread, as in a worker process, so that runtimes compare; restored afterwards.
        torch = sys.modules.get("torch")
        prev_threads = torch.get_num_threads() if torch is not None else 0
        if torch is not None:
            torch.set_num_threads(1)
        try:
            state = _State(built)
            for run, seg in tasks:
                done(_run_task(run, seg, out_dir, save(seg), state))
        finally:
            if torch is not None:
                torch.set_num_threads(prev_threads)
    elif tasks:
        _run_pool(tasks, out_dir, save, workers, done)
    return [rows[(r.label, s.id)] for s in segments for r in runs if (r.label, s.id) in rows]


def _pool_round(tasks, out_dir: Path, save, workers: int, done) -> list:
    """Run ``tasks`` in one pool; returns the tasks lost when a worker process died."""
    ctx = mp.get_context(_start_method())
    lost = []
    # one BLAS thread per worker: set before the workers (and the forkserver) start, because
    # OpenBLAS reads it when numpy is first imported
    saved = {v: os.environ.get(v) for v in _THREAD_VARS}
    os.environ.update(dict.fromkeys(_THREAD_VARS, "1"))
    try:
        return _pool_round_in_env(ctx, tasks, out_dir, save, workers, done, lost)
    finally:
        for v, old in saved.items():
            if old is None:
                os.environ.pop(v, None)
            else:
                os.environ[v] = old


def _pool_round_in_env(ctx, tasks, out_dir: Path, save, workers: int, done, lost) -> list:
    with ProcessPoolExecutor(max_workers=min(workers, len(tasks)), mp_context=ctx,
                             initializer=_init_worker) as pool:  # fmt: skip
        futures = {pool.submit(_run_task, run, seg, out_dir, save(seg)): (run, seg)
                   for run, seg in tasks}  # fmt: skip
        for fut in as_completed(futures):
            run, seg = futures[fut]
            try:
                row = fut.result()
            except BrokenProcessPool:
                lost.append((run, seg))
                continue
            except Exception as e:  # outside the per-segment guard (building the method)
                # Reported but not stored: the next run tries again.
                row = _error_row(run.label, seg, f"{type(e).__name__}: {e}")
            done(row)
    return lost


def _run_pool(tasks, out_dir: Path, save, workers: int, done) -> None:
    """Run tasks in worker processes, surviving workers that die.

    When a worker dies the pool breaks and every unfinished task is lost. The tasks that were
    running (their ``.running`` marker exists) are suspects: each runs again alone in a
    one-worker pool, and one that kills its worker there too is recorded as an error. The
    others go back into a fresh pool.
    """
    pending = list(tasks)
    while pending:
        lost = _pool_round(pending, out_dir, save, workers, done)
        suspects, pending = [], []
        for run, seg in lost:
            marker = _marker(out_dir, run.label, seg.id)
            (suspects if marker.exists() else pending).append((run, seg))
            marker.unlink(missing_ok=True)
        if lost and not suspects:
            raise BenchError("worker processes died before running any segment; run with "
                             "--workers 1 to see the error")  # fmt: skip
        for run, seg in suspects:
            if _pool_round([(run, seg)], out_dir, save, 1, done):
                _marker(out_dir, run.label, seg.id).unlink(missing_ok=True)
                row = _error_row(run.label, seg, "the worker process died while running this "
                                 "segment (crash or out of memory)")  # fmt: skip
                _write_row(out_dir, row)
                done(row)


def load_rows(out_dir: str | os.PathLike, runs: Sequence[MethodRun],
              segments: Sequence[Segment]) -> list[dict]:  # fmt: skip
    """The finished rows of ``runs`` x ``segments`` in ``out_dir`` (missing ones left out)."""
    out_dir = Path(out_dir)
    rows = []
    for seg in segments:
        for run in runs:
            p = _segment_file(out_dir, run.label, seg.id)
            if p.is_file():
                rows.append(_read_row(p, seg))
    return rows


# ---------------------------------------------------------------------------- aggregation
def aggregate(rows: Sequence[dict], labels: Sequence[str]) -> dict[str, dict]:
    """Per label: segment means of :data:`METRIC_KEYS`, ``segments`` (finished without error),
    ``failed`` (segments whose method raised), and ``per_joint`` ``{key: (24,)}``.

    Means use :func:`grip.core.metrics.summarize` (NaN segments skipped; NaN if none). The
    success rate is over the segments that ran without error.
    """
    out: dict[str, dict] = {}
    for label in labels:
        mine = [r for r in rows if r["method"] == label]
        ok = [r for r in mine if r["status"] == "ok"]
        s = M.summarize([r["metrics"] for r in ok]) if ok else {}
        res: dict = {k: float(s.get(k, float("nan"))) for k in METRIC_KEYS}
        res["segments"] = len(ok)
        res["blowups"] = int(sum(r.get("blowups", 0) for r in ok))
        res["failed"] = len(mine) - len(ok)
        pj = M.summarize([r["per_joint"] for r in ok if r["per_joint"]]) if ok else {}
        res["per_joint"] = {k: np.asarray(v) for k, v in pj.items()}
        out[label] = res
    return out


def _cell(v, fmt: str) -> str:
    return "n/a" if v is None or not np.isfinite(v) else fmt.format(v)


def markdown_table(summary: Mapping[str, Mapping]) -> str:
    """The GRIP Table 1 columns, runtime (ms per frame), segments and failures, one row per
    method label; "n/a" where a method has no value (no forces, cannot fall)."""
    head = ["method", *[c[1] for c in _TABLE_COLUMNS], "segments", "failed"]
    lines = ["| " + " | ".join(head) + " |", "|---|" + "---:|" * (len(head) - 1)]
    for label, s in summary.items():
        cells = [_cell(s[k], fmt) for k, _, fmt in _TABLE_COLUMNS]
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {s['segments']} | {s['failed']} |")
    return "\n".join(lines)


def _category_table(rows: Sequence[dict], labels: Sequence[str]) -> str:
    cats = sorted({r["category"] for r in rows})
    lines = ["| category | " + " | ".join(labels) + " |", "|---|" + "---:|" * len(labels)]
    for c in cats:
        cells = []
        for label in labels:
            ok = [r["metrics"] for r in rows if r["category"] == c and r["method"] == label
                  and r["status"] == "ok"]  # fmt: skip
            cells.append(_cell(M.summarize(ok)["MPJPE_mm"], "{:.1f}") if ok else "n/a")
        lines.append(f"| {c} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _sweep_table(summary: Mapping[str, Mapping], runs: Sequence[MethodRun]) -> str:
    from grip.eval.methods import sensor_set

    lines = ["| method | #IMU | insoles | MPJPE (mm) | PA-MPJPE (mm) | Succ. (%) |",
             "|---|---:|:---:|---:|---:|---:|"]  # fmt: skip
    for run in runs:
        s, st = summary[run.label], sensor_set(run.options.sensors)
        lines.append(f"| {run.name} | {st.n_imu} | {'yes' if st.insoles else 'no'} | "
                     f"{_cell(s['MPJPE_mm'], '{:.2f}')} | {_cell(s['PA_MPJPE_mm'], '{:.2f}')} | "
                     f"{_cell(s['success_rate'], '{:.2f}')} |")  # fmt: skip
    return "\n".join(lines)


def _results_json(summary: Mapping[str, Mapping]) -> dict:
    return {label: _jsonable({k: s[k] for k in (*RESULT_KEYS, "failed")})
            for label, s in summary.items()}  # fmt: skip


def _csv(rows: Sequence[Mapping], keys: Sequence[str]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(keys), extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: "" if r.get(k) is None else r.get(k) for k in keys})
    return buf.getvalue()


def write_outputs(
    out_dir: str | os.PathLike,
    rows: Sequence[dict],
    runs: Sequence[MethodRun],
    segments: Sequence[Segment],
    title: str = "",
    plots: bool = True,
) -> dict[str, dict]:
    """Write ``results.json``, ``results.csv``, ``segments.csv``, ``table.md`` and the plots.

    Returns:
        :func:`aggregate` of the rows.
    """
    out_dir = Path(out_dir)
    labels = [r.label for r in runs]
    summary = aggregate(rows, labels)
    results = _results_json(summary)
    atomic_write_text(out_dir / "results.json", json.dumps(results, indent=1) + "\n")
    atomic_write_text(out_dir / "results.csv",
                      _csv([{"method": k, **v} for k, v in results.items()],
                           ["method", *RESULT_KEYS, "failed"]))  # fmt: skip
    seg_rows = [{**{k: r[k] for k in ("method", "segment", "category", "start", "stop",
                                      "status")},
                 "frames": r.get("frames"), "falls": r.get("falls"),
                 "blowups": r.get("blowups"), "error": r.get("error"),
                 **_jsonable(r["metrics"])} for r in rows]  # fmt: skip
    atomic_write_text(out_dir / "segments.csv",
                      _csv(seg_rows, ["method", "segment", "category", "start", "stop", "status",
                                      "frames", "falls", "blowups", *METRIC_KEYS,
                                      "error"]))  # fmt: skip
    n_frames = sorted({s.n_frames for s in segments})
    parts = [f"# {title}" if title else "# Benchmark",
             f"{len(segments)} segment(s) of {', '.join(map(str, n_frames))} frames, each started "
             "from the ground truth at its first frame; means over segments; n/a: the method "
             "has no such output (no forces, cannot fall).", "", markdown_table(summary), "",
             "ms/frame: wall time of one segment's reconstruction per frame, measured with "
             "the run's worker count (other processes share the cores).", "",
             "## MPJPE (mm) per category", "", _category_table(rows, labels)]  # fmt: skip
    blown = {label: s["blowups"] for label, s in summary.items() if s["blowups"]}
    if blown:
        parts[5:5] = ["Simulation blow-ups (each recovered like a fall, its frames replaced): "
                      + ", ".join(f"{k} {v}" for k, v in blown.items()), ""]  # fmt: skip
    if any(r.options.sensors for r in runs):
        parts += ["", "## Sensor configurations (GRIP Table 3 layout)", "",
                  _sweep_table(summary, [r for r in runs if r.options.sensors])]  # fmt: skip
    errors = [r for r in rows if r["status"] != "ok"]
    if errors:
        parts += ["", "## Failed segments", ""]
        parts += [f"- {r['method']} / {r['segment']}: {r['error']}" for r in errors]
    atomic_write_text(out_dir / "table.md", "\n".join(parts) + "\n")
    if plots:
        plot_per_joint(summary, out_dir / "per_joint.png")
        plot_sample(out_dir, runs, segments[0], out_dir / "trajectory.png", out_dir / "grf.png")
    return summary


# ---------------------------------------------------------------------------------- plots
def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_per_joint(summary: Mapping[str, Mapping], out_png: str | os.PathLike) -> None:
    """Grouped bars of the per-joint PEL-MPJPE and MPJRE of every method."""
    plt = _pyplot()
    labels = [k for k, s in summary.items() if s["per_joint"]]
    fig, axes = plt.subplots(1, 2, figsize=(14, 8), constrained_layout=True)
    y = np.arange(len(sk.JOINT_NAMES))
    h = 0.8 / max(len(labels), 1)
    for ax, key, xlabel in ((axes[0], "PEL_MPJPE_mm", "PEL-MPJPE (mm)"),
                            (axes[1], "MPJRE_deg", "MPJRE (deg)")):  # fmt: skip
        for i, label in enumerate(labels):
            ax.barh(y + (i - (len(labels) - 1) / 2) * h, summary[label]["per_joint"][key],
                    height=h, label=label)  # fmt: skip
        ax.set_yticks(y, sk.JOINT_NAMES)
        ax.invert_yaxis()
        ax.set_xlabel(xlabel)
        if labels:
            ax.legend()
        else:
            ax.text(0.5, 0.5, "no finished segment", ha="center", transform=ax.transAxes)
    fig.suptitle("Per-joint errors (means over segments)")
    fig.savefig(out_png, dpi=80)
    plt.close(fig)


def plot_sample(
    out_dir: str | os.PathLike,
    runs: Sequence[MethodRun],
    seg: Segment,
    traj_png: str | os.PathLike,
    grf_png: str | os.PathLike,
) -> None:
    """Pelvis trajectory (top view, height) and vertical GRF per foot of the sample segment:
    the ground truth (insole force) against each method's saved reconstruction."""
    from prism_tools.io import load_recording

    plt = _pyplot()
    rec = load_recording(seg.path).slice_frames(seg.start, seg.stop)
    gt = ground_truth(rec)
    t = np.arange(seg.n_frames) / gt.fps
    recons = {}
    for run in runs:
        p = _recon_file(Path(out_dir), run.label, seg.id)
        if p.is_file():
            recons[run.label] = Reconstruction.load(p)
    fig, (ax_xy, ax_z) = plt.subplots(1, 2, figsize=(13, 5.5), constrained_layout=True)
    ax_xy.plot(*gt.joint_pos[:, 0, :2].T, "k-", lw=2, label="ground truth")
    ax_z.plot(t, gt.joint_pos[:, 0, 2], "k-", lw=2, label="ground truth")
    for label, r in recons.items():
        ax_xy.plot(*r.root_pos[:, :2].T, label=label)
        ax_z.plot(t, r.root_pos[:, 2], label=label)
    ax_xy.plot(*gt.joint_pos[0, 0, :2], "ko")
    ax_xy.set(xlabel="x (m)", ylabel="y (m)", title="pelvis, top view (dot: start)")
    ax_xy.axis("equal")
    ax_z.set(xlabel="time (s)", ylabel="pelvis height (m)", title="pelvis height")
    ax_xy.legend()
    fig.suptitle(f"sample segment {seg.id} ({seg.category})", fontsize=10)
    fig.savefig(traj_png, dpi=80)
    plt.close(fig)

    fig, axes = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True, constrained_layout=True)
    with_forces = {k: r for k, r in recons.items() if r.grf is not None}
    for i, (ax, foot) in enumerate(zip(axes, _FEET, strict=True)):
        if gt.insole_force_n is not None:
            ax.plot(t, gt.insole_force_n[:, i], "k-", lw=2, label="insole")
        for label, r in with_forces.items():
            ax.plot(t, r.grf[:, i, 2], label=label)
        ax.set(ylabel=f"{foot} vertical force (N)")
        ax.legend(loc="upper right")
    axes[-1].set_xlabel("time (s)")
    note = "" if with_forces else " (no method outputs forces)"
    fig.suptitle(f"vertical ground reaction force{note}\nsample segment {seg.id}", fontsize=10)
    fig.savefig(grf_png, dpi=80)
    plt.close(fig)
