"""What the body contact points change in the synthesised insoles, clip by clip.

Each clip is retargeted onto the default body and synthesised clean twice: with the lowest
points of the body's other shapes able to carry load (`prism_tools.synth.insole.
body_contact_points`, the synthesis as it is) and with none of them (the soles alone, as before
that change). Prints per clip the share of frames whose ZMP lies more than 3 cm outside the
loaded supports, the frames where other body parts carry more than 5 % of the body weight, and
the insoles' median total force (body weights). docs/props.md quotes its output.

    python benchmarks/insole_contacts.py cmu/bvh/14_31.bvh hdm05/amc/HDM_bd_lieDownFloor_002_120.amc
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

DEFAULT_CLIPS = (
    "cmu/bvh/14_31.bvh", "cmu/bvh/14_30.bvh", "cmu/bvh/13_01.bvh", "cmu/bvh/14_21.bvh",
    "hdm05/amc/HDM_bd_lieDownFloor_002_120.amc", "deepmimic/humanoid3d_crawl.txt",
    "deepmimic/humanoid3d_getup_faceup.txt", "hdm05/amc/HDM_bk_depositFloorR_011_120.amc",
    "cmu/bvh/07_05.bvh",
)  # fmt: skip


def measure(path: Path, contacts: bool) -> tuple[float, float, float]:
    """``(ZMP-outside share, other-support share, median insole force in body weights)``."""
    import numpy as np

    import prism_tools.synth.insole as insole
    from grip.motion.catalog import load_clip
    from grip.motion.retarget import retarget
    from prism_tools.synth import recording_from_motion

    real = insole.body_contact_points

    def no_points(global_rot, joint_pos, body):
        pts, bodies, where = real(global_rot, joint_pos, body)
        return pts[:, :0], bodies[:0], where[:0]

    insole.body_contact_points = real if contacts else no_points
    try:
        rec = recording_from_motion(retarget(load_clip(str(path))), noise=False)
    finally:
        insole.body_contact_points = real
    n = rec.n_frames
    force = sum(rec.insole[f].force[:, 0] for f in rec.insole)
    return (rec.extras["insole_zmp_outside_frames"] / n,
            rec.extras["insole_other_support_frames"] / n, float(np.median(force)))  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("clips", nargs="*", default=list(DEFAULT_CLIPS),
                    help="clip paths below --motions (default: those of docs/props.md)")
    ap.add_argument("--motions", type=Path, default=None,
                    help="folder of motion clips (default: ../shared/data/motions)")  # fmt: skip
    args = ap.parse_args(argv)
    from grip.cli.paths import default_motions_dir

    root = args.motions or default_motions_dir()
    if root is None or not Path(root).is_dir():
        print("no motion folder: give --motions", file=sys.stderr)
        return 2
    print("| clip | ZMP > 3 cm, soles only | with body contacts | frames with other support "
          "| insoles, median (body weights) |\n|---|---:|---:|---:|---|")  # fmt: skip
    for clip in args.clips:
        before = measure(Path(root) / clip, contacts=False)
        after = measure(Path(root) / clip, contacts=True)
        print(f"| {clip} | {100 * before[0]:.1f} % | {100 * after[0]:.1f} % | "
              f"{100 * after[1]:.1f} % | {before[2]:.2f} -> {after[2]:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
