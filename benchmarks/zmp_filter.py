"""The dynamic filter (:mod:`grip.dataset.zmp_filter`) on a seeded sample of clips: ZMP shares
before and after, and what the correction costs.

Samples ``--per-source N`` clips of every source as ``benchmarks/insole_zmp.py`` does (same
seed, same clips), retargets each onto the body ``grip data build`` gives variant 0, runs the
filter and synthesises the clean insoles of the motion before and after. Per source it prints

- the share of frames whose ZMP lies more than 3 cm (``ZMP_OUTSIDE_M``) from the cells' force
  centroid, before and after, over all frames and over the frames where the feet alone carry
  the body (:func:`~grip.dataset.zmp_filter.feet_alone_frames` of the input motion);
- the shares outside in single and double support (phases as in insole_zmp.py);
- the pelvis shift |d| (median, 95th percentile, max; mm);
- the horizontal pelvis acceleration the shift adds and the pelvis' own (95th percentiles,
  m/s^2, differentiated as the IMU synthesis does: second differences 7 frames apart at 100 Hz);
- how far a supported foot's ankle moved (95th percentile and max over frames where that foot is
  down; mm): the foot sliding the correction causes where the leg IK cannot reach.

Usage::

    .venv/bin/python benchmarks/zmp_filter.py [--per-source 5] [--seed 0] [--props]
        [--set smoothing_window_s=0.2] [--filter shift_weight=2 ...] [--json out.json]

``--props`` infers the props as ``grip data build`` does (a few CMU stair and stool clips), and
both the filter and the synthesis stand on them; without it the floor is flat, as in
insole_zmp.py. ``--set`` overrides :class:`~prism_tools.synth.config.InsoleSynthConfig` fields
(used by the filter and the synthesis alike), ``--filter`` :class:`~grip.dataset.zmp_filter.
ZmpFilterConfig` fields.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from insole_zmp import DEFAULT_ROOT, FOOT_SUPPORTED, LOW_FORCE_BW, _parse_sets, _sample

from grip.core.body import GRAVITY
from grip.dataset.build import BuildConfig, subject_for
from grip.dataset.zmp_filter import ZmpFilterConfig, inferred_ground, zmp_filter
from grip.motion.catalog import load_clip
from grip.motion.retarget import retarget
from prism_tools.synth.config import ImuSynthConfig
from prism_tools.synth.imu import second_difference
from prism_tools.synth.recording import ZMP_OUTSIDE_M


def _phase(synth, body) -> np.ndarray:
    """0 low force, 1 no foot, 2 single, 3 double (as insole_zmp.py)."""
    fz_bw = synth.wrench.force_world[:, 2] / (body.total_mass * GRAVITY)
    supported = synth.support.mean(axis=-1) > FOOT_SUPPORTED
    return np.where(fz_bw < LOW_FORCE_BW, 0, 1 + supported.sum(axis=1))


def clip_rows(motion, synth_cfg, filt_cfg, props: bool) -> tuple[dict, dict]:
    """Counts of one clip (sums) and its per-frame samples (for percentiles)."""
    body = motion.body_model()
    res = zmp_filter(motion, filt_cfg, synth_cfg, inferred_ground(motion) if props else None)
    before, after = res.synth_before, res.synth_after
    out_b = before.zmp_error_m > ZMP_OUTSIDE_M
    out_a = after.zmp_error_m > ZMP_OUTSIDE_M
    feet = res.feet_alone
    ph_b, ph_a = _phase(before, body), _phase(after, body)
    row = {
        "frames": len(out_b), "outside_before": int(out_b.sum()), "outside_after": int(out_a.sum()),
        "feet_alone": int(feet.sum()), "feet_outside_before": int((out_b & feet).sum()),
        "feet_outside_after": int((out_a & feet).sum()),
    }  # fmt: skip
    for k, name in ((2, "single"), (3, "double")):
        row[f"{name}_frames_before"] = int((ph_b == k).sum())
        row[f"{name}_outside_before"] = int(((ph_b == k) & out_b).sum())
        row[f"{name}_frames_after"] = int((ph_a == k).sum())
        row[f"{name}_outside_after"] = int(((ph_a == k) & out_a).sum())
    # Accelerations as the IMU synthesis differentiates (TransPose's spacing, 7 frames at 100 Hz).
    n = max(1, round(ImuSynthConfig().acc_smoothing_s * motion.fps))
    added = np.linalg.norm(second_difference(res.shift_m, motion.fps, n), axis=1)
    own = np.linalg.norm(second_difference(motion.root_pos[:, :2], motion.fps, n), axis=1)
    down = before.support.mean(axis=-1) > FOOT_SUPPORTED  # (T, 2)
    samples = {"shift": np.linalg.norm(res.shift_m, axis=1), "accel": added, "own_accel": own,
               "ankle": res.ankle_moved_m[down]}  # fmt: skip
    return row, samples


def _pct(a: np.ndarray, q: float) -> float:
    return float(np.percentile(a, q)) if a.size else 0.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--motions", type=Path, default=DEFAULT_ROOT, help="motion clip folder")
    ap.add_argument("--per-source", type=int, default=5, help="clips sampled per source")
    ap.add_argument("--seed", type=int, default=0, help="seed of the clip sample")
    ap.add_argument("--props", action="store_true", help="infer props as grip data build does")
    ap.add_argument("--json", type=Path, default=None, help="write per-clip and per-source counts")
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="InsoleSynthConfig override (repeatable)")  # fmt: skip
    ap.add_argument("--filter", action="append", default=[], metavar="FIELD=VALUE",
                    help="ZmpFilterConfig override (repeatable)")  # fmt: skip
    args = ap.parse_args()
    synth_cfg = _parse_sets(args.set)
    fields = {f.name: f.type for f in dataclasses.fields(ZmpFilterConfig)}
    kw: dict[str, float] = {}
    for item in args.filter:
        key, _, raw = item.partition("=")
        if key not in fields:
            raise SystemExit(f"--filter: unknown ZmpFilterConfig field {key!r}")
        kw[key] = int(raw) if "iterations" in key else float(raw)
    filt_cfg = ZmpFilterConfig(**kw)  # type: ignore[arg-type]
    t0 = time.perf_counter()
    clips, per_source = [], {}
    for src, refs in _sample(args.motions, args.per_source, args.seed).items():
        total: dict[str, float] = defaultdict(float)
        samples: dict[str, list] = defaultdict(list)
        for ref in refs:
            try:
                motion = retarget(load_clip(ref), subject_for(ref.clip_id, 0, BuildConfig()))
                row, smp = clip_rows(motion, synth_cfg, filt_cfg, args.props)
            except Exception as e:  # one bad clip is reported, the run goes on
                print(f"{ref.clip_id}: {type(e).__name__}: {e}", file=sys.stderr)
                continue
            row["shift_max_mm"] = 1e3 * float(smp["shift"].max(initial=0.0))
            clips.append({"clip_id": ref.clip_id, "source": src, **row})
            for k, v in row.items():
                total[k] += v
            total["clips"] += 1
            for k, v in smp.items():
                samples[k].append(v)
        agg = {k: int(v) for k, v in total.items() if k != "shift_max_mm"}
        cat = {k: np.concatenate(v) if v else np.zeros(0) for k, v in samples.items()}
        agg.update({
            "shift_median_mm": 1e3 * _pct(cat["shift"], 50),
            "shift_p95_mm": 1e3 * _pct(cat["shift"], 95),
            "shift_max_mm": 1e3 * float(cat["shift"].max(initial=0.0)),
            "accel_p95_m_s2": _pct(cat["accel"], 95),
            "own_accel_p95_m_s2": _pct(cat["own_accel"], 95),
            "ankle_p95_mm": 1e3 * _pct(cat["ankle"], 95),
            "ankle_max_mm": 1e3 * float(cat["ankle"].max(initial=0.0)),
        })  # fmt: skip
        per_source[src] = agg

    def sh(a: dict, num: str, den: str) -> str:
        return f"{100 * a.get(num, 0) / max(a.get(den, 0), 1):.1f}"

    print(
        f"ZMP > {100 * ZMP_OUTSIDE_M:.0f} cm outside, before -> after the filter "
        f"(synthesis: {' '.join(args.set) or 'defaults'}; filter: "
        f"{' '.join(args.filter) or 'defaults'}; props: {'on' if args.props else 'off'})\n"
    )
    print(
        "| source | clips | frames | all frames | feet alone (share of frames) | single | "
        "double | shift median / 95th / max (mm) | pelvis acc. 95th: added / own (m/s^2) | "
        "ankle moved 95th / max (mm) |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for src, a in per_source.items():
        print(
            f"| {src} | {a.get('clips', 0)} | {a.get('frames', 0)} | "
            f"{sh(a, 'outside_before', 'frames')} → {sh(a, 'outside_after', 'frames')} % | "
            f"{sh(a, 'feet_outside_before', 'feet_alone')} → "
            f"{sh(a, 'feet_outside_after', 'feet_alone')} % ({sh(a, 'feet_alone', 'frames')} %)"
            f" | {sh(a, 'single_outside_before', 'single_frames_before')} → "
            f"{sh(a, 'single_outside_after', 'single_frames_after')} % | "
            f"{sh(a, 'double_outside_before', 'double_frames_before')} → "
            f"{sh(a, 'double_outside_after', 'double_frames_after')} % | "
            f"{a['shift_median_mm']:.1f} / {a['shift_p95_mm']:.1f} / {a['shift_max_mm']:.1f} | "
            f"{a['accel_p95_m_s2']:.2f} / {a['own_accel_p95_m_s2']:.2f} | "
            f"{a['ankle_p95_mm']:.2f} / {a['ankle_max_mm']:.1f} |"
        )
    print(f"\n{time.perf_counter() - t0:.0f} s")
    if args.json:
        report = {"synth_config": dataclasses.asdict(synth_cfg),
                  "filter_config": dataclasses.asdict(filt_cfg), "props": args.props,
                  "threshold_m": ZMP_OUTSIDE_M, "seed": args.seed, "per_source": per_source,
                  "clips": clips}  # fmt: skip
        args.json.write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
