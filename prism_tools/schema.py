"""The PRISM-format recording type (:class:`Recording`).

A :class:`Recording` mirrors one PRISM take (``/work/shared/docs/PRISM_FORMAT.md``) field for field:

=========================  =====================================================================
PRISM key                   attribute
=========================  =====================================================================
``info.subj_info``          :attr:`Recording.subject` (:class:`SubjectInfo`)
``info.data_info``          :attr:`Recording.data_info` (:class:`DataInfo`)
``smpl_params``             :attr:`Recording.smpl_params` (:class:`SmplParams`, or ``None``)
``imu.<part>``              :attr:`Recording.imu` ``[part]`` (:class:`ImuStream`)
``imu_gt.<part>``           :attr:`Recording.imu_gt` ``[part]`` (:class:`ImuGt`)
``insole.<foot>``           :attr:`Recording.insole` ``[foot]`` (:class:`InsoleStream`)
``insole.combined``         :attr:`Recording.insole_combined` (:class:`InsoleCombined`)
``slam``                    :attr:`Recording.slam` (:class:`Slam`)
``objects``                 :attr:`Recording.objects` (``dict[str, SceneObject]`` or ``None``)
``grip`` (ours)             :attr:`Recording.extras` plus the declared force unit
=========================  =====================================================================

The ground truth (``smpl_params``, from motion capture, and ``imu_gt``, derived from it) is
optional: a recording of real sensors alone (IMUs, insoles, frame rate, subject) is complete, and
whatever needs the truth asks for it with :meth:`Recording.require_ground_truth`.

The parts and the format's constants live in :mod:`prism_tools.streams`, the checks in
:mod:`prism_tools.validation` (:func:`~prism_tools.validation.validate`) and
:mod:`prism_tools.plausibility`, the reading of PRISM dicts in :mod:`prism_tools.prism_dict`
(:func:`~prism_tools.prism_dict.recording_from_prism_dict`).

This module imports numpy only.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from prism_tools.errors import RecordingError
from prism_tools.streams import (
    DEFAULT_FPS,
    EXTRAS_KEY,
    FEET,
    FORMAT_VERSION,
    IMU_PARTS,
    DataInfo,
    ImuGt,
    ImuStream,
    InsoleCombined,
    InsoleStream,
    SceneObject,
    Slam,
    SmplParams,
    SubjectInfo,
    _array_fields,
    _float32_fields,
    _slice_per_frame,
)

__all__ = ["Recording", "recording_as_float32"]


@dataclass(frozen=True, eq=False)
class Recording:
    """One PRISM take (or a chunk of one), all streams at :attr:`fps`.

    Attributes:
        subject: The subject.
        data_info: The take's metadata.
        imu: Part name (any subset of :data:`IMU_PARTS`) -> recorded IMU stream.
        insole: Foot (subset of :data:`FEET`) -> insole stream.
        smpl_params: SMPL fit (the ground truth), or ``None`` for a recording of sensors only.
        imu_gt: Part name (any subset of :data:`IMU_PARTS`) -> ground-truth IMU kinematics
            (empty without ground truth).
        insole_combined: Both insoles together, or ``None``.
        slam: SLAM point cloud and head trajectory, or ``None``.
        objects: Object name -> mesh, or ``None`` when the take has no objects.
        fps: Frame rate, frames per second (100); equals ``data_info.fps``.
        extras: This project's additions (for example ``source_clip``, ``category``,
            ``noise_seed``, ``chunk_id``, ``force_unit_detected``), stored under the
            :data:`EXTRAS_KEY` key of the PRISM dict. Values: str, int, float, bool, None,
            numpy arrays and (nested) lists/dicts of those with string keys.
        source: Where the recording was read from (a file path; ``""`` when built in memory),
            for messages; never saved.
    """

    subject: SubjectInfo
    data_info: DataInfo
    imu: dict[str, ImuStream]
    insole: dict[str, InsoleStream]
    smpl_params: SmplParams | None = None
    imu_gt: dict[str, ImuGt] = field(default_factory=dict)
    insole_combined: InsoleCombined | None = None
    slam: Slam | None = None
    objects: dict[str, SceneObject] | None = None
    fps: float = DEFAULT_FPS
    extras: dict[str, Any] = field(default_factory=dict)
    source: str = field(default="", repr=False)

    @classmethod
    def from_streams(
        cls, subject: SubjectInfo, data_info: DataInfo, imu: dict[str, ImuStream],
        insole: dict[str, InsoleStream], insole_combined: InsoleCombined | None = None,
        extras: dict[str, Any] | None = None, **optional: Any,
    ) -> Recording:  # fmt: skip
        """A recording at ``data_info.fps`` from its sensor streams; ``optional`` holds the
        other fields by name (``smpl_params``, ``imu_gt``, ``slam``, ``objects``, ``source``)."""
        return cls(subject=subject, data_info=data_info, imu=imu, insole=insole,
                   insole_combined=insole_combined, fps=float(data_info.fps),
                   extras={} if extras is None else extras, **optional)  # fmt: skip

    # ----------------------------------------------------------------------------- properties
    @property
    def n_frames(self) -> int:
        """Number of frames ``F``: the rows of ``smpl_params.poses``, or without ground truth
        of the first sensor stream (IMUs in PRISM order, then insoles; 0 when there is none)."""
        if self.smpl_params is not None:
            return int(self.smpl_params.poses.shape[0])
        return _sensor_frames(self)

    @property
    def has_ground_truth(self) -> bool:
        """Whether the recording holds the motion-capture ground truth (``smpl_params``)."""
        return self.smpl_params is not None

    def require_ground_truth(self, purpose: str) -> SmplParams:
        """The ground truth, for ``purpose`` (``"the metrics"``, ``"training"``, ...).

        Raises:
            RecordingError: The recording has sensors only; the message names its file (or
                its name when it was not read from one) and what needs the ground truth.
        """
        if self.smpl_params is None:
            where = self.source or f"recording {self.name}"
            raise RecordingError(
                f"{where}: {purpose} needs ground truth (smpl_params, from motion capture), and "
                "this recording has sensors only"
            )
        return self.smpl_params

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
            smpl_params=(
                None if self.smpl_params is None else _slice_per_frame(self.smpl_params, sl)
            ),
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

        Keys: ``info.subj_info``, ``info.data_info``, ``smpl_params`` (``None`` without ground
        truth), ``imu.<part>``, ``imu_gt.<part>``, ``insole.<foot>``, ``insole.combined`` (when
        present), ``slam`` (``None`` when absent), ``objects`` (``None`` or ``{name: {...}}``),
        plus this project's namespace
        ``grip = {"format_version": 1, "force_unit": "body_weight", "extras": {...}}``.
        Optional IMU fields that are ``None`` are omitted.
        """
        smpl = None
        if self.smpl_params is not None:
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


def _sensor_frames(rec: Recording) -> int:
    """Rows of the first sensor stream (IMUs in PRISM order, then insoles), 0 without any."""
    for part in IMU_PARTS:
        if part in rec.imu:
            return int(np.shape(rec.imu[part].acc_world_raw)[0])
    for foot in FEET:
        if foot in rec.insole:
            return int(np.shape(rec.insole[foot].force)[0])
    return 0


def _id_str(value: Any, prefix: str) -> str:
    """``1 -> "subj001"``, ``"001" -> "subj001"``, ``"subj001" -> "subj001"``."""
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, int | np.integer):
        return f"{prefix}{int(value):03d}"
    s = str(value)
    return f"{prefix}{int(s):03d}" if s.isdigit() else s


def recording_as_float32(rec: Recording) -> Recording:
    """The recording with float32 sensor and pose arrays, as PRISM stores its ``poses``.

    ``smpl_params.trans`` and ``root_offset`` stay float64 (PRISM's dtype; world translations
    need the precision). Halves the size of synthesised datasets; float32 keeps ~7 significant
    digits, far below any sensor noise.
    """
    return dataclasses.replace(
        rec,
        smpl_params=(
            None
            if rec.smpl_params is None
            else _float32_fields(rec.smpl_params, keep=("trans", "root_offset"))
        ),
        imu={p: _float32_fields(s) for p, s in rec.imu.items()},
        imu_gt={p: _float32_fields(s) for p, s in rec.imu_gt.items()},
        insole={p: _float32_fields(s) for p, s in rec.insole.items()},
        insole_combined=(
            None if rec.insole_combined is None else _float32_fields(rec.insole_combined)
        ),
    )
