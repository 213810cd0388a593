"""Plots of the evaluations: per-joint errors and a sample segment (``grip bench``), errors per
category (``grip kin eval``)."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from grip.core import skeleton as sk
from grip.core.reconstruction import Reconstruction
from grip.eval.runner import MethodRun, recon_file
from grip.eval.scoring import FEET
from grip.eval.segments import Segment
from grip.kinematics.features import ground_truth

__all__ = ["plot_categories", "plot_per_joint", "plot_sample"]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_per_joint(summary: Mapping[str, Mapping], out_png: str | os.PathLike) -> None:
    """Grouped bars of the per-joint PEL-MPJPE and MPJRE of every method."""
    plt = _pyplot()
    labels = [k for k, s in summary.items() if s["per_joint"]]
    fig, axes = plt.subplots(1, 2, figsize=(14, 8), constrained_layout=True)
    y = np.arange(len(sk.JOINT_NAMES))
    h = 0.8 / max(len(labels), 1)
    for ax, key, xlabel in ((axes[0], "PEL_MPJPE_mm", "PEL-MPJPE (mm)"),
                            (axes[1], "MPJRE_deg", "MPJRE (deg)")):  # fmt: skip
        for i, label in enumerate(labels):
            ax.barh(y + (i - (len(labels) - 1) / 2) * h, summary[label]["per_joint"][key],
                    height=h, label=label)  # fmt: skip
        ax.set_yticks(y, sk.JOINT_NAMES)
        ax.invert_yaxis()
        ax.set_xlabel(xlabel)
        if labels:
            ax.legend()
        else:
            ax.text(0.5, 0.5, "no finished segment", ha="center", transform=ax.transAxes)
    fig.suptitle("Per-joint errors (means over segments)")
    fig.savefig(out_png, dpi=80)
    plt.close(fig)


def plot_sample(
    out_dir: str | os.PathLike,
    runs: Sequence[MethodRun],
    seg: Segment,
    traj_png: str | os.PathLike,
    grf_png: str | os.PathLike,
) -> None:
    """Pelvis trajectory (top view, height) and vertical GRF per foot of the sample segment:
    the ground truth (insole force) against each method's saved reconstruction."""
    from prism_tools.io import load_recording

    plt = _pyplot()
    rec = load_recording(seg.path).slice_frames(seg.start, seg.stop)
    gt = ground_truth(rec)
    t = np.arange(seg.n_frames) / gt.fps
    recons = {}
    for run in runs:
        p = recon_file(Path(out_dir), run.label, seg.id)
        if p.is_file():
            recons[run.label] = Reconstruction.load(p)
    fig, (ax_xy, ax_z) = plt.subplots(1, 2, figsize=(13, 5.5), constrained_layout=True)
    ax_xy.plot(*gt.joint_pos[:, 0, :2].T, "k-", lw=2, label="ground truth")
    ax_z.plot(t, gt.joint_pos[:, 0, 2], "k-", lw=2, label="ground truth")
    for label, r in recons.items():
        ax_xy.plot(*r.root_pos[:, :2].T, label=label)
        ax_z.plot(t, r.root_pos[:, 2], label=label)
    ax_xy.plot(*gt.joint_pos[0, 0, :2], "ko")
    ax_xy.set(xlabel="x (m)", ylabel="y (m)", title="pelvis, top view (dot: start)")
    ax_xy.axis("equal")
    ax_z.set(xlabel="time (s)", ylabel="pelvis height (m)", title="pelvis height")
    ax_xy.legend()
    fig.suptitle(f"sample segment {seg.id} ({seg.category})", fontsize=10)
    fig.savefig(traj_png, dpi=80)
    plt.close(fig)

    fig, axes = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True, constrained_layout=True)
    with_forces = {k: r for k, r in recons.items() if r.grf is not None}
    for i, (ax, foot) in enumerate(zip(axes, FEET, strict=True)):
        if gt.insole_force_n is not None:
            ax.plot(t, gt.insole_force_n[:, i], "k-", lw=2, label="insole")
        for label, r in with_forces.items():
            ax.plot(t, r.grf[:, i, 2], label=label)
        ax.set(ylabel=f"{foot} vertical force (N)")
        ax.legend(loc="upper right")
    axes[-1].set_xlabel("time (s)")
    note = "" if with_forces else " (no method outputs forces)"
    fig.suptitle(f"vertical ground reaction force{note}\nsample segment {seg.id}", fontsize=10)
    fig.savefig(grf_png, dpi=80)
    plt.close(fig)


def plot_categories(agg: dict, out_png) -> None:
    """Bar chart of PEL-MPJPE and MPJRE per category (``grip kin eval``'s summary)."""
    plt = _pyplot()
    cats = list(agg["categories"])
    fig, axes = plt.subplots(1, 2, figsize=(14, max(4, 0.3 * len(cats))), constrained_layout=True)
    for ax, key, label in ((axes[0], "PEL_MPJPE_mm", "PEL-MPJPE (mm)"),
                           (axes[1], "MPJRE_deg", "MPJRE (deg)")):  # fmt: skip
        ax.barh(cats, [agg["categories"][c][key] for c in cats], color="tab:blue")
        ax.axvline(agg["overall"][key], color="k", ls="--", lw=1, label="all")
        ax.set_xlabel(label)
        ax.invert_yaxis()
        ax.legend()
    fig.suptitle("KinematicsNet error per motion category (test split)")
    fig.savefig(out_png, dpi=90)
    plt.close(fig)
