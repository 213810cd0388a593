"""``grip train-baseline`` and ``grip baseline-export``: the TransPose / PIP kinematics nets."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

BASELINE_NAMES: tuple[str, ...] = ("transpose", "pip")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "train-baseline",
        help="train the TransPose (TP-4) or PIP (PIP-4) kinematics nets on a dataset",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Train the kinematics networks of a baseline on the train split of a dataset\n"
            "folder, adapted to 4 IMUs (BASELINES_AND_METRICS.md section 2): TransPose's\n"
            "Pose-S1/S2/S3 and Trans-B1/B2, or PIP's P_L, P_A, R_A, V_A, C_F with the learned\n"
            "RNN initialisation. --insoles trains the '+I' variant (insole values appended to\n"
            "every input). Checkpoints every epoch to RUN/last.pt (RUN/best.pt: each net at its\n"
            "lowest validation loss); running the same command again resumes.\n"
            "TensorBoard: tensorboard --logdir RUN/tb"
        ),
        epilog="example: grip train-baseline transpose --data data/prism_synth --out runs/tp4\n"
        "         grip train-baseline pip --insoles --data data/prism_synth --out runs/pip4i\n"
        "         grip train-baseline pip --data data/prism_synth --out runs/pip4_long "
        "--set train.epochs=40",
    )
    p.add_argument("name", choices=BASELINE_NAMES, help="baseline to train")
    p.add_argument("--data", required=True, type=Path, help="dataset folder (with split.json)")
    p.add_argument("--out", required=True, type=Path, help="run folder (created or resumed)")
    p.add_argument(
        "--config",
        type=Path,
        default=None,
        help="TOML overrides (default: configs/baselines/NAME.toml if present)",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override one setting, e.g. --set train.lr=3e-4 (repeatable)",
    )
    p.add_argument("--insoles", action="store_true", help="'+I' variant (same as net.insoles=true)")
    p.add_argument("--threads", type=int, default=0, help="torch threads (default: all cores)")
    p.set_defaults(func=cmd_train)

    from grip.cli.kinematics import add_export_parser

    add_export_parser(sub, "baseline-export", "TransPose / PIP baseline",
                      "for shipping trained baseline nets (a few MB)",
                      "grip baseline-export runs/tp4/best.pt --out grip/assets/transpose4.pt",
                      "grip.kinematics.baselines:export_baseline")


def cmd_train(args: argparse.Namespace) -> int:
    import torch

    from grip.cli.errors import CliError
    from grip.cli.kinematics import fit_run
    from grip.cli.paths import REPO_ROOT, load_run_config
    from grip.kinematics.baselines import (
        BaselineTrainer,
        default_run_config,
        load_baseline_sequences,
        n_inputs,
    )

    config = args.config
    if config is None:
        candidate = REPO_ROOT / "configs" / "baselines" / f"{args.name}.toml"
        config = candidate if candidate.is_file() else None
    overrides = [*args.set, *(["net.insoles=true"] if args.insoles else [])]
    cfg = load_run_config(config, "baselines", default_run_config(args.name), overrides)
    if args.threads:
        torch.set_num_threads(args.threads)
    t0 = time.perf_counter()
    try:
        train = load_baseline_sequences(args.data, "train", cfg)
        val = load_baseline_sequences(args.data, "test", cfg)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(str(e)) from e
    n_frames = sum(len(s.x) for s in train)
    variant = " + insoles" if cfg.net.insoles else ""
    print(f"{args.name}{variant}: {n_inputs(cfg)} inputs; loaded {len(train)} train / "
          f"{len(val)} test sequences ({n_frames} train frames) in "
          f"{time.perf_counter() - t0:.1f} s")  # fmt: skip
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    try:
        trainer = BaselineTrainer(cfg, train, val, out)
    except ValueError as e:
        raise CliError(str(e)) from e
    info = {"method": args.name, "data": str(args.data.resolve()), "train_frames": n_frames}
    return fit_run(trainer, cfg, out, info, epochs=cfg.train.epochs, postfix="epoch")
