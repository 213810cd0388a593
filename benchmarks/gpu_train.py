"""Throughput of the tracking task on MuJoCo Warp (:class:`envs.warp.env.WarpTrackingEnv`).

For each number of worlds N it builds the env on the device, plays ``--warmup`` decisions (the
first ones compile MuJoCo Warp's kernels, about a minute on a cold CPU cache; they are timed
apart) and then times ``--decisions`` decisions of random actions (N(0, 0.3) clipped, as a
young policy's), resetting the worlds whose episode ended after each decision, as training
does. It reports:

* ``decisions_per_s``: N x decisions / s, the rate at which PPO receives transitions;
* ``env_frames_per_s``: N x frames / s, simulated 100 Hz frames (each decision holds its action
  for ``env.action_repeat`` frames of ``env.substeps`` physics steps);
* ``physics_steps_per_s``: env frames x substeps;
* ``build_s`` (models, clip tables, warp arrays) and ``warmup_s``.

    python benchmarks/gpu_train.py --device cuda --envs 1024 4096 8192 --json gpu_env.json
    python benchmarks/gpu_train.py --device cpu --envs 8 --decisions 5   # MuJoCo Warp's CPU

``--physics flat stairs`` instead compares MuJoCo Warp with MuJoCo C from the same states and
controls (:mod:`envs.warp.physics_check`; ``--steps`` physics steps): on the flat floor, four
states of the first bundled clip driven toward its estimate; on the stairs, the standing
humanoid of :data:`envs.warp.physics_check.TERRAIN_CASES`. It prints, per world, the root and
hinge differences after 1, 10, 50, 100, 200, 400 steps and the share of steps whose contact
pairs agree (docs/gpu.md, "MuJoCo Warp against MuJoCo C").

The env settings are those of a policy recipe (``--config``, default
``configs/policy/default.toml``) on the bundled sample clips (``--reference`` for others). The
training part of issue 36's script (PPO + AMP on the device, a learning curve) is not written
yet: docs/gpu.md says what is measured.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _shown(path: str) -> str:
    """``path`` relative to the repository when it lies inside it (JSON files stay portable)."""
    p = Path(path).resolve()
    return str(p.relative_to(ROOT)) if p.is_relative_to(ROOT) else str(p)


def _sync(device: str) -> None:
    import torch
    import warp as wp

    wp.synchronize_device(device)
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def measure(env_cfg, reference, n: int, device: str, decisions: int, warmup: int,
            seed: int, nconmax: int, njmax: int) -> dict:  # fmt: skip
    """The figures of one N (see the module docstring)."""
    import torch

    from envs.warp.env import WarpTrackingEnv

    t0 = time.perf_counter()
    env = WarpTrackingEnv(env_cfg, reference, n, device=device, seed=seed, nconmax=nconmax,
                          njmax=njmax)  # fmt: skip
    _sync(device)
    build_s = time.perf_counter() - t0
    gen = torch.Generator(device=env.device)
    gen.manual_seed(seed)

    def play(k: int) -> tuple[int, int]:
        frames = ends = 0
        for _ in range(k):
            a = (0.3 * torch.randn(n, 69, generator=gen, device=env.device)).clamp(-1.0, 1.0)
            _, _, term, trunc, info = env.step(a)
            done = term | trunc
            frames += int(info["frames"].sum())
            ends += int(done.sum())
            env.reset(done)
        return frames, ends

    t0 = time.perf_counter()
    play(warmup)
    _sync(device)
    warmup_s = time.perf_counter() - t0
    if device.startswith("cuda"):
        torch.cuda.reset_peak_memory_stats()
    t0 = time.perf_counter()
    frames, ends = play(decisions)
    _sync(device)
    wall = time.perf_counter() - t0
    out = {
        "envs": n,
        "decisions": decisions,
        "wall_s": wall,
        "build_s": build_s,
        "warmup_s": warmup_s,
        "decisions_per_s": n * decisions / wall,
        "env_frames_per_s": frames / wall,
        "physics_steps_per_s": frames * env_cfg.substeps / wall,
        "episode_ends": ends,
        "contact_overflow": env.overflowed(),
    }
    if device.startswith("cuda"):
        out["peak_torch_memory_gb"] = torch.cuda.max_memory_allocated() / 2**30
    return out


def physics(scenario: str, device: str, steps: int, reference) -> dict:
    """MuJoCo Warp against MuJoCo C in one scenario (``"flat"`` or a terrain name)."""
    from envs.warp.physics_check import TERRAIN_CASES, compare_physics, terrain_case, tracking_case
    from grip.task.config import TrackingEnvConfig

    cfg = TrackingEnvConfig(terrain=scenario)
    if scenario == "flat":
        starts = [0, 30, 60, 90]
        case = tracking_case(cfg, reference, 0, starts, steps)
        labels = [f"clip 0 from frame {s}" for s in starts]
    else:
        case = terrain_case(cfg, steps)
        labels = [f"x {x} y {y} lift {z} vy {v}" for x, y, z, v in TERRAIN_CASES]
    gap = compare_physics(*case, device=device)
    marks = [k for k in (1, 10, 50, 100, 200, 400, 1000) if k <= steps]
    worlds = []
    for w, label in enumerate(labels):
        row = {
            "world": label,
            "root_pos_m": {k: float(gap.root_pos_m[w, k - 1]) for k in marks},
            "hinge_rad": {k: float(gap.hinge_rad[w, k - 1]) for k in marks},
            "contact_pairs_agree": float(gap.contacts_equal[w].mean()),
            "pairs_per_step_c": float(gap.pairs_c[w].mean()),
            "pairs_per_step_warp": float(gap.pairs_warp[w].mean()),
            "contacts_per_step_c": float(gap.contacts_c[w].mean()),
            "contacts_per_step_warp": float(gap.contacts_warp[w].mean()),
        }
        worlds.append(row)
        print(f"{scenario:>7} | {label:<28} | root m "
              + " ".join(f"{k}:{v:.1e}" for k, v in row["root_pos_m"].items())
              + " | hinge rad " + " ".join(f"{k}:{v:.1e}" for k, v in row["hinge_rad"].items())
              + f" | pairs agree {row['contact_pairs_agree']:.1%}"
              f" | pairs/step C {row['pairs_per_step_c']:.1f} warp "
              f"{row['pairs_per_step_warp']:.1f} | contacts/step C "
              f"{row['contacts_per_step_c']:.1f} warp {row['contacts_per_step_warp']:.1f}",
              flush=True)  # fmt: skip
    return {"scenario": scenario, "steps": steps, "warp_s": gap.warp_s, "worlds": worlds}


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--device", default="cuda", help="warp device: cuda, cuda:0 or cpu")
    p.add_argument("--envs", type=int, nargs="+", default=[1024, 4096, 8192])
    p.add_argument("--decisions", type=int, default=50, help="timed decisions per N")
    p.add_argument("--warmup", type=int, default=3, help="decisions before timing")
    p.add_argument("--config", default=str(ROOT / "configs" / "policy" / "default.toml"))
    p.add_argument("--reference", default="", help="reference set (.npz); bundled sample if empty")
    p.add_argument("--nconmax", type=int, default=64, help="contacts per world")
    p.add_argument("--njmax", type=int, default=400, help="constraint rows per world")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", default="", help="write the figures here")
    p.add_argument("--physics", nargs="+", default=[], metavar="SCENE",
                   help="compare with MuJoCo C instead: flat and/or a terrain (stairs, boxes)")
    p.add_argument("--steps", type=int, default=400, help="physics steps of --physics")
    args = p.parse_args(argv)

    import warp as wp

    from envs.tracking_env import SAMPLE_REFERENCE
    from grip.config import load_config
    from grip.core.reference import ReferenceSet
    from policies.config import PolicyRunConfig

    wp.config.quiet = True
    env_cfg = load_config(args.config, PolicyRunConfig()).env
    reference = ReferenceSet.load(args.reference or SAMPLE_REFERENCE)
    if args.physics:
        out = [physics(s, args.device, args.steps, reference) for s in args.physics]
        if args.json:
            Path(args.json).write_text(json.dumps({"device": args.device, "physics": out},
                                                  indent=2) + "\n")  # fmt: skip
        return 0
    rows = []
    for n in args.envs:
        r = measure(env_cfg, reference, n, args.device, args.decisions, args.warmup, args.seed,
                    args.nconmax, args.njmax)  # fmt: skip
        rows.append(r)
        print(f"{n:>6} envs: {r['decisions_per_s']:>10.0f} decisions/s "
              f"{r['env_frames_per_s']:>10.0f} env frames/s "
              f"{r['physics_steps_per_s']:>10.0f} physics steps/s "
              f"(build {r['build_s']:.1f} s, warm-up {r['warmup_s']:.1f} s)",
              flush=True)  # fmt: skip
    result = {
        "device": args.device,
        "warp_device": str(wp.get_device(args.device)),
        "config": _shown(args.config),
        "action_repeat": env_cfg.action_repeat,
        "substeps": env_cfg.substeps,
        "rows": rows,
    }
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
