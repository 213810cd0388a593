"""Time of one joint-phase KinematicsNet training step, split into its parts.

Runs the real ``Trainer`` (default config) for a few steps of the joint phase on the first 40
training sequences of a dataset (``--data``; without it, synthetic recordings, on which the
backward pass produces subnormal floats that slow it down several-fold, so subnormals are then
flushed to zero) and prints the mean seconds of window sampling, augmentation (incl.
mirroring), forward pass, backward pass and optimiser step, with a reference measured in the
same run: forward + backward of one bare ``torch.nn.LSTM`` of the same width and depth on a
random batch of the same shape (KinematicsNet has four such stages). Compare ratios across
machines.

    python benchmarks/kinematics_train_step.py --data data/prism_synth [--threads 1] [--steps 6]
        [--bf16]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time

import torch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--steps", type=int, default=6, help="timed steps (after 2 warm-up steps)")
    ap.add_argument("--data", default=None, help="dataset folder (default: synthetic data)")
    ap.add_argument("--json", default=None)
    ap.add_argument("--bf16", action="store_true",
                    help="train.bf16: the network under bfloat16 autocast (the reference stays "
                         "float32, so the ratio shows the gain)")  # fmt: skip
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    torch.set_flush_denormal(args.data is None)

    from grip.cli.paths import load_run_config
    from grip.kinematics.config import KinematicsRunConfig
    from grip.kinematics.dataset import load_split_sequences, sequence_arrays
    from grip.kinematics.train import Trainer
    from prism_tools.synthetic import make_recording

    sets = ["train.bf16=true"] if args.bf16 else []
    cfg = load_run_config(None, "kinematics", KinematicsRunConfig(), sets)
    tc = cfg.train
    if args.data:
        seqs = load_split_sequences(args.data, "train", cfg.features, limit=40)
    else:
        seqs = [sequence_arrays(make_recording(600, seed=s), cfg.features) for s in range(4)]
    with tempfile.TemporaryDirectory() as tmp:
        tr = Trainer(cfg, seqs, seqs[:1], tmp)
    parts = dict.fromkeys(("sample", "augment", "forward", "backward", "step"), 0.0)
    for i in range(args.steps + 2):
        t = [time.perf_counter()]
        tr.train_step("joint", tc.lr, clock=t)
        if i >= 2:
            for k, a, b in zip(parts, t[:-1], t[1:], strict=True):
                parts[k] += (b - a) / args.steps
    lstm = torch.nn.LSTM(cfg.features.n_features, cfg.hidden, cfg.layers, batch_first=True)
    xr = torch.randn(tc.batch_size, tc.window_frames, cfg.features.n_features)
    ref = 0.0
    for i in range(args.steps + 2):
        t0 = time.perf_counter()
        out, _ = lstm(xr)
        out.square().mean().backward()
        if i >= 2:
            ref += (time.perf_counter() - t0) / args.steps
    step = sum(parts.values())
    frames = tc.batch_size * tc.window_frames
    print(f"threads {args.threads}, batch {tc.batch_size} x {tc.window_frames} frames, "
          f"mirror_augment={tc.mirror_augment}, bf16={tc.bf16}, "
          f"data {args.data or 'synthetic'}")  # fmt: skip
    print(" | ".join(f"{k} {v:.3f} s" for k, v in parts.items()))
    print(f"step {step:.3f} s ({frames / step:.0f} frames/s); bare LSTM fwd+bwd {ref:.3f} s; "
          f"ratio {step / ref:.2f}")  # fmt: skip
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"threads": args.threads, "data": args.data, "bf16": tc.bf16,
                       "parts_s": parts, "step_s": step,
                       "frames_per_s": frames / step, "lstm_ref_s": ref,
                       "ratio": step / ref}, f, indent=1)  # fmt: skip


if __name__ == "__main__":
    main()
