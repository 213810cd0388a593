"""``benchmarks/bench_compare.py``: two bench folders per category, on hand-written
``segments.csv`` files."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.cli.test_data_cli import _benchmark

HEAD = "method,segment,category,status,falls,lost,MPJPE_mm\n"


@pytest.fixture(scope="module")
def bc():
    return _benchmark("bench_compare")


def _write(folder: Path, rows: list[str]) -> Path:
    folder.mkdir()
    (folder / "segments.csv").write_text(HEAD + "".join(r + "\n" for r in rows))
    return folder


def test_categories_events_and_the_unmatched(bc, tmp_path, capsys) -> None:
    before = _write(tmp_path / "a", [
        "grip,s1,walk,ok,0,,400", "grip,s2,walk,ok,1,,600", "grip,s3,sit-stand,ok,2,,500",
        "grip,s4,walk,ok,0,,1", "kinematics,s1,walk,ok,0,,300", "kinematics,s2,walk,ok,0,,350",
        "kinematics,s3,sit-stand,ok,0,,450"])  # fmt: skip
    after = _write(tmp_path / "b", [
        "grip,s1,walk,ok,1,1,320", "grip,s2,walk,ok,1,0,500", "grip,s3,sit-stand,ok,3,2,420",
        "grip,s5,walk,ok,0,0,1"])  # fmt: skip
    res = bc.compare(before, after)
    walk, sit, all_ = (res["categories"][k] for k in ("walk", "sit-stand", "all"))
    assert res["unmatched"] == 2 and list(res["categories"])[-1] == "all"
    assert walk["segments"] == 2 and walk["mpjpe_before"] == 500 and walk["mpjpe_after"] == 410
    assert walk["mpjpe_kinematics"] == 325
    assert (walk["no_event_before"], walk["no_event_after"]) == (1, 0)
    assert (walk["no_fall_before"], walk["no_fall_after"]) == (1, 1)  # s1's event: lost
    assert (sit["events_before"], sit["events_after"], sit["lost_after"]) == (2, 3, 2)
    assert all_["segments"] == 3 and all_["lost_after"] == 3
    out = tmp_path / "c.json"
    assert bc.main([str(before), str(after), "--json", str(out)]) == 0
    line = "| walk | 2 | 500 | 410 | 325 | 1 -> 2 (1) | 1 -> 0 | 1 -> 1 |"
    assert line in capsys.readouterr().out
    assert json.loads(out.read_text())["categories"]["all"]["segments"] == 3
    assert bc.main([str(before), str(after), "--method", "pip"]) == 1
    with pytest.raises(SystemExit, match="cannot read"):
        bc.main([str(before), str(tmp_path / "missing")])


def test_pose_by_events_splits_segments_by_falls(bc, tmp_path, capsys) -> None:
    head = "method,segment,category,status,falls,PEL_MPJPE_mm,MPJRE_deg\n"
    rows = ["grip,s1,walk,ok,0,60,16", "grip,s2,walk,ok,0,80,20", "grip,s3,jump,ok,2,150,30",
            "grip,s4,jump,failed,0,1,1", "kinematics,s1,walk,ok,0,40,9",
            "kinematics,s2,walk,ok,0,50,11", "kinematics,s3,jump,ok,0,100,18"]  # fmt: skip
    csv_file = tmp_path / "a_segments.csv"
    csv_file.write_text(head + "".join(r + "\n" for r in rows))
    res = bc.pose_by_events(csv_file)
    assert res["no event"] == {"segments": 2, "pel_mpjpe": 70, "mpjre": 18, "kin_pel_mpjpe": 45,
                               "kin_mpjre": 10}  # fmt: skip
    assert res["events"]["segments"] == 1 and res["events"]["kin_mpjre"] == 18
    assert bc.main([str(csv_file), str(csv_file), "--pose-by-events"]) == 0
    assert "| no event: 2 | 70 | 18.0 | 45 / 10.0 |" in capsys.readouterr().out
    assert bc.main([str(csv_file), str(csv_file), "--pose-by-events", "--method", "pip"]) == 1


def test_pose_by_events_paired_splits_both_folders_alike(bc, tmp_path, capsys) -> None:
    head = "method,segment,category,status,falls,lost,PEL_MPJPE_mm,MPJRE_deg\n"
    a = ["grip,s1,walk,ok,0,0,60,16", "grip,s2,walk,ok,0,0,80,20", "grip,s3,jump,ok,1,0,150,30",
         "grip,s5,walk,ok,0,0,10,1"]  # fmt: skip
    b = ["grip,s1,walk,ok,0,0,50,14", "grip,s2,walk,ok,0,1,90,22", "grip,s3,jump,ok,0,0,120,25"]
    fa, fb = tmp_path / "a.csv", tmp_path / "b.csv"
    fa.write_text(head + "".join(r + "\n" for r in a))
    fb.write_text(head + "".join(r + "\n" for r in b))
    calm, both = bc.calm_in_both(fa, fb)
    assert calm == {"s1"} and both == {"s1", "s2", "s3"}  # (s2 lost in b, s3 fell in a)
    assert bc.main([str(fa), str(fb), "--pose-by-events", "--paired"]) == 0
    out = capsys.readouterr().out
    assert f"| {fa} | no event: 1 | 60 | 16.0 |" in out
    assert f"| {fb} | no event: 1 | 50 | 14.0 |" in out
    assert f"| {fa} | events: 2 | 115 | 25.0 |" in out  # s2 and s3, not s5 (only in a)
    assert f"| {fb} | events: 2 | 105 | 23.5 |" in out


def test_action_scale_writes_a_policy_with_its_offsets_shrunk(tmp_path, capsys) -> None:
    from grip.assets import SHIPPED_POLICY
    from policies.runner import PolicyRunner

    mod = _benchmark("action_scale")
    out = tmp_path / "p60.pt"
    assert mod.main(["--policy", str(SHIPPED_POLICY), "--scale", "0.6", "--out", str(out)]) == 0
    base, got = PolicyRunner.load(SHIPPED_POLICY), PolicyRunner.load(out)
    assert got.env_cfg.action_scale == pytest.approx(0.6 * base.env_cfg.action_scale)
    assert got.env_cfg.kinematic_obs == base.env_cfg.kinematic_obs
    assert mod.main(["--policy", str(SHIPPED_POLICY), "--scale", "0", "--out", str(out)]) == 2
    assert "--scale must be in (0, 2]" in capsys.readouterr().err
