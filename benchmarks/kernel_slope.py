"""Do the imitation kernels still have slope where episodes fail? (issue 47, part 2)

Plays training-style episodes of an exported policy (random starts, deterministic actions, the
policy's action repeat, stage-1 termination at ``--termination-m`` and falls below
``--fall-height``) and, at the last frame of every episode that ended in a failure, reads each
kernel's value from ``info["reward/<term>"]`` and turns it back into the error it was computed
from (``r = exp(-k x)``: ``x = -ln(r) / k``). It reports, per kernel, the value and the
derivative with respect to its error at the median failure, and the share of failures where
the kernel is flat (slope under a tenth of its steepest); the same ``--before-s`` seconds before
each failure (in stage 2, where a fall ends the episode, the failing frame itself lies on the
floor) and over every decision. A kernel that is flat where episodes fail gives PPO no gradient
toward staying up in the frames before a failure.

Error measures (``env.reward.form = "mean_sq"``, the default): ``imit_pos`` the RMS joint
position error (m, with the pelvis moved over the reference's horizontally), ``imit_rot`` the
RMS joint angle error (rad), ``imit_vel`` the RMS joint velocity error (m/s), ``imit_angvel`` the
RMS angular velocity error (rad/s); ``r = exp(-k e^2)``, ``dr/de = -2 k e r``, steepest at
``e = 1 / sqrt(2 k)``. With ``"norm"``: ``r = exp(-k e)``, ``e`` the norm of the stacked
errors, ``dr/de = -k r``, steepest at 0.

    python benchmarks/kernel_slope.py --policy POLICY.pt --reference RUN/reference_train.npz \\
        [--truth] [--category 'walk*' ...] [--episodes 60] [--termination-m 0.25] [--json OUT]
    python benchmarks/kernel_slope.py --mpjpe-mm 50 100 150 250   # the kernels alone

``--truth`` follows each clip's ground truth (``ReferenceClip.oracle``: what a teacher,
``follow = "truth"``, was trained on; taken by default when the file says so).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import torch

from envs.tracking_env import GripTrackingEnv
from envs.wrappers import ActionRepeat
from grip.core.reference import ReferenceSet
from grip.core.reference_sets import load_reference, select_clips
from grip.task.config import RewardConfig
from policies.controller import load_controller

KERNELS = (("imit_pos", "k_pos", "m"), ("imit_rot", "k_rot", "rad"),
           ("imit_vel", "k_vel", "m/s"), ("imit_angvel", "k_angvel", "rad/s"))  # fmt: skip
FLAT = 0.1
"""A kernel is flat where its slope is under this share of its steepest."""


def kernel_error(r: np.ndarray, k: float, form: str) -> np.ndarray:
    """The error behind kernel values ``r``: RMS (``mean_sq``) or norm (``norm``)."""
    x = -np.log(np.clip(r, 1e-300, 1.0)) / k
    return np.sqrt(x) if form == "mean_sq" else x


def kernel_value_slope(e: np.ndarray, k: float, form: str) -> tuple[np.ndarray, np.ndarray]:
    """Value and derivative ``dr/de`` of a kernel at errors ``e``."""
    e = np.asarray(e, dtype=np.float64)
    if form == "mean_sq":
        r = np.exp(-k * e * e)
        return r, -2.0 * k * e * r
    r = np.exp(-k * e)
    return r, -k * r


def steepest_slope(k: float, form: str) -> float:
    """The largest ``|dr/de|`` of a kernel (at ``1 / sqrt(2k)``; at 0 for ``norm``)."""
    return math.sqrt(2.0 * k) * math.exp(-0.5) if form == "mean_sq" else k


def summarise(r_values: np.ndarray, rcfg: RewardConfig) -> dict:
    """Per kernel: the median failure's error, value and slope, and the share of flat ones.

    Args:
        r_values: ``(E, 4)`` the imitation kernels' values at the failures.
    """
    out = {}
    for j, (term, kname, unit) in enumerate(KERNELS):
        k = float(getattr(rcfg, kname))
        e = kernel_error(r_values[:, j], k, rcfg.form)
        r, slope = kernel_value_slope(e, k, rcfg.form)
        rel = np.abs(slope) / steepest_slope(k, rcfg.form)
        med = float(np.median(e))
        rm, sm = kernel_value_slope(med, k, rcfg.form)
        out[term] = {"k": k, "unit": unit, "error_median": med,
                     "error_p10_p90": np.percentile(e, [10, 90]).tolist(),
                     "value_at_median": float(rm), "slope_at_median": float(sm),
                     "slope_share_of_steepest_at_median": float(abs(sm)
                                                                / steepest_slope(k, rcfg.form)),
                     "flat_share": float((rel < FLAT).mean()),
                     "value_median": float(np.median(r))}  # fmt: skip
    return out


@torch.no_grad()
def play(args) -> dict:
    """Roll out the policy and collect the kernels at every failure (and at every decision)."""
    runner = load_controller(args.policy)
    ref = select_clips(load_reference(args.reference), tuple(args.category or ()))
    truth = args.truth or runner.info.get("follow") == "truth"
    if truth:
        ref = ReferenceSet([c.oracle() for c in ref.clips], ref.sensor_sites, ref.insoles,
                           ref.source)  # fmt: skip
    cfg = dataclasses.replace(runner.env_cfg, termination_dist_m=args.termination_m,
                              fall_height_m=args.fall_height,
                              fall_below_reference_m=args.fall_below,
                              max_episode_frames=args.max_frames, random_start=True,
                              clip_index=-1, reference="")  # fmt: skip
    env = GripTrackingEnv(cfg, ref)
    if cfg.action_repeat > 1:
        env = ActionRepeat(env, cfg.action_repeat)
    names = [t for t, _, _ in KERNELS]
    decision_s = cfg.control_dt_s * cfg.action_repeat
    lags = [(s, round(s / decision_s)) for s in args.before_s]
    obs, _ = env.reset(seed=args.seed)
    fails, every, mpjpe_fail, ended, cats, episode = [], [], [], 0, {}, []
    before: dict[float, list] = {s: [] for s, _ in lags}
    while ended < args.episodes:
        obs, _, term, trunc, info = env.step(runner.act(obs))
        row = [info[f"reward/{t}"] for t in names]
        every.append(row)
        episode.append(row)
        if term or trunc:
            ended += 1
            clip = env.unwrapped.clip
            n, f = cats.get(clip.category, (0, 0))
            failed = bool(term) and not info["sim_unstable"]
            cats[clip.category] = (n + 1, f + int(failed))
            if failed:
                fails.append(row)
                mpjpe_fail.append(info["mpjpe_m"])
                for s, lag in lags:  # (episodes shorter than the lag have no such frame)
                    if lag < len(episode):
                        before[s].append(episode[-1 - lag])
            episode = []
            obs, _ = env.reset()
    rcfg = cfg.reward
    out = {"policy": str(args.policy), "reference": str(args.reference), "truth": truth,
           "episodes": ended, "failures": len(fails), "by_category": cats,
           "termination_m": args.termination_m, "form": rcfg.form}  # fmt: skip
    if fails:
        out["mpjpe_at_failure_mm"] = 1000 * float(np.median(mpjpe_fail))
        out["at_failure"] = summarise(np.array(fails), rcfg)
        for s, rows in before.items():
            if rows:
                out[f"{s:g}s_before_failure"] = summarise(np.array(rows), rcfg)
    out["every_decision"] = summarise(np.array(every), rcfg)
    return out


def analytic(mpjpe_mm: list[float], rcfg: RewardConfig) -> list[dict]:
    """The position kernel at given errors (the RMS error taken as the MPJPE: a lower bound
    on it, so the value an upper bound)."""
    k = rcfg.k_pos
    rows = []
    for mm in mpjpe_mm:
        r, s = kernel_value_slope(mm / 1000.0, k, rcfg.form)
        rows.append(
            {
                "mpjpe_mm": mm,
                "imit_pos": float(r),
                "slope_per_m": float(s),
                "slope_share_of_steepest": float(abs(s) / steepest_slope(k, rcfg.form)),
            }
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--policy", help="exported policy file")
    ap.add_argument("--reference", help="reference set (.npz)")
    ap.add_argument("--truth", action="store_true", help="follow each clip's ground truth")
    ap.add_argument("--category", action="append", help="category glob (repeatable; all)")
    ap.add_argument("--episodes", type=int, default=60)
    ap.add_argument("--termination-m", type=float, default=0.25)
    ap.add_argument("--fall-height", type=float, default=0.3)
    ap.add_argument("--fall-below", type=float, default=0.2)
    ap.add_argument("--max-frames", type=int, default=300)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--before-s",
        type=float,
        nargs="*",
        default=[0.3, 1.0],
        help="also report the kernels this long before each failure, s",
    )
    ap.add_argument("--mpjpe-mm", type=float, nargs="*", help="only the kernels at these errors")
    ap.add_argument("--json", type=Path, help="write the results here")
    args = ap.parse_args()
    if args.mpjpe_mm:
        out = {"analytic": analytic(args.mpjpe_mm, RewardConfig())}
        for row in out["analytic"]:
            print(f"MPJPE {row['mpjpe_mm']:6.0f} mm: imit_pos {row['imit_pos']:.3f}, slope "
                  f"{row['slope_per_m']:8.2f} /m ({row['slope_share_of_steepest']:.2f} of the "
                  f"steepest)")  # fmt: skip
    else:
        if not args.policy or not args.reference:
            ap.error("--policy and --reference (or --mpjpe-mm)")
        out = play(args)
        print(
            f"{out['episodes']} episodes, {out['failures']} failures "
            f"(termination {args.termination_m} m); by category: {out['by_category']}"
        )
        if "at_failure" in out:
            print(f"median MPJPE at the failing frame: {out['mpjpe_at_failure_mm']:.0f} mm")
        wheres = ["at_failure", *(f"{s:g}s_before_failure" for s in args.before_s),
                  "every_decision"]  # fmt: skip
        for where in wheres:
            for term, s in out.get(where, {}).items():
                print(f"{where:22s} {term:12s} error {s['error_median']:.3f} {s['unit']:5s} "
                      f"value {s['value_at_median']:.3f} slope {s['slope_at_median']:9.3f} "
                      f"({s['slope_share_of_steepest_at_median']:.2f} of the steepest), "
                      f"flat in {100 * s['flat_share']:.0f} %")  # fmt: skip
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
