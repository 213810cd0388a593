"""``grip train-kin``: train KinematicsNet on a dataset folder."""

from __future__ import annotations

import argparse
import time
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "train-kin",
        help="train KinematicsNet on a dataset built by 'grip data build'",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Train the four-stage KinematicsNet (LP -> FP -> FA -> LV) on the train split of a\n"
            "dataset folder: stage-wise, then jointly, with MSE + forward-kinematics losses,\n"
            "input noise and random-yaw augmentation. Checkpoints every epoch to RUN/last.pt\n"
            "(best validation: RUN/best.pt); running the same command again resumes.\n"
            "TensorBoard: tensorboard --logdir RUN/tb"
        ),
        epilog="example: grip train-kin --data data/prism_synth --out runs/kin\n"
        "         grip train-kin --data data/prism_synth --out runs/kin_small "
        "--set hidden=128 --set train.joint_epochs=5",
    )
    p.add_argument("--data", required=True, type=Path, help="dataset folder (with split.json)")
    p.add_argument("--out", required=True, type=Path, help="run folder (created or resumed)")
    p.add_argument("--config", type=Path, default=None,
                   help="TOML overrides (default: configs/kinematics/default.toml if present)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override one setting, e.g. --set train.lr=3e-4 (repeatable)")
    p.add_argument("--threads", type=int, default=0, help="torch threads (default: all cores)")
    p.set_defaults(func=cmd_train)


def cmd_train(args: argparse.Namespace) -> int:
    import torch
    from torch.utils.tensorboard import SummaryWriter
    from tqdm import tqdm

    from grip.cli.main import CliError
    from grip.cli.paths import REPO_ROOT
    from grip.config import ConfigError, load_config
    from grip.kinematics.dataset import load_split_sequences
    from grip.kinematics.train import KinematicsRunConfig, Trainer, write_run_config

    cfg_path = args.config
    if cfg_path is None:
        default = REPO_ROOT / "configs" / "kinematics" / "default.toml"
        cfg_path = default if default.is_file() else None
    try:
        cfg = load_config(cfg_path, KinematicsRunConfig(), args.set)
    except ConfigError as e:
        raise CliError(str(e)) from e
    if args.threads:
        torch.set_num_threads(args.threads)
    t0 = time.perf_counter()
    try:
        train = load_split_sequences(args.data, "train", cfg.features)
        val = load_split_sequences(args.data, "test", cfg.features)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(str(e)) from e
    n_frames = sum(len(s.x) for s in train)
    print(f"loaded {len(train)} train / {len(val)} test sequences ({n_frames} train frames) "
          f"in {time.perf_counter() - t0:.1f} s")  # fmt: skip
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    trainer = Trainer(cfg, train, val, out)
    last = out / "last.pt"
    if last.exists():
        try:
            trainer.load(last)
        except ValueError as e:
            raise CliError(f"{e}; use another --out or the same settings") from e
        print(f"resuming {last} at epoch {trainer.epoch}/{cfg.total_epochs()}")
    write_run_config(out, cfg, {"data": str(args.data.resolve()), "train_frames": n_frames})
    total = cfg.total_epochs() * cfg.train.steps_per_epoch
    done = trainer.epoch * cfg.train.steps_per_epoch
    with SummaryWriter(str(out / "tb")) as writer, tqdm(total=total, initial=done,
                                                          unit="step") as bar:  # fmt: skip
        def progress(info: dict) -> None:
            bar.set_postfix(phase=info["phase"], loss=f"{info['loss']:.4f}")
            bar.update(1)

        t1 = time.perf_counter()
        trainer.fit(writer=writer, progress=progress)
    dt = time.perf_counter() - t1
    steps = total - done
    if steps:
        fps = steps * cfg.train.batch_size * cfg.train.window_frames / dt
        print(f"trained {steps} steps in {dt:.0f} s ({fps:.0f} frames/s)")
    if trainer.history:
        print(f"final validation losses: {trainer.history[-1]['val']}")
    print(f"checkpoints: {out / 'last.pt'} and {out / 'best.pt'}")
    return 0
