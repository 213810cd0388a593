"""The PRISM-format recording type, its validation and its conversion to/from PRISM dicts.

A :class:`Recording` mirrors one PRISM take (``/work/shared/docs/PRISM_FORMAT.md``) field for field:

=========================  =====================================================================
PRISM key                   attribute
=========================  =====================================================================
``info.subj_info``          :attr:`Recording.subject` (:class:`SubjectInfo`)
``info.data_info``          :attr:`Recording.data_info` (:class:`DataInfo`)
``smpl_params``             :attr:`Recording.smpl_params` (:class:`SmplParams`)
``imu.<part>``              :attr:`Recording.imu` ``[part]`` (:class:`ImuStream`)
``imu_gt.<part>``           :attr:`Recording.imu_gt` ``[part]`` (:class:`ImuGt`)
``insole.<foot>``           :attr:`Recording.insole` ``[foot]`` (:class:`InsoleStream`)
``insole.combined``         :attr:`Recording.insole_combined` (:class:`InsoleCombined`)
``slam``                    :attr:`Recording.slam` (:class:`Slam`)
``objects``                 :attr:`Recording.objects` (``dict[str, SceneObject]`` or ``None``)
``grip`` (ours)             :attr:`Recording.extras` plus the declared force unit
=========================  =====================================================================

Conventions: ``F`` is the number of frames (shared by every per-frame array), world frame z-up in
metres with the floor at z = 0, rotation matrices map sensor/segment vectors to the world
(``v_world = R @ v_local``), insole forces are in body weights (1.0 = the subject's weight, about
1.0 in total while standing still).

The dataclasses are frozen (fields cannot be reassigned; use :func:`dataclasses.replace`), but the
numpy arrays they hold are ordinary writable arrays and are not copied on construction.

Limits (:class:`grip.core.limits.InputLimits`): :func:`validate` refuses a frame rate outside
``[min_fps, max_fps]``, more than ``max_frames`` frames or ``max_duration_s`` seconds, and checks
every rotation matrix of every frame; :meth:`Recording.from_prism_dict` also refuses physically
absurd values (accelerations, insole forces, positions above the ``max_*`` limits) with a message
saying which unit was probably meant.

This module imports numpy and :mod:`grip.core.limits` only.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from grip.core.limits import InputLimits, LimitExceeded, active_limits
from prism_tools.errors import RecordingError

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
    "Recording",
    "SceneObject",
    "Slam",
    "SmplParams",
    "SubjectInfo",
    "check_plausible",
    "detect_force_unit",
    "validate",
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

ROTATION_TOL = 1e-3
"""Largest accepted ``max |R R^T - I|`` for a rotation matrix."""

_ROTATION_CHUNK = 65536
"""Frames checked per vectorised step of the rotation check (bounds its temporaries)."""

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
            centimetres and converted, see :meth:`Recording.from_prism_dict`), or ``None``.
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


@dataclass(frozen=True, eq=False)
class Recording:
    """One PRISM take (or a chunk of one), all streams at :attr:`fps`.

    Attributes:
        subject: The subject.
        data_info: The take's metadata.
        smpl_params: SMPL fit; ``smpl_params.poses.shape[0]`` defines ``F``.
        imu: Part name (any subset of :data:`IMU_PARTS`) -> recorded IMU stream.
        imu_gt: Part name (any subset of :data:`IMU_PARTS`) -> ground-truth IMU kinematics.
        insole: Foot (subset of :data:`FEET`) -> insole stream.
        insole_combined: Both insoles together, or ``None``.
        slam: SLAM point cloud and head trajectory, or ``None``.
        objects: Object name -> mesh, or ``None`` when the take has no objects.
        fps: Frame rate, frames per second (100); equals ``data_info.fps``.
        extras: This project's additions (for example ``source_clip``, ``category``,
            ``noise_seed``, ``chunk_id``, ``force_unit_detected``), stored under the
            :data:`EXTRAS_KEY` key of the PRISM dict. Values: str, int, float, bool, None,
            numpy arrays and (nested) lists/dicts of those with string keys.
    """

    subject: SubjectInfo
    data_info: DataInfo
    smpl_params: SmplParams
    imu: dict[str, ImuStream]
    imu_gt: dict[str, ImuGt]
    insole: dict[str, InsoleStream]
    insole_combined: InsoleCombined | None = None
    slam: Slam | None = None
    objects: dict[str, SceneObject] | None = None
    fps: float = DEFAULT_FPS
    extras: dict[str, Any] = field(default_factory=dict)

    # ----------------------------------------------------------------------------- properties
    @property
    def n_frames(self) -> int:
        """Number of frames ``F``."""
        return int(self.smpl_params.poses.shape[0])

    @property
    def duration_s(self) -> float:
        """Duration, seconds."""
        return self.n_frames / self.fps

    @property
    def category(self) -> str | None:
        """Activity category: ``extras["category"]`` if set, else ``data_info.trial_name``."""
        cat = self.extras.get("category")
        if isinstance(cat, str) and cat:
            return cat
        return self.data_info.trial_name or None

    @property
    def take_name(self) -> str:
        """Take name such as ``"subj001_take002"``.

        ``extras["take_name"]`` if set (``load_recording`` sets it from the file path for real
        PRISM files), else composed from ``subject.subj_id`` and ``data_info.take_id``.
        """
        name = self.extras.get("take_name")
        if isinstance(name, str) and name:
            return name
        sid = _id_str(self.subject.subj_id, "subj")
        tid = _id_str(self.data_info.take_id, "take")
        return tid if tid.startswith(sid) else f"{sid}_{tid}"

    @property
    def name(self) -> str:
        """``extras["chunk_id"]`` for a chunk (``"subj001_take002_seq000"``), else the take name."""
        chunk = self.extras.get("chunk_id")
        return chunk if isinstance(chunk, str) and chunk else self.take_name

    # ------------------------------------------------------------------------------ slicing
    def slice_frames(self, start: int, stop: int) -> Recording:
        """Frames ``[start, stop)`` as a new recording (arrays copied).

        Per-frame arrays are sliced, ``data_info.synth_imu_frames`` is re-indexed to the slice,
        ``slam.points``, ``objects``, ``smpl_params.root_offset`` and ``extras`` are kept (the
        extras dict is shallow-copied).

        Args:
            start: First frame, ``0 <= start < stop``.
            stop: One past the last frame, ``stop <= n_frames``.

        Returns:
            A recording with ``stop - start`` frames.
        """
        n = self.n_frames
        if not 0 <= start < stop <= n:
            raise ValueError(f"slice_frames: need 0 <= start < stop <= {n}, got [{start}, {stop})")
        sl = slice(start, stop)
        synth = {
            part: (idx[(idx >= start) & (idx < stop)] - start).astype(np.int64)
            for part, idx in self.data_info.synth_imu_frames.items()
        }
        slam = None
        if self.slam is not None:
            slam = dataclasses.replace(self.slam, head_traj=np.array(self.slam.head_traj[sl]))
        return dataclasses.replace(
            self,
            data_info=dataclasses.replace(self.data_info, synth_imu_frames=synth),
            smpl_params=_slice_per_frame(self.smpl_params, sl),
            imu={p: _slice_per_frame(s, sl) for p, s in self.imu.items()},
            imu_gt={p: _slice_per_frame(s, sl) for p, s in self.imu_gt.items()},
            insole={p: _slice_per_frame(s, sl) for p, s in self.insole.items()},
            insole_combined=(
                None if self.insole_combined is None else _slice_per_frame(self.insole_combined, sl)
            ),
            slam=slam,
            extras=dict(self.extras),
        )

    # ------------------------------------------------------------------------- conversions
    def to_prism_dict(self) -> dict[str, Any]:
        """The PRISM nested-dict layout of PRISM_FORMAT.md (arrays are not copied).

        Keys: ``info.subj_info``, ``info.data_info``, ``smpl_params``, ``imu.<part>``,
        ``imu_gt.<part>``, ``insole.<foot>``, ``insole.combined`` (when present), ``slam``
        (``None`` when absent), ``objects`` (``None`` or ``{name: {...}}``), plus this project's
        namespace ``grip = {"format_version": 1, "force_unit": "body_weight", "extras": {...}}``.
        Optional IMU fields that are ``None`` are omitted.
        """
        smpl = _array_fields(self.smpl_params)
        smpl["gender"] = self.smpl_params.gender
        insole: dict[str, Any] = {p: _array_fields(s) for p, s in self.insole.items()}
        if self.insole_combined is not None:
            insole["combined"] = _array_fields(self.insole_combined)
        objects = (
            None
            if self.objects is None
            else {name: _array_fields(o) for name, o in self.objects.items()}
        )
        return {
            "info": {"subj_info": self.subject.to_prism(), "data_info": self.data_info.to_prism()},
            "smpl_params": smpl,
            "imu": {p: _array_fields(s) for p, s in self.imu.items()},
            "imu_gt": {p: _array_fields(s) for p, s in self.imu_gt.items()},
            "insole": insole,
            "slam": None if self.slam is None else _array_fields(self.slam),
            "objects": objects,
            EXTRAS_KEY: {
                "format_version": FORMAT_VERSION,
                "force_unit": "body_weight",
                "extras": dict(self.extras),
            },
        }

    @classmethod
    def from_prism_dict(
        cls,
        d: Mapping[str, Any],
        source: str = "",
        *,
        force_unit: ForceUnit = "auto",
        limits: InputLimits | None = None,
    ) -> Recording:
        """Builds and validates a recording from a PRISM dict.

        Arrays are used as given (no copy, dtypes kept). Scalars are turned into Python scalars.
        Normalisations, each recorded in :attr:`extras` (no prints, no warnings):

        * Insole force unit. Unless the dict declares it (files written by this package do,
          under :data:`EXTRAS_KEY`) or ``force_unit`` says it, the unit is decided from the data by
          :func:`detect_force_unit` (median combined force over the first 100 frames: about 1.0
          means body weights, about 9.81 means N/kg). N/kg is divided by :data:`GRAVITY` in
          ``force``, ``forces``, ``force_world`` and ``combined.force_world``. Recorded as
          ``extras["force_unit_detected"]`` (``"body_weight"``, ``"n_per_kg"`` or
          ``"undetermined"``), ``extras["force_scale"]`` (the factor applied) and
          ``extras["force_unit_note"]`` (a sentence saying what was done and why).
        * ``subj_info.height`` above 3 is taken as centimetres and divided by 100
          (``extras["height_unit_note"]``).
        * ``contacts`` stored as 0/1 numbers become bool (lossless).
        * Keys this schema does not know are dropped and listed in ``extras["ignored_keys"]``.

        Args:
            d: The PRISM dict (as unpickled from a PRISM ``.pkl``).
            source: Where ``d`` came from (a file path); prefixes every error message.
            force_unit: ``"auto"`` (decide from the data unless the dict declares the unit),
                ``"body_weight"`` or ``"n_per_kg"`` (the stored unit, given explicitly).
            limits: Frame rate, duration and plausibility limits; default
                :func:`grip.core.limits.active_limits`.

        Returns:
            A validated recording with insole forces in body weights.

        Raises:
            RecordingError: A key is missing, has the wrong type, an array fails
                :func:`validate`, or a value is physically absurd (after the force unit is
                decided); the message starts with ``source`` and names the key path.
        """
        limits = limits or active_limits()
        rec = cls._from_prism_dict(d, source, force_unit, limits)
        try:
            check_plausible(rec, limits)
        except RecordingError as e:
            raise RecordingError(f"{source}: {e}" if source else str(e)) from None
        return rec

    @classmethod
    def _from_prism_dict(
        cls, d: Mapping[str, Any], source: str, force_unit: ForceUnit, limits: InputLimits
    ) -> Recording:
        if force_unit not in ("auto", "body_weight", "n_per_kg"):
            raise ValueError(
                f"force_unit must be 'auto', 'body_weight' or 'n_per_kg', got {force_unit!r}"
            )
        p = _Parser(source)
        rec, declared = p.recording(d)
        try:
            validate(rec, limits, plausible=False)
        except RecordingError as e:
            raise p.error(str(e)) from None
        unit = force_unit
        how = "given by the caller"
        if unit == "auto" and declared is not None:
            unit, how = declared, f"declared by the file ({EXTRAS_KEY}.force_unit)"
        if unit == "auto" and declared is None:
            return _apply_detected_force_unit(rec)
        if unit == "body_weight" and how.startswith("declared"):
            return rec  # our own file: nothing to convert and nothing new to record
        scale = 1.0 if unit == "body_weight" else 1.0 / GRAVITY
        note = f"insole force unit {unit} {how}; multiplied force values by {scale:.6g}"
        return _scale_forces(rec, scale, unit=unit, note=note)


def _id_str(value: Any, prefix: str) -> str:
    """``1 -> "subj001"``, ``"001" -> "subj001"``, ``"subj001" -> "subj001"``."""
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, int | np.integer):
        return f"{prefix}{int(value):03d}"
    s = str(value)
    return f"{prefix}{int(s):03d}" if s.isdigit() else s


# -------------------------------------------------------------------------------- force units
def detect_force_unit(total_force: np.ndarray, n_frames: int = 100) -> tuple[str, float]:
    """Decides the unit of stored insole forces from the initial still T-pose.

    Args:
        total_force: ``(F,)`` total vertical force of both feet, unknown unit.
        n_frames: Number of initial frames to look at (all frames if the recording is shorter).

    Returns:
        ``(unit, median)``: the median of the first ``n_frames`` finite values and ``"body_weight"``
        (closest to 1.0), ``"n_per_kg"`` (closest to :data:`GRAVITY`, in log scale) or
        ``"undetermined"`` (median not finite or below 0.1: nobody standing on the insoles).
    """
    head = np.asarray(total_force, dtype=np.float64).reshape(-1)[:n_frames]
    head = head[np.isfinite(head)]
    median = float(np.median(head)) if head.size else math.nan
    if not math.isfinite(median) or median < 0.1:
        return "undetermined", median
    return ("n_per_kg" if median > math.sqrt(GRAVITY) else "body_weight"), median


def _total_vertical_force(rec: Recording) -> np.ndarray | None:
    """``(F,)`` summed vertical force of both feet in the stored unit, or ``None``."""
    if all(f in rec.insole for f in FEET):
        return sum(rec.insole[f].force[:, 0] for f in FEET)  # type: ignore[return-value]
    if rec.insole_combined is not None:
        return rec.insole_combined.force_world[:, 2]
    return None


def _apply_detected_force_unit(rec: Recording) -> Recording:
    total = _total_vertical_force(rec)
    if total is None:
        return dataclasses.replace(
            rec,
            extras={
                **rec.extras,
                "force_unit_detected": "undetermined",
                "force_scale": 1.0,
                "force_unit_note": "no insole force to decide the unit from; left unchanged",
            },
        )
    n = min(100, rec.n_frames)
    unit, median = detect_force_unit(total, n)
    if unit == "undetermined":
        note = (
            f"median combined insole force over frames 0-{n - 1} is {median:.3g}: cannot tell "
            "body weights from N/kg; values left unchanged"
        )
        return _scale_forces(rec, 1.0, unit=unit, note=note)
    ref = GRAVITY if unit == "n_per_kg" else 1.0
    ambiguous = not 0.5 <= median / ref <= 2.0
    scale = 1.0 / ref
    note = (
        f"median combined insole force over frames 0-{n - 1} is {median:.3g}, "
        f"{'ambiguous, nearest' if ambiguous else 'close'} to {ref:g}: read as "
        f"{'N/kg' if unit == 'n_per_kg' else 'body weights'}"
        + (f", divided by {GRAVITY:g} to get body weights" if scale != 1.0 else ", unchanged")
    )
    return _scale_forces(rec, scale, unit=unit, note=note)


def _scale_forces(rec: Recording, scale: float, *, unit: str, note: str) -> Recording:
    """Multiplies every insole force quantity by ``scale`` and records the decision in extras."""
    insole = rec.insole
    combined = rec.insole_combined
    if scale != 1.0:
        insole = {
            foot: dataclasses.replace(
                s, force=s.force * scale, forces=s.forces * scale, force_world=s.force_world * scale
            )
            for foot, s in rec.insole.items()
        }
        if combined is not None:
            combined = dataclasses.replace(combined, force_world=combined.force_world * scale)
    extras = {
        **rec.extras,
        "force_unit_detected": unit,
        "force_scale": float(scale),
        "force_unit_note": note,
    }
    return dataclasses.replace(rec, insole=insole, insole_combined=combined, extras=extras)


# ------------------------------------------------------------------------------------ parsing
_SUBJ_KEYS = ("subj_id", "gender", "age", "height", "weight", "shoe_length", "arm_length")
_DATA_KEYS_REQUIRED = ("take_id", "trial_name", "fps")
_DATA_KEYS_OPTIONAL = ("insole_size", "synth_imu_frames")
_TOP_KEYS = ("info", "smpl_params", "imu", "imu_gt", "insole", "slam", "objects", EXTRAS_KEY)


def _scalar(value: Any) -> Any:
    """numpy scalars / 0-d arrays -> Python scalars, bytes -> str, anything else unchanged."""
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, bytes):
        value = value.decode("utf-8", errors="replace")
    return value


class _Parser:
    """Reads a PRISM dict into dataclasses, raising errors that name the key path."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.ignored: list[str] = []
        self.notes: dict[str, Any] = {}

    def error(self, msg: str) -> RecordingError:
        return RecordingError(f"{self.source}: {msg}" if self.source else msg)

    def mapping(self, value: Any, path: str) -> Mapping[str, Any]:
        if not isinstance(value, Mapping):
            raise self.error(f"{path}: expected a dict, got {type(value).__name__}")
        return value

    def get(self, d: Mapping[str, Any], key: str, path: str) -> Any:
        if key not in d:
            raise self.error(f"{path}.{key}: missing key" if path else f"{key}: missing key")
        return d[key]

    def note_unknown(self, d: Mapping[str, Any], known: tuple[str, ...], path: str) -> None:
        prefix = f"{path}." if path else ""
        self.ignored.extend(f"{prefix}{k}" for k in d if k not in known)

    def array(self, value: Any, path: str) -> np.ndarray:
        if value is None:
            raise self.error(f"{path}: missing (None)")
        try:
            arr = np.asarray(value)
        except (ValueError, TypeError) as e:
            raise self.error(f"{path}: not convertible to an array ({e})") from None
        if arr.dtype.kind not in "biuf":
            raise self.error(f"{path}: expected a numeric array, got dtype {arr.dtype}")
        return arr

    def arrays(self, d: Any, cls: type, path: str) -> dict[str, np.ndarray | None]:
        d = self.mapping(d, path)
        specs = _SPECS[cls]
        self.note_unknown(d, tuple(specs), path)
        out: dict[str, np.ndarray | None] = {}
        for name, spec in specs.items():
            if spec.optional and d.get(name) is None:
                out[name] = None
                continue
            out[name] = self.array(self.get(d, name, path), f"{path}.{name}")
        return out

    def subject(self, d: Mapping[str, Any]) -> SubjectInfo:
        path = "info.subj_info"
        self.note_unknown(d, _SUBJ_KEYS, path)
        v = {k: _scalar(self.get(d, k, path)) for k in _SUBJ_KEYS}
        height = v["height"]
        if isinstance(height, int | float) and height > 3.0:
            self.notes["height_unit_note"] = (
                f"{path}.height = {height:g} read as centimetres and divided by 100"
            )
            height = height / 100.0
        return SubjectInfo(
            subj_id=v["subj_id"],
            gender=str(v["gender"]),
            age=v["age"],
            height_m=height,
            weight_kg=v["weight"],
            shoe_length=v["shoe_length"],
            arm_length=v["arm_length"],
        )

    def data_info(self, d: Mapping[str, Any]) -> DataInfo:
        path = "info.data_info"
        self.note_unknown(d, _DATA_KEYS_REQUIRED + _DATA_KEYS_OPTIONAL, path)
        fps = _scalar(self.get(d, "fps", path))
        if not isinstance(fps, int | float) or isinstance(fps, bool):
            raise self.error(f"{path}.fps: expected a number, got {type(fps).__name__}")
        synth_raw = d.get("synth_imu_frames")
        synth: dict[str, np.ndarray] = {}
        if synth_raw is not None:
            for part, idx in self.mapping(synth_raw, f"{path}.synth_imu_frames").items():
                synth[str(part)] = self.frame_indices(idx, f"{path}.synth_imu_frames.{part}")
        return DataInfo(
            take_id=_scalar(self.get(d, "take_id", path)),
            trial_name=str(_scalar(self.get(d, "trial_name", path))),
            insole_size=_scalar(d.get("insole_size")),
            fps=float(fps),
            synth_imu_frames=synth,
        )

    def frame_indices(self, value: Any, path: str) -> np.ndarray:
        arr = np.asarray(value) if value is not None else np.zeros(0, np.int64)
        if arr.size == 0:
            return np.zeros(0, np.int64)
        if arr.dtype.kind in "iu":
            return arr.reshape(-1).astype(np.int64, copy=False)
        if arr.dtype.kind == "f" and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr)):
            return arr.reshape(-1).astype(np.int64)
        raise self.error(f"{path}: expected integer frame indices, got dtype {arr.dtype}")

    def smpl(self, d: Any) -> SmplParams:
        path = "smpl_params"
        d = self.mapping(d, path)
        arrays = self.arrays({k: v for k, v in d.items() if k != "gender"}, SmplParams, path)
        gender = _scalar(self.get(d, "gender", path))
        return SmplParams(gender=str(gender), **arrays)  # type: ignore[arg-type]

    def insole_stream(self, d: Any, path: str) -> InsoleStream:
        arrays = self.arrays(d, InsoleStream, path)
        contacts = arrays["contacts"]
        assert contacts is not None
        if contacts.dtype.kind != "b":
            values = np.unique(contacts)
            if np.all(np.isin(values, (0, 1))):
                arrays["contacts"] = contacts.astype(bool)
            else:
                raise self.error(
                    f"{path}.contacts: expected bool (or 0/1) values, got dtype {contacts.dtype} "
                    f"with values outside {{0, 1}}"
                )
        return InsoleStream(**arrays)  # type: ignore[arg-type]

    def recording(self, d: Any) -> tuple[Recording, str | None]:
        """Returns the (not yet validated) recording and the force unit declared by the file."""
        d = self.mapping(d, "<top level>")
        self.note_unknown(d, _TOP_KEYS, "")
        info = self.mapping(self.get(d, "info", ""), "info")
        self.note_unknown(info, ("subj_info", "data_info"), "info")
        subject = self.subject(self.mapping(self.get(info, "subj_info", "info"), "info.subj_info"))
        data_info = self.data_info(
            self.mapping(self.get(info, "data_info", "info"), "info.data_info")
        )
        smpl = self.smpl(self.get(d, "smpl_params", ""))

        imu: dict[str, ImuStream] = {}
        for part, sd in self.mapping(self.get(d, "imu", ""), "imu").items():
            if part not in IMU_PARTS:
                self.ignored.append(f"imu.{part}")
                continue
            imu[part] = ImuStream(**self.arrays(sd, ImuStream, f"imu.{part}"))  # type: ignore[arg-type]
        imu_gt: dict[str, ImuGt] = {}
        for part, sd in self.mapping(self.get(d, "imu_gt", ""), "imu_gt").items():
            if part not in IMU_PARTS:
                self.ignored.append(f"imu_gt.{part}")
                continue
            imu_gt[part] = ImuGt(**self.arrays(sd, ImuGt, f"imu_gt.{part}"))  # type: ignore[arg-type]
        insole: dict[str, InsoleStream] = {}
        combined: InsoleCombined | None = None
        for part, sd in self.mapping(self.get(d, "insole", ""), "insole").items():
            if part == "combined":
                if sd is not None:
                    arrays = self.arrays(sd, InsoleCombined, "insole.combined")
                    combined = InsoleCombined(**arrays)  # type: ignore[arg-type]
            elif part in FEET:
                insole[part] = self.insole_stream(sd, f"insole.{part}")
            else:
                self.ignored.append(f"insole.{part}")

        slam = None
        if d.get("slam") is not None:
            slam = Slam(**self.arrays(d["slam"], Slam, "slam"))  # type: ignore[arg-type]
        objects = None
        if d.get("objects") is not None:
            objects = {
                str(name): SceneObject(**self.arrays(od, SceneObject, f"objects.{name}"))  # type: ignore[arg-type]
                for name, od in self.mapping(d["objects"], "objects").items()
            }

        extras: dict[str, Any] = {}
        declared: str | None = None
        ns = d.get(EXTRAS_KEY)
        if ns is not None:
            ns = self.mapping(ns, EXTRAS_KEY)
            self.note_unknown(ns, ("format_version", "force_unit", "extras"), EXTRAS_KEY)
            declared = _scalar(ns.get("force_unit"))
            if declared not in (None, "body_weight", "n_per_kg"):
                raise self.error(f"{EXTRAS_KEY}.force_unit: unknown unit {declared!r}")
            extras = dict(self.mapping(ns.get("extras", {}), f"{EXTRAS_KEY}.extras"))
        extras.update(self.notes)
        if self.ignored:
            extras["ignored_keys"] = sorted(self.ignored)

        rec = Recording(
            subject=subject,
            data_info=data_info,
            smpl_params=smpl,
            imu=imu,
            imu_gt=imu_gt,
            insole=insole,
            insole_combined=combined,
            slam=slam,
            objects=objects,
            fps=data_info.fps,
            extras=extras,
        )
        return rec, declared


# --------------------------------------------------------------------------------- validation
_KIND_CODES = {"float": "f", "bool": "b", "int": "iu"}


def _shape_str(shape: tuple[int | str, ...]) -> str:
    inner = ", ".join(str(s) for s in shape)
    return f"({inner},)" if len(shape) == 1 else f"({inner})"


def _check_array(arr: Any, path: str, spec: _ArraySpec, n_frames: int) -> None:
    if not isinstance(arr, np.ndarray):
        raise RecordingError(f"{path}: expected a numpy array, got {type(arr).__name__}")
    expected = spec.shape
    ok = arr.ndim == len(expected) and all(
        (e == "F" and s == n_frames) or (isinstance(e, str) and e != "F") or s == e
        for e, s in zip(expected, arr.shape, strict=False)
    )
    if not ok:
        with_f = f" with F={n_frames}" if "F" in expected else ""
        raise RecordingError(
            f"{path}: expected shape {_shape_str(expected)}{with_f}, got {tuple(arr.shape)}"
        )
    if arr.dtype.kind not in _KIND_CODES[spec.kind]:
        raise RecordingError(f"{path}: expected {spec.kind} dtype, got {arr.dtype}")
    if spec.kind == "float":
        finite = np.isfinite(arr)
        if not finite.all():
            bad = np.flatnonzero(~finite.reshape(-1))
            where = np.unravel_index(int(bad[0]), arr.shape)
            at = f"frame {where[0]}" if spec.per_frame else f"index {tuple(int(i) for i in where)}"
            raise RecordingError(f"{path}: {bad.size} non-finite value(s) (NaN/inf), first at {at}")
    if spec.rotation and arr.shape[0] > 0:
        _check_rotations(arr, path)


def _check_rotations(rot: np.ndarray, path: str) -> None:
    """Checks that every frame's matrix is a rotation (vectorised, in chunks of frames)."""
    n = rot.shape[0]
    eye = np.eye(3)
    for start in range(0, n, _ROTATION_CHUNK):
        sub = np.asarray(rot[start : start + _ROTATION_CHUNK], dtype=np.float64)
        err = np.abs(np.einsum("nij,nkj->nik", sub, sub) - eye).max(axis=(-2, -1))
        det = np.linalg.det(sub)
        bad = np.flatnonzero((err > ROTATION_TOL) | (det <= 0.0) | ~np.isfinite(err))
        if bad.size:
            i = int(bad[0])
            raise RecordingError(
                f"{path}: not a rotation matrix at frame {start + i} of {n} ({bad.size} bad "
                f"frame(s) among frames {start}-{start + len(sub) - 1}; max |R R^T - I| = "
                f"{err[i]:.3g}, det = {det[i]:.3g}, tolerance {ROTATION_TOL:g})"
            )


def _check_fields(obj: Any, cls: type, path: str, n_frames: int) -> None:
    if not isinstance(obj, cls):
        raise RecordingError(f"{path}: expected {cls.__name__}, got {type(obj).__name__}")
    for name, spec in _SPECS[cls].items():
        arr = getattr(obj, name)
        if arr is None:
            if spec.optional:
                continue
            raise RecordingError(f"{path}.{name}: missing (None)")
        _check_array(arr, f"{path}.{name}", spec, n_frames)


def _check_parts(streams: Any, cls: type, path: str, allowed: tuple[str, ...], n: int) -> None:
    if not isinstance(streams, dict):
        raise RecordingError(f"{path}: expected a dict, got {type(streams).__name__}")
    for part, stream in streams.items():
        if part not in allowed:
            raise RecordingError(f"{path}.{part}: unknown part (expected one of {allowed})")
        _check_fields(stream, cls, f"{path}.{part}", n)


def _check_number(value: Any, path: str, *, positive: bool = False, none_ok: bool = True) -> None:
    if value is None and none_ok:
        return
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise RecordingError(f"{path}: expected a number, got {type(value).__name__}")
    if not math.isfinite(value) or (positive and value <= 0):
        raise RecordingError(
            f"{path}: expected a finite{' positive' if positive else ''} number, got {value}"
        )


def validate(
    rec: Recording, limits: InputLimits | None = None, *, plausible: bool = True
) -> None:
    """Checks every array of a recording: shape, dtype kind, finiteness, rotations, and fps.

    All per-frame arrays must share ``F = smpl_params.poses.shape[0]``; float arrays must be
    finite; rotation matrices (every frame) must satisfy ``max |R R^T - I| <= 1e-3`` with a
    positive determinant; contacts are bool, object faces and synthesised-frame indices are
    integers within range; ``fps`` is finite, within ``[limits.min_fps, limits.max_fps]`` and
    equal to ``data_info.fps``; ``F`` and the duration are within ``limits.max_frames`` and
    ``limits.max_duration_s``. Part names must be in :data:`IMU_PARTS` (insoles: :data:`FEET`).
    With ``plausible``, :func:`check_plausible` follows.

    Args:
        rec: The recording.
        limits: The limits; default :func:`grip.core.limits.active_limits`.
        plausible: Also refuse physically absurd values (:func:`check_plausible`).

    Raises:
        RecordingError: On the first problem found, naming its key path, for example
            ``"imu.L_Wrist.ori_world: expected shape (F, 3, 3) with F=1000, got (999, 3, 3)"``.
            The caller adds the file name.
    """
    if not isinstance(rec, Recording):
        raise RecordingError(f"expected a Recording, got {type(rec).__name__}")
    _check_number(rec.fps, "fps", positive=True, none_ok=False)
    if not isinstance(rec.data_info, DataInfo):
        raise RecordingError(
            f"info.data_info: expected DataInfo, got {type(rec.data_info).__name__}"
        )
    _check_number(rec.data_info.fps, "info.data_info.fps", positive=True, none_ok=False)
    if not math.isclose(rec.fps, rec.data_info.fps, rel_tol=1e-9):
        raise RecordingError(
            f"info.data_info.fps: {rec.data_info.fps} differs from the recording's fps {rec.fps}"
        )
    limits = limits or active_limits()
    try:
        limits.check_fps(float(rec.fps), "info.data_info.fps: frame rate")
    except LimitExceeded as e:
        raise RecordingError(str(e)) from None
    if not isinstance(rec.subject, SubjectInfo):
        raise RecordingError(
            f"info.subj_info: expected SubjectInfo, got {type(rec.subject).__name__}"
        )
    for name in ("age", "height_m", "weight_kg", "arm_length"):
        _check_number(getattr(rec.subject, name), f"info.subj_info.{name}", positive=True)
    if not isinstance(rec.subject.gender, str):
        raise RecordingError("info.subj_info.gender: expected a str")

    smpl = rec.smpl_params
    if not isinstance(smpl, SmplParams):
        raise RecordingError(f"smpl_params: expected SmplParams, got {type(smpl).__name__}")
    poses = smpl.poses
    if not isinstance(poses, np.ndarray) or poses.ndim != 2 or poses.shape[0] < 1:
        shape = getattr(poses, "shape", type(poses).__name__)
        raise RecordingError(f"smpl_params.poses: expected shape (F, 72) with F >= 1, got {shape}")
    n = int(poses.shape[0])
    try:
        limits.check("max_frames", n, "smpl_params.poses: frame count")
        limits.check("max_duration_s", n / float(rec.fps),
                     f"duration ({n} frames at {float(rec.fps):g} Hz)", " s")  # fmt: skip
    except LimitExceeded as e:
        raise RecordingError(str(e)) from None
    _check_fields(smpl, SmplParams, "smpl_params", n)
    if not isinstance(smpl.gender, str):
        raise RecordingError("smpl_params.gender: expected a str")

    for part, idx in rec.data_info.synth_imu_frames.items():
        path = f"info.data_info.synth_imu_frames.{part}"
        if not isinstance(idx, np.ndarray) or idx.ndim != 1 or idx.dtype.kind not in "iu":
            desc = getattr(idx, "dtype", type(idx).__name__)
            raise RecordingError(f"{path}: expected a 1-D integer index array, got {desc}")
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise RecordingError(f"{path}: frame indices outside [0, {n})")

    _check_parts(rec.imu, ImuStream, "imu", IMU_PARTS, n)
    _check_parts(rec.imu_gt, ImuGt, "imu_gt", IMU_PARTS, n)
    _check_parts(rec.insole, InsoleStream, "insole", FEET, n)
    if rec.insole_combined is not None:
        _check_fields(rec.insole_combined, InsoleCombined, "insole.combined", n)
    if rec.slam is not None:
        _check_fields(rec.slam, Slam, "slam", n)
    if rec.objects is not None:
        if not isinstance(rec.objects, dict):
            raise RecordingError(
                f"objects: expected a dict or None, got {type(rec.objects).__name__}"
            )
        for name, obj in rec.objects.items():
            path = f"objects.{name}"
            _check_fields(obj, SceneObject, path, n)
            if obj.faces.size and (obj.faces.min() < 0 or obj.faces.max() >= len(obj.vertices)):
                raise RecordingError(
                    f"{path}.faces: vertex indices outside [0, {len(obj.vertices)})"
                )
    if not isinstance(rec.extras, dict) or not all(isinstance(k, str) for k in rec.extras):
        raise RecordingError("extras: expected a dict with str keys")
    if plausible:
        check_plausible(rec, limits)


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
    positions = [("smpl_params.trans", rec.smpl_params.trans)]
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


def _float32_fields(obj: Any, keep: tuple[str, ...] = ()) -> Any:
    """Copy of ``obj`` with its float64 arrays stored as float32 (names in ``keep`` excepted)."""
    changes = {
        name: np.asarray(arr, dtype=np.float32)
        for name, arr in _array_fields(obj).items()
        if name not in keep and arr.dtype == np.float64
    }
    return dataclasses.replace(obj, **changes)


def recording_as_float32(rec: Recording) -> Recording:
    """The recording with float32 sensor and pose arrays, as PRISM stores its ``poses``.

    ``smpl_params.trans`` and ``root_offset`` stay float64 (PRISM's dtype; world translations
    need the precision). Halves the size of synthesised datasets; float32 keeps ~7 significant
    digits, far below any sensor noise.
    """
    return dataclasses.replace(
        rec,
        smpl_params=_float32_fields(rec.smpl_params, keep=("trans", "root_offset")),
        imu={p: _float32_fields(s) for p, s in rec.imu.items()},
        imu_gt={p: _float32_fields(s) for p, s in rec.imu_gt.items()},
        insole={p: _float32_fields(s) for p, s in rec.insole.items()},
        insole_combined=(
            None if rec.insole_combined is None else _float32_fields(rec.insole_combined)
        ),
    )


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
