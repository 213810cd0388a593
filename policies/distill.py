"""Distil a teacher policy (usually an ensemble) into one network with DAgger.

The shipped controller is an ensemble whose mean action keeps more segments on their feet than
any of its members alone. :class:`Distiller` trains a single student
network to act like the teacher on the states the *student* visits (DAgger, Ross et al. 2011):

1. Roll out the training environments (GRIP's stage 2: random starts, falls end episodes) with
   the student acting, except that each action is the teacher's with probability ``beta_i =
   beta0 x beta_decay^i`` in iteration ``i`` (iteration 0 with ``beta0 = 1`` is behaviour
   cloning on the teacher's own states).
2. Label every visited observation with the teacher's action and add it to the data set (the
   newest ``max_samples`` are kept).
3. Fit the student to all labels by mean-squared error for ``epochs`` passes.

A *privileged* teacher (a policy trained with ``follow = "truth"``, ``configs/policy/
teacher.toml``) follows the ground truth, the student the KinematicsNet estimate. The rollout
environments then add the teacher's inputs to every observation
(:attr:`grip.task.config.TrackingEnvConfig.teacher_obs`): the teacher acts on the kinematic
observation against the truth, and its action becomes the student's label shifted by the
difference of the two PD targets, so that the student learns to reach the truth's pose from
what GRIP sees. The student's file follows the estimate.

The student has one member's network shape and observation normaliser and starts from that
member's weights (``init_member``), so its file is an ordinary policy file: ``grip policy eval``
plays it and ``grip policy train --init`` fine-tunes it with PPO. Runs checkpoint after every
iteration (``RUN/checkpoint/``, ``RUN/data/iter_NNN.npz``) and resume.
"""

from __future__ import annotations

import io
import json
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from grip.config import REMOVED_ANY_VALUE, RemovedSetting, drop_removed
from grip.core.atomic import atomic_write
from grip.core.checks import check
from grip.core.rundir import RunDir
from grip.task.config import TEACHER_ROOTS
from policies.config import REMOVED_IN, speed_rules
from policies.runner import mlp

VEC_ENVS: tuple[str, ...] = ("batched", "dummy")
"""How :class:`Distiller` steps its rollout environments (:attr:`DistillConfig.vec_env`)."""

RESUMABLE: tuple[str, ...] = ("iterations",)
"""Settings a resumed distillation may change: its length."""

REMOVED_SETTINGS: tuple[RemovedSetting, ...] = (
    RemovedSetting("push_force_n", 0.0, "random pushes (experiments/random_pushes.py)",
                   REMOVED_IN),
    RemovedSetting("push_every_s", REMOVED_ANY_VALUE, "random pushes", REMOVED_IN),
    RemovedSetting("push_duration_s", REMOVED_ANY_VALUE, "random pushes", REMOVED_IN),
)  # fmt: skip
"""Settings deleted from :class:`DistillConfig` that older run folders may record."""


def _upgrade_settings(old: dict, where: str) -> dict:
    """An older run folder's recorded settings without those removed since."""
    return drop_removed(old, REMOVED_SETTINGS, where)


@dataclass(frozen=True)
class DistillConfig:
    """Settings of ``grip policy distill`` (``configs/policy/distill.toml``).

    Attributes:
        iterations: DAgger iterations (each: a rollout, then a fit).
        decisions_per_iteration: Policy decisions collected per iteration, all environments
            together (one decision = ``env.action_repeat`` frames of the teacher's settings).
        n_envs: Environments stepped together.
        beta0: Share of the teacher's actions in iteration 0 (1: behaviour cloning first).
        beta_decay: Factor on that share after each iteration.
        epochs: Passes over the whole data set per iteration.
        batch_size: Samples per gradient step.
        learning_rate: Adam's step size.
        max_samples: Samples kept (the oldest are dropped).
        init_member: The teacher's member whose network shape, normaliser, discriminator and
            (unless ``fresh_student``) weights the student takes.
        fresh_student: Start from random weights instead of the member's.
        student_hidden: Hidden layer widths of a student of another size than the member's
            (random weights; the member's normaliser, discriminator and value network stay):
            a one-network student that loses categories may need more capacity (issue 47).
            Empty (the default): the member's network.
        categories: Motion categories of the training clips (globs).
        max_episode_frames: Truncate episodes after this many decisions (0: the clip's end).
        fall_height_m: An episode ends when the pelvis is below this height, m.
        fall_below_reference_m: ... and also this far below the ground truth's pelvis, m (0:
            always; floor clips are followed with it, :class:`grip.task.config.
            TrackingEnvConfig`).
        action_noise: Standard deviation of Gaussian noise added to every action played
            (clipped to [-1, 1]); the label stays the teacher's action without noise. Noise in
            the rollouts shows the student the teacher's corrections from states a little off
            its own path (DART, Laskey et al. 2017). 0: none.
        reverse_categories: As ``grip policy train``'s: training clips of these categories,
            played backwards, join the reference set (``RUN/reference_train.npz``).
        mirror_references: As ``grip policy train``'s: the mirror image of every clip joins.
        speed_factors: As ``grip policy train``'s: training clips of ``speed_categories``
            played each of these times faster join the reference set (names
            ``<clip>@x<factor>``, categories unchanged). Empty: none.
        speed_categories: Category globs of the clips ``speed_factors`` plays faster.
        truth_references: The student also follows the ground truth of every training clip
            (the reference set holds each clip twice, ``follow = "both"`` of ``grip policy
            train``): rollouts on the truth, where the teacher's label needs no shift, mixed
            with rollouts on the estimate, so that the student learns to track motion rather
            than one estimator's errors.
        teacher_root: The pelvis a privileged teacher's observation follows
            (:attr:`grip.task.config.TrackingEnvConfig.teacher_root`): ``"truth"``, as it
            trained, or ``"estimate"``, the pelvis the student follows and is judged by (its
            labels then steer toward what the student sees; docs/pace.md).
        threads: Torch threads (0: all cores).
        vec_env: ``"batched"``: the rollout environments stepped by one call (the env maker's
            ``batched`` form, :class:`envs.batched.BatchedTrackingEnv`; the same transitions
            as ``"dummy"`` to float rounding, the physics in a thread pool); ``"dummy"``: one
            after another (SB3's ``DummyVecEnv``).
        seed: Seed of the environments, the mixing and the minibatches.
    """

    iterations: int = 8
    decisions_per_iteration: int = 40960
    n_envs: int = 16
    beta0: float = 1.0
    beta_decay: float = 0.5
    epochs: int = 2
    batch_size: int = 2048
    learning_rate: float = 3e-4
    max_samples: int = 400_000
    init_member: int = 0
    fresh_student: bool = False
    student_hidden: tuple[int, ...] = ()
    categories: tuple[str, ...] = ("walk*", "run*", "dash*")
    max_episode_frames: int = 1000
    fall_height_m: float = 0.3
    fall_below_reference_m: float = 0.0
    reverse_categories: tuple[str, ...] = ("walk",)
    mirror_references: bool = True
    speed_factors: tuple[float, ...] = ()
    speed_categories: tuple[str, ...] = ("walk*",)
    truth_references: bool = False
    action_noise: float = 0.0
    teacher_root: str = "truth"
    threads: int = 0
    vec_env: str = "batched"
    seed: int = 0

    def __post_init__(self) -> None:
        check(
            self,
            (self.iterations >= 1, "iterations must be >= 1"),
            (self.n_envs >= 1, "n_envs must be >= 1"),
            (self.decisions_per_iteration >= self.n_envs,
             "decisions_per_iteration must be at least n_envs"),
            (0.0 <= self.beta0 <= 1.0 and 0.0 <= self.beta_decay <= 1.0,
             "beta0 and beta_decay must be in [0, 1]"),
            (self.epochs >= 1 and self.batch_size >= 1, "epochs and batch_size must be >= 1"),
            (self.learning_rate > 0, "learning_rate must be > 0"),
            (self.max_samples >= self.decisions_per_iteration,
             "max_samples must hold at least one iteration's decisions"),
            (self.init_member >= 0, "init_member must be >= 0"),
            (all(isinstance(w, int) and w >= 1 for w in self.student_hidden),
             "student_hidden must be positive layer widths (empty: the member's network)"),
            (self.action_noise >= 0, "action_noise must be >= 0"),
            (self.teacher_root in TEACHER_ROOTS, f"teacher_root must be one of {TEACHER_ROOTS}"),
            (self.fall_height_m >= 0 and self.max_episode_frames >= 0,
             "fall_height_m and max_episode_frames must be >= 0"),
            (self.vec_env in VEC_ENVS, f"vec_env must be one of {list(VEC_ENVS)}"),
            *speed_rules(self.speed_factors, self.speed_categories),
        )  # fmt: skip

    def beta(self, iteration: int) -> float:
        """The teacher's share of the actions played in ``iteration``."""
        return self.beta0 * self.beta_decay**iteration


class SampleBuffer:
    """The newest ``capacity`` samples ``(x, y)`` of a distillation, in one preallocated pair of
    arrays written in place (a ring): no second copy of the kept samples is ever made, so a
    student's memory stays at one copy of ``max_samples`` however many iterations it runs.
    The order of the rows is the ring's, not the samples' (the fit draws them shuffled)."""

    def __init__(self, capacity: int) -> None:
        self.capacity = int(capacity)
        self.n = self._next = 0
        self._x: np.ndarray | None = None
        self._y: np.ndarray | None = None

    def add(self, x: np.ndarray, y: np.ndarray) -> None:
        """Keep ``x (N, X)``, ``y (N, Y)`` (the oldest kept rows make room)."""
        if len(x) != len(y):
            raise ValueError(f"samples: {len(x)} inputs against {len(y)} targets")
        if self._x is None:
            self._x = np.empty((self.capacity, *x.shape[1:]), x.dtype)
            self._y = np.empty((self.capacity, *y.shape[1:]), y.dtype)
        x, y = x[-self.capacity :], y[-self.capacity :]
        rows = (self._next + np.arange(len(x))) % self.capacity
        self._x[rows], self._y[rows] = x, y
        self._next = int((self._next + len(x)) % self.capacity)
        self.n = min(self.capacity, self.n + len(x))

    def samples(self) -> tuple[np.ndarray, np.ndarray]:
        """The kept rows (views, not copies)."""
        if self._x is None:
            raise ValueError("no samples kept yet")
        return self._x[: self.n], self._y[: self.n]


class Distiller:
    """A resumable DAgger run in ``run_dir``.

    Args:
        cfg: Settings.
        teacher: Policy or ensemble files whose (mean) action the student learns.
        run_dir: Run folder (created or resumed).
        reference: The training reference set (``.npz``, as ``grip policy train`` builds it).
        make_env: The environment constructor (:class:`policies.vec_env.EnvMaker`; the edge
            passes :func:`envs.factory.make_tracking_env`).
        progress: tqdm-like factory ``progress(total=..., initial=...)`` (None: no bar).
        log: Where each iteration's summary line goes (None: nowhere).
        specialists: Families whose clips learn from their own teacher instead
            (:class:`policies.teachers.TeacherRouter`; issue 47's specialists).

    Raises:
        ValueError: naming the file, when a teacher file is not a policy, its members act
            differently, or ``cfg.init_member`` is not one of them, or when ``run_dir`` holds a
            checkpoint of other settings or teachers (besides :data:`RESUMABLE`).
    """

    def __init__(self, cfg: DistillConfig, teacher: Sequence[str | os.PathLike],
                 run_dir: str | os.PathLike, reference: str | os.PathLike,
                 make_env: Callable, progress: Callable | None = None,
                 log: Callable[[str], None] | None = None,
                 specialists: Sequence = ()) -> None:  # fmt: skip
        from policies.runner import PolicyRunner
        from policies.teachers import TeacherRouter, load_teacher

        self.cfg = cfg
        self.rundir = RunDir(run_dir, RESUMABLE, "'grip policy distill' run")
        self.teacher_resolved = [str(Path(t).resolve()) for t in teacher]
        self.specialists_resolved = [[list(s.categories), str(Path(s.policy).resolve())]
                                     for s in specialists] or None  # fmt: skip
        self.rundir.check_resume(cfg, DistillConfig(), {"teacher": self.teacher_resolved,
                                                        "specialists": self.specialists_resolved},
                                 upgrade=_upgrade_settings)  # fmt: skip
        self.run_dir = self.rundir.path
        self.reference = str(reference)
        self.make_env = make_env
        self.progress = progress
        self.log = log or (lambda _s: None)
        self.teacher_files = [str(p) for p in teacher]
        loaded = load_teacher(self.teacher_files)
        payloads, self.teacher_names = loaded.payloads, loaded.names
        if not cfg.init_member < len(payloads):
            raise ValueError(f"init_member {cfg.init_member}: the teacher has {len(payloads)} "
                             f"member(s) (0..{len(payloads) - 1})")  # fmt: skip
        self.teacher = loaded.controller
        self.router = TeacherRouter(self.teacher, loaded.privileged, specialists)
        self.privileged = self.router.privileged
        """A teacher follows the ground truth (``follow = "truth"``): it acts on the truth's
        observation of each state and its actions are shifted to the student's estimate."""
        self._families: dict[str, int] = {}  # clip name -> the router's family
        # the student's file: the member's payload, with the teacher's fall detector (the
        # first member's discriminator) where the member's file stores none
        disc = {k: payloads[0][k] for k in ("disc", "amp_frame_dim") if k in payloads[0]}
        self.base = {**disc, **payloads[cfg.init_member]}
        if cfg.student_hidden:  # a fresh network of its own size between the member's ends
            sizes = self.base["actor_sizes"]
            self.base["actor_sizes"] = [sizes[0], *cfg.student_hidden, sizes[-1]]
            activation = json.loads(self.base["config"])["ppo"]["activation"]
            self.base["actor"] = mlp(self.base["actor_sizes"], activation).state_dict()
        self.student = PolicyRunner.from_payload(self.base, self.teacher_names[cfg.init_member])
        if cfg.fresh_student:
            for m in self.student.actor:
                if isinstance(m, torch.nn.Linear):
                    m.reset_parameters()
        self.optim = torch.optim.Adam(self.student.actor.parameters(), lr=cfg.learning_rate)
        self.iteration = 0
        self.history: list[dict] = []
        self._kept: SampleBuffer | None = None  # the samples fit on (read on first use)

    # -------------------------------------------------------------- bookkeeping
    @property
    def ckpt_dir(self) -> Path:
        return self.rundir.checkpoint_dir

    @property
    def data_dir(self) -> Path:
        return self.run_dir / "data"

    def wall_s(self) -> float:
        return self.rundir.wall_s()

    def save_checkpoint(self) -> None:
        """The student, its optimiser and the history: ``checkpoint/student.pt`` and
        ``state.json``, swapped in together (:meth:`grip.core.rundir.RunDir.save_checkpoint`)."""
        ck = {"actor": self.student.actor.state_dict(), "optim": self.optim.state_dict(),
              "iteration": self.iteration}  # fmt: skip
        state = {"iteration": self.iteration, "wall_s": self.wall_s(), "history": self.history}
        self.rundir.save_checkpoint(lambda tmp: torch.save(ck, tmp / "student.pt"), state)

    def _resume(self) -> None:
        from policies.checkpoint import load_weights

        state = self.rundir.read_state()
        if state is None:
            return
        ck = load_weights(self.ckpt_dir / "student.pt", "distillation checkpoint")
        if int(ck.get("iteration", -1)) != int(state["iteration"]):
            raise ValueError(
                f"{self.ckpt_dir}: student.pt (iteration {ck.get('iteration')}) "
                f"and state.json (iteration {state['iteration']}) disagree"
            )
        self.student.actor.load_state_dict(ck["actor"])
        self.optim.load_state_dict(ck["optim"])
        self.iteration, self.rundir.wall0_s = int(state["iteration"]), float(state["wall_s"])
        self.history = list(state["history"])

    # -------------------------------------------------------------- data
    def _data_files(self) -> list[Path]:
        return sorted(self.data_dir.glob("iter_*.npz"))[: self.iteration]

    def _add_data(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Keep one iteration's samples; returns the newest ``max_samples`` of all iterations
        done (:class:`SampleBuffer`): normalised student inputs and teacher actions (float16).
        The iterations of a resumed run are read from their files once, later ones kept in
        memory."""
        if self._kept is None:
            self._kept = SampleBuffer(self.cfg.max_samples)
            for f in self._data_files()[:-1]:  # the last one is (x, y)
                try:
                    with np.load(f, allow_pickle=False) as z:
                        self._kept.add(z["x"], z["y"])
                except (OSError, ValueError, KeyError) as e:
                    raise ValueError(f"{f}: unreadable distillation data ({e})") from e
        self._kept.add(x, y)
        return self._kept.samples()

    def _make_env(self):
        """The iteration's rollout environments: GRIP's stage-2 episodes with the teacher's
        settings (:func:`policies.vec_env.stage2_rollout_env`), batched or one by one
        (:attr:`DistillConfig.vec_env`)."""
        import dataclasses

        from policies.vec_env import BatchedVecEnv, stage2_rollout_env

        c = self.cfg
        seed = c.seed + 7919 * self.iteration
        teacher_env = dataclasses.replace(self.teacher.env_cfg, teacher_obs=self.privileged,
                                          teacher_root=c.teacher_root)  # fmt: skip
        if c.vec_env == "dummy":
            return stage2_rollout_env(self.make_env, teacher_env, self.reference,
                                      c.categories, c.n_envs, seed, c.fall_height_m,
                                      c.max_episode_frames, c.fall_below_reference_m)  # fmt: skip
        batched = getattr(self.make_env, "batched", None)
        if batched is None:
            raise ValueError("vec_env = 'batched' needs an env maker with a 'batched' form "
                             "(envs.factory.make_tracking_env has one)")  # fmt: skip
        # stage2_rollout_env's settings, for the environments of one batch
        stage2 = {"reference": self.reference, "random_start": True, "clip_index": -1,
                  "termination_dist_m": 0.0, "fall_height_m": c.fall_height_m,
                  "fall_below_reference_m": c.fall_below_reference_m,
                  "max_episode_frames": c.max_episode_frames}  # fmt: skip
        env_cfg = dataclasses.replace(teacher_env, **stage2)
        seeds = [seed + 1000 * i for i in range(c.n_envs)]
        return BatchedVecEnv(batched(env_cfg, tuple(c.categories), seeds, 0))

    def collect(self, bar=None) -> tuple[np.ndarray, np.ndarray, dict]:
        """One rollout of ``decisions_per_iteration`` decisions with the student acting (the
        teacher with probability ``beta``); returns the normalised inputs, the teacher's actions
        and the rollout's statistics."""
        c = self.cfg
        beta = c.beta(self.iteration)
        rng = np.random.default_rng(c.seed + 104729 * (self.iteration + 1))
        venv = self._make_env()
        steps = -(-c.decisions_per_iteration // c.n_envs)
        xs, ys = [], []
        sq_err = 0.0
        ended = falls = 0
        ep_len = np.zeros(c.n_envs, np.int64)
        lens: list[int] = []
        taught = np.zeros(len(self.router.specialists) + 1, np.int64)  # [-1] the default
        try:
            obs = venv.reset()
            families = self._clip_families([info["clip"] for info in venv.reset_infos])
            for _ in range(steps):
                x = self.student._flat(obs)
                a_t = self.router.act(obs, families)
                np.add.at(taught, families, 1)
                with torch.no_grad():
                    a_s = self.student.actor(torch.as_tensor(x, dtype=torch.float32)).numpy()
                a_s = np.clip(a_s, -1.0, 1.0)
                sq_err += float(((a_s - a_t) ** 2).mean(1).sum())
                use_t = rng.random(c.n_envs) < beta
                xs.append(x.astype(np.float16))
                ys.append(a_t.astype(np.float16))
                a = np.where(use_t[:, None], a_t, a_s)
                if c.action_noise > 0:
                    a = np.clip(a + c.action_noise * rng.standard_normal(a.shape), -1.0, 1.0)
                obs, _r, dones, infos = venv.step(a)
                if self.router.specialists:  # (a done env has begun its next episode)
                    families = self._clip_families([
                        venv.reset_infos[i]["clip"] if d else infos[i]["clip"]
                        for i, d in enumerate(dones)])  # fmt: skip
                ep_len += 1
                for i in np.flatnonzero(dones):
                    ended += 1
                    falls += not infos[i].get("TimeLimit.truncated", False)
                    lens.append(int(ep_len[i]))
                    ep_len[i] = 0
                if bar is not None:
                    bar.update(c.n_envs)
        finally:
            venv.close()
        n = steps * c.n_envs
        stats = {"beta": beta, "decisions": n, "episodes": ended, "falls": falls,
                 "falls_per_1k": 1000.0 * falls / n,
                 "ep_len": float(np.mean(lens)) if lens else float("nan"),
                 "onpolicy_mse": sq_err / n}  # fmt: skip
        if self.router.specialists:  # decisions labelled by each specialist, then the default
            stats["taught"] = [int(t) for t in taught]
        return np.concatenate(xs), np.concatenate(ys), stats

    def _clip_families(self, clips: Sequence[str]) -> np.ndarray:
        """The router's family (:meth:`policies.teachers.TeacherRouter.family`) of each of the
        reference set's ``clips`` (names); -1 for all without specialists."""
        if not self.router.specialists:
            return np.full(len(clips), -1, np.int64)
        if not self._families:
            from grip.core.reference_sets import load_reference

            self._families = {c.name: self.router.family(c.category)
                              for c in load_reference(self.reference).clips}  # fmt: skip
        return np.array([self._families[c] for c in clips], np.int64)

    def fit(self, x: np.ndarray, y: np.ndarray) -> float:
        """``epochs`` passes of mean-squared error over ``(x, y)``; returns the last pass's mean
        loss."""
        c = self.cfg
        rng = np.random.default_rng(c.seed + 15485863 * (self.iteration + 1))
        actor = self.student.actor.train()
        xt, yt = torch.from_numpy(x), torch.from_numpy(y)
        loss_sum = 0.0
        for _ in range(c.epochs):
            order = torch.from_numpy(rng.permutation(len(x)))
            loss_sum, seen = 0.0, 0
            for s in range(0, len(x), c.batch_size):
                idx = order[s : s + c.batch_size]
                pred = actor(xt[idx].float())
                loss = torch.nn.functional.mse_loss(pred, yt[idx].float())
                self.optim.zero_grad()
                loss.backward()
                self.optim.step()
                loss_sum += float(loss.detach()) * len(idx)
                seen += len(idx)
            loss_sum /= max(seen, 1)
        actor.eval()
        return loss_sum

    # -------------------------------------------------------------- run
    def run(self) -> None:
        """Run (or resume) the iterations left, checkpointing after each."""
        c = self.cfg
        if c.threads:
            torch.set_num_threads(c.threads)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.data_dir.mkdir(exist_ok=True)
        self._resume()
        per_iter = -(-c.decisions_per_iteration // c.n_envs) * c.n_envs
        bar = None
        if self.progress is not None:
            bar = self.progress(total=c.iterations * per_iter, initial=self.iteration * per_iter,
                                unit="decision", smoothing=0.05)  # fmt: skip
        try:
            while self.iteration < c.iterations:
                t0 = time.time()
                x, y, stats = self.collect(bar)
                f = self.data_dir / f"iter_{self.iteration:03d}.npz"
                atomic_write(f, lambda fh, x=x, y=y: np.savez(fh, x=x, y=y))
                t1 = time.time()
                self.iteration += 1
                xa, ya = self._add_data(x, y)
                stats["fit_mse"] = self.fit(xa, ya)
                stats.update(iteration=self.iteration, samples=len(xa),
                             collect_s=t1 - t0, fit_s=time.time() - t1)  # fmt: skip
                self.history.append(stats)
                self.save_checkpoint()
                self.log(f"iteration {self.iteration}/{c.iterations}: beta {stats['beta']:.3f}, "
                         f"falls {stats['falls']} of {stats['episodes']} episodes "
                         f"({stats['falls_per_1k']:.2f} per 1k decisions), on-policy MSE "
                         f"{stats['onpolicy_mse']:.4f}, fit MSE {stats['fit_mse']:.4f} on "
                         f"{len(xa)} samples ({stats['collect_s']:.0f} + "
                         f"{stats['fit_s']:.0f} s)")  # fmt: skip
        finally:
            if bar is not None:
                bar.close()

    def export(self, out: str | os.PathLike, precision: str = "fp16") -> int:
        """Write the student as a policy file (the member's payload with the student's actor);
        returns its size in bytes."""
        from grip.nn.weights import pack_weights

        payload = dict(self.base)
        payload["actor"] = pack_weights(self.student.actor.state_dict(), precision)
        if self.privileged:  # the student follows the estimate, whatever its teacher followed
            config = json.loads(payload["config"])
            config["follow"] = "estimate"
            payload["config"] = json.dumps(config)
        info = json.loads(payload.get("info", "{}"))
        info = {k: v for k, v in info.items() if k == "holdout"}
        info["distilled"] = {"teacher": self.teacher_names, "init_member": self.cfg.init_member,
                             "specialists": [[cats, Path(f).name] for cats, f in
                                             self.specialists_resolved or ()],
                             "iterations": self.iteration,
                             "decisions": sum(h["decisions"] for h in self.history),
                             "wall_s": self.wall_s()}  # fmt: skip
        payload["info"] = json.dumps(info)
        from policies.runner import write_policy_file

        return write_policy_file([payload], [self.teacher_names[self.cfg.init_member]], out)


def plot_distill_curves(history: list[dict], out_png: str | os.PathLike) -> None:
    """Falls per 1,000 decisions and the student's error against the teacher, per iteration."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    it = [h["iteration"] for h in history]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), constrained_layout=True)
    axes[0].plot(it, [h["falls_per_1k"] for h in history], "o-")
    axes[0].set_ylabel("falls per 1,000 decisions")
    axes[1].plot(it, [h["onpolicy_mse"] for h in history], "o-", label="on its states, before fit")
    axes[1].plot(it, [h["fit_mse"] for h in history], "s--", label="fit (all data)")
    axes[1].set_ylabel("student - teacher action MSE")
    axes[1].set_yscale("log")
    axes[1].legend()
    axes[2].plot(it, [h["beta"] for h in history], "o-")
    axes[2].set_ylabel("teacher's share of actions (beta)")
    for ax in axes:
        ax.set_xlabel("DAgger iteration")
        ax.grid(alpha=0.3)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    atomic_write(out_png, lambda f: f.write(buf.getvalue()))
