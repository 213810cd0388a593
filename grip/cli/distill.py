"""``grip policy distill``: one network that acts like an ensemble (DAgger)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from policies.teachers import SPECIALIST_SYNTAX

DEFAULT_CONFIG = "configs/policy/distill.toml"


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grip policy distill`` on the ``grip policy`` subparsers."""
    p = sub.add_parser(
        "distill",
        help="distil a policy ensemble into one network (DAgger on the training clips)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Train one student network to act like a teacher policy, usually an ensemble\n"
            "(its mean action), on the states the student itself visits (DAgger): each\n"
            "iteration rolls out the training environments (random starts on the training\n"
            "clips, falls end episodes) with the student acting, or the teacher with a\n"
            "probability that halves every iteration (beta_decay), labels every observation\n"
            "with the teacher's action and fits the student to all labels so far. It takes\n"
            "one member's network shape, observation normaliser and weights, so RUN/policy.pt\n"
            "is an ordinary policy file (grip policy eval; grip policy train --init fine-tunes\n"
            "it). Checkpoints after every iteration; the same command resumes.\n"
            f"Settings: {DEFAULT_CONFIG} (--config, --set)."
        ),
        epilog="example: grip policy distill --teacher grip/assets/policy_default.pt "
        "--data data/prism_synth --out runs/distill\n"
        "         grip policy distill --teacher a.pt --teacher b.pt --data data/prism_synth "
        "--out runs/d --set iterations=4 --set init_member=1",
    )
    p.add_argument("--teacher", type=Path, action="append", default=None, metavar="POLICY",
                   help="policy or ensemble file (default: the shipped one); repeat it for the "
                   "mean action of several")  # fmt: skip
    p.add_argument("--specialist", action="append", default=[], metavar=SPECIALIST_SYNTAX,
                   help="the teacher of one motion family (repeatable): clips whose category "
                   "matches one of the globs learn from this policy file, every other clip "
                   "from --teacher (e.g. walk-back,walk-side=runs/spec_walkbs/policy.pt)")
    p.add_argument("--data", required=True, type=Path, help="dataset folder (with split.json)")
    p.add_argument("--out", required=True, type=Path, help="run folder (created or resumed)")
    p.add_argument("--kin", type=Path, default=None,
                   help="KinematicsNet checkpoint that makes the references (default: the "
                   "shipped one)")  # fmt: skip
    p.add_argument("--config", type=Path, default=None,
                   help=f"TOML overrides (default: {DEFAULT_CONFIG})")  # fmt: skip
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override one setting, e.g. --set iterations=4 (repeatable)")  # fmt: skip
    p.add_argument("--precision", default="fp16", choices=("fp32", "fp16", "int8"),
                   help="weights of RUN/policy.pt (default fp16)")  # fmt: skip
    p.set_defaults(func=cmd_distill)


def cmd_distill(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from envs.factory import make_tracking_env
    from grip.assets import SHIPPED_POLICY
    from grip.cli.errors import CliError
    from grip.cli.paths import REPO_ROOT, load_run_config
    from grip.cli.policy_runs import build_training_reference
    from grip.cli.recordings import kin_checkpoint, split_paths
    from policies.distill import DistillConfig, Distiller, plot_distill_curves
    from policies.teachers import Specialist

    cfg = load_run_config(args.config or REPO_ROOT / DEFAULT_CONFIG, "distill", DistillConfig(),
                          args.set)  # fmt: skip
    teachers = args.teacher or [SHIPPED_POLICY]
    for t in teachers:
        if not Path(t).is_file():
            raise CliError(f"{t}: no such policy file")
    try:
        specialists = [Specialist.parse(text) for text in args.specialist]
    except ValueError as e:
        raise CliError(str(e)) from e
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    kin = kin_checkpoint(args.kin)
    ref_path = out / "reference_train.npz"
    build_training_reference(ref_path, args.data, split_paths(args.data, "train"), [kin],
                             cfg.reverse_categories, cfg.mirror_references,
                             follow="both" if cfg.truth_references else "estimate",
                             speed_factors=tuple(cfg.speed_factors),
                             speed_categories=tuple(cfg.speed_categories))  # fmt: skip
    try:  # (refuses to resume with other settings than iterations changed, or other teachers)
        dist = Distiller(cfg, teachers, out, ref_path, make_tracking_env, progress=tqdm,
                         log=tqdm.write, specialists=specialists)
    except ValueError as e:
        raise CliError(str(e)) from e
    dist.rundir.write_config(cfg, teacher=dist.teacher_resolved,
                             specialists=dist.specialists_resolved,
                             data=str(args.data.resolve()), kin=str(kin.resolve()))  # fmt: skip
    names = dist.teacher_names
    print(f"teacher: {len(names)} polic{'ies' if len(names) > 1 else 'y'}; the student starts "
          f"from member {cfg.init_member}, {names[cfg.init_member]}"
          f"{' (fresh weights)' if cfg.fresh_student else ''}")  # fmt: skip
    for sp in specialists:
        print(f"specialist: clips of {', '.join(sp.categories)} learn from {sp.policy}")
    t0 = time.perf_counter()
    try:
        dist.run()
    except ValueError as e:
        raise CliError(str(e)) from e
    print(f"distilled {dist.iteration} iterations ({dist.wall_s():.0f} s in all; this call "
          f"{time.perf_counter() - t0:.0f} s)")  # fmt: skip
    plot_distill_curves(dist.history, out / "curves.png")
    size = dist.export(out / "policy.pt", args.precision)
    print(f"wrote {out / 'policy.pt'} ({size / 1e6:.1f} MB) and {out / 'curves.png'}")
    return 0
