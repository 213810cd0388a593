"""``grip data import``: device exports (Moticon OpenGo insoles, wrist/foot IMU CSVs) -> one
PRISM-format recording without ground truth (:func:`prism_tools.devices.import_devices`)."""

from __future__ import annotations

import argparse
from pathlib import Path

IMPORT_DESCRIPTION = (
    "Import what the devices recorded into one PRISM-format recording that 'grip reconstruct\n"
    "REC --init standing' reads (no motion capture needed; docs/devices.md):\n"
    "  --insoles: a Moticon OpenGo text export (.txt: 16 pressures, acceleration, angular rate,\n"
    "    total force and CoP per side; N/cm², g, deg/s, N, normalised CoP);\n"
    "  --imu PART=FILE (repeatable; PART L_Wrist, R_Wrist, L_Foot, R_Foot, ...): a Movella DOT\n"
    "    CSV export (PacketCounter, SampleTimeFine, Quat_*, Acc_*, Gyr_*: its own units) or a\n"
    "    generic CSV with the header time,ax,ay,az,gx,gy,gz,qw,qx,qy,qz in the units of\n"
    "    --acc-unit/--acc-has-gravity/--gyro-unit/--quat-order (default m/s² with gravity,\n"
    "    rad/s, wxyz). Without quaternion columns the orientation is filtered from the\n"
    "    accelerometer and gyroscope. A foot without --imu uses its insole's built-in IMU.\n"
    "Protocol (GRIP's): all sensors on, stand still in the T-pose facing the direction that\n"
    "becomes +y for at least a second, jump once with the arms still, then record.\n"
    "The files are synchronised by the jump's landing peak (--no-sync: they share a clock),\n"
    "resampled to 100 Hz on one time axis over the span they all cover, and the recording\n"
    "starts at the still T-pose, which calibrates each sensor's mount and heading. The\n"
    "summary names the landing found in each file, the clock offsets, the gaps bridged and the\n"
    "duration; a file without a jump (sync on), with a gap over --max-gap, a wrong column\n"
    "count, a non-numeric value, missing columns or a time that does not increase is refused\n"
    "with its name and line."
)


def add_import_parser(dsub: argparse._SubParsersAction) -> None:
    """Registers ``grip data import`` in the ``grip data`` group."""
    from grip.cli.common import positive_float
    from grip.cli.recordings import add_limit_arguments

    p = dsub.add_parser(
        "import",
        help="device exports (Moticon insoles, IMU CSVs) -> a PRISM-format recording",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=IMPORT_DESCRIPTION,
        epilog="example: grip data import --insoles take1.txt --imu L_Wrist=lw.csv "
        "--imu R_Wrist=rw.csv --out data/mine/take1.npz --subject-height 1.78\n"
        "         grip reconstruct data/mine/take1.npz --init standing --out recon",
    )
    p.add_argument("--insoles", type=Path, default=None, metavar="MOTICON.txt",
                   help="Moticon OpenGo text export (both insoles)")  # fmt: skip
    p.add_argument("--imu", action="append", default=[], metavar="PART=FILE",
                   help="an IMU CSV and the part it sat on (repeatable): L_Wrist, R_Wrist, "
                   "L_Foot, R_Foot (a foot without one takes its insole's IMU), Head, Pelvis, "
                   "L_Knee, R_Knee")  # fmt: skip
    p.add_argument("--out", required=True, type=Path, help="output recording (.npz or .pkl)")
    p.add_argument("--subject-height", type=positive_float, default=1.70, metavar="M",
                   help="body height, m (default 1.70): the body model's foot and cell sizes")
    p.add_argument("--subject-mass", type=positive_float, default=None, metavar="KG",
                   help="body mass, kg (default: the insoles' total force while standing still "
                   "/ g; 70 without both insoles)")  # fmt: skip
    p.add_argument("--acc-unit", choices=("g", "mps2"), default=None,
                   help="acceleration unit of generic IMU CSVs (default mps2)")
    p.add_argument("--acc-has-gravity", action=argparse.BooleanOptionalAction, default=None,
                   help="generic IMU CSVs' accelerations include gravity (an accelerometer's "
                   "reading; the default) or not (gravity removed, sensor frame)")
    p.add_argument("--gyro-unit", choices=("deg", "rad"), default=None,
                   help="angular-rate unit of generic IMU CSVs: deg/s or rad/s (default rad)")
    p.add_argument("--quat-order", choices=("wxyz", "xyzw"), default=None,
                   help="order of positional quaternion columns q0..q3 of generic IMU CSVs "
                   "(default wxyz; named columns qw,qx,qy,qz need none)")  # fmt: skip
    p.add_argument("--no-sync", action="store_true",
                   help="do not look for the jump: the files' clocks are one")
    p.add_argument("--calib-at", type=float, default=None, metavar="SECONDS",
                   help="start of the still T-pose on the reference file's clock (the insoles', "
                   "else the first --imu's); default: the first still second before the jump")
    p.add_argument("--calib-seconds", type=positive_float, default=1.0, metavar="S",
                   help="length of the still window averaged for the calibration (default 1)")
    p.add_argument("--max-gap", type=positive_float, default=0.2, metavar="S",
                   help="longest run of missing samples interpolated, s (default 0.2)")
    p.add_argument("--mount", action="append", default=[], metavar="PART=X,Y,Z",
                   help="where a sensor's x, y, z axes point in the T-pose (forward, back, left, "
                   "right, up, down; repeatable); defaults: feet forward,left,up; L_Wrist "
                   "left,back,up; R_Wrist right,forward,up (x along the forearm to the hand, z "
                   "out of the back of the wrist)")  # fmt: skip
    p.add_argument("--name", default=None, help="take name (default: the first file's stem)")
    p.add_argument("--category", default=None,
                   help="activity category of the take (for per-category tables)")
    add_limit_arguments(p)
    p.set_defaults(func=cmd_import)


def _parse_imus(items: list[str]) -> dict[str, Path]:
    from grip.cli.errors import CliError
    from prism_tools.streams import IMU_PARTS

    out: dict[str, Path] = {}
    for item in items:
        part, sep, file = item.partition("=")
        part = part.strip()
        if not sep or not file:
            raise CliError(f"--imu {item!r}: expected PART=FILE, e.g. L_Wrist=left_watch.csv")
        if part not in IMU_PARTS:
            raise CliError(f"--imu {item!r}: unknown part {part!r}; choose from "
                           f"{', '.join(IMU_PARTS)}")  # fmt: skip
        if part in out:
            raise CliError(f"--imu: {part} given twice")
        out[part] = Path(file)
    return out


def cmd_import(args: argparse.Namespace) -> int:
    from grip.cli.errors import CliError
    from grip.cli.recordings import limits_from_args
    from prism_tools.devices import ImportOptions, ImuCsvOptions, import_devices
    from prism_tools.devices.calibrate import parse_mount
    from prism_tools.errors import RecordingError
    from prism_tools.io import save_recording

    limits = limits_from_args(args)
    imus = _parse_imus(args.imu)
    if args.insoles is None and not imus:
        raise CliError("nothing to import: give --insoles and/or --imu PART=FILE")
    if args.out.suffix.lower() not in (".npz", ".pkl"):
        raise CliError(f"--out {args.out}: the recording must be a .npz or .pkl file")
    try:
        mounts = dict(parse_mount(m) for m in args.mount)
        options = ImportOptions(
            sync=not args.no_sync, calib_s=args.calib_seconds, calib_at_s=args.calib_at,
            max_gap_s=args.max_gap, subject_height_m=args.subject_height,
            subject_mass_kg=args.subject_mass, mounts=mounts, name=args.name,
            category=args.category,
        )  # fmt: skip
        csv_options = ImuCsvOptions(acc_unit=args.acc_unit, acc_has_gravity=args.acc_has_gravity,
                                    gyro_unit=args.gyro_unit, quat_order=args.quat_order)
        rec, report = import_devices(args.insoles, imus, options, csv_options, limits,
                                     progress=print)  # fmt: skip
        save_recording(rec, args.out)
    except (FileNotFoundError, RecordingError, ValueError, OSError) as e:
        raise CliError(str(e)) from e
    print(_summary(report, args.out))
    return 0


def _summary(report, out: Path) -> str:
    """The closing lines: clocks, gaps, the recording."""
    lines = []
    for s in report.streams:
        clock = ("reference clock" if s.name == report.reference
                 else f"clock offset {s.offset_s:+.3f} s")  # fmt: skip
        landing = "" if s.landing_s is None else f"jump landing at {s.landing_s:.3f} s, "
        gaps = "; ".join(
            f"{label}: {c['samples']} samples at {c['rate_hz']:.4g} Hz, " + (
                f"{c['missing']} missing in {c['gaps']} gap(s) (longest "
                f"{c['longest_gap_s']:.3f} s)" if c["gaps"] else "no gaps")
            for label, c in s.channels.items())  # fmt: skip
        dropped = f"; {s.dropped_rows} row(s) with missing values dropped" if s.dropped_rows else ""
        lines.append(f"  {s.name} ({s.file}, {s.kind}): {landing}{clock}; {gaps}{dropped}")
    jump = "" if report.jump_frame is None else f", jump landing at frame {report.jump_frame}"
    lines.append(
        f"wrote {out}: {report.frames} frames ({report.duration_s:.2f} s at {report.fps:g} Hz) "
        f"from {report.start_reference_s:.3f} s on the {report.reference} clock; calibration "
        f"frames {report.calib_frames[0]}-{report.calib_frames[1] - 1}{jump}; subject "
        f"{report.subject_mass_kg:.1f} kg ({report.mass_source}); IMUs {', '.join(report.sites)}"
    )
    lines += [f"note: {n}" for n in report.notes]
    return "\n".join(lines)
