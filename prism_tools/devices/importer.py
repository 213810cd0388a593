"""Device exports -> a PRISM-format :class:`~prism_tools.schema.Recording` without ground truth
(:func:`import_devices`), ready for ``grip reconstruct REC --init standing``.

The recording a user makes follows GRIP's protocol (supplement Sec. 7.1): all sensors on, the
subject stands still in the body model's T-pose facing the direction that becomes world +y for
at least a second, then jumps (arms still), then does what is to be recorded. Import:

1. Read the Moticon insole export (:mod:`prism_tools.devices.moticon`) and the IMU CSVs
   (:mod:`prism_tools.devices.imu_csv`); a foot without an IMU file takes its insole's IMU.
   Each IMU's units, kind and quaternion order are checked against gravity
   (:mod:`prism_tools.devices.checks`).
2. Synchronise: find the jump's landing in every file (:mod:`prism_tools.devices.sync`; the
   insole file by its IMUs, else by its total force) and shift each file's clock so that the
   landings coincide. ``sync=False`` takes the files' clocks as one.
3. Resample every channel onto one 100 Hz axis anchored on the reference file's samples (the
   insole file, else the first IMU file) over the span every file covers: linear
   interpolation, slerp for quaternions. Gaps (missing rows, a side's empty fields, rows with
   missing values) are bridged by the interpolation up to ``max_gap_s`` within the output and
   reported; a longer one is an error.
4. Find the calibration window: the first ``calib_s`` s of the first run of frames before the
   jump in which every IMU is still (angular rate below 20 deg/s, specific force within 0.1 g of
   1 g), or the window starting at ``calib_at_s`` (which must be still throughout). The
   recording starts there: frame 0 is the calibration pose, as ``--init standing`` assumes.
5. Orient and calibrate each IMU (:mod:`prism_tools.devices.orientation` for sensors that
   export no orientation, :mod:`prism_tools.devices.calibrate`): ``ori_world`` is the segment's
   world orientation (the rest T-pose's at frame 0, heading +y), ``acc_world_*`` the sensor's
   acceleration without gravity in the world (``acc_world_filt`` through the synthetic data's
   causal 6 Hz low-pass), the feet's ``acc_local_raw``/``gyr_local_raw`` the specific force and
   angular rate in the segment frame (``acc_world_raw + g z = ori_world @ acc_local_raw``).
6. Insoles: cell forces = pressure x the body model's cell area, scaled to sum to Moticon's
   total force; ``force`` = total force / (mass g); CoP = Moticon's normalised CoP x (foot
   length, foot width) in metres (insole frame: forward, medial); contacts by the synthetic
   data's rule (front cells 8-15 / back cells 0-3 above 20 N). The subject's mass, unless given,
   is the insoles' total force while standing still / g.

This module imports numpy, scipy (through the synthetic data's low-pass filter,
:func:`prism_tools.synth.imu.lowpass_causal`) and :mod:`grip.core`.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from grip.core.body import CANONICAL_TO_WORLD, BodyParams, build_body
from grip.core.limits import InputLimits
from grip.core.rotations import (
    angular_velocity,
    quat_to_matrix,
    resample_linear,
    resample_quats,
)
from prism_tools.devices.calibrate import (
    DEFAULT_MOUNTS,
    SiteCalibration,
    calibrate_site,
    mount_matrix,
    still_runs,
)
from prism_tools.devices.checks import check_imu_export, unit_fixes
from prism_tools.devices.common import DeviceFileError, find_gaps
from prism_tools.devices.imu_csv import ImuCsv, ImuCsvOptions, read_imu_csv
from prism_tools.devices.insole_import import insole_steps, insole_stream, resample_insole
from prism_tools.devices.moticon import MoticonExport, read_moticon
from prism_tools.devices.orientation import DEFAULT_GAIN, gravity_filter
from prism_tools.devices.report import ImportReport, StreamReport
from prism_tools.devices.sync import Landing, SyncSettings, find_landings
from prism_tools.schema import Recording
from prism_tools.streams import (
    FEET,
    GRAVITY,
    IMU_PARTS,
    DataInfo,
    ImuStream,
    SubjectInfo,
)
from prism_tools.validation import validate

__all__ = ["ImportOptions", "ImportReport", "StreamReport", "import_devices"]

INSOLES = "insoles"
_MOTICON_KIND = "Moticon OpenGo text export"
"""Name of the insole file's stream in reports."""
STILL_GYR_RAD_S = math.radians(20.0)
STILL_ACC_MPS2 = 0.1 * GRAVITY
_UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class ImportOptions:
    """Settings of :func:`import_devices`.

    Attributes:
        fps: Output frame rate, Hz.
        sync: Align the files by the jump's landing; ``False``: their clocks are one.
        sync_settings: What counts as a jump (:class:`~prism_tools.devices.sync.SyncSettings`).
        calib_s: Length of the still calibration window, s.
        calib_at_s: Start of the calibration window on the reference file's clock, s; ``None``:
            found (the first still window before the jump).
        max_gap_s: Longest gap bridged by interpolation within the output, s.
        subject_height_m: Body height, m (the body model: cell areas, foot size).
        subject_mass_kg: Body mass, kg; ``None``: the insoles' total force while still / g
            (70 kg without both insoles).
        mounts: Part -> the sensor's (x, y, z) directions in the T-pose
            (:data:`~prism_tools.devices.calibrate.DEFAULT_MOUNTS` for the others).
        filter_gain: Tilt gain of the orientation filter, rad/s per rad.
        name: Take name (default: the insole file's stem, else the first IMU file's).
        category: Activity category (``extras["category"]``), or ``None``.
        subject_id: Subject identifier.
    """

    fps: float = 100.0
    sync: bool = True
    sync_settings: SyncSettings = field(default_factory=SyncSettings)
    calib_s: float = 1.0
    calib_at_s: float | None = None
    max_gap_s: float = 0.2
    subject_height_m: float = 1.70
    subject_mass_kg: float | None = None
    mounts: Mapping[str, tuple[str, str, str]] = field(default_factory=dict)
    filter_gain: float = DEFAULT_GAIN
    name: str | None = None
    category: str | None = None
    subject_id: str = "subject"


@dataclass
class _Imu:
    """One IMU's samples on its own clock (all channels present)."""

    part: str
    stream: str
    file: str
    time_s: np.ndarray
    acc: np.ndarray
    acc_kind: str
    gyr: np.ndarray | None
    quat: np.ndarray | None


# ------------------------------------------------------------------------------------ import
def import_devices(
    insoles: str | os.PathLike[str] | None,
    imus: Mapping[str, str | os.PathLike[str]],
    options: ImportOptions = ImportOptions(),
    csv_options: ImuCsvOptions | None = None,
    limits: InputLimits | None = None,
    progress: Callable[[str], None] | None = None,
) -> tuple[Recording, ImportReport]:
    """Device exports -> a validated recording of sensors only (module docstring).

    Args:
        insoles: The Moticon OpenGo text export, or ``None``.
        imus: Part (``"L_Wrist"``, ...) -> IMU CSV. Feet without one use the insole's IMU.
        options: Import settings.
        csv_options: Units of generic IMU CSVs.
        limits: Input limits of the readers; default the active ones.
        progress: Called with one line per step (the command prints them).

    Returns:
        The recording and the report.

    Raises:
        FileNotFoundError: A file is missing.
        DeviceFileError: A malformed file, no jump found in a file (with sync on), a gap longer
            than ``max_gap_s``, no still calibration window, files that share no time span;
            each message names the file (or the files) concerned.
        ValueError: Bad options (an unknown part, a bad mount).
    """
    say = progress or (lambda _line: None)
    for part in imus:
        if part not in IMU_PARTS:
            raise ValueError(f"unknown IMU part {part!r}; expected one of {IMU_PARTS}")
    mounts = {p: mount_matrix(DEFAULT_MOUNTS[p], f"mount of {p}") for p in IMU_PARTS}
    for p, axes in options.mounts.items():
        if p not in IMU_PARTS:
            raise ValueError(f"mount for unknown part {p!r}; expected one of {IMU_PARTS}")
        mounts[p] = mount_matrix(axes, f"mount of {p}")
    if insoles is None and not imus:
        raise ValueError("nothing to import: give an insole export and/or IMU files")

    moticon = None
    if insoles is not None:
        moticon = read_moticon(insoles, limits)
        sides = ", ".join(f"{f} {int(s.valid.sum())} samples" for f, s in moticon.sides.items())
        say(f"read {insoles}: Moticon OpenGo text export, {len(moticon.time_s)} rows ({sides})")
    csvs: dict[str, ImuCsv] = {}
    for part, path in imus.items():
        csvs[part] = read_imu_csv(path, csv_options, limits)
        c = csvs[part]
        check_imu_export(c.time_s, c.acc_mps2, c.acc_kind, c.gyr_rad_s, c.quat_wxyz, c.source,
                         part, unit_fixes(c.fmt), c.quat_order)  # fmt: skip
        rate = 1.0 / float(np.median(np.diff(c.time_s)))
        say(f"read {path}: {_csv_kind(c)} for {part}, {len(c.time_s)} samples at {rate:.4g} Hz"
            + (f", {len(c.dropped_lines)} rows with missing values dropped"
               if c.dropped_lines else ""))  # fmt: skip

    imu_sources = [_from_csv(part, c) for part, c in csvs.items()]
    notes: list[str] = []
    if moticon is not None:
        for foot in FEET:
            side = moticon.sides.get(foot)
            if foot in csvs or side is None:
                continue
            if side.acc_mps2 is None or side.gyr_rad_s is None:
                notes.append(f"{foot}: no IMU file and the insole export has no acceleration/"
                             f"angular channels: the recording has no {foot} IMU")  # fmt: skip
                continue
            ok = side.valid & np.isfinite(side.acc_mps2).all(1) & np.isfinite(side.gyr_rad_s).all(1)
            if ok.sum() < 2:
                notes.append(f"{foot}: the insole's IMU channels are empty: no {foot} IMU")
                continue
            imu_sources.append(_Imu(foot, INSOLES, moticon.source, moticon.time_s[ok],
                                    side.acc_mps2[ok], "specific_force", side.gyr_rad_s[ok],
                                    None))  # fmt: skip
            check_imu_export(moticon.time_s[ok], side.acc_mps2[ok], "specific_force",
                             side.gyr_rad_s[ok], None, moticon.source, f"{foot} insole IMU",
                             unit_fixes("moticon"))  # fmt: skip
    imu_sources.sort(key=lambda s: IMU_PARTS.index(s.part))

    # ---- 2. synchronise
    stream_files = ([(INSOLES, moticon.source)] if moticon is not None else []) + [
        (p, c.source) for p, c in csvs.items()]  # fmt: skip
    reference = stream_files[0][0]
    landings: dict[str, Landing | None] = {name: None for name, _ in stream_files}
    shift: dict[str, float] = {name: 0.0 for name, _ in stream_files}
    if options.sync:
        for name, file in stream_files:
            landings[name] = _landing(name, file, moticon, imu_sources, options.sync_settings)
            shift[name] = landings[name].time_s
        ref_t = shift[reference]
        say("jump landings: " + ", ".join(
            f"{n} {landings[n].time_s:.3f} s" + ("" if n == reference else
                                                 f" (offset {shift[n] - ref_t:+.3f} s)")
            for n, _ in stream_files))  # fmt: skip

    # ---- 3. one time axis
    ranges: list[tuple[str, float, float]] = []
    for s in imu_sources:
        ranges.append((f"{s.part} IMU ({s.file})", s.time_s[0] - shift[s.stream],
                       s.time_s[-1] - shift[s.stream]))  # fmt: skip
    if moticon is not None:
        for foot, side in moticon.sides.items():
            t = moticon.time_s[side.valid]
            if len(t) < 2:
                raise DeviceFileError(f"{moticon.source}: the {foot} insole has fewer than 2 "
                                      "samples")  # fmt: skip
            ranges.append((f"{foot} insole ({moticon.source})", t[0] - shift[INSOLES],
                           t[-1] - shift[INSOLES]))  # fmt: skip
    lo = max(r[1] for r in ranges)
    hi = min(r[2] for r in ranges)
    if hi - lo < options.calib_s:
        span = "; ".join(f"{n}: {a:+.2f}..{b:+.2f} s" for n, a, b in ranges)
        where = "relative to each file's landing" if options.sync else "on the shared clock"
        raise DeviceFileError(f"the files share no common span of {options.calib_s:g} s ({span}, "
                              f"{where})")  # fmt: skip
    ref_times = (moticon.time_s if reference == INSOLES else csvs[reference].time_s) - shift[
        reference]  # fmt: skip
    tau0 = float(ref_times[np.searchsorted(ref_times, lo - 1e-9)])
    n = math.floor((hi - tau0) * options.fps + 1e-6) + 1
    grid = tau0 + np.arange(n) / options.fps

    imu_grid = {s.part: _resample_imu(s, grid + shift[s.stream]) for s in imu_sources}

    # ---- 4. calibration window
    win = max(1, round(options.calib_s * options.fps))
    still = np.ones(n, dtype=bool)
    for s in imu_sources:
        g = imu_grid[s.part]
        still &= _still(g["acc"], g["gyr"], g["rot"], s.acc_kind, options.fps)
    jump_frame = round(-tau0 * options.fps) if options.sync else None
    if jump_frame is not None and jump_frame < win:
        raise DeviceFileError(
            f"the jump lands {-tau0:.2f} s after the span all files cover begins, too soon for a "
            f"{options.calib_s:g} s still pose before it (a device started after the jump, or "
            "the pose was too short): start every device, stand still in the T-pose, then jump"
        )
    imu_files = list(dict.fromkeys(s.file for s in imu_sources))
    c0, still_len = _calibration_start(still, win, jump_frame, grid, shift[reference], options,
                                       imu_files)  # fmt: skip
    if still_len < win:
        moved = grid[c0 + still_len] + shift[reference]
        raise DeviceFileError(
            f"the calibration window at {options.calib_at_s:g} s is not still: an IMU moves from "
            f"{moved:.3f} s on the {reference} clock ({still_len / options.fps:.2f} s of the "
            f"{options.calib_s:g} s still; still: angular rate below "
            f"{math.degrees(STILL_GYR_RAD_S):g} deg/s, acceleration within "
            f"{STILL_ACC_MPS2 / GRAVITY:g} g of 1 g), which would turn every orientation: give "
            "the start of the still T-pose, or leave --calib-at out to find it")  # fmt: skip
    out_n = n - c0
    say(f"calibration: still from {grid[c0] + shift[reference]:.3f} s on the {reference} clock "
        f"({still_len / options.fps:.2f} s still; the first {options.calib_s:g} s averaged)")

    # gaps within the output
    channels: dict[str, dict[str, dict[str, float]]] = {name: {} for name, _ in stream_files}
    out_lo, out_hi = grid[c0], grid[-1]
    for s in imu_sources:
        label = "IMU" if s.stream != INSOLES else f"{s.part} insole IMU"
        channels[s.stream][label] = _check_gaps(s.time_s - shift[s.stream], out_lo, out_hi,
                                                options.max_gap_s, s.file, label,
                                                shift[s.stream])  # fmt: skip
    if moticon is not None:
        for foot, side in moticon.sides.items():
            channels[INSOLES][f"{foot} insole"] = _check_gaps(
                moticon.time_s[side.valid] - shift[INSOLES], out_lo, out_hi, options.max_gap_s,
                moticon.source, f"{foot} insole", shift[INSOLES])  # fmt: skip
            if channels[INSOLES].get(f"{foot} insole IMU") == channels[INSOLES][f"{foot} insole"]:
                del channels[INSOLES][f"{foot} insole IMU"]  # the same rows: said once

    # ---- 6 (first: the mass). insoles
    body_height = options.subject_height_m
    mass, mass_source = options.subject_mass_kg, "given"
    insole_grid: dict[str, dict[str, np.ndarray]] = {}
    if moticon is not None:
        body0 = build_body(BodyParams(height_m=body_height))
        for foot in moticon.sides:
            insole_grid[foot] = resample_insole(moticon, foot, grid + shift[INSOLES],
                                                body0.insole_area_cm2[FEET.index(foot)])
    if mass is None:
        if len(insole_grid) == 2:
            standing = sum(g["total_n"][c0 : c0 + win].mean() for g in insole_grid.values())
            mass, mass_source = float(standing / GRAVITY), "insoles"
            if not 10.0 <= mass <= 300.0:
                raise DeviceFileError(
                    f"{moticon.source}: the insoles read {standing:.4g} N in all while the "
                    "subject stands still, not a body weight (10-300 kg): give the subject's mass"
                )
            say(f"subject mass {mass:.1f} kg from the insoles while standing still")
        else:
            mass, mass_source = 70.0, "default"
            notes.append("subject mass not given and not measurable without both insoles: 70 kg")
    body = build_body(BodyParams(height_m=body_height, mass_kg=mass))

    # ---- 5. IMUs
    imu: dict[str, ImuStream] = {}
    sites: dict[str, dict[str, Any]] = {}
    for s in imu_sources:
        stream, info = _calibrated_imu(s, imu_grid[s.part], c0, win, mounts[s.part], options)
        imu[s.part] = stream
        sites[s.part] = info
        say(f"{s.part}: {info['source']}, reference heading {info['heading_deg']:+.1f} deg, "
            f"tilt {info['ref_tilt_deg']:.1f} deg, mount {info['mount_error_deg']:.1f} deg "
            "from nominal")  # fmt: skip
    missing = [p for p in ("L_Foot", "R_Foot", "L_Wrist", "R_Wrist") if p not in imu]
    if missing:
        notes.append(f"no IMU for {', '.join(missing)}: the shipped models read L_Foot, R_Foot, "
                     "L_Wrist and R_Wrist")  # fmt: skip

    insole = {foot: insole_stream(g, foot, c0, body, mass)
              for foot, g in insole_grid.items()}  # fmt: skip
    steps = insole_steps(moticon, grid, shift.get(INSOLES, 0.0), c0, out_n, options.fps)

    streams = tuple(
        StreamReport(name=name, file=file,
                     kind=_MOTICON_KIND if name == INSOLES else _csv_kind(csvs[name]),
                     channels=channels[name],
                     dropped_rows=0 if name == INSOLES else len(csvs[name].dropped_lines),
                     landing_s=None if landings[name] is None else landings[name].time_s,
                     offset_s=shift[name] - shift[reference])
        for name, file in stream_files)  # fmt: skip
    report = ImportReport(
        streams=streams, reference=reference, fps=options.fps, frames=out_n,
        start_reference_s=float(grid[c0] + shift[reference]),
        jump_frame=None if jump_frame is None else jump_frame - c0,
        calib_frames=(0, win), still_s=still_len / options.fps, subject_mass_kg=mass,
        mass_source=mass_source, sites=sites, notes=tuple(notes),
    )  # fmt: skip
    name = options.name or Path(stream_files[0][1]).stem
    extras: dict[str, Any] = {
        "take_name": name,
        "source": "devices",
        "device_import": json.dumps(report.to_dict()),
        "cop_world": "not measured: the devices do not say where the feet are; CoP_world is the "
                     "insole CoP on the standing T-pose's feet at the origin",
    }  # fmt: skip
    if options.category:
        extras["category"] = options.category
    if steps:
        extras["insole_steps"] = steps
    rec = Recording.from_streams(
        SubjectInfo(subj_id=options.subject_id, gender="neutral", age=None,
                    height_m=float(body_height), weight_kg=float(mass), shoe_length=None,
                    arm_length=None),
        DataInfo(take_id=name, trial_name=options.category or "",
                 insole_size=None if moticon is None else moticon.insole_size,
                 fps=float(options.fps), synth_imu_frames={}),
        imu, insole, None, extras, source="",
    )  # fmt: skip
    validate(rec)
    return rec, report


# ------------------------------------------------------------------------------------ helpers
def _csv_kind(c: ImuCsv) -> str:
    return "Movella DOT CSV" if c.fmt == "movella_dot" else "generic IMU CSV"


def _from_csv(part: str, c: ImuCsv) -> _Imu:
    return _Imu(part, part, c.source, c.time_s, c.acc_mps2, c.acc_kind, c.gyr_rad_s, c.quat_wxyz)


def _specific_force_g(s: _Imu) -> np.ndarray:
    """``(N,)`` specific-force magnitude of an IMU's samples, g."""
    if s.acc_kind == "specific_force":
        f = s.acc
    elif s.acc_kind == "free_earth":
        f = s.acc + GRAVITY * _UP
    else:  # free in the sensor frame: gravity back through the orientation (reference z up)
        f = np.einsum("nij,nj->ni", quat_to_matrix(s.quat), s.acc) + GRAVITY * _UP
    return np.linalg.norm(f, axis=1) / GRAVITY


def _landing(name: str, file: str, moticon: MoticonExport | None, sources: list[_Imu],
             settings: SyncSettings) -> Landing:  # fmt: skip
    """The first landing of a stream (the insole file: the mean of its two IMUs' landings, or by
    the total force without IMUs)."""
    if name == INSOLES:
        assert moticon is not None
        found = []
        for side in moticon.sides.values():
            if side.acc_mps2 is None:
                continue
            ok = side.valid & np.isfinite(side.acc_mps2).all(1)
            sig = np.linalg.norm(side.acc_mps2[ok], axis=1) / GRAVITY
            got = find_landings(moticon.time_s[ok], sig, settings)
            if got:
                found.append(got[0])
        if found:
            return Landing(float(np.mean([f.time_s for f in found])),
                           float(np.mean([f.peak for f in found])),
                           float(np.mean([f.flight_s for f in found])))  # fmt: skip
        has_imu = any(s.acc_mps2 is not None for s in moticon.sides.values())
        if not has_imu:
            got = find_landings(moticon.time_s, _force_bw(moticon),
                                SyncSettings(flight_below=0.1, min_flight_s=settings.min_flight_s,
                                             peak_above=settings.peak_above,
                                             peak_within_s=settings.peak_within_s,
                                             search_s=settings.search_s))  # fmt: skip
            if got:
                return got[0]
        what = "insole accelerations" if has_imu else "insole force"
    else:
        s = next(s for s in sources if s.stream == name)
        got = find_landings(s.time_s, _specific_force_g(s), settings)
        if got:
            return got[0]
        what = "accelerations"
    raise DeviceFileError(
        f"{file}: no jump found in the first {settings.search_s:g} s of its {what} (a flight "
        f"below {settings.flight_below:g} g for at least {settings.min_flight_s:g} s, then a "
        f"landing peak above {settings.peak_above:g} g within {settings.peak_within_s:g} s): "
        "jump once after the still T-pose with the arms still, or import files recorded on one "
        "clock without synchronisation (--no-sync)"
    )


def _force_bw(m: MoticonExport) -> np.ndarray:
    """Both insoles' total force per row over its median in the first second (the still pose),
    NaN where a side has no sample."""
    total = np.zeros(len(m.time_s))
    for side in m.sides.values():
        f = side.total_force_n if side.total_force_n is not None else np.nansum(
            side.pressure_n_cm2, axis=1)  # fmt: skip
        total = total + np.where(side.valid, f, np.nan)
    first = (m.time_s - m.time_s[0] < 1.0) & np.isfinite(total)
    level = float(np.median(total[first])) if first.any() else float(np.nanmedian(total))
    return total / (level if level > 0 else 1.0)


def _resample_imu(s: _Imu, t: np.ndarray) -> dict[str, np.ndarray | None]:
    out: dict[str, np.ndarray | None] = {
        "acc": resample_linear(s.time_s, s.acc, t),
        "gyr": None if s.gyr is None else resample_linear(s.time_s, s.gyr, t),
        "rot": None if s.quat is None else quat_to_matrix(resample_quats(s.time_s, s.quat, t)),
    }
    return out


def _still(acc: np.ndarray, gyr: np.ndarray | None, rot: np.ndarray | None, kind: str,
           fps: float) -> np.ndarray:  # fmt: skip
    rate = np.linalg.norm(gyr if gyr is not None else angular_velocity(rot, fps), axis=1)
    mag = np.linalg.norm(acc, axis=1)
    level = np.abs(mag - GRAVITY) if kind == "specific_force" else mag
    return (rate < STILL_GYR_RAD_S) & (level < STILL_ACC_MPS2)


def _calibration_start(still: np.ndarray, win: int, jump_frame: int | None, grid: np.ndarray,
                       ref_shift: float, options: ImportOptions,
                       files: list[str]) -> tuple[int, int]:  # fmt: skip
    """First frame of the calibration window and the length of the still run there."""
    n = len(still)
    if options.calib_at_s is not None:
        c0 = round((options.calib_at_s - ref_shift - grid[0]) * options.fps)
        if not 0 <= c0 <= n - win:
            raise DeviceFileError(
                f"calibration start {options.calib_at_s:g} s is outside the span all files "
                f"cover ({grid[0] + ref_shift:.3f}..{grid[-1] + ref_shift - win / options.fps:.3f}"
                " s on the reference clock)"
            )
        run = still[c0:]
        length = int(np.argmin(run)) if not run.all() else len(run)
        return c0, length
    for a, b in still_runs(still):
        if b - a >= win and (jump_frame is None or a < jump_frame):
            return a, b - a
    where = "before the jump" if jump_frame is not None else "in the recording"
    raise DeviceFileError(
        f"no still window of {win / options.fps:g} s {where} in {', '.join(files) or 'the IMUs'} "
        f"(every IMU still: angular rate below {math.degrees(STILL_GYR_RAD_S):g} deg/s, "
        f"acceleration within {STILL_ACC_MPS2 / GRAVITY:g} g of 1 g): stand still in the T-pose "
        "for a second at the start, or give the calibration window's start (--calib-at)"
    )


def _check_gaps(t_common: np.ndarray, lo: float, hi: float, max_gap_s: float, file: str,
                label: str, shift: float) -> dict[str, float]:  # fmt: skip
    g = find_gaps(t_common)
    for gap in g.gaps:
        if gap.length_s > max_gap_s + 1e-9 and gap.end_s > lo and gap.start_s < hi:
            raise DeviceFileError(
                f"{file}: {label}: no samples from {gap.start_s + shift:.3f} s to "
                f"{gap.end_s + shift:.3f} s ({gap.length_s:.3f} s, {gap.missing} samples) inside "
                f"the recording; gaps up to {max_gap_s:g} s are interpolated"
            )
    return {"samples": g.samples, "rate_hz": round(g.rate_hz, 6), "missing": g.missing,
            "gaps": len(g.gaps), "longest_gap_s": round(g.longest_s, 6)}  # fmt: skip


def _calibrated_imu(s: _Imu, g: dict[str, np.ndarray | None], c0: int, win: int,
                    mount: np.ndarray, options: ImportOptions
                    ) -> tuple[ImuStream, dict[str, Any]]:  # fmt: skip
    from prism_tools.synth.config import ImuSynthConfig
    from prism_tools.synth.imu import lowpass_causal

    acc, gyr, rot = g["acc"], g["gyr"], g["rot"]
    window = slice(c0, c0 + win)
    bias = None if gyr is None else gyr[window].mean(axis=0)
    if rot is None:
        assert gyr is not None and bias is not None
        rot = gravity_filter(acc, gyr - bias, options.fps, c0, win, options.filter_gain)
        source = ("insole IMU, orientation filtered" if s.stream == INSOLES
                  else "IMU CSV, orientation filtered")  # fmt: skip
    else:
        source = "IMU CSV, device orientation"
    up = None
    if s.acc_kind == "specific_force":
        up = np.einsum("nij,nj->ni", rot[window], acc[window]).mean(axis=0)
    cal: SiteCalibration = calibrate_site(rot[window], mount, up, CANONICAL_TO_WORLD)
    rot, acc = rot[c0:], acc[c0:]
    ori = cal.orientation(rot)
    if s.acc_kind == "free_earth":
        f_world = cal.to_world(acc) + GRAVITY * _UP
    else:
        f_world = cal.to_world(np.einsum("nij,nj->ni", rot, acc))
        if s.acc_kind == "free_sensor":
            f_world = f_world + GRAVITY * _UP
    acc_world = f_world - GRAVITY * _UP
    cfg = ImuSynthConfig()
    foot = s.part in FEET
    acc_local = gyr_local = None
    if foot:
        acc_local = np.einsum("nji,nj->ni", ori, f_world)
        gyr_local = (gyr[c0:] @ cal.sensor_to_segment.T if gyr is not None
                     else angular_velocity(ori, options.fps, local=True))  # fmt: skip
    stream = ImuStream(
        acc_world_raw=acc_world,
        acc_world_filt=lowpass_causal(acc_world, options.fps, cfg.filt_cutoff_hz, cfg.filt_order),
        ori_world=np.ascontiguousarray(ori),
        acc_local_raw=acc_local,
        gyr_local_raw=gyr_local,
    )
    info = {"source": source, "file": s.file, "heading_deg": round(cal.heading_deg, 3),
            "ref_tilt_deg": round(cal.ref_tilt_deg, 3),
            "mount_error_deg": round(cal.mount_error_deg, 3),
            "gyro_bias_deg_s": None if bias is None else np.degrees(bias).round(4).tolist()}
    return stream, info  # fmt: skip
