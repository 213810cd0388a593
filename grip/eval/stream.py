"""Streaming GRIP: one frame of sensors in, one frame of simulated motion out, state carried.

The stream runs the same computation as the offline path (:mod:`grip.eval.reconstruct`), frame
by frame: :class:`grip.kinematics.features.FeatureStream` builds the network inputs,
KinematicsNet steps its LSTMs once per frame, a :class:`grip.core.reference.LiveClip` grows by
the estimate, and :class:`grip.eval.reconstruct.ClipPlayer` advances the policy and MuJoCo one
control step with GRIP's fall recovery.

Latency: two frames (20 ms at 100 Hz) on top of the computation. The angular velocities of the
sensors and of the estimate are central differences (as in training), so frame ``t`` of the
features needs the sensors of ``t + 1``, and the control step to ``t`` needs the estimate of
``t + 1``: pushing frame ``t`` returns the simulated frame ``t - 2``; :meth:`GripStream.finish`
returns the last two.

Falls: a recovery at frame ``t`` replaces frames ``t - N .. t`` with the buffered kinematic
estimate (GRIP Sec. 3.4). A stream has already handed out frames ``t - N .. t - 1``; the frame
of ``t`` carries the event (:attr:`StreamFrame.fall`) and :meth:`GripStream.reconstruction`
returns every frame as the offline path does, replacements included.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from grip.core import skeleton as sk
from grip.core.body import build_body
from grip.core.reconstruction import Reconstruction
from grip.core.reference import LiveClip, ReferenceClip, ReferenceSet
from grip.core.rotations import matrix_to_6d
from grip.eval.reconstruct import ClipPlayer, RecoveryConfig, inference_env
from grip.kinematics.features import FeatureStream, SensorFrame, recording_body
from grip.kinematics.inference import decode_outputs
from grip.kinematics.reference import gt_qpos

LATENCY_FRAMES = 2
"""Frames between a sensor frame going in and its simulated frame coming out."""


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
    """

    frame: int
    joint_pos: np.ndarray
    global_rot: np.ndarray
    grf: np.ndarray
    cop: np.ndarray
    torques: np.ndarray
    contacts: np.ndarray
    fall: tuple[int, int] | None = None


def calibration_clip(calibration, sensor_dim: int) -> ReferenceClip:
    """A :class:`ReferenceClip` of a recording's first two frames of ground truth (one frame:
    the body at rest), the start of a stream. Only its ground truth is read (by
    :class:`grip.core.reference.LiveClip`); its estimate arrays are zeros and identities."""
    n = min(calibration.n_frames, 2)
    q = gt_qpos(calibration.slice_frames(0, n))
    if n == 1:
        q = np.repeat(q, 2, axis=0)
    eye = matrix_to_6d(np.broadcast_to(np.eye(3), (2, sk.N_JOINTS, 3, 3)))
    return ReferenceClip(
        name=str(calibration.name), category=calibration.category or "unknown",
        fps=float(calibration.fps), body=recording_body(calibration), gt_qpos=q,
        est_pos=np.zeros((2, sk.N_JOINTS, 3)), est_rot6d=eye,
        est_vel=np.zeros((2, len(sk.VELOCITY_JOINTS), 3)), sensor=np.zeros((2, sensor_dim)),
    )  # fmt: skip


class GripStream:
    """GRIP on a live sensor stream (see the module docstring).

    Args:
        runner: A :class:`policies.runner.PolicyRunner` or an ensemble of them
            (:class:`policies.ensemble.PolicyEnsemble`).
        estimator: A :class:`grip.kinematics.inference.KinematicsEstimator`.
        calibration: The recording's first frames with ground truth (``smpl_params``,
            ``imu_gt``; a PRISM recording or a slice of one): the calibration pose the humanoid
            and the LSTMs start from, and the sensor-to-segment alignment.
        recovery: Fall detection and recovery settings (default :class:`RecoveryConfig`).
        capacity: Frames allocated at first (the buffers double when a stream runs longer).

    Example::

        stream = GripStream(runner, estimator, rec.slice_frames(0, 2))
        for frame in sensor_frames(rec, estimator.cfg.features):
            out = stream.push(frame)  # StreamFrame of two frames ago, or None
        tail = stream.finish()
    """

    def __init__(self, runner, estimator, calibration, recovery: RecoveryConfig | None = None,
                 capacity: int = 1024) -> None:  # fmt: skip
        cfg = estimator.cfg.features
        recovery = recovery or RecoveryConfig()
        self.runner, self.estimator, self.recovery = runner, estimator, recovery
        self._features = FeatureStream.for_recording(calibration, cfg)
        self._kin = estimator.stream(calibration.slice_frames(0, min(2, calibration.n_frames)))
        self.clip = LiveClip(calibration_clip(calibration, cfg.n_features), cfg.n_features,
                             capacity)  # fmt: skip
        self._sites, self._insoles = tuple(cfg.sites), bool(cfg.insoles)
        self._offsets = build_body(recording_body(calibration)).offsets
        self._capacity = capacity
        self.env = None
        self.player: ClipPlayer | None = None
        self._busy_s = 0.0
        self._finished = False

    # ------------------------------------------------------------------ frames
    def push(self, frame: SensorFrame) -> StreamFrame | None:
        """Take the sensors of frame ``t``; return simulated frame ``t - 2`` (``None`` for the
        first two frames, and after a blow-up that ended the stream without recovery).

        Raises:
            ValueError: A malformed or non-finite frame (named), or a push after :meth:`finish`.
        """
        if self._finished:
            raise ValueError(f"{self.clip.name}: push after finish()")
        t0 = time.perf_counter()
        try:
            row = self._features.push(frame)
            return None if row is None else self._next(row)
        finally:
            self._busy_s += time.perf_counter() - t0

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
            row = self._features.finish()
            if row is None or self._features.frames_in < 2:
                raise ValueError(f"{self.clip.name}: a stream needs at least 2 frames, got "
                                 f"{self._features.frames_in}")  # fmt: skip
            out = [self._next(row)]
            player = self.player
            while not player.done:
                player.advance()
                out.append(self._frame_out())
            return [f for f in out if f is not None]
        finally:
            self._busy_s += time.perf_counter() - t0

    def _next(self, row: np.ndarray) -> StreamFrame | None:
        """Estimate the frame of ``row``; add it to the clip; play one control step."""
        o = {k: v.astype(np.float64) for k, v in self._kin.step(row).items()}
        joint_pos, global_rot, vel = decode_outputs(o, 1, self._offsets)
        i = self.clip.append(joint_pos[0], global_rot[0], vel[0], row)
        if i == 1:  # the first two estimates are in: the humanoid starts at the calibration
            ref = ReferenceSet([self.clip], self._sites, self._insoles, "<stream>")
            self.env = inference_env(self.runner, ref)
            self.player = ClipPlayer(self.env, self.runner, self.recovery)
            self.player.start(0, frames_hint=self._capacity)
            return self._frame_out()
        if i < 1 or self.player.done:
            return None
        # frame i - 1's derivatives turned central, frame i is new: re-observe, then step
        self.player.obs = self.env.refresh_reference(i - 1)
        self.player.advance()
        return self._frame_out()

    def _frame_out(self) -> StreamFrame | None:
        p = self.player
        t = p.t
        if t > p.last:  # a blow-up without recovery: the frame does not exist
            return None
        tr = p.trace
        fall = p.falls[-1] if p.falls and p.falls[-1][1] == t else None
        return StreamFrame(t, tr.pos[t].copy(), tr.rot[t].copy(), tr.grf[t].copy(),
                           tr.cop[t].copy(), tr.torques[t].copy(), tr.contacts[t].copy(),
                           fall)  # fmt: skip

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
        n = max(self._features.frames_in, 1)
        return self.player.reconstruction(1e3 * self._busy_s / n)

    def close(self) -> None:
        if self.env is not None:
            self.env.close()
