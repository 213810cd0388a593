"""Benchmark runner of ``grip bench``: every method on the same test segments, GRIP's metrics.

Protocol (GRIP; BASELINES_AND_METRICS 4.1): the recordings of a dataset split are cut into
consecutive ``segment_frames``-frame segments (500 by default; shorter tails are left out), every
method reconstructs every segment starting from the ground truth at its first frame (or from the
standing calibration pose, ``MethodOptions.init == "standing"``: ``grip bench --init``), the metrics
of :mod:`grip.core.metrics` are computed per segment (:mod:`grip.eval.scoring`) and averaged over
the segments. The pieces are shared with ``grip kin eval`` and ``grip policy eval``: segments
(:mod:`grip.eval.segments`), running (:mod:`grip.eval.runner`), aggregation and tables
(:mod:`grip.eval.report`), plots (:mod:`grip.eval.plots`); this module writes the output folder.

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
pace_1s_m         m      horizontal distance of the pelvis to the pelvis the method followed
                         (``Reconstruction.ref_root_pos``: GRIP's kinematic estimate, integrated
                         from its velocity) after the first second (frame ``fps - 1``); NaN for
                         methods that follow none (:func:`~grip.core.metrics.measure_pace`)
pace_5s_m         m      the same after the first 5 s (frame ``5 fps - 1``; NaN if shorter)
pace_end_m        m      the same at the last frame
drift_mps         m/s    least-squares slope of that distance over time (0: keeps pace)
root_gt_1s_m      m      horizontal distance of the pelvis to the truth's after the first second
root_gt_5s_m      m      the same after the first 5 s
root_gt_end_m     m      the same at the last frame
================  =====  ==========================================================================

``results.json`` also counts ``blowups``: simulation blow-ups over the segments (a method's
``Reconstruction.notes["blowups"]``; GRIP recovers each like a fall, so its frames are never
in the metrics; 0 for methods without a simulation); each segment's row carries its own; and
``lost``: GRIP's recoveries of a humanoid that stood but had lost the pelvis it follows
(``--lost-gap``; each also a fall in the success rate). Its
``init`` says where the method started (``"truth"`` or ``"standing"``), and its
``pace_by_category`` the pace keys per motion category (``{category: {key: mean, "segments":
n}}``).

Output folder (``OUT``)::

    segments/<label>/method.json        the method's name and options, and its model files'
                                        contents (SHA-256; checked on resume)
    inputs.json                         the recordings' contents (SHA-256; checked on resume)
    segments/<label>/<segment>.json     one finished segment (written atomically)
    recons/<label>/<segment>.npz        reconstructions (--save-recons; always the sample's)
    results.json, results.csv           {label: {metric: value}} (null / empty for NaN)
    segments.csv                        one row per method and segment
    table.md                            the GRIP Table 1 layout, runtime, failures, categories,
                                        pace and distance to the truth (overall, per category)
    per_joint.png, trajectory.png, grf.png

A *label* is the method name, with ``@<sensors>`` for a sensor configuration of a sweep
(``kinematics@imu4_press``). Finished segments are kept: running the same command again only
runs what is missing, and is refused when a model file or a recording has other contents than
the finished segments were computed from (:mod:`grip.eval.resume`). A segment whose method
raised is finished with ``"status": "error"`` (shown as a failure in the table; ``retry_failed``
runs it again). A worker process that dies (segfault, out of memory) is replaced; a segment that
kills its worker when run alone is recorded as an error.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

from grip.core.atomic import atomic_write_text
from grip.eval.methods import sensor_set
from grip.eval.plots import plot_per_joint, plot_sample
from grip.eval.report import (
    RESULT_KEYS,
    aggregate,
    category_means,
    category_table,
    cell,
    csv_text,
    jsonable,
    markdown_table,
    method_table,
    pace_category_table,
    pace_table,
    results_json,
)
from grip.eval.runner import MethodRun
from grip.eval.scoring import METRIC_KEYS
from grip.eval.segments import Segment

__all__ = ["write_outputs"]


def _sweep_table(summary: Mapping[str, Mapping], runs: Sequence[MethodRun]) -> str:
    head = ["method", "#IMU", "insoles", "MPJPE (mm)", "PA-MPJPE (mm)", "Succ. (%)"]
    body = []
    for run in runs:
        s, st = summary[run.label], sensor_set(run.options.sensors)
        body.append([run.name, str(st.n_imu), "yes" if st.insoles else "no",
                     *[cell(s[k], "{:.2f}") for k in ("MPJPE_mm", "PA_MPJPE_mm", "success_rate")]])
    return markdown_table(head, body, ["---", "---:", ":---:", "---:", "---:", "---:"])


def _start_text(runs: Sequence[MethodRun]) -> str:
    """Where the runs started, for ``table.md``."""
    inits = {r.options.init for r in runs}
    if inits == {"truth"}:
        return "from the ground truth at its first frame"
    if inits == {"standing"}:
        return ("from the standing pose at the foot IMUs' heading (no ground-truth pose read; "
                "the pelvis at the truth's frame-0 horizontal position)")  # fmt: skip
    return "from " + ", ".join(f"{r.label}: {r.options.init}" for r in runs)


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
    results = results_json(summary)
    for r in runs:  # where the method started (MethodOptions.init)
        results[r.label]["init"] = r.options.init
        results[r.label]["pace_by_category"] = jsonable(category_means(rows, r.label))
    atomic_write_text(out_dir / "results.json", json.dumps(results, indent=1) + "\n")
    atomic_write_text(out_dir / "results.csv",
                      csv_text([{"method": k, **v} for k, v in results.items()],
                               ["method", *RESULT_KEYS, "failed"]))  # fmt: skip
    seg_rows = [{**{k: r[k] for k in ("method", "segment", "category", "start", "stop",
                                      "status")},
                 "frames": r.get("frames"), "falls": r.get("falls"),
                 "blowups": r.get("blowups"), "lost": r.get("lost"), "error": r.get("error"),
                 **jsonable(r["metrics"])} for r in rows]  # fmt: skip
    seg_keys = ["method", "segment", "category", "start", "stop", "status", "frames", "falls",
                "blowups", "lost", *METRIC_KEYS, "error"]  # fmt: skip
    atomic_write_text(out_dir / "segments.csv", csv_text(seg_rows, seg_keys))
    n_frames = sorted({s.n_frames for s in segments})
    parts = [f"# {title}" if title else "# Benchmark",
             f"{len(segments)} segment(s) of {', '.join(map(str, n_frames))} frames, each started "
             f"{_start_text(runs)}; means over segments; n/a: the method "
             "has no such output (no forces, cannot fall).", "", method_table(summary), "",
             "ms/frame: wall time of one segment's reconstruction per frame, measured with "
             "the run's worker count (other processes share the cores).", "",
             "## MPJPE (mm) per category", "", category_table(rows, labels), "",
             "## Pace and distance to the truth", "",
             "Horizontal distance (m) of each method's pelvis to the pelvis it followed (pace; "
             "GRIP: the kinematic estimate's; n/a: the method follows none) and to the "
             "truth's, after the first 1 s and 5 s and at the last frame; drift: the "
             "least-squares slope of the pace distance over time (m/s).", "",
             pace_table(summary), "", "### Per category (means over segments)", "",
             pace_category_table(rows, labels)]  # fmt: skip
    blown = {label: s["blowups"] for label, s in summary.items() if s["blowups"]}
    if blown:
        parts[5:5] = ["Simulation blow-ups (each recovered like a fall, its frames replaced): "
                      + ", ".join(f"{k} {v}" for k, v in blown.items()), ""]  # fmt: skip
    lost = {label: s["lost"] for label, s in summary.items() if s.get("lost")}
    if lost:
        parts[5:5] = ["Lost (recovered standing, farther than --lost-gap from the pelvis "
                      "followed; each a fall in Succ.): "
                      + ", ".join(f"{k} {v}" for k, v in lost.items()), ""]  # fmt: skip
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
