"""Where PPO + AMP training time goes: a breakdown per part of a short training run.

Runs ``--rollouts`` PPO rollouts and updates of the default recipe (``configs/policy/
default.toml``; ``--set KEY=VALUE`` overrides, e.g. ``--set ppo.vec_env=dummy``) on the bundled
sample reference and times, in the learner's main thread, the exclusive time of each part (a
part's time excludes the parts it calls):

    physics                  Humanoid.step; the batched env's wait on its physics threads
    state read-out           Humanoid.state, hinge angles, velocities, torques
    observations             the environments' observation building
    reward, AMP features     the rest of the env step: PD targets from the reference, rewards,
                             termination, AMP frames, info dicts
    episode resets           GripTrackingEnv.reset (clip sampling, start state)
    vector env, wrappers     DummyVecEnv / BatchedVecEnv / ActionRepeat / VecNormalize /
                             AmpReward bookkeeping
    AMP reward               the discriminator's forward for the style reward
    policy forward           the actor-critic's forward and value predictions in the rollout
    rollout loop (SB3)       the rest of collect_rollouts: buffer writes, tensor conversions
    callbacks, logging       the trainer's per-step and per-rollout callbacks
    PPO update               PPO.train (all epochs and minibatches)
    discriminator update     the AMP discriminator's update after each rollout
    other                    whatever is left (set-up of the run excluded)

    python benchmarks/train_profile.py --rollouts 6 --json profile.json
    python benchmarks/train_profile.py --set ppo.vec_env=dummy --json profile_dummy.json
    python benchmarks/train_profile.py --config configs/policy/teacher.toml --reference REF.npz \
        --set ppo.threads=1 --set ppo.env_threads=1 --clock cpu --json F

Timing wrappers cost about a microsecond per call; the shares, not the absolute times, are the
figures to compare (the README quotes them with this command).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import sys
import tempfile
import threading
import time
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

PARTS = (
    "physics", "state read-out", "observations", "reward, AMP features", "episode resets",
    "vector env, wrappers", "AMP reward", "policy forward", "rollout loop (SB3)",
    "callbacks, logging", "PPO update", "discriminator update",
)  # fmt: skip


class PartTimer:
    """Exclusive wall time per part of the functions it wraps (main thread only: calls from
    other threads, e.g. physics threads, pass through untimed)."""

    def __init__(self, clock=time.perf_counter) -> None:
        self.clock = clock
        self.excl: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)
        self._stack: list[list[float]] = []  # [child time] per open call
        self._main = threading.main_thread()
        self._undo: list[tuple[object, str, object]] = []

    def wrap(self, owner: object, name: str, part: str, consume: bool = False) -> None:
        own = name in vars(owner)
        orig = getattr(owner, name)
        timer = self

        def timed(*args, **kwargs):
            if threading.current_thread() is not timer._main:
                return orig(*args, **kwargs)
            timer._stack.append([0.0])
            t0 = timer.clock()
            try:
                out = orig(*args, **kwargs)
                if consume:  # (Executor.map returns a lazy iterator: the wait is in its use)
                    out = iter(list(out))
                return out
            finally:
                dt = timer.clock() - t0
                child = timer._stack.pop()[0]
                timer.excl[part] += dt - child
                timer.calls[part] += 1
                if timer._stack:
                    timer._stack[-1][0] += dt

        setattr(owner, name, timed)
        self._undo.append((owner, name, orig if own else None))

    def restore(self) -> None:
        for owner, name, orig in reversed(self._undo):
            if orig is None:  # (it was inherited)
                delattr(owner, name)
            else:
                setattr(owner, name, orig)
        self._undo.clear()


def instrument(timer: PartTimer) -> None:
    """Wrap the functions of each part (those of envs.batched only where that module exists)."""
    from concurrent.futures import ThreadPoolExecutor

    from stable_baselines3 import PPO
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
    from stable_baselines3.common.policies import ActorCriticPolicy
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    import envs.tracking_env as te
    import envs.wrappers as wr
    import policies.amp as pa
    import policies.train as pt
    import policies.vec_env as pv
    from grip.sim.humanoid import Humanoid

    w = timer.wrap
    w(Humanoid, "step", "physics")
    w(ThreadPoolExecutor, "map", "physics", consume=True)
    for name in ("state", "hinge_angles", "hinge_velocities", "torques"):
        if name in Humanoid.__dict__:
            w(Humanoid, name, "state read-out")
    w(te.GripTrackingEnv, "_observe", "observations")
    w(te.GripTrackingEnv, "step", "reward, AMP features")
    w(te.GripTrackingEnv, "reset", "episode resets")
    try:
        import envs.batched as eb
    except ImportError:
        eb = None
    if eb is not None:
        w(eb.BatchedTrackingEnv, "_observe", "observations")
        w(eb.BatchedTrackingEnv, "step", "reward, AMP features")
    w(DummyVecEnv, "step_wait", "vector env, wrappers")
    w(DummyVecEnv, "reset", "vector env, wrappers")
    if hasattr(pv, "BatchedVecEnv"):
        w(pv.BatchedVecEnv, "step_wait", "vector env, wrappers")
    w(wr.ActionRepeat, "step", "vector env, wrappers")
    w(VecNormalize, "step_wait", "vector env, wrappers")
    w(pv.AmpReward, "step_wait", "vector env, wrappers")
    w(pa.AmpTrainer, "reward", "AMP reward")
    w(pa.AmpTrainer, "update", "discriminator update")
    w(ActorCriticPolicy, "forward", "policy forward")
    w(ActorCriticPolicy, "predict_values", "policy forward")
    w(OnPolicyAlgorithm, "collect_rollouts", "rollout loop (SB3)")
    w(PPO, "train", "PPO update")
    w(pt.TrainingCallback, "_on_step", "callbacks, logging")
    w(pt.TrainingCallback, "_on_rollout_end", "callbacks, logging")


def profile_training(overrides: Sequence[str], rollouts: int, config: Path | None = None,
                     reference: Path | None = None, cpu: bool = False,
                     warmup: int = 0) -> dict:  # fmt: skip
    """Train ``rollouts`` rollouts of the recipe ``config`` (default ``configs/policy/
    default.toml``) with ``overrides`` on ``reference`` (default: the bundled sample); returns
    the breakdown (seconds and shares per part, env steps/s; ``cpu``: seconds of the main
    thread's CPU time instead of wall time). With ``warmup``, that many rollouts run first and
    are not counted (the caches of clips and subjects fill in them)."""
    from stable_baselines3 import PPO

    from envs.factory import make_tracking_env
    from envs.tracking_env import SAMPLE_REFERENCE
    from grip.config import load_config
    from policies.config import PolicyRunConfig
    from policies.train import PolicyTrainer

    config = config or ROOT / "configs" / "policy" / "default.toml"
    cfg = load_config(config, PolicyRunConfig(), list(overrides))
    steps = (warmup + rollouts) * cfg.ppo.n_steps * cfg.ppo.n_envs
    cfg = dataclasses.replace(
        cfg, stage1=dataclasses.replace(cfg.stage1, timesteps=steps, categories=()),
        stage2=dataclasses.replace(cfg.stage2, timesteps=0), checkpoint_every=10**6,
    )  # fmt: skip
    run = Path(tempfile.mkdtemp(prefix="grip_prof_"))
    timer = PartTimer(time.thread_time if cpu else time.perf_counter)
    start = {"t": 0.0, "done": 0, "trains": 0}
    ppo_train = PPO.train
    try:
        tr = PolicyTrainer(cfg, run, reference or SAMPLE_REFERENCE, make_tracking_env)
        instrument(timer)
        timed_train = PPO.train

        def counted_train(model, *a, **k):  # (the count starts after the warm-up rollouts)
            out = timed_train(model, *a, **k)
            start["trains"] += 1
            if start["trains"] == warmup:
                timer.excl.clear()
                timer.calls.clear()
                start["t"], start["done"] = timer.clock(), model.num_timesteps
            return out

        PPO.train = counted_train
        start["t"] = timer.clock()
        tr.train()
        total = timer.clock() - start["t"]
        done = tr.total_done() - start["done"]
    finally:
        PPO.train = ppo_train
        timer.restore()
        shutil.rmtree(run, ignore_errors=True)
    parts = {p: timer.excl.get(p, 0.0) for p in PARTS}
    parts["other"] = max(0.0, total - sum(parts.values()))
    return {
        "vec_env": cfg.ppo.vec_env, "n_envs": cfg.ppo.n_envs,
        "action_repeat": cfg.env.action_repeat, "rollouts": rollouts, "decisions": int(done),
        "wall_s": total, "env_steps_per_s": done * cfg.env.action_repeat / total,
        "ms_per_decision": 1000 * total / done,
        "seconds": parts, "share": {p: s / total for p, s in parts.items()},
        "ms_per_decision_by_part": {p: 1000 * s / done for p, s in parts.items()},
    }  # fmt: skip


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--rollouts", type=int, default=4, help="PPO rollouts to time (default 4)")
    ap.add_argument(
        "--warmup-rollouts",
        type=int,
        default=0,
        help="untimed rollouts first (the caches of clips and subjects fill)",
    )
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="override one setting of the default recipe (repeatable)")  # fmt: skip
    ap.add_argument(
        "--config", type=Path, default=None, help="recipe (default configs/policy/default.toml)"
    )
    ap.add_argument(
        "--reference",
        type=Path,
        default=None,
        help="training reference set (default: the bundled sample)",
    )
    ap.add_argument(
        "--clock",
        choices=("wall", "cpu"),
        default="wall",
        help="wall time, or the main thread's CPU time (a shared machine; with "
        "ppo.threads=1 and ppo.env_threads=1 all the work is on that thread)",
    )
    ap.add_argument("--json", type=Path, default=None, metavar="PATH", help="write the figures")
    args = ap.parse_args(argv)
    if args.rollouts < 1:
        ap.error("--rollouts must be >= 1")
    res = profile_training(args.overrides, args.rollouts, args.config, args.reference,
                           args.clock == "cpu", warmup=args.warmup_rollouts)  # fmt: skip
    res["clock"], res["warmup_rollouts"] = args.clock, args.warmup_rollouts
    print(
        f"{res['vec_env']}:{res['n_envs']}, action repeat {res['action_repeat']}: "
        f"{res['decisions']} decisions in {res['wall_s']:.1f} s, "
        f"{res['env_steps_per_s']:.0f} env steps/s, {res['ms_per_decision']:.2f} ms/decision"
    )
    print(f"{'part':24s} {'share':>7s} {'ms/decision':>12s}")
    for p, s in res["share"].items():
        print(f"{p:24s} {100 * s:6.1f}% {res['ms_per_decision_by_part'][p]:12.3f}")
    if args.json:
        args.json.write_text(json.dumps(res, indent=1))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
