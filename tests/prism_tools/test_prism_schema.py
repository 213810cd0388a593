"""Tests for the recording schema: validate(), PRISM dict conversion, force-unit detection."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from prism_tools import Recording, RecordingError, validate
from prism_tools.prism_dict import detect_force_unit, recording_from_prism_dict
from prism_tools.streams import (
    EXTRAS_KEY,
    FEET,
    GRAVITY,
    IMU_PARTS,
    INSOLE_BACK_CELLS,
    INSOLE_FRONT_CELLS,
)
from prism_tools.synthetic import make_recording

F = 300


@pytest.fixture(scope="module")
def rec() -> Recording:
    return make_recording(F, seed=3, with_objects=True)


def _replace_imu(rec: Recording, part: str, **changes: Any) -> Recording:
    return dataclasses.replace(
        rec, imu={**rec.imu, part: dataclasses.replace(rec.imu[part], **changes)}
    )


def test_constants() -> None:
    assert IMU_PARTS == (
        "L_Foot", "R_Foot", "L_Wrist", "R_Wrist", "Head", "Pelvis", "L_Knee", "R_Knee",
    )  # fmt: skip
    assert FEET == ("L_Foot", "R_Foot")
    assert list(INSOLE_FRONT_CELLS) == list(range(8, 16))
    assert list(INSOLE_BACK_CELLS) == [0, 1, 2, 3]


def test_synthetic_recording_is_valid(rec: Recording) -> None:
    validate(rec)
    assert rec.n_frames == F
    assert rec.fps == 100.0
    assert rec.category == "walk"
    assert rec.take_name == "subj003_take003"
    assert rec.smpl_params.poses.dtype == np.float32
    assert rec.smpl_params.betas.dtype == np.float32
    assert rec.smpl_params.trans.dtype == np.float64


def test_wrong_shape_names_key_path(rec: Recording) -> None:
    bad = _replace_imu(rec, "L_Wrist", ori_world=rec.imu["L_Wrist"].ori_world[:-1])
    with pytest.raises(RecordingError) as exc:
        validate(bad)
    assert str(exc.value) == (
        f"imu.L_Wrist.ori_world: expected shape (F, 3, 3) with F={F}, got ({F - 1}, 3, 3)"
    )


def test_nan_names_key_path_and_frame(rec: Recording) -> None:
    pos = rec.imu_gt["Head"].pos_world.copy()
    pos[7, 1] = np.nan
    bad = dataclasses.replace(
        rec, imu_gt={**rec.imu_gt, "Head": dataclasses.replace(rec.imu_gt["Head"], pos_world=pos)}
    )
    with pytest.raises(RecordingError, match=r"^imu_gt\.Head\.pos_world: 1 non-finite .* frame 7"):
        validate(bad)


def test_non_orthonormal_rotation(rec: Recording) -> None:
    ori = rec.imu["Pelvis"].ori_world.copy()
    ori[0] *= 1.01
    with pytest.raises(RecordingError, match=r"^imu\.Pelvis\.ori_world: not a rotation matrix"):
        validate(_replace_imu(rec, "Pelvis", ori_world=ori))
    reflected = rec.imu["Pelvis"].ori_world.copy()
    reflected[-1] = -reflected[-1]  # orthonormal but det = -1
    with pytest.raises(RecordingError, match=rf"not a rotation matrix at frame {F - 1}"):
        validate(_replace_imu(rec, "Pelvis", ori_world=reflected))


def test_wrong_dtype_and_missing_field(rec: Recording) -> None:
    left = rec.insole["L_Foot"]
    bad = dataclasses.replace(
        rec,
        insole={**rec.insole, "L_Foot": dataclasses.replace(left, contacts=left.contacts * 1.0)},
    )
    with pytest.raises(RecordingError, match=r"^insole\.L_Foot\.contacts: expected bool dtype"):
        validate(bad)
    with pytest.raises(RecordingError, match=r"^imu\.Head\.acc_world_raw: missing \(None\)"):
        validate(_replace_imu(rec, "Head", acc_world_raw=None))


def test_fps_and_unknown_part(rec: Recording) -> None:
    with pytest.raises(RecordingError, match=r"^fps: expected a finite positive number"):
        validate(dataclasses.replace(rec, fps=0.0))
    with pytest.raises(RecordingError, match=r"^info\.data_info\.fps: .* differs"):
        validate(dataclasses.replace(rec, fps=50.0))
    with pytest.raises(RecordingError, match=r"^imu\.Chest: unknown part"):
        validate(dataclasses.replace(rec, imu={**rec.imu, "Chest": rec.imu["Head"]}))


def test_prism_dict_layout(rec: Recording) -> None:
    d = rec.to_prism_dict()
    assert set(d) == {
        "info", "smpl_params", "imu", "imu_gt", "insole", "slam", "objects", EXTRAS_KEY,
    }  # fmt: skip
    assert set(d["info"]["subj_info"]) == {
        "subj_id", "gender", "age", "height", "weight", "shoe_length", "arm_length",
    }  # fmt: skip
    assert d["info"]["data_info"]["fps"] == 100.0
    assert set(d["insole"]) == {"L_Foot", "R_Foot", "combined"}
    assert set(d["insole"]["combined"]) == {"force_world", "CoP_world"}
    assert set(d["imu"]["L_Foot"]) >= {"acc_local_raw", "gyr_local_raw"}
    assert "acc_local_raw" not in d["imu"]["Head"]
    assert set(d["objects"]["BoxSmall"]) == {"vertices", "faces", "centroid", "extents"}
    assert d["smpl_params"]["gender"] == rec.smpl_params.gender


def test_from_prism_dict_round_trip(rec: Recording) -> None:
    back = recording_from_prism_dict(rec.to_prism_dict())
    assert back.extras == rec.extras  # declared unit: no detection, nothing added
    for part in rec.imu:
        np.testing.assert_array_equal(back.imu[part].ori_world, rec.imu[part].ori_world)
    assert back.subject == rec.subject


def test_missing_key_names_path_and_source(rec: Recording) -> None:
    d = rec.to_prism_dict()
    del d["imu"]["L_Wrist"]["ori_world"]
    with pytest.raises(RecordingError) as exc:
        recording_from_prism_dict(d, source="subj001/take002.pkl")
    assert str(exc.value) == "subj001/take002.pkl: imu.L_Wrist.ori_world: missing key"
    d = rec.to_prism_dict()
    del d["info"]["subj_info"]["weight"]
    with pytest.raises(RecordingError, match=r"^info\.subj_info\.weight: missing key"):
        recording_from_prism_dict(d)


def _as_real_prism(rec: Recording, force_scale: float) -> dict[str, Any]:
    """A PRISM dict without our namespace, insole forces multiplied by ``force_scale``."""
    d = rec.to_prism_dict()
    del d[EXTRAS_KEY]
    for foot in FEET:
        s = d["insole"][foot]
        for key in ("force", "forces", "force_world"):
            s[key] = s[key] * force_scale
    d["insole"]["combined"]["force_world"] = d["insole"]["combined"]["force_world"] * force_scale
    return d


def test_force_unit_n_per_kg_detected_and_converted(rec: Recording) -> None:
    back = recording_from_prism_dict(_as_real_prism(rec, GRAVITY))
    assert back.extras["force_unit_detected"] == "n_per_kg"
    assert back.extras["force_scale"] == pytest.approx(1 / GRAVITY)
    assert "divided by 9.81" in back.extras["force_unit_note"]
    for foot in FEET:
        for key in ("force", "forces", "force_world"):
            np.testing.assert_allclose(
                getattr(back.insole[foot], key), getattr(rec.insole[foot], key), atol=1e-12
            )
    assert back.insole_combined is not None and rec.insole_combined is not None
    np.testing.assert_allclose(
        back.insole_combined.force_world, rec.insole_combined.force_world, atol=1e-12
    )


def test_force_unit_body_weight_detected_unchanged(rec: Recording) -> None:
    back = recording_from_prism_dict(_as_real_prism(rec, 1.0))
    assert back.extras["force_unit_detected"] == "body_weight"
    assert back.extras["force_scale"] == 1.0
    np.testing.assert_array_equal(back.insole["L_Foot"].force, rec.insole["L_Foot"].force)


def test_force_unit_explicit_overrides_detection(rec: Recording) -> None:
    back = recording_from_prism_dict(_as_real_prism(rec, 1.0), force_unit="n_per_kg")
    assert back.extras["force_unit_detected"] == "n_per_kg"
    np.testing.assert_allclose(back.insole["R_Foot"].force, rec.insole["R_Foot"].force / GRAVITY)


def test_detect_force_unit() -> None:
    assert detect_force_unit(np.full(50, 1.02))[0] == "body_weight"
    assert detect_force_unit(np.full(500, 9.7))[0] == "n_per_kg"
    assert detect_force_unit(np.zeros(100))[0] == "undetermined"
    unit, median = detect_force_unit(np.r_[np.full(100, 1.0), np.full(900, 20.0)])
    assert unit == "body_weight" and median == 1.0  # only the first 100 frames count


def test_real_prism_normalisations(rec: Recording) -> None:
    d = _as_real_prism(rec, 1.0)
    d["info"]["subj_info"]["height"] = 172.0
    d["info"]["subj_info"]["weight"] = np.float64(70.5)
    d["insole"]["L_Foot"]["contacts"] = d["insole"]["L_Foot"]["contacts"].astype(np.float32)
    d["info"]["data_info"]["synth_imu_frames"] = {"L_Wrist": [3, 4, 5], "R_Wrist": []}
    d["info"]["data_info"]["camera"] = "extra"
    back = recording_from_prism_dict(d)
    assert back.subject.height_m == pytest.approx(1.72)
    assert "centimetres" in back.extras["height_unit_note"]
    assert type(back.subject.weight_kg) is float
    assert back.insole["L_Foot"].contacts.dtype == bool
    np.testing.assert_array_equal(back.data_info.synth_imu_frames["L_Wrist"], [3, 4, 5])
    assert back.data_info.synth_imu_frames["R_Wrist"].dtype == np.int64
    assert back.extras["ignored_keys"] == ["info.data_info.camera"]


def test_slice_frames_reindexes_synth_frames(rec: Recording) -> None:
    r = dataclasses.replace(
        rec,
        data_info=dataclasses.replace(
            rec.data_info, synth_imu_frames={"L_Wrist": np.array([5, 120, 250])}
        ),
    )
    part = r.slice_frames(100, 200)
    validate(part)
    assert part.n_frames == 100
    np.testing.assert_array_equal(part.data_info.synth_imu_frames["L_Wrist"], [20])
    np.testing.assert_array_equal(part.smpl_params.poses, rec.smpl_params.poses[100:200])
    assert part.slam is not None and rec.slam is not None
    assert part.slam.points.shape == rec.slam.points.shape
    assert not np.shares_memory(part.imu["Head"].ori_world, rec.imu["Head"].ori_world)


def test_recording_as_float32_halves_arrays_and_keeps_trans():
    from prism_tools.schema import recording_as_float32
    from prism_tools.synthetic import make_recording

    rec = make_recording(50, seed=3)
    small = recording_as_float32(rec)
    assert small.imu["L_Foot"].acc_world_raw.dtype == np.float32
    assert small.insole["R_Foot"].forces.dtype == np.float32
    assert small.smpl_params.trans.dtype == rec.smpl_params.trans.dtype
    np.testing.assert_allclose(small.imu["L_Wrist"].ori_world, rec.imu["L_Wrist"].ori_world,
                               atol=1e-6)  # fmt: skip
    validate(small)
