"""``grip reconstruct`` on malformed and partial recordings: short dropouts are filled, the
rest is reported per recording and the others are still reconstructed."""

from __future__ import annotations

import dataclasses
import json
import pickle

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
