"""``grip demo``: the longest real pipeline that exists, on the shared clips."""

from __future__ import annotations

import argparse
import time
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="run the end-to-end demo (a small dataset, its summary and a plot)",
        description="Build a small PRISM-format dataset from a spread of the shared mocap "
        "clips (import, retarget, IMU and insole synthesis by physics, noise, chunking, split), "
        "print its summary and plot one walking recording.",
        epilog="example: grip demo --out demo_out --clips 16",
    )
    p.add_argument("--out", type=Path, default=Path("demo_out"), help="output folder")
    p.add_argument("--clips", type=int, default=16, help="number of clips (default 16)")
    p.add_argument("--workers", type=int, default=0, help="worker processes (default: all)")
    p.add_argument("--motions", type=Path, default=None,
                   help="clip folder (default: ../shared/data/motions)")  # fmt: skip
    p.set_defaults(func=cmd_demo)


def cmd_demo(args: argparse.Namespace) -> int:
    import json

    from tqdm import tqdm

    from grip.cli.data import select_clips
    from grip.cli.main import CliError
    from grip.cli.paths import default_motions_dir
    from grip.dataset.build import BuildConfig, build_dataset
    from grip.dataset.info import dataset_summary, format_summary
    from grip.dataset.plot import plot_recording
    from prism_tools.io import load_recording

    root = args.motions or default_motions_dir()
    if root is None:
        raise CliError("the shared clips (../shared/data/motions) were not found; "
                       "pass --motions DIR or set GRIP_MOTIONS_DIR")  # fmt: skip
    out: Path = args.out
    ds = out / "dataset"
    clips = select_clips([Path(root)], args.clips)
    print(f"[1/3] building a PRISM-format dataset from {len(clips)} clips of {root} -> {ds}")
    t0 = time.perf_counter()
    with tqdm(total=len(clips), desc="clips", unit="clip") as bar:
        results = build_dataset(clips, ds, BuildConfig(), workers=args.workers,
                                progress=bar.update)  # fmt: skip
    dt = time.perf_counter() - t0
    print(f"      done in {dt:.1f} s")
    print("[2/3] summary")
    summary = dataset_summary(ds)
    print(format_summary(summary))
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    print("[3/3] plotting one recording")
    done = [r for r in results if r.status == "done" and r.sequences]
    if not done:
        raise CliError("no clip could be built; see the errors above")
    walks = [r for r in done if r.category == "walk"] or [r for r in done if "walk" in r.category]
    pick = next((r for r in walks if "normal" in r.clip_id), walks[0] if walks else done[0])
    seq = ds / "sequences" / f"{pick.sequences[0]}.npz"
    png = plot_recording(load_recording(seq), out / "recording.png")
    print(f"      {seq.name} -> {png}")
    print(f"\nOutputs in {out}/: dataset/, summary.json, recording.png")
    failed = [r for r in results if r.status != "done"]
    for r in failed:
        print(f"FAILED {r.clip_id}: {r.error}")
    return 1 if failed else 0
