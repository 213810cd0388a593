"""benchmarks/pace_cause.py: how far the followed pelvis runs from the truth's."""

from __future__ import annotations

import numpy as np
import pytest

from tests.cli.test_data_cli import _benchmark


def _walk(speed: float, frames: int, fps: float = 100.0) -> np.ndarray:
    t = np.arange(frames) / fps
    return np.stack([speed * t, np.zeros(frames), np.full(frames, 0.9)], axis=1)


def test_a_followed_pelvis_that_runs_ahead_of_the_truth() -> None:
    pc = _benchmark("pace_cause")
    truth = _walk(1.2, 600)
    ahead = _walk(1.32, 700)[:, :2] + [3.0, -2.0]  # 10 % faster, starting elsewhere
    d = pc.followed_to_truth(ahead, truth, 100.0)
    assert d["ref_to_truth_1s_m"] == pytest.approx(0.12, abs=1e-9)
    assert d["ref_to_truth_5s_m"] == pytest.approx(0.12 * 4.99, abs=1e-9)
    assert d["ref_to_truth_end_m"] == pytest.approx(0.12 * 5.99, abs=1e-9)  # common frames only
    assert d["ref_over_truth_speed"] == pytest.approx(1.1)
    same = pc.followed_to_truth(truth[:, :2] + 5.0, truth, 100.0)
    assert max(same[k] for k in ("ref_to_truth_1s_m", "ref_to_truth_5s_m")) < 1e-9
    short = pc.followed_to_truth(truth[:300, :2], truth, 100.0)
    assert short["ref_to_truth_5s_m"] is None  # a segment shorter than 5 s has no 5 s value


def test_hybrid_references_take_the_estimate_apart() -> None:
    from grip.kinematics.features import targets
    from grip.kinematics.reference import oracle_reference_clip, reference_clip
    from prism_tools.synthetic import make_recording

    pc = _benchmark("pace_cause")
    rec = make_recording(200, seed=3)
    truth = oracle_reference_clip(rec)
    t = targets(rec)
    slow = t.velocity * 0.5  # an estimate whose every velocity is half the truth's
    est = reference_clip(rec, t.joint_pos + 0.01, t.global_rot, slow, truth.sensor)
    pose = pc.hybrid_clip(est, truth, "pose")
    np.testing.assert_array_equal(pose.est_pos, est.est_pos)
    np.testing.assert_array_equal(pose.est_vel[:, :-1], est.est_vel[:, :-1])
    np.testing.assert_allclose(pose.est_root_pos, truth.est_root_pos, atol=1e-9)  # the truth's path
    root = pc.hybrid_clip(est, truth, "root")
    np.testing.assert_array_equal(root.est_pos, truth.est_pos)
    np.testing.assert_array_equal(root.est_vel[:, :-1], truth.est_vel[:, :-1])
    np.testing.assert_allclose(root.est_root_pos, est.est_root_pos, atol=1e-9)  # the estimate's
    assert np.linalg.norm(est.est_root_pos[-1] - truth.est_root_pos[-1]) > 0.2
    with pytest.raises(ValueError, match="keep"):
        pc.hybrid_clip(est, truth, "legs")


def test_pelvis_heading_error_of_an_estimate_turned_about_the_vertical() -> None:
    from grip.core.rotations import rot_z
    from grip.kinematics.features import targets
    from grip.kinematics.reference import oracle_reference_clip, reference_clip
    from prism_tools.synthetic import make_recording

    pc = _benchmark("pace_cause")
    rec = make_recording(120, seed=2)
    truth = oracle_reference_clip(rec)
    assert pc.pelvis_heading_error_deg(truth) < 1e-9
    t = targets(rec)
    turned = rot_z(np.radians(-7.0)) @ t.global_rot  # every segment 7 deg to the right
    est = reference_clip(rec, t.joint_pos, turned, t.velocity, truth.sensor)
    assert pc.pelvis_heading_error_deg(est) == pytest.approx(7.0, abs=1e-6)


def test_fold_models_estimate_the_people_they_never_saw(tmp_path, monkeypatch) -> None:
    """``--kin-fold``: each recording goes to the fold model that held its person out."""
    import json

    from grip.kinematics.dataset import group_fold
    from grip.kinematics.inference import KinematicsEstimator
    from prism_tools.synthetic import make_recording
    from tests.kinematics.test_cross_fit import _FoldModel

    pc = _benchmark("pace_cause")
    members = {f"src/p{p}": [f"src/p{p}_clip0"] for p in range(6)}
    (tmp_path / "split.json").write_text(json.dumps(
        {"format": "grip-prism-split", "version": 1, "train": [], "test": [],
         "split_by": "person", "members": members}))  # fmt: skip
    models = {"f0.pt": _FoldModel(0), "f1.pt": _FoldModel(1)}
    monkeypatch.setattr(KinematicsEstimator, "from_checkpoint", lambda p, tta="none": models[p])
    choose = pc.fold_chooser(["f1.pt", "f0.pt"], str(tmp_path))
    for p in range(6):
        rec = make_recording(20, seed=p)
        rec.extras["source_clip"] = f"src/p{p}_clip0"
        assert choose(rec).fold == group_fold(f"src/p{p}", 2, 0)
    monkeypatch.setattr(KinematicsEstimator, "from_checkpoint",
                        lambda p, tta="none": _FoldModel(0, val_source="test"))  # fmt: skip
    with pytest.raises(ValueError, match="not fold models"):
        pc.fold_chooser(["a.pt", "b.pt"], str(tmp_path))


def test_a_root_speed_scaled_clip_travels_further_with_the_same_pose() -> None:
    from grip.kinematics.reference import oracle_reference_clip
    from prism_tools.synthetic import make_recording

    pc = _benchmark("pace_cause")
    clip = oracle_reference_clip(make_recording(200, seed=5))
    fast = pc.root_speed_scaled(clip, 1.1)
    np.testing.assert_array_equal(fast.est_pos, clip.est_pos)
    shift = fast.est_vel - clip.est_vel  # (every velocity joint: the pelvis' extra velocity)
    np.testing.assert_allclose(shift[..., :2], 0.1 * np.repeat(clip.est_vel[:, -1:, :2], 6, 1),
                               atol=1e-12)  # fmt: skip
    np.testing.assert_array_equal(shift[..., 2], 0.0)
    moved = clip.est_root_pos[-1, :2] - clip.est_root_pos[0, :2]
    moved_fast = fast.est_root_pos[-1, :2] - fast.est_root_pos[0, :2]
    assert np.linalg.norm(moved) > 0.1
    np.testing.assert_allclose(moved_fast, 1.1 * moved, rtol=1e-6, atol=1e-9)


def test_paired_speed_ratio_pairs_the_walks_kept_in_both_runs() -> None:
    pp = _benchmark("pace_paired")

    def run(speeds: dict) -> dict:
        rows = [{"segment": k, "fell": v is None, "sim_speed_mps": v or 0.0}
                for k, v in speeds.items()]  # fmt: skip
        return {"by_reference": {"estimate": {"rows": rows}}}

    a = run({"w1": 1.0, "w2": 2.0, "w3": 1.0, "w4": None})
    b = run({"w1": 1.1, "w2": 2.4, "w3": None, "w4": 3.0, "w5": 1.0})
    got = pp.paired_speed_ratio(a, b)
    assert got["walks"] == 2
    assert got["median"] == pytest.approx(1.15) and got["mean"] == pytest.approx(1.15)
    assert pp.paired_speed_ratio(a, run({"w3": None}))["walks"] == 0


def test_first_second_figures_of_an_estimate() -> None:
    """``benchmarks/estimate_first_second.py``: the truth against itself gives ratios of 1 and
    no error (NaN where the truth stands still: this walk's first second); a root carried 10 %
    faster and feet that move 20 % faster show as such."""
    from types import SimpleNamespace

    from grip.kinematics.reference import oracle_reference_clip
    from prism_tools.synthetic import make_recording

    fs = _benchmark("estimate_first_second")
    truth = oracle_reference_clip(make_recording(300, seed=5))
    same = fs.window_ratios(truth, truth)
    assert same["joint_err_first_m"] == same["joint_err_rest_m"] == 0.0
    assert np.isnan(same["root_speed_ratio_first"])  # (it stands in its first second)
    assert same["root_speed_ratio_rest"] == pytest.approx(1.0)
    root = truth.est_root_pos.copy()
    root[:, :2] = root[0, :2] + 1.1 * (root[:, :2] - root[0, :2])
    pos = truth.est_pos.copy()
    pos[:, list(fs.FEET)] = 1.2 * pos[:, list(fs.FEET)]
    other = fs.window_ratios(SimpleNamespace(fps=truth.fps, est_root_pos=root, est_pos=pos), truth)
    assert other["root_speed_ratio_rest"] == pytest.approx(1.1, rel=1e-6)
    assert other["feet_speed_ratio_rest"] == pytest.approx(1.2, rel=1e-6)
    assert other["joint_err_rest_m"] > 0.0
    # The walker's own speed: this one sets off from standing; one at 1.2 m/s throughout does not.
    assert same["setting_off"] == 1.0 and same["truth_speed_0_0.3s_mps"] < 0.05
    steady_root = np.zeros((300, 3))
    steady_root[:, 0] = 1.2 * np.arange(300) / truth.fps
    steady = SimpleNamespace(fps=truth.fps, est_root_pos=steady_root, est_pos=truth.est_pos)
    w = fs.window_ratios(steady, steady)
    assert w["setting_off"] == 0.0
    for k in ("truth_speed_0_0.3s_mps", "truth_speed_0.3_1s_mps", "truth_speed_after_1s_mps"):
        assert w[k] == pytest.approx(1.2, rel=1e-6)


def test_warm_clip_settles_the_estimator_before_the_segment(tmp_path) -> None:
    """``--warm-up``: the estimate of a segment starts the KinematicsNet on the frames before
    it (as many as its file has), then is cut to the segment, its truth and root start those
    of the segment; a segment at its file's start has no frames before it (a cold start)."""
    from grip.assets import SHIPPED_KIN
    from grip.eval.policy import _estimates
    from grip.eval.segments import Segment, SegmentReader
    from grip.kinematics.features import ground_truth
    from grip.kinematics.inference import KinematicsEstimator
    from prism_tools.io import save_recording
    from prism_tools.synthetic import make_recording

    pc = _benchmark("pace_cause")
    path = tmp_path / "walk.npz"
    save_recording(make_recording(260, seed=4), path)
    est = KinematicsEstimator.from_checkpoint(SHIPPED_KIN)
    read = SegmentReader()
    seg = Segment("walk_f000060", path, 60, 260, "walk")
    warm, w = pc.warm_clip(est, read, seg, 0.5)
    assert w == 50  # 0.5 s at 100 Hz, all of it before the segment
    cold = _estimates(est, [read(seg)], 1, "estimate", "truth")[0]
    np.testing.assert_allclose(warm.gt_qpos, cold.gt_qpos)
    np.testing.assert_allclose(warm.est_root_pos[0], ground_truth(read(seg)).root_pos[0],
                               atol=1e-9)  # fmt: skip
    assert warm.n_frames == 200 and not np.allclose(warm.est_pos[:5], cold.est_pos[:5])
    assert pc.warm_clip(est, read, seg, 2.0)[1] == 60  # (only 60 frames before it)
    assert pc.warm_clip(est, read, Segment("walk_f000000", path, 0, 200, "walk"), 1.0)[1] == 0
    # --shift: later in the file, or dropped where the file ends before
    shifted = pc.shifted_segments([Segment("walk_f000000", path, 0, 200, "walk"), seg], 0.5)
    assert [(s.id, s.start, s.stop) for s in shifted] == [("walk_f000000_shift", 50, 250)]


def test_stride_amplitude_of_an_estimate_against_the_truth(tmp_path, monkeypatch) -> None:
    """``benchmarks/stride_amplitude.py``: an estimate whose ankles swing 0.8 times as far
    apart as the walker's scores 0.8, the truth itself 1.0 (``--shift`` as pace_cause's)."""
    import dataclasses
    import json

    from grip.kinematics.features import targets
    from grip.kinematics.inference import KinematicsEstimator
    from prism_tools.chunking import make_split, save_split
    from prism_tools.io import save_recording
    from prism_tools.synthetic import make_recording

    sa = _benchmark("stride_amplitude")
    for i in range(2):
        rec = make_recording(300, seed=i)
        rec = dataclasses.replace(rec, extras={**rec.extras, "take_name": f"t{i}",
                                               "category": "walk"})  # fmt: skip
        save_recording(rec, tmp_path / "sequences" / f"t{i}.npz")
    save_split(make_split(["t0", "t1"], test_fraction=0.5), tmp_path / "split.json")

    class Shrunk:
        def __init__(self, scale: float) -> None:
            self.scale = scale

        def predict(self, recs):
            t = targets(recs[0])
            pos = t.joint_pos.copy()
            pos[..., :2] *= self.scale  # (root-relative joints: every horizontal offset)
            return [dataclasses.replace(t, joint_pos=pos)]

    for scale in (1.0, 0.8):
        monkeypatch.setattr(KinematicsEstimator, "from_checkpoint",
                            lambda p, tta="none", s=scale: Shrunk(s))  # fmt: skip
        out = tmp_path / f"s{scale}.json"
        sa.main(["--data", str(tmp_path), "--json", str(out), "--segment-frames", "100",
                 "--shift", "0.2"])  # fmt: skip
        got = json.loads(out.read_text())
        assert got["segments"] >= 1
        assert got["median_ratio"] == pytest.approx(scale, rel=1e-6)
        assert got["median_legs_ratio"] == pytest.approx(scale, rel=1e-6)
        assert all(r["segment"].endswith("_shift") for r in got["rows"])


def test_leg_speed_is_the_rate_the_ankles_part_and_close() -> None:
    """Ankles that swing 0.3 m either way of each other along one axis, twice a second: the
    offset travels 4 x 0.3 m per cycle, 2.4 m per second, whatever the axis' direction; legs
    held still: 0."""
    sa = _benchmark("stride_amplitude")
    t = np.arange(1001) / 100.0
    pos = np.zeros((len(t), 24, 3))
    u = np.array([0.6, 0.8])
    pos[:, 7, :2] = (0.3 * np.sin(2 * np.pi * 2 * t))[:, None] * u
    pos[:, 8, :2] = 0.1  # (the right ankle still: its offset is the left's alone)
    assert sa.leg_speed(pos, 100.0) == pytest.approx(4 * 0.3 * 2, rel=0.01)
    assert sa.leg_speed(np.zeros((50, 24, 3)), 100.0) == 0.0


def test_a_leaned_clip_turns_the_upper_body_towards_the_travel() -> None:
    """``--lean``: the neck's offset from the pelvis turns DEG towards the direction the walker
    travels; the legs, the pelvis and the root path stay; 0 deg changes nothing."""
    from grip.kinematics.reference import oracle_reference_clip
    from prism_tools.synthetic import make_recording

    pc = _benchmark("pace_cause")
    clip = oracle_reference_clip(make_recording(200, seed=4))
    same = pc.leaned_clip(clip, 0.0)
    np.testing.assert_allclose(same.est_pos, clip.est_pos, atol=1e-12)
    np.testing.assert_allclose(same.est_rot, clip.est_rot, atol=1e-9)
    lean = pc.leaned_clip(clip, 10.0)
    legs = [0, 1, 2, 4, 5, 7, 8, 10, 11]
    np.testing.assert_allclose(lean.est_pos[:, legs], clip.est_pos[:, legs], atol=1e-12)
    np.testing.assert_allclose(lean.est_root_pos, clip.est_root_pos, atol=1e-9)
    t = 100
    fwd = clip.gt_vel[t - 50:t + 50, 0, :2].mean(axis=0)
    fwd = np.append(fwd / np.linalg.norm(fwd), 0.0)

    def pitch(pos):  # the neck's angle from the vertical towards the travel, deg
        n = pos[t, 12]
        return np.degrees(np.arctan2(n @ fwd, n[2]))

    assert pitch(lean.est_pos) - pitch(clip.est_pos) == pytest.approx(10.0, abs=1.0)
    neck = lean.est_rot[t, 12] @ clip.est_rot[t, 12].T  # the neck's rotation turned the same
    assert np.degrees(np.arccos((np.trace(neck) - 1) / 2)) == pytest.approx(10.0, abs=1e-6)


def test_trunk_lean_towards_the_travel() -> None:
    """``stride_amplitude.trunk_lean_deg``: a neck 10 deg ahead of the pelvis along the walk
    leans +10, behind it -10; a root that does not travel gives NaN."""
    sa = _benchmark("stride_amplitude")
    pos = np.zeros((50, 24, 3))
    a = np.radians(10.0)
    pos[:, 12] = [0.0, 0.5 * np.sin(a), 0.5 * np.cos(a)]  # (the neck ahead along +y)
    root = np.zeros((50, 3))
    root[:, 1] = np.linspace(0.0, 1.0, 50)
    assert sa.trunk_lean_deg(pos, root) == pytest.approx(10.0)
    assert sa.trunk_lean_deg(pos, root[::-1]) == pytest.approx(-10.0)
    assert np.isnan(sa.trunk_lean_deg(pos, np.zeros((50, 3))))
