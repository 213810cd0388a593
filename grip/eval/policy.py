"""Evaluation of a DynamicsNet policy on recordings (``grip eval-policy``).

Each segment is one episode: the simulation starts from the ground truth at the segment's first
frame (the GRIP protocol) and the policy follows the KinematicsNet estimate, without early
termination and without fall recovery. The fall detector of GRIP (pelvis below 0.30 m and the
discriminator's probability below 0.7, BASELINES_AND_METRICS 5.4) ends a segment as a failure;
metrics cover the frames simulated until then.

Metric keys follow ``grip bench``: ``MPJPE_mm`` (world, simulated vs ground truth),
``PA_MPJPE_mm``, ``FS_mps`` (foot sliding of the simulated feet over the frames the insole
reports contact), ``FP_mm`` (sole penetration below the floor), ``vGRF_N`` (simulated touch-
sensor force per foot vs the insole's), ``success_rate`` (%), and ``kin_MPJPE_mm``: the
kinematics-only MPJPE (KinematicsNet pose on the integrated root) over the same frames.
"""

from __future__ import annotations

import csv
import dataclasses
import io
from collections.abc import Callable
from pathlib import Path

import numpy as np

from envs.tracking_env import GripTrackingEnv
from grip.core import metrics as M
from grip.core import skeleton as sk
from grip.core.reference import ReferenceSet
from grip.eval.bench import (
    foot_penetration_mm,
    foot_sliding_mps,
    gt_foot_contacts,
    insole_vertical_force_n,
    vgrf_error_n,
)
from grip.sim.model import insole_forces

FALL_HEIGHT_M = 0.30
FALL_PROBABILITY = 0.7

METRIC_KEYS: tuple[str, ...] = (
    "MPJPE_mm", "PA_MPJPE_mm", "FS_mps", "FP_mm", "vGRF_N", "success_rate", "kin_MPJPE_mm",
)  # fmt: skip


@dataclasses.dataclass
class Episode:
    """What one segment's episode produced (arrays over the simulated frames)."""

    pos: np.ndarray  # (T, 24, 3) simulated joint positions, world
    rot: np.ndarray  # (T, 24, 3, 3)
    grf: np.ndarray  # (T, 2) vertical force per foot, N
    fell_at: int  # frame of the fall, -1 if none


def run_episode(env: GripTrackingEnv, runner, clip_index: int) -> Episode:
    """Play one clip from its first frame with the policy; stop at a detected fall."""
    obs, info = env.reset(options={"clip": clip_index, "start": 0})
    ix = env._sim.index
    n = env.clip.n_frames
    pos = np.empty((n, sk.N_JOINTS, 3))
    rot = np.empty((n, sk.N_JOINTS, 3, 3))
    grf = np.empty((n, 2))
    has_touch = ix.touch_adr.size > 0

    def record(t: int) -> None:
        d = env.data
        pos[t] = d.xpos[ix.body_ids]
        rot[t] = d.xmat[ix.body_ids].reshape(-1, 3, 3)
        grf[t] = insole_forces(d, ix).sum(axis=1) if has_touch else np.nan

    record(0)
    fell_at = -1
    t = 0
    while True:
        obs, _, terminated, truncated, info = env.step(runner.act(obs))
        t = info["frame"]
        if info.get("sim_unstable"):
            fell_at = t
            break
        record(t)
        if info["root_height_m"] < FALL_HEIGHT_M and (
            runner.disc is None or runner.fall_probability(info["amp_obs"])[0] < FALL_PROBABILITY
        ):
            fell_at = t
            break
        if terminated or truncated:
            break
    end = t + 1 if fell_at < 0 else max(fell_at, 1)
    return Episode(pos[:end], rot[:end], grf[:end], fell_at)


def segment_metrics(ep: Episode, clip, rec) -> dict[str, float]:
    """Metrics of one episode against its recording (see the module docstring)."""
    t = len(ep.pos)
    gt = clip.gt_pos[:t]
    kin = clip.est_pos[:t] + clip.est_root_pos[:t, None]
    out = {
        "MPJPE_mm": float(M.mpjpe(ep.pos, gt)),
        "PA_MPJPE_mm": float(M.pa_mpjpe(ep.pos - ep.pos[:, :1], gt - gt[:, :1])),
        "kin_MPJPE_mm": float(M.mpjpe(kin, gt)),
        "fell": ep.fell_at >= 0,
        "frames": t,
    }
    out["FS_mps"] = foot_sliding_mps(ep.pos, gt_foot_contacts(rec, gt, clip.fps), clip.fps)
    out["FP_mm"] = foot_penetration_mm(ep.rot, ep.pos, clip.body)
    out["vGRF_N"] = vgrf_error_n(ep.grf, insole_vertical_force_n(rec, clip.body.mass_kg, t))
    return out


def evaluate_policy(runner, estimator, recs: list, batch: int = 16,
                    progress: Callable[[int], object] | None = None) -> list[dict]:  # fmt: skip
    """One row of metrics per recording (segment), with ``name`` and ``category``."""
    from grip.kinematics.reference import build_reference_set

    ref: ReferenceSet = build_reference_set(recs, estimator, batch=batch)
    cfg = dataclasses.replace(runner.env_cfg, random_start=False, termination_dist_m=0.0,
                              fall_height_m=0.0, max_episode_frames=0, clip_index=-1)  # fmt: skip
    env = GripTrackingEnv(cfg, ref)
    rows = []
    try:
        for i, rec in enumerate(recs):
            ep = run_episode(env, runner, i)
            rows.append({"name": rec.name, "category": rec.category or "unknown",
                         **segment_metrics(ep, ref.clip(i), rec)})  # fmt: skip
            if progress is not None:
                progress(1)
    finally:
        env.close()
    return rows


def _summary(rows: list[dict]) -> dict[str, float]:
    frames = np.array([r["frames"] for r in rows], dtype=float)
    out: dict[str, float] = {}
    for k in ("MPJPE_mm", "PA_MPJPE_mm", "FS_mps", "FP_mm", "vGRF_N", "kin_MPJPE_mm"):
        v = np.array([r[k] for r in rows], dtype=float)
        ok = np.isfinite(v)
        out[k] = float(np.average(v[ok], weights=frames[ok])) if ok.any() else float("nan")
    out["success_rate"] = M.success_rate([r["fell"] for r in rows])
    out["segments"] = len(rows)
    out["frames"] = int(frames.sum())
    return out


def summarize_rows(rows: list[dict]) -> dict:
    """Frame-weighted means overall and per category (success rate per segment)."""
    if not rows:
        raise ValueError("no segments were evaluated")
    cats = sorted({r["category"] for r in rows})
    return {
        "overall": _summary(rows),
        "categories": {c: _summary([r for r in rows if r["category"] == c]) for c in cats},
    }


def markdown_table(summary: dict) -> str:
    cols = ("success_rate", "MPJPE_mm", "kin_MPJPE_mm", "PA_MPJPE_mm", "FS_mps", "FP_mm",
            "vGRF_N", "segments")  # fmt: skip
    head = ("| category | success % | MPJPE mm | kinematics-only MPJPE mm | PA-MPJPE mm | FS m/s "
            "| FP mm | vGRF N | segments |")  # fmt: skip
    lines = [head, "|" + "---|" * (len(cols) + 1)]
    items = [*summary["categories"].items(), ("**all**", summary["overall"])]
    for name, s in items:
        cells = []
        for c in cols:
            v = s[c]
            cells.append(f"{v:d}" if isinstance(v, int) else f"{v:.3f}" if c == "FS_mps"
                         else f"{v:.1f}")  # fmt: skip
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_rows(rows: list[dict], summary: dict, out_dir: str | Path) -> None:
    """``segments.csv`` (one row per segment) and ``summary.md``."""
    from grip.core.atomic import atomic_write_text

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    keys = ["name", "category", "fell", "frames", *[k for k in METRIC_KEYS if k != "success_rate"]]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=keys, extrasaction="ignore")
    w.writeheader()
    w.writerows(rows)
    atomic_write_text(out_dir / "segments.csv", buf.getvalue())
    atomic_write_text(out_dir / "summary.md", markdown_table(summary) + "\n")
