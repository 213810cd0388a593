"""A resumed ``grip bench`` never mixes two models or two versions of the data (issue 50, item 1).

A run killed after some segments, its policy file then replaced at the same path (as a training
run rewrites its ``policy.pt``), and run again once kept the old rows and reported the mean of
both models. A resume now compares the contents of every model file (``method.json``) and every
recording (``inputs.json``) and refuses a change, naming the file.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from grip.assets import SHIPPED_BASELINES, SHIPPED_KIN, SHIPPED_POLICY
from grip.cli.main import main
from grip.core import digests
from grip.core.reconstruction import Reconstruction
from grip.eval import runner as R
from grip.eval import segments as S
from grip.eval.methods import MethodOptions, model_files
from grip.kinematics.features import ground_truth
from prism_tools.chunking import make_split, save_split
from prism_tools.io import save_recording
from prism_tools.synthetic import make_recording

FRAMES = 100
TAKES = ("take0", "take1")  # 200 frames each: 4 segments


class FromModel:
    """A method whose whole model is a number in a file: its root is shifted by that many m."""

    name = "frommodel"
    supports_sensors = False
    can_fall = False

    def __init__(self, shift_m: float) -> None:
        self.shift_m = shift_m

    def reconstruct(self, rec) -> Reconstruction:
        gt = ground_truth(rec)
        return Reconstruction(name=rec.name, method=self.name, fps=rec.fps,
                              joint_pos=gt.joint_pos + np.array([self.shift_m, 0.0, 0.0]),
                              global_rot=gt.global_rot)  # fmt: skip


def _from_model(options: MethodOptions) -> FromModel:
    return FromModel(float(Path(options.policy_checkpoint).read_text()))


def _recording(name: str, seed: int):
    rec = make_recording(200, seed=seed)
    return dataclasses.replace(rec, extras={**rec.extras, "take_name": name, "category": "walk"})


@pytest.fixture
def dataset(tmp_path) -> Path:
    """A dataset of its own per test (the tests replace its files)."""
    root = tmp_path / "data"
    for i, name in enumerate(TAKES):
        save_recording(_recording(name, i), root / "sequences" / f"{name}.npz")
    save_split(make_split(list(TAKES), test_fraction=1.0), root / "split.json")
    return root


def _segments(dataset: Path) -> list[S.Segment]:
    return S.list_segments(sorted((dataset / "sequences").glob("*.npz")), FRAMES)


def _mpjpe(rows) -> list[float]:
    return [round(r["metrics"]["MPJPE_mm"], 3) for r in rows]


def test_a_model_replaced_in_place_is_refused_not_mixed(dataset, tmp_path) -> None:
    model = tmp_path / "policy.pt"
    model.write_text("0.1")
    run = R.MethodRun("m", "frommodel", _from_model, MethodOptions(policy_checkpoint=model))
    segs = _segments(dataset)
    out = tmp_path / "bench"
    R.run_bench([run], segs[:2], out, log=lambda s: None)  # killed after 2 of 4 segments
    model.write_text("0.3")  # a training run wrote its new policy.pt over the old one
    with pytest.raises(S.BenchError) as err:
        R.run_bench([run], segs, out, log=lambda s: None)
    msg = str(err.value)
    assert str(model.resolve()) in msg and "policy_checkpoint" in msg
    assert "contents changed" in msg and "another --out" in msg
    assert len(list((out / "segments" / "m").glob("*.json"))) == 3  # method.json + 2 rows
    fresh = R.run_bench([run], segs, tmp_path / "fresh", log=lambda s: None)
    assert _mpjpe(fresh) == [300.0] * 4  # one model only
    model.write_text("0.1")  # the contents the folder was started with: it resumes
    assert _mpjpe(R.run_bench([run], segs, out, log=lambda s: None)) == [100.0] * 4


def test_a_recording_replaced_in_place_is_refused(dataset, tmp_path) -> None:
    model = tmp_path / "m.txt"
    model.write_text("0.0")
    run = R.MethodRun("m", "frommodel", _from_model, MethodOptions(policy_checkpoint=model))
    segs = _segments(dataset)
    out = tmp_path / "bench"
    R.run_bench([run], segs[:3], out, log=lambda s: None)  # (segments 0, 1 of take0, 0 of take1)
    take1 = dataset / "sequences" / "take1.npz"
    copy = tmp_path / "copy.npz"
    shutil.copy(take1, copy)
    os.replace(copy, take1)  # the same bytes written anew (new inode and times): resumes
    assert len(R.run_bench([run], segs[:3], out, log=lambda s: None)) == 3
    save_recording(_recording("take1", 7), take1)  # other data at the same path
    with pytest.raises(S.BenchError) as err:
        R.run_bench([run], segs, out, log=lambda s: None)
    assert str(take1.resolve()) in str(err.value) and "another --out" in str(err.value)
    recorded = json.loads((out / "inputs.json").read_text())["files"]
    assert sorted(Path(p).name for p in recorded) == ["take0.npz", "take1.npz"]


def test_a_resume_reads_no_unchanged_file_again(dataset, tmp_path, monkeypatch) -> None:
    model = tmp_path / "m.txt"
    model.write_text("0.0")
    run = R.MethodRun("m", "frommodel", _from_model, MethodOptions(policy_checkpoint=model))
    segs = _segments(dataset)
    out = tmp_path / "bench"
    R.run_bench([run], segs[:3], out, log=lambda s: None)  # (of both recordings)
    hashed: list[str] = []
    real = digests.file_sha256
    monkeypatch.setattr(digests, "file_sha256", lambda p: hashed.append(str(p)) or real(p))
    R.run_bench([run], segs, out, log=lambda s: None)
    assert hashed == []  # the model and both recordings trusted by their size and times


def test_a_folder_from_before_the_records_resumes_with_a_note(dataset, tmp_path) -> None:
    model = tmp_path / "m.txt"
    model.write_text("0.0")
    run = R.MethodRun("m", "frommodel", _from_model, MethodOptions(policy_checkpoint=model))
    segs = _segments(dataset)
    out = tmp_path / "bench"
    R.run_bench([run], segs[:2], out, log=lambda s: None)
    method = out / "segments" / "m" / "method.json"
    old = json.loads(method.read_text())
    del old["models"]  # as written before the records existed
    method.write_text(json.dumps(old))
    (out / "inputs.json").unlink()
    said: list[str] = []
    rows = R.run_bench([run], segs, out, log=said.append)
    assert len(rows) == 4
    notes = [s for s in said if "no record of" in s]
    assert len(notes) == 2 and all("assumed unchanged" in s for s in notes)
    assert "models" in json.loads(method.read_text()) and (out / "inputs.json").is_file()
    model.write_text("0.5")  # from now on a change is seen
    with pytest.raises(S.BenchError, match="contents changed"):
        R.run_bench([run], segs, out, log=lambda s: None)


def test_model_files_are_the_files_each_method_reads(tmp_path) -> None:
    shipped = MethodOptions()
    assert model_files("grip", shipped) == {"policy_checkpoint": SHIPPED_POLICY.resolve(),
                                            "kin_checkpoint": SHIPPED_KIN.resolve()}  # fmt: skip
    assert model_files("kin+pip", shipped) == {"kin_checkpoint": SHIPPED_KIN.resolve()}
    assert model_files("transpose", shipped) == {
        "transpose_checkpoint": Path(SHIPPED_BASELINES["transpose"]).resolve()
    }
    given = MethodOptions(pip_checkpoint=Path("/x/pip.pt"), kin_checkpoint=Path("k.pt"))
    assert model_files("pip", given) == {"pip_checkpoint": Path("/x/pip.pt"),
                                         "kin_checkpoint": Path("k.pt").resolve()}  # fmt: skip
    assert model_files("custom", shipped) == {}
    ck = tmp_path / "sweep" / "imu4_press" / "best.pt"
    ck.parent.mkdir(parents=True)
    ck.write_bytes(b"net")
    sweep = MethodOptions(sensors="imu4_press", sweep_dir=tmp_path / "sweep")
    assert model_files("kinematics", sweep) == {"sweep_checkpoint": ck.resolve()}


def test_cli_refuses_a_resume_over_changed_data(dataset, tmp_path, capsys) -> None:
    argv = ["bench", "--data", str(dataset), "--methods", "kinematics", "--segment-frames",
            str(FRAMES), "--workers", "1", "--out", str(tmp_path / "b")]  # fmt: skip
    assert main([*argv, "--segments", "2"]) == 0
    take0 = dataset / "sequences" / "take0.npz"
    save_recording(_recording("take0", 9), take0)
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert str(take0.resolve()) in err and "contents changed" in err and "--out" in err
    assert "Traceback" not in err
    assert np.isfinite(json.loads((tmp_path / "b" / "results.json").read_text())
                       ["kinematics"]["MPJPE_mm"])  # fmt: skip
