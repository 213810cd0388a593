"""Sensor-to-segment calibration from a still pose (GRIP supplement Sec. 7.1, "IMU
Calibration"), without motion capture.

GRIP writes a segment's world orientation as ``R_g^j = R_g^r R_r^s R_s^j``: the device's
reference frame ``r`` in the world (``R_g^r``), the sensor in the reference (what the device
reports, ``R_r^s``) and the segment in the sensor (a constant mount, ``R_s^j``). PRISM found
``R_g^r`` by laying each sensor on the floor aligned with the world and ``R_s^j`` from the T-pose
with the motion capture's segment orientations. Here the subject holds the body model's rest
T-pose, facing what becomes world +y, so every segment's world orientation there is
:data:`grip.core.body.CANONICAL_TO_WORLD` (as :func:`grip.core.mjcf.standing_qpos` stands), and:

1. the device's reference frame is taken as gravity-aligned up to a small tilt, which the mean
   specific force over the still window measures (``R_r^s f`` should point up) and removes;
2. its heading about the vertical and the sensor's mount are then one unknown angle apart: the
   pose fixes ``R_g^r R_r^s R_s^j`` only. The angle is chosen so that the mount comes closest to
   the sensor's nominal mount on its segment (:data:`DEFAULT_MOUNTS`: e.g. a watch's x along
   the forearm to the hand, z out of the back of the wrist). The mount's tilt is measured (by
   gravity); only its heading about the vertical is assumed, so a watch that sits rolled on the
   wrist or an insole tilted by the shoe's heel drop is calibrated exactly, while a sensor
   turned about the vertical by ``d`` deg in the T-pose against its nominal mount is off by
   ``d`` about that axis.

The result, :class:`SiteCalibration`, maps the device's readings to the segment:
``ori_world(t) = W R(t) S^T`` with ``W`` reference -> world and ``S`` sensor -> segment, and the
world-frame specific force is ``W R(t) f(t)``.

This module imports numpy and :mod:`grip.core` only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grip.core.body import CANONICAL_TO_WORLD
from grip.core.rotations import geodesic_angle, orthonormalize, rot_z, rotation_between
from prism_tools.streams import IMU_PARTS

__all__ = [
    "DEFAULT_MOUNTS",
    "DIRECTIONS",
    "SiteCalibration",
    "calibrate_site",
    "mean_rotation",
    "mount_matrix",
    "parse_mount",
    "still_runs",
]

DIRECTIONS: dict[str, tuple[float, float, float]] = {
    "forward": (0.0, 0.0, 1.0), "back": (0.0, 0.0, -1.0), "left": (1.0, 0.0, 0.0),
    "right": (-1.0, 0.0, 0.0), "up": (0.0, 1.0, 0.0), "down": (0.0, -1.0, 0.0),
}  # fmt: skip
"""Directions of a segment in the T-pose, in the body model's canonical segment frame (x the
subject's left, y up, z forward)."""

DEFAULT_MOUNTS: dict[str, tuple[str, str, str]] = {
    "L_Foot": ("forward", "left", "up"),
    "R_Foot": ("forward", "left", "up"),
    "L_Wrist": ("left", "back", "up"),
    "R_Wrist": ("right", "forward", "up"),
    "Head": ("forward", "left", "up"),
    "Pelvis": ("up", "left", "back"),
    "L_Knee": ("down", "left", "forward"),
    "R_Knee": ("down", "left", "forward"),
}
"""Nominal mount of each site: where the sensor's x, y and z axes point in the T-pose. Feet: x to
the toes, z up (an insole, or a sensor on the instep); wrists: x along the forearm to the hand,
z out of the back of the wrist (palms down); head: x forward, z up; pelvis: on the sacrum, z
out of the back, x up; knees: on the front of the shank, z forward, x down."""


def mount_matrix(axes: tuple[str, str, str], where: str = "mount") -> np.ndarray:
    """``(3, 3)`` sensor -> segment rotation whose columns are the sensor's axes.

    Raises:
        ValueError: An unknown direction, or axes that are not a right-handed frame (naming
            ``where``).
    """
    try:
        m = np.array([DIRECTIONS[a] for a in axes]).T
    except KeyError as e:
        raise ValueError(f"{where}: unknown direction {e.args[0]!r} (use {sorted(DIRECTIONS)})"
                         ) from None  # fmt: skip
    if len(axes) != 3 or not np.allclose(m.T @ m, np.eye(3)) or np.linalg.det(m) < 0:
        raise ValueError(f"{where}: axes {','.join(axes)} are not a right-handed frame "
                         "(x, y, z must point three different ways with z = x cross y)")
    return m


def parse_mount(text: str) -> tuple[str, tuple[str, str, str]]:
    """``"L_Wrist=left,back,up"`` -> ``("L_Wrist", ("left", "back", "up"))``, checked.

    Raises:
        ValueError: A bad part, direction or frame.
    """
    part, sep, rest = text.partition("=")
    part = part.strip()
    if not sep or part not in IMU_PARTS:
        raise ValueError(f"mount {text!r}: expected PART=X,Y,Z with PART one of {IMU_PARTS}")
    axes = tuple(a.strip().lower() for a in rest.split(","))
    if len(axes) != 3:
        raise ValueError(f"mount {text!r}: give three directions X,Y,Z")
    mount_matrix(axes, f"mount {text!r}")  # type: ignore[arg-type]
    return part, axes  # type: ignore[return-value]


def mean_rotation(rot: np.ndarray) -> np.ndarray:
    """Chordal mean of ``(K, 3, 3)`` rotations (the rotation nearest their average)."""
    return orthonormalize(np.asarray(rot, dtype=np.float64).mean(axis=0))


def still_runs(still: np.ndarray) -> list[tuple[int, int]]:
    """``[start, stop)`` frame ranges of the runs of ``True`` in ``(T,)`` bool, in order."""
    edges = np.diff(np.concatenate([[0], np.asarray(still, dtype=np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(),
                    strict=True))  # fmt: skip


@dataclass(frozen=True)
class SiteCalibration:
    """One sensor's calibration.

    Attributes:
        ref_to_world: ``(3, 3)`` ``W``: the device's reference frame -> world.
        sensor_to_segment: ``(3, 3)`` ``S``: sensor frame -> segment frame.
        ref_tilt_deg: Tilt of the device's reference frame from gravity-aligned, deg (0 when
            the accelerations carry no gravity to measure it).
        heading_deg: Heading of the reference frame in the world, deg about world z.
        mount_error_deg: Angle between the calibrated mount and the nominal one, deg (the tilt
            part of a mount that differs from the nominal).
    """

    ref_to_world: np.ndarray
    sensor_to_segment: np.ndarray
    ref_tilt_deg: float
    heading_deg: float
    mount_error_deg: float

    def orientation(self, rot_ref: np.ndarray) -> np.ndarray:
        """``(T, 3, 3)`` segment -> world orientations from ``(T, 3, 3)`` sensor -> reference."""
        return self.ref_to_world @ rot_ref @ self.sensor_to_segment.T

    def to_world(self, v_ref: np.ndarray) -> np.ndarray:
        """``(T, 3)`` reference-frame vectors in the world frame."""
        return v_ref @ self.ref_to_world.T


def calibrate_site(rot_ref: np.ndarray, mount: np.ndarray, up_ref: np.ndarray | None = None,
                   segment_world: np.ndarray = CANONICAL_TO_WORLD) -> SiteCalibration:  # fmt: skip
    """Calibrates one sensor from its still window (module docstring).

    Args:
        rot_ref: ``(K, 3, 3)`` sensor -> reference rotations over the still window.
        mount: ``(3, 3)`` nominal sensor -> segment rotation (:func:`mount_matrix`).
        up_ref: ``(3,)`` mean specific force over the window in the reference frame (m/s^2), or
            ``None`` when the readings carry no gravity (the reference is then taken as level).
        segment_world: ``(3, 3)`` the segment's world orientation in the calibration pose.

    Returns:
        The calibration; ``orientation(rot_ref)`` equals ``segment_world`` at the window's mean.
    """
    r_c = mean_rotation(rot_ref)
    tilt = np.eye(3) if up_ref is None else rotation_between(np.asarray(up_ref), np.eye(3)[2])
    c = tilt @ r_c @ mount.T @ segment_world.T
    alpha = float(np.arctan2(c[0, 1] - c[1, 0], c[0, 0] + c[1, 1]))
    w = rot_z(np.array(alpha)) @ tilt
    s = segment_world.T @ w @ r_c
    return SiteCalibration(
        ref_to_world=w,
        sensor_to_segment=s,
        ref_tilt_deg=float(np.degrees(geodesic_angle(np.eye(3), tilt))),
        heading_deg=float(np.degrees(alpha)),
        mount_error_deg=float(np.degrees(geodesic_angle(mount, s))),
    )
