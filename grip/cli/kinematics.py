"""``grip train-kin``: train KinematicsNet on a dataset folder."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from grip.cli.recordings import add_limit_arguments, add_tta_argument, limits_from_args


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
        "--set hidden=128 --set train.joint_epochs=5\n"
        "         grip train-kin --data data/prism_synth --out runs/sweep --sweep "
        "--config configs/kinematics/sweep.toml\n"
        "         grip train-kin --data data/prism_synth --out runs/kin_ft "
        "--init runs/kin/last.pt --config configs/kinematics/finetune.toml",
    )
    p.add_argument("--data", required=True, type=Path, help="dataset folder (with split.json)")
    p.add_argument("--out", required=True, type=Path, help="run folder (created or resumed)")
    p.add_argument(
        "--config",
        type=Path,
        default=None,
        help="TOML overrides (default: configs/kinematics/default.toml if present)",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override one setting, e.g. --set train.lr=3e-4 (repeatable)",
    )
    p.add_argument("--threads", type=int, default=0, help="torch threads (default: all cores)")
    p.add_argument(
        "--init",
        type=Path,
        default=None,
        metavar="CKPT",
        help="fine-tune: start from the weights and normaliser of this checkpoint (a run's "
        "last.pt or an export with the same network and sensors) instead of random weights; "
        "usually with --set train.stage_epochs=0 (ignored when OUT resumes)",
    )
    p.add_argument(
        "--sweep",
        action="store_true",
        help="sensor sweep (GRIP Table 3): train one run per IMU count, with and "
        "without insoles, in OUT/imu<N>_press|nopress (finished runs are skipped, "
        "interrupted ones resume); evaluate with 'grip eval-kin --sweep OUT'",
    )
    p.add_argument(
        "--imus",
        default="2,3,4,6",
        metavar="N,N,...",
        help="IMU counts of --sweep (feet, +left wrist, +right wrist, +pelvis, +head; "
        "default 2,3,4,6)",
    )
    p.set_defaults(func=cmd_train)
    add_eval_parser(sub)
    add_export_parser(
        sub,
        "kin-export",
        "KinematicsNet",
        "the form in which the default model ships (grip/assets/kinematics_default.pt)",
        "grip kin-export runs/kin/best.pt --out grip/assets/kinematics_default.pt",
        "grip.kinematics.train:export_for_inference",
    )


def add_export_parser(
    sub: argparse._SubParsersAction, name: str, what: str, shipped: str, example: str, exporter: str
) -> None:
    """A ``<name> CKPT --out FILE [--precision P]`` command writing a small inference copy of a
    training checkpoint with ``exporter`` (``"module:function(src, dst, precision) -> bytes"``)."""
    x = sub.add_parser(
        name,
        help=f"write a small inference-only copy of a {what} checkpoint",
        description=f"Drop the optimiser state and store the weights as float16 (or int8 with "
        f"a scale per row, or float32): {shipped}.",
        epilog=f"example: {example}",
    )
    x.add_argument("checkpoint", type=Path, help="training checkpoint (RUN/best.pt)")
    x.add_argument("--out", required=True, type=Path, help="output .pt")
    x.add_argument(
        "--precision",
        choices=("fp32", "fp16", "int8"),
        default="fp16",
        help="weight storage (default fp16; int8 halves the file again)",
    )
    x.set_defaults(func=cmd_export, exporter=exporter)


def cmd_export(args: argparse.Namespace) -> int:
    import importlib

    from grip.cli.errors import CliError

    module, func = args.exporter.split(":")
    export = getattr(importlib.import_module(module), func)
    try:
        size = export(args.checkpoint, args.out, precision=args.precision)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(str(e)) from e
    print(f"wrote {args.out} ({size / 1e6:.1f} MB)")
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    import torch

    from grip.cli.errors import CliError
    from grip.cli.paths import load_run_config
    from grip.kinematics.train import KinematicsRunConfig

    cfg = load_run_config(args.config, "kinematics", KinematicsRunConfig(), args.set)
    if args.threads:
        torch.set_num_threads(args.threads)
    if not args.sweep:
        return _train_one(args.data, args.out, cfg, init=args.init)
    if args.init is not None:
        raise CliError("--init fine-tunes one run; it does not combine with --sweep")
    import dataclasses

    from grip.kinematics.sweep import parse_counts, sensor_sets

    try:
        sets = sensor_sets(parse_counts(args.imus))
    except ValueError as e:
        raise CliError(str(e)) from e
    for i, s in enumerate(sets):
        run_cfg = dataclasses.replace(
            cfg, features=dataclasses.replace(cfg.features, sites=s.sites, insoles=s.insoles)
        )
        print(f"[{i + 1}/{len(sets)}] {s.name}: {', '.join(s.sites)}"
              f"{' + insoles' if s.insoles else ''}")  # fmt: skip
        _train_one(args.data, args.out / s.name, run_cfg)
    print(f"sweep finished; evaluate with: grip eval-kin --sweep {args.out} --data {args.data}")
    return 0


def _train_one(data: Path, out: Path, cfg, init: Path | None = None) -> int:
    from grip.cli.errors import CliError
    from grip.kinematics.dataset import holdout_split, load_split_sequences, split_files
    from grip.kinematics.train import Trainer

    t0 = time.perf_counter()
    tc = cfg.train
    try:
        train = load_split_sequences(data, "train", cfg.features)
        stems = [f.stem for f in split_files(data, "train")]  # in the order of ``train``
        if tc.val_source == "holdout":
            kept, val = holdout_split(train, tc.val_fraction, tc.seed)
            names = {s.name for s in kept}
            stems = [st for st, s in zip(stems, train, strict=True) if s.name in names]
            train = kept
        else:
            val = load_split_sequences(data, "test", cfg.features)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(f"{data}: {e}" if str(data) not in str(e) else str(e)) from e
    if tc.reverse_categories:
        from grip.cli.recordings import reversed_training_recordings
        from grip.kinematics.dataset import sequence_arrays

        recs = reversed_training_recordings(data, stems, tc.reverse_categories)
        train += [sequence_arrays(r, cfg.features) for r in recs]
    n_frames = sum(len(s.x) for s in train)
    what = "held-out training" if tc.val_source == "holdout" else "test"
    print(f"loaded {len(train)} train / {len(val)} validation ({what}) sequences "
          f"({n_frames} train frames) in {time.perf_counter() - t0:.1f} s")  # fmt: skip
    try:
        trainer = Trainer(cfg, train, val, out)
        info = {"data": str(data.resolve()), "train_frames": n_frames}
        if init is not None:
            trainer.init_from(init)
            info["init"] = str(init.resolve())
            print(f"initialised from {init}")
    except (FileNotFoundError, ValueError) as e:
        raise CliError(str(e)) from e
    out.mkdir(parents=True, exist_ok=True)
    return fit_run(trainer, cfg, out, info, epochs=cfg.total_epochs(), postfix="phase")


def fit_run(trainer, cfg, out: Path, info: dict, *, epochs: int, postfix: str) -> int:
    """The training loop of ``grip train-kin`` and ``grip train-baseline``: resume ``trainer``
    from ``OUT/last.pt`` when it exists, write the run config (with ``info``), fit with a
    progress bar (``postfix``: the progress key shown next to the loss) and TensorBoard scalars,
    and print the throughput and where the checkpoints are."""
    from torch.utils.tensorboard import SummaryWriter
    from tqdm import tqdm

    from grip.cli.errors import CliError
    from grip.kinematics.train import write_run_config

    last = out / "last.pt"
    if last.exists():
        try:
            trainer.load(last)
        except ValueError as e:
            raise CliError(f"{e}; use another --out or the same settings") from e
        print(f"resuming {last} at epoch {trainer.epoch}/{epochs}")
    write_run_config(out, cfg, info)
    tc = cfg.train
    total = epochs * tc.steps_per_epoch
    done = trainer.epoch * tc.steps_per_epoch
    with SummaryWriter(str(out / "tb")) as writer, tqdm(total=total, initial=done,
                                                          unit="step") as bar:  # fmt: skip

        def progress(p: dict) -> None:
            bar.set_postfix({postfix: p[postfix], "loss": f"{p['loss']:.4f}"})
            bar.update(1)

        t1 = time.perf_counter()
        trainer.fit(writer=writer, progress=progress)
    dt = time.perf_counter() - t1
    steps = total - done
    if steps:
        fps = steps * tc.batch_size * tc.window_frames / dt
        print(f"trained {steps} steps in {dt:.0f} s ({steps / dt:.3f} steps/s, {fps:.0f} frames/s)")
        print(f"{trainer.wall_s():.0f} s of training over all sittings of the run (epochs "
              "with their validation)")  # fmt: skip
    if trainer.history:
        print(f"final validation losses: {trainer.history[-1]['val']}")
    print(f"checkpoints: {out / 'last.pt'} and {out / 'best.pt'}")
    return 0


def add_eval_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "eval-kin",
        help="evaluate KinematicsNet on the test split of a dataset",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Run KinematicsNet on the 500-frame segments of a dataset's test split (each\n"
            "initialised from its first frame's ground truth) and report root-relative MPJPE,\n"
            "MPJRE, leaf-velocity error and the error of the integrated root trajectory, per\n"
            "motion category, as a Markdown table, a plot and (with --json) the overall figures\n"
            "under PEL_MPJPE_mm, MPJRE_deg, leaf_vel_err_mps, frames."
        ),
        epilog="example: grip eval-kin --model runs/kin/best.pt --data data/prism_synth "
        "--json kin.json --out runs/kin/eval",
    )
    p.add_argument("--model", type=Path, default=None,
                   help="checkpoint (default: the shipped one in grip/assets)")  # fmt: skip
    p.add_argument("--data", required=True, type=Path, help="dataset folder (with split.json)")
    p.add_argument("--split", default="test", choices=("train", "test"), help="split to use")
    p.add_argument("--json", type=Path, default=None, metavar="PATH", help="write the figures")
    p.add_argument("--out", type=Path, default=None, help="folder for the table and the plot")
    p.add_argument("--segment-frames", type=int, default=500, help="segment length (frames)")
    p.add_argument(
        "--joints",
        default="pose",
        choices=("pose", "fp"),
        help="joints of the position metrics: the estimated rotations posed on the subject's "
        "body (default, what every method is judged on) or the FP stage's direct estimate",
    )
    add_tta_argument(p)
    p.add_argument(
        "--sweep",
        type=Path,
        default=None,
        metavar="DIR",
        help="evaluate every run of a sensor sweep folder ('grip train-kin --sweep') "
        "and print a table like GRIP Table 3 instead",
    )
    add_limit_arguments(p)
    p.set_defaults(func=cmd_eval)


def cmd_eval(args: argparse.Namespace) -> int:
    import json

    from tqdm import tqdm

    from grip.cli.errors import CliError
    from grip.cli.recordings import kin_checkpoint
    from grip.core.atomic import atomic_write_text
    from grip.kinematics.evaluate import (
        aggregate,
        evaluate_recordings,
        markdown_table,
        plot_categories,
    )
    from grip.kinematics.inference import KinematicsEstimator

    limits_from_args(args)
    if args.sweep is not None:
        if args.model is not None:
            raise CliError("give --model or --sweep, not both")
        return _eval_sweep(args)
    model = kin_checkpoint(args.model, "--model")
    try:
        est = KinematicsEstimator.from_checkpoint(model, tta=args.tta)
    except ValueError as e:
        raise CliError(str(e)) from e
    errors: list[tuple[str, str]] = []
    recs = _load_split(args.data, args.split, errors)
    with tqdm(unit="segment", desc="evaluating") as bar:
        rows = evaluate_recordings(est, recs, args.segment_frames, progress=bar.update,
                                   joints=args.joints)  # fmt: skip
    agg = aggregate(rows)
    table = markdown_table(agg)
    print(table)
    overall = agg["overall"]
    figures = {k: overall[k] for k in ("PEL_MPJPE_mm", "MPJRE_deg", "leaf_vel_err_mps",
                                       "trans_err_m", "MPJPE_mm", "PA_MPJPE_mm", "frames",
                                       "segments")}  # fmt: skip
    figures["model"] = str(model)
    figures["joints"] = args.joints
    figures["tta"] = args.tta
    if args.json:
        atomic_write_text(args.json, json.dumps(figures | {"categories": agg["categories"]},
                                                indent=1))  # fmt: skip
        print(f"wrote {args.json}")
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(args.out / "table.md", table + "\n")
        plot_categories(agg, args.out / "categories.png")
        print(f"wrote {args.out / 'table.md'} and {args.out / 'categories.png'}")
    return _exit_status(errors)


def _load_split(data: Path, split: str, errors: list[tuple[str, str]]) -> list:
    """The recordings of a split; unreadable files are reported, skipped and put in
    ``errors``."""
    from grip.cli.recordings import load_recordings, split_paths

    return load_recordings(split_paths(data, split), errors=errors)


def _exit_status(errors: list[tuple[str, str]]) -> int:
    from grip.cli.recordings import exit_status

    return exit_status(errors)


def _eval_sweep(args: argparse.Namespace) -> int:
    import json

    from tqdm import tqdm

    from grip.cli.errors import CliError
    from grip.core.atomic import atomic_write_text
    from grip.kinematics.evaluate import aggregate, evaluate_recordings
    from grip.kinematics.inference import KinematicsEstimator
    from grip.kinematics.sweep import find_runs, sweep_table

    runs = find_runs(args.sweep)
    if not runs:
        raise CliError(f"{args.sweep}: no sweep runs (imu<N>_press|nopress/best.pt); train them "
                       "with 'grip train-kin --sweep --out DIR'")  # fmt: skip
    errors: list[tuple[str, str]] = []
    recs = _load_split(args.data, args.split, errors)
    results = []
    for s, ck in tqdm(runs, unit="config", desc="sweep"):
        try:
            est = KinematicsEstimator.from_checkpoint(ck)
        except ValueError as e:
            raise CliError(str(e)) from e
        if tuple(est.cfg.features.sites) != s.sites or est.cfg.features.insoles != s.insoles:
            raise CliError(f"{ck}: trained on {est.cfg.features.sites} "
                           f"(insoles={est.cfg.features.insoles}), not the {s.name} "
                           "configuration its folder names")  # fmt: skip
        results.append(
            (s, aggregate(evaluate_recordings(est, recs, args.segment_frames, joints=args.joints)))
        )
    table = sweep_table([(s, a["overall"]) for s, a in results])
    print(table)
    if args.json:
        data = {s.name: {"n_imu": s.n_imu, "insoles": s.insoles, "sites": list(s.sites),
                         **a["overall"]} for s, a in results}  # fmt: skip
        atomic_write_text(args.json, json.dumps(data, indent=1))
        print(f"wrote {args.json}")
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(args.out / "sweep.md", table + "\n")
        print(f"wrote {args.out / 'sweep.md'}")
    return _exit_status(errors)
