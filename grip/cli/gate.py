"""``grip policy combine FILES --gate CATS ...``: a gate over frozen controllers, one per
motion family (:mod:`policies.gate`)."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``grip policy combine`` that only ``--gate`` reads."""
    p.add_argument("--data", type=Path, default=None,
                   help="with --gate: the dataset folder whose train split the gate learns "
                   "from (with split.json)")  # fmt: skip
    p.add_argument("--kin", type=Path, default=None,
                   help="with --gate: the KinematicsNet whose input features the gate reads "
                   "(default: the shipped one; the controllers' sensor observation)")
    p.add_argument("--gate-steps", type=int, default=3000, metavar="N",
                   help="with --gate: the classifier's training steps (default 3000)")
    p.add_argument("--gate-window", type=int, default=60, metavar="FRAMES",
                   help="with --gate: frames of context the classifier reads beside each frame "
                   "(each sensor feature's mean and deviation over the last FRAMES; default "
                   "60 = 0.6 s; 1: the frame alone)")  # fmt: skip


def cmd_gate(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from grip.cli.common import write_artifact
    from grip.cli.errors import CliError
    from grip.cli.recordings import kin_checkpoint
    from grip.kinematics.dataset import load_split_sequences
    from grip.kinematics.inference import KinematicsEstimator
    from policies.gate import fit_gate, route_table, write_gated_policy

    files = [Path(f) for f in args.policies]
    families = [tuple(c.strip() for c in g.split(",") if c.strip()) for g in args.gate]
    if len(files) != len(families) + 1 or not all(families):
        raise CliError(f"--gate: {len(files)} policy files need {len(files) - 1} --gate "
                       f"(one per file after the first, each naming categories), got "
                       f"{len(families)}")  # fmt: skip
    if args.data is None:
        raise CliError("--gate needs --data: the dataset whose train split the gate learns from")
    if args.gate_steps < 1:
        raise CliError("--gate-steps must be positive")
    if args.gate_window < 1:
        raise CliError("--gate-window must be at least 1 frame")
    for f in files:
        if not f.is_file():
            raise CliError(f"{f}: no such policy file")
    kin = kin_checkpoint(args.kin)
    try:
        feats = KinematicsEstimator.from_checkpoint(kin).cfg.features
        train = load_split_sequences(args.data, "train", feats)
        test = load_split_sequences(args.data, "test", feats)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(str(e)) from e
    if not train:
        raise CliError(f"{args.data}: no training recordings for the gate")
    print(f"{len(train)} training and {len(test)} test recordings, {train[0].x.shape[1]} "
          f"sensor features per frame ({kin}), context {args.gate_window} frames")  # fmt: skip
    bar = tqdm(total=args.gate_steps, desc="gate", unit="step")

    def step(loss: float) -> None:
        bar.update()
        bar.set_postfix(loss=f"{loss:.3f}", refresh=False)

    try:
        gate, _ = fit_gate([s.x for s in train], [s.category for s in train], families,
                           steps=args.gate_steps, window=args.gate_window,
                           progress=step)  # fmt: skip
    except ValueError as e:
        raise CliError(f"{args.data}: {e}") from e
    finally:
        bar.close()
    names = [f"{files[0].name} (the rest)"] + [",".join(f) for f in families]
    for split, seqs in (("train", train), ("test", test)):
        if seqs:
            table = route_table(gate, [s.x for s in seqs], [s.category for s in seqs], names)
            print(f"\nroutes on the {split} split (share of each category's frames):\n{table}")

    def write() -> tuple[int, str]:
        size = write_gated_policy(files, gate, args.out, args.precision)
        return size, f", {len(files)} controllers and their gate"

    return write_artifact(args.out, write)
