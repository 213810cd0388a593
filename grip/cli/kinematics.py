"""``grip kin train|eval|export``: KinematicsNet, and the TransPose / PIP kinematics nets."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from grip.cli.recordings import (
    add_init_argument,
    add_limit_arguments,
    add_tta_argument,
    limits_from_args,
)

BASELINE_NAMES: tuple[str, ...] = ("transpose", "pip")
"""The baselines whose kinematics nets ``grip kin train --baseline`` trains."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grip kin`` and its subcommands on the ``grip`` subparsers."""
    from grip.cli.common import PRECISIONS, add_group

    ksub = add_group(sub, "kin", "train, evaluate and export KinematicsNet (or a baseline's "
                     "kinematics nets)", "The kinematics estimators: KinematicsNet (GRIP's), and "
                     "the TransPose and PIP networks the benchmark compares with.")  # fmt: skip
    p = ksub.add_parser(
        "train",
        help="train KinematicsNet (or, with --baseline, TransPose / PIP) on a dataset",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Train the four-stage KinematicsNet (LP -> FP -> FA -> LV) on the train split of a\n"
            "dataset folder: stage-wise, then jointly, with MSE + forward-kinematics losses,\n"
            "input noise and random-yaw augmentation. Checkpoints every epoch to RUN/last.pt\n"
            "(best validation: RUN/best.pt); running the same command again resumes.\n"
            "--baseline NAME trains a baseline's kinematics networks instead, adapted to 4 IMUs\n"
            "(BASELINES_AND_METRICS.md section 2): TransPose's Pose-S1/S2/S3 and Trans-B1/B2,\n"
            "or PIP's P_L, P_A, R_A, V_A, C_F with the learned RNN initialisation; --insoles\n"
            "trains its '+I' variant (insole values appended to every input).\n"
            "TensorBoard: tensorboard --logdir RUN/tb"
        ),
        epilog="example: grip kin train --data data/prism_synth --out runs/kin\n"
        "         grip kin train --data data/prism_synth --out runs/kin_small "
        "--set hidden=128 --set train.joint_epochs=5\n"
        "         grip kin train --data data/prism_synth --out runs/sweep --sweep "
        "--config configs/kinematics/sweep.toml\n"
        "         grip kin train --data data/prism_synth --out runs/kin_ft "
        "--init runs/kin/last.pt --config configs/kinematics/finetune.toml\n"
        "         grip kin train --data data/prism_synth --out runs/kin_lr --tune space.toml "
        "[--ray HEAD:6379]   (docs/cluster.md)\n"
        "         grip kin train --baseline transpose --data data/prism_synth --out runs/tp4\n"
        "         grip kin train --baseline pip --insoles --data data/prism_synth --out runs/pip4i",
    )
    p.add_argument("--data", required=True, type=Path, help="dataset folder (with split.json)")
    p.add_argument("--out", required=True, type=Path, help="run folder (created or resumed)")
    p.add_argument("--baseline", choices=BASELINE_NAMES, default=None,
                   help="train this baseline's kinematics nets instead of KinematicsNet")
    p.add_argument("--config", type=Path, default=None,
                   help="TOML overrides (default: configs/kinematics/default.toml, with "
                   "--baseline configs/baselines/NAME.toml, if present)")  # fmt: skip
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override one setting, e.g. --set train.lr=3e-4 (repeatable)")
    p.add_argument("--threads", type=int, default=0, help="torch threads (default: all cores)")
    p.add_argument("--insoles", action="store_true",
                   help="with --baseline: the '+I' variant (same as net.insoles=true)")
    p.add_argument("--init", type=Path, default=None, metavar="CKPT",
                   help="fine-tune: start from the weights and normaliser of this checkpoint (a "
                   "run's last.pt or an export with the same network and sensors) instead of "
                   "random weights; usually with --set train.stage_epochs=0 (ignored when OUT "
                   "resumes)")  # fmt: skip
    p.add_argument("--sweep", action="store_true",
                   help="sensor sweep (GRIP Table 3): train one run per IMU count, with and "
                   "without insoles, in OUT/imu<N>_press|nopress (finished runs are skipped, "
                   "interrupted ones resume); evaluate with 'grip kin eval --sweep OUT'")
    p.add_argument("--imus", default="2,3,4,6", metavar="N,N,...",
                   help="IMU counts of --sweep (feet, +left wrist, +right wrist, +pelvis, +head; "
                   "default 2,3,4,6)")  # fmt: skip
    from grip.cli.cluster import add_tune_arguments

    add_tune_arguments(p)
    p.set_defaults(func=cmd_train)
    add_eval_parser(ksub)
    x = ksub.add_parser(
        "export",
        help="write a small inference-only copy of a KinematicsNet or baseline checkpoint, or "
        "KinematicsNet's streaming step as ONNX",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "By the suffix of --out:\n"
            "  FILE.pt    drop the optimiser state and store the weights as float16 (or int8\n"
            "             with a scale per row, or float32): the form in which the default\n"
            "             models ship (grip/assets/kinematics_default.pt, transpose4.pt,\n"
            "             pip4.pt)\n"
            "  FILE.onnx  KinematicsNet's streaming step for use outside Python, one frame at a\n"
            "             time: FILE.onnx maps 'features' (B, F) raw sensor features of one\n"
            "             frame (the input normaliser is inside the graph) and the LSTM states\n"
            "             'h', 'c' (4 L, B, H) to 'outputs' (B, 249) = lp|fp|fa|lv and 'h_out',\n"
            "             'c_out'; FILE_init.onnx maps 'first_state' (B, 249), the calibration\n"
            "             pose in the output layout, to the initial 'h', 'c'. float32, no\n"
            "             test-time augmentation; KinematicsNet only (not the baselines). Needs\n"
            "             the onnx package (docs/exports.md: layouts, running with onnxruntime)"
        ),
        epilog="example: grip kin export runs/kin/best.pt --out grip/assets/kinematics_default.pt\n"
        "         grip kin export runs/tp4/best.pt --out grip/assets/transpose4.pt\n"
        "         grip kin export grip/assets/kinematics_default.pt --out kin.onnx",
    )
    x.add_argument("checkpoint", type=Path,
                   help="training checkpoint (RUN/best.pt) or an export of one")  # fmt: skip
    x.add_argument("--out", required=True, type=Path, metavar="FILE",
                   help="output, written atomically: FILE.pt (an inference copy) or FILE.onnx "
                   "(the ONNX step, and FILE_init.onnx beside it)")  # fmt: skip
    x.add_argument("--precision", choices=PRECISIONS, default=None,
                   help="weight storage of a .pt (default fp16; int8 halves the file again); an "
                   "ONNX graph is fp32")  # fmt: skip
    x.set_defaults(func=cmd_export)


def cmd_export(args: argparse.Namespace) -> int:
    from grip.cli.common import write_artifact
    from grip.cli.errors import CliError

    if args.out.suffix.lower() != ".onnx":
        from grip.kinematics.train import export_for_inference

        return write_artifact(args.out, lambda: export_for_inference(
            args.checkpoint, args.out, precision=args.precision or "fp16"))  # fmt: skip
    if args.precision not in (None, "fp32"):
        raise CliError(f"--precision {args.precision}: an ONNX graph holds fp32 weights")

    def write() -> tuple[int, str]:
        from grip.kinematics.onnx import export_kinematics_onnx

        try:
            (_, size), (first, first_size) = export_kinematics_onnx(args.checkpoint, args.out)
        except ImportError as e:
            raise CliError(str(e)) from e
        return size, (f", the ONNX step; and {first} ({first_size / 1e6:.1f} MB), its initial "
                      "LSTM states from the calibration pose")

    return write_artifact(args.out, write)


def cmd_train(args: argparse.Namespace) -> int:
    import torch

    from grip.cli.errors import CliError
    from grip.cli.paths import load_run_config
    from grip.kinematics.config import KinematicsRunConfig

    if args.tune is not None or args.ray is not None:
        return _tune(args)
    if args.baseline is not None:
        for flag, given in (("--init", args.init is not None), ("--sweep", args.sweep)):
            if given:
                raise CliError(f"{flag} is KinematicsNet's; it does not combine with --baseline")
        return cmd_train_baseline(args)
    if args.insoles:
        raise CliError("--insoles picks a baseline's '+I' variant: give --baseline too (for "
                       "KinematicsNet: --set features.insoles=true)")  # fmt: skip
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
        if carried_over(args.out / s.name):
            print(f"      kept: {args.out / s.name / 'best.pt'} holds a finished run's exported "
                  "weights (no last.pt to resume)")  # fmt: skip
            continue
        _train_one(args.data, args.out / s.name, run_cfg)
    print(f"sweep finished; evaluate with: grip kin eval --sweep {args.out} --data {args.data}")
    return 0


def _tune(args: argparse.Namespace) -> int:
    """``--tune SPACE.toml``: a sweep of runs (:func:`grip.cli.cluster.tune_train`), each trial
    one run of KinematicsNet (or of ``--baseline``), the table sorted by ``val/total``."""
    from grip.cli.cluster import kin_metrics, tune_train
    from grip.cli.errors import CliError
    from grip.cli.paths import load_run_config
    from grip.kinematics.config import KinematicsRunConfig

    if args.sweep:
        raise CliError("--tune sweeps --set values; it does not combine with --sweep (the "
                       "sensor sweep)")  # fmt: skip

    def check(sets: list[str]) -> None:
        if args.baseline is not None:
            _baseline_config(args, sets)
        else:
            load_run_config(args.config, "kinematics", KinematicsRunConfig(), [*args.set, *sets])

    return tune_train(args, check, kin_metrics, "val/total", "min")


def _baseline_config(args: argparse.Namespace, extra: list[str] | None = None):
    """The settings of ``--baseline``'s run: its TOML (default ``configs/baselines/NAME.toml``),
    ``--set`` and ``extra`` overrides, ``--insoles``."""
    from grip.cli.paths import REPO_ROOT, load_run_config
    from grip.kinematics.baseline_config import default_run_config

    config = args.config
    if config is None:
        candidate = REPO_ROOT / "configs" / "baselines" / f"{args.baseline}.toml"
        config = candidate if candidate.is_file() else None
    overrides = [*args.set, *(extra or []), *(["net.insoles=true"] if args.insoles else [])]
    return load_run_config(config, "baselines", default_run_config(args.baseline), overrides)


def cmd_train_baseline(args: argparse.Namespace) -> int:
    """Train the kinematics nets of baseline ``args.baseline`` (resumes ``args.out``)."""
    import torch

    from grip.cli.errors import CliError
    from grip.kinematics.baseline_config import n_inputs
    from grip.kinematics.baseline_train import BaselineTrainer, load_baseline_sequences

    cfg = _baseline_config(args)
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
    print(f"{args.baseline}{variant}: {n_inputs(cfg)} inputs; loaded {len(train)} train / "
          f"{len(val)} test sequences ({n_frames} train frames) in "
          f"{time.perf_counter() - t0:.1f} s")  # fmt: skip
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    try:
        trainer = BaselineTrainer(cfg, train, val, out)
    except ValueError as e:
        raise CliError(str(e)) from e
    info = {"method": args.baseline, "data": str(args.data.resolve()), "train_frames": n_frames}
    return fit_run(trainer, cfg, out, info, epochs=cfg.train.epochs, postfix="epoch")


def carried_over(run: Path) -> bool:
    """Whether a sweep run folder holds a finished run carried over as its exported weights
    (``best.pt`` from ``grip kin export``, without the ``last.pt`` checkpoint a resume needs):
    the sweep keeps it instead of training it again (a sweep moved between machines with only
    its small exports, ``experiments/resume/``)."""
    return (run / "best.pt").is_file() and not (run / "last.pt").exists()


def _train_one(data: Path, out: Path, cfg, init: Path | None = None) -> int:
    from grip.cli.errors import CliError
    from grip.kinematics.dataset import (
        dataset_groups,
        fold_split,
        holdout_split,
        load_split_sequences,
        sequence_sources,
    )
    from grip.kinematics.train import Trainer

    t0 = time.perf_counter()
    tc = cfg.train
    try:
        train = load_split_sequences(data, "train", cfg.features)
        groups = dataset_groups(data)
        if tc.val_source == "holdout":
            train, val = holdout_split(train, tc.val_fraction, tc.seed, groups)
        elif tc.val_source == "fold":
            train, val = fold_split(train, tc.folds, tc.fold, tc.seed, groups)
        else:
            val = load_split_sequences(data, "test", cfg.features)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(f"{data}: {e}" if str(data) not in str(e) else str(e)) from e
    n_frames = sum(len(s.x) for s in train)
    what = {"holdout": "held-out training", "fold": f"fold {tc.fold} of {tc.folds}"}.get(
        tc.val_source, "test")
    print(f"loaded {len(train)} train / {len(val)} validation ({what}) sequences "
          f"({n_frames} train frames) in {time.perf_counter() - t0:.1f} s")  # fmt: skip
    try:
        sources = sequence_sources(train, groups)
        trainer = Trainer(cfg, train, val, out, sources=sources)
        for what, of in (("source", {q.name: sources[q.name] for q in train}),
                         ("category", {q.name: q.category for q in train})):  # fmt: skip
            share: dict[str, float] = {}
            for seq, w in zip(train, trainer.weights, strict=True):
                share[of[seq.name]] = share.get(of[seq.name], 0.0) + float(w)
            if len(share) > 1:
                ranked = sorted(share.items(), key=lambda kv: -kv[1])
                print(f"training windows by {what}: "
                      + ", ".join(f"{k} {100 * v:.1f} %" for k, v in ranked))  # fmt: skip
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
    """The training loop of ``grip kin train`` (KinematicsNet and baselines): resume ``trainer``
    from ``OUT/last.pt`` when it exists, write the run config (with ``info``), fit with a
    progress bar (``postfix``: the progress key shown next to the loss) and TensorBoard scalars,
    and print the throughput and where the checkpoints are."""
    from torch.utils.tensorboard import SummaryWriter
    from tqdm import tqdm

    from grip.cli.errors import CliError

    last = out / "last.pt"
    if last.exists():
        try:
            trainer.load(last)
        except ValueError as e:
            raise CliError(f"{e}; use another --out or the same settings") from e
        print(f"resuming {last} at epoch {trainer.epoch}/{epochs}")
    trainer.rundir.write_config(cfg, **info)
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
    """Register ``grip kin eval`` on the ``grip kin`` subparsers."""
    p = sub.add_parser(
        "eval",
        help="evaluate KinematicsNet on the test split of a dataset",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Run KinematicsNet on the 500-frame segments of a dataset's test split (each\n"
            "started from its first frame's ground truth, or standing with --init standing)\n"
            "and report root-relative MPJPE (all frames, and after each segment's first\n"
            "second), MPJRE, leaf-velocity error and the error of the integrated root\n"
            "trajectory, per motion category and per source, as Markdown tables, a plot and\n"
            "(with --json) the overall figures under PEL_MPJPE_mm, PEL_MPJPE_settled_mm,\n"
            "MPJRE_deg, leaf_vel_err_mps, frames."
        ),
        epilog="example: grip kin eval --model runs/kin/best.pt --data data/prism_synth "
        "--json kin.json --out runs/kin/eval",
    )
    p.add_argument("--model", type=Path, default=None,
                   help="checkpoint (default: the shipped one in grip/assets)")  # fmt: skip
    p.add_argument("--data", required=True, type=Path, help="dataset folder (with split.json)")
    p.add_argument("--split", default="test", choices=("train", "test", "all", "held-out"),
                   help="dataset split (default test); held-out: the training people a fold "
                   "model (train.val_source=fold) never saw, the people whose estimates it "
                   "makes for a cross-fitted reference set")  # fmt: skip
    p.add_argument("--category", action="append", default=[], metavar="GLOB",
                   help="only these motion categories (glob, repeatable)")  # fmt: skip
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
    add_init_argument(p)
    p.add_argument(
        "--sweep",
        type=Path,
        default=None,
        metavar="DIR",
        help="evaluate every run of a sensor sweep folder ('grip kin train --sweep') "
        "and print a table like GRIP Table 3 instead",
    )
    p.add_argument("--workers", type=int, default=1, metavar="K",
                   help="processes scoring runs of consecutive segments, one thread each "
                   "(default 1: in this process)")  # fmt: skip
    from grip.cli.cluster import add_ray_argument

    add_ray_argument(p, "runs of segments")
    add_limit_arguments(p)
    p.set_defaults(func=cmd_eval)


def cmd_eval(args: argparse.Namespace) -> int:
    import json

    from tqdm import tqdm

    from grip.cli.cluster import command_pool, ray_args
    from grip.cli.errors import CliError
    from grip.cli.recordings import kin_checkpoint
    from grip.core.atomic import atomic_write_text
    from grip.eval.kinematics import aggregate, markdown_table
    from grip.eval.plots import plot_categories
    from grip.kinematics.inference import KinematicsEstimator

    limits_from_args(args)
    ray_args(args)
    if args.workers < 1:
        raise CliError(f"--workers must be >= 1, got {args.workers}")
    if args.sweep is not None:
        if args.model is not None or args.split == "held-out":
            raise CliError("--sweep scores a split of the data: not with --model or --split "
                           "held-out")  # fmt: skip
        return _eval_sweep(args)
    model = kin_checkpoint(args.model, "--model")
    try:
        est = KinematicsEstimator.from_checkpoint(model, tta=args.tta)
    except ValueError as e:
        raise CliError(str(e)) from e
    errors: list[tuple[str, str]] = []
    segs = _split_segments(args, errors, _eval_files(args, est))
    with command_pool(args, args.workers) as pool, tqdm(total=len(segs), unit="segment",
                                                         desc="evaluating") as bar:  # fmt: skip
        rows = _evaluate(est, model, segs, pool, progress=bar.update, joints=args.joints,
                         init=args.init, tta=args.tta)  # fmt: skip
    sources = _segment_sources(args.data, segs)
    for r in rows:
        r["source"] = sources[r["segment"]]
    agg = aggregate(rows)
    table = markdown_table(agg)
    by_source = aggregate(rows, "source")
    table += "\n\n" + markdown_table(by_source, "source")
    print(table)
    overall = agg["overall"]
    figures = {k: overall[k] for k in ("PEL_MPJPE_mm", "PEL_MPJPE_settled_mm", "MPJRE_deg",
                                       "leaf_vel_err_mps",
                                       "trans_err_m", "MPJPE_mm", "PA_MPJPE_mm", "frames",
                                       "segments")}  # fmt: skip
    figures["model"] = str(model)
    figures["joints"] = args.joints
    figures["tta"] = args.tta
    figures["init"] = args.init
    if args.json:
        atomic_write_text(args.json, json.dumps(figures | {"categories": agg["categories"],
                                                           "sources": by_source["categories"]},
                                                indent=1))  # fmt: skip
        print(f"wrote {args.json}")
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(args.out / "table.md", table + "\n")
        plot_categories(agg, args.out / "categories.png")
        print(f"wrote {args.out / 'table.md'} and {args.out / 'categories.png'}")
    return _exit_status(errors)


def _evaluate(est, model: Path, segs: list, pool, **kw) -> list[dict]:
    """The rows of ``est`` (loaded from ``model``) on ``segs``: in this process without a pool,
    else in its workers (a worker process that died: a :class:`CliError`)."""
    from grip.cli.errors import CliError
    from grip.eval.kinematics import evaluate_in_pool, evaluate_segments
    from grip.eval.segments import BenchError

    tta = kw.pop("tta", "none")
    if pool is None:
        return evaluate_segments(est, segs, **kw)
    try:
        return evaluate_in_pool(str(Path(model).resolve()), segs, pool, tta=tta, **kw)
    except BenchError as e:
        raise CliError(str(e)) from e


def _segment_sources(data: Path, segs: list) -> dict[str, str]:
    """Segment id -> its clip's source (:func:`prism_tools.chunking.clip_source`)."""
    from grip.kinematics.dataset import clip_of, dataset_groups
    from prism_tools.chunking import clip_source

    try:
        groups = dataset_groups(data)
    except (OSError, ValueError):
        groups = {}
    return {s.id: clip_source(clip_of(s.path.stem), groups.get(clip_of(s.path.stem)))
            for s in segs}  # fmt: skip


def _eval_files(args: argparse.Namespace, est) -> list[Path]:
    """The recording files ``grip kin eval`` scores: those of ``--split``, or with ``held-out``
    the training files of the people the fold model ``est`` held out
    (:func:`grip.kinematics.dataset.fold_split`'s rule)."""
    from grip.cli.errors import CliError
    from grip.cli.recordings import split_paths
    from grip.kinematics.dataset import dataset_groups, group_fold, sequence_group

    if args.split != "held-out":
        return split_paths(args.data, args.split)
    t = est.cfg.train
    if t.val_source != "fold":
        raise CliError(f"--split held-out needs a fold model (train.val_source = 'fold'); "
                       f"{args.model or 'the shipped model'} was validated on "
                       f"'{t.val_source}'")  # fmt: skip
    groups = dataset_groups(args.data)
    return [f for f in split_paths(args.data, "train")
            if group_fold(sequence_group(f.stem, groups), t.folds, t.seed) == t.fold]


def _split_segments(args: argparse.Namespace, errors: list[tuple[str, str]],
                    files: list[Path] | None = None) -> list:  # fmt: skip
    """The segments of ``files`` (default: those of ``--split``; tails down to 10 frames
    kept); unreadable files are reported, skipped and put in ``errors``."""
    from grip.cli.errors import CliError
    from grip.cli.recordings import skip_file, split_paths
    from grip.eval.kinematics import MIN_SEGMENT_FRAMES
    from grip.eval.segments import BenchError, list_segments

    unreadable: list[tuple[str, str]] = []
    try:
        files = split_paths(args.data, args.split) if files is None else files
        segs = list_segments(files, args.segment_frames,
                             args.category, errors=unreadable,
                             min_frames=MIN_SEGMENT_FRAMES)  # fmt: skip
    except BenchError as e:
        raise CliError(str(e)) from e
    finally:
        for f, why in unreadable:
            skip_file(errors, f, why)
    return segs


def _exit_status(errors: list[tuple[str, str]]) -> int:
    from grip.cli.recordings import exit_status

    return exit_status(errors)


def _eval_sweep(args: argparse.Namespace) -> int:
    import json

    from tqdm import tqdm

    from grip.cli.cluster import command_pool
    from grip.cli.errors import CliError
    from grip.core.atomic import atomic_write_text
    from grip.eval.kinematics import aggregate
    from grip.kinematics.inference import KinematicsEstimator
    from grip.kinematics.sweep import find_runs, sweep_table

    runs = find_runs(args.sweep)
    if not runs:
        raise CliError(f"{args.sweep}: no sweep runs (imu<N>_press|nopress/best.pt); train them "
                       "with 'grip kin train --sweep --out DIR'")  # fmt: skip
    errors: list[tuple[str, str]] = []
    segs = _split_segments(args, errors)
    results = []
    with command_pool(args, args.workers) as pool:
        for s, ck in tqdm(runs, unit="config", desc="sweep"):
            try:
                est = KinematicsEstimator.from_checkpoint(ck)
            except ValueError as e:
                raise CliError(str(e)) from e
            if tuple(est.cfg.features.sites) != s.sites or est.cfg.features.insoles != s.insoles:
                raise CliError(f"{ck}: trained on {est.cfg.features.sites} "
                               f"(insoles={est.cfg.features.insoles}), not the {s.name} "
                               "configuration its folder names")  # fmt: skip
            results.append((s, aggregate(_evaluate(est, ck, segs, pool, joints=args.joints))))
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
