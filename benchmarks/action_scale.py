"""Does the controller's pose gap come from its offsets? A policy file whose actions move the PD
targets less far from the estimate's pose.

A relative action moves each hinge's PD target from the KinematicsNet pose by ``action x
env.action_scale x`` half the hinge's range. This writes a copy of a single policy file with
``env.action_scale`` times ``--scale`` (the same network, the same observations: its offsets
shrunk at inference), to be played like any policy:

    python benchmarks/action_scale.py --policy grip/assets/policy_default.pt --scale 0.6 \
        --out P60.pt
    grip bench --data DATA --out B60 --methods grip --policy P60.pt --workers 1
    python benchmarks/bench_compare.py BASE_BENCH B60 --pose-by-events --paired

docs/teacher_student.md § K1 reads the pose on the segments neither version falls in.
"""

from __future__ import annotations

import argparse
import json
import sys

from policies.runner import read_policy_file, write_policy_file


def scaled(policy: str, scale: float, out: str) -> float:
    """Write ``policy`` (one member) with its ``env.action_scale`` times ``scale`` to ``out``;
    returns the new action scale."""
    members, names = read_policy_file(policy)
    if len(members) != 1:
        raise ValueError(f"{policy}: {len(members)} members; one policy expected")
    if not 0.0 < scale <= 2.0:
        raise ValueError(f"--scale must be in (0, 2], got {scale}")
    cfg = json.loads(members[0]["config"])
    cfg["env"]["action_scale"] = float(cfg["env"]["action_scale"]) * scale
    members[0]["config"] = json.dumps(cfg)
    write_policy_file(members, names, out)
    return cfg["env"]["action_scale"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--policy", required=True, help="a policy file of one member")
    ap.add_argument("--scale", type=float, required=True, help="factor on env.action_scale")
    ap.add_argument("--out", required=True, help="the policy file to write")
    args = ap.parse_args(argv)
    try:
        new = scaled(args.policy, args.scale, args.out)
    except (OSError, ValueError) as e:
        print(e, file=sys.stderr)
        return 2
    print(f"wrote {args.out}: env.action_scale {new:g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
