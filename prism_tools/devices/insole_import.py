"""The insole half of :func:`prism_tools.devices.importer.import_devices`: a Moticon export's
pressures, total force, CoP and step events on the recording's frames, as a PRISM insole
stream (the importer's step 6).

numpy and :mod:`grip.core` only (and the synthetic data's insole settings).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from grip.core.body import CANONICAL_TO_WORLD
from grip.core.rotations import resample_linear
from prism_tools.devices.moticon import MoticonExport
from prism_tools.streams import FEET, GRAVITY, InsoleStream, contacts_from_cells

__all__ = ["insole_steps", "insole_stream", "resample_insole"]


def resample_insole(m: MoticonExport, foot: str, t: np.ndarray,
                    area_cm2: np.ndarray) -> dict[str, np.ndarray]:  # fmt: skip
    """One side of the insole export on the times ``t``: ``"pressure"`` ``(T, 16)`` N/cm^2,
    ``"total_n"`` ``(T,)`` N and, where exported, ``"cop_norm"`` ``(T, 2)`` (linear
    interpolation of the valid rows)."""
    side = m.sides[foot]
    ok = side.valid
    times = m.time_s[ok]
    p = side.pressure_n_cm2[ok]
    out = {"pressure": resample_linear(times, p, t)}
    cells_n = p * area_cm2
    total = side.total_force_n[ok] if side.total_force_n is not None else cells_n.sum(axis=1)
    total = np.where(np.isfinite(total), total, cells_n.sum(axis=1))
    out["total_n"] = resample_linear(times, total, t)
    if side.cop_norm is not None:
        cop = side.cop_norm[ok]
        cop = np.where(np.isfinite(cop), cop, 0.0)
        out["cop_norm"] = resample_linear(times, cop, t)
    return out


def insole_stream(g: dict[str, np.ndarray], foot: str, c0: int, body: Any,
                  mass: float) -> InsoleStream:  # fmt: skip
    """The PRISM insole stream of one side from frame ``c0`` on (see the importer's step 6)."""
    from grip.core import skeleton as sk
    from prism_tools.synth.config import InsoleSynthConfig

    cfg = InsoleSynthConfig()
    f = FEET.index(foot)
    cells = g["pressure"][c0:] * body.insole_area_cm2[f]
    total = np.maximum(g["total_n"][c0:], 0.0)
    s = cells.sum(axis=1)
    cells = np.where((s > 0)[:, None], cells * (total / np.where(s > 0, s, 1.0))[:, None], 0.0)
    dims = np.array([body.foot_length, body.foot_width])
    loaded = total >= cfg.cop_min_force_n
    if "cop_norm" in g:
        cop = g["cop_norm"][c0:] * dims
    else:
        uv = sk.INSOLE_CELL_UV * dims
        cop = cells @ uv / np.where(s > 0, cells.sum(axis=1), 1.0)[:, None]
    cop = np.where(loaded[:, None], cop, 0.0)
    bw = mass * GRAVITY
    force = total / bw
    origin = CANONICAL_TO_WORLD @ (body.rest_joint_pos[sk.FOOT_BODY[foot]] + body.insole_origin[f])
    axes = CANONICAL_TO_WORLD @ body.insole_axes[f].T  # (3, 2): forward, medial
    force_world = np.zeros((len(force), 3))
    force_world[:, 2] = force
    return InsoleStream(
        contacts=contacts_from_cells(cells, cfg.contact_threshold_n),
        force=force[:, None],
        forces=cells / bw,
        CoP=cop,
        force_world=force_world,
        CoP_world=origin + cop @ axes.T,
    )


def insole_steps(m: MoticonExport | None, grid: np.ndarray, shift: float, c0: int, n: int,
                 fps: float) -> dict[str, dict[str, list[int]]]:  # fmt: skip
    """Moticon's step events as output frames ``{foot: {"heel_strike": [...], "toe_off": [...]}}``
    (feet without events left out)."""
    if m is None:
        return {}
    out: dict[str, dict[str, list[int]]] = {}
    for foot, side in m.sides.items():
        ev = {}
        for key, rows in (("heel_strike", side.heel_strike_rows), ("toe_off", side.toe_off_rows)):
            frames = np.round((m.time_s[rows] - shift - grid[c0]) * fps).astype(np.int64)
            ev[key] = [int(x) for x in frames if 0 <= x < n]
        if ev["heel_strike"] or ev["toe_off"]:
            out[foot] = ev
    return out
