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

``--train-rollouts K`` (after the throughput rows; 30 by default on CUDA) trains DynamicsNet on
the device for K rollouts of ``--train-envs`` environments (:class:`policies.warp.train.
WarpPolicyTrainer`, stage 1 only) in a fresh run folder (``--train-out``), exports its policy
file, and writes the learning curve as ``--curve`` (PNG) and its rows in the JSON
(``"training"``). The recipe's settings except two that scale with the environments:
``ppo.n_steps`` = ``--train-steps`` (32) and ``ppo.batch_size`` = envs x steps /
``--train-minibatches`` (4 minibatches, as rsl-rl's PPO; the CPU recipe's 1,024 would give
thousands of minibatch steps per update at 4,096 environments).

``--ppo-compare`` instead times the two PPO updates this project could use on the same
rollouts of random observations of the task's widths, on ``--device``: stable-baselines3's
``PPO.train()`` reading :class:`policies.warp.rollout.DeviceRolloutBuffer`, and rsl-rl's
``PPO.update()`` (``pip install rsl-rl-lib``; skipped when it is absent), with the recipe's
network, epochs and minibatch size, ``--envs`` x ``--ppo-steps`` samples. It also times each
one's per-decision work of the collect loop (policy forward, sampling, storing).

The env settings are those of a policy recipe (``--config``, default
``configs/policy/default.toml``) on the bundled sample clips (``--reference`` for others).
docs/gpu.md says what is measured.

    python benchmarks/gpu_train.py --device cuda --json docs/perf/gpu_train_cuda.json \\
        --train-rollouts 30 --curve docs/perf/gpu_train_cuda.png      # the GPU session's run
"""

from __future__ import annotations

import argparse
import dataclasses
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


def _median_time(fn, repeats: int, device: str, setup=None) -> float:
    """The median wall time of ``repeats`` calls of ``fn`` (after one untimed call), s; each
    call after an untimed call of ``setup`` when given."""
    import torch

    def sync() -> None:  # (torch only: the PPO comparison runs no warp kernel)
        if device.startswith("cuda"):
            torch.cuda.synchronize()

    if setup is not None:
        setup()
    fn()
    times = []
    for _ in range(repeats):
        if setup is not None:
            setup()
        sync()
        t0 = time.perf_counter()
        fn()
        sync()
        times.append(time.perf_counter() - t0)
    return float(sorted(times)[len(times) // 2])


def compare_ppo(run_cfg, obs_dims: dict[str, int], n: int, steps: int, device: str,
                repeats: int, seed: int) -> dict:  # fmt: skip
    """SB3's ``PPO.train()`` on a device buffer against rsl-rl's ``PPO.update()``, on the same
    random rollout of ``n`` x ``steps`` decisions (see the module docstring)."""
    import math

    import numpy as np
    import torch
    from gymnasium import spaces
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import configure

    from grip.task.amp import N_HINGES
    from policies.runner import ACTIVATION_FNS
    from policies.warp.rollout import DeviceRolloutBuffer

    p = run_cfg.ppo
    dev = torch.device(device)
    gen = torch.Generator(device=dev).manual_seed(seed)
    total = n * steps
    obs = {k: torch.randn(steps, n, d, generator=gen, device=dev) for k, d in obs_dims.items()}
    rew = torch.randn(steps, n, generator=gen, device=dev)
    dones = torch.rand(steps, n, generator=gen, device=dev) < 0.01
    arch = list(p.net_arch)
    out = {"envs": n, "steps": steps, "samples": total, "batch_size": p.batch_size,
           "n_epochs": p.n_epochs, "net_arch": arch,
           "obs_width": sum(obs_dims.values())}  # fmt: skip

    # stable-baselines3: PPO.train() on DeviceRolloutBuffer (what WarpPolicyTrainer runs)
    model = PPO("MultiInputPolicy", None, learning_rate=p.learning_rate, n_steps=steps,
                batch_size=p.batch_size, n_epochs=p.n_epochs, gamma=p.gamma,
                gae_lambda=p.gae_lambda, clip_range=p.clip_range, ent_coef=p.ent_coef,
                vf_coef=p.vf_coef, max_grad_norm=p.max_grad_norm, seed=seed, device=dev,
                policy_kwargs={"net_arch": {"pi": arch, "vf": arch},
                               "activation_fn": ACTIVATION_FNS[p.activation],
                               "log_std_init": p.log_std_init},
                rollout_buffer_class=DeviceRolloutBuffer, _init_setup_model=False)  # fmt: skip
    model.observation_space = spaces.Dict({k: spaces.Box(-np.inf, np.inf, (d,), np.float32)
                                           for k, d in obs_dims.items()})  # fmt: skip
    model.action_space = spaces.Box(-1.0, 1.0, (N_HINGES,), np.float32)
    model.n_envs = n
    model._setup_model()
    model.set_logger(configure(None, []))
    buf, pol = model.rollout_buffer, model.policy
    buf.seed(seed)

    @torch.no_grad()
    def sb3_collect() -> None:
        buf.reset()
        for t in range(steps):
            o = {k: v[t] for k, v in obs.items()}
            a, v, lp = pol(o)
            buf.add(o, a, rew[t], dones[t], v, lp)
        buf.compute_returns_and_advantage(pol.predict_values(o), dones[-1])

    out["sb3"] = {"collect_s": _median_time(sb3_collect, repeats, device),
                  "update_s": _median_time(model.train, repeats, device, sb3_collect),
                  }  # fmt: skip
    try:
        from rsl_rl.algorithms import PPO as RslPPO
        from rsl_rl.models import MLPModel
        from rsl_rl.modules import GaussianDistribution
        from rsl_rl.storage import RolloutStorage
        from tensordict import TensorDict
    except ImportError as e:
        out["rsl_rl"] = f"not installed ({e})"
        return out
    from importlib.metadata import version

    first = TensorDict({k: v[0] for k, v in obs.items()}, batch_size=[n], device=dev)
    groups = {"actor": list(obs_dims), "critic": list(obs_dims)}
    act = {"silu": "swish", "relu": "relu", "tanh": "tanh", "elu": "elu"}[p.activation]
    actor = MLPModel(first, groups, "actor", N_HINGES, tuple(arch), act,
                     distribution_cfg={"class_name": GaussianDistribution,
                                       "init_std": math.exp(p.log_std_init),
                                       "std_type": "log"})  # fmt: skip
    critic = MLPModel(first, groups, "critic", 1, tuple(arch), act)
    storage = RolloutStorage("rl", n, steps, first, (N_HINGES,), device=str(dev))
    alg = RslPPO(actor, critic, storage, num_learning_epochs=p.n_epochs,
                 num_mini_batches=max(1, total // p.batch_size), clip_param=p.clip_range,
                 gamma=p.gamma, lam=p.gae_lambda, value_loss_coef=p.vf_coef,
                 entropy_coef=p.ent_coef, learning_rate=p.learning_rate,
                 max_grad_norm=p.max_grad_norm, use_clipped_value_loss=False, schedule="fixed",
                 device=str(dev))  # fmt: skip

    @torch.no_grad()
    def rsl_collect() -> None:
        storage.clear()
        for t in range(steps):
            o = TensorDict({k: v[t] for k, v in obs.items()}, batch_size=[n], device=dev)
            alg.act(o)
            alg.process_env_step(o, rew[t], dones[t], {})
        alg.compute_returns(o)

    out["rsl_rl"] = {"version": version("rsl-rl-lib"),
                     "collect_s": _median_time(rsl_collect, repeats, device),
                     "update_s": _median_time(alg.update, repeats, device, rsl_collect),
                     }  # fmt: skip
    return out


def train_curve(run_cfg, reference: str, n: int, rollouts: int, device: str, out_dir: str,
                curve_png: str) -> dict:  # fmt: skip
    """A short device training (stage 1 only) in a fresh run folder; returns its history,
    timings and the exported policy file's size (see the module docstring)."""
    import shutil

    from envs.warp.factory import make_warp_tracking_env
    from grip.core.rundir import RunDir
    from policies.report import plot_curves
    from policies.runner import export_policy
    from policies.warp.train import BACKEND, WarpPolicyTrainer

    steps = rollouts * n * run_cfg.ppo.n_steps
    cfg = dataclasses.replace(
        run_cfg, ppo=dataclasses.replace(run_cfg.ppo, n_envs=n, device=device),
        stage1=dataclasses.replace(run_cfg.stage1, timesteps=steps),
        stage2=dataclasses.replace(run_cfg.stage2, timesteps=0), checkpoint_every=10**9,
    )  # fmt: skip
    out = Path(out_dir)
    if out.exists():
        shutil.rmtree(out)
    trainer = WarpPolicyTrainer(cfg, out, reference, make_warp_tracking_env)
    RunDir(out).write_config(cfg, backend=BACKEND)
    t0 = time.perf_counter()
    trainer.train()
    _sync(device)
    wall = time.perf_counter() - t0
    plot_curves(trainer.history, curve_png)
    size = export_policy(out, out / "policy.pt", info={"timesteps": trainer.total_done()})
    done = trainer.total_done()
    return {"envs": n, "rollouts": len(trainer.history), "decisions": done, "wall_s": wall,
            "decisions_per_s": done / wall, "policy_file": _shown(str(out / "policy.pt")),
            "policy_bytes": size, "curve_png": _shown(curve_png),
            "history": trainer.history}  # fmt: skip


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
                   help="compare with MuJoCo C instead: flat and/or a terrain (stairs, boxes)",
                   )  # fmt: skip
    p.add_argument("--steps", type=int, default=400, help="physics steps of --physics")
    p.add_argument("--train-rollouts", type=int, default=None,
                   help="then train this many rollouts on the device (0: no training; default "
                   "30 on cuda, 0 on cpu)")  # fmt: skip
    p.add_argument("--train-envs", type=int, default=4096, help="environments of the training")
    p.add_argument("--train-steps", type=int, default=32, help="ppo.n_steps of the training")
    p.add_argument("--train-minibatches", type=int, default=4,
                   help="minibatches per epoch of the training (ppo.batch_size = envs x steps / "
                   "this)")  # fmt: skip
    p.add_argument("--train-out", default="/tmp/grip_gpu_train_run", help="its run folder")
    p.add_argument("--curve", default="gpu_train_curve.png", help="its learning curve (PNG)")
    p.add_argument("--ppo-compare", action="store_true",
                   help="time SB3's and rsl-rl's PPO updates on the same rollouts instead",
                   )  # fmt: skip
    p.add_argument("--ppo-steps", type=int, default=32, help="decisions per env of --ppo-compare")
    p.add_argument("--repeats", type=int, default=3, help="timed repeats of --ppo-compare")
    p.add_argument("--threads", type=int, default=0,
                   help="torch threads (0: torch's default; 1 on a loaded CPU, where threads "
                   "that wait for a core make the timings noise)")  # fmt: skip
    args = p.parse_args(argv)
    if args.train_rollouts is None:
        args.train_rollouts = 30 if args.device.startswith("cuda") else 0
    if args.threads > 0:
        import torch

        torch.set_num_threads(args.threads)

    import warp as wp

    from envs.tracking_env import SAMPLE_REFERENCE
    from grip.config import load_config
    from grip.core.reference import ReferenceSet
    from policies.config import PolicyRunConfig

    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING  # (no line per kernel module loaded)
    reference = ReferenceSet.load(args.reference or SAMPLE_REFERENCE)
    run_cfg = load_config(args.config, PolicyRunConfig())
    if args.ppo_compare:
        from envs.tracking_env import GripTrackingEnv

        space = GripTrackingEnv(run_cfg.env, reference).observation_space
        dims = {k: int(s.shape[0]) for k, s in space.spaces.items()}
        out = [compare_ppo(run_cfg, dims, n, args.ppo_steps, args.device, args.repeats,
                           args.seed) for n in args.envs]  # fmt: skip
        for r in out:
            rsl = r["rsl_rl"]
            rsl_s = (f"rsl-rl collect {rsl['collect_s']:.3f} s update {rsl['update_s']:.3f} s"
                     if isinstance(rsl, dict) else f"rsl-rl {rsl}")  # fmt: skip
            print(f"{r['samples']:>8} samples: SB3 collect {r['sb3']['collect_s']:.3f} s update "
                  f"{r['sb3']['update_s']:.3f} s | {rsl_s}", flush=True)  # fmt: skip
        if args.json:
            Path(args.json).write_text(json.dumps({"device": args.device, "config":
                                                   _shown(args.config), "threads": args.threads,
                                                   "ppo": out}, indent=2) + "\n")  # fmt: skip
        return 0
    if args.physics:
        out = [physics(s, args.device, args.steps, reference) for s in args.physics]
        if args.json:
            Path(args.json).write_text(json.dumps({"device": args.device, "physics": out},
                                                  indent=2) + "\n")  # fmt: skip
        return 0
    rows = []
    for n in args.envs:
        r = measure(run_cfg.env, reference, n, args.device, args.decisions, args.warmup, args.seed,
                    args.nconmax, args.njmax)  # fmt: skip
        rows.append(r)
        print(f"{n:>6} envs: {r['decisions_per_s']:>10.0f} decisions/s "
              f"{r['env_frames_per_s']:>10.0f} env frames/s "
              f"{r['physics_steps_per_s']:>10.0f} physics steps/s "
              f"(build {r['build_s']:.1f} s, warm-up {r['warmup_s']:.1f} s)",
              flush=True)  # fmt: skip
    if args.train_rollouts > 0:
        ref_path = args.reference or SAMPLE_REFERENCE
        n, k = args.train_envs, args.train_steps
        batch = max(1, n * k // args.train_minibatches)
        ppo = dataclasses.replace(run_cfg.ppo, n_steps=k, batch_size=batch)
        cfg = dataclasses.replace(run_cfg, ppo=ppo)
        tr = train_curve(cfg, str(ref_path), n, args.train_rollouts, args.device,
                         args.train_out, args.curve)  # fmt: skip
        last = tr["history"][-1]
        print(f"training: {tr['envs']} envs, {tr['rollouts']} rollouts, {tr['decisions']} "
              f"decisions in {tr['wall_s']:.0f} s ({tr['decisions_per_s']:.0f} decisions/s); "
              f"last reward/imit_pos {last['reward/imit_pos']:.3f}; wrote {args.curve}",
              flush=True)  # fmt: skip
    result = {
        "device": args.device,
        "warp_device": str(wp.get_device(args.device)),
        "config": _shown(args.config),
        "action_repeat": run_cfg.env.action_repeat,
        "substeps": run_cfg.env.substeps,
        "rows": rows,
    }
    if args.train_rollouts > 0:
        result["training"] = tr
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
