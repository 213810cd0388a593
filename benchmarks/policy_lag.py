"""Where the controller falls behind: per-frame trace of one episode, or an evaluation on
time-reversed walks (docs/controller.md, "Why walking backwards fails").

``trace`` plays one 500-frame segment (no fall recovery) and prints every 10th frame: pelvis
height of the simulation and of the ground truth, the simulation's distance behind (-) or ahead
of the truth along the direction of travel, the trunk's tilt from the vertical, foot heights and
contacts; then the mean pelvis speeds. ``--option`` adds MuJoCo ``<option>`` attributes to the
humanoid's model (e.g. ``'noslip_iterations="5"'``) to test the physics.

``reversed`` evaluates on the forward walks of a split played backwards
(:mod:`grip.dataset.augment`), cut into 500-frame segments.

    python benchmarks/policy_lag.py trace --data DATA --split train --category walk-back \\
        --index 0 --reference truth
    python benchmarks/policy_lag.py reversed --data DATA --split test
"""

from __future__ import annotations

import argparse

import numpy as np

from grip.assets import SHIPPED_POLICY
from grip.cli.recordings import kin_checkpoint, load_recordings, split_paths
from grip.kinematics.inference import KinematicsEstimator
from policies.controller import load_controller

SEGMENT = 500


def _trace(args, runner, est) -> None:
    import envs.scenes as te
    from grip.core.reference import ReferenceSet
    from grip.kinematics.reference import build_reference_set, oracle_reference_clip
    from grip.pipeline import GripPipeline, RecoveryConfig, start_from_clip

    if args.option:
        build, opt = te.build_mjcf, f"<option {args.option} "
        te.build_mjcf = lambda *a, **k: build(*a, **k).replace("<option ", opt, 1)
    recs = load_recordings(split_paths(args.data, args.split), [args.category], SEGMENT)
    rec = recs[args.index]
    f = est.cfg.features
    ref = (ReferenceSet([oracle_reference_clip(rec, f)], tuple(f.sites), f.insoles, "truth")
           if args.reference == "truth" else build_reference_set([rec], est))  # fmt: skip
    c = ref.clip(0)
    recon, _ = GripPipeline(runner, est, RecoveryConfig(enabled=False)).play(
        c, start_from_clip(c), c.body, c.objects, stop_at_fall=True)
    n = recon.n_frames
    print(f"{rec.name}: {n} frames, {'fell' if recon.fell else 'kept'}")
    print("frame | pelvis z sim/truth | along travel m | tilt deg sim/truth | feet z | contacts")
    for t in range(0, n, 10):
        sp, gp = recon.joint_pos[t, 0], c.gt_pos[t, 0]
        ahead = c.gt_pos[min(t + 10, len(c.gt_pos) - 1), 0, :2] - gp[:2]
        ahead /= np.linalg.norm(ahead) + 1e-9
        tilt = [np.degrees(np.arctan2(np.linalg.norm(v[:2]), v[2]))
                for v in (recon.joint_pos[t, 9] - sp, c.gt_pos[t, 9] - gp)]  # fmt: skip
        fz = recon.joint_pos[t, [10, 11], 2]
        print(f"{t:5d} | {sp[2]:.2f} / {gp[2]:.2f} | {(sp - gp)[:2] @ ahead:+.2f} | "
              f"{tilt[0]:4.1f} / {tilt[1]:4.1f} | {fz[0]:.2f} {fz[1]:.2f} | "
              f"{recon.contacts[t].astype(int)}")  # fmt: skip

    def speed(p):
        return float(np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1).mean() * c.fps)

    print(f"pelvis speed: simulation {speed(recon.joint_pos[:, 0]):.2f} m/s, "
          f"truth {speed(c.gt_pos[:n, 0]):.2f} m/s")  # fmt: skip


def _reversed(args, runner, est) -> None:
    from grip.dataset.augment import time_reversed_recordings
    from grip.eval.policy import evaluate_policy, markdown_table, summarize_rows

    stems = [f.stem for f in split_paths(args.data, args.split)]
    recs = time_reversed_recordings(args.data, stems, [args.category])
    segs = [r.slice_frames(s, s + SEGMENT) for r in recs
            for s in range(0, r.n_frames - SEGMENT + 1, SEGMENT)]  # fmt: skip
    if not segs:
        raise SystemExit(f"no {SEGMENT}-frame segment of a reversed {args.category!r} clip")
    print(markdown_table(summarize_rows(evaluate_policy(runner, est, segs,
                                                       reference=args.reference))))  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("mode", choices=("trace", "reversed"))
    ap.add_argument("--data", required=True, help="a 'grip data build' folder")
    ap.add_argument("--split", default="test", choices=("train", "test"))
    ap.add_argument("--category", default="walk",
                    help="category glob (trace: of the segment; reversed: clips to reverse)")
    ap.add_argument("--index", type=int, default=0, help="trace: which segment of the category")
    ap.add_argument("--reference", default="estimate", choices=("estimate", "truth"))
    ap.add_argument("--policy", action="append", default=None,
                    help="policy or ensemble file (repeatable; default: the shipped one)")
    ap.add_argument("--option", default="", help="trace: extra MuJoCo <option> attributes")
    args = ap.parse_args()
    runner = load_controller(args.policy or [SHIPPED_POLICY])
    est = KinematicsEstimator.from_checkpoint(kin_checkpoint(None))
    (_trace if args.mode == "trace" else _reversed)(args, runner, est)


if __name__ == "__main__":
    main()
