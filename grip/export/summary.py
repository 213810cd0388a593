"""One-page PNG overview of a reconstruction (matplotlib, Agg canvas; no pyplot state).

Panels: the pelvis trajectory from above (world x-y) and its height over time; the vertical
ground reaction force of each foot against the insole force; the contact states of both feet
(reconstruction and insoles); the per-joint position errors. Ground-truth curves, the insole
force and the errors appear when a :class:`~grip.kinematics.features.GroundTruth` is given;
fall events (``recon.falls``: first replaced frame to detection frame) are shaded red on every
time axis and marked with a cross on the trajectory.

Errors are computed with :mod:`grip.core.metrics` on the method's own joint positions
(``recon.joint_pos``): MPJPE (world) and PEL-MPJPE (pelvis-relative), per joint and overall.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from grip.core import metrics as M
from grip.core import skeleton as sk
from grip.core.reconstruction import Reconstruction
from grip.export.common import ExportError, check_ground_truth, check_rotations, write_file
from grip.kinematics.features import GroundTruth

_REC_COLOR = "tab:blue"
_GT_COLOR = "black"
_FALL_COLOR = "tab:red"


def per_joint_errors(recon: Reconstruction, gt: GroundTruth) -> tuple[np.ndarray, np.ndarray]:
    """``(24,)`` MPJPE (world) and ``(24,)`` PEL-MPJPE per joint, mm."""
    check_ground_truth(recon, gt)
    return (np.asarray(M.mpjpe(recon.joint_pos, gt.joint_pos, per_joint=True)),
            np.asarray(M.pel_mpjpe(recon.joint_pos, gt.joint_pos, per_joint=True)))  # fmt: skip


def summary_stats(recon: Reconstruction, gt: GroundTruth | None = None) -> dict[str, float]:
    """The numbers the summary shows.

    Returns:
        ``frames``, ``duration_s``, ``falls`` (count), ``ms_per_frame``; with a ground truth
        also ``MPJPE_mm``, ``PEL_MPJPE_mm``; ``vGRF_N`` (mean |F_z - insole|, both feet) when
        the reconstruction has forces and the recording insoles; ``contact_agreement`` (fraction
        of foot-frames whose contact state equals the insole's) when both have contacts.
    """
    out: dict[str, float] = {
        "frames": float(recon.n_frames),
        "duration_s": recon.n_frames / recon.fps,
        "falls": float(recon.falls.shape[0]),
        "ms_per_frame": float(recon.ms_per_frame),
    }
    if gt is None:
        return out
    check_ground_truth(recon, gt)
    out["MPJPE_mm"] = float(M.mpjpe(recon.joint_pos, gt.joint_pos))
    out["PEL_MPJPE_mm"] = float(M.pel_mpjpe(recon.joint_pos, gt.joint_pos))
    if recon.grf is not None and gt.insole_force_n is not None:
        out["vGRF_N"] = M.vgrf_error(recon.grf[:, :, 2], gt.insole_force_n)
    if recon.contacts is not None and gt.insole_contacts is not None:
        out["contact_agreement"] = float(np.mean(recon.contacts == gt.insole_contacts))
    return out


def _shade_falls(ax, recon: Reconstruction) -> None:
    for a, b in recon.falls:
        ax.axvspan(a / recon.fps, (b + 1) / recon.fps, color=_FALL_COLOR, alpha=0.2, lw=0)


def _message(ax, text: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="0.4")
    ax.set_xticks([])
    ax.set_yticks([])


def _trajectory(ax, recon: Reconstruction, gt: GroundTruth | None) -> None:
    root = recon.root_pos
    ax.plot(root[:, 0], root[:, 1], color=_REC_COLOR, lw=1.5, label=recon.method)
    if gt is not None:
        ax.plot(gt.root_pos[:, 0], gt.root_pos[:, 1], color=_GT_COLOR, lw=1, ls="--",
                label="ground truth")  # fmt: skip
    ax.plot(*root[0, :2], "o", color=_REC_COLOR, ms=6, label="start")
    ax.plot(*root[-1, :2], "s", color=_REC_COLOR, ms=6, label="end")
    if recon.falls.shape[0]:
        det = recon.falls[:, 1]
        ax.plot(root[det, 0], root[det, 1], "x", color=_FALL_COLOR, ms=10, mew=2,
                label="recovery (fall or lost)")  # fmt: skip
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("world x (m)")
    ax.set_ylabel("world y (m)")
    ax.set_title("pelvis trajectory, top view")
    ax.legend(loc="best", fontsize=8)


def _height(ax, recon: Reconstruction, gt: GroundTruth | None, t: np.ndarray) -> None:
    ax.plot(t, recon.root_pos[:, 2], color=_REC_COLOR, lw=1.2, label=recon.method)
    if gt is not None:
        ax.plot(t, gt.root_pos[:, 2], color=_GT_COLOR, lw=1, ls="--", label="ground truth")
    _shade_falls(ax, recon)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("pelvis height (m)")
    ax.set_title("pelvis height (recoveries shaded)")
    ax.legend(loc="best", fontsize=8)


def _grf(ax, recon: Reconstruction, gt: GroundTruth | None, t: np.ndarray, foot: int) -> None:
    side = ("left", "right")[foot]
    insole = None if gt is None else gt.insole_force_n
    if recon.grf is None and insole is None:
        _message(ax, f"{side} foot: no forces\n({recon.method} gives none; "
                     "pass the recording for the insole force)")  # fmt: skip
        ax.set_title(f"vertical GRF, {side} foot")
        return
    if recon.grf is not None:
        ax.plot(t, recon.grf[:, foot, 2], color=_REC_COLOR, lw=1.2, label=f"{recon.method} GRF")
    else:
        ax.text(0.01, 0.95, f"{recon.method} gives no GRF", transform=ax.transAxes,
                va="top", fontsize=8, color="0.4")  # fmt: skip
    if insole is not None:
        ax.plot(t, insole[:, foot], color=_GT_COLOR, lw=1, ls="--", label="insole")
    _shade_falls(ax, recon)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("vertical force (N)")
    ax.set_title(f"vertical GRF, {side} foot")
    ax.legend(loc="best", fontsize=8)


def _contacts(ax, recon: Reconstruction, gt: GroundTruth | None, t: np.ndarray) -> None:
    lanes: list[tuple[str, np.ndarray, str]] = []
    if recon.contacts is not None:
        lanes += [(f"{recon.method} L", recon.contacts[:, 0], _REC_COLOR),
                  (f"{recon.method} R", recon.contacts[:, 1], _REC_COLOR)]  # fmt: skip
    if gt is not None and gt.insole_contacts is not None:
        lanes += [("insole L", gt.insole_contacts[:, 0], "0.3"),
                  ("insole R", gt.insole_contacts[:, 1], "0.3")]  # fmt: skip
    ax.set_title("foot contacts")
    if not lanes:
        _message(ax, "no contact states\n(none in the reconstruction, no recording given)")
        return
    dt = 1.0 / recon.fps
    for k, (_, on, color) in enumerate(lanes):
        y = len(lanes) - 1 - k
        ax.fill_between(t + dt / 2, y + 0.1, y + 0.9, where=on, step="mid", color=color,
                        alpha=0.8, lw=0)  # fmt: skip
    _shade_falls(ax, recon)
    ax.set_yticks(np.arange(len(lanes)) + 0.5, [n for n, _, _ in lanes][::-1])
    ax.set_ylim(0, len(lanes))
    ax.set_xlim(t[0], t[-1] + dt)
    ax.set_xlabel("time (s)")


def _errors(ax, recon: Reconstruction, gt: GroundTruth | None) -> None:
    ax.set_title("per-joint position error")
    if gt is None:
        _message(ax, "no ground truth (pass the recording with --gt)")
        return
    world, pel = per_joint_errors(recon, gt)
    x = np.arange(sk.N_JOINTS)
    ax.bar(x - 0.2, world, width=0.4, color=_REC_COLOR, label=f"MPJPE {world.mean():.1f} mm")
    ax.bar(x + 0.2, pel, width=0.4, color="tab:orange",
           label=f"PEL-MPJPE {pel.mean():.1f} mm")  # fmt: skip
    ax.set_xticks(x, sk.JOINT_NAMES, rotation=60, ha="right", fontsize=7)
    ax.set_ylabel("mean error (mm)")
    ax.legend(loc="best", fontsize=8)


def summary_figure(recon: Reconstruction, gt: GroundTruth | None = None) -> Figure:
    """The overview figure (see the module docstring); not attached to pyplot."""
    if gt is not None:
        check_ground_truth(recon, gt)
    stats = summary_stats(recon, gt)
    fig = Figure(figsize=(14, 12), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(3, 2)
    t = np.arange(recon.n_frames) / recon.fps
    _trajectory(axes[0, 0], recon, gt)
    _height(axes[0, 1], recon, gt, t)
    _grf(axes[1, 0], recon, gt, t, 0)
    _grf(axes[1, 1], recon, gt, t, 1)
    _contacts(axes[2, 0], recon, gt, t)
    _errors(axes[2, 1], recon, gt)
    head = (f"{recon.name} ({recon.method}): {recon.n_frames} frames, {stats['duration_s']:.2f} s "
            f"at {recon.fps:g} Hz, {int(stats['falls'])} recovery event(s)")  # fmt: skip
    lost = int(recon.notes.get("lost", 0))
    if lost:
        head += f" ({lost} lost, not fallen)"
    if recon.ms_per_frame:
        head += f", {recon.ms_per_frame:.2f} ms/frame"
    labels = {"MPJPE_mm": "MPJPE {:.1f} mm", "PEL_MPJPE_mm": "PEL-MPJPE {:.1f} mm",
              "vGRF_N": "vGRF error {:.1f} N"}  # fmt: skip
    extra = [fmt.format(stats[k]) for k, fmt in labels.items() if k in stats]
    if "contact_agreement" in stats:
        extra.append(f"contact agreement {100 * stats['contact_agreement']:.1f} %")
    fig.suptitle(head + ("\n" + ", ".join(extra) if extra else ""))
    return fig


def write_summary_png(
    recon: Reconstruction,
    path: str | os.PathLike,
    *,
    gt: GroundTruth | None = None,
    dpi: int = 100,
) -> dict[str, float]:
    """Draw :func:`summary_figure` and write it as a PNG, atomically.

    Returns:
        :func:`summary_stats` of the reconstruction.

    Raises:
        ExportError: The file cannot be written (the message names it), a rotation is no
            rotation, or ``gt`` does not cover the reconstruction's frames.
    """
    path = Path(path)
    check_rotations(recon, path)
    fig = summary_figure(recon, gt)
    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", dpi=dpi)
    except (ValueError, RuntimeError) as e:
        raise ExportError(f"{path}: cannot draw the summary ({e})") from e
    data = buf.getvalue()
    write_file(path, lambda f: f.write(data))
    return summary_stats(recon, gt)
