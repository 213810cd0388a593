"""Tests for prism_tools.gaps (degraded mode: short NaN dropouts filled) and load_recording."""

from __future__ import annotations

import math
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from prism_tools import Recording, RecordingError, load_recording, save_recording
from prism_tools.gaps import fill_gaps, missing_runs
from prism_tools.io import atomic_write
from prism_tools.prism_dict import recording_from_prism_dict
from prism_tools.synthetic import make_recording

F = 150


@pytest.fixture(scope="module")
def rec() -> Recording:
    return make_recording(F, seed=3)


def _copy_tree(value: Any) -> Any:
    """Copies every dict and array separately (deepcopy would keep arrays shared between keys)."""
    if isinstance(value, dict):
        return {k: _copy_tree(v) for k, v in value.items()}
    return value.copy() if isinstance(value, np.ndarray) else value


def _dict(rec: Recording) -> dict[str, Any]:
    """A PRISM dict whose nested dicts and arrays are private copies (safe to edit)."""
    return _copy_tree(rec.to_prism_dict())


def _ramp(dtype: type = np.float64) -> np.ndarray:
    """``(F, 3)`` linear in the frame index, exact in binary floating point."""
    i = np.arange(F, dtype=np.float64)[:, None]
    return (i * np.array([1.0, 2.0, -0.5]) + np.array([0.0, 1.0, 2.0])).astype(dtype)


def _rot_z(deg: float) -> np.ndarray:
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Rotation angle of ``a^T b``, degrees."""
    cos = (np.trace(a.T @ b) - 1.0) / 2.0
    return math.degrees(math.acos(float(np.clip(cos, -1.0, 1.0))))


def _write_pkl(d: dict[str, Any], path: Path) -> None:
    """Writes a (possibly invalid) PRISM dict as save_recording would, without validating it."""
    atomic_write(path, lambda f: pickle.dump(d, f, protocol=4))


# ------------------------------------------------------------------------------ fill_gaps
def test_missing_runs() -> None:
    a = np.zeros((10, 2))
    a[[0, 3, 4, 9], 1] = np.nan
    a[5, 0] = np.inf
    assert missing_runs(a) == [(0, 0), (3, 5), (9, 9)]
    assert missing_runs(np.zeros((4, 3, 3))) == []
    assert missing_runs(np.zeros((0, 3))) == []


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_linear_ramp_gap_restored_exactly(rec: Recording, dtype: type) -> None:
    d = _dict(rec)
    ramp = _ramp(dtype)
    gappy = ramp.copy()
    gappy[10:13, 1] = np.nan  # one component missing: the whole frame is replaced
    gappy[11, :] = np.nan
    d["imu"]["L_Wrist"]["acc_world_filt"] = gappy

    out, report = fill_gaps(d, 3)

    filled = out["imu"]["L_Wrist"]["acc_world_filt"]
    assert filled.dtype == dtype and filled.shape == (F, 3)
    np.testing.assert_array_equal(filled, ramp)
    assert report == [{"key": "imu.L_Wrist.acc_world_filt", "first": 10, "last": 12}]
    recording_from_prism_dict(out)  # now valid


def test_orientation_gap_is_slerped(rec: Recording) -> None:
    d = _dict(rec)
    ori = np.empty((F, 3, 3))
    ori[:21] = np.eye(3)
    ori[22:] = _rot_z(90.0)
    ori[21] = np.nan
    ori[60:100] = _rot_z(90.0)  # second gap, 3 frames from 90 deg to 170 deg about z
    ori[104:] = _rot_z(170.0)
    ori[101:104] = np.nan
    ori[100] = _rot_z(90.0)
    d["imu"]["Head"]["ori_world"] = ori

    out, report = fill_gaps(d, 3)

    got = out["imu"]["Head"]["ori_world"]
    np.testing.assert_allclose(got[21], _rot_z(45.0), atol=1e-12)  # the slerp midpoint
    assert _angle_deg(np.eye(3), got[21]) == pytest.approx(45.0, abs=1e-9)
    for k, frame in enumerate(range(101, 104), start=1):
        assert _angle_deg(_rot_z(90.0), got[frame]) == pytest.approx(20.0 * k, abs=1e-9)
        np.testing.assert_allclose(got[frame], _rot_z(90.0 + 20.0 * k), atol=1e-12)
    np.testing.assert_array_equal(np.delete(got, [21, 101, 102, 103], axis=0),
                                  np.delete(ori, [21, 101, 102, 103], axis=0))  # fmt: skip
    assert report == [
        {"key": "imu.Head.ori_world", "first": 21, "last": 21},
        {"key": "imu.Head.ori_world", "first": 101, "last": 103},
    ]


def test_start_and_end_gaps_hold_nearest_frame(rec: Recording) -> None:
    d = _dict(rec)
    force = d["insole"]["L_Foot"]["force"]
    force[:2] = np.nan
    force[-3:] = np.nan
    ori = d["imu"]["Pelvis"]["ori_world"]
    ori[0, 0, 0] = np.inf
    cop = d["insole"]["combined"]["CoP_world"]
    cop[-1] = np.nan

    out, report = fill_gaps(d, 3)

    got = out["insole"]["L_Foot"]["force"]
    np.testing.assert_array_equal(got[:2], np.repeat(force[2:3], 2, axis=0))
    np.testing.assert_array_equal(got[-3:], np.repeat(force[-4:-3], 3, axis=0))
    np.testing.assert_array_equal(got[2:-3], force[2:-3])
    np.testing.assert_array_equal(out["imu"]["Pelvis"]["ori_world"][0], ori[1])
    np.testing.assert_array_equal(out["insole"]["combined"]["CoP_world"][-1], cop[-2])
    assert sorted((r["key"], r["first"], r["last"]) for r in report) == [
        ("imu.Pelvis.ori_world", 0, 0),
        ("insole.L_Foot.force", 0, 1),
        ("insole.L_Foot.force", F - 3, F - 1),
        ("insole.combined.CoP_world", F - 1, F - 1),
    ]
    recording_from_prism_dict(out)


def test_long_gap_left_untouched(rec: Recording) -> None:
    d = _dict(rec)
    acc = d["imu"]["L_Wrist"]["acc_world_filt"]
    acc[10:16] = np.nan  # 6 frames: too long
    acc[40:42] = np.nan  # 2 frames: filled

    out, report = fill_gaps(d, 5)

    got = out["imu"]["L_Wrist"]["acc_world_filt"]
    assert np.isnan(got[10:16]).all()
    assert np.isfinite(got[40:42]).all()
    assert report == [{"key": "imu.L_Wrist.acc_world_filt", "first": 40, "last": 41}]
    with pytest.raises(RecordingError, match=r"imu\.L_Wrist\.acc_world_filt: 18 non-finite"):
        recording_from_prism_dict(out, source="x.pkl")


def test_input_dict_unchanged(rec: Recording) -> None:
    d = _dict(rec)
    d["imu"]["L_Wrist"]["acc_world_filt"][5:8] = np.nan
    d["imu"]["L_Wrist"]["ori_world"][5:8] = np.nan
    d["insole"]["R_Foot"]["forces"][0] = np.nan
    before = _copy_tree(d)
    ids = {k: id(v) for k, v in d.items()}
    wrist = d["imu"]["L_Wrist"]

    out, report = fill_gaps(d, 5)

    assert len(report) == 3
    assert {k: id(v) for k, v in d.items()} == ids and d["imu"]["L_Wrist"] is wrist
    # assert_array_equal treats NaN == NaN: the gaps are still in the input
    for group in ("imu", "insole"):
        for part, fields in before[group].items():
            for name, arr in fields.items():
                np.testing.assert_array_equal(d[group][part][name], arr, err_msg=name)
    assert np.isnan(d["imu"]["L_Wrist"]["acc_world_filt"][5:8]).all()
    # unchanged arrays are shared, changed ones are new
    assert out["imu"]["Head"]["ori_world"] is d["imu"]["Head"]["ori_world"]
    assert out["imu"]["L_Wrist"]["acc_world_filt"] is not d["imu"]["L_Wrist"]["acc_world_filt"]
    assert out["smpl_params"] is d["smpl_params"]


def test_no_filling_cases(rec: Recording) -> None:
    d = _dict(rec)
    d["imu"]["R_Wrist"]["acc_world_raw"][3] = np.nan
    d["imu"]["L_Knee"]["acc_world_raw"][:] = np.nan  # entirely non-finite: not filled
    for max_frames in (0, -1):
        out, report = fill_gaps(d, max_frames)
        assert report == []
        assert np.isnan(out["imu"]["R_Wrist"]["acc_world_raw"][3]).all()
    out, report = fill_gaps(d, 5)
    assert report == [{"key": "imu.R_Wrist.acc_world_raw", "first": 3, "last": 3}]
    assert np.isnan(out["imu"]["L_Knee"]["acc_world_raw"]).all()
    assert out["insole"]["L_Foot"]["contacts"] is d["insole"]["L_Foot"]["contacts"]
    with pytest.raises(RecordingError, match=r"^f\.pkl: expected a dict"):
        fill_gaps([1, 2], 5, source="f.pkl")  # type: ignore[arg-type]


def test_imu_gt_and_unknown_parts_are_filled(rec: Recording) -> None:
    d = _dict(rec)
    d["imu_gt"]["Pelvis"]["vel_world"][7] = np.nan
    d["imu"]["Spine"] = {"acc_world_raw": _ramp()}  # any part name
    d["imu"]["Spine"]["acc_world_raw"][1] = np.nan
    _, report = fill_gaps(d, 1)
    assert report == [
        {"key": "imu.Spine.acc_world_raw", "first": 1, "last": 1},
        {"key": "imu_gt.Pelvis.vel_world", "first": 7, "last": 7},
    ]


# ------------------------------------------------------------------------ load_recording
def test_load_recording_fills_gaps(rec: Recording, tmp_path: Path) -> None:
    d = _dict(rec)
    d["imu"]["L_Wrist"]["acc_world_filt"][50:53] = np.nan
    d["imu"]["L_Wrist"]["ori_world"][50] = np.nan
    path = tmp_path / "subj001_take001.pkl"
    _write_pkl(d, path)

    with pytest.raises(RecordingError, match="non-finite"):
        load_recording(path)  # default: no degraded mode
    back = load_recording(path, fill_gaps=5)

    assert back.extras["filled_gaps"] == [
        {"key": "imu.L_Wrist.acc_world_filt", "first": 50, "last": 52},
        {"key": "imu.L_Wrist.ori_world", "first": 50, "last": 50},
    ]
    assert np.isfinite(back.imu["L_Wrist"].acc_world_filt).all()
    np.testing.assert_array_equal(back.imu["L_Wrist"].acc_world_raw,
                                  rec.imu["L_Wrist"].acc_world_raw)  # fmt: skip
    # the report survives a save/load round trip in both formats
    for suffix in (".pkl", ".npz"):
        out = tmp_path / f"filled{suffix}"
        save_recording(back, out)
        assert load_recording(out).extras["filled_gaps"] == back.extras["filled_gaps"]


def test_load_recording_without_gaps_has_no_report(rec: Recording, tmp_path: Path) -> None:
    path = tmp_path / "clean.npz"
    save_recording(rec, path)
    assert "filled_gaps" not in load_recording(path, fill_gaps=5).extras


def test_load_recording_rejects_long_gap(rec: Recording, tmp_path: Path) -> None:
    d = _dict(rec)
    d["insole"]["R_Foot"]["CoP_world"][20:30] = np.nan
    path = tmp_path / "subj002_take003.pkl"
    _write_pkl(d, path)

    with pytest.raises(RecordingError) as ei:
        load_recording(path, fill_gaps=5)

    msg = str(ei.value)
    assert msg.startswith(str(path))
    assert "insole.R_Foot.CoP_world: 30 non-finite value(s)" in msg
    assert "first at frame 20" in msg and "fill_gaps=5" in msg
