"""GRIP's inference pipeline: ``SensorStream -> KinematicsNet -> controller -> Humanoid``.

No ground truth and no training task: the humanoid (:class:`grip.sim.humanoid.Humanoid`) starts
from the calibration pose (:class:`grip.kinematics.features.Calibration`: the recording's first
frames where it has ground truth, else the standing rest pose turned to the heading of the foot
IMUs, :func:`grip.kinematics.features.standing_calibration`) and the policy follows
the KinematicsNet estimate, observing it exactly as the training task does
(:class:`grip.task.observations.EstimateFrames`); no reward is computed. Offline and streaming share
:class:`Player`, which plays one control step at a time: offline runs KinematicsNet once over the
whole recording (batched; the same numbers as its step-wise use within float32 rounding) and
then steps the player over every frame (or several recordings side by side:
:class:`BatchedPlayer`, one controller forward per frame over their observations, each player
stepped by :meth:`Player.step` as :meth:`Player.advance` steps it alone); a stream
(:class:`grip.eval.stream.GripStream`) grows a :class:`grip.core.reference.LiveEstimate` and
steps the player once per frame.

The player of one episode, its start states and fall recovery live in :mod:`grip.player`.
"""

from __future__ import annotations

import itertools
import os
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from envs.scenes import HumanoidScenes, humanoid_scenes
from grip.core.body import BodyParams
from grip.core.reconstruction import Reconstruction
from grip.core.reference import Estimate
from grip.core.rotations import matrix_to_6d
from grip.kinematics.features import SensorStream, first_state, stream_features
from grip.player import (
    CONTACT_FORCE_N,
    PaceKeeper,
    Player,
    RecoveryConfig,
    StartState,
    kinematic_frames,
    start_from_calibration,
    start_from_clip,
)
from grip.sim.humanoid import Humanoid

__all__ = [
    "CONTACT_FORCE_N",
    "BatchedPlayer",
    "Episode",
    "GripPipeline",
    "PaceKeeper",
    "Player",
    "RecoveryConfig",
    "StartState",
    "kinematic_frames",
    "start_from_calibration",
    "start_from_clip",
    "usable_cores",
]


@dataclass(frozen=True, eq=False)
class Episode:
    """One recording to play (:meth:`GripPipeline.play_many`).

    Attributes:
        est: What the policy follows: an :class:`grip.core.reference.Estimate` or a reference
            clip (``name``, ``fps``, ``n_frames`` and the ``est_*`` arrays).
        start: Where the humanoid starts.
        body: The subject's body.
        objects: The scene's objects (None: the policy's terrain).
        stop_at_fall: End at the first fall that is not recovered (evaluation).
    """

    est: object
    start: StartState
    body: BodyParams
    objects: dict | None = None
    stop_at_fall: bool = False


Played = tuple[int, "Reconstruction | Exception", dict]
"""``(index, result, info)`` of a finished episode: its position in the input, its
reconstruction (or the exception that ended it) and ``{"blowups": int, "sim_s": float}``
(empty for an exception)."""


def usable_cores() -> int:
    """The cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


class _Lane:
    """One row of a :class:`BatchedPlayer`: an episode's index, its player and its share of the
    time spent so far, s."""

    __slots__ = ("index", "player", "sim_s")

    def __init__(self, index: int, player: Player, sim_s: float) -> None:
        self.index, self.player, self.sim_s = index, player, sim_s


def _step_lanes(lanes: Sequence[_Lane], actions: Sequence) -> list:
    """Step each lane's player with its action (None: none due; an exception: its decision
    failed, the lane fails with it); per lane ``True``/``False`` (over or not) or the
    exception."""
    out: list = []
    for lane, a in zip(lanes, actions, strict=True):
        if isinstance(a, Exception):
            out.append(a)
            continue
        try:
            out.append(lane.player.step(a))
        except Exception as e:  # (that episode fails; the others play on)
            out.append(e)
    return out


class BatchedPlayer:
    """Episodes played side by side: up to ``batch`` :class:`Player` s at once, one controller
    forward over the ``(K, ...)`` observations of those whose decision is due, then each
    player's :meth:`Player.step` (falls, recovery and blow-ups exactly as it plays alone), the
    players split over ``threads`` threads (MuJoCo's bindings release the GIL while the
    physics steps). A finished episode leaves its row, the next one takes it.

    An episode's ``ms_per_frame`` is its share of the batch's time (each step's time split
    evenly over the rows it stepped). Its numbers are those it gets played alone
    (:meth:`Player.advance`) when the
    controller's action for one row of a batch equals its action for that observation alone:
    bit for bit for a controller that acts row by row; a torch MLP's batched matrix products
    may round the last bits of an action otherwise (float32), and a simulation amplifies them.

    Args:
        runner: The controller (:class:`Player`'s ``runner``); ``act`` takes a batch.
        make_player: A new player for an episode, on a humanoid no other row uses.
        batch: Rows, >= 1.
        threads: Threads stepping the players (0: the cores this process may use).
        release: Called with each player whose episode is over (its humanoid may be reused).
    """

    def __init__(self, runner, make_player: Callable[[Episode], Player], batch: int = 16,
                 threads: int = 0,
                 release: Callable[[Player], object] | None = None) -> None:  # fmt: skip
        if batch < 1:
            raise ValueError(f"batch must be >= 1, got {batch}")
        self.runner, self.make_player, self.batch = runner, make_player, int(batch)
        self.release = release
        self.threads = max(1, min(int(threads) if threads > 0 else usable_cores(), self.batch))
        self._keys = getattr(runner, "obs_keys", None)

    def play(self, episodes: Iterable[Episode | Exception]) -> Iterator[Played]:
        """Play every episode (an exception in their place is passed through as its result);
        yields each as it finishes, so not in order. Episodes are taken from ``episodes`` only
        when a row is free."""
        pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None
        try:
            yield from self._play(iter(enumerate(episodes)), pool)
        finally:
            if pool is not None:
                pool.shutdown()

    def _play(self, items: Iterator, pool: ThreadPoolExecutor | None) -> Iterator[Played]:
        lanes: list[_Lane] = []
        more = True
        while True:
            while more and len(lanes) < self.batch:
                item = next(items, None)
                if item is None:
                    more = False
                    break
                i, ep = item
                if isinstance(ep, Exception):
                    yield i, ep, {}
                    continue
                t0 = time.perf_counter()
                try:
                    player = self.make_player(ep)
                    player.start(ep.est, ep.start, ep.est.name, ep.est.fps)
                except Exception as e:
                    yield i, e, {}
                    continue
                lanes.append(_Lane(i, player, time.perf_counter() - t0))
            if not lanes:
                return
            t0 = time.perf_counter()
            outcome = self._step(lanes, self._actions(lanes), pool)
            share = (time.perf_counter() - t0) / len(lanes)
            kept = []
            for lane, out in zip(lanes, outcome, strict=True):
                lane.sim_s += share
                if not out:  # (False: plays on; True or an exception: over)
                    kept.append(lane)
                    continue
                got = (out, {}) if isinstance(out, Exception) else _finish(lane.player,
                                                                           lane.sim_s)
                if self.release is not None:
                    self.release(lane.player)
                yield lane.index, *got
            lanes = kept

    def _actions(self, lanes: Sequence[_Lane]) -> list:
        """The due decisions: one forward over the rows whose decision is due (per row again
        when the batch fails, so that the failure stays with its row)."""
        due = [k for k, lane in enumerate(lanes) if lane.player.needs_action()]
        actions: list = [None] * len(lanes)
        if not due:
            return actions
        obs = [lanes[k].player.obs for k in due]
        keys = self._keys or list(obs[0])
        try:
            got = self.runner.act({key: np.stack([o[key] for o in obs]) for key in keys})
            if np.shape(got)[0] != len(due):
                raise ValueError(f"the controller returned {np.shape(got)} actions for "
                                 f"{len(due)} observations")  # fmt: skip
        except Exception:
            got = [_act_or_error(self.runner, o) for o in obs]
        for k, a in zip(due, got, strict=True):
            actions[k] = a
        return actions

    def _step(self, lanes: list[_Lane], actions: list, pool: ThreadPoolExecutor | None) -> list:
        if pool is None or len(lanes) < 2:
            return _step_lanes(lanes, actions)
        n = min(self.threads, len(lanes))
        cuts = np.linspace(0, len(lanes), n + 1).astype(int)
        futures = [pool.submit(_step_lanes, lanes[a:b], actions[a:b])
                   for a, b in itertools.pairwise(cuts)]  # fmt: skip
        return [r for f in futures for r in f.result()]


def _act_or_error(runner, obs: dict) -> np.ndarray | Exception:
    try:
        return runner.act(obs)
    except Exception as e:
        return e


def _finish(player: Player, sim_s: float) -> tuple[Reconstruction, dict]:
    """A finished player's reconstruction and info (``sim_s``: its time, s)."""
    recon = player.reconstruction(1e3 * sim_s / max(player.last + 1, 1))
    return recon, {"blowups": player.blowups, "sim_s": sim_s}


_IDLE_HUMANOIDS = 64
"""Humanoids of finished rows a :class:`GripPipeline` keeps for later episodes."""


class GripPipeline:
    """KinematicsNet + policy + humanoid + fall recovery, without ground truth.

    Args:
        runner: A :class:`policies.runner.PolicyRunner` or an ensemble of them (its env
            settings and sensor features must match the estimator's).
        estimator: A :class:`grip.kinematics.inference.KinematicsEstimator`.
        recovery: Fall detection and recovery settings.
        pace: The pace keeper of every player (:class:`grip.player.PaceKeeper`).
    """

    def __init__(self, runner, estimator, recovery: RecoveryConfig = RecoveryConfig(),
                 pace: PaceKeeper = PaceKeeper()) -> None:  # fmt: skip
        self.runner, self.estimator, self.recovery, self.pace = runner, estimator, recovery, pace
        self._compiled: dict = {}  # compiled models by (scene, subject), for every humanoid here
        self.scenes = humanoid_scenes(runner.env_cfg, compiled=self._compiled)
        self._scene_tag = 0
        self._idle: dict[tuple, list[Humanoid]] = {}  # by subject: humanoids of finished rows
        self._lent: dict[int, tuple] = {}  # id(player) -> subject, of rows on the flat floor

    def humanoid(self, body: BodyParams, objects: dict | None) -> Humanoid:
        """The humanoid of a subject in its scene (each scene of objects compiled anew)."""
        self._scene_tag += 1
        return self.scenes.get(body, objects, self._scene_tag)

    def player(self, body: BodyParams, objects: dict | None = None,
               stop_at_fall: bool = False) -> Player:  # fmt: skip
        """A :class:`Player` on the subject's humanoid."""
        return Player(self.runner, self.humanoid(body, objects), self.recovery, stop_at_fall,
                      self.pace)  # fmt: skip

    def _own_player(self, ep: Episode) -> Player:
        """A :class:`Player` of ``ep`` on a humanoid no other row of a :class:`BatchedPlayer`
        uses: an idle one of the subject on the flat floor (:meth:`_release`; a reset makes it
        new), else a new one from the compiled model, which simulates as the shared humanoid
        switched to that subject does (:class:`grip.sim.model.ModelVariants`)."""
        key = (ep.body.height_m, ep.body.mass_kg)
        idle = self._idle.get(key) if ep.objects is None else None
        if idle:
            h = idle.pop()
        else:
            self._scene_tag += 1
            scenes: HumanoidScenes = humanoid_scenes(self.runner.env_cfg,
                                                     compiled=self._compiled)  # fmt: skip
            h = scenes.get(ep.body, ep.objects, self._scene_tag)
        player = Player(self.runner, h, self.recovery, ep.stop_at_fall, self.pace)
        if ep.objects is None:
            self._lent[id(player)] = key
        return player

    def _release(self, player: Player) -> None:
        """A finished row's humanoid on the flat floor waits for the subject's next episode
        (at most :data:`_IDLE_HUMANOIDS` wait)."""
        key = self._lent.pop(id(player), None)
        if key is not None and sum(map(len, self._idle.values())) < _IDLE_HUMANOIDS:
            self._idle.setdefault(key, []).append(player.h)

    def play_many(self, episodes: Iterable[Episode | Exception], batch: int = 16,
                  threads: int = 0) -> Iterator[Played]:  # fmt: skip
        """Play episodes, ``batch`` side by side (:class:`BatchedPlayer`; 1: one after another
        through :meth:`play`); yields ``(index, reconstruction or exception, info)`` of each as
        it finishes. An exception in place of an episode, or one an episode raises, is its
        result; the others play on.

        Args:
            episodes: What to play (taken when a row is free, so it may be a generator that
                estimates the next recordings only then).
            batch: Episodes played side by side.
            threads: Threads stepping the humanoids of a batch (0: the usable cores).
        """
        if batch > 1:
            rows = BatchedPlayer(self.runner, self._own_player, batch, threads, self._release)
            yield from rows.play(episodes)
            return
        for i, ep in enumerate(episodes):
            if isinstance(ep, Exception):
                yield i, ep, {}
                continue
            try:
                recon, info = self.play(ep.est, ep.start, ep.body, ep.objects, ep.stop_at_fall)
            except Exception as e:
                yield i, e, {}
                continue
            yield i, recon, info

    def estimate(self, streams: Sequence[SensorStream]) -> list[Estimate]:
        """KinematicsNet over whole recordings, as one padded batch, from their calibration
        poses and velocities (the LSTMs' first states: :func:`first_state`)."""
        import torch

        from grip.core.body import build_body
        from grip.kinematics.inference import decode_outputs

        cfg = self.estimator.cfg.features
        feats = [stream_features(s, cfg) for s in streams]
        t_max = max(len(f) for f in feats)
        x = np.zeros((len(feats), t_max, feats[0].shape[1]), dtype=np.float32)
        for i, f in enumerate(feats):
            x[i, : len(f)] = f
            x[i, len(f) :] = f[-1]  # causal model: padding never affects earlier frames
        firsts = [first_state(s.calibration, s.body, s.fps) for s in streams]
        first = {k: torch.from_numpy(np.stack([f[k] for f in firsts])) for k in firsts[0]}
        out = self.estimator.run_features(torch.from_numpy(x), first)
        ests = []
        for i, s in enumerate(streams):
            n = s.n_frames
            o = {k: v[i, :n].numpy().astype(np.float64) for k, v in out.items()}
            pos, rot, vel = decode_outputs(o, n, build_body(s.body).offsets)
            ests.append(Estimate(s.name, s.fps, pos, matrix_to_6d(rot), vel, feats[i],
                                 s.calibration.root_pos[0]))  # fmt: skip
        return ests

    def play(self, est, start: StartState, body: BodyParams, objects: dict | None = None,
             stop_at_fall: bool = False) -> tuple[Reconstruction, dict]:  # fmt: skip
        """Play a whole estimate from ``start``.

        Returns:
            The reconstruction (method ``"grip"``) and ``{"blowups": int, "sim_s": float}``.
        """
        t0 = time.perf_counter()
        player = self.player(body, objects, stop_at_fall)
        player.start(est, start, est.name, est.fps)
        while not player.advance():
            pass
        sim_s = time.perf_counter() - t0
        recon = player.reconstruction(1e3 * sim_s / max(player.last + 1, 1))
        return recon, {"blowups": player.blowups, "sim_s": sim_s}

    def reconstruct(
        self, streams: Sequence[SensorStream], batch: int = 16,
        progress: Callable[[int], object] | None = None, play_batch: int = 1,
        threads: int = 0, errors: bool = False,
    ) -> list:  # fmt: skip
        """One :class:`Reconstruction` per sensor stream, in order.

        Args:
            streams: The recordings' sensors.
            batch: Recordings per KinematicsNet forward pass (1: each alone, the numbers of
                ``reconstruct([s])``; a padded batch rounds its float32 sums otherwise).
            progress: Called with 1 after each recording.
            play_batch: Recordings played side by side (:meth:`play_many`).
            threads: Threads stepping a batch's humanoids (0: the usable cores).
            errors: Return the exception that a recording raised in its place (the others go
                on); False: raise it.
        """
        kin_ms: dict[int, float] = {}
        out: list = [None] * len(streams)
        played = self.play_many(self._stream_episodes(streams, batch, kin_ms), play_batch,
                                threads)  # fmt: skip
        for i, recon, _ in played:
            if isinstance(recon, Exception):
                if not errors:
                    played.close()
                    raise recon
            else:
                recon.ms_per_frame += kin_ms[i]
                recon.notes["kinematics_ms_per_frame"] = kin_ms[i]
            out[i] = recon
            if progress is not None:
                progress(1)
        return out

    def _stream_episodes(self, streams: Sequence[SensorStream], batch: int,
                         kin_ms: dict[int, float]) -> Iterator[Episode | Exception]:  # fmt: skip
        """The episodes of sensor streams (KinematicsNet ``batch`` at a time, when the player
        asks for the next; ``kin_ms[i]``: KinematicsNet's time per frame of stream ``i``, ms)."""
        for i in range(0, len(streams), batch):
            part = list(streams[i : i + batch])
            t0 = time.perf_counter()
            try:
                ests = self.estimate(part)
            except Exception as e:
                yield from [e] * len(part)
                continue
            ms = 1e3 * (time.perf_counter() - t0) / max(sum(s.n_frames for s in part), 1)
            for j, (s, est) in enumerate(zip(part, ests, strict=True)):
                kin_ms[i + j] = ms
                try:
                    start = start_from_calibration(s.calibration, s.body, s.fps)
                except Exception as e:
                    yield e
                    continue
                yield Episode(est, start, s.body, s.objects)
