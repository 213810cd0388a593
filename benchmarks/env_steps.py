"""Tracking-environment steps/s against raw ``mj_step`` of the same model.

Times GripTrackingEnv.step (observations, reward, termination; zero actions in the default
relative mode, reset when an episode ends) and, in the same run, raw mujoco.mj_step on the same
compiled model from the same start state. The ratio env_steps_per_s x substeps /
raw_mj_steps_per_s is the share of time left to physics (target >= 0.5: observation building
and reward must not dominate). The raw rate depends on the state (contacts, solver iterations),
so one env also reports its own physics: the states it stepped, replayed in a tight loop of raw
mj_step, each on the model it was stepped with (``own_states_us_per_mj_step``; the env's humanoid
switches subjects in place: until issue 48 every state was replayed on the last episode's
subject, which put the other subjects' states in the air and made them look 1.7x cheaper
than inside the env), the same physics timed inside the env (``in_env_us_per_mj_step``) and
the share of the env's time spent inside MuJoCo's step calls (``in_env_physics_time_share``).

    python benchmarks/env_steps.py [--steps 3000] [--reference REF.npz] [--json out.json]
    python benchmarks/env_steps.py --batch 16 --threads 1   # the batched env (envs/batched.py)

With ``--batch N`` the figures are those of :class:`envs.batched.BatchedTrackingEnv` stepping N
environments (``--threads`` physics threads, 0: all cores) against the same single-thread raw
``mj_step`` rate: with one thread the physics share compares with the single env's; with more
it can exceed 1 (that is the parallel speed-up); ``physics_share_per_thread`` divides it by the
threads (target >= 0.8 per core).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import mujoco as _mj

_STATE = (_mj.mjtState.mjSTATE_FULLPHYSICS | _mj.mjtState.mjSTATE_CTRL
          | _mj.mjtState.mjSTATE_WARMSTART)  # fmt: skip


def _env_states(env, action, steps: int) -> list:
    """``(model, state)`` before each of the env's physics steps over ``steps`` env steps of
    ``action`` (resets as in the timing): the full physics state with controls and warm start,
    and a copy of the model it was stepped with (the humanoid switches subjects in place, so
    the model of the env's last episode is not every state's)."""
    import copy

    import mujoco
    import numpy as np

    from grip.sim.humanoid import Humanoid

    spec = _STATE
    states, models = [], {}
    orig = Humanoid.step

    def recording_step(sim) -> None:
        m, d = sim.model, sim.data
        key = (id(sim), sim.key)
        if key not in models:
            models[key] = copy.copy(m)
        for _ in range(sim.cfg.substeps):
            s = np.empty(mujoco.mj_stateSize(m, spec))
            mujoco.mj_getState(m, d, s, spec)
            states.append((models[key], s))
            mujoco.mj_step2(m, d)
            mujoco.mj_step1(m, d)

    Humanoid.step = recording_step
    try:
        _play(env, action, steps)
    finally:
        Humanoid.step = orig
    return states


def _play(env, action, steps: int) -> float:
    """Seconds of ``steps`` env steps of ``action`` from a seeded reset, resetting where an
    episode ends."""
    import time

    env.reset(seed=0)
    t0 = time.perf_counter()
    for _ in range(steps):
        _, _, term, trunc, _ = env.step(action)
        if term or trunc:
            env.reset()
    return time.perf_counter() - t0


def _physics_time_in_env(env, action, steps: int) -> tuple[float, float]:
    """Seconds inside the humanoid's physics steps and seconds of the whole pass, over
    ``steps`` env steps of ``action`` (a pass of its own: the timer costs ~1 us a call)."""
    import time

    from grip.sim.humanoid import Humanoid

    inside = [0.0]
    step = Humanoid.step

    def timed_step(sim) -> None:
        t0 = time.perf_counter()
        step(sim)
        inside[0] += time.perf_counter() - t0

    Humanoid.step = timed_step
    try:
        total = _play(env, action, steps)
    finally:
        Humanoid.step = step
    return inside[0], total


def bench_env(steps: int, reference: str | None = None, repeats: int = 5,
              amp_window: int = 10, batch: int = 0, threads: int = 1) -> dict:  # fmt: skip
    """Env steps/s and raw mj_step/s (best of ``repeats``), single process, single thread
    (``batch`` > 0: that many environments in a batched env with ``threads`` physics
    threads)."""
    import time

    import mujoco
    import numpy as np

    from envs.tracking_env import GripTrackingEnv
    from grip.task.config import TrackingEnvConfig

    env = GripTrackingEnv(TrackingEnvConfig(reference=reference or "", amp_window=amp_window))
    action = np.zeros(env.action_space.shape, dtype=np.float32)

    def run_env() -> float:
        return _play(env, action, steps)

    if batch > 0:
        from envs.batched import BatchedTrackingEnv

        cfg = env.cfg
        envs, compiled = [], {}
        for i in range(batch):
            e = GripTrackingEnv(cfg, env.reference, compiled_models=compiled)
            e.reset(seed=i)
            envs.append(e)
        bat = BatchedTrackingEnv(envs, threads)
        actions = np.zeros((batch, *env.action_space.shape), dtype=np.float32)
        rounds = max(1, steps // batch)

        def run_env() -> float:  # (N env steps per call)
            for i in range(batch):
                bat.reset(i, seed=i)
            t0 = time.perf_counter()
            for _ in range(rounds):
                _, _, term, trunc, _ = bat.step(actions)
                for i in np.flatnonzero(term | trunc).tolist():
                    bat.reset(i)
            return (time.perf_counter() - t0) * steps / (rounds * batch)

    env.reset(seed=0)
    model = env.model
    start = mujoco.MjData(model)
    start.qpos[:], start.qvel[:], start.ctrl[:] = env.data.qpos, env.data.qvel, env.data.ctrl
    data = mujoco.MjData(model)
    n_raw = steps * env.cfg.substeps

    def run_raw() -> float:
        mujoco.mj_copyData(data, model, start)
        t0 = time.perf_counter()
        for i in range(n_raw):
            mujoco.mj_step(model, data)
            if i % 400 == 399:  # restart like the env does after its (short) episodes
                mujoco.mj_copyData(data, model, start)
        return time.perf_counter() - t0

    env_s = min(run_env() for _ in range(repeats))
    raw_s = min(run_raw() for _ in range(repeats))
    env_sps = steps / env_s
    raw_sps = n_raw / raw_s
    own = {}
    if batch == 0:
        states = _env_states(env, action, steps)
        datas = {id(m): mujoco.MjData(m) for m, _ in states}

        def run_own() -> float:
            t0 = time.perf_counter()
            for m, s in states:
                d = datas[id(m)]
                mujoco.mj_setState(m, d, s, _STATE)
                mujoco.mj_step(m, d)
            return time.perf_counter() - t0

        own_sps = len(states) / min(run_own() for _ in range(repeats))
        in_env_s, env_pass_s = _physics_time_in_env(env, action, steps)
        own = {
            # the same states in a tight loop of raw mj_step (a warm cache)
            "own_states_us_per_mj_step": 1e6 / own_sps,
            # the env's physics timed inside the env (its other work between the calls)
            "in_env_us_per_mj_step": 1e6 * in_env_s / (steps * env.cfg.substeps),
            # the share of the env's time spent inside MuJoCo's step calls
            "in_env_physics_time_share": in_env_s / env_pass_s,
        }
    return {
        "env_steps_per_s": env_sps,
        "raw_mj_steps_per_s": raw_sps,
        "substeps": env.cfg.substeps,
        "physics_share": env_sps * env.cfg.substeps / raw_sps,
        **own,
        # (the share per physics thread: the batched env's target is >= 0.8 per core)
        "physics_share_per_thread": env_sps * env.cfg.substeps / raw_sps
        / (threads if batch > 0 else 1),
        "steps": steps,
        "batch": batch,
        "threads": threads if batch > 0 else 1,
    }


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark; returns the exit status (2: bad arguments or an unreadable reference
    set, named on stderr)."""
    from grip.core.atomic import atomic_write_text
    from grip.core.reference import ReferenceError

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--steps", type=int, default=3000, help="env steps to time (default 3000)")
    ap.add_argument("--reference", type=Path, default=None,
                    help="reference-set file (default: the bundled sample)")  # fmt: skip
    ap.add_argument("--repeats", type=int, default=5, help="best of N timings (default 5)")
    ap.add_argument("--amp-window", type=int, default=10,
                    help="AMP frames kept for the discriminator (0: none; default 10)")
    ap.add_argument("--batch", type=int, default=0,
                    help="time a batched env of this many environments (0: one GripTrackingEnv)")
    ap.add_argument("--threads", type=int, default=1,
                    help="physics threads of the batched env (0: all cores; default 1)")
    ap.add_argument("--json", type=Path, default=None, metavar="PATH", help="write the figures")
    args = ap.parse_args(argv)
    if args.steps < 1 or args.repeats < 1 or args.batch < 0 or args.threads < 0:
        ap.error("--steps and --repeats must be >= 1, --batch and --threads >= 0")
    try:
        res = bench_env(args.steps, str(args.reference) if args.reference else None, args.repeats,
                        args.amp_window, args.batch, args.threads)  # fmt: skip
    except (OSError, ReferenceError) as e:
        print(f"env_steps: error: {e}", file=sys.stderr)
        return 2
    for k, v in res.items():
        print(f"{k:22s} {v:.4g}" if isinstance(v, float) else f"{k:22s} {v}")
    if args.json:
        atomic_write_text(args.json, json.dumps(res, indent=1))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
