"""The network inputs one frame at a time (numpy only): :class:`FeatureStream` gives the rows of
:func:`grip.kinematics.features.input_features` with the same values, from
:class:`grip.kinematics.features.SensorFrame` as a live system delivers them.
"""

from __future__ import annotations

import numpy as np

from grip.core.rotations import angular_velocity_at
from grip.kinematics.features import FeatureConfig, SensorFrame, calibration_orientations


def sensor_frame_arrays(
    frame: SensorFrame, cfg: FeatureConfig, name: str, index: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """A frame's sensors as float64 arrays, checked: ``acc (S, 3)``, ``ori (S, 3, 3)`` and the
    ``(10,)`` insole values (``None`` when ``cfg`` reads no insoles).

    Raises:
        ValueError: A wrong shape, a missing insole or a non-finite value, naming the recording
            ``name`` and frame ``index``.
    """
    s = len(cfg.sites)
    acc = np.asarray(frame.acc, dtype=np.float64)
    ori = np.asarray(frame.ori, dtype=np.float64)
    where = f"{name}: frame {index}"
    if acc.shape != (s, 3) or ori.shape != (s, 3, 3):
        raise ValueError(f"{where}: expected acc ({s}, 3) and ori ({s}, 3, 3) for sites "
                         f"{cfg.sites}, got {acc.shape} and {ori.shape}")  # fmt: skip
    ok = np.isfinite(acc).all() and np.isfinite(ori).all()
    ins = None
    if cfg.insoles:
        if frame.insole is None:
            raise ValueError(f"{where}: the features need the 10 insole values, got None")
        ins = np.asarray(frame.insole, dtype=np.float64).reshape(-1)
        if ins.shape != (10,):
            raise ValueError(f"{where}: insole must have 10 values, got {ins.shape}")
        ok = ok and np.isfinite(ins).all()
    if not ok:
        raise ValueError(f"{name}: non-finite sensor values at frame {index}")
    return acc, ori, ins


class FeatureStream:
    """:func:`grip.kinematics.features.input_features` one frame at a time, with the same values.

    The angular velocity of frame ``t`` is the central difference of the orientations of
    ``t - 1`` and ``t + 1`` (as in training), so the row of frame ``t`` comes out when frame
    ``t + 1`` goes in: :meth:`push` returns the previous frame's row (``None`` for the first
    frame) and :meth:`finish` the last one (one-sided difference, as offline).

    Args:
        cfg: The feature settings of the network that reads the rows.
        fps: Frame rate, Hz.
        calibration: :func:`calibration_orientations` of the recording (``None``: no
            re-alignment).
        name: Recording name for messages.
    """

    def __init__(self, cfg: FeatureConfig, fps: float, calibration: np.ndarray | None = None,
                 name: str = "<stream>") -> None:  # fmt: skip
        self.cfg, self.fps, self.name = cfg, float(fps), name
        self._calib = calibration
        self._offset: np.ndarray | None = None  # (S, 3, 3) sensor-to-segment offsets
        self._rot: list[np.ndarray] = []  # aligned orientations of the last (up to) 3 frames
        self._rest: list[np.ndarray] = []  # [acc / scale, insole] of the same frames
        self._n = 0

    @classmethod
    def for_recording(cls, rec, cfg: FeatureConfig = FeatureConfig()) -> FeatureStream:
        """A stream calibrated on a recording's first frame (its ``imu_gt``)."""
        return cls(cfg, float(rec.fps), calibration_orientations(rec, cfg), str(rec.name))

    @property
    def frames_in(self) -> int:
        """Frames pushed so far."""
        return self._n

    def push(self, frame: SensorFrame) -> np.ndarray | None:
        """Take frame ``t``; return the ``(F,)`` float32 row of frame ``t - 1`` (or ``None``).

        Raises:
            ValueError: A wrong shape or a non-finite value (naming the frame).
        """
        cfg, s = self.cfg, len(self.cfg.sites)
        acc, ori, ins = sensor_frame_arrays(frame, cfg, self.name, self._n)
        rest = (acc / cfg.acc_scale).reshape(-1)
        if ins is not None:
            rest = np.concatenate([rest, ins])
        if self._offset is None:
            self._offset = np.broadcast_to(np.eye(3), (s, 3, 3)).copy()
            if self._calib is not None:
                for i in range(s):
                    if np.isfinite(self._calib[i]).all():
                        self._offset[i] = ori[i].T @ self._calib[i]
        self._rot.append(ori @ self._offset)
        self._rest.append(rest)
        self._n += 1
        if len(self._rot) > 3:
            del self._rot[0], self._rest[0]
        if self._n < 2:
            return None
        # the row of the previous frame: central difference inside, one-sided at the start
        return self._row(len(self._rot) - 2)

    def finish(self) -> np.ndarray | None:
        """The row of the last frame pushed (``None`` if nothing was pushed)."""
        if self._n == 0:
            return None
        return self._row(len(self._rot) - 1)

    def _row(self, i: int) -> np.ndarray:
        """Row of buffered frame ``i`` with the frames around it (as
        :func:`grip.core.rotations.angular_velocity` does for a whole sequence)."""
        gyr = angular_velocity_at(np.stack(self._rot), i, self.fps)
        s = len(self.cfg.sites)
        rest = self._rest[i]
        imu = np.concatenate([rest[: 3 * s].reshape(s, 3), gyr, self._rot[i].reshape(s, 9)],
                             axis=-1).reshape(-1)  # fmt: skip
        return np.concatenate([imu, rest[3 * s :]]).astype(np.float32)
