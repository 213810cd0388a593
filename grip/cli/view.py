"""``grip view``: one self-contained interactive HTML page of a reconstruction."""

from __future__ import annotations

import argparse
import zipfile
from pathlib import Path

from grip.cli.recordings import add_limit_arguments, limits_from_args


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grip view`` on the ``grip`` subparsers."""
    p = sub.add_parser(
        "view",
        help="write an interactive HTML page (3D body, ground truth, other methods, GRF)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Write one self-contained HTML page that plays a reconstruction in 3D (three.js,\n"
            "inlined: it works offline and from file://, no server):\n"
            "  - the body model posed by RECON.npz (GRIP's simulated humanoid),\n"
            "  - the ground truth of --gt as a green ghost, the recording's objects (props)\n"
            "    and its insoles' centre of pressure and force,\n"
            "  - other methods' reconstructions of the same recording (--compare), each in\n"
            "    its colour, overlaid or side by side,\n"
            "  - the centre of pressure and ground reaction force of each foot,\n"
            "  - play/pause, speed, a frame slider, a timeline with the fall events (frames\n"
            "    recovered from the history buffer, detection) and the vertical GRF of each\n"
            "    foot against the insole force with a cursor at the current frame,\n"
            "  - the pace: the horizontal distance of the humanoid's pelvis to the estimate's\n"
            "    pelvis it followed (also drawn in 3D, where RECON.npz records it) and of each\n"
            "    body's pelvis to the ground truth's (with --gt), under the timeline.\n"
            "Add #frame=N to the page's address to open it at frame N."
        ),
        epilog="example: grip view runs/rc/seq000.npz --gt data/seq000.npz \\\n"
        "           --compare demo_out/seq000.kinematics.npz --out seq000.html",
    )
    p.add_argument("recon", type=Path, metavar="RECON.npz",
                   help="reconstruction file (grip.core.reconstruction format)")  # fmt: skip
    p.add_argument("--out", required=True, type=Path, metavar="PAGE.html",
                   help="the page to write (atomically; its folder is created)")  # fmt: skip
    p.add_argument("--gt", type=Path, default=None, metavar="RECORDING",
                   help="PRISM-format recording the reconstruction was made from: ground truth, "
                        "insoles, objects and the subject's body")  # fmt: skip
    p.add_argument("--compare", type=Path, nargs="+", action="extend", default=[],
                   metavar="OTHER.npz",
                   help="reconstructions of the same recording by other methods (same frames "
                        "and frame rate); repeatable")  # fmt: skip
    p.add_argument("--title", default=None, metavar="TEXT",
                   help="page title (default: the reconstruction's name)")  # fmt: skip
    add_limit_arguments(p)
    p.set_defaults(func=cmd_view)


def _labels(main: tuple[Path, object], recons: list[tuple[Path, object]]) -> list[str]:
    """Each compared reconstruction's method, with its file's name where methods repeat (the
    shown reconstruction's included: two policies' runs are both "grip"), or its folder's name
    where the file names repeat too (the same recording reconstructed into two folders), or its
    path where both do."""
    everyone = [main, *recons]
    methods = [r.method for _, r in everyone]
    names = [p.name for p, _ in everyone]
    folders = [p.parent.name for p, _ in everyone]

    def where(p: Path) -> str:
        if names.count(p.name) == 1:
            return p.name
        return p.parent.name if folders.count(p.parent.name) == 1 else str(p)

    return [m if methods.count(m) == 1 else f"{m} ({where(p)})" for (p, _), m in
            zip(recons, methods[1:], strict=True)]  # fmt: skip


def _lacks_joints(path: Path) -> bool:
    """Whether ``path`` is a zip (npz) archive without a ``joint_pos`` member."""
    try:
        with zipfile.ZipFile(path) as z:
            return "joint_pos.npy" not in z.namelist()
    except (OSError, zipfile.BadZipFile):
        return False


def cmd_view(args: argparse.Namespace) -> int:
    """Run ``grip view``. Returns 0; any unreadable or mismatched input is a CliError."""
    limits_from_args(args)
    from grip.assets import ASSETS
    from grip.cli.errors import CliError
    from grip.core.reconstruction import Reconstruction, ReconstructionError
    from grip.export.common import ExportError, check_rotations, fk_mismatch_m
    from grip.export.html import check_compatible, load_web_assets, write_viewer

    def load(path: Path) -> Reconstruction:
        try:
            return Reconstruction.load(path)
        except ReconstructionError as e:
            text = str(e)
            if _lacks_joints(path):  # the loader only says "no frames"
                raise CliError(
                    f"{path}: no joint positions ('joint_pos', (T, 24, 3)) in this "
                    f"reconstruction; the viewer needs them ({text})"
                ) from e
            raise CliError(text if str(path) in text else f"{path}: {text}") from e
        except OSError as e:
            raise CliError(f"{path}: cannot read the reconstruction "
                           f"({e.strerror or e})") from e  # fmt: skip

    recon = load(args.recon)
    compare = [(path, load(path)) for path in args.compare]
    for path, other in compare:
        try:
            check_compatible(recon, other)
        except ExportError as e:
            raise CliError(f"--compare {path}: {e} (RECON.npz is {args.recon})") from e

    recording = None
    if args.gt is not None:
        from prism_tools.io import load_recording

        try:
            recording = load_recording(args.gt)
        except (OSError, ValueError, KeyError) as e:
            raise CliError(f"{args.gt}: cannot read the recording ({e})") from e
    try:
        assets = load_web_assets(ASSETS / "web")
    except ExportError as e:
        raise CliError(f"{e} (reinstall the package)") from e

    print(f"{args.recon}: {recon.name} ({recon.method}), {recon.n_frames} frames at "
          f"{recon.fps:g} Hz, {recon.falls.shape[0]} fall event(s)")  # fmt: skip
    try:
        for r in (recon, *(r for _, r in compare)):  # (a zero or mirrored rotation: refused)
            check_rotations(r)
        labels = _labels((args.recon, recon), compare)
        page = write_viewer(recon, args.out, assets, recording=recording,
                            compare=[r for _, r in compare], compare_labels=labels,
                            title=args.title)  # fmt: skip
    except ExportError as e:
        text = str(e)
        if text.startswith(str(args.out)):  # the page could not be written
            raise CliError(text) from e
        where = f" (--gt {args.gt})" if args.gt is not None else ""
        raise CliError(f"{args.recon}: {text}{where}") from e
    if recording is not None:
        from grip.kinematics.features import recording_body

        mismatch_mm = 1000.0 * fk_mismatch_m(recon, recording_body(recording))
    else:
        mismatch_mm = 1000.0 * fk_mismatch_m(recon)
    if mismatch_mm > 10.0:
        print(f"  note: the body model's joints differ from the reconstruction's by up to "
              f"{mismatch_mm:.0f} mm (other subject? pass --gt); the page shows the body model "
              "with the reconstruction's rotations and pelvis trajectory")  # fmt: skip
    print(f"wrote {page.path} ({page.n_bytes / 1e6:.2f} MB: {page.frames} frames, "
          f"{len(page.labels)} bod{'y' if len(page.labels) == 1 else 'ies'}: "
          f"{', '.join(page.labels)}); open it in a browser, no "
          "server needed")  # fmt: skip
    return 0
