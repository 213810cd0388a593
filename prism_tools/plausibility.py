"""Refusal of finite but physically absurd values in a recording, with the unit probably meant
(:func:`check_plausible`).

This module imports numpy and :mod:`grip.core.limits` only.
"""

from __future__ import annotations

import numpy as np

from grip.core.limits import InputLimits, LimitExceeded, active_limits
from prism_tools.errors import RecordingError
from prism_tools.schema import Recording
from prism_tools.streams import GRAVITY

__all__ = ["check_plausible"]


def _magnitude_max(arr: np.ndarray) -> tuple[float, float]:
    """(max, median) of the row norms of a ``(F, k)`` array (0 for an empty one)."""
    if arr.size == 0:
        return 0.0, 0.0
    mag = np.sqrt(np.einsum("fi,fi->f", arr, arr, dtype=np.float64))
    return float(mag.max()), float(np.median(mag))


def _too_big(limits: InputLimits, name: str, value: float, text: str) -> None:
    if value > getattr(limits, name):
        raise RecordingError(str(LimitExceeded(name, value, getattr(limits, name), text)))


def check_plausible(rec: Recording, limits: InputLimits | None = None) -> None:
    """Refuses finite but physically absurd values, saying which unit was probably meant.

    Checked: acceleration magnitudes (``imu.*.acc_*``, ``imu_gt.*.acc_world``): their median
    against ``limits.max_typical_acc_mps2`` (a unit error moves every sample; a glitch of motion
    capture differentiated twice is a spike and passes) and every sample against
    ``max_acc_mps2``; velocities (``imu_gt.*.vel_world``) likewise against
    ``max_typical_vel_mps`` and ``max_vel_mps``;
    insole forces in body weights (``insole.*.force``, ``force_world``, ``combined``) against
    ``max_force_bw``, and positions (``smpl_params.trans``, ``imu_gt.*.pos_world``,
    ``CoP_world``, ``slam.head_traj``: magnitude and span over the take) against
    ``max_position_m``. Insole-frame ``CoP``, cell values and gyroscope rates are not checked:
    PRISM does not document their units.

    Args:
        rec: A structurally valid recording (:func:`validate`), forces in body weights.
        limits: The limits; default :func:`grip.core.limits.active_limits`.

    Raises:
        RecordingError: For example ``"imu.L_Foot.acc_local_raw: acc magnitude 9.81e+03 m/s^2
            (median 9.81e+03; values look like mm/s^2) is above the limit max_acc_mps2=2000
            ..."``.
    """
    limits = limits or active_limits()
    accs = [(f"imu.{p}.{k}", getattr(s, k)) for p, s in rec.imu.items()
            for k in ("acc_world_raw", "acc_world_filt", "acc_local_raw")
            if getattr(s, k) is not None]  # fmt: skip
    accs += [(f"imu_gt.{p}.acc_world", s.acc_world) for p, s in rec.imu_gt.items()]
    vels = [(f"imu_gt.{p}.vel_world", s.vel_world) for p, s in rec.imu_gt.items()]
    for (path, arr), (what, unit, mm) in [*((a, ("acc", "_acc_mps2", "mm/s^2")) for a in accs),
                                          *((v, ("speed", "_vel_mps", "mm/s")) for v in vels)]:
        mx, med = _magnitude_max(arr)
        su = "m/s^2" if what == "acc" else "m/s"
        _too_big(limits, "max_typical" + unit, med, f"{path}: median {what} magnitude "
                 f"{med:.3g} {su} (values look like {mm}) is above")  # fmt: skip
        _too_big(limits, "max" + unit, mx, f"{path}: {what} magnitude {mx:.3g} {su} (median "
                 f"{med:.3g}: corrupt samples?) is above")  # fmt: skip
    forces = [(f"insole.{p}.{k}", getattr(s, k)) for p, s in rec.insole.items()
              for k in ("force", "force_world")]  # fmt: skip
    if rec.insole_combined is not None:
        forces.append(("insole.combined.force_world", rec.insole_combined.force_world))
    weight = rec.subject.weight_kg or 70.0
    for path, arr in forces:
        mx, _ = _magnitude_max(arr)
        if mx > limits.max_force_bw:
            hint = ("values look like newtons, not body weights" if mx < 20 * weight
                    else "grams or Pa?")  # fmt: skip
            _too_big(limits, "max_force_bw", mx, f"{path}: insole force {mx:.3g} body weights "
                     f"(= {mx * weight * GRAVITY:.3g} N for {weight:g} kg; {hint}) is above")
    positions = [] if rec.smpl_params is None else [("smpl_params.trans", rec.smpl_params.trans)]
    positions += [(f"imu_gt.{p}.pos_world", s.pos_world) for p, s in rec.imu_gt.items()]
    positions += [(f"insole.{p}.CoP_world", s.CoP_world) for p, s in rec.insole.items()]
    if rec.insole_combined is not None:
        positions.append(("insole.combined.CoP_world", rec.insole_combined.CoP_world))
    if rec.slam is not None:
        positions.append(("slam.head_traj", rec.slam.head_traj))
    for path, arr in positions:
        if arr.size == 0:
            continue
        span = float(np.ptp(arr, axis=0).max())
        mx, _ = _magnitude_max(arr)
        value = span if span > limits.max_position_m else mx
        if value > limits.max_position_m:
            hint = "millimetres?" if value < 1000 * limits.max_position_m else "corrupt?"
            what = (f"spans {span:.4g} m" if value == span
                    else f"reaches {mx:.4g} m from the origin")  # fmt: skip
            _too_big(limits, "max_position_m", value, f"{path}: {what} ({hint}), which is above")
