"""``--ray`` and ``--tune`` on a local Ray of 2 CPUs: each command's results with ``--ray`` equal
its local path's on tiny data, a failing unit is reported per unit as on the local path, a
task whose worker dies comes back as lost, and a Tune sweep gives the numbers of the ordinary
runs and resumes."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from grip.assets import SAMPLE_RECORDING
from grip.cli.main import main

ray = pytest.importorskip("ray")

from grip.cluster import RayPool  # noqa: E402
from grip.cluster.ray_pool import RemoteTraceback  # noqa: E402

DEEPMIMIC = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "motions" / "deepmimic"


@pytest.fixture(scope="module", autouse=True)
def local_ray():
    """One local Ray of 2 CPUs for the module (the commands keep a connection they find); a
    new one, whatever cluster runs on this machine."""
    started = not ray.is_initialized()
    if started:
        ray.init(address="local", num_cpus=2, include_dashboard=False)
    yield
    if started:
        ray.shutdown()


def _numbers(a, b, rel: float = 1e-6) -> None:
    """Same structure; numbers equal to ``rel`` (NaN equals NaN)."""
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for k in a:
            _numbers(a[k], b[k], rel)
    elif isinstance(a, list):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            _numbers(x, y, rel)
    elif isinstance(a, float):
        assert (np.isnan(a) and np.isnan(b)) or a == pytest.approx(b, rel=rel, abs=1e-12)
    elif isinstance(a, np.ndarray):
        np.testing.assert_allclose(a, b, rtol=rel, atol=1e-12)
    else:
        assert a == b


# ---------------------------------------------------------------------------------- the pool
def test_results_exceptions_and_lost_calls_come_back_per_call(monkeypatch) -> None:
    monkeypatch.setenv("GRIP_LIMITS", "max_frames=5")
    with RayPool() as pool:
        assert pool.workers == 2
        got: dict[int, object] = {}
        calls = [(abs, (-1,)), (os._exit, (3,)), (int, ("x",)), (os.environ.get, ("GRIP_LIMITS",))]
        assert pool.run(calls, got.__setitem__) == [1]  # the call whose worker died
        assert got[0] == 1 and got[3] == "max_frames=5"  # the driver's limits reach the task
        assert isinstance(got[2], ValueError) and "'x'" in str(got[2])
        assert isinstance(got[2].__cause__, RemoteTraceback) and "int" in str(got[2].__cause__)
        monkeypatch.delenv("GRIP_LIMITS")
        assert pool.run([(os.environ.get, ("GRIP_LIMITS",))], got.__setitem__) == []
        assert got[0] is None
    assert ray.is_initialized()  # a connection the pool found is kept


# ------------------------------------------------------------------------------ the commands
def test_kin_eval(walk_takes, tmp_path) -> None:
    base = ["kin", "eval", "--data", str(walk_takes), "--segment-frames", "100"]
    figures = {}
    for name, extra in (("local", []), ("ray", ["--ray"])):
        out = tmp_path / f"{name}.json"
        assert main([*base, *extra, "--json", str(out)]) == 0
        figures[name] = json.loads(out.read_text())
    assert figures["ray"]["segments"] == 7  # (in units of 4 and 3 segments)
    _numbers(figures["local"], figures["ray"])


def test_policy_eval_rows_are_bit_identical(walk_takes, tmp_path) -> None:
    base = ["policy", "eval", "--data", str(walk_takes), "--segment-frames", "40", "--batch",
            "5", "--init", "standing", "--reference", "truth"]  # fmt: skip
    text = {}
    for name, extra in (("local", ["--workers", "1"]), ("ray", ["--ray"])):
        out = tmp_path / name
        assert main([*base, *extra, "--out", str(out)]) == 0
        text[name] = [(out / f).read_text() for f in ("segments.csv", "summary.md")]
    assert text["local"] == text["ray"] and len(text["ray"][0].splitlines()) == 1 + 12


def test_bench(walk_takes, tmp_path, capsys) -> None:
    base = ["bench", "--data", str(walk_takes), "--methods", "kinematics", "--segment-frames",
            "100", "--segments", "3"]  # fmt: skip
    res = {}
    for name, extra in (("local", ["--workers", "1"]), ("ray", ["--ray"])):
        assert main([*base, *extra, "--out", str(tmp_path / name)]) == 0
        res[name] = json.loads((tmp_path / name / "results.json").read_text())
        res[name]["kinematics"].pop("ms_per_frame")  # (a runtime)
    _numbers(res["local"], res["ray"])
    assert main([*base, "--ray", "--out", str(tmp_path / "ray")]) == 0  # resumes: nothing to run
    assert "3 finished segment result(s) kept" in capsys.readouterr().out


def test_bench_reports_a_failing_segment_as_locally(walk_takes, tmp_path) -> None:
    """A recording damaged after the segments were listed: its segments are error rows, the
    others are scored, with Ray as in this process."""
    from grip.eval.methods import MethodOptions
    from grip.eval.runner import prepare_runs, run_bench
    from grip.eval.segments import list_segments, split_files

    data = tmp_path / "data"
    shutil.copytree(walk_takes, data)
    segs = list_segments(split_files(data, "test"), 100)
    (data / "sequences" / "take1.npz").write_bytes(b"damaged")
    runs, built = prepare_runs(["kinematics"], MethodOptions(), log=lambda s: None)
    local = run_bench(runs, segs, tmp_path / "local", workers=1, built=built, log=lambda s: None)
    with RayPool() as pool:
        remote = run_bench(runs, segs, tmp_path / "ray", pool=pool, log=lambda s: None)
    assert [r["status"] for r in remote] == ["ok", "ok", "error", "ok"]
    assert "take1.npz" in remote[2]["error"]
    for r in (*local, *remote):  # (runtimes)
        r.get("metrics", {}).pop("ms_per_frame", None)
        r.pop("method_ms_per_frame", None)
    _numbers(local, remote)


def test_reconstruct(tmp_path, capsys) -> None:
    from prism_tools.io import load_recording, save_recording

    rec = load_recording(SAMPLE_RECORDING)
    files = []
    for i in range(2):
        files.append(tmp_path / "takes" / f"take{i}.npz")
        save_recording(rec.slice_frames(40 * i, 40 * i + 40), files[-1])
    files.append(tmp_path / "takes" / "one_insole.npz")  # the models read both: an error row
    part = rec.slice_frames(0, 40)
    save_recording(dataclasses.replace(part, insole={"L_Foot": part.insole["L_Foot"]}), files[-1])
    summary = {}
    for name, extra in (("local", []), ("ray", ["--ray"])):
        out = tmp_path / name
        argv = ["reconstruct", *map(str, files), "--out", str(out), "--batch", "1", *extra]
        assert main(argv) == 1  # one recording not reconstructed
        assert "one_insole.npz: not reconstructed" in capsys.readouterr().err
        summary[name] = json.loads((out / "summary.json").read_text())
    local, remote = summary["local"], summary["ray"]
    assert local["errors"] == remote["errors"] and len(remote["errors"]) == 1
    for a, b in zip(local["recordings"], remote["recordings"], strict=True):
        assert a["file"] == b["file"] and a["frames"] == b["frames"] == 40
        assert a["falls"] == b["falls"]
        np.testing.assert_array_equal(np.load(a["written"][0])["joint_pos"],
                                      np.load(b["written"][0])["joint_pos"])  # fmt: skip


@pytest.mark.skipif(not DEEPMIMIC.is_dir(), reason="shared motion clips not found")
def test_data_build(tmp_path, capsys) -> None:
    motions = tmp_path / "motions" / "mixed"
    motions.mkdir(parents=True)
    shutil.copy(DEEPMIMIC / "humanoid3d_walk.txt", motions / "walk.txt")
    shutil.copy(DEEPMIMIC / "humanoid3d_jump.txt", motions / "jump.txt")
    (motions / "fuzzed.bvh").write_bytes(b"HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 \xff\x00 1e999\n")
    manifests = {}
    for name, extra in (("local", ["--workers", "1"]), ("ray", ["--ray"])):
        out = tmp_path / name
        argv = ["data", "build", "--out", str(out), "--motions", str(motions.parent), *extra]
        assert main(argv) == 1  # the fuzzed clip failed, the others were built
        assert "FAILED mixed/fuzzed: " in capsys.readouterr().err
        manifests[name] = json.loads((out / "manifest.json").read_text())
        for clip in manifests[name]["clips"]:
            clip.pop("seconds")
    assert manifests["local"] == manifests["ray"]
    status = {c["clip_id"]: c["status"] for c in manifests["ray"]["clips"]}
    assert status == {"mixed/fuzzed": "failed", "mixed/jump": "done", "mixed/walk": "done"}
    seqs = sorted(p.name for p in (tmp_path / "local" / "sequences").glob("*.npz"))
    assert seqs and seqs == sorted(p.name for p in (tmp_path / "ray" / "sequences").glob("*.npz"))
    for s in seqs:
        with np.load(tmp_path / "local" / "sequences" / s) as a, \
                np.load(tmp_path / "ray" / "sequences" / s) as b:  # fmt: skip
            assert a.files == b.files
            for k in a.files:
                np.testing.assert_array_equal(a[k], b[k], err_msg=f"{s}: {k}")


# ---------------------------------------------------------------------------------- --tune
TINY_KIN = ["--threads", "1", "--set", "layers=1", "--set", "init_hidden=8",
            "--set", "train.window_frames=30", "--set", "train.batch_size=2",
            "--set", "train.steps_per_epoch=2", "--set", "train.stage_epochs=0",
            "--set", "train.joint_epochs=1", "--set", "train.val_windows=2"]  # fmt: skip


@pytest.fixture(scope="module")
def train_takes(tmp_path_factory) -> Path:
    """Four synthetic takes, two in each split."""
    from prism_tools.chunking import make_split, save_split
    from prism_tools.io import save_recording
    from prism_tools.synthetic import make_recording

    root = tmp_path_factory.mktemp("train_takes")
    names = {"take0": 230, "take1": 160, "take2": 200, "take3": 180}
    for i, (name, n) in enumerate(names.items()):
        rec = make_recording(n, seed=i)
        rec = dataclasses.replace(rec, extras={**rec.extras, "take_name": name})
        save_recording(rec, root / "sequences" / f"{name}.npz")
    save_split(make_split(list(names), test_fraction=0.5), root / "split.json")
    return root


def test_kin_sweep_gives_the_runs_numbers_and_resumes(train_takes, tmp_path, capsys) -> None:
    space = tmp_path / "space.toml"
    space.write_text("[set]\nhidden = [8, 16]\n")
    out = tmp_path / "sweep"
    argv = ["kin", "train", "--data", str(train_takes), "--out", str(out), "--tune", str(space),
            *TINY_KIN]  # fmt: skip
    assert main(argv) == 0
    trials = json.loads((out / "sweep.json").read_text())["trials"]
    sweep = {t["values"]["hidden"]: t for t in trials}
    assert {t["status"] for t in sweep.values()} == {"done"}
    for hidden, t in sweep.items():  # each trial is an ordinary run folder with its value
        run = out / t["trial"]
        assert json.loads((run / "config.json").read_text())["config"]["hidden"] == hidden
        assert (run / "last.pt").is_file() and (run / "trial.json").is_file()
    # the trial's numbers are those of the same run without Ray
    assert main(["kin", "train", "--data", str(train_takes), "--out", str(tmp_path / "plain"),
                 *TINY_KIN, "--set", "hidden=8"]) == 0  # fmt: skip
    from grip.cli.cluster import kin_metrics
    from grip.cluster.sweep import flat_metrics

    plain = flat_metrics(kin_metrics(tmp_path / "plain"))
    assert sweep[8]["metrics"]["val/total"] == plain["val/total"]
    # the space grows by one trial whose folder holds another run's checkpoint: it fails
    # alone; the unfinished trial (no marker) runs again and resumes from its checkpoint; the
    # finished one is kept
    space.write_text("[set]\nhidden = [8, 16, 32]\n")
    small, big = out / sweep[8]["trial"], out / sweep[16]["trial"]
    (small / "trial.json").unlink()
    from grip.cluster import Trial

    odd = out / Trial((("hidden", 32),)).name
    odd.mkdir()
    shutil.copy(big / "last.pt", odd / "last.pt")
    capsys.readouterr()
    assert main(argv) == 1
    captured = capsys.readouterr()
    assert "1 finished trial(s) kept, 2 to run" in captured.out
    assert "resuming" in (small / "trial.log").read_text()
    assert f"grip: error: {odd.name} (hidden=32): " in captured.err
    assert "another configuration" in captured.err
    again = {t["trial"]: t for t in json.loads((out / "sweep.json").read_text())["trials"]}
    assert [again[p.name]["status"] for p in (small, big, odd)] == ["done", "kept", "failed"]
    for t in sweep.values():
        assert again[t["trial"]]["metrics"] == t["metrics"]
    rows = (out / "sweep.md").read_text().splitlines()
    assert rows[-1].startswith(f"| {odd.name} | failed | 32 | n/a | ")


@pytest.mark.slow
def test_policy_sweep_trains_one_run_per_trial(tmp_path, tiny_policy_settings) -> None:
    """Two tiny PPO + AMP runs as trials (their reference sets copied in beforehand, as the
    tiny policy run of tests/conftest.py does: no KinematicsNet pass)."""
    from envs.tracking_env import SAMPLE_REFERENCE
    from grip.cluster import expand_trials, load_space

    data = tmp_path / "data"
    data.mkdir()
    (data / "split.json").write_text(json.dumps({"train": ["s0"], "test": []}))
    space = tmp_path / "space.toml"
    space.write_text('metric = "reward/imit_pos"\n[set]\n"ppo.learning_rate" = [3e-4, 1e-3]\n')
    out = tmp_path / "sweep"
    for t in expand_trials(load_space(space)):
        (out / t.name).mkdir(parents=True)
        shutil.copy(SAMPLE_REFERENCE, out / t.name / "reference_train.npz")
    assert main(["policy", "train", "--data", str(data), "--out", str(out), "--tune", str(space),
                 *tiny_policy_settings]) == 0  # fmt: skip
    trials = json.loads((out / "sweep.json").read_text())["trials"]
    assert [t["status"] for t in trials] == ["done", "done"]
    for t in trials:
        assert t["metrics"]["timesteps"] == 128 and "reward/imit_pos" in t["metrics"]
        assert (out / t["trial"] / "policy.pt").is_file()
