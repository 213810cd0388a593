"""``grip policy gate``: a gate over frozen controllers, one per motion family."""

from __future__ import annotations

import argparse
from pathlib import Path

from policies.teachers import SPECIALIST_SYNTAX


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grip policy gate`` on the ``grip policy`` subparsers."""
    from grip.cli.common import PRECISIONS

    p = sub.add_parser(
        "gate",
        help="one policy file of several controllers, each frame driven by the one a "
        "classifier of the wearables picks",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Train a gate over frozen controllers (policies/gate.py): a small classifier of\n"
            "the frame's sensor features (the KinematicsNet's inputs: IMUs and insoles) that\n"
            "picks, every frame, which controller drives the humanoid: --default for every\n"
            "motion no --specialist names, each specialist for its family's categories. It\n"
            "is trained on the train split's recordings and their categories (no simulation;\n"
            "about a minute) and the routes it takes are printed per category for the train\n"
            "and the test split. OUT is a policy file like any other (grip policy eval,\n"
            "grip bench --policy, grip reconstruct --policy)."
        ),
        epilog="example: grip policy gate --default grip/assets/policy_default.pt "
        "--specialist 'sit-stand=runs/sit/policy.pt' --data data/person --out gated.pt",
    )
    p.add_argument(
        "--default",
        type=Path,
        default=None,
        metavar="POLICY",
        help="the controller of every other motion (default: the shipped one)",
    )
    p.add_argument(
        "--specialist",
        action="append",
        required=True,
        metavar=SPECIALIST_SYNTAX,
        help="a family's controller (repeatable), e.g. sit-stand,stairs=sit.pt",
    )
    p.add_argument("--data", required=True, type=Path, help="dataset folder (with split.json)")
    p.add_argument("--out", required=True, type=Path, help="the gated policy file to write")
    p.add_argument(
        "--kin",
        type=Path,
        default=None,
        help="KinematicsNet checkpoint whose input features the gate reads "
        "(default: the shipped one; the controllers' sensor observation)",
    )
    p.add_argument("--hidden", default="128,128", help="hidden layer sizes (default 128,128)")
    p.add_argument("--steps", type=int, default=3000, help="training steps (default 3000)")
    p.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    p.add_argument(
        "--precision",
        choices=PRECISIONS,
        default=None,
        help="weights of the members (default: as their files store them)",
    )
    p.set_defaults(func=cmd_gate)


def cmd_gate(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from grip.assets import SHIPPED_POLICY
    from grip.cli.errors import CliError
    from grip.cli.recordings import kin_checkpoint
    from grip.kinematics.dataset import load_split_sequences
    from grip.kinematics.inference import KinematicsEstimator
    from policies.gate import fit_gate, route_table, write_gated_policy
    from policies.teachers import Specialist

    default = args.default or SHIPPED_POLICY
    try:
        specialists = [Specialist.parse(text) for text in args.specialist]
        hidden = tuple(int(h) for h in args.hidden.split(","))
    except ValueError as e:
        raise CliError(f"{e}" if "--specialist" in str(e) else f"--hidden {args.hidden}: "
                       "expected sizes such as 128,128") from e  # fmt: skip
    files = [Path(default)] + [Path(s.policy) for s in specialists]
    for f in files:
        if not f.is_file():
            raise CliError(f"{f}: no such policy file")
    if args.steps < 1 or any(h < 1 for h in hidden):
        raise CliError("--steps and --hidden must be positive")
    kin = kin_checkpoint(args.kin)
    try:
        feats = KinematicsEstimator.from_checkpoint(kin).cfg.features
        train = load_split_sequences(args.data, "train", feats)
        test = load_split_sequences(args.data, "test", feats)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(str(e)) from e
    print(f"{len(train)} training and {len(test)} test recordings, {train[0].x.shape[1]} "
          f"sensor features per frame ({kin})")  # fmt: skip
    families = [s.categories for s in specialists]
    bar = tqdm(total=args.steps, desc="gate", unit="step")

    def step(loss: float) -> None:
        bar.update()
        bar.set_postfix(loss=f"{loss:.3f}", refresh=False)

    try:
        gate, _ = fit_gate(
            [s.x for s in train],
            [s.category for s in train],
            families,
            hidden=hidden,
            steps=args.steps,
            seed=args.seed,
            progress=step,
        )
    except ValueError as e:
        raise CliError(f"{args.data}: {e}") from e
    finally:
        bar.close()
    names = ["default"] + [",".join(f) for f in families]
    for split, seqs in (("train", train), ("test", test)):
        if seqs:
            print(
                f"\nroutes on the {split} split (share of each category's frames):\n"
                + route_table(gate, [s.x for s in seqs], [s.category for s in seqs], names)
            )
    try:
        size = write_gated_policy(files, gate, args.out, args.precision)
    except ValueError as e:
        raise CliError(str(e)) from e
    print(f"\nwrote {args.out} ({size / 1e6:.1f} MB): {len(files)} controllers and the gate")
    return 0
