"""PD tracking of a mocap clip with the pelvis pinned to the ground truth (no policy).

Plays a clip through ``GripTrackingEnv`` with ``pin_root=True``, relative actions of 0 and a
perfect estimate (the ground truth), with and without the velocity feed-forward, and prints the
MPJPE, the mean per-frame worst joint error against the ground truth and the mean mechanical
power of the actuators (the raw energy term of the reward, W). These are the numbers
docs/controller.md quotes for the environment's PD control and for the energy weight of
configs/policy.

    python benchmarks/env_pd_tracking.py [--clip ../shared/data/motions/cmu/bvh/07_05.bvh]
        [--time-scale 1.5]

``--time-scale F`` plays the clip F times faster (``Motion.time_scaled``): can the PD control
follow a faster gait's swing at all (issue 46: every controller tops out near 1.1 m/s)?
"""

from __future__ import annotations

import argparse

import numpy as np

from envs.tracking_env import GripTrackingEnv
from grip.cli.paths import default_motions_dir
from grip.core.reference import ReferenceSet
from grip.kinematics.reference import oracle_reference_clip
from grip.motion.catalog import load_clip
from grip.motion.retarget import retarget
from grip.task.config import TrackingEnvConfig
from prism_tools.synth import SynthConfig, recording_from_motion


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    root = default_motions_dir()
    ap.add_argument("--clip", default=str(root / "cmu/bvh/07_05.bvh") if root else None,
                    help="motion clip (default: CMU 07_05, a slow walk)")  # fmt: skip
    ap.add_argument("--time-scale", type=float, default=1.0,
                    help="play the clip this many times faster (0.5-2)")
    args = ap.parse_args()
    if not args.clip:
        ap.error("no shared motion data found: pass --clip")
    motion = retarget(load_clip(args.clip))
    if args.time_scale != 1.0:
        motion = motion.time_scaled(args.time_scale)
    rec = recording_from_motion(motion, SynthConfig(), seed=0, noise=False)
    ref = ReferenceSet([oracle_reference_clip(rec)], ("L_Foot", "R_Foot", "L_Wrist", "R_Wrist"),
                       True)  # fmt: skip
    for ff in (True, False):
        env = GripTrackingEnv(TrackingEnvConfig(pin_root=True, random_start=False,
                                                termination_dist_m=0.0, velocity_feedforward=ff),
                              reference=ref)  # fmt: skip
        env.reset(seed=0)
        mpjpe, worst, power = [], [], []
        while True:
            _, _, term, trunc, info = env.step(np.zeros(69, np.float32))
            mpjpe.append(info["mpjpe_m"])
            worst.append(info["max_joint_err_m"])
            power.append(info["reward/energy"])
            if term or trunc:
                break
        print(
            f"velocity feed-forward {'on ' if ff else 'off'}: {len(mpjpe)} frames, "
            f"MPJPE {1e3 * np.mean(mpjpe):.1f} mm, "
            f"mean worst joint {1e3 * np.mean(worst):.1f} mm, "
            f"mechanical power {np.mean(power[3:]):.0f} W"
        )


if __name__ == "__main__":
    main()
