"""``grip bench`` and its shared pieces (:mod:`grip.eval.segments`, :mod:`grip.eval.runner`,
:mod:`grip.eval.report`): segment listing, metrics of one segment, the runner (failures, resume,
worker crashes), the method registry, the kinematics-only method and the command line."""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
import textwrap
from pathlib import Path

import numpy as np
import pytest

from grip.assets import SAMPLE_RECORDING, SHIPPED_KIN
from grip.cli.main import main
from grip.core import metrics as M
from grip.core.reconstruction import Reconstruction
from grip.eval import bench as B
from grip.eval import pool, report, scoring
from grip.eval import runner as R
from grip.eval import segments as S
from grip.eval.methods import (
    KinematicsOnly,
    MethodOptions,
    UnknownMethodError,
    kinematics_method,
    make_method,
    parse_method_names,
    sensor_set,
)
from grip.kinematics import features as F
from prism_tools.chunking import make_split, save_split
from prism_tools.io import save_recording
from prism_tools.synthetic import make_recording

FRAMES = 100  # segment length of these tests
LENGTHS = {"take0": (250, "walk"), "take1": (120, "run"), "take2": (210, "walk")}


def _recording(name: str, seed: int):
    n, cat = LENGTHS[name]
    rec = make_recording(n, seed=seed)
    return dataclasses.replace(rec, extras={**rec.extras, "take_name": name, "category": cat})


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    """A tiny ``grip data build``-style folder: every recording in the test split."""
    root = tmp_path_factory.mktemp("data")
    for i, name in enumerate(LENGTHS):
        save_recording(_recording(name, i), root / "sequences" / f"{name}.npz")
    split = make_split(list(LENGTHS), test_fraction=1.0)
    save_split(split, root / "split.json")
    return root


@pytest.fixture(scope="module")
def segments(dataset: Path) -> list[S.Segment]:
    return S.list_segments(sorted((dataset / "sequences").glob("*.npz")), FRAMES)


# ------------------------------------------------------------------------------ fake methods
class Oracle:
    """Returns the ground truth (+ a constant shift); forces equal to the insoles'.

    ``fail_on``: recording names on which it raises; ``calls``: list the names it ran on.
    """

    name = "oracle"
    supports_sensors = False

    def __init__(self, shift=(0.0, 0.0, 0.0), fail_on=(), calls=None, can_fall=True,
                 fall=False, grf_offset_n=0.0, blowups=0, lead_mps=None,
                 lost=0) -> None:  # fmt: skip
        self.shift = np.asarray(shift, dtype=float)
        self.fail_on = set(fail_on)
        self.calls = calls if calls is not None else []
        self.can_fall = can_fall
        self.fall = fall
        self.grf_offset_n = grf_offset_n
        self.blowups = blowups  # reported in the notes, as GRIP's simulation does
        self.lost = lost
        # a pelvis it follows that walks away along x at this speed (None: it follows none)
        self.lead_mps = lead_mps

    def reconstruct(self, rec) -> Reconstruction:
        self.calls.append(rec.name)
        if rec.name in self.fail_on:
            raise RuntimeError(f"solver diverged on {rec.name}")
        gt = F.ground_truth(rec)
        grf = np.zeros((rec.n_frames, 2, 3))
        grf[..., 2] = gt.insole_force_n + self.grf_offset_n
        falls = np.array([[rec.n_frames - 5, rec.n_frames - 2]]) if self.fall else None
        ref = None
        if self.lead_mps is not None:
            ref = gt.root_pos + self.shift
            ref[:, 0] += self.lead_mps * np.arange(rec.n_frames) / rec.fps
        return Reconstruction(name=rec.name, method=self.name, fps=rec.fps,
                              joint_pos=gt.joint_pos + self.shift, global_rot=gt.global_rot,
                              grf=grf, notes={"blowups": self.blowups, "lost": self.lost},
                              ref_root_pos=ref,
                              **({"falls": falls} if self.fall else {}))  # fmt: skip


def _run(label: str, factory) -> R.MethodRun:
    return R.MethodRun(label, "oracle", factory, MethodOptions())


def _oracle_factory(options: MethodOptions) -> Oracle:
    return Oracle()


# ------------------------------------------------------------------------------- segments
def test_list_segments_cuts_full_segments_and_names_them(segments, dataset) -> None:
    ids = [s.id for s in segments]
    # 250 -> 2 segments, 120 -> 1, 210 -> 2: shorter tails are left out.
    assert ids == ["take0_f000000", "take0_f000100", "take1_f000000", "take2_f000000",
                   "take2_f000100"]  # fmt: skip
    assert all(s.n_frames == FRAMES for s in segments)
    assert [s.category for s in segments] == ["walk", "walk", "run", "walk", "walk"]
    only_run = S.list_segments(sorted((dataset / "sequences").glob("*.npz")), FRAMES, ["r*"])
    assert [s.id for s in only_run] == ["take1_f000000"]
    with pytest.raises(S.BenchError, match="no 300-frame segment"):
        S.list_segments([dataset / "sequences" / "take1.npz"], 300)


def test_list_segments_names_an_unreadable_file(tmp_path) -> None:
    bad = tmp_path / "broken.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(S.BenchError, match=r"broken\.npz"):
        S.list_segments([bad], FRAMES)


def test_select_segments_spreads_over_categories_deterministically() -> None:
    cats = ["a"] * 5 + ["b"] + ["c"] * 2
    segs = [S.Segment(f"s{i}", Path(f"f{i}"), 0, 10, c) for i, c in enumerate(cats)]
    picked = S.select_segments(segs, 4)
    assert [s.id for s in picked] == ["s0", "s1", "s5", "s6"]  # a, a, b, c in input order
    assert sorted({s.category for s in picked}) == ["a", "b", "c"]
    assert S.select_segments(segs, 4) == picked
    assert S.select_segments(segs, 0) == segs and S.select_segments(segs, 99) == segs


# ------------------------------------------------------------------------ segment metrics
@pytest.fixture(scope="module")
def seg_rec():
    return _recording("take0", 0).slice_frames(0, FRAMES)


def test_ground_truth_reconstruction_has_zero_errors(seg_rec) -> None:
    gt = F.ground_truth(seg_rec)
    m, per_joint = scoring.segment_metrics(Oracle().reconstruct(seg_rec), gt, can_fall=True)
    for k in ("MPJPE_mm", "PEL_MPJPE_mm", "PA_MPJPE_mm", "MPJRE_deg", "Acc_mps2", "vGRF_N"):
        assert m[k] == pytest.approx(0.0, abs=1e-6), k
    assert m["success_rate"] == 100.0
    # Foot sliding and penetration are properties of the motion itself: the ground truth's.
    assert gt.foot_contacts.any() and m["FS_mps"] == pytest.approx(
        M.foot_sliding(gt.joint_pos, gt.foot_contacts, 100.0)
    )
    assert m["FP_mm"] >= 0.0 and math.isfinite(m["FP_mm"])
    assert per_joint["MPJPE_mm"].shape == (24,) and np.allclose(per_joint["MPJPE_mm"], 0.0)


def test_hand_made_errors(seg_rec) -> None:
    gt = F.ground_truth(seg_rec)
    shifted = Oracle(shift=(0.1, 0.0, 0.0), grf_offset_n=10.0).reconstruct(seg_rec)
    m, per_joint = scoring.segment_metrics(shifted, gt, can_fall=True)
    assert m["MPJPE_mm"] == pytest.approx(100.0)
    np.testing.assert_allclose(per_joint["MPJPE_mm"], 100.0)
    for k in ("PEL_MPJPE_mm", "PA_MPJPE_mm", "MPJRE_deg", "Acc_mps2"):
        assert m[k] == pytest.approx(0.0, abs=1e-6), k  # a constant shift changes none of them
    assert m["vGRF_N"] == pytest.approx(10.0)

    # Every global rotation turned by 90 deg about z: MPJRE 90 deg, positions unchanged.
    rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    turned = Oracle().reconstruct(seg_rec)
    turned.global_rot = turned.global_rot @ rz
    m, _ = scoring.segment_metrics(turned, gt, can_fall=False)
    assert m["MPJRE_deg"] == pytest.approx(90.0) and m["MPJPE_mm"] == pytest.approx(0.0)
    assert math.isnan(m["success_rate"])  # a method that cannot fall has no success rate

    m, _ = scoring.segment_metrics(Oracle(fall=True).reconstruct(seg_rec), gt, can_fall=True)
    assert m["success_rate"] == 0.0
    no_forces = Oracle().reconstruct(seg_rec)
    no_forces.grf = None
    assert math.isnan(scoring.segment_metrics(no_forces, gt, can_fall=True)[0]["vGRF_N"])


def test_pace_of_a_method_that_falls_behind_the_pelvis_it_follows(seg_rec) -> None:
    gt = F.ground_truth(seg_rec)
    lagging = Oracle(shift=(0.3, 0.4, 0.0), lead_mps=1.2).reconstruct(seg_rec)
    m, _ = scoring.segment_metrics(lagging, gt, can_fall=True)
    # what it follows walks away at 1.2 m/s: 100 frames, frame 99 closes the first second
    assert m["pace_1s_m"] == pytest.approx(1.2 * 0.99) == pytest.approx(m["pace_end_m"])
    assert m["drift_mps"] == pytest.approx(1.2) and math.isnan(m["pace_5s_m"])
    assert m["root_gt_1s_m"] == pytest.approx(0.5) == pytest.approx(m["root_gt_end_m"])
    plain, _ = scoring.segment_metrics(Oracle(shift=(0.3, 0.4, 0.0)).reconstruct(seg_rec), gt,
                                       can_fall=False)  # fmt: skip
    assert all(math.isnan(plain[k]) for k in M.PACE_KEYS)  # follows nothing: no pace
    assert plain["root_gt_end_m"] == pytest.approx(0.5)  # every method: the distance to truth
    assert set(m) == set(plain) == set(scoring.METRIC_KEYS) - {"ms_per_frame"}


def test_contacts_and_insole_force_fall_back_without_insoles(seg_rec) -> None:
    gt = F.ground_truth(seg_rec)
    np.testing.assert_array_equal(
        gt.foot_contacts,
        np.stack([seg_rec.insole[f].contacts.any(axis=1) for f in scoring.FEET], 1),
    )
    bare = dataclasses.replace(seg_rec, insole={}, insole_combined=None)
    gt_bare = F.ground_truth(bare)
    np.testing.assert_array_equal(
        gt_bare.foot_contacts, M.contacts_from_motion(gt.joint_pos[:, [10, 11]], 100.0)
    )
    assert gt_bare.insole_force_n is None
    mass = gt.body.mass_kg
    np.testing.assert_allclose(gt.insole_force_n[:, 0],
                               seg_rec.insole["L_Foot"].force[:, 0] * mass * 9.81, rtol=1e-3)
    assert gt.head(7).n_frames == 7 and gt.head(7).insole_force_n.shape == (7, 2)


# ---------------------------------------------------------------------------------- runner
def test_failures_are_reported_and_resume_skips_finished_segments(segments, tmp_path) -> None:
    calls: list[str] = []
    oracle = Oracle(fail_on={"take1"}, calls=calls)
    runs = [_run("oracle", lambda o: oracle)]
    out = tmp_path / "bench"
    rows = R.run_bench(runs, segments, out, built={"oracle": oracle}, log=lambda s: None)
    assert len(calls) == len(segments) == len(rows)
    status = {r["segment"]: r["status"] for r in rows}
    assert status.pop("take1_f000000") == "error" and set(status.values()) == {"ok"}
    bad = json.loads((out / "segments" / "oracle" / "take1_f000000.json").read_text())
    assert "solver diverged on take1" in bad["error"] and "RuntimeError" in bad["traceback"]
    assert (out / "recons" / "oracle" / f"{segments[0].id}.npz").is_file()  # the sample's

    summary = B.write_outputs(out, rows, runs, segments, "test", plots=False)
    assert summary["oracle"]["failed"] == 1 and summary["oracle"]["segments"] == 4
    assert summary["oracle"]["MPJPE_mm"] == pytest.approx(0.0, abs=1e-6)
    results = json.loads((out / "results.json").read_text())
    assert set(results["oracle"]) == {*report.RESULT_KEYS, "failed", "init", "pace_by_category"}
    assert results["oracle"]["init"] == "truth"
    assert results["oracle"]["success_rate"] == 100.0 and results["oracle"]["segments"] == 4
    table = (out / "table.md").read_text()
    assert "| oracle | 0.00 |" in table and "| 4 | 1 |" in table
    assert "solver diverged on take1" in table  # listed under the failed segments
    assert "take1_f000000" in (out / "segments.csv").read_text()

    # Resume: nothing runs again, the failure is kept (until retry_failed).
    calls.clear()
    again = R.run_bench(runs, segments, out, built={"oracle": oracle}, log=lambda s: None)
    assert calls == [] and [r["status"] for r in again] == [r["status"] for r in rows]
    (out / "segments" / "oracle" / "take2_f000100.json").unlink()
    R.run_bench(runs, segments, out, built={"oracle": oracle}, log=lambda s: None)
    assert calls == ["take2"]
    calls.clear()
    oracle.fail_on.clear()
    fixed = R.run_bench(runs, segments, out, built={"oracle": oracle}, retry_failed=True,
                        log=lambda s: None)  # fmt: skip
    assert calls == ["take1"] and {r["status"] for r in fixed} == {"ok"}
    assert R.load_rows(out, runs, segments)[2]["status"] == "ok"


def test_pace_is_reported_per_segment_per_category_and_overall(segments, tmp_path) -> None:
    lagging = Oracle(shift=(0.3, 0.4, 0.0), lead_mps=1.2)
    runs = [_run("lagging", lambda o: lagging), _run("oracle", _oracle_factory)]
    out = tmp_path / "bench"
    rows = R.run_bench(runs, segments, out, built={"lagging": lagging}, log=lambda s: None)
    B.write_outputs(out, rows, runs, segments, "test", plots=False)
    results = json.loads((out / "results.json").read_text())
    lag, exact = results["lagging"], results["oracle"]
    assert lag["drift_mps"] == pytest.approx(1.2) and lag["pace_end_m"] == pytest.approx(1.188)
    assert lag["root_gt_5s_m"] is None  # 100-frame segments: no 5 s value
    assert lag["root_gt_1s_m"] == pytest.approx(0.5) and exact["root_gt_end_m"] == 0.0
    assert exact["drift_mps"] is None and exact["pace_1s_m"] is None
    by_cat = lag["pace_by_category"]
    assert {c: v["segments"] for c, v in by_cat.items()} == {"run": 1, "walk": 4}
    assert by_cat["walk"]["drift_mps"] == pytest.approx(1.2)
    csv_head = (out / "results.csv").read_text().splitlines()[0].split(",")
    seg_head = (out / "segments.csv").read_text().splitlines()[0].split(",")
    keys = ["pace_1s_m", "pace_5s_m", "pace_end_m", "drift_mps", "root_gt_1s_m",
            "root_gt_5s_m", "root_gt_end_m"]  # fmt: skip
    assert set(keys) <= set(csv_head) and set(keys) <= set(seg_head)
    table = (out / "table.md").read_text()
    assert "## Pace and distance to the truth" in table
    assert "| lagging | 1.19 | n/a | 1.19 | 1.20 | 0.50 | n/a | 0.50 | 5 |" in table
    assert "| oracle | n/a | n/a | n/a | n/a | 0.00 | n/a | 0.00 | 5 |" in table
    assert "| category | lagging pace end (m) | lagging drift (m/s) |" in table
    assert "| walk | 1.19 | 1.20 | 0.50 | 0.00 |" in table


def test_resume_refuses_other_settings(segments, tmp_path) -> None:
    out = tmp_path / "bench"
    R.run_bench([_run("oracle", _oracle_factory)], segments[:1], out, log=lambda s: None)
    other = R.MethodRun("oracle", "oracle", _oracle_factory,
                        MethodOptions(kin_checkpoint=tmp_path / "other.pt"))  # fmt: skip
    with pytest.raises(S.BenchError, match="other settings"):
        R.run_bench([other], segments[:1], out, log=lambda s: None)
    moved = dataclasses.replace(segments[0], start=50, stop=150)
    with pytest.raises(S.BenchError, match="other data"):
        R.run_bench([_run("oracle", _oracle_factory)], [moved], out, log=lambda s: None)


def test_methods_without_falls_or_forces_report_nan_and_table_says_na(segments, tmp_path) -> None:
    def factory(options):
        return Oracle(can_fall=False)

    runs = [_run("stiff", factory), _run("oracle", _oracle_factory)]
    out = tmp_path / "b"
    rows = R.run_bench(runs, segments[:2], out, log=lambda s: None)
    summary = B.write_outputs(out, rows, runs, segments[:2], plots=True)
    assert math.isnan(summary["stiff"]["success_rate"])
    assert json.loads((out / "results.json").read_text())["stiff"]["success_rate"] is None
    stiff_row = next(line for line in (out / "table.md").read_text().splitlines()
                     if line.startswith("| stiff |"))  # fmt: skip
    assert "n/a" in stiff_row
    for png in ("per_joint.png", "trajectory.png", "grf.png"):
        assert (out / png).read_bytes()[:4] == b"\x89PNG"


CRASHY = """
import os
from grip.kinematics.features import ground_truth
from grip.core.reconstruction import Reconstruction


class Crashy:
    name = "crashy"
    supports_sensors = False
    can_fall = False

    def reconstruct(self, rec):
        if rec.name == "take1":
            os._exit(3)  # a segfault, as far as the pool can tell
        gt = ground_truth(rec)
        return Reconstruction(name=rec.name, method=self.name, fps=rec.fps,
                              joint_pos=gt.joint_pos, global_rot=gt.global_rot)


def factory(options):
    return Crashy()
"""


def test_a_worker_that_dies_fails_only_its_segment(segments, tmp_path, monkeypatch) -> None:
    """Two spawned workers; the one running take1 dies (twice: in the pool, then alone)."""
    mod_dir = tmp_path / "mods"
    mod_dir.mkdir()
    (mod_dir / "bench_crashy_method.py").write_text(textwrap.dedent(CRASHY))
    monkeypatch.syspath_prepend(str(mod_dir))
    monkeypatch.setattr(pool, "start_method", lambda: "spawn")  # children inherit sys.path
    import bench_crashy_method

    run = R.MethodRun("crashy", "crashy", bench_crashy_method.factory, MethodOptions())
    segs = segments[:3]  # take0 x 2, take1
    rows = R.run_bench([run], segs, tmp_path / "b", workers=2, log=lambda s: None)
    by_seg = {r["segment"]: r for r in rows}
    assert by_seg["take1_f000000"]["status"] == "error"
    assert "worker process died" in by_seg["take1_f000000"]["error"]
    assert by_seg["take0_f000000"]["status"] == by_seg["take0_f000100"]["status"] == "ok"
    assert not list((tmp_path / "b").rglob("*.running"))


# -------------------------------------------------------------------------------- registry
def test_registry_errors_list_the_known_methods() -> None:
    with pytest.raises(UnknownMethodError, match=r"known methods: .*kinematics"):
        parse_method_names("kinematics,nope")
    with pytest.raises(UnknownMethodError, match=r"known methods: .*kinematics"):
        make_method("nope", MethodOptions())
    with pytest.raises(ValueError, match="more than once"):
        parse_method_names("kinematics,kinematics")
    assert parse_method_names(" kinematics ") == ["kinematics"]
    with pytest.raises(ValueError, match="imu4_press"):
        sensor_set("imu9_press")


def test_prepare_runs_skips_methods_without_sensor_support(segments, tmp_path) -> None:
    def sensing(options):
        o = Oracle()
        o.supports_sensors = True
        o.sensors = options.sensors
        return o

    registry = {"oracle": _oracle_factory, "sensing": sensing}
    messages: list[str] = []
    runs, built = R.prepare_runs(["oracle", "sensing"], MethodOptions(),
                                 ["imu2_nopress", "imu4_press"], registry,
                                 log=messages.append)  # fmt: skip
    assert [r.label for r in runs] == ["sensing@imu2_nopress", "sensing@imu4_press"]
    assert built["sensing@imu4_press"].sensors == "imu4_press"
    assert messages == ["oracle: does not support --sensors; skipped"]
    out = tmp_path / "sweep"
    rows = R.run_bench(runs, segments[:1], out, built=built, log=lambda s: None)
    B.write_outputs(out, rows, runs, segments[:1], plots=False)
    table = (out / "table.md").read_text()
    assert "GRIP Table 3" in table
    assert "| sensing | 2 | no | 0.00 |" in table and "| sensing | 4 | yes | 0.00 |" in table
    with pytest.raises(S.BenchError, match="no method to run"):
        R.prepare_runs(["oracle"], MethodOptions(), ["imu4_press"], registry, log=print)


# ------------------------------------------------------------------------ kinematics only
def test_kinematics_method_starts_at_the_true_root(seg_rec) -> None:
    method = kinematics_method(MethodOptions())
    assert isinstance(method, KinematicsOnly) and not method.can_fall
    recon = method.reconstruct(seg_rec)
    assert recon.n_frames == FRAMES and recon.grf is None and recon.ms_per_frame > 0
    gt = F.ground_truth(seg_rec)
    np.testing.assert_allclose(recon.joint_pos[0, 0], gt.joint_pos[0, 0], atol=1e-6)
    m, _ = scoring.segment_metrics(recon, gt, can_fall=method.can_fall)
    assert all(math.isfinite(m[k]) for k in ("MPJPE_mm", "PEL_MPJPE_mm", "MPJRE_deg", "FS_mps"))
    assert math.isnan(m["vGRF_N"]) and math.isnan(m["success_rate"])


def test_kinematics_sensor_checkpoints_come_from_the_sweep_folder(tmp_path) -> None:
    shipped = SHIPPED_KIN  # trained on feet + wrists + insoles = imu4_press
    for name in ("imu4_press", "imu2_press"):
        (tmp_path / name).mkdir()
        shutil.copy(shipped, tmp_path / name / "best.pt")
    ok = kinematics_method(MethodOptions(sensors="imu4_press", sweep_dir=tmp_path))
    assert ok.checkpoint == tmp_path / "imu4_press" / "best.pt"
    with pytest.raises(ValueError, match="not the imu2_press configuration"):
        kinematics_method(MethodOptions(sensors="imu2_press", sweep_dir=tmp_path))
    with pytest.raises(ValueError, match=r"no best\.pt or last\.pt"):
        kinematics_method(MethodOptions(sensors="imu6_press", sweep_dir=tmp_path))
    with pytest.raises(ValueError, match="--sweep DIR"):
        kinematics_method(MethodOptions(sensors="imu4_press"))
    with pytest.raises(ValueError, match="no such KinematicsNet checkpoint"):
        kinematics_method(MethodOptions(kin_checkpoint=tmp_path / "none.pt"))


# ------------------------------------------------------------------------------------- CLI
def test_cli_bench_kinematics_writes_results_and_resumes(dataset, tmp_path, capsys) -> None:
    args = ["bench", "--data", str(dataset), "--methods", "kinematics", "--segment-frames",
            str(FRAMES)]  # fmt: skip
    out1 = tmp_path / "one"
    assert main([*args, "--out", str(out1), "--workers", "1", "--segments", "3"]) == 0
    res = json.loads((out1 / "results.json").read_text())
    assert set(res["kinematics"]) == {*report.RESULT_KEYS, "failed", "init",
                                      "pace_by_category"}  # fmt: skip
    assert res["kinematics"]["init"] == "truth"
    assert "started from the ground truth at its first frame" in (out1 / "table.md").read_text()
    assert res["kinematics"]["segments"] == 3 and res["kinematics"]["failed"] == 0
    assert res["kinematics"]["vGRF_N"] is None and res["kinematics"]["success_rate"] is None
    assert res["kinematics"]["MPJPE_mm"] > 0
    seg_files = sorted(p.name for p in (out1 / "segments" / "kinematics").glob("*_f*.json"))
    assert "take1_f000000.json" in seg_files  # the run category is represented
    for name in ("results.csv", "segments.csv", "table.md", "per_joint.png", "trajectory.png",
                 "grf.png"):  # fmt: skip
        assert (out1 / name).is_file(), name
    assert "| kinematics |" in capsys.readouterr().out

    assert main([*args, "--out", str(out1), "--workers", "1", "--segments", "3"]) == 0
    captured = capsys.readouterr()
    assert "3 finished segment result(s) kept" in captured.out + captured.err


@pytest.mark.slow
def test_cli_bench_workers_give_the_in_process_numbers(dataset, tmp_path) -> None:
    """Two forkserver workers (each imports torch: ~10 s on a busy machine, hence slow)."""
    args = ["bench", "--data", str(dataset), "--methods", "kinematics", "--segment-frames",
            str(FRAMES), "--segments", "3"]  # fmt: skip
    res = {}
    for workers in (1, 2):
        out = tmp_path / f"w{workers}"
        assert main([*args, "--out", str(out), "--workers", str(workers)]) == 0
        res[workers] = json.loads((out / "results.json").read_text())["kinematics"]
    assert res[2]["segments"] == 3 and res[2]["failed"] == 0
    for k in ("MPJPE_mm", "PA_MPJPE_mm", "MPJRE_deg", "FS_mps", "FP_mm"):
        assert res[2][k] == pytest.approx(res[1][k], rel=1e-5), k


def test_cli_bench_errors_are_clean(dataset, tmp_path, capsys) -> None:
    base = ["bench", "--data", str(dataset), "--out", str(tmp_path / "o"), "--workers", "1"]
    assert main([*base, "--methods", "kinematics,nope"]) == 2
    err = capsys.readouterr().err
    assert "nope" in err and "kinematics" in err and "Traceback" not in err
    assert main([*base, "--sensors", "imu4_press"]) == 2
    assert "--sweep" in capsys.readouterr().err
    assert main([*base, "--data", str(tmp_path / "nowhere")]) == 2
    assert "split.json" in capsys.readouterr().err
    assert main([*base, "--kin", str(tmp_path / "none.pt"), "--segment-frames", "100"]) == 2
    assert "none.pt" in capsys.readouterr().err


def test_pip_physics_on_kinematicsnet_gives_forces_and_less_foot_sliding(seg_rec) -> None:
    method = make_method("kin+pip", MethodOptions())
    recon = method.reconstruct(seg_rec)
    assert recon.method == "kin+pip" and recon.n_frames == FRAMES and not method.can_fall
    gt = F.ground_truth(seg_rec)
    m, _ = scoring.segment_metrics(recon, gt, can_fall=False)
    assert math.isfinite(m["vGRF_N"]) and recon.residual.shape == (FRAMES, 6)
    kin_recon = kinematics_method(MethodOptions()).reconstruct(seg_rec)
    kin, _ = scoring.segment_metrics(kin_recon, gt, False)
    assert m["FS_mps"] < kin["FS_mps"]


def test_vgrf_leaves_out_frames_without_forces() -> None:
    pred = np.array([[100.0, 200.0], [np.nan, np.nan], [110.0, 190.0]])
    ins = np.array([[90.0, 200.0], [500.0, 500.0], [110.0, 200.0]])
    assert scoring.vgrf_error_n(pred, ins) == pytest.approx(5.0)
    assert math.isnan(scoring.vgrf_error_n(np.full((2, 2), np.nan), ins[:2]))


@pytest.mark.parametrize("name", ["transpose", "pip"])
def test_shipped_baselines_start_at_the_true_first_frame(name) -> None:
    """The shipped TransPose-4 / PIP-4 networks load by default and reconstruct a real walk
    (the bundled sample; the synthetic recordings float above the floor) from the ground truth
    at its first frame (PIP: pose and root; TransPose: the root)."""
    from prism_tools.io import load_recording

    rec = load_recording(SAMPLE_RECORDING).slice_frames(0, FRAMES)
    method = make_method(name, MethodOptions())
    recon = method.reconstruct(rec)
    gt = F.ground_truth(rec)
    assert recon.n_frames == FRAMES and np.isfinite(recon.joint_pos).all()
    np.testing.assert_allclose(recon.joint_pos[0, 0], gt.joint_pos[0, 0], atol=1e-6)
    if name == "pip":
        np.testing.assert_allclose(recon.global_rot[0], gt.global_rot[0], atol=1e-6)
        assert recon.notes["qp_failures"] < FRAMES // 10
    m, _ = scoring.segment_metrics(recon, gt, can_fall=method.can_fall)
    assert m["MPJRE_deg"] < 60


def test_blow_ups_are_counted_per_segment_and_in_the_results(segments, tmp_path) -> None:
    oracle = Oracle(blowups=2, lost=3)
    runs = [_run("oracle", lambda o: oracle)]
    out = tmp_path / "bench"
    rows = R.run_bench(runs, segments, out, built={"oracle": oracle}, log=lambda s: None)
    assert [r["blowups"] for r in rows] == [2] * len(segments)
    B.write_outputs(out, rows, runs, segments, "test", plots=False)
    results = json.loads((out / "results.json").read_text())
    assert results["oracle"]["blowups"] == 2 * len(segments)
    assert results["oracle"]["lost"] == 3 * len(segments)
    table = (out / "table.md").read_text()
    assert "Simulation blow-ups" in table and f"oracle {3 * len(segments)}" in table
    head = (out / "segments.csv").read_text().splitlines()[0].split(",")
    assert "blowups" in head and "lost" in head


class BatchOracle(Oracle):
    """:class:`Oracle` that plays several segments at once (``reconstruct_many``, as method
    grip does); ``batches``: the number of recordings of each call."""

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.batches: list[int] = []

    def reconstruct_many(self, recs: list, threads: int = 0) -> list:
        self.batches.append(len(recs))
        out: list = []
        for rec in recs:
            try:
                out.append(self.reconstruct(rec))
            except Exception as e:
                out.append(e)
        return out


def test_batched_methods_run_segments_together_with_the_same_rows(segments, tmp_path) -> None:
    rows = {}
    for batch in (1, 3):
        oracle = BatchOracle(fail_on={"take1"})
        runs = [_run("oracle", lambda o, m=oracle: m)]
        rows[batch] = R.run_bench(runs, segments, tmp_path / f"b{batch}",
                                  built={"oracle": oracle},
                                  log=lambda s: None, batch=batch)  # fmt: skip
        assert oracle.batches == ([] if batch == 1 else [3, 2])  # 5 segments
    drop = ("ms_per_frame", "method_ms_per_frame", "traceback")
    for a, b in zip(rows[1], rows[3], strict=True):
        a, b = ({k: v for k, v in r.items() if k not in drop} for r in (a, b))
        a["metrics"].pop("ms_per_frame", None), b["metrics"].pop("ms_per_frame", None)
        assert json.dumps(report.jsonable(a)) == json.dumps(report.jsonable(b))
    assert [r["status"] for r in rows[3]].count("error") == 1  # take1 keeps its error row
    # with two workers a batch of 3 would leave one idle: units of 2
    run = _run("oracle", _oracle_factory)
    units = R._units([(run, s) for s in segments], 3, 2, lambda r: True)
    assert [len(segs) for _, segs in units] == [3, 2]
    units = R._units([(run, s) for s in segments[:4]], 3, 2, lambda r: True)
    assert [len(segs) for _, segs in units] == [2, 2]
