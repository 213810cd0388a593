"""Configuration of sensor synthesis: IMUs, insoles and the sensor noise model.

Frozen dataclasses with documented fields; units are in the field names. Build variants with
:func:`dataclasses.replace`, never by mutating a shared default. :func:`config_to_json` gives the
exact configuration a recording was synthesised with (stored in the recording's ``extras``).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from typing import Literal

from grip.core.checks import check, check_fields

__all__ = [
    "ImuSynthConfig",
    "InsoleSynthConfig",
    "NoiseConfig",
    "SynthConfig",
    "config_to_json",
]


@dataclass(frozen=True)
class ImuSynthConfig:
    """How IMU signals are derived from a motion.

    Attributes:
        acc_smoothing_frames: Frame spacing ``n`` of the smoothed second difference
            ``a(t) = (x(t-n) + x(t+n) - 2 x(t)) / (n dt)^2`` (TransPose); ``"auto"`` derives it
            from the frame rate as ``round(acc_smoothing_s * fps)`` (7 at 100 Hz, 4 at 60 Hz).
        acc_smoothing_s: Time spacing used by ``"auto"``, s (TransPose's n = 4 at 60 Hz).
        filt_cutoff_hz: Cut-off of the causal Butterworth low-pass that turns ``acc_world_raw``
            into ``acc_world_filt``, Hz (at or above Nyquist: no filtering).
        filt_order: Order of that Butterworth filter.
        mount_offsets_rotvec_rad: Optional fixed sensor-to-segment mounting rotations, as
            ``((part, (rx, ry, rz)), ...)`` axis-angle vectors in the segment frame, rad; the
            sensor orientation is ``R_segment @ R_offset``. Parts not listed: identity.
    """

    acc_smoothing_frames: int | Literal["auto"] = "auto"
    acc_smoothing_s: float = 0.0667
    filt_cutoff_hz: float = 6.0
    filt_order: int = 2
    mount_offsets_rotvec_rad: tuple[tuple[str, tuple[float, float, float]], ...] = ()

    def __post_init__(self) -> None:
        n = self.acc_smoothing_frames
        check(
            self,
            (n == "auto" or (not isinstance(n, bool) and isinstance(n, int) and n >= 1),
             f"acc_smoothing_frames must be a positive int or 'auto', got {n!r}"),
            (self.acc_smoothing_s > 0, f"acc_smoothing_s must be > 0, got {self.acc_smoothing_s}"),
            (self.filt_cutoff_hz > 0 and self.filt_order >= 1,
             "filt_cutoff_hz must be > 0 and filt_order >= 1"),
        )  # fmt: skip


@dataclass(frozen=True)
class InsoleSynthConfig:
    """How insole readings are derived from the whole-body motion (Newton-Euler + ZMP).

    Attributes:
        smoothing_window_s: Savitzky-Golay window used to differentiate segment COM positions
            and the spin angular momentum (and foot-cell positions for their speed), s; rounded
            to an odd number of frames (11 at 100 Hz, about 10 Hz cut-off). 0.2 s (about 5 Hz,
            the usual low-pass for accelerations derived from motion capture) takes out the
            jitter that moves the ZMP by decimetres and lowers the share of frames whose ZMP
            lies off the insoles by 4-13 points per source (docs/insoles_zmp.md); it becomes
            the default with the next rebuild of the corpus and retraining of KinematicsNet,
            whose shipped weights read insoles synthesised with 0.1 s.
        smoothing_polyorder: Polynomial order of that Savitzky-Golay filter.
        contact_height_full_m: A cell at or below this height above the contact level (the
            floor, see ``contact_float_tolerance_m``) may carry full load, m.
        contact_height_zero_m: A cell at or above this height carries none, m (smoothstep
            ramp in between).
        contact_float_tolerance_m: Cell heights are measured from the lowest slow cell of the
            frame when it hovers above the floor by at most this, m, so that motions whose feet
            float a little during stance (retargeting error) keep their support; 0 measures
            from the floor only.
        contact_speed_full_m_s: A cell moving horizontally at or below this speed may carry
            full load, m/s.
        contact_speed_zero_m_s: A cell at or above this horizontal speed carries none, m/s.
        zmp_penalty_per_m2: Weight of the squared error between the cells' force centroid and
            the zero-moment point, 1/m^2, relative to the pressure-spread term (normalised so
            that spreading the force evenly over the available cells costs 1). Large: the
            centroid equals the ZMP (within ~0.1 mm) whenever the ZMP lies in the support polygon,
            else it is the nearest reachable point.
        cell_prior: ``(16,)`` relative compliance of each cell (multiplies its area in the
            spread term); 1 everywhere by default.
        contact_threshold_n: PRISM contact rule: ``front`` when cells 8-15 sum above this,
            ``back`` when cells 0-3 do, N.
        cop_min_force_n: Below this foot force the CoP is reported as the insole origin
            (insole frame ``(0, 0)``), N.
        max_newton_iters: Iteration cap of the vectorised active-set solver; frames that do not
            converge within it are solved again with ``scipy.optimize.nnls``.
    """

    smoothing_window_s: float = 0.1
    smoothing_polyorder: int = 2
    contact_height_full_m: float = 0.01
    contact_height_zero_m: float = 0.03
    contact_float_tolerance_m: float = 0.06
    contact_speed_full_m_s: float = 0.4
    contact_speed_zero_m_s: float = 1.2
    zmp_penalty_per_m2: float = 1e8
    cell_prior: tuple[float, ...] = (1.0,) * 16
    contact_threshold_n: float = 20.0
    cop_min_force_n: float = 1.0
    max_newton_iters: int = 50

    def __post_init__(self) -> None:
        check(
            self,
            (self.smoothing_window_s > 0 and self.smoothing_polyorder >= 2,
             "smoothing_window_s must be > 0 and smoothing_polyorder >= 2"),
            (0 <= self.contact_height_full_m < self.contact_height_zero_m,
             "need 0 <= contact_height_full_m < contact_height_zero_m"),
            (self.contact_float_tolerance_m >= 0, "contact_float_tolerance_m must be >= 0"),
            (0 <= self.contact_speed_full_m_s < self.contact_speed_zero_m_s,
             "need 0 <= contact_speed_full_m_s < contact_speed_zero_m_s"),
            (len(self.cell_prior) == 16 and min(self.cell_prior, default=0) > 0,
             "cell_prior must hold 16 positive values"),
            (self.zmp_penalty_per_m2 > 0, "zmp_penalty_per_m2 must be > 0"),
        )  # fmt: skip


@dataclass(frozen=True)
class NoiseConfig:
    """Sensor noise model; :meth:`off` gives exact ground truth.

    IMU model per sensor: the accelerometer reads the specific force in the sensor frame plus a
    constant bias and white noise; the gyroscope reads the body-frame angular velocity plus a
    constant bias and white noise; the orientation estimate carries a slow random-walk drift
    (mostly yaw) and small white jitter, and the world-frame free acceleration is computed with
    that estimate (so tilt drift leaks gravity, as on a real device). Insole model per cell:
    ``max(0, gain_foot * f * (1 + rel * n1) + area * (bias_cell + abs * n2))``.

    Attributes:
        acc_white_m_s2: Accelerometer white-noise standard deviation per sample and axis, m/s^2.
        acc_bias_m_s2: Standard deviation of the constant accelerometer bias per axis, m/s^2.
        gyr_white_rad_s: Gyroscope white-noise standard deviation per sample and axis, rad/s.
        gyr_bias_rad_s: Standard deviation of the constant gyroscope bias per axis, rad/s.
        ori_drift_yaw_deg_per_sqrt_s: Random-walk intensity of the orientation drift about the
            world vertical, deg/sqrt(s).
        ori_drift_tilt_deg_per_sqrt_s: Random-walk intensity about the horizontal axes,
            deg/sqrt(s).
        ori_white_deg: White orientation jitter per sample and axis, deg.
        imu_drop_prob: Probability that a sensor's sample is dropped (the logger repeats the
            previous sample), per frame and sensor. Frame 0 is never dropped.
        insole_rel_noise: Relative white noise of each cell force (standard deviation, fraction).
        insole_abs_noise_n_per_cm2: Absolute white noise of each cell pressure, N/cm^2.
        insole_bias_n_per_cm2: Standard deviation of a constant per-cell pressure offset, N/cm^2.
        insole_gain_std: Standard deviation of a constant per-foot gain error (fraction).
        insole_drop_prob: Probability that an insole sample is dropped, per frame and foot.
    """

    acc_white_m_s2: float = 0.05
    acc_bias_m_s2: float = 0.05
    gyr_white_rad_s: float = 0.01
    gyr_bias_rad_s: float = 0.005
    ori_drift_yaw_deg_per_sqrt_s: float = 0.3
    ori_drift_tilt_deg_per_sqrt_s: float = 0.03
    ori_white_deg: float = 0.2
    imu_drop_prob: float = 0.002
    insole_rel_noise: float = 0.03
    insole_abs_noise_n_per_cm2: float = 0.05
    insole_bias_n_per_cm2: float = 0.03
    insole_gain_std: float = 0.03
    insole_drop_prob: float = 0.002

    def __post_init__(self) -> None:
        check_fields(self, lambda v: v >= 0, "must be >= 0")
        check(self, (self.imu_drop_prob < 1 and self.insole_drop_prob < 1,
                     "drop probabilities must be < 1"))  # fmt: skip

    @classmethod
    def off(cls) -> NoiseConfig:
        """All noise terms zero: the readings equal the clean synthesised signals exactly."""
        return cls(**{f.name: 0.0 for f in dataclasses.fields(cls)})

    @property
    def is_off(self) -> bool:
        """True when every noise term is zero."""
        return all(getattr(self, f.name) == 0 for f in dataclasses.fields(self))


@dataclass(frozen=True)
class SynthConfig:
    """Everything that controls the synthesis of one recording from a motion.

    Attributes:
        imu: IMU synthesis.
        insole: Insole synthesis.
        noise: Sensor noise (applied when the caller asks for noisy readings).
    """

    imu: ImuSynthConfig = field(default_factory=ImuSynthConfig)
    insole: InsoleSynthConfig = field(default_factory=InsoleSynthConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)


def config_to_json(cfg: SynthConfig) -> str:
    """The configuration as a JSON string (sorted keys), for provenance."""
    return json.dumps(dataclasses.asdict(cfg), sort_keys=True)
