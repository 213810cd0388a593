"""Per-frame latency of streaming GRIP (``grip.eval.stream.GripStream``) on one core, batch 1.

Pushes the frames of a recording (default: the bundled sample walk) one at a time through the
shipped KinematicsNet and policy and MuJoCo, and prints the computation time per pushed frame
(mean, median, 95th and 99th percentile, worst), the time of its parts measured alone
(KinematicsNet's streaming step, the policy's forward pass), the offline path's time per frame,
and the ratio of the stream's mean to a reference measured in the same run on the same model:
one bare control step of MuJoCo (``mj_step`` x substeps). The ratio is the number to compare
between machines; the absolute numbers depend on the machine's load. The stream adds
LATENCY_FRAMES frames (20 ms at 100 Hz) of algorithmic delay on top (see grip.eval.stream).

    python benchmarks/stream_latency.py [--recording FILE] [--frames N] [--repeat R] [--json PATH]
"""

from __future__ import annotations

import argparse
import json
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one core, before numpy and torch load

import mujoco
import numpy as np
import torch

from grip.eval.reconstruct import GripReconstructor
from grip.eval.stream import LATENCY_FRAMES, GripStream
from grip.kinematics.features import sensor_frames
from prism_tools.io import load_recording

TARGET_MS = 5.0
"""Issue 7's aim for one frame on one core (PIP reports 16 ms)."""


def _physics_ms(stream: GripStream, steps: int = 300) -> float:
    """ms per bare control step (``mj_step`` x substeps) on the stream's model and state."""
    h = stream.player.h
    m = h.model
    d = mujoco.MjData(m)
    d.qpos[:] = h.data.qpos
    d.ctrl[:] = h.data.ctrl
    mujoco.mj_forward(m, d)
    start = time.perf_counter()
    for _ in range(steps):
        for _ in range(h.cfg.substeps):
            mujoco.mj_step(m, d)
    return 1e3 * (time.perf_counter() - start) / steps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--recording", default="grip/assets/sample_recording.npz")
    ap.add_argument("--policy", default="grip/assets/policy_default.pt")
    ap.add_argument("--kin", default="grip/assets/kinematics_default.pt")
    ap.add_argument("--frames", type=int, default=500, help="frames per pass (default 500)")
    ap.add_argument("--repeat", type=int, default=3, help="passes; the first one warms up")
    ap.add_argument("--json", help="also write the numbers here")
    args = ap.parse_args()
    torch.set_num_threads(1)
    rec = load_recording(args.recording)
    rec = rec.slice_frames(0, min(args.frames, rec.n_frames))
    g = GripReconstructor.from_files(args.policy, args.kin)
    frames = list(sensor_frames(rec, g.estimator.cfg.features))

    lat: list[float] = []
    ref_ms: list[float] = []
    for r in range(max(args.repeat, 2)):
        stream = GripStream(g.runner, g.estimator, rec.slice_frames(0, 2), g.recovery)
        times = []
        for f in frames:
            t0 = time.perf_counter()
            stream.push(f)
            times.append(time.perf_counter() - t0)
        stream.finish()
        ref_ms.append(_physics_ms(stream))
        if r > 0:  # the first pass warms up caches and allocations
            lat += times[LATENCY_FRAMES:]
        falls = len(stream.reconstruction().falls)
        stream.close()
    ms = 1e3 * np.array(lat)

    # the parts alone: KinematicsNet's streaming step and the policy's forward pass
    kin = g.estimator.stream(rec.slice_frames(0, 2))
    row = np.zeros(g.estimator.cfg.features.n_features, dtype=np.float32)
    t0 = time.perf_counter()
    for _ in range(len(frames)):
        kin.step(row)
    kin_ms = 1e3 * (time.perf_counter() - t0) / len(frames)
    stream = GripStream(g.runner, g.estimator, rec.slice_frames(0, 2), g.recovery)
    for f in frames[:3]:
        stream.push(f)
    obs = stream.player.obs
    t0 = time.perf_counter()
    for _ in range(len(frames)):
        g.runner.act(obs)
    act_ms = 1e3 * (time.perf_counter() - t0) / len(frames)
    stream.close()
    t0 = time.perf_counter()
    g.reconstruct([rec])
    offline_ms = 1e3 * (time.perf_counter() - t0) / rec.n_frames

    ref = float(np.median(ref_ms))
    out = {
        "frames": int(ms.size), "mean_ms": float(ms.mean()), "p50_ms": float(np.median(ms)),
        "p95_ms": float(np.percentile(ms, 95)), "p99_ms": float(np.percentile(ms, 99)),
        "max_ms": float(ms.max()), "kinematics_step_ms": kin_ms, "policy_act_ms": act_ms,
        "offline_ms_per_frame": offline_ms, "physics_step_ms": ref,
        "ratio_to_physics": float(ms.mean()) / ref, "latency_frames": LATENCY_FRAMES,
        "falls_per_pass": falls,
    }  # fmt: skip
    print(f"streaming GRIP, one thread, batch 1, {rec.name} ({rec.n_frames} frames x "
          f"{max(args.repeat, 2) - 1} passes after a warm-up)")  # fmt: skip
    print(f"  per pushed frame: mean {out['mean_ms']:.2f} ms, median {out['p50_ms']:.2f}, "
          f"p95 {out['p95_ms']:.2f}, p99 {out['p99_ms']:.2f}, max {out['max_ms']:.2f}")
    print(f"  parts alone: KinematicsNet step {kin_ms:.2f} ms, policy forward {act_ms:.2f} ms")
    print(f"  offline path (GripReconstructor): {offline_ms:.2f} ms per frame")
    print(f"  reference, bare MuJoCo control step: {ref:.3f} ms; stream / reference = "
          f"{out['ratio_to_physics']:.1f}")  # fmt: skip
    met = "met" if out["mean_ms"] < TARGET_MS else "NOT met"
    print(f"  aim < {TARGET_MS:g} ms per frame: {met} (plus {LATENCY_FRAMES} frames of "
          "algorithmic delay)")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
