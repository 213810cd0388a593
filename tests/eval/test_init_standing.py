"""``--init standing`` of ``grip policy eval`` and ``grip bench`` (issue 33, no oracle at the
start): every method starts from the standing calibration (PIP's physics from the
estimate's first pose, on the floor) and reads no ground-truth pose for it
(a recording whose ground truth of frames 0-1 is altered gives the same reconstruction under
``standing`` and another under ``truth``), bench folders resume only with their own ``--init``,
and the standing pelvis stands at the truth's frame-0 horizontal position (the gauge)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

import grip.eval.policy as P
from grip.assets import SAMPLE_RECORDING, SHIPPED_KIN, SHIPPED_POLICY
from grip.cli.main import main
from grip.core.mjcf import standing_qpos
from grip.eval.methods import MethodOptions, make_method
from grip.kinematics import features as F
from prism_tools.chunking import make_split, save_split
from prism_tools.io import load_recording, save_recording
from prism_tools.synthetic import make_recording

FRAMES = 60


def _altered(rec):
    """``rec`` with another ground truth at frames 0 and 1 (pose and height; the frame-0
    horizontal position, the gauge of the standing start, kept)."""
    sp = rec.smpl_params
    poses = np.array(sp.poses, dtype=np.float32)
    trans = np.array(sp.trans, dtype=np.float64)
    poses[:2, 3:] += 0.3
    trans[:2, 2] += 0.05
    trans[1, :2] += 0.02
    return dataclasses.replace(rec, smpl_params=dataclasses.replace(sp, poses=poses, trans=trans))


@pytest.fixture(scope="module")
def walk():
    """The bundled real walk, its first :data:`FRAMES` frames."""
    return load_recording(SAMPLE_RECORDING).slice_frames(0, FRAMES)


# ----------------------------------------------------------------------------------- gauge
def test_standing_pelvis_stands_at_the_truths_first_horizontal_position(walk) -> None:
    cal = F.standing_calibration(walk)
    truth = F.targets(walk).root_pos[0]
    height = standing_qpos(F.recording_body(walk))[2]
    for t in range(2):
        np.testing.assert_allclose(cal.root_pos[t, :2], truth[:2], atol=1e-12)
        np.testing.assert_allclose(cal.root_pos[t, 2], height, atol=1e-12)
    np.testing.assert_array_equal(F.recording_calibration(walk, init="standing").root_pos,
                                  cal.root_pos)  # fmt: skip
    no_gt = F.standing_calibration(dataclasses.replace(walk, smpl_params=None))
    np.testing.assert_allclose(no_gt.root_pos[:, :2], 0.0, atol=1e-12)  # the origin
    np.testing.assert_array_equal(no_gt.local_rot, cal.local_rot)  # heading from the feet


# --------------------------------------------------------------------------------- bench
@pytest.mark.parametrize("name", ["kinematics", "kin+pip", "transpose", "pip", "grip"])
def test_bench_methods_start_standing_without_the_truths_pose(name, walk) -> None:
    """The same reconstruction from a recording whose first two ground-truth frames differ
    (standing); another one from the truth; the pelvis starts at the standing calibration's."""
    standing = make_method(name, MethodOptions(init="standing"))
    a, b = standing.reconstruct(walk), standing.reconstruct(_altered(walk))
    np.testing.assert_array_equal(a.joint_pos, b.joint_pos)
    np.testing.assert_array_equal(a.global_rot, b.global_rot)
    root0 = F.standing_calibration(walk).root_pos[0]
    if name in ("kin+pip", "pip"):  # PIP's physics: the estimate's first pose, on the floor
        from grip.core.body import build_body
        from grip.core.fk import sole_points

        np.testing.assert_allclose(a.joint_pos[0, 0, :2], root0[:2], atol=1e-6)
        soles = sole_points(a.global_rot[0], a.joint_pos[0], build_body(F.recording_body(walk)))
        assert abs(soles[..., 2].min()) < 1e-6
    else:
        np.testing.assert_allclose(a.joint_pos[0, 0], root0, atol=1e-6 if name != "grip" else 0.05)
    truth = make_method(name, MethodOptions())
    c, d = truth.reconstruct(walk), truth.reconstruct(_altered(walk))
    assert np.abs(c.joint_pos - d.joint_pos).max() > 1e-3


def test_method_options_refuse_an_unknown_init() -> None:
    with pytest.raises(ValueError, match="init must be one of"):
        MethodOptions(init="oracle")
    assert MethodOptions(init="standing").to_dict()["init"] == "standing"


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    """Two synthetic takes, both in the test split."""
    root = tmp_path_factory.mktemp("data")
    for i, name in enumerate(("take0", "take1")):
        rec = make_recording(FRAMES + 10, seed=30 + i)
        rec = dataclasses.replace(rec, extras={**rec.extras, "take_name": name,
                                               "category": "walk"})  # fmt: skip
        save_recording(rec, root / "sequences" / f"{name}.npz")
    save_split(make_split(["take0", "take1"], test_fraction=1.0), root / "split.json")
    return root


def test_cli_bench_init_is_reported_and_a_folder_resumes_only_with_its_own(
    dataset, tmp_path, capsys
) -> None:
    base = ["bench", "--data", str(dataset), "--methods", "kinematics", "--segment-frames",
            str(FRAMES), "--workers", "1"]  # fmt: skip
    out = tmp_path / "standing"
    assert main([*base, "--out", str(out), "--init", "standing"]) == 0
    assert json.loads((out / "results.json").read_text())["kinematics"]["init"] == "standing"
    assert "each started from the standing pose" in (out / "table.md").read_text()
    method = out / "segments" / "kinematics" / "method.json"
    assert json.loads(method.read_text())["options"]["init"] == "standing"
    capsys.readouterr()
    assert main([*base, "--out", str(out)]) == 2  # --init truth on a standing folder
    err = capsys.readouterr().err
    assert "other settings" in err and "'standing'" in err

    # a folder written before --init existed started from the truth: it resumes as truth only
    old = tmp_path / "old"
    assert main([*base, "--out", str(old)]) == 0
    settings = json.loads((old / "segments" / "kinematics" / "method.json").read_text())
    del settings["options"]["init"]
    (old / "segments" / "kinematics" / "method.json").write_text(json.dumps(settings))
    assert main([*base, "--out", str(old), "--init", "truth"]) == 0
    assert main([*base, "--out", str(old), "--init", "standing"]) == 2


# ------------------------------------------------------------------------------ policy eval
@pytest.fixture(scope="module")
def models():
    """The shipped controller and KinematicsNet."""
    from grip.kinematics.inference import KinematicsEstimator
    from policies.controller import load_controller

    return load_controller([SHIPPED_POLICY]), KinematicsEstimator.from_checkpoint(SHIPPED_KIN)


def _played(monkeypatch, runner, est, rec, **kw) -> tuple:
    """``(reconstruction, what the controller followed, row)`` of one policy eval episode."""
    got = []
    row_of = P.segment_row

    def spy(recon, clip, r):
        got.append((recon, clip))
        return row_of(recon, clip, r)

    monkeypatch.setattr(P, "segment_row", spy)
    (row,) = P.evaluate_policy(runner, est, [rec], **kw)
    return (*got[0], row)


def test_policy_eval_standing_reads_no_start_from_the_truth(monkeypatch, models, walk) -> None:
    runner, est = models
    recon, clip, row = _played(monkeypatch, runner, est, walk, init="standing")
    other, other_clip, _ = _played(monkeypatch, runner, est, _altered(walk), init="standing")
    np.testing.assert_array_equal(recon.joint_pos, other.joint_pos)
    np.testing.assert_array_equal(clip.est_root_pos, other_clip.est_root_pos)
    # the kinematics-only root starts standing too
    np.testing.assert_allclose(clip.est_root_pos[0], F.standing_calibration(walk).root_pos[0],
                               atol=1e-12)  # fmt: skip
    assert np.isfinite(row["kin_root_err_m"]) and row["frames"] > 0
    truth, _, _ = _played(monkeypatch, runner, est, walk)
    altered, _, _ = _played(monkeypatch, runner, est, _altered(walk))
    n = min(truth.n_frames, altered.n_frames)
    assert np.abs(truth.joint_pos[:n] - altered.joint_pos[:n]).max() > 1e-3
    with pytest.raises(ValueError, match="init must be one of"):
        P.evaluate_policy(runner, est, [walk], init="oracle")


def test_policy_eval_on_the_truth_still_starts_standing(monkeypatch, models, walk) -> None:
    def no_clip_start(clip):
        raise AssertionError("started from the reference clip's ground truth")

    monkeypatch.setattr(P, "start_from_clip", no_clip_start)
    runner, est = models
    (row,) = P.evaluate_policy(runner, est, [walk], reference="truth", init="standing")
    assert row["kin_MPJPE_mm"] < 10.0 and row["frames"] > 0  # it followed the truth
    with pytest.raises(AssertionError, match="reference clip"):
        P.evaluate_policy(runner, est, [walk], reference="truth")


def test_cli_policy_eval_init_standing(monkeypatch, dataset, tmp_path) -> None:
    """``grip policy eval --init standing`` builds no reference clip (whose root and start are
    the truth's) and writes its init to --json."""
    import grip.kinematics.reference as ref

    def no_clips(*a, **kw):
        raise AssertionError("reference clips start from the ground truth")

    monkeypatch.setattr(ref, "build_reference_set", no_clips)
    monkeypatch.setattr(P, "start_from_clip", no_clips)
    out = tmp_path / "eval.json"
    argv = ["policy", "eval", "--data", str(dataset), "--segment-frames", str(FRAMES),
            "--segments", "1", "--json", str(out)]  # fmt: skip
    assert main([*argv, "--init", "standing"]) == 0
    got = json.loads(out.read_text())
    assert got["init"] == "standing" and got["segments"] == 1
    with pytest.raises(AssertionError, match="ground truth"):
        main(argv)


def test_grip_from_a_standing_start_plays_the_estimate_for_the_first_second() -> None:
    """Started standing (no ground truth), GRIP's first second is KinematicsNet's estimate (the
    network converges from the standing pose; a recording begun mid-motion snaps to it) and the
    humanoid starts at the estimate after it; from the truth it starts at frame 0."""
    from grip.player import STANDING_WARMUP_S

    rec = load_recording(SAMPLE_RECORDING).slice_frames(0, 200)
    k = round(STANDING_WARMUP_S * rec.fps)
    grip = make_method("grip", MethodOptions(init="standing")).reconstruct(rec)
    kin = make_method("kinematics", MethodOptions(init="standing")).reconstruct(rec)
    assert grip.notes["warmup_frames"] == k and grip.n_frames == 200
    rel = [r.joint_pos[:k] - r.joint_pos[:k, :1] for r in (grip, kin)]
    np.testing.assert_allclose(rel[0], rel[1], atol=1e-4)  # the estimate, as kinematics gives it
    assert not grip.contacts[:k].any() and grip.contacts[k:].any()  # simulated after it
    truth = make_method("grip", MethodOptions()).reconstruct(rec)
    assert truth.notes["warmup_frames"] == 0 and truth.contacts[:k].any()
