"""Cost of a reset onto another subject: the env's model swap against compiling a model.

A training set has a subject (body size, mass) per clip. ``GripTrackingEnv`` keeps one MuJoCo
model per scene and swaps a subject's arrays in (``grip.sim.model.ModelVariants``); before, it
compiled a model per subject into a cache of 16, which thrashed. In one run this prints: the
mean reset time cycling through the clips once every subject has been seen (the steady state of
a training), the first pass (each subject compiled once), a reset onto the same clip, and the
reference: compiling one subject's model, as every reset onto a new subject used to.

    python benchmarks/env_reset.py --reference RUN/reference_train.npz [--resets 300]
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np

from envs.tracking_env import SAMPLE_REFERENCE, GripTrackingEnv
from grip.core.mjcf import build_mjcf
from grip.core.reference import ReferenceSet
from grip.task.config import TrackingEnvConfig


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--reference", default=str(SAMPLE_REFERENCE),
                    help="reference set (grip policy train writes RUN/reference_train.npz)")
    ap.add_argument("--resets", type=int, default=300)
    args = ap.parse_args()
    ref = ReferenceSet.load(args.reference)
    cfg = TrackingEnvConfig(amp_window=10, max_episode_frames=300, terrain="flat")
    env = GripTrackingEnv(cfg, ref)
    n = len(ref)
    bodies = len({(c.body.height_m, c.body.mass_kg) for c in ref.clips})

    def cycle(k: int) -> float:
        t0 = time.perf_counter()
        for i in range(k):
            env.reset(options={"clip": i % n, "start": 0})
        return 1e3 * (time.perf_counter() - t0) / k

    first = cycle(n)  # every subject once: compiled and registered
    steady = cycle(args.resets)
    t0 = time.perf_counter()
    for _ in range(50):
        env.reset(options={"clip": 0, "start": 0})
    same = 1e3 * (time.perf_counter() - t0) / 50
    picks = np.linspace(0, n - 1, min(n, 20)).astype(int)
    t0 = time.perf_counter()
    for i in picks:
        mujoco.MjModel.from_xml_string(build_mjcf(ref.clip(int(i)).body, cfg.mjcf))
    compile_ms = 1e3 * (time.perf_counter() - t0) / len(picks)
    print(f"{args.reference}: {n} clips, {bodies} subjects")
    print(f"  reset, cycling through the clips (steady state): {steady:.2f} ms")
    print(f"  reset, first pass (each subject compiled once):  {first:.2f} ms")
    print(f"  reset onto the same clip:                        {same:.2f} ms")
    print(f"  reference, compiling one subject's model:        {compile_ms:.2f} ms "
          f"(ratio {compile_ms / steady:.1f})")  # fmt: skip


if __name__ == "__main__":
    main()
