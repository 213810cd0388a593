"""DynamicsNet training throughput against the physics limit measured in the same run.

In one run: short PPO + AMP trainings (rollout collection, discriminator updates and PPO updates
all included) of a recipe on a reference set, for each vector-env layout; and, as the yardstick,
the raw ``mj_step`` rate on the training's own states. While the training runs, every
``--sample-every``-th control step of each humanoid saves its full physics state (positions,
velocities, controls, warm start) before and after the step; afterwards those states are
replayed in a tight loop of raw ``mj_step`` on the same subject's model (each state on the model
it was simulated with: the humanoids switch subjects in place) and the replay is checked to end
in the recorded state, bit for bit. The figures:

- ``frames_per_s``: simulated frames per second of training (decisions x action repeat);
- ``raw_mj_steps_per_s``: the replay's rate, the physics limit of these states;
- ``physics_limit_share`` = frames/s x substeps / raw steps/s: 1 would be training at the speed
  of its bare physics;
- ``in_training_us_per_mj_step`` against ``raw_us_per_mj_step``: the same physics inside the
  training and in the tight loop;
- ``decisions_per_core_hour``: decisions per second x 3600 / the cores used (the larger of
  ``ppo.threads`` and ``ppo.env_threads``, all the process may use where either is 0).

    python benchmarks/policy_throughput.py --config configs/policy/teacher.toml \\
        --reference REF.npz --set ppo.threads=1 --set ppo.env_threads=1 --json F
    python benchmarks/policy_throughput.py --layouts dummy:16,batched:16 --rollouts 4
    python benchmarks/policy_throughput.py --bare-env-steps 3000   # + one bare env's rate

The reference set comes from ``grip data reference`` (default: the bundled two-clip sample).
Where the machine is shared, compare the ratios of one run, not absolute rates.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import os
import shutil
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path

import mujoco
import numpy as np

ROOT = Path(__file__).resolve().parents[1]

STATE_SPEC = (mujoco.mjtState.mjSTATE_FULLPHYSICS | mujoco.mjtState.mjSTATE_CTRL
              | mujoco.mjtState.mjSTATE_WARMSTART)  # fmt: skip
"""What a saved state holds: everything a step reads (MuJoCo's full physics, the PD targets and
the solver's warm start), so that a replayed step repeats the training's step exactly."""


def bare_env_rate(steps: int, reference: str | None = None) -> float:
    """Steps/s of one GripTrackingEnv with zero actions (resetting where an episode ends)."""
    from envs.tracking_env import GripTrackingEnv
    from grip.task.config import TrackingEnvConfig

    env = GripTrackingEnv(TrackingEnvConfig(reference=reference or ""))
    env.reset(seed=0)
    a = np.zeros(env.action_space.shape)
    t = time.perf_counter()
    for _ in range(steps):
        _, _, te, tr, _ = env.step(a)
        if te or tr:
            env.reset()
    return steps / (time.perf_counter() - t)


class PhysicsRecorder:
    """Times every ``Humanoid.step`` of a training, saves the states around every ``every``-th
    control step of each humanoid, and replays them (:meth:`replay`) after each rollout, so
    that a change in the machine's load hits the training and its yardstick alike."""

    def __init__(self, every: int) -> None:
        self.every = max(1, int(every))
        self.seconds = 0.0  # inside Humanoid.step during training
        self.substeps = 0
        self.count: dict[int, int] = defaultdict(int)
        # (humanoid id, subject key) -> [(state before, state after)], since the last replay
        self.pending: dict[tuple, list[tuple[np.ndarray, np.ndarray]]] = defaultdict(list)
        self.humanoids: dict[int, object] = {}
        self._sims: dict[tuple, tuple] = {}  # (humanoid id, key) -> (model copy, data)
        self.replay_wall = self.replay_cpu = 0.0  # seconds of the replays' mj_step calls
        self.replay_overhead_wall = self.replay_overhead_cpu = 0.0  # the rest of the replays
        self.replayed_steps = self.replayed_states = self.identical = 0
        self._orig = None

    def install(self) -> None:
        from grip.sim.humanoid import Humanoid

        self._orig = orig = Humanoid.step
        rec = self

        def step(h) -> None:
            n = rec.count[id(h)]
            rec.count[id(h)] = n + 1
            save = n % rec.every == 0
            if save:
                m, d = h.model, h.data
                before = np.empty(mujoco.mj_stateSize(m, STATE_SPEC))
                mujoco.mj_getState(m, d, before, STATE_SPEC)
            t0 = time.perf_counter()
            orig(h)
            rec.seconds += time.perf_counter() - t0
            rec.substeps += h.cfg.substeps
            if save:
                after = np.empty_like(before)
                mujoco.mj_getState(m, d, after, STATE_SPEC)
                rec.humanoids[id(h)] = h
                rec.pending[(id(h), h.key)].append((before, after))

        Humanoid.step = step

    def remove(self) -> None:
        from grip.sim.humanoid import Humanoid

        if self._orig is not None:
            Humanoid.step = self._orig
            self._orig = None

    def _sim(self, hid: int, key) -> tuple:
        """A copy of humanoid ``hid``'s model as subject ``key`` (it switches subjects in
        place; it is switched back) and a data of its own."""
        got = self._sims.get((hid, key))
        if got is None:
            h = self.humanoids[hid]
            now = h.key
            h.switch(key)
            m = copy.copy(h.model)
            h.switch(now)
            got = self._sims[(hid, key)] = (m, mujoco.MjData(m), h.cfg.substeps)
        return got

    def replay(self) -> None:
        """Replay the states saved since the last call in a tight loop of raw ``mj_step``,
        each on its own subject's model; count those that end in the recorded state bit for
        bit."""
        w0, c0 = time.perf_counter(), time.process_time()
        groups = [(self._sim(*k), pairs) for k, pairs in self.pending.items()]
        self.pending = defaultdict(list)
        w1, c1 = time.perf_counter(), time.process_time()
        for (m, d, sub), pairs in groups:
            for before, _ in pairs:
                mujoco.mj_setState(m, d, before, STATE_SPEC)
                for _ in range(sub):
                    mujoco.mj_step(m, d)
        w2, c2 = time.perf_counter(), time.process_time()
        for (m, d, _), pairs in groups:  # (the cost of setting the states, taken off)
            for before, _ in pairs:
                mujoco.mj_setState(m, d, before, STATE_SPEC)
        w3, c3 = time.perf_counter(), time.process_time()
        for (m, d, sub), pairs in groups:  # (the check, untimed)
            got = np.empty(mujoco.mj_stateSize(m, STATE_SPEC))
            for before, after in pairs:
                mujoco.mj_setState(m, d, before, STATE_SPEC)
                for _ in range(sub):
                    mujoco.mj_step(m, d)
                mujoco.mj_getState(m, d, got, STATE_SPEC)
                self.identical += int(np.array_equal(got, after))
                self.replayed_states += 1
                self.replayed_steps += sub
        self.replay_wall += (w2 - w1) - (w3 - w2)
        self.replay_cpu += (c2 - c1) - (c3 - c2)
        self.replay_overhead_wall += time.perf_counter() - w0 - ((w2 - w1) - (w3 - w2))
        self.replay_overhead_cpu += time.process_time() - c0 - ((c2 - c1) - (c3 - c2))

    def reset_clock(self) -> None:
        """Count from now on (the states saved so far stay to be replayed, uncounted)."""
        self.seconds = 0.0
        self.substeps = 0
        self.replay_wall = self.replay_cpu = 0.0
        self.replay_overhead_wall = self.replay_overhead_cpu = 0.0
        self.replayed_steps = self.replayed_states = self.identical = 0
        self.pending = defaultdict(list)

    def figures(self) -> dict:
        n = max(self.replayed_steps, 1)
        return {
            "raw_mj_steps_per_s": n / self.replay_wall,
            "raw_us_per_mj_step": 1e6 * self.replay_wall / n,
            "raw_cpu_us_per_mj_step": 1e6 * self.replay_cpu / n,
            "replayed_states": self.replayed_states,
            "replay_identical_share": self.identical / max(self.replayed_states, 1),
            "in_training_us_per_mj_step": 1e6 * self.seconds / max(self.substeps, 1),
        }


def training_rate(cfg, rollouts: int, reference: Path, sample_every: int,
                  warmup: int = 1) -> dict:  # fmt: skip
    """Train ``warmup + rollouts`` rollouts of ``cfg`` (stage 1 only, every clip of
    ``reference``) and time the last ``rollouts`` (the first ones build the caches of clips and
    subjects that a long run builds once); returns frames/s of the learning loop (wall and CPU
    time, the replays taken off) and the physics figures of its states."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm

    from envs.factory import make_tracking_env
    from policies.train import PolicyTrainer

    steps = (warmup + rollouts) * cfg.ppo.n_steps * cfg.ppo.n_envs
    cfg = dataclasses.replace(
        cfg, stage1=dataclasses.replace(cfg.stage1, timesteps=steps, categories=()),
        stage2=dataclasses.replace(cfg.stage2, timesteps=0), checkpoint_every=10**6,
    )  # fmt: skip
    run = Path(tempfile.mkdtemp(prefix="grip_tp_"))
    rec = PhysicsRecorder(sample_every)
    learn, train = OnPolicyAlgorithm.learn, PPO.train
    clock = {"trains": 0, "start": None, "end": None}

    def start(model) -> None:
        clock["start"] = (time.perf_counter(), time.process_time(), model.num_timesteps)
        rec.reset_clock()

    def timed_learn(self, *a, **k):  # (the run's set-up, model building, is not timed)
        if warmup == 0:
            start(self)
        try:
            return learn(self, *a, **k)
        finally:
            clock["end"] = (time.perf_counter(), time.process_time(), self.num_timesteps)

    def replay_then_train(self, *a, **k):  # (after each rollout: replay its states)
        rec.replay()
        try:
            return train(self, *a, **k)
        finally:
            clock["trains"] += 1
            if clock["trains"] == warmup:
                start(self)

    OnPolicyAlgorithm.learn, PPO.train = timed_learn, replay_then_train
    rec.install()
    try:
        tr = PolicyTrainer(cfg, run, reference, make_tracking_env)
        tr.train()
    finally:
        rec.remove()
        OnPolicyAlgorithm.learn, PPO.train = learn, train
        shutil.rmtree(run, ignore_errors=True)
    (w0, c0, n0), (w1, c1, n1) = clock["start"], clock["end"]
    done = n1 - n0
    frames = done * cfg.env.action_repeat
    out = rec.figures()
    wall = w1 - w0 - rec.replay_wall - rec.replay_overhead_wall
    cpu = c1 - c0 - rec.replay_cpu - rec.replay_overhead_cpu
    out.update({"decisions": int(done), "warmup_rollouts": warmup, "learn_wall_s": wall,
                "learn_cpu_s": cpu, "frames_per_s": frames / wall, "decisions_per_s": done / wall,
                "frames_per_cpu_s": frames / cpu, "substeps": cfg.env.substeps,
                "physics_time_share": rec.seconds / wall})  # fmt: skip
    sub = cfg.env.substeps
    out["physics_limit_share"] = out["frames_per_s"] * sub / out["raw_mj_steps_per_s"]
    out["physics_limit_share_cpu"] = (out["frames_per_cpu_s"] * sub * out["raw_cpu_us_per_mj_step"]
                                      * 1e-6)  # fmt: skip
    return out


def cores_used(ppo) -> int:
    """The cores a training of ``ppo`` settings may keep busy."""
    avail = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    t, e = ppo.threads or avail, ppo.env_threads or avail
    return max(1, min(avail, max(t, e if ppo.vec_env == "batched" else 1)))


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--config", type=Path, default=ROOT / "configs" / "policy" / "default.toml",
                    help="recipe (default configs/policy/default.toml)")  # fmt: skip
    ap.add_argument("--reference", type=Path, default=None,
                    help="training reference set (default: the bundled sample)")  # fmt: skip
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="override one setting of the recipe (repeatable)")  # fmt: skip
    ap.add_argument(
        "--layouts",
        default="",
        help="vec_env:n_envs pairs, comma separated (default: the recipe's)",
    )
    ap.add_argument("--rollouts", type=int, default=4, help="PPO rollouts timed per layout")
    ap.add_argument(
        "--warmup-rollouts",
        type=int,
        default=1,
        help="untimed rollouts first (default 1: clip and subject caches fill)",
    )
    ap.add_argument(
        "--sample-every",
        type=int,
        default=4,
        help="save the states around every N-th control step (default 4)",
    )
    ap.add_argument(
        "--bare-env-steps",
        type=int,
        default=0,
        help="also time one bare env for this many steps (0: not)",
    )
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)

    from envs.tracking_env import SAMPLE_REFERENCE
    from grip.config import load_config
    from policies.config import PolicyRunConfig

    base = load_config(args.config, PolicyRunConfig(), args.overrides)
    reference = args.reference or SAMPLE_REFERENCE
    out: dict = {
        "config": str(args.config),
        "reference": str(reference),
        "overrides": args.overrides,
        "rollouts": args.rollouts,
        "layouts": {},
    }
    if args.bare_env_steps > 0:
        ref = bare_env_rate(args.bare_env_steps, str(args.reference or ""))
        out["bare_env_steps_per_s"] = ref
        print(f"bare env (1 env, zero actions): {ref:8.0f} steps/s")
    layouts = args.layouts or f"{base.ppo.vec_env}:{base.ppo.n_envs}"
    for item in layouts.split(","):
        kind, n = item.split(":")
        n = int(n)
        n_steps = max(base.ppo.n_steps, -(-base.ppo.batch_size // n))  # same batch per update
        cfg = dataclasses.replace(base, ppo=dataclasses.replace(base.ppo, vec_env=kind, n_envs=n,
                                                                n_steps=n_steps))  # fmt: skip
        res = training_rate(cfg, args.rollouts, reference, args.sample_every, args.warmup_rollouts)
        cores = cores_used(cfg.ppo)
        res["cores"] = cores
        res["decisions_per_core_hour"] = res["decisions_per_s"] * 3600 / cores
        if "bare_env_steps_per_s" in out:
            res["ratio_to_bare_env"] = res["frames_per_s"] / out["bare_env_steps_per_s"]
        out["layouts"][item] = res
        print(
            f"{item}: {res['frames_per_s']:.0f} frames/s ({res['decisions_per_s']:.0f} "
            f"decisions/s, {res['decisions_per_core_hour'] / 1e6:.2f} M per core-hour on "
            f"{cores} core(s))"
        )
        print(
            f"  raw mj_step on the training's states: {res['raw_mj_steps_per_s']:.0f}/s "
            f"({res['raw_us_per_mj_step']:.1f} us; {res['replayed_states']} states, "
            f"{100 * res['replay_identical_share']:.1f} % replayed bit for bit)"
        )
        print(
            f"  in training: {res['in_training_us_per_mj_step']:.1f} us per mj_step, "
            f"{100 * res['physics_time_share']:.1f} % of the time"
        )
        print(
            f"  physics limit share: {res['physics_limit_share']:.3f} (wall time), "
            f"{res['physics_limit_share_cpu']:.3f} (CPU time)"
        )
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
