"""DynamicsNet training throughput as a ratio to the single-environment benchmark.

In one run: the bare environment's step rate (one GripTrackingEnv, zero actions, as
``benchmarks/env_steps.py``), then short PPO + AMP trainings (rollout collection, discriminator
updates and PPO updates all included) with each vector-env layout. Prints env steps/s (simulated
frames per second) of each and its ratio to the bare env; with an action repeat k the policy
decides every k frames, so a training step covers k env steps.

    python benchmarks/policy_throughput.py                       # defaults of configs/policy
    python benchmarks/policy_throughput.py --layouts dummy:16,subproc:8,batched:16 --rollouts 4
    python benchmarks/policy_throughput.py --layouts dummy:16 --action-repeat 1,3
    python benchmarks/policy_throughput.py --layouts dummy:16,batched:16 --json tp.json

``batched`` is :class:`envs.batched.BatchedTrackingEnv` (all environments stepped by one call,
the physics in ``--env-threads`` threads). Decisions per core-hour divide by the cores the
process may use.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def bare_env_rate(steps: int) -> float:
    from envs.tracking_env import GripTrackingEnv

    env = GripTrackingEnv()
    env.reset(seed=0)
    a = np.zeros(env.action_space.shape)
    t = time.perf_counter()
    for _ in range(steps):
        _, _, te, tr, _ = env.step(a)
        if te or tr:
            env.reset()
    return steps / (time.perf_counter() - t)


def training_rate(cfg, rollouts: int) -> float:
    from envs.factory import make_tracking_env
    from envs.tracking_env import SAMPLE_REFERENCE
    from policies.train import PolicyTrainer

    steps = rollouts * cfg.ppo.n_steps * cfg.ppo.n_envs
    cfg = dataclasses.replace(
        cfg, stage1=dataclasses.replace(cfg.stage1, timesteps=steps, categories=()),
        stage2=dataclasses.replace(cfg.stage2, timesteps=0), checkpoint_every=10**6,
    )  # fmt: skip
    run = Path(tempfile.mkdtemp(prefix="grip_tp_"))
    try:
        tr = PolicyTrainer(cfg, run, SAMPLE_REFERENCE, make_tracking_env)
        t = time.perf_counter()
        tr.train()
        return tr.total_done() * cfg.env.action_repeat / (time.perf_counter() - t)
    finally:
        shutil.rmtree(run, ignore_errors=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--config", type=Path, default=ROOT / "configs" / "policy" / "default.toml")
    ap.add_argument("--layouts", default="dummy:16,batched:16",
                    help="vec_env:n_envs pairs, comma separated")  # fmt: skip
    ap.add_argument("--rollouts", type=int, default=3, help="PPO rollouts per layout")
    ap.add_argument("--env-steps", type=int, default=3000, help="steps of the bare-env reference")
    ap.add_argument("--threads", type=int, default=0, help="learner torch threads (0: default)")
    ap.add_argument(
        "--env-threads",
        type=int,
        default=0,
        help="physics threads of the batched layout (0: all cores)",
    )
    ap.add_argument(
        "--action-repeat",
        default="",
        help="comma-separated action repeats to measure (default: the config's)",
    )
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()

    from grip.config import load_config
    from policies.config import PolicyRunConfig

    base = load_config(args.config, PolicyRunConfig())
    ref = bare_env_rate(args.env_steps)
    print(f"bare env (1 env, zero actions): {ref:8.0f} steps/s")
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    out = {"bare_env_steps_per_s": ref, "cores": cores, "layouts": {}}
    repeats = [int(k) for k in args.action_repeat.split(",") if k] or [base.env.action_repeat]
    for item in args.layouts.split(","):
        kind, n = item.split(":")
        n = int(n)
        n_steps = max(base.ppo.n_steps, -(-base.ppo.batch_size // n))  # same batch per update
        for k in repeats:
            cfg = dataclasses.replace(
                base, env=dataclasses.replace(base.env, action_repeat=k),
                ppo=dataclasses.replace(base.ppo, vec_env=kind, n_envs=n, n_steps=n_steps,
                                        threads=args.threads, env_threads=args.env_threads),
            )  # fmt: skip
            rate = training_rate(cfg, args.rollouts)
            name = f"{item} repeat {k}"
            per_core_h = rate / k * 3600 / cores
            out["layouts"][name] = {"steps_per_s": rate, "ratio_to_bare_env": rate / ref,
                                    "decisions_per_core_hour": per_core_h}  # fmt: skip
            print(f"PPO+AMP training {name:>20}: {rate:8.0f} env steps/s  ratio {rate / ref:.3f}"
                  f"  {per_core_h / 1e6:.2f} M decisions/core-hour")  # fmt: skip
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
