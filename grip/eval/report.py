"""The one aggregation and table writer of the evaluations (``grip bench``, ``grip kin eval``,
``grip policy eval``): rows of :mod:`grip.eval.runner` grouped per category and overall, means
(frame-weighted or per segment), success rates and their spread over replays, Markdown tables,
CSV and JSON.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from grip.core import metrics as M
from grip.eval.scoring import METRIC_KEYS, PACE_METRIC_KEYS

__all__ = [
    "RESULT_KEYS",
    "aggregate",
    "category_means",
    "category_summary",
    "category_table",
    "cell",
    "csv_text",
    "jsonable",
    "markdown_table",
    "method_table",
    "nan_floats",
    "pace_category_table",
    "pace_table",
    "replay_spread",
    "results_json",
    "weighted_means",
]

RESULT_KEYS: tuple[str, ...] = (*METRIC_KEYS, "segments", "blowups", "lost")
"""Keys of each method's entry in ``results.json`` (plus ``failed``: segments that raised)."""
_TABLE_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("MPJPE_mm", "MPJPE (mm)", "{:.2f}"), ("PEL_MPJPE_mm", "PEL-MPJPE (mm)", "{:.2f}"),
    ("PA_MPJPE_mm", "PA-MPJPE (mm)", "{:.2f}"), ("MPJRE_deg", "MPJRE (deg)", "{:.2f}"),
    ("Acc_mps2", "Acc (m/s²)", "{:.2f}"), ("FS_mps", "FS (m/s)", "{:.2f}"),
    ("FP_mm", "FP (mm)", "{:.2f}"), ("vGRF_N", "vGRF (N)", "{:.2f}"),
    ("success_rate", "Succ. (%)", "{:.2f}"), ("ms_per_frame", "ms/frame", "{:.3g}"),
)  # fmt: skip
_PACE_COLUMNS: tuple[tuple[str, str], ...] = (
    ("pace_1s_m", "pace 1 s (m)"), ("pace_5s_m", "pace 5 s (m)"), ("pace_end_m", "pace end (m)"),
    ("drift_mps", "drift (m/s)"), ("root_gt_1s_m", "to truth 1 s (m)"),
    ("root_gt_5s_m", "to truth 5 s (m)"), ("root_gt_end_m", "to truth end (m)"),
)  # fmt: skip


# ------------------------------------------------------------------------------- values
def jsonable(x):
    """``x`` with numpy values as Python ones and non-finite floats as ``None``."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, np.generic):
        return jsonable(x.item())
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if x is None or isinstance(x, bool | int | str):
        return x
    return str(x)


def nan_floats(d: Mapping) -> dict:
    """``d`` with ``None`` values (:func:`jsonable`'s NaN) as NaN again."""
    return {k: (float("nan") if v is None else v) for k, v in d.items()}


# ---------------------------------------------------------------------------- aggregation
def weighted_means(rows: Sequence[Mapping], keys: Sequence[str], weight: str = "frames",
                   skip_nan: bool = True) -> dict[str, float]:  # fmt: skip
    """Means of ``keys`` over rows, weighted by each row's ``weight`` (frames: the per-frame
    mean). With ``skip_nan`` a row whose value is not finite is left out of that key's mean (NaN
    when none is left); without, a NaN makes the mean NaN."""
    w = np.array([r[weight] for r in rows], dtype=np.float64)
    out: dict[str, float] = {}
    for k in keys:
        if not skip_nan:
            out[k] = float(np.average([r[k] for r in rows], weights=w))
            continue
        v = np.array([r[k] for r in rows], dtype=float)
        ok = np.isfinite(v)
        out[k] = float(np.average(v[ok], weights=w[ok])) if ok.any() else float("nan")
    return out


def category_summary(rows: Sequence[Mapping], summarize: Callable[[list], dict],
                     key: str = "category") -> dict:  # fmt: skip
    """``{"overall": summarize(rows), "categories": {category: summarize(its rows)}}``, the
    categories sorted (rows grouped by another of their keys with ``key``, e.g. ``"source"``)."""
    cats: dict[str, list] = {}
    for r in rows:
        cats.setdefault(r[key], []).append(r)
    return {"overall": summarize(list(rows)),
            "categories": {c: summarize(v) for c, v in sorted(cats.items())}}  # fmt: skip


def replay_spread(passes: list[list[dict]]) -> dict[str, object]:
    """The success rate of each replay of the same segments (``passes``: one row list per
    replay, e.g. with other action-noise seeds), their mean and sample standard deviation (0
    for one replay), in percent."""
    rates = [M.success_rate([r["fell"] for r in rows]) for rows in passes]
    sd = float(np.std(rates, ddof=1)) if len(rates) > 1 else 0.0
    return {"success_rate_replays": rates, "success_rate_mean": float(np.mean(rates)),
            "success_rate_sd": sd}  # fmt: skip


def category_means(rows: Sequence[dict], label: str,
                   keys: Sequence[str] = PACE_METRIC_KEYS) -> dict[str, dict]:  # fmt: skip
    """``{category: {key: segment mean, "segments": n}}`` of method ``label``'s finished
    segments (means as :func:`aggregate`'s: NaN segments skipped, NaN if none), categories
    sorted; empty when the method finished none."""

    def means(group: list) -> dict:
        ok = [r["metrics"] for r in group if r["method"] == label and r["status"] == "ok"]
        s = M.summarize(ok) if ok else {}
        return {**{k: float(s.get(k, float("nan"))) for k in keys}, "segments": len(ok)}

    cats = category_summary(rows, means)["categories"]
    return {c: v for c, v in cats.items() if v["segments"]}


def aggregate(rows: Sequence[dict], labels: Sequence[str]) -> dict[str, dict]:
    """Per method label: segment means of :data:`~grip.eval.scoring.METRIC_KEYS`, ``segments``
    (finished without error), ``failed`` (segments whose method raised), and ``per_joint``
    ``{key: (24,)}``.

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
        res["lost"] = int(sum(r.get("lost") or 0 for r in ok))
        res["failed"] = len(mine) - len(ok)
        pj = M.summarize([r["per_joint"] for r in ok if r["per_joint"]]) if ok else {}
        res["per_joint"] = {k: np.asarray(v) for k, v in pj.items()}
        out[label] = res
    return out


# --------------------------------------------------------------------------------- tables
def cell(v, fmt: str, na: str = "n/a") -> str:
    """``fmt.format(v)``, or ``na`` for a missing or non-finite value."""
    return na if v is None or not np.isfinite(v) else fmt.format(v)


def markdown_table(head: Sequence[str], body: Sequence[Sequence[str]],
                   align: Sequence[str] | None = None) -> str:  # fmt: skip
    """A Markdown table. ``align``: one marker per column (default: the first ``---``, the
    others right-aligned ``---:``)."""
    align = align or ["---", *["---:"] * (len(head) - 1)]
    lines = ["| " + " | ".join(head) + " |", "|" + "".join(f"{a}|" for a in align)]
    lines += ["| " + " | ".join(r) + " |" for r in body]
    return "\n".join(lines)


def method_table(summary: Mapping[str, Mapping]) -> str:
    """The GRIP Table 1 columns, runtime (ms per frame), segments and failures, one row per
    method label (:func:`aggregate`); "n/a" where a method has no value (no forces, cannot
    fall)."""
    head = ["method", *[c[1] for c in _TABLE_COLUMNS], "segments", "failed"]
    body = [[label, *[cell(s[k], fmt) for k, _, fmt in _TABLE_COLUMNS], str(s["segments"]),
             str(s["failed"])] for label, s in summary.items()]  # fmt: skip
    return markdown_table(head, body)


def category_table(rows: Sequence[dict], labels: Sequence[str]) -> str:
    """MPJPE (mm) per category (rows) and method label (columns), means over segments."""

    def mpjpe(group: list) -> dict:
        return {label: [r["metrics"] for r in group if r["method"] == label
                        and r["status"] == "ok"] for label in labels}  # fmt: skip

    cats = category_summary(rows, mpjpe)["categories"]
    body = [[c, *[cell(M.summarize(m[label])["MPJPE_mm"], "{:.1f}") if m[label] else "n/a"
                  for label in labels]] for c, m in cats.items()]  # fmt: skip
    return markdown_table(["category", *labels], body)


def pace_table(summary: Mapping[str, Mapping]) -> str:
    """The pelvis' horizontal distance to the pelvis each method followed (``pace_*``,
    ``drift_mps``; n/a for methods that follow none) and to the truth (``root_gt_*``), one row
    per method label (:func:`aggregate`), m and m/s."""
    head = ["method", *[h for _, h in _PACE_COLUMNS], "segments"]
    body = [[label, *[cell(s[k], "{:.2f}") for k, _ in _PACE_COLUMNS], str(s["segments"])]
            for label, s in summary.items()]  # fmt: skip
    return markdown_table(head, body)


def pace_category_table(rows: Sequence[dict], labels: Sequence[str]) -> str:
    """Per category (rows): the pace at the last frame and the drift rate of each method label
    that follows a pelvis, and every label's distance to the truth at the last frame (columns),
    m and m/s, means over segments (the last frame: defined whatever the segment length; at
    5 s for ``grip bench``'s 500-frame segments at 100 Hz)."""
    per = {label: category_means(rows, label) for label in labels}
    pacing = [label for label in labels
              if any(np.isfinite(m["drift_mps"]) for m in per[label].values())]  # fmt: skip
    cols = [(label, "pace_end_m", f"{label} pace end (m)") for label in pacing]
    cols += [(label, "drift_mps", f"{label} drift (m/s)") for label in pacing]
    cols += [(label, "root_gt_end_m", f"{label} to truth end (m)") for label in labels]
    cats = sorted({c for m in per.values() for c in m})
    body = [[c, *[cell(per[label][c][k], "{:.2f}") if c in per[label] else "n/a"
                  for label, k, _ in cols]] for c in cats]  # fmt: skip
    return markdown_table(["category", *[h for _, _, h in cols]], body)


def results_json(summary: Mapping[str, Mapping]) -> dict:
    """``results.json`` of :func:`aggregate`: :data:`RESULT_KEYS` and ``failed`` per label."""
    return {label: jsonable({k: s[k] for k in (*RESULT_KEYS, "failed")})
            for label, s in summary.items()}  # fmt: skip


def csv_text(rows: Sequence[Mapping], keys: Sequence[str], lineterminator: str = "\n") -> str:
    """CSV of ``rows`` with the columns ``keys`` (other keys ignored; missing and ``None``
    values as empty cells)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(keys), extrasaction="ignore",
                       lineterminator=lineterminator)  # fmt: skip
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()
