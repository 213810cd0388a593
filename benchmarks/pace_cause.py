"""Why does GRIP's humanoid fall behind the estimate it follows? (issue 46, part 2)

Plays a controller on the locomotion test segments of a dataset, following KinematicsNet's
estimate and, separately, the ground truth, and measures per segment (frames before any fall):

* the horizontal distance between the humanoid's pelvis and the pelvis it follows at 1 s, 5 s
  and the end, split into the part *along* the followed path's direction of travel (behind it:
  positive) and *across* it;
* the ground covered by the humanoid over the ground covered by what it follows
  (``speed_ratio``; 1 s samples of the horizontal path);
* how far the followed pelvis itself runs from the truth's over the whole segment
  (``ref_to_truth_*``; zero when following the truth): the floor of any gap to the truth of a
  controller that keeps to the estimate, and the estimate's own pace (``ref_over_truth_speed``);
* how far the followed pelvis' heading turns from the truth's (``pelvis_heading_err_deg``,
  the median over the frames);
* the share of leg actions near the action bound (|a| > 0.9): a PD target that cannot go
  further would cap the gait;
* what the task's reward pays for pace: the ``imit_vel`` and ``root_vel`` kernels (the only
  terms that see a horizontal velocity deficit with ``align_root_xy``) at the measured deficit,
  and their weighted cost per step.

Two hybrid references take the estimate apart (``--references``): ``estimate-pose`` follows
the estimate's pose and leaf velocities with the truth's pelvis velocity (so the truth's root
path), ``estimate-root`` the truth's pose and leaf velocities with the estimate's pelvis
velocity (its root path). Which part of the estimate slows the humanoid? ``--lean DEG`` leans
the followed upper body DEG further forward (the trunk's lean sets the pace: docs/pace.md).

    python benchmarks/pace_cause.py --data DATA --json F [--policy P] [--kin K] [--segments N]
        [--references estimate,estimate-pose] [--lean DEG]

Defaults: the shipped policy and KinematicsNet, the test split, categories ``walk*,run*``,
500-frame segments, recovery off (as ``grip policy eval``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

LEG_JOINTS = (1, 2, 4, 5, 7, 8, 10, 11)  # hips, knees, ankles, feet (SMPL order)
LEG_HINGES = tuple(3 * (j - 1) + k for j in LEG_JOINTS for k in range(3))


class _Recorder:
    """Wraps a controller and keeps every action it returns (per call, the batch)."""

    def __init__(self, runner) -> None:
        self._r = runner
        self.actions: list[np.ndarray] = []

    def act(self, obs):
        a = self._r.act(obs)
        self.actions.append(np.asarray(a, np.float64).reshape(-1, 69))
        return a

    def __getattr__(self, name):
        return getattr(self._r, name)


def _path_speed(xy: np.ndarray, fps: float) -> float:
    """Ground covered (1 s samples of the horizontal path) per second, m/s."""
    step = max(round(fps), 1)
    pts = xy[::step]
    if len(pts) < 2:
        return float("nan")
    return float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum() / ((len(pts) - 1) * step / fps))


def _gap_parts(sim_xy: np.ndarray, ref_xy: np.ndarray, t: int, fps: float) -> tuple[float, ...]:
    """(distance, along, across) of ``ref - sim`` at frame ``t``: along the followed path's
    direction of travel over the last second (positive: the humanoid is behind)."""
    d = ref_xy[t] - sim_xy[t]
    back = max(t - round(fps), 0)
    v = ref_xy[t] - ref_xy[back]
    n = float(np.linalg.norm(v))
    along = float(d @ v / n) if n > 1e-6 else float("nan")
    across = float(np.sqrt(max(float(d @ d) - along**2, 0.0))) if n > 1e-6 else float("nan")
    return float(np.linalg.norm(d)), along, across


def followed_to_truth(ref_xy: np.ndarray, truth_pos: np.ndarray, fps: float) -> dict:
    """How far the followed pelvis ``ref_xy (T, 2)`` runs from the truth's ``truth_pos (T', 3)``
    (moved to start where it starts) at 1 s, 5 s and the end of their common frames, m, and the
    ground it covers over the truth's (``ref_over_truth_speed``): the floor of any gap to the
    truth for a controller that keeps to what it follows, whatever the humanoid did."""
    m = min(len(ref_xy), len(truth_pos))
    truth_xy = truth_pos[:m, :2] - truth_pos[0, :2] + ref_xy[0]
    out: dict = {}
    for name, sec in (("1s", 1.0), ("5s", 5.0 - 1.0 / fps), ("end", None)):
        t = m - 1 if sec is None else round(sec * fps)
        out[f"ref_to_truth_{name}_m"] = (float(np.linalg.norm(ref_xy[t] - truth_xy[t]))
                                         if t < m else None)  # fmt: skip
    out["ref_over_truth_speed"] = (_path_speed(ref_xy[:m], fps)
                                   / max(_path_speed(truth_xy, fps), 1e-9))  # fmt: skip
    return out


REFERENCES = ("estimate", "truth", "estimate-pose", "estimate-root")
PELVIS_ROW = -1  # the pelvis' row of est_vel (grip.core.skeleton.VELOCITY_JOINTS ends with it)


def hybrid_clip(est, truth, keep: str):
    """A reference clip that keeps one part of the estimate ``est`` and takes the rest from the
    ground truth's clip ``truth`` (both :class:`grip.core.reference.ReferenceClip` of one
    recording): ``keep="pose"`` the estimated joint positions, rotations and leaf velocities
    with the truth's pelvis velocity (the root the clip integrates is the truth's);
    ``keep="root"`` the truth's pose and leaf velocities with the estimated pelvis velocity."""
    import dataclasses

    if keep not in ("pose", "root"):
        raise ValueError(f"keep must be 'pose' or 'root', got {keep!r}")
    pose, other = (est, truth) if keep == "pose" else (truth, est)
    vel = pose.est_vel.copy()
    vel[:, PELVIS_ROW] = other.est_vel[:, PELVIS_ROW]
    return dataclasses.replace(est, est_pos=pose.est_pos, est_rot6d=pose.est_rot6d, est_vel=vel)


def root_speed_scaled(clip, factor: float):
    """``clip`` carried over the ground ``factor`` times as fast with the pose unchanged, as the
    training's root-speed augmentation does it (:func:`grip.task.observations.carried_faster`:
    the estimated pelvis' horizontal velocity, and so the root it integrates, times ``factor``;
    every velocity joint's horizontal velocity shifted by the same amount): does the controller
    read its pace from the followed root?"""
    import dataclasses

    from grip.task.observations import carried_faster

    return dataclasses.replace(clip, est_vel=carried_faster(clip.est_vel, factor))


def leaned_clip(clip, deg: float):
    """``clip`` with its estimated upper body leaned ``deg`` further forward (negative: back)
    about the pelvis, towards the truth's direction of travel (its pelvis' horizontal velocity
    averaged over 1 s; the clip's mean direction where the walker stands): the joint positions
    and global rotations of :data:`grip.task.observations.UPPER_BODY` turned, and the
    velocities of its velocity joints (wrists, head) turned relative to the pelvis'; the legs,
    the pelvis and the root it integrates unchanged. Does the estimated trunk's lean set the
    humanoid's pace?"""
    import dataclasses

    from scipy.ndimage import uniform_filter1d

    from grip.core.rotations import matrix_to_6d
    from grip.task.observations import lean_towards, leaned

    v = uniform_filter1d(clip.gt_vel[:, 0, :2], size=max(1, round(clip.fps)), axis=0)
    mean = clip.gt_vel[:, 0, :2].mean(axis=0)
    mean = mean / np.linalg.norm(mean) if np.linalg.norm(mean) > 1e-6 else np.array([1.0, 0.0])
    speed = np.linalg.norm(v, axis=1, keepdims=True)
    fwd = np.where(speed > 0.1, v / np.maximum(speed, 1e-9), mean)
    rot = lean_towards(fwd, deg)  # (T, 3, 3): z turns towards forward
    pos, glob, vel = leaned(clip.est_pos, clip.est_rot, clip.est_vel, rot)
    return dataclasses.replace(clip, est_pos=pos, est_rot6d=matrix_to_6d(glob), est_vel=vel)


def pelvis_heading_error_deg(clip) -> float:
    """Median over the frames of the angle between the followed pelvis' heading and the truth's
    (a :class:`grip.core.reference.ReferenceClip`), deg: 0 when following the truth."""
    from grip.core.rotations import heading_angle

    d = heading_angle(clip.est_rot[:, 0]) - heading_angle(clip.gt_rot[:, 0])
    return float(np.degrees(np.median(np.abs(np.angle(np.exp(1j * d))))))


def fold_chooser(kin_folds: list[str], data: str):
    """``rec -> estimator``: the fold model (``--kin-fold``) that never saw the recording's
    person, as a cross-fitted training set estimates it
    (:func:`grip.kinematics.reference.fold_model_chooser`)."""
    from grip.kinematics.dataset import dataset_groups
    from grip.kinematics.inference import KinematicsEstimator
    from grip.kinematics.reference import fold_model_chooser

    ests = [KinematicsEstimator.from_checkpoint(k) for k in kin_folds]
    return fold_model_chooser(ests, dataset_groups(data), kin_folds)


def warm_clip(estimator, read, seg, seconds: float):
    """``(clip, w)``: the estimate of segment ``seg`` made by KinematicsNet started from the
    ground truth ``w = min(seconds x fps, seg.start)`` frames before the segment (the frames
    before it in its file, as a recording's estimator has run before any moment of it) and cut
    to the segment: its LSTMs settled at the segment's first frame, its root integrated from the
    truth's there as a cold start's is. ``w = 0``: the cold start itself."""
    import dataclasses

    from grip.eval.policy import _estimates

    rec = read(seg)
    w = min(round(seconds * float(rec.fps)), int(seg.start))
    if w == 0:
        return _estimates(estimator, [rec], 1, "estimate", "truth")[0], 0
    ext = read.whole(seg).slice_frames(seg.start - w, seg.stop)
    clip = _estimates(estimator, [ext], 1, "estimate", "truth")[0]
    cut = {k: getattr(clip, k)[w:] for k in ("gt_qpos", "est_pos", "est_rot6d", "est_vel",
                                             "sensor")}  # fmt: skip
    return dataclasses.replace(clip, name=rec.name, **cut), w


def play(setup, segments, reference: str, choose=None, root_scale: float = 1.0,
         pace=None, warm_s: float = 0.0, lean_deg: float = 0.0) -> list[dict]:  # fmt: skip
    """Play every segment following ``reference``; ``choose(rec)`` picks the KinematicsNet
    of each recording (default: the setup's); ``root_scale`` carries the followed estimate that
    many times as fast (:func:`root_speed_scaled`); ``pace`` the players' pace keeper
    (:class:`grip.player.PaceKeeper`; None: its defaults, on; ``PaceKeeper(gain=0)``: off);
    ``warm_s`` > 0 warms the estimator up on the seconds before each segment
    (:func:`warm_clip`; ``reference="estimate"`` only); ``lean_deg`` leans the followed upper
    body that much further forward (:func:`leaned_clip`)."""
    from grip.eval.policy import _episode, _estimates, _pipeline
    from grip.eval.segments import SegmentReader
    from grip.kinematics.features import ground_truth
    from grip.player import PaceKeeper

    runner, default = setup.build()
    rows = []
    read = SegmentReader()
    for seg in segments:
        rec = read(seg)
        warmed = 0
        estimator = default if choose is None else choose(rec)
        if reference.startswith("estimate-"):
            est = hybrid_clip(_estimates(estimator, [rec], 1, "estimate", "truth")[0],
                              _estimates(estimator, [rec], 1, "truth", "truth")[0],
                              reference.split("-", 1)[1])  # fmt: skip
        elif reference == "estimate" and warm_s > 0:
            est, warmed = warm_clip(estimator, read, seg, warm_s)
        else:
            est = _estimates(estimator, [rec], 1, reference, "truth")[0]
        if root_scale != 1.0:
            est = root_speed_scaled(est, root_scale)
        if lean_deg != 0.0:
            est = leaned_clip(est, lean_deg)
        rec_runner = _Recorder(runner)
        pipe = _pipeline(rec_runner, estimator, reference.split("-")[0], "truth",
                         pace or PaceKeeper())  # fmt: skip
        ep = _episode(rec, est, "truth", estimator.cfg.features)
        recon, _ = pipe.play(ep.est, ep.start, ep.body, ep.objects, stop_at_fall=True)
        n = recon.n_frames
        fps = float(est.fps)
        gt_all = ground_truth(rec)
        gt = gt_all.head(n)
        sim_xy = recon.root_pos[:, :2]
        offset = ep.start.qpos[:3] - est.est_root_pos[0]
        ref_all = (est.est_root_pos + offset)[:, :2]
        ref_xy = ref_all[:n]
        fell = bool(len(recon.falls))
        acts = np.concatenate(rec_runner.actions) if rec_runner.actions else np.zeros((0, 69))
        legs = np.abs(acts[:, list(LEG_HINGES)])
        row = {"segment": seg.id, "category": seg.category, "frames": n, "fell": fell,
               "ref_speed_mps": _path_speed(ref_xy, fps), "sim_speed_mps": _path_speed(sim_xy, fps),
               "gt_speed_mps": _path_speed(gt.root_pos[:, :2], fps),
               "leg_saturated": float((legs > 0.9).mean()) if legs.size else float("nan"),
               "leg_abs_action": float(legs.mean()) if legs.size else float("nan"),
               "warm_frames": warmed}  # fmt: skip
        row["speed_ratio"] = row["sim_speed_mps"] / max(row["ref_speed_mps"], 1e-9)
        for name, sec in (("1s", 1.0), ("5s", 5.0 - 1.0 / fps), ("end", None)):
            t = n - 1 if sec is None else round(sec * fps)
            if t >= n:
                row[f"gap_{name}_m"] = row[f"along_{name}_m"] = row[f"across_{name}_m"] = None
                continue
            row[f"gap_{name}_m"], row[f"along_{name}_m"], row[f"across_{name}_m"] = _gap_parts(
                sim_xy, ref_xy, t, fps)
        truth_xy = gt.root_pos[:, :2] - gt.root_pos[0, :2] + sim_xy[0]  # (from the same start)
        t5 = round((5.0 - 1.0 / fps) * fps)
        row["sim_to_truth_5s_m"], row["sim_behind_truth_5s_m"], _ = (
            _gap_parts(sim_xy, truth_xy, t5, fps) if t5 < n else (None, None, None))
        row.update(followed_to_truth(ref_all, gt_all.root_pos, fps))
        row["pelvis_heading_err_deg"] = pelvis_heading_error_deg(est)
        rows.append(row)
        print(f"{seg.id:50s} {reference:8s} fell={fell!s:5s} speed ratio "
              f"{row['speed_ratio']:.3f} gap 5 s {row['gap_5s_m']} along {row['along_5s_m']}",
              flush=True)  # fmt: skip
    return rows


def reward_cost(deficit_mps: float) -> dict:
    """What the task reward pays for a whole body moving ``deficit_mps`` slower than the truth,
    everything else perfect (the default reward settings)."""
    from grip.task.config import RewardConfig

    c = RewardConfig()
    vel = float(np.exp(-c.k_vel * deficit_mps**2))  # every joint off by the deficit (mean_sq)
    root = float(np.exp(-c.k_root_vel * deficit_mps**2))
    w = c.weights
    return {"deficit_mps": deficit_mps, "imit_vel": vel, "root_vel": root,
            "cost_per_step": w.imit_vel * (1 - vel) + w.root_vel * (1 - root),
            "max_imitation_per_step": w.imit_pos + w.imit_rot + w.imit_vel + w.imit_angvel,
            "weights": {"imit_vel": w.imit_vel, "root_vel": w.root_vel}}  # fmt: skip


def _median(rows: list[dict], key: str) -> float:
    v = [r[key] for r in rows if r.get(key) is not None and np.isfinite(r[key])]
    return float(np.median(v)) if v else float("nan")


def main(argv: list[str] | None = None) -> None:
    from grip.assets import SHIPPED_KIN, SHIPPED_POLICY
    from grip.eval.policy import PolicySetup
    from grip.player import PaceKeeper

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--policy", default=str(SHIPPED_POLICY))
    ap.add_argument("--kin", default=str(SHIPPED_KIN))
    ap.add_argument("--categories", default="walk*,run*")
    ap.add_argument("--split", default="test", choices=("train", "test"),
                    help="the dataset's split to play (train: is the pace a matter of people the "
                    "controller never saw?)")
    ap.add_argument("--segments", type=int, default=0,
                    help="at most this many, evenly over the split's list (0: all)")
    ap.add_argument("--segment-frames", type=int, default=500)
    ap.add_argument("--speed-factor", type=float, default=None,
                    help="play the split's clips this many times faster (sensors synthesised "
                    "again, as speed_factors of 'grip policy train' makes its training walks): "
                    "has a controller trained on the faster training walks learnt their pace?")
    ap.add_argument("--references", default="estimate,truth",
                    help=f"comma-separated, of {', '.join(REFERENCES)} (the hybrids: module "
                    "docstring)")
    ap.add_argument("--kin-fold", action="append", default=[], metavar="CKPT",
                    help="the fold models of a split by person (repeat, one per fold): each "
                    "segment is estimated by the one that never saw its person (with --split "
                    "train: a cross-fitted training set's references, docs/pace.md E3)")
    ap.add_argument("--root-speed-scale", type=float, default=1.0, metavar="F",
                    help="carry the followed estimate F times as fast over the ground, the pose "
                    "unchanged, as env.root_speed_range does in training (the pelvis' horizontal "
                    "velocity, and the root it integrates, times F; every velocity joint shifted "
                    "with it): does the controller read its pace from the root?")
    ap.add_argument("--lean", type=float, default=0.0, metavar="DEG",
                    help="lean the followed upper body DEG further forward (negative: back) "
                    "about the pelvis, towards the direction of travel: does the estimated "
                    "trunk's lean set the humanoid's pace?")
    ap.add_argument("--pace-gain", type=float, default=PaceKeeper().gain, metavar="K",
                    help="the players' pace keeper (grip.player.PaceKeeper): the followed pelvis "
                    "shown leads the estimate's by K x the humanoid's gap to it (0: off)")
    ap.add_argument("--pace-lead-max", type=float, default=PaceKeeper().lead_max_m, metavar="M",
                    help="the pace keeper's longest lead, m")
    ap.add_argument("--lean-gain", type=float, default=PaceKeeper().lean_gain_deg, metavar="D",
                    help="the lean keeper: the followed upper body leans D deg further forward "
                    "per metre the humanoid is behind (0: off)")
    ap.add_argument("--lean-max", type=float, default=PaceKeeper().lean_max_deg, metavar="D",
                    help="the lean keeper's largest lean, deg")
    ap.add_argument("--shift", type=float, default=0.0, metavar="S",
                    help="play every segment S seconds later in its file (those whose file is "
                    "too short are dropped): walks under way instead of from their start")
    ap.add_argument("--warm-up", type=float, default=0.0, metavar="S",
                    help="start KinematicsNet from the truth S seconds before each segment, on "
                    "the frames before it in its file (as many as there are), instead of at its "
                    "first frame: does the estimator's cold start cost the pace? (reference "
                    "'estimate' only; each row's warm_frames says how many it got)")
    ap.add_argument("--json", required=True)
    args = ap.parse_args(argv)
    for name in ("policy", "kin"):
        if not Path(getattr(args, name)).is_file():
            ap.error(f"--{name} {getattr(args, name)}: no such file")
    bad = [r for r in args.references.split(",") if r not in REFERENCES]
    if bad:
        ap.error(f"--references: unknown {bad}; choose from {', '.join(REFERENCES)}")

    import torch

    torch.set_num_threads(1)
    segs, _keep = split_segments(args)  # (_keep: the speed-scaled recordings, read below)
    setup = PolicySetup((args.policy,), args.kin)
    choose = fold_chooser(args.kin_fold, args.data) if args.kin_fold else None
    out: dict = {"policy": args.policy, "kin": args.kin_fold or args.kin, "data": args.data,
                 "split": args.split, "root_speed_scale": args.root_speed_scale,
                 "pace_gain": args.pace_gain, "pace_lead_max_m": args.pace_lead_max,
                 "lean_gain_deg": args.lean_gain, "lean_max_deg": args.lean_max,
                 "speed_factor": args.speed_factor, "segments": len(segs),
                 "warm_up_s": args.warm_up, "shift_s": args.shift, "lean_deg": args.lean,
                 "by_reference": {}}  # fmt: skip
    for ref in args.references.split(","):
        rows = play(setup, segs, ref, choose, args.root_speed_scale,
                    PaceKeeper(args.pace_gain, args.pace_lead_max, args.lean_gain,
                               args.lean_max), args.warm_up,
                    args.lean)  # fmt: skip
        kept = [r for r in rows if not r["fell"]]
        out["by_reference"][ref] = {
            "rows": rows,
            "kept": len(kept),
            "median_without_fall": {k: _median(kept, k) for k in (
                "gap_1s_m", "gap_5s_m", "gap_end_m", "along_5s_m", "across_5s_m", "speed_ratio",
                "sim_to_truth_5s_m", "sim_behind_truth_5s_m", "gt_speed_mps",
                "ref_speed_mps", "sim_speed_mps", "leg_saturated", "leg_abs_action")},
            "followed_to_truth_all_segments": {k: _median(rows, k) for k in (
                "ref_to_truth_1s_m", "ref_to_truth_5s_m", "ref_to_truth_end_m",
                "ref_over_truth_speed", "pelvis_heading_err_deg")},
            "max_gap_5s_without_fall_m": max((r["gap_5s_m"] for r in kept
                                              if r["gap_5s_m"] is not None), default=None),
        }  # fmt: skip
        m = out["by_reference"][ref]["median_without_fall"]
        deficit = m["ref_speed_mps"] - m["sim_speed_mps"]
        out["by_reference"][ref]["reward_at_median_deficit"] = reward_cost(deficit)
    Path(args.json).write_text(json.dumps(out, indent=1))
    for ref, r in out["by_reference"].items():
        print(ref, "followed pelvis to the truth's:",
              json.dumps(r["followed_to_truth_all_segments"]))
        print(ref, json.dumps(r["median_without_fall"]), "max gap 5 s",
              r["max_gap_5s_without_fall_m"], json.dumps(r["reward_at_median_deficit"]))


def split_segments(args) -> tuple[list, object]:
    """``(segments, temporary folder or None)``: the ``--segments`` locomotion segments of
    ``--split`` (evenly over its list), played ``--speed-factor`` times faster when given (the
    folder holds those recordings; keep it alive while the segments are read)."""
    from grip.eval.segments import list_segments, split_files

    files = split_files(args.data, args.split)
    tmp = None
    if args.speed_factor is not None:
        import tempfile

        tmp = tempfile.TemporaryDirectory(prefix="pace_speed_")
        files = _speed_scaled(args.data, files, args.categories.split(","), args.speed_factor,
                              Path(tmp.name))  # fmt: skip
    segs = list_segments(files, args.segment_frames, args.categories.split(","))
    if args.shift > 0:
        segs = shifted_segments(segs, args.shift)
    if 0 < args.segments < len(segs):
        segs = [segs[i] for i in np.linspace(0, len(segs) - 1, args.segments).round().astype(int)]
    return segs, tmp


def shifted_segments(segs: list, seconds: float) -> list:
    """Each segment ``seconds`` later in its file, as long as before (``_shift`` appended to its
    id); a segment whose file ends before that is dropped. Starts later than a clip's first
    second leave out the start of the walk (a walker who sets off from standing)."""
    import dataclasses

    from grip.eval.segments import SegmentReader

    read, out = SegmentReader(), []
    for seg in segs:
        rec = read.whole(seg)
        shift = round(seconds * float(rec.fps))
        if seg.stop + shift <= rec.n_frames:
            out.append(dataclasses.replace(seg, id=f"{seg.id}_shift", start=seg.start + shift,
                                           stop=seg.stop + shift))  # fmt: skip
    return out


def _speed_scaled(data: str, files: list[Path], categories: list[str], factor: float,
                  folder: Path) -> list[Path]:  # fmt: skip
    """The clips of ``categories`` among ``files`` played ``factor`` times faster, written to
    ``folder`` (:func:`grip.dataset.augment.time_scaled_recordings`)."""
    from grip.dataset.augment import time_scaled_recordings
    from prism_tools.io import save_recording

    recs = time_scaled_recordings(data, [f.stem for f in files], categories, (factor,))
    out = []
    for r in recs:
        path = folder / f"{r.name.replace('/', '__')}.npz"
        save_recording(r, path)
        out.append(path)
    return out


if __name__ == "__main__":
    main()
