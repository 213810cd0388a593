"""Recordings without ground truth (real sensors, no motion capture): valid, saved and loaded in
both formats, and refused with a clear message wherever the ground truth is needed."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest

from prism_tools import (
    Recording,
    RecordingError,
    chunk_recording,
    load_recording,
    save_recording,
    validate,
)
from prism_tools.schema import recording_as_float32
from prism_tools.synthetic import make_recording


def _sensors_only(rec: Recording) -> Recording:
    return dataclasses.replace(rec, smpl_params=None, imu_gt={}, slam=None, objects=None)


@pytest.fixture(scope="module")
def rec() -> Recording:
    return _sensors_only(make_recording(120, seed=7))


def test_a_sensors_only_recording_is_valid(rec: Recording) -> None:
    validate(rec)
    assert rec.n_frames == 120 and not rec.has_ground_truth
    part = rec.slice_frames(10, 50)
    assert part.n_frames == 40 and part.smpl_params is None
    assert recording_as_float32(rec).imu["L_Foot"].acc_world_raw.dtype == np.float32
    assert [c.n_frames for c in chunk_recording(rec, 50, min_length=10)] == [50, 50, 20]
    d = rec.to_prism_dict()
    assert d["smpl_params"] is None and d["imu_gt"] == {}


@pytest.mark.parametrize("suffix", [".npz", ".pkl"])
def test_save_and_load_without_ground_truth(rec: Recording, tmp_path, suffix: str) -> None:
    path = tmp_path / f"take{suffix}"
    save_recording(rec, path)
    back = load_recording(path)
    assert back.smpl_params is None and back.imu_gt == {} and back.source == str(path)
    assert back.n_frames == rec.n_frames
    for part, s in rec.imu.items():
        np.testing.assert_array_equal(back.imu[part].ori_world, s.ori_world)
    np.testing.assert_array_equal(back.insole["R_Foot"].forces, rec.insole["R_Foot"].forces)


def test_a_prism_pickle_without_the_ground_truth_keys_loads(rec: Recording, tmp_path) -> None:
    d = rec.to_prism_dict()
    del d["smpl_params"], d["imu_gt"], d["grip"]
    path = tmp_path / "subj001" / "take002.pkl"
    path.parent.mkdir()
    path.write_bytes(pickle.dumps(d, protocol=4))
    back = load_recording(path)
    assert back.smpl_params is None and back.take_name == "subj001_take002"


def test_frames_come_from_the_sensors_and_must_agree(rec: Recording) -> None:
    short = dataclasses.replace(rec.imu["L_Wrist"], ori_world=rec.imu["L_Wrist"].ori_world[:-1])
    with pytest.raises(RecordingError, match=r"imu\.L_Wrist\.ori_world: expected shape"):
        validate(dataclasses.replace(rec, imu={**rec.imu, "L_Wrist": short}))
    insoles_only = dataclasses.replace(rec, imu={})
    validate(insoles_only)
    assert insoles_only.n_frames == rec.n_frames
    with pytest.raises(RecordingError, match="no smpl_params and no imu or insole stream"):
        validate(dataclasses.replace(rec, imu={}, insole={}, insole_combined=None))


def test_what_needs_ground_truth_refuses_naming_the_file(rec: Recording, tmp_path) -> None:
    from grip.kinematics.features import ground_truth, targets

    path = tmp_path / "sensors.npz"
    save_recording(rec, path)
    back = load_recording(path)
    for fn in (targets, ground_truth):
        with pytest.raises(RecordingError, match=rf"^{path}: .* needs ground truth"):
            fn(back)
    with pytest.raises(RecordingError, match=r"^recording .*: training .* sensors only"):
        targets(rec)


def test_data_info_and_plot_show_what_there_is(rec: Recording, tmp_path) -> None:
    from grip.dataset.info import dataset_summary, format_summary
    from grip.dataset.plot import plot_recording

    save_recording(rec, tmp_path / "a.npz")
    save_recording(make_recording(50, seed=1), tmp_path / "b.npz")
    s = dataset_summary(tmp_path)
    assert s["recordings"] == 2 and s["sensors_only"] == 1 and s["frames"] == 170
    assert "without ground truth (sensors only, no smpl_params): 1" in format_summary(s)
    assert plot_recording(rec, tmp_path / "p.png").stat().st_size > 0
