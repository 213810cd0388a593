"""``grip reconstruct`` on malformed and partial recordings: short dropouts are filled, the
rest is reported per recording and the others are still reconstructed."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import pickle
from pathlib import Path

import numpy as np
import pytest

from grip.cli.main import main
from prism_tools.io import load_recording

SAMPLE = "grip/assets/sample_recording.npz"


def _with_nan(rec, part: str, first: int, n: int):
    acc = np.array(rec.imu[part].acc_world_filt, copy=True)
    acc[first : first + n] = np.nan
    imu = dict(rec.imu)
    imu[part] = dataclasses.replace(rec.imu[part], acc_world_filt=acc)
    return dataclasses.replace(rec, imu=imu)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("recs")
    rec = load_recording(SAMPLE).slice_frames(0, 40)
    cases = {
        "gap": _with_nan(rec, "L_Wrist", 10, 3),  # 3 frames: filled
        "long_gap": _with_nan(rec, "L_Wrist", 10, 25),  # longer than --fill-gaps: refused
        "no_insole": dataclasses.replace(rec, insole={"L_Foot": rec.insole["L_Foot"]}),
        "no_wrist": dataclasses.replace(
            rec, imu={k: v for k, v in rec.imu.items() if k != "R_Wrist"}
        ),
    }
    out = {}
    for name, r in cases.items():  # written as a PRISM pickle (save_recording refuses NaN)
        out[name] = d / f"{name}.pkl"
        with open(out[name], "wb") as f:
            pickle.dump(r.to_prism_dict(), f, protocol=4)
    return out


def test_bad_recordings_are_reported_and_the_others_reconstructed(files, tmp_path, capsys):
    out = tmp_path / "out"
    argv = ["reconstruct", *map(str, files.values()), "--out", str(out), "--fill-gaps", "10"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    (row,) = summary["recordings"]
    assert row["file"] == str(files["gap"]) and row["frames"] == 40
    assert row["filled_gaps"] == [{"key": "imu.L_Wrist.acc_world_filt", "first": 10, "last": 12}]
    errors = summary["errors"]
    assert set(errors) == {str(files[k]) for k in ("long_gap", "no_insole", "no_wrist")}
    assert "non-finite" in errors[str(files["long_gap"])]
    assert "R_Foot" in errors[str(files["no_insole"])]
    assert "R_Wrist" in errors[str(files["no_wrist"])]
    assert "model trained for the sensors present" in errors[str(files["no_wrist"])]
    assert err.count("not reconstructed") == 3
    # without filling, the dropout fails its recording too
    assert main(["reconstruct", str(files["gap"]), "--out", str(tmp_path / "o2"),
                 "--fill-gaps", "0"]) == 1  # fmt: skip
    assert "first at frame 10" in capsys.readouterr().err


@pytest.fixture(scope="module")
def takes(tmp_path_factory):
    """One short recording saved under PRISM-like paths that share a ``subjNNN/takeNNN`` tail
    (and so a recording name) in two folders, and once more as a pickle beside one of them."""
    from prism_tools.io import save_recording

    d = tmp_path_factory.mktemp("takes")
    rec = load_recording(SAMPLE).slice_frames(0, 20)
    paths = [d / "a" / "subj001" / "take001.npz", d / "b" / "subj001" / "take001.npz",
             d / "a" / "subj001" / "take001.pkl"]  # fmt: skip
    for p in paths:
        save_recording(rec, p)
    return paths


def test_outputs_of_different_inputs_never_share_a_name(takes, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["reconstruct", *map(str, takes), "--out", str(out), "--formats",
                 "npz,bvh,amass,html"]) == 0  # fmt: skip
    printed = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    stems = [r["stem"] for r in summary["recordings"]]
    assert stems == ["a__subj001__take001_npz", "b__subj001__take001", "a__subj001__take001_pkl"]
    assert sorted(p.name for p in out.glob("*.npz") if not p.name.endswith("_amass.npz")) \
        == sorted(f"{s}.npz" for s in stems)  # fmt: skip
    assert sorted(p.name for p in out.glob("*.bvh")) == sorted(f"{s}.bvh" for s in stems)
    assert sorted(p.name for p in out.glob("*.html")) == sorted(f"{s}.html" for s in stems)
    assert len(list(out.glob("*_amass.npz"))) == 3
    assert "wrote 3 reconstruction(s)" in printed and "0 blow-up(s) recovered" in printed
    assert summary["blowups"] == sum(r["blowups"] for r in summary["recordings"]) == 0
    # a single input keeps its file name; a later input with that name gets another one
    one = tmp_path / "one"
    assert main(["reconstruct", str(takes[0]), "--out", str(one)]) == 0
    assert main(["reconstruct", str(takes[1]), "--out", str(one)]) == 0
    summary = json.loads((one / "summary.json").read_text())
    assert [r["stem"] for r in summary["recordings"]] == ["take001", "take001-2"]
    assert sorted(p.name for p in one.glob("*.npz")) == ["take001-2.npz", "take001.npz"]


def test_resume_with_other_settings_is_refused(takes, tmp_path, capsys):
    out = tmp_path / "out"
    base = ["reconstruct", str(takes[0]), "--out", str(out), "--max-frames", "15"]
    assert main(base) == 0
    before = (out / "take001.npz").stat().st_mtime_ns
    for extra in (["--max-frames", "12"], ["--history", "20"], ["--no-recovery"],
                  ["--fill-gaps", "3"], ["--init", "standing"],
                  ["--lost-gap", "0"], ["--lost-gap", "0.3"]):  # fmt: skip
        assert main([*base, *extra]) == 2
        err = capsys.readouterr().err
        assert "different settings" in err and "--overwrite" in err
    # the same model file elsewhere is the same model; a changed one is not
    policy = tmp_path / "policy.pt"
    policy.write_bytes(Path("grip/assets/policy_default.pt").read_bytes())
    assert main([*base, "--policy", str(policy)]) == 0
    assert "1 already done" in capsys.readouterr().out
    with open(policy, "ab") as f:
        f.write(b"\0")
    assert main([*base, "--policy", str(policy)]) == 2
    assert "policy_sha256" in capsys.readouterr().err
    assert (out / "take001.npz").stat().st_mtime_ns == before
    # --overwrite redoes them with the new settings
    assert main([*base[:-1], "12", "--overwrite"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["settings"]["max_frames"] == 12 and summary["recordings"][0]["frames"] == 12


def test_a_recording_replaced_in_place_is_refused(tmp_path, capsys):
    from prism_tools.io import save_recording

    rec = load_recording(SAMPLE)
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    save_recording(rec.slice_frames(0, 20), a)
    save_recording(rec.slice_frames(20, 40), b)
    out = tmp_path / "out"
    base = ["reconstruct", str(a), str(b), "--out", str(out)]
    assert main(base) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert [r["input"]["sha256"] for r in summary["recordings"]] == [
        hashlib.sha256(p.read_bytes()).hexdigest() for p in (a, b)]  # fmt: skip
    before = (out / "b.npz").read_bytes()
    save_recording(rec.slice_frames(40, 60), b)  # another take written over b.npz
    capsys.readouterr()
    assert main(base) == 2
    err = capsys.readouterr().err
    assert str(b.resolve()) in err and "contents changed" in err
    assert "--overwrite" in err and "another --out" in err
    assert (out / "b.npz").read_bytes() == before  # nothing redone, nothing mixed
    assert main([*base, "--overwrite"]) == 0
    # a summary written before the inputs were recorded: nothing to compare, it resumes
    summary = json.loads((out / "summary.json").read_text())
    for r in summary["recordings"]:
        del r["input"]
    (out / "summary.json").write_text(json.dumps(summary))
    capsys.readouterr()
    assert main(base) == 0
    printed = capsys.readouterr().out
    assert "2 already done" in printed and "no record of the contents of 2" in printed


def test_a_recording_without_ground_truth_is_reconstructed(tmp_path, capsys):
    """Real sensors and no motion capture: the humanoid starts from the standing pose at the
    feet's heading and every frame comes out."""
    from grip.core.reconstruction import Reconstruction
    from prism_tools.io import save_recording

    rec = load_recording(SAMPLE)
    path = tmp_path / "sensors_only.npz"
    save_recording(dataclasses.replace(rec, smpl_params=None, imu_gt={}), path)
    out = tmp_path / "out"
    assert main(["reconstruct", str(path), "--out", str(out)]) == 0
    recon = Reconstruction.load(out / "sensors_only.npz")
    assert recon.n_frames == rec.n_frames
    assert np.isfinite(recon.joint_pos).all()
    # what needs the ground truth says so, naming the file
    assert main(["export", str(out / "sensors_only.npz"), "--gt", str(path), "--formats", "png",
                 "--out", str(tmp_path / "exp")]) != 0  # fmt: skip
    assert f"{path}: " in capsys.readouterr().err


def test_init_standing_starts_as_without_ground_truth(tmp_path):
    """--init standing on a recording with ground truth: the reconstruction of the same
    recording with its motion capture removed, moved to the truth's frame-0 horizontal pelvis
    position (the gauge of :func:`grip.kinematics.features.standing_calibration`; the floor is
    flat, the simulation the same up to rounding)."""
    from grip.core.reconstruction import Reconstruction
    from grip.kinematics.features import targets
    from prism_tools.io import save_recording

    rec = load_recording(SAMPLE)
    path = tmp_path / "no_mocap.npz"
    save_recording(dataclasses.replace(rec, smpl_params=None), path)
    args = ["--max-frames", "40", "--batch", "1"]
    assert main(["reconstruct", str(SAMPLE), "--out", str(tmp_path / "a"), "--init", "standing",
                 *args]) == 0  # fmt: skip
    assert main(["reconstruct", str(path), "--out", str(tmp_path / "b"), *args]) == 0
    assert main(["reconstruct", str(SAMPLE), "--out", str(tmp_path / "c"), *args]) == 0
    a = Reconstruction.load(next((tmp_path / "a").glob("*.npz")))
    b = Reconstruction.load(tmp_path / "b" / "no_mocap.npz")
    c = Reconstruction.load(next((tmp_path / "c").glob("*.npz")))
    shift = np.append(targets(rec.slice_frames(0, 2)).root_pos[0, :2], 0.0)
    np.testing.assert_allclose(a.joint_pos, b.joint_pos + shift, atol=1e-6)
    np.testing.assert_allclose(a.global_rot, b.global_rot, atol=1e-6)
    assert np.abs(a.joint_pos[0] - c.joint_pos[0]).max() > 1e-3  # truth starts elsewhere
