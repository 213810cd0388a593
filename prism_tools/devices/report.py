"""What :func:`prism_tools.devices.importer.import_devices` reports: one
:class:`StreamReport` per file and the :class:`ImportReport` of the import (stored in the
recording's ``extras["device_import"]``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["ImportReport", "StreamReport"]


@dataclass(frozen=True)
class StreamReport:
    """One file as imported.

    Attributes:
        name: ``"insoles"`` or the IMU part.
        file: The file.
        kind: ``"Moticon OpenGo text export"``, ``"Movella DOT CSV"``, ``"generic IMU CSV"``.
        channels: Channel group (``"L_Foot insole"``, ``"IMU"``, ...) -> ``{"samples", "rate_hz",
            "missing", "gaps", "longest_gap_s"}`` over the whole file.
        dropped_rows: Rows dropped for missing values (IMU CSVs).
        landing_s: The jump's landing on the file's clock, s (``None`` without sync).
        offset_s: The file's clock minus the reference file's, s.
    """

    name: str
    file: str
    kind: str
    channels: dict[str, dict[str, float]]
    dropped_rows: int
    landing_s: float | None
    offset_s: float


@dataclass(frozen=True)
class ImportReport:
    """What :func:`import_devices` did, for the summary and ``extras["device_import"]``.

    Attributes:
        streams: One per file.
        reference: Name of the reference stream (its clock is the recording's).
        fps: Output frame rate, Hz.
        frames: Output frames.
        start_reference_s: Frame 0 on the reference clock, s.
        jump_frame: The landing's output frame (``None`` without sync).
        calib_frames: The calibration window's frames ``[start, stop)`` (start = 0).
        still_s: Length of the still run it was taken from, s.
        subject_mass_kg: The mass used.
        mass_source: ``"given"``, ``"insoles"`` or ``"default"``.
        sites: Part -> ``{"source", "heading_deg", "ref_tilt_deg", "mount_error_deg",
            "gyro_bias_deg_s"}``.
        notes: Warnings for the user.
    """

    streams: tuple[StreamReport, ...]
    reference: str
    fps: float
    frames: int
    start_reference_s: float
    jump_frame: int | None
    calib_frames: tuple[int, int]
    still_s: float
    subject_mass_kg: float
    mass_source: str
    sites: dict[str, dict[str, Any]]
    notes: tuple[str, ...] = ()

    @property
    def duration_s(self) -> float:
        return self.frames / self.fps

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "streams": [vars(s) for s in self.streams],
            "reference": self.reference, "fps": self.fps, "frames": self.frames,
            "start_reference_s": self.start_reference_s, "jump_frame": self.jump_frame,
            "calib_frames": list(self.calib_frames), "still_s": self.still_s,
            "subject_mass_kg": self.subject_mass_kg, "mass_source": self.mass_source,
            "sites": self.sites, "notes": list(self.notes),
        }  # fmt: skip
