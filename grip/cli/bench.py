"""``grip bench``: GRIP and the baselines on the same test segments, with GRIP's metrics."""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from grip.cli.recordings import (
    add_init_argument,
    add_limit_arguments,
    add_pace_arguments,
    add_restart_argument,
    limits_from_args,
)


def shipped_methods() -> list[str]:
    """Registered methods whose default models exist in this checkout."""
    from grip.assets import SHIPPED_BASELINES, SHIPPED_POLICY
    from grip.eval.methods import METHODS

    files = {**SHIPPED_BASELINES, "grip": SHIPPED_POLICY}
    return [n for n in METHODS if n not in files or Path(files[n]).is_file()]


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "bench",
        help="benchmark methods on the test segments (GRIP Table 1 metrics, tables, plots)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Run every method on the same segments of a dataset split (500 frames by default,\n"
            "each started from the ground truth at its first frame: the GRIP protocol; --init\n"
            "standing: from the standing pose, as without motion capture), in parallel worker\n"
            "processes, and write OUT/results.json ({method: {metric: value}}, with 'init'),\n"
            "OUT/results.csv, OUT/segments.csv, OUT/table.md (the GRIP Table 1 layout plus\n"
            "runtime and failures) and plots (per-joint errors, the trajectory and the ground\n"
            "reaction force of a sample segment). Finished segments are kept in OUT/segments:\n"
            "running the same command again resumes; a resume is refused when a model file or\n"
            "a recording has other contents than those results were computed from (compared by\n"
            "SHA-256; use another --out). A method that raises on a segment is counted as a\n"
            "failure of that segment."
        ),
        epilog="example: grip bench --data data/prism_synth --methods kinematics --out runs/bench\n"
        "         grip bench --data data/prism_synth --methods kinematics --out runs/bench_s "
        "--sweep runs/sweep --sensors imu2_nopress,imu4_press",
    )
    p.add_argument("--data", required=True, type=Path, help="dataset folder (with split.json)")
    p.add_argument("--out", required=True, type=Path, help="output folder (created or resumed)")
    p.add_argument("--methods", default=None, metavar="NAME,NAME,...",
                   help="methods to run, e.g. pip,transpose,kinematics,grip (default: every "
                   "registered method whose models ship; an unknown name lists them)")  # fmt: skip
    p.add_argument("--split", default="test", choices=("train", "test", "all"))
    p.add_argument("--category", action="append", default=[], metavar="GLOB",
                   help="only these motion categories (glob, repeatable)")  # fmt: skip
    p.add_argument("--segment-frames", type=int, default=500, help="frames per segment")
    p.add_argument("--segments", type=int, default=0, metavar="N",
                   help="at most N segments, spread over the categories (0: all)")  # fmt: skip
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="worker processes, one thread each (1: run in this process; "
                   "default: the number of cores)")  # fmt: skip
    p.add_argument("--batch", type=int, default=16, metavar="N",
                   help="segments method grip plays side by side in each worker, one "
                   "controller forward per frame over all of them (default 16; 1: one after "
                   "another); the numbers of each alone up to the float32 rounding of a "
                   "batched forward, which a simulation can amplify")  # fmt: skip
    p.add_argument("--kin", type=Path, default=None,
                   help="KinematicsNet checkpoint (default: the shipped one)")  # fmt: skip
    p.add_argument("--policy", type=Path, default=None,
                   help="GRIP policy export for method grip (default: the shipped one)")
    p.add_argument("--transpose", type=Path, default=None,
                   help="TransPose nets for method transpose (default: the shipped ones)")
    p.add_argument("--pip", type=Path, default=None,
                   help="PIP nets for method pip (default: the shipped ones)")
    p.add_argument("--sensors", default=None, metavar="NAME,NAME,...",
                   help="sensor configurations of a 'grip kin train --sweep' folder "
                   "(imu<N>_press|nopress), GRIP Table 3; methods that cannot change sensors "
                   "are skipped")  # fmt: skip
    p.add_argument("--sweep", type=Path, default=None, metavar="DIR",
                   help="the sweep folder the --sensors configurations are read from")  # fmt: skip
    p.add_argument("--save-recons", action="store_true",
                   help="save every reconstruction (OUT/recons/<method>/<seg>.npz)")  # fmt: skip
    p.add_argument("--retry-failed", action="store_true",
                   help="run segments that failed in an earlier run again")  # fmt: skip
    add_init_argument(p, "the methods (KinematicsNet's LSTMs and root, GRIP's humanoid, "
                      "TransPose's root, PIP's learned initialisation and its physics' first "
                      "state)", "; a folder resumes only with the --init it was written "
                      "with")  # fmt: skip
    add_restart_argument(p)
    add_pace_arguments(p)
    from grip.cli.cluster import add_ray_argument

    add_ray_argument(p, "units of work (a method on a segment, or on --batch N of them)")
    add_limit_arguments(p)
    p.set_defaults(func=cmd_bench)


def cmd_bench(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from grip.cli.cluster import ray_args, ray_pool
    from grip.cli.errors import CliError
    from grip.cli.recordings import exit_status, lost_gap, pace_keeper, skip_file, split_paths
    from grip.eval.bench import write_outputs
    from grip.eval.methods import MethodOptions, parse_method_names, sensor_set
    from grip.eval.report import method_table
    from grip.eval.runner import prepare_runs, run_bench
    from grip.eval.segments import BenchError, list_segments, select_segments

    limits_from_args(args)
    pace_keeper(args)  # (a bad --pace-gain or --pace-lead-max refused by name)
    lost_gap(args)
    ray_args(args)
    if args.workers < 1:
        raise CliError(f"--workers must be >= 1, got {args.workers}")
    if args.batch < 1:
        raise CliError(f"--batch must be >= 1, got {args.batch}")
    if args.segment_frames < 3:
        raise CliError(f"--segment-frames must be >= 3, got {args.segment_frames}")
    sensors: list[str] = []
    skipped: list[tuple[str, str]] = []  # (file, reason) of unreadable recordings
    unreadable: list[tuple[str, str]] = []
    try:
        names = parse_method_names(args.methods or ",".join(shipped_methods()))
        if args.sensors is not None:
            sensors = [s.strip() for s in args.sensors.split(",") if s.strip()]
            if not sensors:
                raise ValueError("--sensors: no configuration given")
            for s in sensors:
                sensor_set(s)
            if args.sweep is None:
                raise ValueError("--sensors needs --sweep DIR (the 'grip kin train --sweep' "
                                 "folder)")  # fmt: skip
        elif args.sweep is not None:
            raise ValueError("--sweep is only used with --sensors")
        segs = list_segments(split_paths(args.data, args.split), args.segment_frames,
                             args.category, errors=unreadable)  # fmt: skip
        segs = select_segments(segs, args.segments)
        options = MethodOptions(kin_checkpoint=args.kin, sweep_dir=args.sweep,
                                policy_checkpoint=args.policy,
                                transpose_checkpoint=args.transpose, pip_checkpoint=args.pip,
                                init=args.init, restart=args.restart,
                                lost_gap_m=args.lost_gap,
                                pace_gain=args.pace_gain,
                                pace_lead_max_m=args.pace_lead_max,
                                lean_gain_deg=args.lean_gain,
                                lean_max_deg=args.lean_max)  # fmt: skip
        runs, built = prepare_runs(names, options, sensors)
    except (BenchError, ValueError, FileNotFoundError) as e:
        for f, why in unreadable:
            skip_file(skipped, f, why)
        raise CliError(str(e)) from e
    for f, why in unreadable:
        skip_file(skipped, f, why)
    labels = [r.label for r in runs]
    where = (f"{args.workers} worker(s)" if args.ray is None
             else f"Ray ({args.ray or 'started on this machine'})")  # fmt: skip
    print(f"{len(segs)} segment(s) x {len(runs)} method(s) ({', '.join(labels)}), {where} -> "
          f"{args.out}")  # fmt: skip
    t0 = time.perf_counter()
    failed = 0
    stored = sum((args.out / "segments" / r.label / f"{s.id}.json").is_file()
                 for r in runs for s in segs)  # fmt: skip
    with ray_pool(args) as pool, tqdm(total=len(segs) * len(runs), initial=stored, unit="seg",
                                      desc="bench") as bar:  # fmt: skip

        def progress(row: dict) -> None:
            nonlocal failed
            failed += row["status"] != "ok"
            bar.set_postfix(failed=failed)
            bar.update(1)

        try:
            rows = run_bench(runs, segs, args.out, workers=args.workers,
                             save_recons=args.save_recons, retry_failed=args.retry_failed,
                             built=built, progress=progress, log=bar.write,
                             batch=args.batch, pool=pool)  # fmt: skip
        except BenchError as e:
            raise CliError(str(e)) from e
    title = f"Benchmark on {args.data} ({args.split} split, --init {args.init})"
    summary = write_outputs(args.out, rows, runs, segs, title)
    print(method_table(summary))
    if failed:
        print(f"{failed} segment(s) failed in this run; see {args.out / 'table.md'}")
    print(f"wrote {args.out}/results.json, results.csv, segments.csv, table.md and plots "
          f"in {time.perf_counter() - t0:.0f} s")  # fmt: skip
    return exit_status(skipped)
