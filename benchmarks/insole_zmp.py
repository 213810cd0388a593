"""Share of synthesised frames whose ZMP the insole cells cannot follow, per source, and why.

Samples ``--per-source N`` clips of every source of the shared motions (seeded), retargets each
onto the body ``grip data build`` gives its first variant, synthesises the clean insoles and
counts the frames whose cells' force centroid lies more than 1 cm and more than
``ZMP_OUTSIDE_M`` (3 cm, what the manifest counts) from the ZMP. The outside frames are split

- by phase: low force (``F_z`` < 0.2 body weights: flight, take-off, landing), no foot supported,
  single support, double support (a foot is supported when its cells' mean support weight,
  :func:`~prism_tools.synth.insole.cell_support_weights`, exceeds 0.2);
- by where the ZMP lies: under the cells of the two feet (within 1 cm of the hull of all 32 cells:
  the contact detection left those cells unloaded), inside the outline of a foot near the floor
  but outside its cells, 1-5 cm, 5-15 cm or more than 15 cm off the hull of all cells (the
  motion's own dynamics put the ZMP off the feet).

It also checks that the cells carry the whole vertical force wherever a foot can take load.

Usage::

    .venv/bin/python benchmarks/insole_zmp.py [--per-source 5] [--seed 0] [--json out.json]
        [--motions DIR] [--set smoothing_window_s=0.1 ...]

``--set`` overrides :class:`~prism_tools.synth.config.InsoleSynthConfig` fields (the "before"
of docs/insoles_zmp.md is ``--set smoothing_window_s=0.1``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import random
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from grip.core.body import GRAVITY
from grip.dataset.build import BuildConfig, subject_for
from grip.motion.catalog import find_clips, load_clip
from grip.motion.retarget import retarget
from prism_tools.chunking import group_source
from prism_tools.synth.config import InsoleSynthConfig
from prism_tools.synth.insole import synthesize_insoles
from prism_tools.synth.recording import ZMP_OUTSIDE_M

DEFAULT_ROOT = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "motions"
LOW_FORCE_BW = 0.2
FOOT_SUPPORTED = 0.2
WHERE = ("under the cells", "in a foot outline", "1-5 cm off", "5-15 cm off", ">15 cm off")
PHASES = ("low force", "no foot", "single", "double")


def _hull_distance(points: np.ndarray, q: np.ndarray) -> float:
    """Distance of ``q (2,)`` outside the convex hull of ``points (N, 2)`` (<= 0 inside), m."""
    try:
        hull = ConvexHull(points)
    except (QhullError, ValueError):
        return float(np.linalg.norm(points - q, axis=1).min())
    inside = hull.equations[:, :2] @ q + hull.equations[:, 2]
    if inside.max() <= 0:
        return float(inside.max())
    v = points[hull.vertices]
    a, b = v, np.roll(v, -1, axis=0)
    ab = b - a
    t = np.clip(np.sum((q - a) * ab, axis=1) / np.sum(ab * ab, axis=1), 0.0, 1.0)
    return float(np.linalg.norm(q - (a + t[:, None] * ab), axis=1).min())


def clip_stats(motion, cfg: InsoleSynthConfig) -> dict:
    """Counts of one motion (see the module docstring)."""
    body = motion.body_model()
    g, p = motion.fk(body)
    s = synthesize_insoles(g, p, body, motion.fps, cfg)
    err = s.zmp_error_m
    fz_bw = s.wrench.force_world[:, 2] / (body.total_mass * GRAVITY)
    supported = s.support.mean(axis=-1) > FOOT_SUPPORTED  # (T, 2)
    phase = np.where(fz_bw < LOW_FORCE_BW, 0, 1 + supported.sum(axis=1))
    # ZMP in each foot's insole frame, in foot lengths / widths (outline: |u|, |v| <= 0.5).
    fwd = np.einsum("tfij,fj->tfi", g[:, [7, 8]], body.insole_axes[:, 0])[..., :2]
    med = np.einsum("tfij,fj->tfi", g[:, [7, 8]], body.insole_axes[:, 1])[..., :2]
    rel = s.wrench.zmp_world[:, None] - s.origin_world[..., :2]
    u = np.sum(rel * fwd, axis=-1) / body.foot_length
    v = np.sum(rel * med, axis=-1) / body.foot_width
    near = s.cell_pos_world[..., 2].min(axis=-1) < s.contact_level_m[:, None] + 0.03
    in_outline = ((np.abs(u) <= 0.5) & (np.abs(v) <= 0.5) & near).any(axis=1)
    cells = s.cell_pos_world[..., :2].reshape(len(err), -1, 2)
    out = {"frames": len(err), "outside_1cm": int(np.sum(err > 0.01)),
           "outside": int(np.sum(err > ZMP_OUTSIDE_M))}  # fmt: skip
    for k, name in enumerate(PHASES):
        out[f"phase_frames/{name}"] = int(np.sum(phase == k))
        out[f"phase_outside/{name}"] = int(np.sum((phase == k) & (err > ZMP_OUTSIDE_M)))
    where = dict.fromkeys(WHERE, 0)
    for t in np.flatnonzero((err > ZMP_OUTSIDE_M) & (phase > 0)):
        d = _hull_distance(cells[t], s.wrench.zmp_world[t])
        key = ("under the cells" if d <= 0.01 else "in a foot outline" if in_outline[t]
               else "1-5 cm off" if d <= 0.05 else "5-15 cm off" if d <= 0.15
               else ">15 cm off")  # fmt: skip
        where[key] += 1
    out.update({f"where/{k}": v for k, v in where.items()})
    # Every newton of F_z is carried by the cells unless no cell can take load.
    fz = np.maximum(s.wrench.force_world[:, 2], 0.0)
    carried = s.cell_force_n.sum(axis=(1, 2))
    loadable = s.unsupported_force_n == 0
    out["max_fz_mismatch_n"] = float(np.max(np.abs(carried - fz)[loadable], initial=0.0))
    out["unsupported_frames"] = int(np.sum(s.unsupported_force_n > 1.0))
    return out


def _parse_sets(items: list[str]) -> InsoleSynthConfig:
    fields = {f.name for f in dataclasses.fields(InsoleSynthConfig)}
    kwargs: dict[str, float] = {}
    for item in items:
        key, _, raw = item.partition("=")
        if key not in fields:
            raise SystemExit(f"--set: unknown InsoleSynthConfig field {key!r}")
        kwargs[key] = float(raw)
    return InsoleSynthConfig(**kwargs)  # type: ignore[arg-type]


def _sample(root: Path, per_source: int, seed: int) -> dict[str, list]:
    by_source: dict[str, list] = defaultdict(list)
    for ref in find_clips(root):
        by_source[group_source(ref.group or ref.clip_id) or ref.clip_id.split("/")[0]].append(ref)
    rng = random.Random(seed)
    return {src: rng.sample(refs, min(per_source, len(refs)))
            for src, refs in sorted(by_source.items())}  # fmt: skip


def _table(per_source: dict[str, dict]) -> str:
    lines = [f"| source | clips | frames | > 1 cm | > {100 * ZMP_OUTSIDE_M:.0f} cm | "
             + " | ".join(f"{p} (share / outside)" for p in PHASES) + " | "
             + " | ".join(WHERE) + " |",
             "|---|" + "---:|" * (4 + len(PHASES) + len(WHERE))]  # fmt: skip
    for src, a in per_source.items():
        n = max(a["frames"], 1)

        def pct(k: str, a: dict = a, n: int = n) -> str:
            return f"{100 * a[k] / n:.1f}"

        phases = [f"{100 * a[f'phase_frames/{p}'] / n:.1f} / "
                  f"{100 * a[f'phase_outside/{p}'] / max(a[f'phase_frames/{p}'], 1):.1f}"
                  for p in PHASES]  # fmt: skip
        lines.append(f"| {src} | {a['clips']} | {a['frames']} | {pct('outside_1cm')} % | "
                     f"{pct('outside')} % | " + " | ".join(phases) + " | "
                     + " | ".join(pct(f"where/{w}") for w in WHERE) + " |")  # fmt: skip
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--motions", type=Path, default=DEFAULT_ROOT, help="motion clip folder")
    ap.add_argument("--per-source", type=int, default=5, help="clips sampled per source")
    ap.add_argument("--seed", type=int, default=0, help="seed of the clip sample")
    ap.add_argument("--json", type=Path, default=None, help="write per-clip and per-source counts")
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="InsoleSynthConfig override (repeatable)")  # fmt: skip
    args = ap.parse_args()
    cfg = _parse_sets(args.set)
    t0 = time.perf_counter()
    clips, per_source = [], {}
    for src, refs in _sample(args.motions, args.per_source, args.seed).items():
        total: dict[str, float] = defaultdict(float)
        for ref in refs:
            try:
                motion = retarget(load_clip(ref), subject_for(ref.clip_id, 0, BuildConfig()))
                row = clip_stats(motion, cfg)
            except Exception as e:  # one bad clip is reported, the run goes on
                print(f"{ref.clip_id}: {type(e).__name__}: {e}", file=sys.stderr)
                continue
            clips.append({"clip_id": ref.clip_id, "source": src, "category": ref.category, **row})
            for k, v in row.items():
                total[k] = max(total[k], v) if k == "max_fz_mismatch_n" else total[k] + v
            total["clips"] += 1
        per_source[src] = {k: (float(v) if k == "max_fz_mismatch_n" else int(v))
                           for k, v in total.items()}  # fmt: skip
    print(
        f"ZMP error = distance from the cells' force centroid to the ZMP; outside > "
        f"{100 * ZMP_OUTSIDE_M:.0f} cm unless stated; phases: share of frames / share of them "
        f"outside; where: share of all frames (overrides: {' '.join(args.set) or 'none'})\n"
    )
    print(_table(per_source))
    worst = max((a["max_fz_mismatch_n"] for a in per_source.values()), default=0.0)
    print(
        f"\nlargest |sum of cell forces - F_z| where a foot can take load: {worst:.2e} N; "
        f"{time.perf_counter() - t0:.0f} s"
    )
    if args.json:
        report = {"config": dataclasses.asdict(cfg), "threshold_m": ZMP_OUTSIDE_M,
                  "seed": args.seed, "per_source": per_source, "clips": clips}  # fmt: skip
        args.json.write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
