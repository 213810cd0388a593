"""The parts of a PRISM-format recording: one frozen dataclass per PRISM sub-dict, their array
layouts and the format's constants.

Conventions: ``F`` is the number of frames (shared by every per-frame array), world frame z-up in
metres with the floor at z = 0, rotation matrices map sensor/segment vectors to the world
(``v_world = R @ v_local``), insole forces are in body weights (1.0 = the subject's weight, about
1.0 in total while standing still).

The dataclasses are frozen (fields cannot be reassigned; use :func:`dataclasses.replace`), but the
numpy arrays they hold are ordinary writable arrays and are not copied on construction. The
recording that holds them is :class:`prism_tools.schema.Recording`.

This module imports numpy only.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

__all__ = [
    "DEFAULT_FPS",
    "EXTRAS_KEY",
    "FEET",
    "GRAVITY",
    "IMU_PARTS",
    "INSOLE_BACK_CELLS",
    "INSOLE_FRONT_CELLS",
    "N_INSOLE_CELLS",
    "DataInfo",
    "ForceUnit",
    "ImuGt",
    "ImuStream",
    "InsoleCombined",
    "InsoleStream",
    "SceneObject",
    "Slam",
    "SmplParams",
    "SubjectInfo",
    "contacts_from_cells",
]

IMU_PARTS: tuple[str, ...] = (
    "L_Foot", "R_Foot", "L_Wrist", "R_Wrist", "Head", "Pelvis", "L_Knee", "R_Knee",
)  # fmt: skip
"""The eight PRISM IMU parts, in PRISM's order."""

FEET: tuple[str, str] = ("L_Foot", "R_Foot")
"""Parts that carry an insole (and whose IMU has ``acc_local_raw``/``gyr_local_raw``)."""

N_INSOLE_CELLS = 16
INSOLE_FRONT_CELLS = range(8, 16)
"""Cells summed for the "front" contact: metatarsal row, hallux and lesser toes."""
INSOLE_BACK_CELLS = range(0, 4)
"""Cells summed for the "back" contact: rear and front heel."""

DEFAULT_FPS = 100.0
"""PRISM's frame rate, frames per second."""

GRAVITY = 9.81
"""Standard gravity used to convert insole forces in N/kg to body weights, m/s^2."""

EXTRAS_KEY = "grip"
"""Top-level key of the PRISM dict under which this project stores its own additions."""

FORMAT_VERSION = 1
"""Version of the :data:`EXTRAS_KEY` namespace written by :meth:`Recording.to_prism_dict`."""

ForceUnit = Literal["auto", "body_weight", "n_per_kg"]
"""Unit of stored insole forces: decided from the data (``"auto"``), body weights or N/kg."""


# ----------------------------------------------------------------------------------- dataclasses
@dataclass(frozen=True)
class SubjectInfo:
    """The subject (PRISM ``info.subj_info``).

    PRISM key names: ``subj_id, gender, age, height, weight, shoe_length, arm_length``.

    Attributes:
        subj_id: Subject identifier as stored (``"subj001"`` or an integer).
        gender: ``"male"``, ``"female"`` or ``"neutral"`` (as stored).
        age: Age, years, or ``None`` if unknown.
        height_m: Body height, metres (PRISM ``height``; a stored value above 3 is read as
            centimetres and converted, see
            :func:`prism_tools.prism_dict.recording_from_prism_dict`), or ``None``.
        weight_kg: Body mass, kg (PRISM ``weight``), or ``None``.
        shoe_length: Shoe length as stored (PRISM does not document the unit), or ``None``.
        arm_length: Arm length as stored (PRISM does not document the unit), or ``None``.
    """

    subj_id: str | int
    gender: str
    age: float | None
    height_m: float | None
    weight_kg: float | None
    shoe_length: float | str | None
    arm_length: float | None

    def to_prism(self) -> dict[str, Any]:
        """Returns the PRISM ``info.subj_info`` dict (original key names)."""
        return {
            "subj_id": self.subj_id,
            "gender": self.gender,
            "age": self.age,
            "height": self.height_m,
            "weight": self.weight_kg,
            "shoe_length": self.shoe_length,
            "arm_length": self.arm_length,
        }


@dataclass(frozen=True, eq=False)
class DataInfo:
    """The take (PRISM ``info.data_info``).

    Attributes:
        take_id: Take identifier as stored (``"take002"`` or an integer).
        trial_name: Name of the trial/activity as stored.
        insole_size: Insole size label as stored, or ``None``.
        fps: Frame rate, frames per second (100 in PRISM).
        synth_imu_frames: Part name (``"L_Wrist"``, ``"R_Wrist"``) -> ``(K,)`` int64 indices of
            the frames whose IMU signal was synthesised from the SMPL fit. Empty when none.
    """

    take_id: str | int
    trial_name: str
    insole_size: str | int | float | None
    fps: float
    synth_imu_frames: dict[str, np.ndarray] = field(default_factory=dict)

    def to_prism(self) -> dict[str, Any]:
        """Returns the PRISM ``info.data_info`` dict."""
        return {
            "take_id": self.take_id,
            "trial_name": self.trial_name,
            "insole_size": self.insole_size,
            "fps": self.fps,
            "synth_imu_frames": dict(self.synth_imu_frames),
        }


@dataclass(frozen=True, eq=False)
class SmplParams:
    """SMPL body-model fit (PRISM ``smpl_params``).

    Attributes:
        poses: ``(F, 72)`` float32, SMPL axis-angle, rad: 24 joints x 3; the first 3 values are the
            global (pelvis) orientation in the world frame, the rest are parent-relative.
        betas: ``(F, 10)`` float32, SMPL shape coefficients (dimensionless).
        trans: ``(F, 3)`` float64, SMPL translation, metres, world frame.
        gender: SMPL model gender, ``"male"``, ``"female"`` or ``"neutral"``.
        root_offset: ``(3,)``, metres, world frame: world translation = ``trans + root_offset``.
    """

    poses: np.ndarray
    betas: np.ndarray
    trans: np.ndarray
    gender: str
    root_offset: np.ndarray


@dataclass(frozen=True, eq=False)
class ImuStream:
    """One IMU as recorded (PRISM ``imu.<part>``).

    Attributes:
        acc_world_raw: ``(F, 3)`` acceleration in the world frame, m/s^2, as recorded.
        acc_world_filt: ``(F, 3)`` the same, low-pass filtered, m/s^2, world frame.
        ori_world: ``(F, 3, 3)`` sensor orientation, rotation matrix sensor -> world.
        acc_local_raw: ``(F, 3)`` accelerometer reading (specific force, includes gravity),
            m/s^2, sensor frame. Insole IMUs (feet) only, else ``None``.
        gyr_local_raw: ``(F, 3)`` gyroscope reading, sensor frame (rad/s in synthetic data; PRISM
            does not document the unit). Insole IMUs (feet) only, else ``None``.
    """

    acc_world_raw: np.ndarray
    acc_world_filt: np.ndarray
    ori_world: np.ndarray
    acc_local_raw: np.ndarray | None = None
    gyr_local_raw: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class ImuGt:
    """Ground-truth IMU kinematics derived from the SMPL fit (PRISM ``imu_gt.<part>``).

    Attributes:
        pos_world: ``(F, 3)`` sensor position, metres, world frame.
        vel_world: ``(F, 3)`` sensor velocity, m/s, world frame.
        acc_world: ``(F, 3)`` sensor acceleration (free, without gravity), m/s^2, world frame.
        ori_world: ``(F, 3, 3)`` sensor orientation, rotation matrix sensor -> world.
    """

    pos_world: np.ndarray
    vel_world: np.ndarray
    acc_world: np.ndarray
    ori_world: np.ndarray


@dataclass(frozen=True, eq=False)
class InsoleStream:
    """One pressure insole (PRISM ``insole.<foot>``).

    Attributes:
        contacts: ``(F, 2)`` bool, binary contact ``[front, back]``: front sums cells 8-15, back
            sums cells 0-3, thresholded.
        force: ``(F, 1)`` total vertical force of this foot, body weights (dimensionless, the two
            feet sum to about 1.0 while standing still).
        forces: ``(F, 16)`` per-cell values, body weights (they sum to ``force`` in this
            project's synthetic data; PRISM does not document the unit), insole frame.
        CoP: ``(F, 2)`` centre of pressure in the insole plane, metres, insole frame.
        force_world: ``(F, 3)`` ground reaction force of this foot, body weights, world frame.
        CoP_world: ``(F, 3)`` centre of pressure, metres, world frame.
    """

    contacts: np.ndarray
    force: np.ndarray
    forces: np.ndarray
    CoP: np.ndarray
    force_world: np.ndarray
    CoP_world: np.ndarray


@dataclass(frozen=True, eq=False)
class InsoleCombined:
    """Both insoles together (PRISM ``insole.combined``).

    Attributes:
        force_world: ``(F, 3)`` total ground reaction force, body weights, world frame.
        CoP_world: ``(F, 3)`` combined centre of pressure, metres, world frame.
    """

    force_world: np.ndarray
    CoP_world: np.ndarray


@dataclass(frozen=True, eq=False)
class Slam:
    """SLAM output (PRISM ``slam``).

    Attributes:
        points: ``(N, 3)`` environment point cloud, metres, world frame.
        head_traj: ``(F, 3)`` head trajectory, metres, world frame.
    """

    points: np.ndarray
    head_traj: np.ndarray


@dataclass(frozen=True, eq=False)
class SceneObject:
    """A scene object mesh (PRISM ``objects.<name>``: BoxLarge, BoxSmall, Chair, Stair).

    Attributes:
        vertices: ``(V, 3)`` float, metres, world frame.
        faces: ``(Fc, 3)`` int, vertex indices of each triangle.
        centroid: ``(3,)`` float, metres, world frame.
        extents: ``(3,)`` float, bounding-box side lengths, metres.
    """

    vertices: np.ndarray
    faces: np.ndarray
    centroid: np.ndarray
    extents: np.ndarray


def box_object(centroid: np.ndarray, extents: np.ndarray) -> SceneObject:
    """An axis-aligned box mesh (8 vertices, 12 outward triangles) centred at ``centroid (3,)``
    with side lengths ``extents (3,)``, m."""
    centroid = np.asarray(centroid, dtype=np.float64)
    extents = np.asarray(extents, dtype=np.float64)
    corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    faces = np.array(
        [
            [0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
            [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3],
        ],
        dtype=np.int64,
    )  # fmt: skip
    return SceneObject(vertices=centroid + corners * extents, faces=faces, centroid=centroid,
                       extents=extents)  # fmt: skip


@dataclass(frozen=True)
class _ArraySpec:
    """Expected layout of one array field: ``"F"`` in ``shape`` is the frame count."""

    shape: tuple[int | str, ...]
    kind: Literal["float", "bool", "int"] = "float"
    optional: bool = False
    rotation: bool = False

    @property
    def per_frame(self) -> bool:
        return bool(self.shape) and self.shape[0] == "F"


_VEC = _ArraySpec(("F", 3))
_ROT = _ArraySpec(("F", 3, 3), rotation=True)

_SPECS: dict[type, dict[str, _ArraySpec]] = {
    SmplParams: {
        "poses": _ArraySpec(("F", 72)),
        "betas": _ArraySpec(("F", 10)),
        "trans": _VEC,
        "root_offset": _ArraySpec((3,)),
    },
    ImuStream: {
        "acc_world_raw": _VEC,
        "acc_world_filt": _VEC,
        "ori_world": _ROT,
        "acc_local_raw": _ArraySpec(("F", 3), optional=True),
        "gyr_local_raw": _ArraySpec(("F", 3), optional=True),
    },
    ImuGt: {"pos_world": _VEC, "vel_world": _VEC, "acc_world": _VEC, "ori_world": _ROT},
    InsoleStream: {
        "contacts": _ArraySpec(("F", 2), kind="bool"),
        "force": _ArraySpec(("F", 1)),
        "forces": _ArraySpec(("F", N_INSOLE_CELLS)),
        "CoP": _ArraySpec(("F", 2)),
        "force_world": _VEC,
        "CoP_world": _VEC,
    },
    InsoleCombined: {"force_world": _VEC, "CoP_world": _VEC},
    Slam: {"points": _ArraySpec(("N", 3)), "head_traj": _VEC},
    SceneObject: {
        "vertices": _ArraySpec(("V", 3)),
        "faces": _ArraySpec(("Fc", 3), kind="int"),
        "centroid": _ArraySpec((3,)),
        "extents": _ArraySpec((3,)),
    },
}


def _array_fields(obj: Any) -> dict[str, np.ndarray]:
    """The non-``None`` array fields of ``obj`` by PRISM key (same objects, not copies)."""
    return {
        name: getattr(obj, name) for name in _SPECS[type(obj)] if getattr(obj, name) is not None
    }


def _slice_per_frame(obj: Any, sl: slice) -> Any:
    """Copy of ``obj`` with every per-frame array sliced (copied) along frames."""
    changes = {
        name: np.array(getattr(obj, name)[sl])
        for name, spec in _SPECS[type(obj)].items()
        if spec.per_frame and getattr(obj, name) is not None
    }
    return dataclasses.replace(obj, **changes)


def _float32_fields(obj: Any, keep: tuple[str, ...] = ()) -> Any:
    """Copy of ``obj`` with its float64 arrays stored as float32 (names in ``keep`` excepted)."""
    changes = {
        name: np.asarray(arr, dtype=np.float32)
        for name, arr in _array_fields(obj).items()
        if name not in keep and arr.dtype == np.float64
    }
    return dataclasses.replace(obj, **changes)


def contacts_from_cells(cells: np.ndarray, threshold: float) -> np.ndarray:
    """PRISM's insole contact rule.

    Args:
        cells: ``(..., 16)`` cell forces (any unit).
        threshold: Summed force above which a contact is on, same unit as ``cells``.

    Returns:
        ``(..., 2)`` bool ``[front, back]``: cells 8-15 sum above ``threshold``, cells 0-3 likewise.
    """
    cells = np.asarray(cells)
    front = cells[..., list(INSOLE_FRONT_CELLS)].sum(axis=-1) > threshold
    back = cells[..., list(INSOLE_BACK_CELLS)].sum(axis=-1) > threshold
    return np.stack([front, back], axis=-1)
