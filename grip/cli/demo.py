"""``grip demo``: reconstruct the bundled sample recording with the shipped models, compare with
its ground truth and the baselines, write every export; optionally build a small dataset."""

from __future__ import annotations

import argparse
import time
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="run the end-to-end demo on the bundled sample recording",
        description="Reconstruct the bundled sample recording (a 5 s walk of the shipped "
        "models' per-clip test split, 4 IMUs + insoles, grip/assets/sample_recording.npz) "
        "with the shipped KinematicsNet and policy: physics simulation with fall recovery, "
        "then npz/BVH/GLB/PNG (and MP4 where "
        "OpenGL works) exports, and a metrics table of GRIP, kinematics only and PIP's physics "
        "optimiser on the KinematicsNet estimate against the recording's ground truth. "
        "Then a held-out clip with props (6 s of a person in no training split climbing three "
        "steps, grip/assets/sample_props_recording.npz): GRIP, kinematics only and kin+PIP in "
        "a scene with the steps, an HTML viewer with the props and a second metrics table "
        "(OUT/props/). --dataset also builds a small PRISM-format dataset from the shared "
        "mocap clips.",
        epilog="example: grip demo --out demo_out\n         grip demo --out demo_out --dataset "
        "--clips 16",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", type=Path, default=Path("demo_out"), help="output folder")
    p.add_argument("--recording", type=Path, default=None,
                   help="recording to reconstruct (default: the bundled sample)")
    p.add_argument("--props-recording", type=Path, default=None,
                   help="the recording with props (default: the bundled held-out stairs clip)")
    p.add_argument("--no-props", action="store_true", help="skip the clip with props")
    p.add_argument("--policy", type=Path, default=None, help="policy (default: the shipped one)")
    p.add_argument("--no-video", action="store_true", help="skip the MP4 (the slowest export)")
    p.add_argument("--dataset", action="store_true",
                   help="also build a small dataset from the shared clips (--clips of them)")
    p.add_argument("--clips", type=int, default=16, help="number of clips (default 16)")
    p.add_argument("--workers", type=int, default=0, help="worker processes (default: all)")
    p.add_argument("--motions", type=Path, default=None,
                   help="clip folder (default: ../shared/data/motions)")  # fmt: skip
    p.set_defaults(func=cmd_demo)




def cmd_demo(args: argparse.Namespace) -> int:
    code = reconstruct_demo(args)
    if not args.no_props:
        code = max(code, props_demo(args))
    if args.dataset:
        code = max(code, dataset_demo(args))
    return code


def reconstruct_demo(args: argparse.Namespace) -> int:
    """Reconstruct one recording with GRIP and the four other methods, stream it through GRIP
    frame by frame, write metrics and exports."""
    import os

    if not args.no_video:
        os.environ.setdefault("MUJOCO_GL", "egl")  # before MuJoCo is imported
    import json

    import torch

    # Every method runs one recording at batch 1, where a second thread gains little and, on a
    # machine with a busy core, costs a lot (18.6 s against 8.0 s with one thread, measured)
    torch.set_num_threads(1)
    from grip.assets import SAMPLE_RECORDING
    from grip.cli.reconstruct import policy_checkpoint, safe_name
    from grip.core.atomic import atomic_write_text
    from grip.eval.methods import MethodOptions
    from grip.eval.report import method_table
    from grip.export import export_reconstruction

    src = args.recording or SAMPLE_RECORDING
    rec = _load(src)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    opts = MethodOptions(policy_checkpoint=policy_checkpoint(args.policy))
    print(f"[1/4] {src}: {rec.name}, {rec.n_frames} frames at {rec.fps:g} Hz")
    summary, recons, methods = run_methods(rec, DEMO_METHODS, opts, out)
    grip = recons["grip"]
    stem = safe_name(rec.name)
    print("[2/4] the same recording through the streaming API (one frame in, one out)")
    _stream_check(methods["grip"], rec, grip)
    formats = ["bvh", "glb", "png"] + ([] if args.no_video else ["mp4"])
    print(f"[3/4] exports of the GRIP reconstruction: {', '.join(formats)}")
    written, failed = export_reconstruction(grip, out, formats, stem=stem, recording=rec)
    for p in written:
        print(f"      wrote {p}")
    for fmt, msg in failed.items():
        print(f"      {fmt} not written: {msg}")
    print("[4/4] metrics against the recording's ground truth (one 5 s segment)")
    table = method_table(summary)
    print(table)
    atomic_write_text(out / "metrics.md", table + "\n")
    atomic_write_text(out / "metrics.json", json.dumps(summary, indent=1, default=float))
    print(f"\nOutputs in {out}/: {stem}.*.npz (one per method), exports, metrics.md")
    return 0


DEMO_METHODS = ("grip", "kinematics", "kin+pip", "transpose", "pip")
"""The methods the demo runs (GRIP first: the streaming check reuses its models)."""

PROPS_METHODS = ("grip", "kinematics", "kin+pip")
"""The methods the demo runs on the clip with props (those that read the scene or compare)."""


def _load(path: Path):
    from grip.cli.errors import CliError
    from prism_tools.io import load_recording

    try:
        return load_recording(path)
    except (OSError, ValueError) as e:
        raise CliError(str(e)) from e


def run_methods(rec, names, opts, out: Path) -> tuple[dict, dict, dict]:
    """Reconstruct ``rec`` with each method of ``names``, score it against the recording's
    ground truth and save ``out/<stem>.<method>.npz``.

    Returns:
        ``(summary, reconstructions, methods)``, each keyed by method name; ``summary`` holds
        :func:`grip.eval.report.method_table` rows.
    """
    from grip.cli.errors import CliError
    from grip.cli.reconstruct import safe_name
    from grip.eval.methods import make_method
    from grip.eval.scoring import segment_metrics
    from grip.kinematics.features import ground_truth

    gt = ground_truth(rec)
    summary, recons, methods = {}, {}, {}
    for name in names:
        t0 = time.perf_counter()
        try:
            method = make_method(name, opts)
            recon = method.reconstruct(rec)
        except ValueError as e:
            raise CliError(f"{name}: {e}") from e
        m, _ = segment_metrics(recon, gt, can_fall=method.can_fall)
        summary[name] = {**m, "ms_per_frame": recon.ms_per_frame, "segments": 1, "failed": 0}
        recons[name] = recon
        methods[name] = method
        recon.save(out / f"{safe_name(rec.name)}.{name.replace('+', '_')}.npz")
        lost = int(recon.notes.get("lost", 0))
        extra = (f", {len(recon.falls) - lost} fall(s) and {lost} lost (standing, more than "
                 f"--lost-gap from the estimate) recovered") if method.can_fall else ""  # fmt: skip
        print(f"      {name}: {time.perf_counter() - t0:.1f} s{extra}")
    return summary, recons, methods


def props_demo(args: argparse.Namespace) -> int:
    """Reconstruct the held-out clip with props in a scene that has them; a viewer and a
    metrics table in ``OUT/props/``."""
    import json

    from grip.assets import SAMPLE_PROPS_RECORDING
    from grip.cli.reconstruct import policy_checkpoint, safe_name
    from grip.core.atomic import atomic_write_text
    from grip.eval.methods import MethodOptions
    from grip.eval.report import method_table
    from grip.export import export_reconstruction

    src = args.props_recording or SAMPLE_PROPS_RECORDING
    rec = _load(src)
    out: Path = args.out / "props"
    out.mkdir(parents=True, exist_ok=True)
    objects = sorted(rec.objects or {})
    tops = [f"{n} top {float(rec.objects[n].vertices[:, 2].max()):.2f} m" for n in objects]
    print(f"[props] {src}: {rec.name}, {rec.n_frames} frames at {rec.fps:g} Hz, "
          f"{len(objects)} object(s) in the scene{': ' if tops else ''}{', '.join(tops)}")
    opts = MethodOptions(policy_checkpoint=policy_checkpoint(args.policy))
    summary, recons, _ = run_methods(rec, PROPS_METHODS, opts, out)
    stem = safe_name(rec.name)
    written, failed = export_reconstruction(recons["grip"], out, ["html", "png"], stem=stem,
                                            recording=rec)  # fmt: skip
    for p in written:
        print(f"      wrote {p}")
    for fmt, msg in failed.items():
        print(f"      {fmt} not written: {msg}")
    table = method_table(summary)
    print(table)
    atomic_write_text(out / "metrics.md", table + "\n")
    atomic_write_text(out / "metrics.json", json.dumps(summary, indent=1, default=float))
    print(f"\nOutputs in {out}/: {stem}.*.npz (one per method), {stem}.html (open it in a "
          "browser: the props, GRIP and the ground truth), metrics.md")
    return 0


def _stream_check(grip_method, rec, offline) -> None:
    """Push ``rec`` through :class:`grip.eval.stream.GripStream` and compare with ``offline``."""
    import numpy as np

    from grip.kinematics.features import sensor_frames

    g = grip_method.reconstructor
    stream = g.stream(rec.slice_frames(0, 2))
    times = []
    for frame in sensor_frames(rec, g.estimator.cfg.features):
        t0 = time.perf_counter()
        stream.push(frame)
        times.append(time.perf_counter() - t0)
    stream.finish()
    live = stream.reconstruction()
    n = min(live.n_frames, offline.n_frames)
    first_fall = min([n, *offline.falls[:, 0], *live.falls[:, 0]])
    diff = np.abs(live.joint_pos[:first_fall] - offline.joint_pos[:first_fall]).max(initial=0.0)
    ms = 1e3 * np.array(times[2:])
    print(f"      {len(times)} frames pushed: {ms.mean():.2f} ms per frame on one thread "
          f"(median {np.median(ms):.2f}), output 2 frames behind the input")
    print(f"      largest joint difference to the offline result over the {first_fall} frames "
          f"before the first recovery: {1e3 * diff:.4f} mm (float32 rounding of the LSTM's "
          "step-wise and sequence passes; a recovery amplifies it)")


def dataset_demo(args: argparse.Namespace) -> int:
    """Build a small PRISM-format dataset from the shared clips, summarise and plot it."""
    import json

    from tqdm import tqdm

    from grip.cli.data import select_clips
    from grip.cli.errors import CliError
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
