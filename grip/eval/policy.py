"""Evaluation of a DynamicsNet policy on recordings (``grip policy eval``).

Each segment is one episode: the simulation starts from the ground truth at the segment's first
frame (the GRIP protocol; ``init="standing"``: KinematicsNet and the humanoid start from the
standing calibration pose instead, :func:`grip.kinematics.features.standing_calibration`, as a
user without motion capture must) and the policy follows the KinematicsNet estimate, without
early termination and without fall recovery. The fall detector of GRIP (pelvis below 0.30 m and the
discriminator's probability below 0.7, BASELINES_AND_METRICS 5.4) ends a segment as a failure;
metrics cover the frames simulated until then.

The episode is :meth:`grip.pipeline.GripPipeline.play` with recovery off, stopped at the
first fall; ``play_batch`` episodes play side by side (:class:`grip.pipeline.BatchedPlayer`: one
controller forward per frame over the batch; the numbers of each episode played alone, up to
the float32 rounding of the batched forward). ``grip policy eval`` plays whole batches of
segments, in this process or in worker processes (:func:`evaluate_batches`: the same rows
whatever the number of workers). Metrics are ``grip bench``'s
(:func:`grip.eval.scoring.segment_metrics`: ``MPJPE_mm``, ``PEL_MPJPE_mm``, ``PA_MPJPE_mm``,
``MPJRE_deg``, ``Acc_mps2``, ``FS_mps``, ``FP_mm``, ``vGRF_N`` from MuJoCo's foot-ground
contact forces) plus ``kin_MPJPE_mm``: the kinematics-only MPJPE
(KinematicsNet pose on the integrated root) over the same frames, and where the world error comes
from: ``root_err_m`` / ``kin_root_err_m`` (mean horizontal pelvis distance from the truth,
:func:`grip.core.metrics.root_error_xy`) and ``travel_ratio`` / ``kin_travel_ratio`` (ground
covered over the truth's, :func:`grip.core.metrics.travel_ratio`) of the simulation and of
kinematics only. ``pelvis_min_m`` is each segment's lowest pelvis height, and
``success_rate_height`` the success rate by pelvis height alone (below 0.30 m at any frame is a
failure, whatever the discriminator says): a lenient discriminator cannot hide a fall, and
policies with different discriminators compare on one criterion.

Pace (issue 46; :func:`grip.core.metrics.measure_pace`): ``pace_1s_m``, ``pace_5s_m`` and
``pace_end_m`` are the horizontal distance of the humanoid's pelvis to the pelvis the policy
followed (the estimate's integrated pelvis, or the truth's with ``reference="truth"``, where the
episode started it: ``Reconstruction.ref_root_pos``) after the first second, after the first 5 s
(NaN for a segment that ended sooner, e.g. at a fall) and at its last frame, m; ``drift_mps`` the
least-squares slope of that distance over time, m/s; ``root_gt_*_m`` / ``kin_root_gt_*_m`` the
horizontal distance of the humanoid's / kinematics only's pelvis to the truth's at the same
times, m. These are means over segments (the others: over frames); ``segments_5s`` counts the
segments that reached 5 s.

``blowups``: simulation blow-ups (:meth:`grip.sim.humanoid.Humanoid.blown_up`), per segment
and summed in the summary. A blow-up ends its segment as a failure (``fell``) before the
blown-up frame: no frame of a blown-up state enters the metrics.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from grip.core import metrics as M
from grip.core.runs import CallPool
from grip.eval.pool import WorkerPool, one_torch_thread
from grip.eval.report import category_summary, csv_text, weighted_means
from grip.eval.report import markdown_table as table
from grip.eval.runner import segment_keys
from grip.eval.scoring import segment_metrics as bench_metrics
from grip.eval.segments import BenchError, Segment, SegmentReader
from grip.kinematics.features import INITS, ground_truth
from grip.pipeline import (
    Episode,
    GripPipeline,
    PaceKeeper,
    RecoveryConfig,
    start_from_calibration,
    start_from_clip,
)

if TYPE_CHECKING:
    from grip.kinematics.inference import KinematicsEstimator
    from policies.controller import Controller

METRIC_KEYS: tuple[str, ...] = (
    "MPJPE_mm", "PA_MPJPE_mm", "FS_mps", "FP_mm", "vGRF_N", "success_rate", "kin_MPJPE_mm",
    "root_err_m", "kin_root_err_m", "travel_ratio", "kin_travel_ratio",
)  # fmt: skip
_MEAN_KEYS = tuple(k for k in METRIC_KEYS if k != "success_rate")
_KIN_ROOT_GT_KEYS = tuple(f"kin_{k}" for k in M.ROOT_GT_KEYS)
PACE_KEYS: tuple[str, ...] = (*M.PACE_KEYS, *M.ROOT_GT_KEYS, *_KIN_ROOT_GT_KEYS)
"""Each row's pace keys (module docstring), averaged over segments in the summary."""


def segment_row(recon, clip, rec) -> dict:
    """Metrics of one episode (a :class:`~grip.core.reconstruction.Reconstruction` that may
    end at a fall) against its recording, with the kinematics-only MPJPE on the same frames
    (``clip``: what the policy followed, a reference clip or a
    :class:`~grip.core.reference.Estimate`)."""
    t = recon.n_frames
    gt = ground_truth(rec).head(t)
    row, _ = bench_metrics(recon, gt, can_fall=True)
    kin = clip.est_pos[:t] - clip.est_pos[:t, :1] + clip.est_root_pos[:t, None]
    row["kin_MPJPE_mm"] = float(M.mpjpe(kin, gt.joint_pos))
    # where the world error comes from: the pelvis' horizontal distance from the truth, and the
    # ground covered (1 s samples) over the truth's, for the simulation and kinematics only
    kin_root = clip.est_root_pos[:t]
    row["root_err_m"] = M.root_error_xy(recon.root_pos, gt.root_pos)
    row["kin_root_err_m"] = M.root_error_xy(kin_root, gt.root_pos)
    row["travel_ratio"] = M.travel_ratio(recon.root_pos, gt.root_pos, clip.fps)
    row["kin_travel_ratio"] = M.travel_ratio(kin_root, gt.root_pos, clip.fps)
    # (the humanoid's pace keys come with bench_metrics, from recon.ref_root_pos)
    kin_gap = M.horizontal_gap(kin_root, gt.root_pos, clip.fps).root_gt_metrics()
    row.update({f"kin_{k}": v for k, v in kin_gap.items()})
    row["fell"] = recon.fell
    row["pelvis_min_m"] = float(recon.root_pos[:, 2].min())
    row["frames"] = t
    row["blowups"] = int(recon.notes.get("blowups", 0))
    return row


REFERENCES: tuple[str, ...] = ("estimate", "truth")


def evaluate_policy(runner: Controller, estimator, recs: list, batch: int = 16,
                    progress: Callable[[int], object] | None = None,
                    reference: str = "estimate", play_batch: int = 1,
                    threads: int = 0, init: str = "truth",
                    pace: PaceKeeper = PaceKeeper()) -> list[dict]:  # fmt: skip
    """One row of metrics per recording (segment), with ``name`` and ``category``.

    ``reference``: what the controller follows: ``"estimate"`` (KinematicsNet's, the method) or
    ``"truth"`` (the ground-truth motion, a perfect KinematicsNet: separates the controller's
    own failures from those the estimate causes; ``kin_MPJPE_mm`` is then ~0). ``init``: where
    the episodes start (:data:`grip.kinematics.features.INITS`): ``"truth"``, the ground truth
    of the first frame (KinematicsNet's LSTMs, its integrated root and the humanoid), or
    ``"standing"``, the standing calibration pose
    (:func:`grip.kinematics.features.standing_calibration`; with ``reference="truth"`` the
    humanoid still starts standing). ``batch``: recordings per KinematicsNet forward pass;
    ``progress``: called after each episode; ``play_batch``: episodes played side by side
    (:meth:`grip.pipeline.GripPipeline.play_many`; 1: one after another), their humanoids
    stepped by ``threads`` threads (0: the usable cores); ``pace``: the players' pace keeper
    (:class:`grip.player.PaceKeeper`). An episode that raises raises here.
    """
    pipe = _pipeline(runner, estimator, reference, init, pace)
    chunks = [([{}] * len(recs), recs, _estimates(estimator, recs, batch, reference, init))]
    return _play_rows(pipe, chunks, len(recs), play_batch, threads, progress, init)


def evaluate_segments(runner: Controller, estimator, segments: Sequence[Segment],
                      batch: int = 16, progress: Callable[[int], object] | None = None,
                      reference: str = "estimate", play_batch: int = 1,
                      threads: int = 0, init: str = "truth",
                      pace: PaceKeeper = PaceKeeper()) -> list[dict]:  # fmt: skip
    """:func:`evaluate_policy` on :mod:`grip.eval.segments` (read and estimated ``batch`` at a
    time, when the player needs the next): one row per segment, in order, starting with its
    segment keys (:func:`grip.eval.runner.segment_keys`)."""
    pipe = _pipeline(runner, estimator, reference, init, pace)

    def chunks() -> Iterator[tuple[list[dict], list, list]]:
        read = SegmentReader()
        for i in range(0, len(segments), batch):
            part = list(segments[i : i + batch])
            recs = [read(s) for s in part]
            heads = [segment_keys(seg, rec) for seg, rec in zip(part, recs, strict=True)]
            yield heads, recs, _estimates(estimator, recs, batch, reference, init)

    return _play_rows(pipe, chunks(), len(segments), play_batch, threads, progress, init)


@dataclass(frozen=True)
class PolicySetup:
    """What ``grip policy eval`` builds its controller and KinematicsNet from (files and
    options, so that a worker process builds its own: :meth:`build`).

    Attributes:
        policies: Policy files (several: their ensemble, :func:`policies.controller.
            load_controller`).
        kin: KinematicsNet checkpoint.
        tta: KinematicsNet's test-time augmentation (:data:`grip.kinematics.features.
            TTA_MODES`).
        mirror: Average each action with its mirror image's (with KinematicsNet's sensors).
    """

    policies: tuple[str, ...]
    kin: str
    tta: str = "none"
    mirror: bool = False

    def build(self) -> tuple[Controller, KinematicsEstimator]:
        """The controller and the KinematicsNet.

        Raises:
            ValueError, OSError: A file that is not what it should be.
        """
        from grip.kinematics.inference import KinematicsEstimator
        from policies.controller import load_controller

        est = KinematicsEstimator.from_checkpoint(self.kin, tta=self.tta)
        f = est.cfg.features
        runner = load_controller(list(self.policies),
                                 mirror=(f.sites, f.insoles) if self.mirror else None)  # fmt: skip
        return runner, est


def unit_seed(seed: int, unit: int) -> int:
    """The action-noise seed of batch ``unit`` of a pass seeded with ``seed``
    (:func:`evaluate_batches`): ``seed`` itself for the first batch, so a pass of one batch
    draws the noise it always did."""
    if unit == 0:
        return int(seed)
    return int(np.random.SeedSequence([int(seed), int(unit)]).generate_state(1)[0])


def _play_unit(runner: Controller, estimator, segments: Sequence[Segment], play_batch: int,
               reference: str, init: str, action_noise: float, seed: int, threads: int,
               progress: Callable[[int], object] | None = None,
               pace: PaceKeeper = PaceKeeper()) -> list[dict]:  # fmt: skip
    """One batch of :func:`evaluate_batches`: its own pipeline, its own noise generator."""
    runner.use_action_noise(action_noise, seed)
    return evaluate_segments(runner, estimator, segments, progress=progress, reference=reference,
                             play_batch=play_batch, threads=threads, init=init,
                             pace=pace)  # fmt: skip


_WORKER_MODELS: dict[PolicySetup, tuple] = {}
"""A worker process' controller and KinematicsNet (of the last setup it was given)."""


def _worker_unit(setup: PolicySetup, segments: Sequence[Segment], play_batch: int,
                 reference: str, init: str, action_noise: float, seed: int,
                 threads: int, pace: PaceKeeper) -> list[dict]:  # fmt: skip
    """:func:`_play_unit` in a worker process: the models are built on the first call (torch
    on one thread) and kept."""
    models = _WORKER_MODELS.get(setup)
    if models is None:
        import torch

        torch.set_num_threads(1)
        _WORKER_MODELS.clear()
        models = _WORKER_MODELS[setup] = setup.build()
    return _play_unit(*models, segments, play_batch, reference, init, action_noise, seed,
                      threads, pace=pace)  # fmt: skip


def evaluate_batches(
    setup: PolicySetup, segments: Sequence[Segment], play_batch: int = 16, workers: int = 1, *,
    reference: str = "estimate", init: str = "truth", action_noise: float = 0.0,
    seeds: Sequence[int] = (0,), progress: Callable[[int], object] | None = None,
    threads: int = 0, built: tuple[Controller, KinematicsEstimator] | None = None,
    pool: CallPool | None = None, pace: PaceKeeper = PaceKeeper(),
) -> list[list[dict]]:  # fmt: skip
    """``grip policy eval``: :func:`evaluate_segments` batch by batch, in ``workers`` processes.

    Segment ``i`` belongs to batch ``i // play_batch``; a batch is played whole, by one process
    (:func:`evaluate_segments` of its segments, ``play_batch`` side by side, a pipeline of its
    own, the action noise drawn from :func:`unit_seed`), with torch on one thread. So every
    batch meets the same controller forwards, and its rows are bit-identical, whatever
    ``workers`` is.

    Args:
        setup: What the controller and KinematicsNet are built from (in each worker).
        segments: What to play, in order.
        play_batch: Segments per batch, played side by side (1: one after another).
        workers: Processes (1: in this process, with ``built`` where given).
        reference, init: As :func:`evaluate_policy`.
        action_noise: The controller's action noise scale (0: the mean action).
        seeds: One pass over all segments per seed (``--repeats``; the action noise of batch
            ``j`` of a pass comes from ``unit_seed(seed, j)``).
        progress: Called with the number of segments finished (in a worker: per batch).
        threads: Threads stepping a batch's humanoids in each process (0: the usable cores
            shared out over the processes).
        built: ``(controller, KinematicsNet)`` of ``setup``, already built here.
        pace: The players' pace keeper (:class:`grip.player.PaceKeeper`).
        pool: Worker processes to use (kept by the caller across calls; ``workers`` is then
            ignored), or Ray tasks (:class:`grip.cluster.RayPool`, ``--ray``). None: a pool
            of ``workers`` for this call when there is more than one batch to play.

    Returns:
        One list of rows per seed, each in segment order (:func:`evaluate_segments`).

    Raises:
        The exception a segment raised (as :func:`evaluate_segments`). BenchError: a worker
        process died.
    """
    from grip.pipeline import usable_cores

    if play_batch < 1:
        raise ValueError(f"play_batch must be >= 1, got {play_batch}")
    parts = [list(segments[i : i + play_batch]) for i in range(0, len(segments), play_batch)]
    units = [(p, j, part) for p in range(len(seeds)) for j, part in enumerate(parts)]
    got: dict[tuple[int, int], list[dict]] = {}
    if pool is None and (workers <= 1 or len(units) <= 1):
        runner, est = built if built is not None else setup.build()
        with one_torch_thread():
            for p, j, part in units:
                got[p, j] = _play_unit(runner, est, part, play_batch, reference, init,
                                       action_noise, unit_seed(seeds[p], j), threads,
                                       progress, pace)  # fmt: skip
    else:
        n = pool.workers if pool is not None else min(workers, len(units))
        per = threads if threads > 0 else max(1, usable_cores() // n)
        calls = [(_worker_unit, (setup, part, play_batch, reference, init, action_noise,
                                 unit_seed(seeds[p], j), per, pace))
                 for p, j, part in units]  # fmt: skip

        def done(k: int, rows) -> None:
            if isinstance(rows, BaseException):
                raise rows  # (its worker's traceback is its cause)
            p, j, part = units[k]
            got[p, j] = rows
            if progress is not None:
                progress(len(part))

        if pool is not None:
            lost = pool.run(calls, done)
        else:
            with WorkerPool(n) as own:
                lost = own.run(calls, done)
        if lost:
            first = [units[k][2][0].id for k in lost]
            raise BenchError(
                f"a worker process died (a crash or out of memory) while playing one of the "
                f"{len(lost)} batch(es) not finished (starting at segment "
                f"{', '.join(first[:4])}{', ...' if len(first) > 4 else ''}); run with "
                "--workers 1 to see the error"
            )  # fmt: skip
    return [[r for j in range(len(parts)) for r in got[p, j]] for p in range(len(seeds))]


def _pipeline(runner: Controller, estimator, reference: str, init: str,
              pace: PaceKeeper = PaceKeeper()) -> GripPipeline:  # fmt: skip
    if reference not in REFERENCES:
        raise ValueError(f"reference must be one of {list(REFERENCES)}, got {reference!r}")
    if init not in INITS:
        raise ValueError(f"init must be one of {list(INITS)}, got {init!r}")
    return GripPipeline(runner, estimator, RecoveryConfig(enabled=False), pace)


def _estimates(estimator, recs: list, batch: int, reference: str, init: str) -> list:
    """What the controller follows on each recording: the ground truth as a reference clip
    (``reference="truth"``), KinematicsNet's estimate as a reference clip (``init="truth"``:
    its root integrated from the truth's) or as an :class:`~grip.core.reference.Estimate`
    started from the standing calibration (``init="standing"``: no ground-truth pose read)."""
    from grip.kinematics.reference import build_reference_set, oracle_reference_clip

    cfg = estimator.cfg.features
    if reference == "truth":
        return [oracle_reference_clip(r, cfg) for r in recs]
    if init == "truth":
        return list(build_reference_set(recs, estimator, batch=batch).clips)
    from grip.core.reference import Estimate
    from grip.core.rotations import matrix_to_6d
    from grip.kinematics.features import input_features

    out = []
    for i in range(0, len(recs), batch):
        part = list(recs[i : i + batch])
        for rec, e in zip(part, estimator.predict(part, init), strict=True):
            out.append(Estimate(rec.name, float(rec.fps), e.joint_pos, matrix_to_6d(e.global_rot),
                                e.velocity, input_features(rec, cfg), e.root_pos[0]))  # fmt: skip
    return out


def _episode(rec, est, init: str, cfg) -> Episode:
    """The evaluation episode of ``rec`` following ``est`` (:func:`_estimates`), started from
    ``est``'s first ground-truth frame (``init="truth"``) or the standing calibration."""
    if init == "truth":
        return Episode(est, start_from_clip(est), est.body, est.objects, stop_at_fall=True)
    from grip.kinematics.features import recording_body, recording_calibration

    body = recording_body(rec)
    start = start_from_calibration(recording_calibration(rec, cfg, init), body, float(rec.fps))
    objects = None
    if rec.objects:
        objects = {n: (np.asarray(o.vertices), np.asarray(o.faces)) for n, o in rec.objects.items()}
    return Episode(est, start, body, objects, stop_at_fall=True)


def _play_rows(pipe: GripPipeline, chunks: Iterable[tuple[list[dict], list, list]],
               n: int, play_batch: int, threads: int, progress: Callable[[int], object] | None,
               init: str = "truth") -> list[dict]:  # fmt: skip
    """Play the episodes of ``chunks`` (``(row heads, recordings, what the controller follows
    on each)``, taken as the player needs them) from the ground truth's first frame (or the
    standing calibration: ``init``) to the first fall; one row per recording, in order: its
    head, ``name``, ``category`` and :func:`segment_row`."""
    held: dict[int, tuple[dict, object, object]] = {}  # until the episode's row is made
    cfg = pipe.estimator.cfg.features

    def episodes() -> Iterator[Episode]:
        k = 0
        for heads, recs, ests in chunks:
            for head, rec, clip in zip(heads, recs, ests, strict=True):
                held[k] = (head, rec, clip)
                k += 1
                yield _episode(rec, clip, init, cfg)

    rows: list = [None] * n
    for i, recon, _ in pipe.play_many(episodes(), play_batch, threads):
        if isinstance(recon, Exception):
            raise recon
        head, rec, clip = held.pop(i)
        rows[i] = {**head, "name": rec.name, "category": rec.category or "unknown",
                   **segment_row(recon, clip, rec)}  # fmt: skip
        if progress is not None:
            progress(1)
    return rows


def _summary(rows: list[dict]) -> dict[str, float]:
    out: dict[str, float] = weighted_means(rows, _MEAN_KEYS)
    pace = M.summarize([{k: r[k] for k in PACE_KEYS} for r in rows])
    out.update({k: float(pace[k]) for k in PACE_KEYS})
    out["segments_5s"] = int(sum(bool(np.isfinite(r["pace_5s_m"])) for r in rows))
    out["success_rate"] = M.success_rate([r["fell"] for r in rows])
    low = RecoveryConfig().fall_height_m
    out["success_rate_height"] = M.success_rate([r["fell"] or r["pelvis_min_m"] < low
                                                 for r in rows])  # fmt: skip
    out["segments"] = len(rows)
    out["frames"] = int(sum(r["frames"] for r in rows))
    out["blowups"] = int(sum(r.get("blowups", 0) for r in rows))
    return out


def summarize_rows(rows: list[dict]) -> dict:
    """Frame-weighted means overall and per category (success rate per segment)."""
    if not rows:
        raise ValueError("no segments were evaluated")
    return category_summary(rows, _summary)


_TWO_DIGITS = ("root_err_m", "kin_root_err_m", "travel_ratio", "kin_travel_ratio")
_COLUMNS: tuple[tuple[str, str], ...] = (
    ("success_rate", "success %"), ("success_rate_height", "by height %"),
    ("MPJPE_mm", "MPJPE mm"), ("kin_MPJPE_mm", "kinematics-only MPJPE mm"),
    ("PA_MPJPE_mm", "PA-MPJPE mm"), ("FS_mps", "FS m/s"), ("FP_mm", "FP mm"),
    ("vGRF_N", "vGRF N"), ("root_err_m", "root err. m"), ("kin_root_err_m", "kin. root err. m"),
    ("travel_ratio", "travel"), ("kin_travel_ratio", "kin. travel"), ("segments", "segments"),
)  # fmt: skip


_PACE_COLUMNS: tuple[tuple[str, str], ...] = (
    ("pace_1s_m", "pace 1 s m"), ("pace_5s_m", "pace 5 s m"), ("pace_end_m", "pace end m"),
    ("drift_mps", "drift m/s"), ("root_gt_5s_m", "to truth 5 s m"),
    ("kin_root_gt_5s_m", "kin. to truth 5 s m"), ("root_gt_end_m", "to truth end m"),
    ("kin_root_gt_end_m", "kin. to truth end m"), ("segments_5s", "reached 5 s"),
    ("segments", "segments"),
)  # fmt: skip


def _fmt(key: str, v) -> str:
    if key in PACE_KEYS and not np.isfinite(v):
        return "n/a"
    return (f"{v:d}" if isinstance(v, int) else f"{v:.2f}" if key in _TWO_DIGITS + PACE_KEYS
            else f"{v:.3f}" if key == "FS_mps" else f"{v:.1f}")  # fmt: skip


def markdown_table(summary: dict) -> str:
    """The per-category tables (and the overall rows) of :func:`summarize_rows`: the metrics,
    then the pace (module docstring; n/a: no segment has the value)."""
    items = [*summary["categories"].items(), ("**all**", summary["overall"])]
    lines = []
    for cols in (_COLUMNS, _PACE_COLUMNS):
        body = [[name, *[_fmt(k, s[k]) for k, _ in cols]] for name, s in items]
        lines.append(table(["category", *[h for _, h in cols]], body, ["---"] * (len(cols) + 1)))
    lines[1:1] = ["\nPace: the pelvis' horizontal distance to the pelvis the policy followed, "
                  "its drift rate, and the distance of the humanoid's and kinematics only's "
                  "pelvis to the truth (means over segments):\n"]  # fmt: skip
    n = summary["overall"].get("blowups", 0)
    if n:
        lines.append(f"\n{n} simulation blow-up(s): each ended its segment as a failure "
                     "before the blown-up frame")  # fmt: skip
    return "\n".join(lines)


def write_rows(rows: list[dict], summary: dict, out_dir: str | Path) -> None:
    """``segments.csv`` (one row per segment) and ``summary.md``."""
    from grip.core.atomic import atomic_write_text

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    keys = ["name", "category", "fell", "pelvis_min_m", "frames", "blowups", *_MEAN_KEYS,
            *PACE_KEYS]  # fmt: skip
    if rows and "replay" in rows[0]:  # grip policy eval --repeats: which replay a row is of
        keys.insert(1, "replay")
    atomic_write_text(out_dir / "segments.csv", csv_text(rows, keys, lineterminator="\r\n"))
    atomic_write_text(out_dir / "summary.md", markdown_table(summary) + "\n")
