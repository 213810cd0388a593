"""Plots of one PRISM-format recording: sensor streams, insole pressure and the skeleton."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from grip.core import skeleton as sk

_MAIN_PARTS = ("L_Foot", "R_Foot", "L_Wrist", "R_Wrist")


def recording_skeleton(rec) -> np.ndarray:
    """Joint positions ``(F, 24, 3)`` of a recording's ground-truth pose on our body model.

    SMPL ``poses`` apply joint by joint (same topology); the rest skeleton is this project's
    anthropometric body for the subject's height and weight, not SMPL's shape.
    """
    from grip.core.body import BodyParams, build_body
    from grip.core.fk import forward_kinematics
    from grip.core.rotations import axis_angle_to_matrix

    sp = rec.require_ground_truth("the skeleton plot")
    height = rec.subject.height_m or 1.70
    mass = rec.subject.weight_kg or 70.0
    body = build_body(BodyParams(height_m=float(height), mass_kg=float(mass)))
    rot = axis_angle_to_matrix(np.asarray(sp.poses, dtype=np.float64).reshape(-1, 24, 3))
    root = np.asarray(sp.trans, dtype=np.float64) + np.asarray(sp.root_offset, dtype=np.float64)
    return forward_kinematics(rot, root, body.offsets)[1]


def plot_recording(rec, out_png: str | os.PathLike, title: str | None = None) -> Path:
    """Draw a recording to a PNG and return its path.

    Panels: free acceleration of the four main IMUs, their orientation (angle from the first
    frame), vertical force of each insole with its contact states, the 16-cell pressure of both
    insoles over time, both CoP paths in the insole frame, and the skeleton at a few instants
    (a note instead for a recording without ground truth).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from grip.core.rotations import geodesic_angle

    out_png = Path(out_png)
    f = rec.n_frames
    t = np.arange(f) / rec.fps
    fig = plt.figure(figsize=(15, 11), constrained_layout=True)
    gs = fig.add_gridspec(3, 3)
    fig.suptitle(title or f"{rec.name}  ({f} frames, {rec.fps:g} Hz, category: {rec.category})")

    ax = fig.add_subplot(gs[0, 0:2])
    for part in _MAIN_PARTS:
        if part in rec.imu:
            ax.plot(t, np.linalg.norm(rec.imu[part].acc_world_raw, axis=-1), lw=0.8, label=part)
    ax.set_ylabel("|free acceleration| (m/s²)")
    ax.set_xlabel("time (s)")
    ax.legend(loc="upper right", fontsize=8, ncol=4)
    ax.set_title("IMU free acceleration, world frame (raw, with noise if synthesised)")

    ax = fig.add_subplot(gs[1, 0:2])
    for part in _MAIN_PARTS:
        if part in rec.imu:
            ori = rec.imu[part].ori_world
            ax.plot(t, np.rad2deg(geodesic_angle(ori[:1], ori)), lw=0.8, label=part)
    ax.set_ylabel("orientation change (deg)")
    ax.set_xlabel("time (s)")
    ax.set_title("IMU orientation: angle from the first frame")
    ax.legend(loc="upper right", fontsize=8, ncol=4)

    ax = fig.add_subplot(gs[2, 0:2])
    colors = {"L_Foot": "tab:blue", "R_Foot": "tab:red"}
    for foot in sk.FEET:
        if foot not in rec.insole:
            continue
        ins = rec.insole[foot]
        c = colors[foot]
        ax.plot(t, np.asarray(ins.force).reshape(-1), color=c, lw=1.0, label=f"{foot} force")
        cont = np.asarray(ins.contacts, dtype=bool)
        base = -0.08 if foot == "L_Foot" else -0.16
        ax.fill_between(t, base, base + 0.03, where=cont[:, 1], color=c, alpha=0.35, lw=0,
                        step="mid", label=f"{foot} back contact")  # fmt: skip
        ax.fill_between(t, base + 0.035, base + 0.065, where=cont[:, 0], color=c, alpha=0.7,
                        lw=0, step="mid", label=f"{foot} front contact")  # fmt: skip
    if rec.insole and all(ft in rec.insole for ft in sk.FEET):
        total = sum(np.asarray(rec.insole[ft].force).reshape(-1) for ft in sk.FEET)
        ax.plot(t, total, color="k", lw=0.8, ls="--", label="total")
    ax.axhline(1.0, color="gray", lw=0.5)
    ax.set_ylabel("vertical force (body weights)")
    ax.set_xlabel("time (s)")
    ax.set_title("Insoles: force and contacts (front = cells 8-15, back = cells 0-3)")
    ax.legend(loc="upper right", fontsize=7, ncol=4)

    ax = fig.add_subplot(gs[0, 2])
    cells = [np.asarray(rec.insole[ft].forces) for ft in sk.FEET if ft in rec.insole]
    if cells:
        img = np.concatenate(cells, axis=1).T
        im = ax.imshow(img, aspect="auto", origin="lower", cmap="magma",
                       extent=(0, f / rec.fps, -0.5, img.shape[0] - 0.5))  # fmt: skip
        ax.axhline(15.5, color="w", lw=0.8)
        ax.set_yticks([0, 8, 15, 16, 24, 31], ["L0", "L8", "L15", "R0", "R8", "R15"])
        fig.colorbar(im, ax=ax, fraction=0.046)
    ax.set_xlabel("time (s)")
    ax.set_title("Insole cells (0-3 heel ... 13-15 toes)")

    ax = fig.add_subplot(gs[1, 2])
    for foot in sk.FEET:
        if foot in rec.insole:
            cop = np.asarray(rec.insole[foot].CoP)
            load = np.asarray(rec.insole[foot].force).reshape(-1) > 0.02
            side = -1.0 if foot == "L_Foot" else 1.0
            ax.scatter(side * 0.1 + cop[load, 1], cop[load, 0], s=2, color=colors[foot],
                       label=foot)  # fmt: skip
    ax.set_aspect("equal")
    ax.set_xlabel("medial (m), feet drawn apart")
    ax.set_ylabel("forward (m)")
    ax.set_title("Centre of pressure, insole frame")
    ax.legend(fontsize=8)

    if rec.smpl_params is None:
        ax = fig.add_subplot(gs[2, 2])
        ax.axis("off")
        ax.text(0.5, 0.5, "no ground truth\n(sensors only): no skeleton", ha="center",
                va="center", fontsize=11)  # fmt: skip
        return _save(fig, out_png)
    ax = fig.add_subplot(gs[2, 2], projection="3d")
    joints = recording_skeleton(rec)
    snaps = np.linspace(0, f - 1, min(6, f)).astype(int)
    cmap = plt.get_cmap("viridis")
    for i, fr in enumerate(snaps):
        col = cmap(i / max(len(snaps) - 1, 1))
        for j in range(1, 24):
            p = sk.PARENTS[j]
            seg = joints[fr, [p, j]]
            ax.plot(seg[:, 0], seg[:, 1], seg[:, 2], color=col, lw=1.2)
    ax.plot(joints[:, 0, 0], joints[:, 0, 1], np.zeros(f), color="gray", lw=0.8)
    objects = _draw_objects(ax, rec.objects)
    pts = joints.reshape(-1, 3) if objects is None else np.concatenate([joints.reshape(-1, 3),
                                                                        objects])  # fmt: skip
    lo, hi = pts.min(0), pts.max(0)
    mid = (lo + hi) / 2
    half = np.maximum((hi - lo)[:2] / 2 + 0.2, 0.6)
    top = max(float(hi[2]) + 0.1, 1.0)
    ax.set_xlim(mid[0] - half[0], mid[0] + half[0])
    ax.set_ylim(mid[1] - half[1], mid[1] + half[1])
    ax.set_zlim(min(0.0, float(lo[2])), top)
    ax.set_box_aspect((2 * half[0], 2 * half[1], top - min(0.0, float(lo[2]))))
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    props = " and its props (grey)" if objects is not None else ""
    ax.set_title(f"Skeleton (ground truth) at 6 instants{props}")
    return _save(fig, out_png)


def _draw_objects(ax, objects) -> np.ndarray | None:
    """Draw a recording's scene objects (props: boxes; any mesh) as grey triangles on a 3-D
    axis; returns their vertices ``(N, 3)`` (``None`` without objects)."""
    if not objects:
        return None
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    verts = []
    for obj in objects.values():
        v, faces = np.asarray(obj.vertices, dtype=np.float64), np.asarray(obj.faces)
        ax.add_collection3d(Poly3DCollection(v[faces], facecolor="0.6", edgecolor="0.35",
                                             alpha=0.35, lw=0.4))  # fmt: skip
        verts.append(v)
    return np.concatenate(verts)


def _save(fig, out_png: Path) -> Path:
    """Write the figure atomically (a temporary file moved over ``out_png``) and close it."""
    import matplotlib.pyplot as plt

    out_png.parent.mkdir(parents=True, exist_ok=True)
    tmp = out_png.with_name(f".{out_png.stem}.tmp.png")
    fig.savefig(tmp, dpi=90)
    plt.close(fig)
    os.replace(tmp, out_png)
    return out_png
