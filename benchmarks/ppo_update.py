"""The PPO update's cost per decision for settings of epochs, minibatch size and optimiser, in
one run: each variant runs stable-baselines3's ``PPO.train`` on the same filled rollout buffer
of a recipe's shapes (its networks, its observation and action sizes, ``n_steps x n_envs``
decisions), in turns, on ``--threads`` torch threads; the figure is CPU time per decision (the
process's, so that other work on a shared machine does not count), the median of the rounds.

    python benchmarks/ppo_update.py --config configs/policy/teacher.toml --json F
    python benchmarks/ppo_update.py --variants 5x1024,5x1024:foreach,2x512:fused --compile

A variant is ``EPOCHSxBATCH[:OPTIMISER]``; the optimiser is SB3's Adam (eps 1e-5) looping over
the tensors (``loop``, SB3's default), over all tensors at once (``foreach``: the same numbers)
or fused (``fused``: the same to float rounding). ``--compile`` adds the recipe's variant with
``torch.compile`` on the policy's ``evaluate_actions`` (compile time reported apart). Fewer
epochs or smaller batches change what an update learns: only the learning curve per decision
(``benchmarks/teacher_ab.py``) says whether a cheaper variant is as good.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]


def _model(cfg, space, n_epochs: int, batch: int, optimizer: str):
    """A PPO of the recipe's networks on a stand-in env of ``space``'s spaces."""
    import gymnasium as gym
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv

    from policies.runner import ACTIVATION_FNS

    obs_space, act_space = space

    class Stand(gym.Env):
        observation_space, action_space = obs_space, act_space

        def reset(self, *, seed=None, options=None):
            return obs_space.sample(), {}

        def step(self, action):
            return obs_space.sample(), 0.0, False, False, {}

    p = cfg.ppo
    opt = {"eps": 1e-5}
    if optimizer != "loop":
        opt[optimizer] = True
    arch = list(p.net_arch)
    kwargs = {"net_arch": {"pi": arch, "vf": arch}, "activation_fn": ACTIVATION_FNS[p.activation],
              "log_std_init": p.log_std_init, "optimizer_kwargs": opt}  # fmt: skip
    from stable_baselines3.common.logger import configure

    venv = DummyVecEnv([Stand] * p.n_envs)
    model = PPO("MultiInputPolicy", venv, n_steps=p.n_steps, batch_size=batch, n_epochs=n_epochs,
               learning_rate=p.learning_rate, policy_kwargs=kwargs, seed=0, device="cpu",
               verbose=0)  # fmt: skip
    model.set_logger(configure(None, []))
    return model


def _fill(model, seed: int = 0) -> None:
    """The rollout buffer filled with a fixed random rollout (observations ~ N(0, 1), as
    normalised ones are) and its returns computed."""
    rng = np.random.default_rng(seed)
    buf, n = model.rollout_buffer, model.n_envs
    buf.reset()
    space = model.observation_space
    for _ in range(model.n_steps):
        obs = {k: rng.normal(size=(n, *s.shape)).astype(np.float32) for k, s in space.items()}
        act = rng.normal(0.0, 0.1, (n, *model.action_space.shape)).astype(np.float32)
        buf.add(obs, act, rng.normal(size=n).astype(np.float32), np.zeros(n, bool),
                torch.as_tensor(rng.normal(size=n).astype(np.float32)),
                torch.as_tensor(rng.normal(-60.0, 1.0, n).astype(np.float32)))  # fmt: skip
    buf.compute_returns_and_advantage(torch.zeros(n), np.zeros(n, bool))


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--config", type=Path, default=ROOT / "configs" / "policy" / "teacher.toml")
    ap.add_argument("--variants", default="5x1024,5x1024:foreach,5x1024:fused,3x1024:foreach,"
                    "2x1024:foreach,2x512:foreach,2x512:fused",
                    help="EPOCHSxBATCH[:loop|foreach|fused], comma separated")  # fmt: skip
    ap.add_argument("--compile", action="store_true", help="also time torch.compile")
    ap.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    ap.add_argument("--rounds", type=int, default=3, help="rounds of every variant, in turns")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)

    from envs.tracking_env import GripTrackingEnv
    from grip.config import load_config
    from policies.config import PolicyRunConfig

    cfg = load_config(args.config, PolicyRunConfig())
    env = GripTrackingEnv(cfg.env_config(cfg.stage1))
    space = (env.observation_space, env.action_space)
    decisions = cfg.ppo.n_steps * cfg.ppo.n_envs
    models = {}
    for v in args.variants.split(","):
        shape, _, optimizer = v.partition(":")
        epochs, batch = (int(k) for k in shape.split("x"))
        models[v] = _model(cfg, space, epochs, batch, optimizer or "loop")
    compile_s = None
    if args.compile:
        name = f"{cfg.ppo.n_epochs}x{cfg.ppo.batch_size}:foreach+compile"
        m = models[name] = _model(cfg, space, cfg.ppo.n_epochs, cfg.ppo.batch_size, "foreach")
        m.policy.evaluate_actions = torch.compile(m.policy.evaluate_actions)
        _fill(m)
        t = time.perf_counter()
        m.train()  # (the first call compiles)
        compile_s = time.perf_counter() - t
    for m in models.values():
        _fill(m)
        m.train()  # (warm-up)
    got: dict[str, list[float]] = {v: [] for v in models}
    for _ in range(args.rounds):
        for v, m in models.items():
            _fill(m)
            c = time.process_time()
            m.train()
            got[v].append(time.process_time() - c)
    out = {"config": str(args.config), "threads": args.threads, "decisions": decisions,
           "rounds": args.rounds, "compile_s": compile_s, "variants": {}}  # fmt: skip
    base = None
    print(f"{'variant':28s} {'ms/decision (CPU)':>18s} {'vs first':>9s}")
    for v, ts in got.items():
        ms = 1e3 * statistics.median(ts) / decisions
        base = base or ms
        out["variants"][v] = {"cpu_ms_per_decision": ms, "ratio_to_first": ms / base}
        print(f"{v:28s} {ms:18.3f} {ms / base:9.3f}")
    if compile_s is not None:
        print(f"(torch.compile took {compile_s:.1f} s in the first update)")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
