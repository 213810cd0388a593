"""Physical plausibility of retargeted motions: foot sliding, floor penetration, floating.

numpy only. All heights are in the z-up world of :class:`~grip.motion.motion.Motion` with the
floor at z = 0. Feet are represented by the 6 sole corner points of each foot of the body model
(:func:`grip.core.fk.sole_points`: heel corners and toe-base corners on the foot, toe-tip corners
on the toes).

Definitions (per clip):

* contact (height + speed rule): a sole point touches when it is below ``contact_height_m``
  (2 cm); a foot is in contact in a frame when any of its sole points touches and the foot (mean
  of its 6 sole points) moves horizontally slower than ``contact_speed_mps`` (1 m/s). The speed
  cap keeps a swing foot that brushes the floor at walking speed out (real toe clearance in gait
  is 1-2 cm at ~4 m/s); a foot gliding faster than 1 m/s is stepping, not sliding.
* foot sliding ``fs_mps``: mean horizontal speed (m/s) of the touching sole points, averaged
  over those points per foot-frame and then over all contact foot-frames. Using only the points
  that touch keeps heel-to-toe roll (the heel lifts while the toes stay put) from counting as
  sliding.
* penetration ``fp_mean_mm`` / ``fp_max_mm``: ``max(0, -lowest sole point)`` in mm, mean over all
  frames and maximum.
* ``contact_fraction``: fraction of frames with at least one foot in contact.
* support frames: frames where the lower foot's lowest sole point moves horizontally slower than
  ``support_speed_mps`` (0.3 m/s), i.e. the foot looks planted whatever its height.
  ``float_mm``: mean height above the floor (0 when below) of the lowest sole point over support
  frames, mm: a planted foot hovering above the floor. ``stance_height_median_m``: the signed
  median of that height over support frames (0 for a perfectly placed floor). Jumps in place can
  have slow feet in the air and feet resting on steps or stools (not in the data) count as
  floating, so ``float_mm`` is meaningful for locomotion and standing clips on flat ground.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from grip.core.body import BodyModel
from grip.core.fk import body_points, sole_points
from grip.motion.motion import Motion

CONTACT_HEIGHT_M = 0.02
CONTACT_SPEED_MPS = 1.0
SUPPORT_SPEED_MPS = 0.3


def body_low_points(global_rot: np.ndarray, joint_pos: np.ndarray, body: BodyModel) -> np.ndarray:
    """Points that can be the lowest point of the body: sole corners and shape bottoms.

    Capsule end points and sphere centres are lowered by their radius (the lowest point of a
    capsule is its lower end point minus the radius along z), boxes contribute their 8 corners.

    Args:
        global_rot: ``(..., 24, 3, 3)`` global body rotations, z-up world.
        joint_pos: ``(..., 24, 3)`` joint positions, m.
        body: The body model.

    Returns:
        ``(..., P, 3)`` candidate points, z-up world, m (P = 12 sole points + shape points).
    """
    bodies: list[int] = []
    local: list[np.ndarray] = []
    drop: list[float] = []
    for g in body.geoms:
        if g.kind == "capsule":
            a, b = g.fromto()[:3], g.fromto()[3:]
            bodies += [g.body, g.body]
            local += [a, b]
            drop += [float(g.size[0])] * 2
        elif g.kind == "sphere":
            bodies.append(g.body)
            local.append(g.pos)
            drop.append(float(g.size[0]))
        else:
            signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1], indexing="ij")).reshape(3, -1).T
            for s in signs:
                bodies.append(g.body)
                local.append(g.pos + s * g.size[:3])
                drop.append(0.0)
    pts = body_points(global_rot, joint_pos, np.array(bodies), np.array(local))
    pts[..., 2] -= np.array(drop)
    soles = sole_points(global_rot, joint_pos, body)
    soles = soles.reshape(*soles.shape[:-3], 12, 3)
    return np.concatenate([soles, pts], axis=-2)


def foot_metrics(
    motion: Motion,
    body: BodyModel | None = None,
    contact_height_m: float = CONTACT_HEIGHT_M,
    contact_speed_mps: float = CONTACT_SPEED_MPS,
    support_speed_mps: float = SUPPORT_SPEED_MPS,
) -> dict:
    """Foot sliding, penetration, contact and floating of one motion (definitions: module doc).

    Args:
        motion: A :class:`~grip.motion.motion.Motion` (z-up world, floor at z = 0).
        body: Its body model (built from ``motion.body`` if None).
        contact_height_m: Sole points below this height touch the floor, m.
        contact_speed_mps: A foot moving horizontally faster than this is not in contact, m/s.
        support_speed_mps: Horizontal speed below which the lowest sole point counts as
            planted, m/s.

    Returns:
        ``name``, ``category``, ``n_frames``, ``duration_s``, ``fs_mps``, ``fp_mean_mm``,
        ``fp_max_mm``, ``contact_fraction``, ``float_mm``, ``stance_height_median_m`` and the
        counts used as weights by :func:`summarize`: ``n_contact_foot_frames``,
        ``n_support_frames``. Rates without any qualifying frame are NaN.
    """
    body = body or motion.body_model()
    g_rot, j_pos = motion.fk(body)
    soles = sole_points(g_rot, j_pos, body)  # (T, 2, 6, 3)
    t = soles.shape[0]
    fps = float(motion.fps)
    z = soles[..., 2]
    if t >= 2:
        vel = np.gradient(soles[..., :2], axis=0) * fps
    else:
        vel = np.zeros((*soles.shape[:-1], 2))
    speed = np.linalg.norm(vel, axis=-1)  # (T, 2, 6)
    touching = z < contact_height_m
    foot_speed = np.linalg.norm(vel.mean(axis=2), axis=-1)  # (T, 2)
    foot_contact = touching.any(axis=-1) & (foot_speed < contact_speed_mps)  # (T, 2)
    n_touch = touching.sum(axis=-1)
    foot_slide = np.where(foot_contact, (speed * touching).sum(-1) / np.maximum(n_touch, 1), 0.0)
    n_cf = int(foot_contact.sum())
    fs = float(foot_slide[foot_contact].mean()) if n_cf else float("nan")

    flat_z = z.reshape(t, 12)
    k = np.argmin(flat_z, axis=1)
    lowest = flat_z[np.arange(t), k]
    low_speed = speed.reshape(t, 12)[np.arange(t), k]
    pen_mm = np.maximum(0.0, -lowest) * 1000.0
    support = low_speed < support_speed_mps
    n_sup = int(support.sum())
    return {
        "name": motion.name,
        "category": motion.category,
        "n_frames": t,
        "duration_s": t / fps,
        "fs_mps": fs,
        "fp_mean_mm": float(pen_mm.mean()),
        "fp_max_mm": float(pen_mm.max()),
        "contact_fraction": float(foot_contact.any(axis=1).mean()),
        "float_mm": float(np.maximum(0.0, lowest[support]).mean() * 1000.0)
        if n_sup
        else float("nan"),
        "stance_height_median_m": float(np.median(lowest[support])) if n_sup else float("nan"),
        "n_contact_foot_frames": n_cf,
        "n_support_frames": n_sup,
    }


def _wmean(values: np.ndarray, weights: np.ndarray) -> float:
    ok = np.isfinite(values) & (weights > 0)
    if not ok.any():
        return float("nan")
    return float(np.sum(values[ok] * weights[ok]) / np.sum(weights[ok]))


def summarize(
    metrics_per_clip: Mapping[str, Mapping] | Iterable[Mapping], by: str = "category"
) -> dict[str, dict[str, float]]:
    """Aggregate :func:`foot_metrics` results per group and overall.

    Rates are weighted by the frames they were measured on: ``fs_mps`` by contacting
    foot-frames, ``float_mm`` by support frames, ``fp_mean_mm`` and ``contact_fraction`` by
    frames; ``fp_max_mm`` is the maximum.

    Args:
        metrics_per_clip: Clip id -> metrics dict, or an iterable of metrics dicts.
        by: Key of the metrics dicts to group by (``"category"``, or e.g. ``"dataset"`` if the
            caller added it).

    Returns:
        Group -> ``{"clips", "frames", "fs_mps", "fp_mean_mm", "fp_max_mm",
        "contact_fraction", "float_mm"}``, plus the group ``"all"``; groups sorted by name.
    """
    rows = list(metrics_per_clip.values() if isinstance(metrics_per_clip, Mapping)
                else metrics_per_clip)  # fmt: skip
    groups: dict[str, list[Mapping]] = {}
    for r in rows:
        groups.setdefault(str(r.get(by, "unknown")), []).append(r)

    def agg(items: list[Mapping]) -> dict[str, float]:
        col = {k: np.array([float(r[k]) for r in items]) for k in (
            "n_frames", "fs_mps", "fp_mean_mm", "fp_max_mm", "contact_fraction", "float_mm",
            "n_contact_foot_frames", "n_support_frames")}  # fmt: skip
        return {
            "clips": len(items),
            "frames": int(col["n_frames"].sum()),
            "fs_mps": _wmean(col["fs_mps"], col["n_contact_foot_frames"]),
            "fp_mean_mm": _wmean(col["fp_mean_mm"], col["n_frames"]),
            "fp_max_mm": float(np.max(col["fp_max_mm"])) if items else float("nan"),
            "contact_fraction": _wmean(col["contact_fraction"], col["n_frames"]),
            "float_mm": _wmean(col["float_mm"], col["n_support_frames"]),
        }

    out = {g: agg(items) for g, items in sorted(groups.items())}
    out["all"] = agg(rows)
    return out
