"""Do a clip's props fit the body simulated on them? The ground truth played back in the scene.

For each chosen clip, the tracking env's humanoid of the clip's subject (``clip.body``) stands in
the clip's scene (its ``objects`` as the env builds them: :class:`envs.tracking_env.
GripTrackingEnv`, :mod:`envs.scenes`) and is posed at the ground truth frame by frame (``qpos``
from ``gt_qpos``, ``mj_forward``, no dynamics). MuJoCo's contacts between body geoms and the scene
give per clip: the frames with a body-prop contact, the deepest penetration and the median of
each such frame's deepest one, the body parts inside a prop, the most simultaneous contacts and
the worst runs of contact frames; the same for the floor. Per prop: its top against the soles
of the reference's planted feet over it, and against the lowest pelvis or thigh point while the
reference sits over it (the rules of :mod:`prism_tools.synth.props`). All of it again with the
default body (``BodyParams()``, the same ``gt_qpos``) and, with ``--data``, the props inferred
anew from the dataset's motion file on either body (:func:`prism_tools.synth.props.
infer_props`) against the clip's own.

Reading the depths: they are MuJoCo's. The foot boxes' undersides sit
``MjcfConfig.foot_box_clearance_m`` (4 mm) above the sole and a sole pad's depth against a height
field stops growing near its radius, so a sole x cm inside a prop reads x - 0.4 cm. A foot
resting on the height field of the props makes up to 50 contacts per geom (one per triangle
under it: MuJoCo's cap per pair), so the contact counts run to hundreds for two feet resting
1 cm into a top; on the floor plane a box makes at most 4.

Clips come from a built dataset (its recordings made into reference clips as a training
reference set with ``follow = "truth"`` makes them: :func:`grip.kinematics.reference.
oracle_reference_clip`; ``--clips``/``--controls`` are globs of the manifest's clip ids) or from
a reference set file (globs of the clip names less ``_seqNNN``). Controls are clips on flat
ground, for the floor's numbers.

    python benchmarks/prop_fit.py --data DATA --run RUN --json prop_fit.json
    python benchmarks/prop_fit.py --data DATA --clips 'cmu/13_35' --controls 'cmu/07_04'
    python benchmarks/prop_fit.py --reference RUN/reference_train.npz --clips 'cmu/13_3[5-8]'

With ``--infer`` (and ``--data``) each clip's scene holds the props inferred anew by the current
rules from the dataset's motion file on the clip's own body, as ``grip data build`` would infer
them now, instead of those its recording was built with: a change of the rules measured without
rebuilding the dataset.

    python benchmarks/prop_fit.py --data DATA --run RUN --infer --json prop_fit_after.json
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import re
import sys
from pathlib import Path

import numpy as np

DEFAULT_CLIPS = ("cmu/13_01", "cmu/13_3[5-8]")
"""CMU subject 13's sit-stand (13_01) and stairs (13_35..13_38) clips."""
DEFAULT_CONTROLS = ("cmu/02_01", "cmu/07_04", "cmu/07_05")
"""Walks on flat ground (training split)."""
PROP_MIN_M = 0.005
"""A contact with the terrain height field where the terrain stands lower than this is a floor
contact (the field is flat, z = 0, around its props)."""
SEATED_THIGH_DEG = 45.0
"""Sitting: thighs at least this far from straight down (as ``prism_tools.synth.props``)."""
SUPPORT_GAP_M = 0.03
"""A sole cell with the scene's top less than this below it stands on it (planted soles float
up to a few centimetres: ``prism_tools.synth.props.MIN_HEIGHT_M``)."""
SEGMENTS = {
    "Pelvis": "pelvis", "L_Hip": "L_thigh", "R_Hip": "R_thigh", "L_Knee": "L_shank",
    "R_Knee": "R_shank", "L_Ankle": "L_foot", "R_Ankle": "R_foot", "L_Foot": "L_toes",
    "R_Foot": "R_toes", "Spine1": "torso", "Spine2": "torso", "Spine3": "torso",
}  # fmt: skip
"""Segment carried by each body (the body model puts a joint's segment on the joint's body)."""
TOP_RUNS = 8
"""Contact runs reported per clip (the deepest)."""


# ------------------------------------------------------------------------------ contacts
def geom_labels(model) -> list[str]:
    """Body-part label of each geom: its segment (:data:`SEGMENTS`, else its body's name), with
    ``" pads"`` for the sole pads; ``""`` for the scene's geoms."""
    out = []
    for g in range(model.ngeom):
        b = int(model.geom_bodyid[g])
        if b == 0:
            out.append("")
            continue
        name = model.body(b).name
        pads = " pads" if model.geom(g).name.startswith("sole_") else ""
        out.append(SEGMENTS.get(name, name) + pads)
    return out


def prop_geoms(model) -> np.ndarray:
    """``(ngeom,)`` True for the scene's prop geoms: the terrain height field and the overhang
    meshes (:func:`envs.scenes.compile_scene`); the floor plane is not one."""
    return np.array([int(model.geom_bodyid[g]) == 0 and (model.geom(g).name == "terrain"
                                                          or model.geom(g).name.startswith(
                                                              "overhang_"))
                     for g in range(model.ngeom)], dtype=bool)  # fmt: skip


def body_scene_contacts(model, data, props: np.ndarray, ground=None) -> dict[str, np.ndarray]:
    """The contacts of the current state (after ``mj_forward``) between the humanoid's geoms and
    the scene (self-contacts left out).

    Args:
        model, data: The MuJoCo model and data.
        props: ``(ngeom,)`` the prop geoms (:func:`prop_geoms`).
        ground: ``xy (K, 2) -> (K,)`` terrain heights (``None``: no height field); a
            height-field contact where the terrain is lower than :data:`PROP_MIN_M` touches the
            floor, not a prop.

    Returns:
        ``geom (K,)`` the body geom of each contact, ``depth (K,)`` its penetration (minus the
        contact distance), m, and ``prop (K,)`` whether the other geom is a prop (else the
        floor).
    """
    n = data.ncon
    pair = np.asarray(data.contact.geom[:n]).reshape(n, 2)
    depth = -np.asarray(data.contact.dist[:n], dtype=np.float64)
    pos = np.asarray(data.contact.pos[:n], dtype=np.float64).reshape(n, 3)
    onbody = model.geom_bodyid[pair] > 0
    keep = onbody[:, 0] != onbody[:, 1]  # (one geom on the body, the other the scene's)
    pair, depth, pos, onbody = pair[keep], depth[keep], pos[keep], onbody[keep]
    body_geom = np.where(onbody[:, 0], pair[:, 0], pair[:, 1])
    scene_geom = np.where(onbody[:, 0], pair[:, 1], pair[:, 0])
    prop = props[scene_geom]
    if ground is not None and prop.any():
        over = ground(pos[:, :2]) >= PROP_MIN_M
        terrain = np.array([model.geom(g).name == "terrain" for g in scene_geom], dtype=bool)
        prop &= ~terrain | over
    return {"geom": body_geom, "depth": depth, "prop": prop}


def playback(humanoid, gt_qpos: np.ndarray) -> dict:
    """Pose ``humanoid`` (:class:`grip.sim.humanoid.Humanoid`) at each row of ``gt_qpos``
    (``mj_forward``, no dynamics) and gather its scene contacts.

    Returns:
        ``{"prop": track, "floor": track}``, a track: ``depth (T,)`` the deepest contact of each
        frame (NaN without one), ``n (T,)`` the contacts, ``parts {label: (T,)}`` the deepest
        contact of each body part (NaN without one).
    """
    import mujoco

    from grip.sim.model import write_pose_vector

    m, d, ix = humanoid.model, humanoid.data, humanoid.index
    labels = np.array(geom_labels(m), dtype=object)
    props = prop_geoms(m)
    origin, axes = np.zeros(2), np.eye(2)
    ground = None
    if humanoid.terrain is not None:
        ground = lambda xy: humanoid.heights_around(origin, axes, xy - origin)  # noqa: E731
    t_n = len(gt_qpos)
    tracks = {k: {"depth": np.full(t_n, np.nan), "n": np.zeros(t_n, dtype=np.int64),
                  "parts": {}} for k in ("prop", "floor")}  # fmt: skip
    for t in range(t_n):
        write_pose_vector(gt_qpos[t], ix, d.qpos)
        mujoco.mj_forward(m, d)
        c = body_scene_contacts(m, d, props, ground)
        for key, sel in (("prop", c["prop"]), ("floor", ~c["prop"])):
            if not sel.any():
                continue
            tr, depth, lab = tracks[key], c["depth"][sel], labels[c["geom"][sel]]
            tr["depth"][t], tr["n"][t] = depth.max(), len(depth)
            for part in set(lab):
                arr = tr["parts"].setdefault(part, np.full(t_n, np.nan))
                arr[t] = depth[lab == part].max()
    return tracks


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` of the runs of True."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(),
                    strict=True))  # fmt: skip


def contact_summary(track: dict) -> dict:
    """Numbers of one :func:`playback` track: contact frames and their share, the deepest
    penetration, the median and 95th percentile of each contact frame's deepest, the most and the
    median simultaneous contacts, per body part (frames, deepest, median) and the
    :data:`TOP_RUNS` deepest runs of consecutive contact frames (frames ``[start, stop)``)."""
    depth, n = track["depth"], track["n"]
    hit = np.isfinite(depth)
    out: dict = {"frames": int(hit.sum()), "share": round(float(hit.mean()), 4)}
    if not hit.any():
        return {**out, "max_depth_m": 0.0, "median_depth_m": 0.0, "p95_depth_m": 0.0,
                "max_contacts": 0, "median_contacts": 0, "parts": {}, "runs": []}  # fmt: skip
    d = depth[hit]
    parts = {}
    for label, arr in track["parts"].items():
        a = arr[np.isfinite(arr)]
        parts[label] = {"frames": len(a), "max_depth_m": round(float(a.max()), 4),
                        "median_depth_m": round(float(np.median(a)), 4)}  # fmt: skip
    parts = dict(sorted(parts.items(), key=lambda kv: -kv[1]["frames"]))
    runs = []
    for a, b in _runs(hit):
        seg = {k: v[a:b] for k, v in track["parts"].items()}
        who = sorted((k for k, v in seg.items() if np.isfinite(v).any()),
                     key=lambda k: -np.nanmax(seg[k]))  # fmt: skip
        runs.append({"start": a, "stop": b, "max_depth_m": round(float(depth[a:b].max()), 4),
                     "max_contacts": int(n[a:b].max()), "parts": who})  # fmt: skip
    runs = sorted(runs, key=lambda r: -r["max_depth_m"])[:TOP_RUNS]
    return {**out, "max_depth_m": round(float(d.max()), 4),
            "median_depth_m": round(float(np.median(d)), 4),
            "p95_depth_m": round(float(np.percentile(d, 95)), 4),
            "max_contacts": int(n.max()), "median_contacts": float(np.median(n[hit])),
            "parts": parts, "runs": sorted(runs, key=lambda r: r["start"])}  # fmt: skip


# ------------------------------------------------------------------------------ heights
def prop_boxes(objects: dict | None) -> list:
    """The props of a clip's ``objects`` as :class:`prism_tools.synth.props.Prop` boxes (top
    extent, top height and underside of each mesh, by name; kind ``"slab"`` for one open
    underneath, else ``"box"``: the objects do not say step or seat)."""
    from envs.terrain import OVERHANG_MIN_M
    from prism_tools.synth.props import Prop

    out = []
    for _, (v, _f) in sorted((objects or {}).items()):
        v = np.asarray(v, dtype=np.float64)
        bottom = float(v[:, 2].min())
        out.append(Prop(v[:, :2].min(0), v[:, :2].max(0), float(v[:, 2].max()),
                        "slab" if bottom > OVERHANG_MIN_M else "box", 0,
                        bottom if bottom > OVERHANG_MIN_M else 0.0))  # fmt: skip
    return out


def _stats(x: np.ndarray) -> dict:
    if not len(x):
        return {"median_m": None, "min_m": None, "max_m": None}
    return {"median_m": round(float(np.median(x)), 4), "min_m": round(float(x.min()), 4),
            "max_m": round(float(x.max()), 4)}  # fmt: skip


def support_fit(gt_rot: np.ndarray, gt_pos: np.ndarray, body, fps: float, props: list) -> dict:
    """How the reference rests on the scene: on the floor, on each prop, and what carries it
    where it stands raised or sits.

    Soles: a foot-frame's sole is planted when flat and still (``prism_tools.synth.props``), its
    height the median of its 16 insole cells; a cell is supported when the scene's top under it
    (:func:`prism_tools.synth.props.support_height`: the highest prop top, else the floor; a
    cell under a slab stands on the floor) lies less than :data:`SUPPORT_GAP_M` below it (or
    above it: inside). Sitting: frames where the pelvis is still and the thighs flexed
    (:data:`SEATED_THIGH_DEG`); the seat points are the lowest points of the pelvis and the
    proximal thigh shapes (as the props rule's).

    Args:
        gt_rot, gt_pos: ``(T, 24, 3, 3)``, ``(T, 24, 3)`` the ground truth on ``body``.
        body: The :class:`grip.core.body.BodyModel`.
        fps: Frame rate, Hz.
        props: :func:`prop_boxes`.

    Returns:
        ``floor``: planted soles with their centre over no prop: sole and lowest cell heights.
        ``props``: per prop, its top, the planted soles with their centre over it (sole and
        lowest cell minus the top, median share of supported cells) and the sitting frames
        with the lowest seat point over it (that point and the pelvis joint minus the top).
        ``raised``: planted soles higher than ``MIN_HEIGHT_M`` (standing on something): their
        count, the median share of their cells supported and how many have under half or not
        all of them supported. ``sitting``: the sitting frames, the share with a pelvis point
        over a prop, the share with a seat point over one and the seat points' smallest gap to
        the scene under them (negative: inside a prop).
    """
    from prism_tools.synth.insole import body_contact_points, insole_cell_positions
    from prism_tools.synth.props import (
        MIN_HEIGHT_M,
        REACH_M,
        SEATED_SPEED_M_S,
        horizontal_speed,
        planted_feet,
        support_height,
    )

    cells = insole_cell_positions(gt_rot, gt_pos, body)  # (T, 2, 16, 3)
    planted, sole = planted_feet(cells, fps)  # (T, 2) each
    centre = cells[..., :2].mean(axis=2)  # (T, 2, 2)
    low_cell = cells[..., 2].min(axis=-1)  # (T, 2)
    held = (cells[..., 2] - support_height(props, cells)) < SUPPORT_GAP_M  # (T, 2, 16)
    share = held.mean(axis=-1)  # (T, 2)
    pts, bodies, where = body_contact_points(gt_rot, gt_pos, body)
    keep = (bodies == 0) | (np.isin(bodies, (1, 2)) & (where <= 0.5))
    seat, pelvis_pts = pts[:, keep], pts[:, bodies == 0]  # (T, K, 3)
    lowest = seat[np.arange(len(seat)), seat[..., 2].argmin(axis=1)]  # (T, 3)
    thigh = gt_pos[:, (4, 5)] - gt_pos[:, (1, 2)]
    down = -thigh[..., 2] / np.maximum(np.linalg.norm(thigh, axis=-1), 1e-9)
    flexed = np.degrees(np.arccos(np.clip(down, -1.0, 1.0))).mean(1) >= SEATED_THIGH_DEG
    sitting = (horizontal_speed(gt_pos[:, 0], fps) < SEATED_SPEED_M_S) & flexed
    off = planted & ~np.any([p.contains(centre) for p in props], axis=0) if props else planted
    out: dict = {"floor": {"foot_frames": int(off.sum()), "sole_m": _stats(sole[off]),
                           "lowest_cell_m": _stats(low_cell[off])}, "props": []}  # fmt: skip
    for k, p in enumerate(props):
        on = planted & p.contains(centre) & (sole >= p.bottom_m)
        sit = sitting & p.contains(lowest[:, :2]) & (lowest[:, 2] >= p.bottom_m - REACH_M)
        out["props"].append({
            "prop": k, "kind": p.kind, "top_m": round(p.height_m, 4),
            "bottom_m": round(p.bottom_m, 4), "extent_m": np.round(p.hi - p.lo, 3).tolist(),
            "feet": {"foot_frames": int(on.sum()),
                     "sole_minus_top": _stats(sole[on] - p.height_m),
                     "lowest_cell_minus_top": _stats(low_cell[on] - p.height_m),
                     "cells_supported_median": (round(float(np.median(share[on])), 3)
                                                if on.any() else None)},
            "seat": {"frames": int(sit.sum()),
                     "seat_point_minus_top": _stats(lowest[sit, 2] - p.height_m),
                     "pelvis_minus_top": _stats(gt_pos[sit, 0, 2] - p.height_m)},
        })  # fmt: skip
    raised = planted & (sole >= MIN_HEIGHT_M)
    out["raised"] = {
        "foot_frames": int(raised.sum()),
        "cells_supported_median": round(float(np.median(share[raised])), 3) if raised.any()
        else None,
        "under_half_supported": int((raised & (share < 0.5)).sum()),
        "not_all_supported": int((raised & (share < 1.0)).sum()),
    }  # fmt: skip
    n_sit = int(sitting.sum())
    gap = (seat[..., 2] - support_height(props, seat)).min(axis=1)  # (T,)

    def over(q: np.ndarray) -> np.ndarray:  # (T,) some point of q (T, K, 3) over a prop
        return np.any([p.contains(q[..., :2]) for p in props], axis=0).any(axis=1)

    out["sitting"] = {
        "frames": n_sit,
        "pelvis_over_prop_share": (round(float(over(pelvis_pts)[sitting].mean()), 3)
                                   if n_sit and props else 0.0),
        "seat_point_over_prop_share": (round(float(over(seat)[sitting].mean()), 3)
                                       if n_sit and props else 0.0),
        "seat_gap_m": _stats(gap[sitting]),
        "pelvis_m": _stats(gt_pos[sitting, 0, 2]),
    }  # fmt: skip
    return out


def refit(motion_path: Path, props: list) -> dict:
    """The props inferred anew from a dataset's motion file (the whole take, as the dataset
    build inferred them) on the motion's own body and on the default body, against ``props``
    (:func:`prop_boxes` of the clip): per body, the props' tops and the largest difference of
    any box coordinate (None when the counts differ)."""
    from grip.core.body import BodyParams, build_body
    from grip.motion.motion import Motion
    from prism_tools.synth.props import infer_props

    motion = Motion.load(motion_path)
    out = {"motion": str(motion_path), "motion_body": _body_dict(motion.body)}
    for key, params in (("own", motion.body), ("default", BodyParams())):
        body = build_body(params)
        g, p = motion.fk(body)
        got = infer_props(g, p, body, motion.fps)
        diff = None
        if len(got) == len(props):
            diff = max((float(np.abs(np.concatenate([a.lo - b.lo, a.hi - b.hi,
                                                     [a.height_m - b.height_m,
                                                      a.bottom_m - b.bottom_m]])).max())
                        for a, b in zip(got, props, strict=True)), default=0.0)  # fmt: skip
        out[key] = {"tops_m": [round(q.height_m, 4) for q in got],
                    "kinds": [q.kind for q in got],
                    "max_diff_m": None if diff is None else round(diff, 5)}  # fmt: skip
    return out


def _body_dict(b) -> dict:
    return {"height_m": b.height_m, "mass_kg": b.mass_kg}


# ------------------------------------------------------------------------------ clips
def clips_from_data(data: Path, patterns: list[str]) -> tuple[list[tuple], tuple, bool]:
    """``(clip, clip_id)`` of the sequences of the manifest's clips whose ids match a glob, made
    as a training reference set with ``follow = "truth"`` makes them, with their sensor sites
    and insoles (the default features)."""
    from grip.cli.recordings import load_recordings
    from grip.kinematics.features import FeatureConfig
    from grip.kinematics.reference import oracle_reference_clip

    feats = FeatureConfig()
    manifest = json.loads((data / "manifest.json").read_text())
    out = []
    for c in manifest["clips"]:
        if c.get("status") != "done" or not any(fnmatch.fnmatch(c["clip_id"], p)
                                                for p in patterns):  # fmt: skip
            continue
        files = [data / "sequences" / f"{s}.npz" for s in c["sequences"]]
        out += [(oracle_reference_clip(r, feats), c["clip_id"]) for r in load_recordings(files)]
    return out, tuple(feats.sites), feats.insoles


def inferred_objects(data: Path, clip_id: str) -> dict | None:
    """The scene objects of the props inferred anew (:func:`prism_tools.synth.props.
    infer_props`, the current rules) from a dataset's motion file on the motion's own body, as
    the dataset build infers them; ``None`` without props."""
    from grip.motion.motion import Motion
    from prism_tools.chunking import safe_name
    from prism_tools.synth.props import infer_props, props_as_objects

    motion = Motion.load(data / "motions" / f"{safe_name(clip_id)}.npz")
    body = motion.body_model()
    objs = props_as_objects(infer_props(*motion.fk(body), body, motion.fps))
    return None if objs is None else {n: (o.vertices, o.faces) for n, o in objs.items()}


def clips_from_reference(path: Path, patterns: list[str]) -> tuple[list[tuple], tuple, bool]:
    """``(clip, None)`` of a reference set's clips whose names, less a leading ``synthetic_``
    and from ``_seq`` on, match a glob, with the set's sensor sites and insoles."""
    from grip.core.reference_sets import load_reference

    ref = load_reference(str(path))
    out = []
    for c in ref.clips:
        take = re.sub(r"_seq\d+.*$", "", c.name.removeprefix("synthetic_"))
        if any(fnmatch.fnmatch(take, p) for p in patterns):
            out.append((c, None))
    return out, ref.sensor_sites, ref.insoles


def with_body(clip, body):
    """``clip`` on another subject (the same ``gt_qpos``)."""
    from grip.core.reference import ReferenceClip

    return ReferenceClip(name=f"{clip.name}@default", category=clip.category, fps=clip.fps,
                         body=body, gt_qpos=clip.gt_qpos.copy(), est_pos=clip.est_pos,
                         est_rot6d=clip.est_rot6d, est_vel=clip.est_vel, sensor=clip.sensor,
                         objects=clip.objects)  # fmt: skip


def env_config(run: Path | None):
    """The tracking env's settings: a policy run's (its ``config.json``) or the defaults."""
    from grip.task.config import TrackingEnvConfig

    if run is None:
        return TrackingEnvConfig()
    from policies.config import policy_config_from_dict

    path = run / "config.json"
    return policy_config_from_dict(json.loads(path.read_text())["config"], str(path)).env


# ------------------------------------------------------------------------------ main
def measure(chosen: list[tuple], controls: set[int], sensors: tuple, cfg, data: Path | None,
            default_body: bool) -> list[dict]:  # fmt: skip
    """One result per clip of ``chosen`` (``(clip, clip_id)``; the indices in ``controls`` are
    the controls; ``sensors``: their sensor sites and insoles): the playback of each body in the
    env's scene, the prop heights and the refit."""
    from envs.tracking_env import GripTrackingEnv
    from grip.core.body import BodyParams, build_body
    from grip.core.reference import ReferenceSet
    from prism_tools.chunking import safe_name

    default = BodyParams()
    entries = []  # (result index, body key, clip)
    for i, (clip, _) in enumerate(chosen):
        entries.append((i, "clip", clip))
        own = (clip.body.height_m, clip.body.mass_kg)
        if default_body and own != (default.height_m, default.mass_kg):
            entries.append((i, "default", with_body(clip, default)))
    env = GripTrackingEnv(cfg, reference=ReferenceSet([e[2] for e in entries], *sensors))
    results = []
    for i, (clip, clip_id) in enumerate(chosen):
        props = prop_boxes(clip.objects)
        res = {"clip": clip.name, "clip_id": clip_id, "category": clip.category,
               "control": i in controls, "frames": clip.n_frames,
               "body": _body_dict(clip.body),
               "props": [{"kind": p.kind, "top_m": round(p.height_m, 4),
                          "bottom_m": round(p.bottom_m, 4), "lo": np.round(p.lo, 3).tolist(),
                          "hi": np.round(p.hi, 3).tolist()} for p in props],
               "bodies": {}}  # fmt: skip
        if data is not None and clip_id is not None and props:
            res["refit"] = refit(data / "motions" / f"{safe_name(clip_id)}.npz", props)
        results.append(res)
    for k, (i, key, clip) in enumerate(entries):
        env.reset(options={"clip": k, "start": 0})
        tracks = playback(env.humanoid, clip.gt_qpos)
        body = build_body(clip.body)
        results[i]["bodies"][key] = {
            "body": _body_dict(clip.body),
            "prop_contacts": contact_summary(tracks["prop"]),
            "floor_contacts": contact_summary(tracks["floor"]),
            "support": support_fit(np.asarray(clip.gt_rot, np.float64),
                                   np.asarray(clip.gt_pos, np.float64), body, clip.fps,
                                   prop_boxes(clip.objects)),
        }  # fmt: skip
        pc = results[i]["bodies"][key]["prop_contacts"]
        print(f"{clip.name} [{key} body {clip.body.height_m:g} m]: prop contact frames "
              f"{pc['frames']}/{clip.n_frames}, max {100 * pc['max_depth_m']:.1f} cm",
              file=sys.stderr, flush=True)  # fmt: skip
    env.close()
    return results


def _cm(x) -> str:
    return "-" if x is None else f"{100 * x:.1f}"


def _bodies(results: list[dict]):
    """``(clip result, body key, body result)`` of every clip and body, in order."""
    for r in results:
        for key, b in r["bodies"].items():
            yield r, key, b


def print_tables(results: list[dict]) -> None:
    """Markdown tables: contacts per clip and body, then the props' heights."""
    print("\n| clip | body | frames | prop contact frames | max pen. (cm) | median pen. (cm) "
          "| max contacts | parts (frames) | floor pen. max / median (cm) |")  # fmt: skip
    print("|---|---|---:|---:|---:|---:|---:|---|---:|")
    for r, key, b in _bodies(results):
        p, f = b["prop_contacts"], b["floor_contacts"]
        parts = ", ".join(f"{k} ({v['frames']})" for k, v in list(p["parts"].items())[:4])
        tag = " (control)" if r["control"] else ""
        print(f"| {r['clip']}{tag} | {key} {b['body']['height_m']:g} m | {r['frames']} "
              f"| {p['frames']} | {_cm(p['max_depth_m'])} | {_cm(p['median_depth_m'])} "
              f"| {p['max_contacts']} | {parts or '-'} | {_cm(f['max_depth_m'])} / "
              f"{_cm(f['median_depth_m'])} |")  # fmt: skip
    print("\n| clip | body | prop | top (cm) | foot frames | sole - top median / min (cm) "
          "| lowest cell - top min (cm) | cells supported | sitting frames "
          "| seat point - top median (cm) | pelvis - top median (cm) |")  # fmt: skip
    print("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r, key, b in _bodies(results):
        for s in b["support"]["props"]:
            ft, st = s["feet"], s["seat"]
            cs = ft["cells_supported_median"]
            print(f"| {r['clip']} | {key} | {s['prop']} {s['kind']} | {_cm(s['top_m'])} "
                  f"| {ft['foot_frames']} | {_cm(ft['sole_minus_top']['median_m'])} / "
                  f"{_cm(ft['sole_minus_top']['min_m'])} "
                  f"| {_cm(ft['lowest_cell_minus_top']['min_m'])} "
                  f"| {'-' if cs is None else f'{cs:.2f}'} | {st['frames']} "
                  f"| {_cm(st['seat_point_minus_top']['median_m'])} "
                  f"| {_cm(st['pelvis_minus_top']['median_m'])} |")  # fmt: skip
    print("\n| clip | body | floor soles: frames, median / min (cm) | raised soles: frames, "
          "cells supported, < half, < all | sitting frames | pelvis / seat point over a prop "
          "| seat gap median / min (cm) | pelvis height (cm) |")  # fmt: skip
    print("|---|---|---|---|---:|---|---:|---:|")
    for r, key, b in _bodies(results):
        fl, ra, si = (b["support"][k] for k in ("floor", "raised", "sitting"))
        cs = ra["cells_supported_median"]
        print(f"| {r['clip']} | {key} | {fl['foot_frames']}, {_cm(fl['sole_m']['median_m'])}"
              f" / {_cm(fl['sole_m']['min_m'])} | {ra['foot_frames']}, "
              f"{'-' if cs is None else f'{cs:.2f}'}, {ra['under_half_supported']}, "
              f"{ra['not_all_supported']} | {si['frames']} "
              f"| {si['pelvis_over_prop_share']:.2f} / {si['seat_point_over_prop_share']:.2f} "
              f"| {_cm(si['seat_gap_m']['median_m'])} / {_cm(si['seat_gap_m']['min_m'])} "
              f"| {_cm(si['pelvis_m']['median_m'])} |")  # fmt: skip
    refits = [r for r in results if "refit" in r]
    if refits:
        print("\n| take | props refit on own body: max diff (cm) | on default body: tops (cm) "
              "| max diff (cm) |\n|---|---:|---|---:|")  # fmt: skip
        for r in refits:
            f = r["refit"]
            tops = ", ".join(_cm(t) for t in f["default"]["tops_m"])
            print(f"| {r['clip']} | {_cm(f['own']['max_diff_m'])} | {tops} "
                  f"| {_cm(f['default']['max_diff_m'])} |")  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--data", type=Path, help="a 'grip data build' output folder")
    src.add_argument("--reference", type=Path, help="a reference set file (.npz)")
    ap.add_argument("--clips", nargs="+", default=list(DEFAULT_CLIPS), metavar="GLOB",
                    help="clip ids (default: CMU 13_01 and 13_35..13_38)")  # fmt: skip
    ap.add_argument("--controls", nargs="*", default=list(DEFAULT_CONTROLS), metavar="GLOB",
                    help="flat-ground clips to compare with (default: 3 CMU walks)")  # fmt: skip
    ap.add_argument("--run", type=Path, default=None,
                    help="a policy run folder: its env settings (default: defaults)")  # fmt: skip
    ap.add_argument("--no-default-body", action="store_true",
                    help="skip the playback on the default body")  # fmt: skip
    ap.add_argument("--infer", action="store_true",
                    help="with --data: the props inferred anew from the motion files")  # fmt: skip
    ap.add_argument("--json", type=Path, default=None, help="write the results here")
    args = ap.parse_args(argv)
    if args.infer and args.data is None:
        ap.error("--infer needs --data")
    pick = clips_from_data if args.data is not None else clips_from_reference
    source = args.data if args.data is not None else args.reference
    chosen, *sensors = pick(source, args.clips)
    n = len(chosen)
    chosen += pick(source, args.controls)[0] if args.controls else []
    if args.infer:
        scenes: dict[str, dict | None] = {}
        for clip, clip_id in chosen:
            if clip_id not in scenes:
                scenes[clip_id] = inferred_objects(args.data, clip_id)
            clip.objects = scenes[clip_id]
    if not chosen:
        print(f"{source}: no clip matches {args.clips + (args.controls or [])}", file=sys.stderr)
        return 2
    cfg = env_config(args.run)
    results = measure(chosen, set(range(n, len(chosen))), tuple(sensors), cfg, args.data,
                      not args.no_default_body)  # fmt: skip
    print_tables(results)
    if args.json:
        paths = {k: None if v is None else str(v)
                 for k, v in (("data", args.data), ("reference", args.reference),
                              ("run", args.run))}  # fmt: skip
        settings = {**paths, "clips": args.clips, "controls": args.controls, "infer": args.infer,
                    "prop_min_m": PROP_MIN_M, "support_gap_m": SUPPORT_GAP_M,
                    "heightfield_cell_m": cfg.heightfield_cell_m}  # fmt: skip
        args.json.write_text(json.dumps({"settings": settings, "clips": results}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
