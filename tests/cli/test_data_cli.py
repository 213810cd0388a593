"""The ``grip data`` and ``grip kin`` commands end to end on three real shared clips (in-process,
small; the dataset is ``conftest.built``). Policies trained on the same dataset:
test_policy_train_cli.py."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from grip.cli.main import main
from grip.core.reference import ReferenceSet

MOTIONS = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "motions"
pytestmark = pytest.mark.skipif(not MOTIONS.is_dir(), reason="shared motion clips not found")


def test_build_writes_sequences_split_and_manifest(built: Path) -> None:
    manifest = json.loads((built / "manifest.json").read_text())
    assert [c["status"] for c in manifest["clips"]] == ["done"] * 3
    split = json.loads((built / "split.json").read_text())
    seqs = sorted(p.stem for p in (built / "sequences").glob("*.npz"))
    assert sorted(split["train"] + split["test"]) == seqs
    assert split["test"], "a third of the clips must be in the test split"
    # Whole clips per split: no clip id appears on both sides.
    assert not set(split["groups"]["train"]) & set(split["groups"]["test"])
    assert not list(built.rglob("*.tmp")), "temporary files left behind"


def test_build_resumes_and_refuses_other_settings(built: Path, capsys) -> None:
    marker = sorted((built / "done").glob("*.json"))[0]
    stamp = {p: p.stat().st_mtime_ns for p in (built / "done").glob("*.json")}
    marker.unlink()
    rc = main(["data", "build", "--out", str(built), "--motions", str(MOTIONS / "deepmimic"),
               "--limit", "3", "--workers", "1", "--test-fraction", "0.34",
               "--split-by", "clip"])  # fmt: skip
    assert rc == 0
    after = {p: p.stat().st_mtime_ns for p in (built / "done").glob("*.json")}
    rebuilt = [p for p in after if p not in stamp or after[p] != stamp[p]]
    assert rebuilt == [marker], "only the clip without a done marker is built again"
    rc = main(["data", "build", "--out", str(built), "--motions", str(MOTIONS / "deepmimic"),
               "--limit", "3", "--noise-variants", "2"])  # fmt: skip
    assert rc == 2
    assert "different settings" in capsys.readouterr().err


def test_info_json_and_plot(built: Path, tmp_path: Path) -> None:
    js = tmp_path / "info.json"
    assert main(["data", "info", str(built), "--json", str(js)]) == 0
    info = json.loads(js.read_text())
    assert info["clips"] == 3 and info["recordings"] >= 3 and info["frames"] > 100
    assert sum(c["frames"] for c in info["categories"].values()) == info["frames"]
    assert 0.0 <= info["insole_zmp_outside_fraction"] <= 1.0
    seq = sorted((built / "sequences").glob("*.npz"))[0]
    png = tmp_path / "rec.png"
    assert main(["data", "plot", str(seq), "--out", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000


def test_plot_of_a_corrupt_file_is_a_clean_error(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "broken.npz"
    bad.write_bytes(b"PK\x03\x04 truncated")
    assert main(["data", "plot", str(bad), "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "broken.npz" in err and "Traceback" not in err
    assert not (tmp_path / "x.png").exists()


def test_console_script_help_lists_the_subcommands() -> None:
    out = subprocess.run([sys.executable, "-m", "grip.cli.main", "--help"],
                         capture_output=True, text=True, check=True).stdout  # fmt: skip
    for cmd in ("data", "body", "demo"):
        assert cmd in out
    out = subprocess.run([sys.executable, "-m", "grip.cli.main", "data", "build", "--help"],
                         capture_output=True, text=True, check=True).stdout  # fmt: skip
    assert "--workers" in out and "example" in out


def test_info_scans_a_folder_of_prism_pickles(tmp_path: Path) -> None:
    """A folder laid out like the real PRISM release (<subject>/<take>.pkl) is summarised."""
    from prism_tools.io import save_recording
    from prism_tools.synthetic import make_recording

    for subj, take, n in (("subj001", "take001", 120), ("subj002", "take004", 80)):
        save_recording(make_recording(n, seed=n), tmp_path / subj / f"{take}.pkl")
    (tmp_path / "subj002" / "take009.pkl").write_bytes(b"\x80\x04 not a pickle")
    js = tmp_path / "info.json"
    assert main(["data", "info", str(tmp_path), "--json", str(js)]) == 1  # a file skipped
    info = json.loads(js.read_text())
    assert info["source"] == "scan" and info["recordings"] == 2 and info["frames"] == 200
    assert len(info["unreadable"]) == 1 and "take009.pkl" in info["unreadable"][0]["file"]


def test_train_kin_runs_and_resumes(built: Path, tmp_path: Path, capsys) -> None:
    run = tmp_path / "run"
    args = ["kin", "train", "--data", str(built), "--out", str(run), "--threads", "1",
            "--set", "hidden=16", "--set", "layers=1", "--set", "init_hidden=8",
            "--set", "train.window_frames=30", "--set", "train.batch_size=2",
            "--set", "train.steps_per_epoch=2", "--set", "train.stage_epochs=0",
            "--set", "train.joint_epochs=1", "--set", "train.val_windows=2"]  # fmt: skip
    assert main(args) == 0
    cfg = json.loads((run / "config.json").read_text())
    assert cfg["config"]["hidden"] == 16 and "git" in cfg
    assert (run / "last.pt").exists() and list((run / "tb").iterdir())
    assert main(args) == 0
    assert "resuming" in capsys.readouterr().out
    bad = [*args[:-2], "--set", "train.lrr=1"]
    assert main(bad) == 2
    assert "lrr" in capsys.readouterr().err
    # validation on training clips held out of training instead of the test split
    held = [*args, "--set", "train.val_source=holdout", "--set", "train.val_fraction=0.3"]
    held[held.index(str(run))] = str(tmp_path / "held")
    assert main(held) == 2  # this dataset's train split has one clip: nothing to hold out
    err = capsys.readouterr().err
    assert "dataset" in err and "at least 2 clips" in err and "Traceback" not in err
    assert main([*held, "--set", "train.val_source=dev"]) == 2
    assert "val_source" in capsys.readouterr().err


def test_train_kin_init_fine_tunes_from_another_run(built: Path, tmp_path: Path, capsys) -> None:
    small = ["--threads", "1", "--set", "hidden=16", "--set", "layers=1", "--set", "init_hidden=8",
             "--set", "train.window_frames=30", "--set", "train.batch_size=2",
             "--set", "train.steps_per_epoch=2", "--set", "train.stage_epochs=0",
             "--set", "train.val_windows=2"]  # fmt: skip
    base = ["kin", "train", "--data", str(built)]
    assert main([*base, "--out", str(tmp_path / "a"), *small, "--set", "train.joint_epochs=1"]) == 0
    ft = [*base, "--out", str(tmp_path / "ft"), *small, "--init", str(tmp_path / "a" / "last.pt"),
          "--set", "train.joint_epochs=2", "--set", "train.lr_final=1e-5",
          "--set", "train.mirror_augment=true"]  # fmt: skip
    assert main(ft) == 0
    assert "initialised from" in capsys.readouterr().out
    cfg = json.loads((tmp_path / "ft" / "config.json").read_text())
    assert cfg["init"].endswith("last.pt") and cfg["config"]["train"]["mirror_augment"] is True
    wide = [a if a != "hidden=16" else "hidden=24" for a in ft]
    wide[wide.index(str(tmp_path / "ft"))] = str(tmp_path / "wide")
    assert main(wide) == 2
    assert "differ" in capsys.readouterr().err
    assert main([*ft[:-2], "--sweep"]) == 2


def test_eval_kin_reports_json_table_and_plot(built: Path, tmp_path: Path, capsys) -> None:
    run = tmp_path / "run"
    main(["kin", "train", "--data", str(built), "--out", str(run), "--threads", "1",
          "--set", "hidden=16", "--set", "layers=1", "--set", "init_hidden=8",
          "--set", "train.window_frames=30", "--set", "train.batch_size=2",
          "--set", "train.steps_per_epoch=1", "--set", "train.stage_epochs=0",
          "--set", "train.joint_epochs=1", "--set", "train.val_windows=2"])  # fmt: skip
    js = tmp_path / "kin.json"
    assert main(["kin", "eval", "--model", str(run / "last.pt"), "--data", str(built),
                 "--json", str(js), "--out", str(tmp_path / "ev")]) == 0  # fmt: skip
    fig = json.loads(js.read_text())
    for key in ("PEL_MPJPE_mm", "MPJRE_deg", "leaf_vel_err_mps", "frames"):
        assert key in fig
    assert fig["frames"] > 0 and (tmp_path / "ev" / "categories.png").exists()
    assert fig["tta"] == "none" and fig["init"] == "truth"
    assert set(fig["sources"]) == {"deepmimic"}  # per-source table (the fixture's one source)
    assert fig["sources"]["deepmimic"]["frames"] == fig["frames"]
    assert main(["kin", "eval", "--model", str(run / "last.pt"), "--data", str(built),
                 "--init", "standing", "--json", str(js)]) == 0  # fmt: skip
    standing = json.loads(js.read_text())
    assert standing["init"] == "standing" and standing["frames"] == fig["frames"]
    assert standing["PEL_MPJPE_mm"] != pytest.approx(fig["PEL_MPJPE_mm"], rel=1e-6)  # tiny net
    assert main(["kin", "eval", "--model", str(run / "last.pt"), "--data", str(built),
                 "--tta", "mirror", "--json", str(js)]) == 0  # fmt: skip
    tta = json.loads(js.read_text())
    assert tta["tta"] == "mirror" and tta["frames"] == fig["frames"]
    assert tta["PEL_MPJPE_mm"] != pytest.approx(fig["PEL_MPJPE_mm"], rel=1e-4)
    # the evaluation interface of every dataset command: --split all, --category GLOB
    assert main(["kin", "eval", "--model", str(run / "last.pt"), "--data", str(built),
                 "--split", "all", "--json", str(js)]) == 0  # fmt: skip
    every = json.loads(js.read_text())
    assert every["frames"] > fig["frames"]  # (the fixture's training clip joins)
    cats = sorted(every["categories"])
    assert len(cats) >= 2
    assert main(["kin", "eval", "--model", str(run / "last.pt"), "--data", str(built),
                 "--split", "all", "--category", cats[0], "--json", str(js)]) == 0  # fmt: skip
    assert sorted(json.loads(js.read_text())["categories"]) == [cats[0]]
    assert main(["kin", "eval", "--model", str(tmp_path / "none.pt"), "--data", str(built)]) == 2
    assert "none.pt" in capsys.readouterr().err


def test_sensor_sweep_trains_each_configuration_and_tabulates(
    built: Path, tmp_path: Path, capsys
) -> None:
    sweep = tmp_path / "sweep"
    args = ["kin", "train", "--data", str(built), "--out", str(sweep), "--threads", "1",
            "--sweep", "--imus", "2,4",
            "--set", "hidden=8", "--set", "layers=1", "--set", "init_hidden=8",
            "--set", "train.window_frames=20", "--set", "train.batch_size=2",
            "--set", "train.steps_per_epoch=1", "--set", "train.stage_epochs=0",
            "--set", "train.joint_epochs=1", "--set", "train.val_windows=2"]  # fmt: skip
    assert main(args) == 0
    names = sorted(p.name for p in sweep.iterdir())
    assert names == ["imu2_nopress", "imu2_press", "imu4_nopress", "imu4_press"]
    cfg = json.loads((sweep / "imu2_press" / "config.json").read_text())["config"]
    assert cfg["features"]["sites"] == ["L_Foot", "R_Foot"] and cfg["features"]["insoles"]
    js = tmp_path / "sweep.json"
    capsys.readouterr()
    assert main(["kin", "eval", "--sweep", str(sweep), "--data", str(built),
                 "--json", str(js)]) == 0  # fmt: skip
    table = capsys.readouterr().out
    assert table.count("\n| 2 |") == 2 and table.count("\n| 4 |") == 2
    res = json.loads(js.read_text())
    assert set(res) == set(names) and res["imu4_press"]["n_imu"] == 4
    assert all(r["PA_MPJPE_mm"] <= r["PEL_MPJPE_mm"] + 1e-6 for r in res.values())
    # a finished run carried over as its export (no last.pt) is kept, not trained again, and
    # evaluates as before
    run = sweep / "imu4_nopress"
    assert main(["kin", "export", str(run / "best.pt"), "--out", str(tmp_path / "x.pt")]) == 0
    for f in ("best.pt", "last.pt"):
        (run / f).unlink()
    (tmp_path / "x.pt").rename(run / "best.pt")
    capsys.readouterr()
    assert main(args) == 0
    assert "kept:" in capsys.readouterr().out and not (run / "last.pt").exists()
    assert main(["kin", "eval", "--sweep", str(sweep), "--data", str(built),
                 "--json", str(js)]) == 0  # fmt: skip
    again = json.loads(js.read_text())["imu4_nopress"]
    assert abs(again["PEL_MPJPE_mm"] - res["imu4_nopress"]["PEL_MPJPE_mm"]) < 1.0  # (fp16)
    # a run whose folder name lies about its sensors is refused
    (sweep / "imu2_press").rename(sweep / "imu3_press")
    assert main(["kin", "eval", "--sweep", str(sweep), "--data", str(built)]) == 2
    assert "imu3_press" in capsys.readouterr().err
    assert main(["kin", "train", "--data", str(built), "--out", str(sweep), "--sweep",
                 "--imus", "2,9"]) == 2  # fmt: skip


def _benchmark(name: str):
    """The module of ``benchmarks/<name>.py`` (a script folder, not a package)."""
    import importlib.util

    path = Path(__file__).resolve().parents[2] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"benchmarks_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_reference_export_and_bench_env(built: Path, tmp_path: Path, capsys) -> None:
    run = tmp_path / "run"
    main(["kin", "train", "--data", str(built), "--out", str(run), "--threads", "1",
          "--set", "hidden=8", "--set", "layers=1", "--set", "init_hidden=8",
          "--set", "train.window_frames=20", "--set", "train.batch_size=2",
          "--set", "train.steps_per_epoch=1", "--set", "train.stage_epochs=0",
          "--set", "train.joint_epochs=1", "--set", "train.val_windows=2"])  # fmt: skip
    small = tmp_path / "kin16.pt"
    assert main(["kin", "export", str(run / "last.pt"), "--out", str(small)]) == 0
    assert small.stat().st_size < (run / "last.pt").stat().st_size
    ref = tmp_path / "ref.npz"
    assert main(["data", "reference", "--data", str(built), "--split", "all", "--kin", str(small),
                 "--max-frames", "120", "--out", str(ref)]) == 0  # fmt: skip

    rs = ReferenceSet.load(ref)
    assert len(rs) >= 1 and max(c.n_frames for c in rs.clips) <= 120
    js = tmp_path / "bench.json"
    env_steps = _benchmark("env_steps")
    assert env_steps.main(["--reference", str(ref), "--steps", "20", "--repeats", "1",
                           "--amp-window", "0", "--json", str(js)]) == 0  # fmt: skip
    res = json.loads(js.read_text())
    assert res["substeps"] == 2 and res["env_steps_per_s"] > 0 and res["raw_mj_steps_per_s"] > 0
    assert 0 < res["in_env_physics_time_share"] < 1 and res["own_states_us_per_mj_step"] > 0
    assert main(["data", "reference", "--out", str(ref)]) == 2  # neither files nor --data
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"garbage")
    assert env_steps.main(["--reference", str(bad), "--steps", "2"]) == 2
    assert "bad.npz" in capsys.readouterr().err


def test_cut_writes_a_window_with_the_objects(tmp_path: Path, capsys) -> None:
    """``grip data cut``: the window's frames, the scene's objects kept; a window outside the
    recording is an error naming the file, and nothing is written."""
    from grip.assets import SAMPLE_PROPS_RECORDING
    from prism_tools.io import load_recording

    src = load_recording(SAMPLE_PROPS_RECORDING)
    out = tmp_path / "cut.npz"
    assert main(["data", "cut", str(SAMPLE_PROPS_RECORDING), "--start", "1", "--end", "2.5",
                 "--out", str(out)]) == 0  # fmt: skip
    assert "frames [100, 250)" in capsys.readouterr().out
    cut = load_recording(out)
    assert cut.n_frames == 150 and sorted(cut.objects) == sorted(src.objects)
    np.testing.assert_array_equal(cut.objects["prop_01"].vertices, src.objects["prop_01"].vertices)
    np.testing.assert_array_equal(cut.smpl_params.trans, src.smpl_params.trans[100:250])
    bad = tmp_path / "bad.npz"
    assert main(["data", "cut", str(SAMPLE_PROPS_RECORDING), "--start", "5", "--end", "9",
                 "--out", str(bad)]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "sample_props_recording.npz" in err and "outside the recording's 600 frames" in err
    assert not bad.exists()
