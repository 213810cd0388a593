"""Sensor-configuration sweep in the spirit of GRIP Table 3.

IMUs are added in GRIP's order: both feet (2), the left wrist (3), the right wrist (4), the pelvis
(5), the head (6); each set is trained and evaluated with and without the insoles. A sweep folder
holds one training run per configuration, named by :func:`run_name` (``imu4_press``...).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

IMU_ORDER: tuple[str, ...] = ("L_Foot", "R_Foot", "L_Wrist", "R_Wrist", "Pelvis", "Head")
"""GRIP's order of adding IMUs (Sec. 4, sensor configuration analysis)."""

DEFAULT_COUNTS: tuple[int, ...] = (2, 3, 4, 6)


@dataclass(frozen=True)
class SensorSet:
    """One sweep configuration: the first ``n_imu`` sites of :data:`IMU_ORDER` +- insoles."""

    n_imu: int
    insoles: bool

    @property
    def sites(self) -> tuple[str, ...]:
        return IMU_ORDER[: self.n_imu]

    @property
    def name(self) -> str:
        return run_name(self.n_imu, self.insoles)


def run_name(n_imu: int, insoles: bool) -> str:
    """Folder name of a configuration inside a sweep folder."""
    return f"imu{n_imu}_{'press' if insoles else 'nopress'}"


def sensor_sets(counts: tuple[int, ...] = DEFAULT_COUNTS) -> list[SensorSet]:
    """Configurations of a sweep, without insoles first (as in GRIP Table 3)."""
    for n in counts:
        if not 1 <= n <= len(IMU_ORDER):
            raise ValueError(f"IMU count {n} outside 1..{len(IMU_ORDER)}")
    return [SensorSet(n, p) for p in (False, True) for n in counts]


def parse_counts(text: str) -> tuple[int, ...]:
    """``"2,3,4,6"`` -> (2, 3, 4, 6) with a clear error."""
    try:
        counts = tuple(int(t) for t in text.split(",") if t.strip())
    except ValueError as e:
        raise ValueError(f"--imus: expected comma-separated integers, got {text!r}") from e
    if not counts:
        raise ValueError("--imus: no IMU count given")
    sensor_sets(counts)
    return counts


def find_runs(sweep_dir: str | Path) -> list[tuple[SensorSet, Path]]:
    """The configurations of a sweep folder that have a checkpoint (best.pt, else last.pt)."""
    sweep_dir = Path(sweep_dir)
    found = []
    for s in sensor_sets(tuple(range(1, len(IMU_ORDER) + 1))):
        for ck in ("best.pt", "last.pt"):
            p = sweep_dir / s.name / ck
            if p.is_file():
                found.append((s, p))
                break
    found.sort(key=lambda t: (t[0].insoles, t[0].n_imu))
    return found


def sweep_table(results: list[tuple[SensorSet, dict]]) -> str:
    """Markdown table laid out like GRIP Table 3 (plus MPJRE and the root-relative error)."""
    lines = [
        "| #IMU | insoles | MPJPE (mm) | PA-MPJPE (mm) | PEL-MPJPE (mm) | MPJRE (deg) "
        "| leaf vel. (m/s) | frames |",
        "|---:|:---:|---:|---:|---:|---:|---:|---:|",
    ]
    for s, m in results:
        lines.append(
            f"| {s.n_imu} | {'yes' if s.insoles else 'no'} | {m['MPJPE_mm']:.1f} | "
            f"{m['PA_MPJPE_mm']:.1f} | {m['PEL_MPJPE_mm']:.1f} | {m['MPJRE_deg']:.2f} | "
            f"{m['leaf_vel_err_mps']:.3f} | {m['frames']} |"
        )
    return "\n".join(lines)
