"""PRISM dict -> :class:`~prism_tools.schema.Recording`: the parser (errors name the key path),
the insole force unit decided from the data, and the normalisations recorded in ``extras``
(:func:`recording_from_prism_dict`).

This module imports numpy and :mod:`grip.core.limits` only.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from grip.core.limits import InputLimits, active_limits
from prism_tools.errors import RecordingError
from prism_tools.plausibility import check_plausible
from prism_tools.schema import Recording
from prism_tools.streams import (
    _SPECS,
    EXTRAS_KEY,
    FEET,
    GRAVITY,
    IMU_PARTS,
    DataInfo,
    ForceUnit,
    ImuGt,
    ImuStream,
    InsoleCombined,
    InsoleStream,
    SceneObject,
    Slam,
    SmplParams,
    SubjectInfo,
)
from prism_tools.validation import validate

__all__ = ["detect_force_unit", "recording_from_prism_dict"]


def recording_from_prism_dict(
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
    rec = _from_prism_dict(d, source, force_unit, limits)
    try:
        check_plausible(rec, limits)
    except RecordingError as e:
        raise RecordingError(f"{source}: {e}" if source else str(e)) from None
    return rec


def _from_prism_dict(
    d: Mapping[str, Any], source: str, force_unit: ForceUnit, limits: InputLimits
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
        # (no ground truth: a recording of real sensors without motion capture)
        smpl = None if d.get("smpl_params") is None else self.smpl(d["smpl_params"])

        imu: dict[str, ImuStream] = {}
        for part, sd in self.mapping(self.get(d, "imu", ""), "imu").items():
            if part not in IMU_PARTS:
                self.ignored.append(f"imu.{part}")
                continue
            imu[part] = ImuStream(**self.arrays(sd, ImuStream, f"imu.{part}"))  # type: ignore[arg-type]
        imu_gt: dict[str, ImuGt] = {}
        for part, sd in self.mapping(d.get("imu_gt") or {}, "imu_gt").items():
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

        rec = Recording.from_streams(subject, data_info, imu, insole, combined, extras,
                                     smpl_params=smpl, imu_gt=imu_gt, slam=slam, objects=objects,
                                     source=self.source)  # fmt: skip
        return rec, declared
