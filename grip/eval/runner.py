"""The one runner of the evaluations: methods played over :mod:`grip.eval.segments`.

Two ways to run:

- :func:`play_segments`: in this process, a batch of segment recordings at a time, through a
  scoring function (``grip kin eval``, ``grip policy eval``); nothing is stored.
- :func:`run_bench`: every :class:`MethodRun` on every segment, in worker processes or here, each
  finished segment stored as ``OUT/segments/<label>/<segment>.json`` so that a run resumes
  (``grip bench``; the folder layout is in :mod:`grip.eval.bench`).

Rows are dicts. Every row starts with the segment's keys (:func:`segment_keys`: ``segment``,
``name``, ``category``, ``start``, ``stop``, ``frames``); a method's row (:func:`base_row`) adds
``method``, ``file``, ``status`` and its metrics under ``metrics``.
"""

from __future__ import annotations

import json
import os
import sys
import time
import traceback
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from grip.core.atomic import atomic_write_text
from grip.core.reconstruction import Reconstruction
from grip.core.runs import CallPool
from grip.eval.methods import (
    METHODS,
    Method,
    MethodFactory,
    MethodOptions,
    make_method,
    model_files,
)
from grip.eval.pool import one_torch_thread, run_pool
from grip.eval.report import jsonable, nan_floats
from grip.eval.resume import check_inputs, check_method
from grip.eval.scoring import segment_metrics
from grip.eval.segments import BenchError, Segment, SegmentReader
from grip.kinematics.features import ground_truth

__all__ = [
    "MethodRun",
    "base_row",
    "error_row",
    "evaluate_segment",
    "load_rows",
    "play_segments",
    "prepare_runs",
    "recon_file",
    "run_bench",
    "score_segment",
    "segment_keys",
]


def segment_keys(seg: Segment, rec) -> dict:
    """The keys a row of ``seg`` starts with (``rec``: its recording)."""
    return {"segment": seg.id, "name": rec.name, "category": seg.category, "start": seg.start,
            "stop": seg.stop, "frames": int(rec.n_frames)}  # fmt: skip


def play_segments(
    segments: Sequence[Segment],
    score: Callable[[list], list[dict]],
    batch: int = 1,
    progress: Callable[[int], object] | None = None,
) -> list[dict]:
    """Score segments in this process, ``batch`` recordings at a time.

    Args:
        segments: What to run, in order.
        score: Segment recordings -> one dict of results per recording (its keys override
            :func:`segment_keys`).
        batch: Recordings handed to ``score`` at once (a batched network's forward pass).
        progress: Called with the number of segments finished after each batch.

    Returns:
        One row per segment: :func:`segment_keys` and what ``score`` returned.
    """
    read = SegmentReader()
    rows: list[dict] = []
    for i in range(0, len(segments), batch):
        part = list(segments[i : i + batch])
        recs = [read(s) for s in part]
        for seg, rec, res in zip(part, recs, score(recs), strict=True):
            rows.append(segment_keys(seg, rec) | res)
        if progress is not None:
            progress(len(part))
    return rows


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
        """What identifies this run's results (stored in ``method.json``), besides the contents
        of its model files (:meth:`model_files`, compared by :mod:`grip.eval.resume`)."""
        return {"label": self.label, "name": self.name, "options": self.options.to_dict()}

    def model_files(self) -> dict[str, Path]:
        """The model files its results depend on (:func:`grip.eval.methods.model_files`)."""
        return model_files(self.name, self.options)

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



# ----------------------------------------------------------------- stored, resumable runs
def base_row(label: str, seg: Segment) -> dict:
    return {"method": label, "segment": seg.id, "file": str(Path(seg.path).resolve()),
            "start": seg.start, "stop": seg.stop, "category": seg.category}  # fmt: skip


def error_row(label: str, seg: Segment, error: str, tb: str = "") -> dict:
    return {**base_row(label, seg), "status": "error", "error": error, "traceback": tb,
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
    t0 = time.perf_counter()
    try:
        recon = method.reconstruct(rec)
    except Exception as e:
        recon = e
    return score_segment(method, rec, label, seg, recon, time.perf_counter() - t0)


def score_segment(method: Method, rec, label: str, seg: Segment,
                  recon: Reconstruction | Exception, wall_s: float,
                  ) -> tuple[dict, Reconstruction | None]:  # fmt: skip
    """:func:`evaluate_segment`'s row of what ``method`` returned for ``rec`` (or the
    exception it raised) in ``wall_s`` seconds."""
    try:
        if isinstance(recon, Exception):
            raise recon
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
        return error_row(label, seg, f"{type(e).__name__}: {e}", tb), None
    metrics["ms_per_frame"] = 1000.0 * wall_s / rec.n_frames
    row = {**base_row(label, seg), "status": "ok", "frames": recon.n_frames,
           "can_fall": bool(method.can_fall), "falls": int(recon.falls.shape[0]),
           "blowups": int(recon.notes.get("blowups", 0)), "lost": int(recon.notes.get("lost", 0)),
           "metrics": metrics, "per_joint": per_joint,
           "method_ms_per_frame": float(recon.ms_per_frame), "notes": recon.notes}  # fmt: skip
    return row, recon


def _batchable(method: Method) -> bool:
    """Whether ``method`` plays several segments side by side (``reconstruct_many(recs,
    threads)``: a list of reconstructions or exceptions, as :class:`grip.eval.methods.Grip`)."""
    return callable(getattr(method, "reconstruct_many", None))


def _evaluate_many(method: Method, recs: list, label: str, segs: list[Segment],
                   threads: int) -> list[tuple[dict, Reconstruction | None]]:  # fmt: skip
    """:func:`evaluate_segment` of each recording, played side by side; the wall time is
    shared out by frames (each row's ``ms_per_frame`` is the batch's per frame)."""
    t0 = time.perf_counter()
    try:
        got = method.reconstruct_many(recs, threads=threads)
    except Exception as e:  # (outside every segment: each fails with it)
        got = [e] * len(recs)
    wall_s = time.perf_counter() - t0
    total = max(sum(int(r.n_frames) for r in recs), 1)
    return [score_segment(method, rec, label, seg, res, wall_s * int(rec.n_frames) / total)
            for rec, seg, res in zip(recs, segs, got, strict=True)]  # fmt: skip


def _segment_file(out_dir: Path, label: str, seg_id: str) -> Path:
    return out_dir / "segments" / label / f"{seg_id}.json"


def recon_file(out_dir: Path, label: str, seg_id: str) -> Path:
    return out_dir / "recons" / label / f"{seg_id}.npz"


def _marker(out_dir: Path, label: str, seg_id: str) -> Path:
    return out_dir / "segments" / label / f"{seg_id}.running"


def _write_row(out_dir: Path, row: dict) -> None:
    text = json.dumps(jsonable(row), indent=1, allow_nan=False)
    atomic_write_text(_segment_file(out_dir, row["method"], row["segment"]), text + "\n")


def _read_row(path: Path, seg: Segment) -> dict:
    """A finished segment's row (NaN restored); errors if it belongs to other data."""
    try:
        row = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as e:
        raise BenchError(
            f"{path}: unreadable segment result ({e}); delete it to run it again"
        ) from e
    want = base_row(row.get("method", ""), seg)
    diff = [k for k in ("file", "start", "stop") if row.get(k) != want[k]]
    if diff:
        raise BenchError(f"{path}: computed on other data ({', '.join(diff)} differ: "
                         f"{[row.get(k) for k in diff]} vs {[want[k] for k in diff]}); use "
                         "another output folder")  # fmt: skip
    row["metrics"] = nan_floats(row.get("metrics", {}))
    row["per_joint"] = {k: np.array([np.nan if v is None else v for v in vals], dtype=float)
                        for k, vals in row.get("per_joint", {}).items()}  # fmt: skip
    return row


class _State:
    """Per-process cache: methods built once, the last recording file loaded."""

    def __init__(self, built: Mapping[str, Method] | None = None, one_thread: bool = False):
        self.methods: dict[str, Method] = dict(built or {})
        self.one_thread = one_thread
        self.segment = SegmentReader()

    def method(self, run: MethodRun) -> Method:
        if run.label not in self.methods:
            self.methods[run.label] = run.build()
            if self.one_thread and "torch" in sys.modules:
                sys.modules["torch"].set_num_threads(1)
        return self.methods[run.label]


_WORKER_STATE: _State | None = None


def _init_worker() -> None:
    """Worker process set-up (the BLAS thread count comes from
    :func:`grip.eval.pool.run_pool`'s environment, or from Ray's for a Ray worker: a worker has
    imported numpy before its first task)."""
    global _WORKER_STATE
    _WORKER_STATE = _State(one_thread=True)


def _worker_task(run: MethodRun, segs: Sequence[Segment], out_dir: Path, saves: Sequence[bool],
                 threads: int) -> list[dict]:  # fmt: skip
    """:func:`_run_task` in a worker process (a local one or Ray's), whose state (the methods
    it built) is made on its first call and kept."""
    if _WORKER_STATE is None:
        _init_worker()
    return _run_task(run, segs, out_dir, saves, _WORKER_STATE, threads)


def _run_task(run: MethodRun, segs: Sequence[Segment], out_dir: Path, saves: Sequence[bool],
              state: _State | None = None, threads: int = 0) -> list[dict]:  # fmt: skip
    """Run one method on segments (one segment, or several that a batchable method plays side
    by side, ``threads`` threads stepping them) and store their rows (and reconstructions,
    where ``saves`` says so)."""
    state = state or _WORKER_STATE
    if state is None:
        raise RuntimeError("_run_task outside a worker needs a state")
    for seg in segs:
        marker = _marker(out_dir, run.label, seg.id)
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.touch()
    method = state.method(run)
    results: dict[str, tuple[dict, Reconstruction | None]] = {}
    readable: list[tuple[Segment, object]] = []
    for seg in segs:
        try:
            readable.append((seg, state.segment(seg)))
        except Exception as e:
            results[seg.id] = (error_row(run.label, seg, f"{type(e).__name__}: {e}"), None)
    if len(readable) > 1 and _batchable(method):
        got = _evaluate_many(method, [r for _, r in readable], run.label,
                             [s for s, _ in readable], threads)  # fmt: skip
        results.update({seg.id: res for (seg, _), res in zip(readable, got, strict=True)})
    else:
        for seg, rec in readable:
            results[seg.id] = evaluate_segment(method, rec, run.label, seg)
    rows = []
    for seg, save in zip(segs, saves, strict=True):
        row, recon = results[seg.id]
        if recon is not None and save:
            recon.name = seg.id
            recon.save(recon_file(out_dir, run.label, seg.id))
        _write_row(out_dir, row)
        _marker(out_dir, run.label, seg.id).unlink(missing_ok=True)
        rows.append(row)
    return rows


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
    batch: int = 1,
    pool: CallPool | None = None,
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
        batch: Segments a method that can (``reconstruct_many``, method ``grip``) plays side
            by side, in each worker (fewer when that leaves a worker idle); its humanoids are
            stepped by the cores a worker has to itself. 1: one segment at a time.
        pool: Runs the units of work instead of ``workers`` local processes (a
            :class:`grip.cluster.RayPool`: ``grip bench --ray``); a unit lost with its worker
            is handled as a local worker's death is.

    Returns:
        One row per (run, segment), in segment-major order.

    Raises:
        BenchError: Results in ``out_dir`` from other settings, other model or recording
            contents (:mod:`grip.eval.resume`), or workers that keep dying.
    """
    out_dir = Path(out_dir)
    if not runs or not segments:
        raise BenchError("nothing to run: no method or no segment")
    labels = [r.label for r in runs]
    if len(set(labels)) != len(labels):
        raise BenchError(f"method labels given twice: {labels}")
    for run in runs:
        check_method(out_dir, run, log)
    check_inputs(out_dir, [s.path for s in segments], log)
    for run in runs:
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
                recon = recon_file(out_dir, run.label, seg.id)
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

    from grip.pipeline import usable_cores

    state = _State(built)
    n = pool.workers if pool is not None else workers
    units = _units(tasks, batch, n, lambda run: _batchable(state.method(run)))
    threads = max(1, usable_cores() // max(n, 1))
    if pool is None and workers <= 1:
        with one_torch_thread():  # as in a worker process, so that runtimes compare
            for run, segs in units:
                for row in _run_task(run, segs, out_dir, [save(s) for s in segs], state,
                                     threads):  # fmt: skip
                    done(row)
    elif units:
        _run_pool(units, out_dir, save, workers, done, threads, pool)
    return [rows[(r.label, s.id)] for s in segments for r in runs if (r.label, s.id) in rows]


def _units(tasks: Sequence[tuple[MethodRun, Segment]], batch: int, workers: int,
           batchable: Callable[[MethodRun], bool],
           ) -> list[tuple[MethodRun, list[Segment]]]:  # fmt: skip
    """Units of work: one segment each, or for a batchable method up to ``batch`` of its
    segments in their order (fewer when ``workers`` would otherwise wait)."""
    single: list[tuple[MethodRun, list[Segment]]] = []
    per_run: dict[str, tuple[MethodRun, list[Segment]]] = {}
    for run, seg in tasks:
        if batch > 1 and batchable(run):
            per_run.setdefault(run.label, (run, []))[1].append(seg)
        else:
            single.append((run, [seg]))
    units = list(single)
    for run, segs in per_run.values():
        size = max(1, min(batch, -(-len(segs) // max(workers, 1))))
        units += [(run, segs[i : i + size]) for i in range(0, len(segs), size)]
    return units


def _pool_round(units, out_dir: Path, save, workers: int, done, threads: int,
                pool: CallPool | None = None) -> list:  # fmt: skip
    """Run ``units`` in ``pool``, or else in a pool of ``workers`` processes of their own
    (:func:`grip.eval.pool.run_pool`); returns the units lost when a worker process died."""

    def finished(k: int, rows) -> None:
        run, segs = units[k]
        if isinstance(rows, Exception):  # outside the per-segment guard (building the method)
            # Reported but not stored: the next run tries again.
            rows = [error_row(run.label, seg, f"{type(rows).__name__}: {rows}") for seg in segs]
        for row in rows:
            done(row)

    calls = [(_worker_task, (run, segs, out_dir, [save(s) for s in segs], threads))
             for run, segs in units]  # fmt: skip
    lost = pool.run(calls, finished) if pool is not None else run_pool(calls, workers, finished)
    return [units[k] for k in lost]


def _run_pool(units, out_dir: Path, save, workers: int, done, threads: int = 1,
              pool: CallPool | None = None) -> None:  # fmt: skip
    """Run units of work in worker processes (or in ``pool``), surviving workers that die.

    When a local worker dies the pool breaks and every unfinished unit is lost (with Ray, the
    unit it ran). The segments that were running (their ``.running`` marker exists) are
    suspects: each runs again alone (in a one-worker pool, or as the only task of ``pool``),
    and one that kills its worker there too is recorded as an error. The others go back into a
    fresh pool.
    """
    pending = list(units)
    while pending:
        lost = _pool_round(pending, out_dir, save, workers, done, threads, pool)
        suspects, pending = [], []
        for run, segs in lost:
            for seg in segs:
                marker = _marker(out_dir, run.label, seg.id)
                (suspects if marker.exists() else pending).append((run, [seg]))
                marker.unlink(missing_ok=True)
        if lost and not suspects:
            raise BenchError("worker processes died before running any segment; run with "
                             "--workers 1 to see the error")  # fmt: skip
        for run, segs in suspects:
            if _pool_round([(run, segs)], out_dir, save, 1, done, threads, pool):
                (seg,) = segs
                _marker(out_dir, run.label, seg.id).unlink(missing_ok=True)
                row = error_row(run.label, seg, "the worker process died while running this "
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
