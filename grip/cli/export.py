"""``grip export``: write reconstructions as BVH, GLB, MP4, PNG, AMASS-style npz and HTML files."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Iterator
from pathlib import Path

from grip.cli.common import positive_float
from grip.cli.recordings import add_limit_arguments, limits_from_args

FORMATS: tuple[str, ...] = ("bvh", "glb", "mp4", "png", "amass", "html")
"""``grip.export.FORMATS``, spelled here so that ``grip --help`` does not import the export
library (1.9 s against 0.1 s); a test keeps the two equal."""
DEFAULT_FORMATS: tuple[str, ...] = ("bvh", "glb", "mp4", "png")
"""What a plain ``grip export`` writes; the data formats (amass) are asked for by name."""

_DEFAULT_HEIGHT_M = 1.70
_DEFAULT_MASS_KG = 70.0


class _NoRenderBackend(Exception):
    """MuJoCo could not create an OpenGL context (the message says how to fix it)."""


def _formats(text: str) -> tuple[str, ...]:
    names = tuple(dict.fromkeys(s.strip().lower() for s in text.split(",") if s.strip()))
    bad = [n for n in names if n not in FORMATS]
    if bad or not names:
        raise argparse.ArgumentTypeError(
            f"unknown format(s) {', '.join(bad) or repr(text)}: choose from {', '.join(FORMATS)}"
        )
    return names


def _frames(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(s) for s in text.split(",") if s.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of frame "
                                         "numbers") from None  # fmt: skip


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grip export`` on the ``grip`` subparsers."""
    p = sub.add_parser(
        "export",
        help="write reconstructions as BVH, GLB, MP4, PNG and AMASS-style npz files",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Export reconstructions (.npz files written by GRIP or a baseline) for other tools.\n"
            "For each RECON.npz, into DIR:\n"
            "  bvh  STEM.bvh            motion of the body model, y up, cm (--bvh-unit m)\n"
            "  glb  STEM_strobe.glb     every Nth pose along the trajectory + floor (glTF, y up)\n"
            "       STEM_fFRAME.glb     the body at single frames (--glb-frames)\n"
            "  mp4  STEM.mp4            MuJoCo offscreen rendering (needs OpenGL: MUJOCO_GL=egl\n"
            "                           is set when unset; ground truth as a green ghost)\n"
            "  png  STEM.png            trajectory, GRF vs insoles, contacts, falls, errors\n"
            "  amass STEM_amass.npz     SMPL-order axis-angle poses (T, 72), trans, z up, m:\n"
            "                           GRIP's SMPL-topology body, not SMPL (docs/exports.md)\n"
            "  html STEM.html           interactive 3D page, one self-contained file (the body,\n"
            "                           --gt as a ghost, GRF vs insoles; 'grip view' compares\n"
            "                           several methods; docs/viewer.md)\n"
            "The body is the subject of --gt (its height and mass), overridden by\n"
            "--body-height/--body-mass, else 1.70 m / 70 kg. A format that fails (e.g. mp4\n"
            "without OpenGL) or a RECON.npz that cannot be read is reported and the others\n"
            "are still written (exit code 1); an unreadable --gt ends the command."
        ),
        epilog="example: grip export runs/eval/seq000_grip.npz --out exports --formats bvh,png \\\n"
        "           --gt data/sequences/seq000.npz",
    )
    p.add_argument("recons", nargs="+", type=Path, metavar="RECON.npz",
                   help="reconstruction files (grip.core.reconstruction format)")  # fmt: skip
    p.add_argument("--out", required=True, type=Path, metavar="DIR",
                   help="output folder (created; files are written atomically)")  # fmt: skip
    p.add_argument(
        "--formats",
        type=_formats,
        default=DEFAULT_FORMATS,
        metavar="LIST",
        help="comma-separated subset of " + ",".join(FORMATS) + " (default: "
        + ",".join(DEFAULT_FORMATS) + ")",
    )
    p.add_argument("--gt", type=Path, default=None, metavar="RECORDING",
                   help="PRISM-format recording the reconstructions were made from: ground "
                        "truth, insole forces and contacts, and the subject's body")  # fmt: skip
    p.add_argument("--fps-video", type=positive_float, default=30.0, metavar="HZ",
                   help="video frame rate (default 30)")  # fmt: skip
    p.add_argument("--width", type=int, default=640, metavar="PX",
                   help="video width, even (default 640)")  # fmt: skip
    p.add_argument("--height", type=int, default=480, metavar="PX",
                   help="video height, even (default 480)")  # fmt: skip
    p.add_argument("--body-height", type=positive_float, default=None, metavar="M",
                   help="subject stature, m (default: from --gt, else 1.70)")  # fmt: skip
    p.add_argument("--body-mass", type=positive_float, default=None, metavar="KG",
                   help="subject mass, kg (default: from --gt, else 70)")  # fmt: skip
    p.add_argument("--bvh-unit", choices=("cm", "m"), default="cm",
                   help="length unit of the BVH file (default cm)")  # fmt: skip
    p.add_argument("--glb-frames", type=_frames, default=None, metavar="LIST",
                   help="frames of the single-frame meshes, e.g. 0,250,-1 (negative: from the "
                        "end; default: the middle frame)")  # fmt: skip
    p.add_argument("--strobe-every", type=int, default=None, metavar="N",
                   help="frames between two strobe poses (default: half a second)")  # fmt: skip
    add_limit_arguments(p)
    p.set_defaults(func=lambda args: cmd_export(args, p))


def _body(args: argparse.Namespace, gt, parser: argparse.ArgumentParser):
    from grip.core.body import BodyParams

    base = gt.body if gt is not None else BodyParams(_DEFAULT_HEIGHT_M, _DEFAULT_MASS_KG)
    height = args.body_height if args.body_height is not None else base.height_m
    mass = args.body_mass if args.body_mass is not None else base.mass_kg
    try:
        params = BodyParams(height_m=height, mass_kg=mass)
    except ValueError as e:
        parser.error(str(e).replace("BodyParams.height_m=", "--body-height ")
                     .replace("BodyParams.mass_kg=", "--body-mass "))  # fmt: skip
    if args.body_height is not None or args.body_mass is not None:
        source = "--body-height/--body-mass"
    elif gt is not None:
        source = f"subject of {args.gt}"
    else:
        source = "default; pass --gt or --body-height/--body-mass for the subject's"
    return params, source


def cmd_export(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Run ``grip export``. Returns 0, or 1 when some file could not be read or written."""
    limits_from_args(args)
    if "mp4" in args.formats:
        # MuJoCo picks its OpenGL backend when first imported; EGL works headless.
        os.environ.setdefault("MUJOCO_GL", "egl")
    from grip.cli.errors import CliError
    from grip.cli.recordings import skip_file
    from grip.core.reconstruction import Reconstruction, ReconstructionError
    from grip.export.common import ExportError, check_ground_truth, fk_mismatch_m

    video_cfg = None
    if "mp4" in args.formats:
        from grip.export.video import VideoConfig

        try:
            video_cfg = VideoConfig(fps=args.fps_video, width=args.width, height=args.height)
        except ValueError as e:
            parser.error(str(e).replace("VideoConfig.", "--"))
    if args.strobe_every is not None and args.strobe_every < 1:
        parser.error(f"argument --strobe-every: must be >= 1, got {args.strobe_every}")

    recons = []
    skipped: list[tuple[str, str]] = []
    for path in args.recons:
        try:
            recons.append((path, Reconstruction.load(path)))
        except (ReconstructionError, OSError) as e:  # reported, the others are exported
            skip_file(skipped, path, e)
    if not recons:
        raise CliError(f"none of the {len(args.recons)} reconstruction file(s) could be read")
    stems = [p.stem for p, _ in recons]
    dup = sorted({s for s in stems if stems.count(s) > 1})
    if dup:
        raise CliError(
            f"several reconstructions are named {dup[0]!r}: their exports would "
            "overwrite each other (export them into separate --out folders)"
        )

    gt = recording = None
    if args.gt is not None:
        from grip.kinematics.features import ground_truth
        from prism_tools.io import load_recording

        try:
            recording = load_recording(args.gt)
            gt = ground_truth(recording)
        except (OSError, ValueError, KeyError) as e:
            raise CliError(f"{args.gt}: cannot read the recording ({e})") from e
        for path, recon in recons:
            try:
                check_ground_truth(recon, gt)
            except ExportError as e:
                raise CliError(f"{path}: {e} (--gt {args.gt})") from e
    glb_frames: dict[Path, list[int]] = {}
    for path, recon in recons:
        frames = args.glb_frames if args.glb_frames is not None else (recon.n_frames // 2,)
        bad = [f for f in frames if not -recon.n_frames <= f < recon.n_frames]
        if bad:
            raise CliError(f"{path}: --glb-frames {bad} outside 0..{recon.n_frames - 1}")
        glb_frames[path] = sorted({f % recon.n_frames for f in frames})

    body, source = _body(args, gt, parser)
    print(f"body: {body.height_m:.3f} m, {body.mass_kg:.1f} kg ({source})")
    try:
        args.out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise CliError(f"{args.out}: cannot create the output folder ({e.strerror or e})") from e

    failures = 0
    video_broken: str | None = None
    for path, recon in recons:
        stem = path.stem
        print(f"{path}: {recon.name} ({recon.method}), {recon.n_frames} frames at "
              f"{recon.fps:g} Hz")  # fmt: skip
        mismatch_mm = 1000.0 * fk_mismatch_m(recon, body)
        if mismatch_mm > 10.0 and {"bvh", "glb", "mp4", "amass"} & set(args.formats):
            print(f"  note: the body model's joints differ from the reconstruction's by up to "
                  f"{mismatch_mm:.0f} mm (other subject?); BVH/GLB/MP4/AMASS show the body model "
                  "with the reconstruction's rotations and pelvis trajectory")  # fmt: skip
        for fmt in args.formats:
            if fmt == "mp4" and video_broken is not None:
                failures += 1
                continue
            try:
                for line in _export_one(fmt, recon, args, stem, body, gt, video_cfg,
                                        glb_frames[path], recording):  # fmt: skip
                    print(f"  {line}")
            except ExportError as e:
                failures += 1
                print(f"grip: error: {fmt} of {path}: {e}", file=sys.stderr)
            except _NoRenderBackend as e:
                failures += 1
                video_broken = str(e)
                print(f"grip: error: mp4 of {path} (and of any further reconstruction): {e}",
                      file=sys.stderr)  # fmt: skip
    if skipped:
        print(f"grip: {len(skipped)} reconstruction file(s) could not be read and were skipped",
              file=sys.stderr)  # fmt: skip
    if failures:
        print(f"grip: {failures} export(s) failed; the other files were written",
              file=sys.stderr)  # fmt: skip
    return 1 if failures or skipped else 0


def _export_one(fmt: str, recon, args: argparse.Namespace, stem: str, body, gt, video_cfg,
                frames: list[int], recording=None) -> Iterator[str]:  # fmt: skip
    """Write one format of one reconstruction, yielding a line to print per file written
    (``recording``: the --gt recording, for the html page's insoles and props)."""
    out: Path = args.out
    if fmt == "html":
        from grip.export.common import check_rotations
        from grip.export.html import write_viewer

        check_rotations(recon, out / f"{stem}.html")
        page = write_viewer(recon, out / f"{stem}.html", recording=recording, body=body)
        yield f"wrote {page.path} ({page.n_bytes / 1e6:.2f} MB, {len(page.labels)} bodies)"
        return
    if fmt == "bvh":
        from grip.export.bvh import write_bvh

        path = write_bvh(recon, out / f"{stem}.bvh", body, unit=args.bvh_unit)
        yield f"wrote {path} (y up, {args.bvh_unit})"
        return
    if fmt == "glb":
        from grip.export.glb import strobe_frames, write_pose_glb, write_strobe_glb

        every = args.strobe_every or max(1, round(recon.fps / 2))
        path = write_strobe_glb(recon, out / f"{stem}_strobe.glb", body, every=every)
        yield (f"wrote {path} ({len(strobe_frames(recon.n_frames, every))} poses, "
               f"every {every} frames, + floor)")  # fmt: skip
        for f in frames:
            yield f"wrote {write_pose_glb(recon, out / f'{stem}_f{f:06d}.glb', f, body)}"
        return
    if fmt == "mp4":
        from grip.export.video import RenderBackendError, write_video

        try:
            n = write_video(recon, out / f"{stem}.mp4", body, gt=gt, cfg=video_cfg)
        except RenderBackendError as e:
            raise _NoRenderBackend(str(e)) from e
        ghost = ", ground truth in green" if gt is not None else ""
        yield f"wrote {out / f'{stem}.mp4'} ({n} frames at {video_cfg.fps:g} fps{ghost})"
        return
    if fmt == "amass":
        from grip.export.amass import write_amass

        path = write_amass(recon, out / f"{stem}_amass.npz", body)
        yield f"wrote {path} (SMPL joint order, axis-angle, z up, m; GRIP's body, not SMPL)"
        return
    if fmt == "png":
        from grip.export.summary import write_summary_png

        stats = write_summary_png(recon, out / f"{stem}.png", gt=gt)
        shown = {k: v for k, v in stats.items()
                 if k in ("MPJPE_mm", "PEL_MPJPE_mm", "vGRF_N", "contact_agreement")}  # fmt: skip
        text = ", ".join(f"{k} {v:.3g}" for k, v in shown.items())
        yield f"wrote {out / f'{stem}.png'}" + (f" ({text})" if text else "")
        return
    raise ValueError(f"unknown export format {fmt!r}")
