"""``grip body``: export the MuJoCo humanoid of one subject as an MJCF file."""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

from grip.cli.common import positive_float

# Subject options: flag -> (BodyParams field, metavar, help text).
_BODY_OPTIONS: dict[str, tuple[str, str, str]] = {
    "--height": ("height_m", "M", "stature, m (default 1.70)"),
    "--mass": ("mass_kg", "KG", "body mass, kg (default 70)"),
    "--leg-length": ("leg_length_m", "M", "measured leg length, hip joint centre to floor, m"),
    "--arm-length": ("arm_length_m", "M", "measured arm length, shoulder to wrist joint, m"),
    "--foot-length": ("foot_length_m", "M", "foot (shoe) length, heel to toe tip, m"),
}


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grip body export`` on the ``grip`` subparsers."""
    from grip.cli.common import add_group

    bsub = add_group(sub, "body", "export the MuJoCo humanoid of a subject",
                     "Tools for the project's body model (SMPL topology, own proportions).")
    e = bsub.add_parser(
        "export",
        help="write the humanoid as an MJCF (MuJoCo XML) file",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Build the body model of one subject and write the MuJoCo humanoid: 24 bodies in\n"
            "SMPL order, a free root and 69 hinges with PD position actuators, capsule limbs,\n"
            "box feet on sole pads, 8 IMU sites, 32 insole cells with touch sensors, a floor,\n"
            "and the keyframe 'stand' (T-pose on the floor, facing +y)."
        ),
        epilog="example: grip body export --out subject.xml --height 1.82 --mass 78\n"
        "         python -m mujoco.viewer --mjcf subject.xml",
    )
    e.add_argument("--out", required=True, type=Path, metavar="FILE.xml",
                   help="output file (written atomically; parent folders are created)")  # fmt: skip
    for flag, (_, metavar, text) in _BODY_OPTIONS.items():
        e.add_argument(flag, type=positive_float, default=None, metavar=metavar, help=text)
    e.add_argument("--timestep", type=positive_float, default=None, metavar="S",
                   help="physics step, s (default 0.005)")  # fmt: skip
    e.add_argument("--no-insole-sensors", action="store_true",
                   help="leave out the 32 insole touch sensors")  # fmt: skip
    e.set_defaults(func=lambda args: cmd_export(args, e))


def _write_atomic(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; an exported model is meant to be shared
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def cmd_export(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Run ``grip body export``; invalid numbers end in ``parser.error`` (exit code 2)."""
    from grip.core.body import BodyParams, build_body
    from grip.core.mjcf import MjcfConfig, build_mjcf

    values = {field: getattr(args, flag[2:].replace("-", "_"))
              for flag, (field, _, _) in _BODY_OPTIONS.items()}  # fmt: skip
    try:
        params = BodyParams(**{k: v for k, v in values.items() if v is not None})
    except ValueError as err:
        for flag, (field, _, _) in _BODY_OPTIONS.items():
            if f"BodyParams.{field}=" in str(err):
                parser.error(f"argument {flag}: {str(err).replace(f'BodyParams.{field}=', '')}")
        parser.error(str(err))
    cfg_kw: dict[str, object] = {"insole_sensors": not args.no_insole_sensors}
    if args.timestep is not None:
        cfg_kw["timestep_s"] = args.timestep
    try:
        cfg = MjcfConfig(**cfg_kw)  # type: ignore[arg-type]
    except ValueError as err:
        parser.error(f"argument --timestep: {err}")

    body = build_body(params)
    xml = build_mjcf(body, cfg)
    nq, nv, nu = 7 + 3 * (len(body.masses) - 1), 6 + 3 * (len(body.masses) - 1), 0
    try:  # verify with MuJoCo itself when it is installed (imported here, not at CLI start-up)
        import mujoco

        model = mujoco.MjModel.from_xml_string(xml)
        nq, nv, nu = model.nq, model.nv, model.nu
        total = float(mujoco.mj_getTotalmass(model))
    except ImportError:
        nu = 3 * (len(body.masses) - 1)
        total = body.total_mass
    _write_atomic(args.out, xml)
    print(f"wrote {args.out}")
    print(
        f"  subject: height {params.height_m:.3f} m, mass {total:.2f} kg, "
        f"pelvis height {body.pelvis_height:.3f} m, foot length {body.foot_length:.3f} m"
    )
    print(f"  model: nq={nq} nv={nv} nu={nu}, timestep {cfg.timestep_s:g} s, "
          f"insole sensors {'on' if cfg.insole_sensors else 'off'}")  # fmt: skip
    print(f"  view it: python -m mujoco.viewer --mjcf {args.out}")
    return 0
