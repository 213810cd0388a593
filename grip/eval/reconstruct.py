"""GRIP's offline reconstruction (``grip reconstruct``): a front end of :mod:`grip.pipeline` for
PRISM-format recordings.

Per recording: KinematicsNet runs once over the whole sequence (batched over recordings); the
humanoid starts from the recording's calibration pose (its first two frames) and the policy
follows the estimate in MuJoCo with GRIP's fall recovery (:mod:`grip.pipeline` describes it).
Every frame records the simulated joints, the ground reaction force and centre of pressure of
each foot (MuJoCo's contact forces), the actuator torques and the foot contact states.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from grip.kinematics.features import sensor_stream
from grip.pipeline import GripPipeline, PaceKeeper, RecoveryConfig


class GripReconstructor:
    """KinematicsNet + policy + fall recovery over PRISM-format recordings.

    Args:
        runner: A policy controller (:func:`policies.controller.load_controller`: a runner or
            an ensemble; its env settings and sensor features must match the estimator's).
        estimator: A :class:`grip.kinematics.inference.KinematicsEstimator`.
        recovery: Fall detection and recovery settings.
        pace: The pace keeper (:class:`grip.player.PaceKeeper`; default: its defaults, gain 1).
    """

    def __init__(self, runner, estimator, recovery: RecoveryConfig | None = None,
                 pace: PaceKeeper | None = None) -> None:  # fmt: skip
        self.runner = runner
        self.estimator = estimator
        self.recovery = recovery = recovery or RecoveryConfig()
        self.pace = pace = pace or PaceKeeper()
        self.pipeline = GripPipeline(runner, estimator, recovery, pace)

    @classmethod
    def from_files(cls, policy, kin, recovery: RecoveryConfig | None = None,
                   pace: PaceKeeper | None = None):  # fmt: skip
        """Load a policy file (``grip policy export`` or ``grip policy combine``) and a
        KinematicsNet checkpoint."""
        from grip.kinematics.inference import KinematicsEstimator
        from policies.controller import load_controller

        return cls(load_controller(policy), KinematicsEstimator.from_checkpoint(kin), recovery,
                   pace)  # fmt: skip

    def stream(self, calibration):
        """A :class:`grip.eval.stream.GripStream` (one frame in, one frame out) with these
        models, starting from ``calibration``: a recording's first frames (or a
        :class:`grip.kinematics.features.SensorStream` of them)."""
        from grip.eval.stream import GripStream

        return GripStream(self.runner, self.estimator, calibration, self.recovery, pace=self.pace)

    def reconstruct(
        self, recs: Sequence, progress: Callable[[int], object] | None = None, batch: int = 16,
        play_batch: int = 1, threads: int = 0, errors: bool = False, init: str = "truth",
    ) -> list:  # fmt: skip
        """One :class:`~grip.core.reconstruction.Reconstruction` per recording, in order (only
        their sensors and calibration frames are read).

        Args:
            recs: The recordings.
            progress: Called with 1 after each recording.
            batch: Recordings per KinematicsNet forward pass (1: the numbers of each alone).
            play_batch: Recordings played side by side (:meth:`grip.pipeline.GripPipeline.
                play_many`; 1: one after another).
            threads: Threads stepping a batch's humanoids (0: the usable cores).
            errors: Return the exception a recording raised (reading its sensors included) in
                its place, the others going on; False: raise it.
            init: Start from the first frame's ground truth (``"truth"``, where the recording
                has it) or the standing pose at the sensors' heading (``"standing"``;
                :func:`grip.kinematics.features.recording_calibration`).
        """
        cfg = self.estimator.cfg.features
        if not errors:
            streams = [sensor_stream(r, cfg, init) for r in recs]
            return self.pipeline.reconstruct(streams, batch, progress, play_batch, threads)
        out: list = [None] * len(recs)
        ok: list[int] = []
        streams = []
        for i, r in enumerate(recs):
            try:
                streams.append(sensor_stream(r, cfg, init))
                ok.append(i)
            except Exception as e:
                out[i] = e
        got = self.pipeline.reconstruct(streams, batch, progress, play_batch, threads, True)
        for i, recon in zip(ok, got, strict=True):
            out[i] = recon
        return out
