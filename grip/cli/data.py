"""``grip data``: build, summarise and plot PRISM-format datasets."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from grip.cli.devices import add_import_parser
from grip.cli.recordings import add_limit_arguments, limits_from_args

# grip.dataset.build.SPLIT_MODES, not imported so that `grip --help` imports no numpy
SPLIT_MODES = ("person", "clip")
DEFAULT_CATEGORIES = Path("configs") / "categories.toml"
"""The category map of the checkout (relative to its root)."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from grip.cli.common import add_group

    dsub = add_group(sub, "data", "build, inspect and plot PRISM-format datasets",
                     "Build PRISM-format recordings from motion clips, summarise a dataset "
                     "folder (ours or real PRISM pickles) and plot one recording.")  # fmt: skip

    b = dsub.add_parser(
        "build",
        help="convert motion clips into a PRISM-format dataset",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Import motion clips (BVH, ASF/AMC, DeepMimic JSON, AMASS npz, poselib npy),\n"
            "retarget them onto the body model at 100 Hz, synthesise the 8 IMUs and both\n"
            "insoles by physics, add sensor noise, chunk into <=1000-frame sequences and write\n"
            "a train/test split.\n"
            "Parallel, resumable (finished clips are skipped), every file written atomically.\n"
            "The settings are recorded in OUT/settings.json before the first clip; a rerun with\n"
            "options that change the clips is refused. A motion file that cannot be read or\n"
            "imported is named (SKIPPED/FAILED, and in manifest.json), the others are built, and\n"
            "the exit status is 1.\n"
            "\n"
            "Categories: each clip's own label (clips.csv, Bandai Namco's JSON, DeepMimic's name)\n"
            "is translated by --categories into one vocabulary shared by every source (walk,\n"
            "walk-turn, run, jump, ...; 'unknown' where the file has no entry); the label is kept\n"
            "next to it. A clips.csv (columns file, category, optionally person) labels the clips\n"
            "of its folder.\n"
            "\n"
            "Split (--split-by person, the default): no performer is on both sides. A clip's\n"
            "group is its performer where the source names one (a clips.csv 'person' column;\n"
            "HDM05: the actor of HDM_<actor>_...; CMU: the subject of <subject>_<trial>), else\n"
            "the finest grouping the source allows (Bandai Namco: dataset and style, e.g.\n"
            "bandai_namco/dataset-2/active; DeepMimic and unlabelled clips: the clip itself).\n"
            "Test groups are chosen within each source, so that every source of two or more\n"
            "groups has about --test-fraction of its sequences in test and a group on each side.\n"
            "--split-by clip: whole clips at random (the split of datasets built before).\n"
            "The split is computed from the finished clips: rerunning a finished OUT with other\n"
            "--split-by/--split-seed/--test-fraction only splits it again, and with an edited\n"
            "--categories file relabels its recordings; neither builds a clip again."
        ),
        epilog="example: grip data build --out data/prism_synth --workers 2\n"
        "         grip data build --out data/small --motions ~/mocap/bvh --limit 20\n"
        "         grip data build --out data/prism_synth --split-by clip   (split again)",
    )
    b.add_argument("--out", required=True, type=Path, help="dataset folder (created/resumed)")
    b.add_argument("--motions", nargs="+", type=Path, default=None, metavar="DIR",
                   help="folders of clips (default: ../shared/data/motions)")  # fmt: skip
    b.add_argument("--limit", type=int, default=None, metavar="N",
                   help="use only N clips, spread evenly over the sorted list")  # fmt: skip
    b.add_argument("--workers", type=int, default=0, metavar="K",
                   help="worker processes (default: one per core)")  # fmt: skip
    b.add_argument(
        "--noise-variants",
        type=int,
        default=1,
        metavar="N",
        help="noisy recordings per clip, each with its own noise draw (default 1)",
    )
    b.add_argument("--clean", action="store_true",
                   help="also write a noise-free recording of every clip")  # fmt: skip
    b.add_argument("--fixed-body", action="store_true",
                   help="one body for all clips (--height/--mass) instead of a drawn subject "
                   "per recording")  # fmt: skip
    b.add_argument("--height", type=float, default=1.70, help="body height, m (--fixed-body)")
    b.add_argument("--mass", type=float, default=70.0, help="body mass, kg (--fixed-body)")
    b.add_argument("--seed", type=int, default=0, help="base seed of noise and subjects")
    b.add_argument("--zmp-filter", action=argparse.BooleanOptionalAction, default=True,
                   help="shift each retargeted motion's pelvis by a few millimetres so that the "
                   "ZMP lies on the feet where they alone carry the body (the dynamic filter, "
                   "docs/insoles_zmp.md; default on); part of the clip settings: a folder "
                   "built before the filter existed resumes with --no-zmp-filter")  # fmt: skip
    b.add_argument("--split-by", choices=SPLIT_MODES, default="person",
                   help="keep whole performers (else the source's finest grouping) or whole "
                   "clips on one side of the split (default person)")  # fmt: skip
    b.add_argument("--test-fraction", type=float, default=0.2,
                   help="share of the sequences in the test split, of each source's with "
                   "--split-by person (default 0.2; 0: all in train; 1: all in test, e.g. a "
                   "folder of one's own recordings to evaluate)")  # fmt: skip
    b.add_argument("--split-seed", type=int, default=42, help="seed of the split (default 42)")
    b.add_argument("--test-group", action="append", default=[], metavar="GROUP",
                   help="put this group in the test split whatever the draw (repeatable; a "
                   "performer such as cmu/14 with --split-by person, 'grip data info' lists "
                   "the groups; a clip id with --split-by clip); like the other split settings "
                   "it re-splits a built folder without building a clip")  # fmt: skip
    b.add_argument("--categories", type=Path, default=None, metavar="FILE",
                   help="a .toml map of the sources' labels to shared categories (default: "
                   "configs/categories.toml), or a .csv table of clips and their categories "
                   "(columns 'clip' or 'file', and 'category'; the default map translates "
                   "them) for one's own clips; without either, a clip without a label takes "
                   "its folder's name")  # fmt: skip
    from grip.cli.cluster import add_ray_argument

    add_ray_argument(b, "clips")
    add_limit_arguments(b)
    b.set_defaults(func=cmd_build)

    i = dsub.add_parser(
        "info",
        help="summarise a dataset folder",
        description="Print recordings, frames, motion categories and per-category counts of a "
        "dataset folder: one built by 'grip data build', or any folder of PRISM recordings "
        "(*.pkl, *.npz), e.g. the real PRISM dataset. For a built folder also its split: the "
        "split mode, groups, clips, sequences and frames per side, per source the groups and "
        "sequences on each side and the test share, the groups of each side (split by person) "
        "and the sequences of each category on each side.",
        epilog="example: grip data info data/prism_synth --json info.json",
    )
    i.add_argument("dir", type=Path, help="dataset folder")
    i.add_argument("--json", type=Path, default=None, metavar="PATH",
                   help="also write the summary as JSON")  # fmt: skip
    add_limit_arguments(i)
    i.set_defaults(func=cmd_info)

    pl = dsub.add_parser(
        "plot",
        help="plot one recording (sensors, insole pressure, skeleton)",
        description="Draw the IMU streams, insole forces/contacts/pressure/CoP and the "
        "ground-truth skeleton of one PRISM-format recording (.pkl or .npz) to a PNG.",
        epilog="example: grip data plot data/prism_synth/sequences/cmu__02_01_v0_seq000.npz "
        "--out walk.png",
    )
    pl.add_argument("file", type=Path, help="recording (.pkl or .npz)")
    pl.add_argument("--out", required=True, type=Path, help="output PNG")
    add_limit_arguments(pl)
    pl.set_defaults(func=cmd_plot)

    r = dsub.add_parser(
        "reference",
        help="precompute KinematicsNet estimates for the tracking environment",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Run KinematicsNet once over recordings (batched) and write a reference-set file\n"
            "(.npz: estimate + ground truth + sensor features per clip) that the MuJoCo\n"
            "tracking environment reads: GripTrackingEnv(TrackingEnvConfig(reference=FILE)).\n"
            "Sources: a dataset folder's split (--data DIR --split train) or recording files."
        ),
        epilog="example: grip data reference --data data/prism_synth --split train "
        "--out data/ref_train.npz\n"
        "         grip data reference rec1.pkl rec2.npz --out ref.npz --kin runs/kin/best.pt",
    )
    r.add_argument("files", nargs="*", type=Path, help="recordings (.pkl/.npz) instead of --data")
    r.add_argument("--data", type=Path, default=None, help="dataset folder (with split.json)")
    r.add_argument("--split", default="train", choices=("train", "test", "all"),
                   help="split of --data (default train)")  # fmt: skip
    r.add_argument("--kin", type=Path, default=None,
                   help="KinematicsNet checkpoint (default: the shipped one)")  # fmt: skip
    r.add_argument("--out", required=True, type=Path, help="output .npz")
    r.add_argument("--category", action="append", default=[],
                   help="keep only recordings of this category (glob, repeatable)")  # fmt: skip
    r.add_argument("--limit", type=int, default=None, help="at most this many recordings")
    r.add_argument("--max-frames", type=int, default=None,
                   help="crop each recording to its first N frames")  # fmt: skip
    add_limit_arguments(r)
    r.set_defaults(func=cmd_reference)

    c = dsub.add_parser(
        "cut",
        help="cut a time window out of one recording",
        description="Write frames [--start, --end) (seconds) of one PRISM-format recording "
        "(.pkl or .npz) as a new recording: every per-frame stream is cut, the scene's objects, "
        "the subject and the extras are kept. The demo's bundled recordings were cut this way "
        "(grip/assets/__init__.py names the commands).",
        epilog="example: grip data cut data/prism_synth/sequences/cmu__14_21_v0_seq000.npz "
        "--start 0.5 --end 6.5 --out stairs.npz",
    )
    c.add_argument("file", type=Path, help="recording (.pkl or .npz)")
    c.add_argument("--start", type=float, default=0.0, help="first second (default 0)")
    c.add_argument("--end", type=float, default=None,
                   help="end in seconds, exclusive (default: the recording's end)")  # fmt: skip
    c.add_argument("--out", required=True, type=Path, help="output recording (.pkl or .npz)")
    add_limit_arguments(c)
    c.set_defaults(func=cmd_cut)

    add_import_parser(dsub)  # grip data import (grip/cli/devices.py)


def default_category_map():
    """The checkout's ``configs/categories.toml`` (:class:`grip.motion.catalog.CategoryMap`),
    ``None`` where the checkout has none (an installed package: categories stay the labels)."""
    from grip.assets import REPO_ROOT

    path = REPO_ROOT / DEFAULT_CATEGORIES
    return category_map(path) if path.is_file() else None


def category_map(path: Path):
    """:func:`grip.motion.catalog.load_category_map`, errors as :class:`CliError`."""
    from grip.cli.errors import CliError
    from grip.motion.catalog import load_category_map

    try:
        return load_category_map(path)
    except (OSError, ValueError) as e:
        raise CliError(f"--categories: {e}") from e


def select_clips(roots: list[Path], limit: int | None, categories=None) -> list:
    """The :class:`grip.dataset.build.ClipSpec` s of the clips under ``roots`` (``limit``:
    evenly spread; ``categories``: a :class:`grip.motion.catalog.CategoryMap`, default
    :func:`default_category_map`)."""
    return scan_motions(roots, limit, categories)[0]


def scan_motions(roots: list[Path], limit: int | None, categories=None, table=None
                 ) -> tuple[list, list[tuple[str, str]]]:  # fmt: skip
    """The clips under ``roots`` as :func:`select_clips` gives them, and the files skipped;
    ``table``: a user's clip -> category table (:func:`grip.motion.catalog.
    load_clip_categories`) that overrides the labels of the clips it lists.

    Returns:
        ``(clips, skipped)``: :class:`grip.dataset.build.ClipSpec` s (path, clip id, category,
        label, group; ``limit``: evenly spread) and ``(path, reason)`` of every candidate file
        the search could not read.
    """
    from grip.cli.errors import CliError
    from grip.dataset.build import ClipSpec
    from grip.motion.catalog import scan_clips, table_category

    if categories is None:
        categories = default_category_map()
    clips, skipped, used = [], [], set()
    for root in roots:
        if not root.is_dir():
            raise CliError(f"--motions {root}: not a folder")
        refs, bad = scan_clips(root, categories)
        for c in refs:
            label, cat = c.label, c.category
            got = table_category(table, c.clip_id, c.path, root, categories) if table else None
            if got is not None:
                label, cat, key = got
                used.add(key)
            clips.append(ClipSpec(str(c.path), c.clip_id, cat, label, c.group))
        skipped += [(str(b.path), b.reason) for b in bad]
    if not clips:
        raise CliError(f"no supported clips (bvh, amc, DeepMimic json, npz) under {roots}")
    unused = sorted(set(table or ()) - used)
    if unused:
        print(f"--categories: {len(unused)} listed clip(s) not found under the motion folders: "
              f"{', '.join(unused[:5])}{' ...' if len(unused) > 5 else ''}", file=sys.stderr)
    if limit is not None and limit < len(clips):
        if limit < 1:
            raise CliError("--limit must be >= 1")
        idx = sorted(
            {round(k) for k in [i * (len(clips) - 1) / max(limit - 1, 1) for i in range(limit)]}
        )
        clips = [clips[k] for k in idx]
    return clips, skipped


def cmd_build(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from grip.cli.cluster import ray_args, ray_pool
    from grip.cli.errors import CliError
    from grip.cli.paths import default_motions_dir
    from grip.dataset.build import BuildConfig, build_dataset
    from grip.dataset.info import dataset_summary, format_summary

    limits_from_args(args)
    ray_args(args)
    roots = args.motions
    if roots is None:
        d = default_motions_dir()
        if d is None:
            raise CliError("no --motions given and ../shared/data/motions not found "
                           "(set GRIP_MOTIONS_DIR or pass --motions DIR)")  # fmt: skip
        roots = [d]
    if args.noise_variants < 0 or (args.noise_variants == 0 and not args.clean):
        raise CliError("--noise-variants must be >= 1 (or 0 together with --clean)")
    if not 0.0 <= args.test_fraction <= 1.0:
        raise CliError("--test-fraction must be in [0, 1] (0: all train, 1: all test)")
    if args.split_seed < 0:
        raise CliError("--split-seed must be >= 0")
    cfg = BuildConfig(noise_variants=args.noise_variants, clean_variant=args.clean,
                      vary_body=not args.fixed_body, height_m=args.height, mass_kg=args.mass,
                      test_fraction=args.test_fraction, seed=args.seed,
                      split_seed=args.split_seed, split_by=args.split_by,
                      zmp_filter=args.zmp_filter,
                      test_groups=tuple(args.test_group))  # fmt: skip
    table = None
    if args.categories is not None and args.categories.suffix.lower() == ".csv":
        from grip.motion.catalog import load_clip_categories

        try:
            table = load_clip_categories(args.categories)
        except ValueError as e:
            raise CliError(f"--categories: {e}") from e
    if args.categories is not None and table is None:
        cmap = category_map(args.categories)
    else:
        cmap = default_category_map()
    if cmap is None:
        print("no configs/categories.toml in this installation: categories are the sources' "
              "own labels (pass --categories FILE)", file=sys.stderr)  # fmt: skip
    clips, skipped = scan_motions(roots, args.limit, cmap, table)
    counts: dict[str, int] = {}
    t0 = time.perf_counter()
    with ray_pool(args) as pool, tqdm(total=len(clips), desc="clips", unit="clip") as bar:
        try:
            results = build_dataset(clips, args.out, cfg, workers=args.workers,
                                    progress=bar.update, skipped_files=skipped,
                                    counts=counts, pool=pool)  # fmt: skip
        except (ValueError, OSError) as e:
            raise CliError(str(e)) from e
    dt = time.perf_counter() - t0
    built = [r for r in results if r.status == "done"]
    failed = [r for r in results if r.status != "done"]
    short = [r for r in built if not r.sequences]
    frames = sum(sum(r.sequence_frames) for r in built)
    print(format_summary(dataset_summary(args.out)))
    print(f"\nbuilt {len(built)}/{len(results)} clips in {dt:.1f} s "
          f"({frames / max(dt, 1e-9):.0f} recording frames/s incl. resumed clips)")  # fmt: skip
    if counts.get("resumed"):
        print(f"{counts['resumed']} clip(s) were finished before and not built again "
              f"({counts['relabelled']} relabelled), {counts['built']} built in this run; "
              f"split.json written anew (split by {cfg.split_by})")  # fmt: skip
    if counts.get("unrecorded"):
        print(f"note: no record of the sources of {counts['unrecorded']} finished clip(s) "
              "(built by an older version): they are kept, their sources assumed unchanged; "
              "recorded now, a change is refused from now on")  # fmt: skip
    if short:
        print(f"{len(short)} built clip(s) gave no sequence (shorter than "
              f"{cfg.min_chunk_frames} frames at 100 Hz; 'note' in manifest.json)")  # fmt: skip
    unmapped = sorted({c.label for c in clips if c.category == "unknown" and c.label})
    if cmap is not None and unmapped:
        print(f"{len(unmapped)} label(s) not in {cmap.source}, category 'unknown': "
              + ", ".join(repr(u) for u in unmapped[:20]))  # fmt: skip
    if skipped:
        print(f"{len(skipped)} file(s) under --motions could not be read and were skipped "
              "(manifest.json 'skipped_files'):", file=sys.stderr)  # fmt: skip
    for f, why in skipped:
        print(f"SKIPPED {f}: {why}", file=sys.stderr)
    for r in failed:
        print(f"FAILED {r.clip_id}: {r.error}", file=sys.stderr)
    if failed or skipped:
        print(f"grip: error: {len(failed)} clip(s) failed, {len(skipped)} file(s) skipped; "
              "the others were built", file=sys.stderr)  # fmt: skip
    return 1 if failed or skipped else 0


def cmd_info(args: argparse.Namespace) -> int:
    from grip.cli.errors import CliError
    from grip.cli.recordings import exit_status, skip_file
    from grip.core.atomic import atomic_write_text
    from grip.dataset.info import dataset_summary, format_summary

    limits_from_args(args)
    try:
        summary = dataset_summary(args.dir)
    except (OSError, ValueError) as e:
        raise CliError(str(e)) from e
    print(format_summary(summary))
    if args.json:
        atomic_write_text(args.json, json.dumps(summary, indent=1))
        print(f"\nwrote {args.json}")
    errors: list[tuple[str, str]] = []
    for bad in summary.get("unreadable", []):
        skip_file(errors, bad["file"], bad["error"])
    return exit_status(errors, summary.get("files"))


def _read_recording(args: argparse.Namespace):
    """The recording ``args.file`` under the command's input limits (errors as CliError)."""
    from grip.cli.errors import CliError
    from prism_tools.io import load_recording

    limits_from_args(args)
    try:
        return load_recording(args.file)
    except (OSError, ValueError) as e:
        raise CliError(str(e)) from e


def cmd_plot(args: argparse.Namespace) -> int:
    from grip.dataset.plot import plot_recording

    out = plot_recording(_read_recording(args), args.out)
    print(f"wrote {out}")
    return 0


def cmd_cut(args: argparse.Namespace) -> int:
    from grip.cli.errors import CliError
    from prism_tools.io import save_recording

    rec = _read_recording(args)
    n, fps = rec.n_frames, rec.fps
    start = round(args.start * fps)
    stop = n if args.end is None else round(args.end * fps)
    if not 0 <= start < stop <= n:
        raise CliError(f"{args.file}: --start {args.start:g} s / --end "
                       f"{'end' if args.end is None else f'{args.end:g} s'} give frames "
                       f"[{start}, {stop}), outside the recording's {n} frames "
                       f"({n / fps:g} s at {fps:g} Hz)")  # fmt: skip
    cut = rec.slice_frames(start, stop)
    try:
        save_recording(cut, args.out)
    except (OSError, ValueError) as e:
        raise CliError(str(e)) from e
    print(f"wrote {args.out}: frames [{start}, {stop}) of {args.file} ({stop - start} frames, "
          f"{(stop - start) / fps:g} s, objects: {', '.join(cut.objects or {}) or 'none'})")
    return 0


def cmd_reference(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from grip.cli.errors import CliError
    from grip.cli.recordings import exit_status, kin_checkpoint, load_recordings, split_paths
    from grip.kinematics.inference import KinematicsEstimator
    from grip.kinematics.reference import build_reference_set

    limits_from_args(args)
    if bool(args.files) == (args.data is not None):
        raise CliError("give recording files or --data DIR (one of them)")
    files = split_paths(args.data, args.split) if args.data is not None else list(args.files)
    errors: list[tuple[str, str]] = []
    recs = load_recordings(files, args.category, max_frames=args.max_frames or 0,
                           limit=args.limit or 0, errors=errors)  # fmt: skip
    kin = kin_checkpoint(args.kin)
    try:
        est = KinematicsEstimator.from_checkpoint(kin)
    except ValueError as e:
        raise CliError(str(e)) from e
    with tqdm(total=len(recs), unit="rec", desc="KinematicsNet") as bar:
        ref = build_reference_set(recs, est, progress=bar.update, source=str(args.out))
    ref.save(args.out)
    print(f"wrote {args.out}: {len(ref)} clips, {ref.total_frames} frames, "
          f"sensor features {ref.sensor_dim} ({', '.join(ref.sensor_sites)}"
          f"{' + insoles' if ref.insoles else ''})")  # fmt: skip
    return exit_status(errors, len(files))
