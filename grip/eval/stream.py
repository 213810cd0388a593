"""Streaming GRIP: one frame of sensors in, one frame of simulated motion out, state carried.

The stream runs the same computation as the offline path (:mod:`grip.eval.reconstruct`), frame
by frame: :class:`grip.kinematics.feature_stream.FeatureStream` builds the network inputs,
KinematicsNet steps its LSTMs once per frame, a :class:`grip.core.reference.LiveEstimate` grows
by the estimate, and :class:`grip.pipeline.Player` advances the policy and the humanoid one
control step with GRIP's fall recovery. No ground truth is read: the calibration frames give the
start pose and the sensor alignment (:class:`grip.kinematics.features.Calibration`).

Latency: two frames (20 ms at 100 Hz) on top of the computation. The angular velocities of the
sensors and of the estimate are central differences (as in training), so frame ``t`` of the
features needs the sensors of ``t + 1``, and the control step to ``t`` needs the estimate of
``t + 1``: pushing frame ``t`` returns the simulated frame ``t - 2``; :meth:`GripStream.finish`
returns the last two.

Falls: a recovery at frame ``t`` replaces frames ``t - N .. t`` with the buffered kinematic
estimate (GRIP Sec. 3.4). A stream has already handed out frames ``t - N .. t - 1``; the frame
of ``t`` carries the event (:attr:`StreamFrame.fall`) and :meth:`GripStream.reconstruction`
returns every frame as the offline path does, replacements included. A simulation blow-up is
recovered the same way (:attr:`StreamFrame.blowup`); the stream never ends early.

Time: every pushed frame has an index (``push(frame, index=i)``, or ``timestamp_s``: the index is
the time since frame 0 times the frame rate, rounded; or neither: the frame after the last one).
Output frame ``i`` is input frame ``i``, whatever was refused or missing. A duplicate or an
earlier index is refused (``ValueError`` naming both indices). Missing frames (a dropout, or a
frame refused for its values) are filled when the next frame arrives: up to ``max_gap_frames``
(10, as ``grip reconstruct --fill-gaps``) by interpolating the sensors (linear, orientations by
slerp; as :func:`prism_tools.gaps.fill_gaps` does offline) and simulating them as usual; a
longer gap is not simulated: its frames hold the last simulated pose (forces NaN), the pipeline
restarts at the next frame and the humanoid is put at the kinematic estimate there. Each gap is
a :class:`StreamEvent` in :attr:`GripStream.events` and in the reconstruction's notes. A frame
whose index would make the stream longer than the input limits (``max_frames``,
``max_duration_s``: a wall clock that jumped 10,000 s) is refused, and the stream goes on with the
next frame that is not.
"""

from __future__ import annotations

import operator
import time
from dataclasses import dataclass

import numpy as np

from grip.core.body import build_body
from grip.core.limits import InputLimits, LimitExceeded, active_limits
from grip.core.reconstruction import Reconstruction
from grip.core.reference import LiveEstimate
from grip.core.rotations import matrix_to_quat, quat_slerp, quat_to_matrix
from grip.kinematics.feature_stream import FeatureStream, sensor_frame_arrays
from grip.kinematics.features import SensorFrame, SensorStream, first_state, sensor_stream
from grip.kinematics.inference import decode_outputs
from grip.pipeline import (
    GripPipeline,
    PaceKeeper,
    Player,
    RecoveryConfig,
    start_from_calibration,
)

LATENCY_FRAMES = 2
"""Frames between a sensor frame going in and its simulated frame coming out."""

MAX_GAP_FRAMES = 10
"""Longest run of missing frames a stream fills by interpolation (``grip reconstruct``'s
``--fill-gaps`` default: 0.1 s at 100 Hz)."""


@dataclass(frozen=True)
class StreamEvent:
    """Something a stream did besides simulating the frames pushed.

    Attributes:
        kind: ``"filled"``: input frames ``first..last`` were missing; their sensors were
            interpolated and simulated. ``"gap"``: ``first..last`` were missing, more than the
            stream fills; they hold the last simulated pose (forces NaN) and the humanoid
            restarted at ``last + 1``. ``"blowup"``: the simulation blew up at ``last`` and was
            recovered (frames ``first..last`` replaced, as for a fall).
        first: First frame concerned.
        last: Last frame concerned.
        message: What happened, in words.
    """

    kind: str
    first: int
    last: int
    message: str


@dataclass(frozen=True, eq=False)
class StreamFrame:
    """One simulated frame (world frame, metres, newtons).

    Attributes:
        frame: Frame index in the recording.
        joint_pos: ``(24, 3)`` joint positions.
        global_rot: ``(24, 3, 3)`` joint rotations.
        grf: ``(2, 3)`` ground reaction force on the left, right foot (NaN in a recovery).
        cop: ``(2, 3)`` centre of pressure of each foot (NaN without contact).
        torques: ``(69,)`` actuator torques, N m (NaN in a recovery).
        contacts: ``(2,)`` bool foot contacts.
        fall: ``(first, last)`` frames replaced by a fall recovery that ended at this frame,
            else ``None``.
        blowup: That recovery followed a simulation blow-up.
    """

    frame: int
    joint_pos: np.ndarray
    global_rot: np.ndarray
    grf: np.ndarray
    cop: np.ndarray
    torques: np.ndarray
    contacts: np.ndarray
    fall: tuple[int, int] | None = None
    blowup: bool = False


class GripStream:
    """GRIP on a live sensor stream (see the module docstring).

    Args:
        runner: A :class:`policies.runner.PolicyRunner` or an ensemble of them
            (:class:`policies.ensemble.PolicyEnsemble`).
        estimator: A :class:`grip.kinematics.inference.KinematicsEstimator`.
        calibration: The recording's first frames: a :class:`grip.kinematics.features.
            SensorStream` (its calibration and subject), or a PRISM recording or slice of one
            (its ``smpl_params`` and ``imu_gt`` of frames 0 and 1 only): the calibration pose the
            humanoid and the LSTMs start from, and the sensor-to-segment alignment.
        recovery: Fall detection and recovery settings (default :class:`RecoveryConfig`).
        capacity: Frames allocated at first (the buffers double when a stream runs longer).
        max_gap_frames: Longest run of missing frames filled by interpolation (longer ones are
            gaps, see the module docstring).
        pace: The pace keeper (:class:`grip.player.PaceKeeper`; default: its defaults, gain 1).
        limits: Bound the stream's length (``max_frames``, ``max_duration_s``): a frame whose
            index or timestamp lies beyond is refused (default
            :func:`grip.core.limits.active_limits`).

    Attributes:
        events: The :class:`StreamEvent` s so far (filled frames, gaps, blow-ups), in order.

    Example::

        stream = GripStream(runner, estimator, rec.slice_frames(0, 2))
        for i, frame in enumerate(sensor_frames(rec, estimator.cfg.features)):
            out = stream.push(frame, index=i)  # StreamFrame of frame i - 2, or None
        tail = stream.finish()
    """

    def __init__(self, runner, estimator, calibration, recovery: RecoveryConfig | None = None,
                 capacity: int = 1024, max_gap_frames: int = MAX_GAP_FRAMES,
                 limits: InputLimits | None = None,
                 pace: PaceKeeper | None = None) -> None:  # fmt: skip
        if max_gap_frames < 0:
            raise ValueError(f"max_gap_frames must be >= 0, got {max_gap_frames}")
        self._limits = limits or active_limits()
        cfg = estimator.cfg.features
        self._cfg, self.max_gap_frames = cfg, int(max_gap_frames)
        recovery = recovery or RecoveryConfig()
        self.runner, self.estimator, self.recovery = runner, estimator, recovery
        head = calibration
        if not isinstance(head, SensorStream):
            head = sensor_stream(calibration.slice_frames(0, min(2, calibration.n_frames)), cfg)
        cal, self._head = head.calibration, head
        self._features = FeatureStream(cfg, head.fps, cal.imu_ori, head.name)
        self._kin = estimator.stream_from(first_state(cal, head.body, head.fps))
        self.clip = LiveEstimate(head.name, head.fps, cal.root_pos[0], cfg.n_features, capacity)
        # (live: the humanoid starts at frame 0, where a stream begins standing still)
        self._start = start_from_calibration(cal, head.body, head.fps, warmup=False)
        self._pipeline = GripPipeline(runner, estimator, recovery, pace or PaceKeeper())
        self._offsets = build_body(head.body).offsets
        self._capacity = capacity
        self.player: Player | None = None
        self._busy_s = 0.0
        self._finished = False
        self.events: list[StreamEvent] = []
        self._last_in = -1  # index of the last frame taken
        self._next_in = 0  # index of a frame pushed without one
        self._t0_s: float | None = None  # timestamp of frame 0, s
        self._prev: tuple | None = None  # (acc, ori, insole) of the last frame taken, copies
        self._base = 0  # index of the features' first frame (> 0 after a gap: restarted)
        self._resume: int | None = None  # after a gap: the frame the humanoid restarts at
        self._est: tuple | None = None  # (pos, rot, row) of the newest estimate
        self._n_blowups = 0

    # ------------------------------------------------------------------ frames
    def push(self, frame: SensorFrame, index: int | None = None,
             timestamp_s: float | None = None) -> StreamFrame | None:  # fmt: skip
        """Take the sensors of frame ``t``; return simulated frame ``t - 2`` (``None`` for the
        first two frames and the two after a gap). Frames filled before ``t`` (missing ones)
        are simulated first; :meth:`frame` returns any of them.

        Args:
            frame: The sensors.
            index: The frame's index ``t`` (0 = the calibration frame).
            timestamp_s: Or its time, s: ``t`` = the time since frame 0 x fps, rounded (frame
                0's time is that of the first timestamped frame less its index / fps).
                Neither: the frame after the last one pushed (refused ones included).

        Raises:
            ValueError: A malformed or non-finite frame (named), a duplicate or an earlier
                index, an index beyond the input limits (a clock jump), a missing frame 0 or 1,
                both ``index`` and ``timestamp_s``, or a push after :meth:`finish`. A refused
                frame changes nothing (without an index it still takes its number, except
                frames 0 and 1: the next frame is the one after it, and the refused one is
                filled as missing; a frame beyond the limits takes none).
        """
        if self._finished:
            raise ValueError(f"{self.clip.name}: push after finish()")
        t0 = time.perf_counter()
        try:
            i = self._index(index, timestamp_s)
            if i != self._last_in + 1 or self._base:
                return self._push_slow(frame, i)
            try:
                row = self._features.push(frame)
            except ValueError:
                self._refused(i)
                raise
            self._take(frame, i)
            return None if row is None else self._next(row)
        finally:
            self._busy_s += time.perf_counter() - t0

    def _index(self, index: int | None, timestamp_s: float | None) -> int:
        """The index of a pushed frame; refuses duplicates and earlier frames."""
        at = ""
        if timestamp_s is not None:
            if index is not None:
                raise ValueError(f"{self.clip.name}: give a frame index or a timestamp, not both")
            ts = float(timestamp_s)
            if not np.isfinite(ts):
                raise ValueError(f"{self.clip.name}: timestamp {timestamp_s} is not finite")
            if self._t0_s is None:
                self._t0_s = ts - self._next_in / self.clip.fps
            i = round((ts - self._t0_s) * self.clip.fps)
            at = f" (t = {ts:.4f} s)"
        elif index is not None:
            i = operator.index(index)
        else:
            i = self._next_in
        self._check_span(i, at)
        if i <= self._last_in:
            what = ("was already pushed (a duplicate)" if i == self._last_in
                    else f"is earlier than frame {self._last_in}, pushed before")  # fmt: skip
            raise ValueError(f"{self.clip.name}: frame {i}{at} {what}: refused")
        if self._last_in < 1 and i != self._last_in + 1:
            raise ValueError(f"{self.clip.name}: frame {i}{at}: a stream starts with frames 0 and "
                             f"1 (its calibration); frame {self._last_in + 1} is missing")
        return i

    def _check_span(self, i: int, at: str) -> None:
        """Refuse an index that makes the stream longer than the input limits allow (a clock
        jump of 10,000 s asked to hold a million frames)."""
        lim = self._limits
        try:
            lim.check("max_duration_s", (i + 1) / self.clip.fps,
                      f"frame {i}{at}: a stream of", " s")  # fmt: skip
            lim.check("max_frames", i + 1, f"frame {i}{at}: a stream of", " frames")
        except LimitExceeded as e:
            gap = i - self._last_in - 1
            raise ValueError(f"{self.clip.name}: {e}; {gap} frames after frame {self._last_in}"
                             " (a clock jump?): refused") from None  # fmt: skip

    def _refused(self, i: int) -> None:
        """Frame ``i``'s values were refused: it still takes its number (the next frame pushed
        without an index is ``i + 1``), except frames 0 and 1, which a stream must have."""
        if i > 1:
            self._next_in = i + 1

    def _take(self, frame: SensorFrame, i: int) -> None:
        """Frame ``i`` was taken: keep a copy of its sensors (to interpolate a later gap)."""
        ins = None if frame.insole is None else np.array(frame.insole, np.float64).reshape(-1)
        self._prev = (np.array(frame.acc, dtype=np.float64),
                      np.array(frame.ori, dtype=np.float64), ins)  # fmt: skip
        self._last_in, self._next_in = i, i + 1

    def _check(self, frame: SensorFrame, i: int) -> None:
        """The checks of :meth:`FeatureStream.push`, naming the stream's frame index."""
        sensor_frame_arrays(frame, self._cfg, self.clip.name, i)

    def _push_slow(self, frame: SensorFrame, i: int) -> StreamFrame | None:
        """A frame after missing ones, or after a gap's restart."""
        try:
            self._check(frame, i)
        except ValueError:
            self._refused(i)
            raise
        first, last = self._last_in + 1, i - 1
        n = last - first + 1
        if 0 < n <= self.max_gap_frames:
            acc, ori, ins = self._prev
            d_acc = np.asarray(frame.acc, np.float64) - acc
            d_ins = None if ins is None else np.asarray(frame.insole, np.float64).reshape(-1) - ins
            q0, q1 = matrix_to_quat(ori), matrix_to_quat(np.asarray(frame.ori, np.float64))
            for k in range(1, n + 1):
                f = k / (n + 1)
                self._feed(SensorFrame(acc + f * d_acc, quat_to_matrix(quat_slerp(q0, q1, f)),
                                       None if ins is None else ins + f * d_ins))
                self._last_in = first + k - 1
            self.events.append(StreamEvent("filled", first, last, (
                f"frames {first}..{last} missing: sensors interpolated and simulated")))
        elif n > 0:
            self._gap(first, last)
        out = self._feed(frame)
        self._take(frame, i)
        return out

    def _feed(self, frame: SensorFrame) -> StreamFrame | None:
        row = self._features.push(frame)
        return None if row is None else self._next(row)

    def _gap(self, first: int, last: int) -> None:
        """Frames ``first..last`` are missing, too many to fill: finish the frames before, hold
        the last pose over the gap and restart the pipeline after it."""
        self._flush()
        p = self.player
        self.clip.append_held(last + 1 - self.clip.n_frames)  # the estimate held, standing still
        tr, k = p.trace, p.last
        tr.ensure(last)
        tr.pos[first : last + 1], tr.rot[first : last + 1] = tr.pos[k], tr.rot[k]
        tr.grf[first : last + 1] = tr.cop[first : last + 1] = tr.torques[first : last + 1] = np.nan
        tr.contacts[first : last + 1] = False
        p.t = p.last = last
        old = self._features
        self._features = FeatureStream(old.cfg, old.fps, None, old.name)
        self._features._offset = old._offset  # the sensor-to-segment alignment of frame 0
        self._base = self._resume = last + 1
        self.events.append(StreamEvent("gap", first, last, (
            f"frames {first}..{last} missing ({last - first + 1}, more than max_gap_frames = "
            f"{self.max_gap_frames}): not simulated, the last pose held; the humanoid restarts "
            f"at frame {last + 1} from the kinematic estimate")))  # fmt: skip

    def _flush(self) -> list[StreamFrame]:
        """Simulate to the newest frame taken (as :meth:`finish` does)."""
        row = self._features.finish()
        out = [self._next(row)] if row is not None else []
        player = self.player
        if self._resume is not None and self.clip.n_frames - 1 >= self._resume:
            player.refresh(self._resume)  # (the estimate grew over the gap: observe it)
            self._place()
            out.append(self._frame_out())
        while not player.done:
            player.advance()
            out.append(self._frame_out())
        return [f for f in out if f is not None]

    def finish(self) -> list[StreamFrame]:
        """End of the recording: the remaining simulated frames (the last two).

        Raises:
            ValueError: Fewer than two frames were pushed (a reconstruction needs two).
        """
        if self._finished:
            return []
        self._finished = True
        t0 = time.perf_counter()
        try:
            if self._last_in < 1:
                raise ValueError(f"{self.clip.name}: a stream needs at least 2 frames, got "
                                 f"{self._last_in + 1}")  # fmt: skip
            return self._flush()
        finally:
            self._busy_s += time.perf_counter() - t0

    def _next(self, row: np.ndarray) -> StreamFrame | None:
        """Estimate the frame of ``row``; add it to the clip; play one control step."""
        o = {k: v.astype(np.float64) for k, v in self._kin.step(row).items()}
        joint_pos, global_rot, vel = decode_outputs(o, 1, self._offsets)
        i = self.clip.append(joint_pos[0], global_rot[0], vel[0], row)
        self._est = (joint_pos[0], global_rot[0], row)
        if i == 1:  # the first two estimates are in: the humanoid starts at the calibration
            head = self._head
            self.player = self._pipeline.player(head.body, head.objects)
            self.player.start(self.clip, self._start, head.name, head.fps,
                              frames_hint=self._capacity)  # fmt: skip
            return self._frame_out()
        if self._resume is not None:  # after a gap: start when two estimates are in again
            if i <= self._resume:
                return None
            self.player.refresh(i - 1)
            self._place()
            return self._frame_out()
        if i < 1 or self.player.done:
            return None
        # frame i - 1's derivatives turned central, frame i is new: re-observe, then step
        p = self.player
        p.refresh(i - 1)
        p.advance()
        if len(p.blowup_frames) > self._n_blowups:
            self._n_blowups = len(p.blowup_frames)
            s, t = p.falls[-1]
            self.events.append(StreamEvent("blowup", s, t, (
                f"simulation blow-up at frame {t}: recovered, frames {s}..{t} replaced")))
        return self._frame_out()

    def _place(self) -> None:
        """Put the humanoid at the frame a gap's restart starts at."""
        self.player.resume(self._resume)
        self._resume = None

    def _frame_out(self) -> StreamFrame | None:
        p = self.player
        t = p.t
        if t > p.last:  # a blow-up without recovery: the frame does not exist
            return None
        return self.frame(t)

    def frame(self, t: int) -> StreamFrame:
        """Simulated frame ``t`` as it stands now (a later fall recovery may replace it).

        Raises:
            IndexError: Frame ``t`` is not simulated yet.
        """
        p = self.player
        if p is None or not 0 <= t <= p.last:
            raise IndexError(f"{self.clip.name}: frame {t} is not simulated yet")
        tr = p.trace
        fall = p.falls[-1] if p.falls and p.falls[-1][1] == t else None
        blowup = fall is not None and bool(p.blowup_frames) and p.blowup_frames[-1] == t
        return StreamFrame(t, tr.pos[t].copy(), tr.rot[t].copy(), tr.grf[t].copy(),
                           tr.cop[t].copy(), tr.torques[t].copy(), tr.contacts[t].copy(),
                           fall, blowup)  # fmt: skip

    # ------------------------------------------------------------------ results
    @property
    def frames_out(self) -> int:
        """Simulated frames handed out so far."""
        return 0 if self.player is None else self.player.t + 1

    def reconstruction(self) -> Reconstruction:
        """Every frame so far as the offline path returns it (fall replacements included);
        ``ms_per_frame`` is the mean computation time per pushed frame."""
        if self.player is None:
            raise ValueError(f"{self.clip.name}: no frame simulated yet")
        n = max(self._last_in + 1, 1)
        recon = self.player.reconstruction(1e3 * self._busy_s / n)
        for kind in ("filled", "gap"):
            recon.notes[f"stream_{kind}"] = [[e.first, e.last] for e in self.events
                                             if e.kind == kind]  # fmt: skip
        return recon

    def close(self) -> None:
        """Nothing to release (kept for callers that close their streams)."""
