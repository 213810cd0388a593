import numpy as np
import pytest

from grip.core.rotations import sixd_to_matrix
from grip.kinematics.feature_stream import FeatureStream
from grip.kinematics.features import (
    FeatureConfig,
    SensorFrame,
    input_features,
    sensor_frames,
    targets,
)
from prism_tools.synthetic import make_recording


@pytest.fixture(scope="module")
def rec():
    return make_recording(200, seed=5)


def test_feature_sizes_follow_the_configuration(rec):
    assert input_features(rec).shape == (200, 4 * 15 + 10)
    cfg = FeatureConfig(sites=("L_Foot", "R_Foot", "L_Wrist", "R_Wrist", "Head", "Pelvis"),
                        insoles=False)  # fmt: skip
    f = input_features(rec, cfg)
    assert f.shape == (200, 90) and f.dtype == np.float32


def test_orientation_block_is_the_aligned_imu_orientation(rec):
    cfg = FeatureConfig(sites=("L_Wrist",), insoles=False, align_first_frame=False)
    f = input_features(rec, cfg)
    np.testing.assert_allclose(f[:, 6:15].reshape(-1, 3, 3), rec.imu["L_Wrist"].ori_world,
                               atol=1e-6)  # fmt: skip
    aligned = input_features(rec, FeatureConfig(sites=("L_Wrist",), insoles=False))
    np.testing.assert_allclose(aligned[0, 6:15].reshape(3, 3),
                               rec.imu_gt["L_Wrist"].ori_world[0], atol=1e-6)  # fmt: skip


def test_missing_site_and_nan_are_named(rec):
    import dataclasses

    no_head = dataclasses.replace(rec, imu={k: v for k, v in rec.imu.items() if k != "Head"})
    with pytest.raises(KeyError, match="Head"):
        input_features(no_head, FeatureConfig(sites=("Head",)))
    acc = rec.imu["L_Foot"].acc_world_filt.copy()
    acc[17, 1] = np.nan
    bad = dataclasses.replace(rec, imu=rec.imu | {"L_Foot": dataclasses.replace(
        rec.imu["L_Foot"], acc_world_filt=acc)})  # fmt: skip
    with pytest.raises(ValueError, match="frame 17"):
        input_features(bad)
    with pytest.raises(ValueError, match="unknown"):
        FeatureConfig(sites=("Nose",))


def test_targets_are_root_relative_with_global_rotation(rec):
    t = targets(rec)
    np.testing.assert_allclose(t.joint_pos[:, 0], 0.0)
    np.testing.assert_allclose(sixd_to_matrix(t.rot6d), t.global_rot, atol=1e-9)
    # Velocity of the pelvis integrates back to its trajectory (central differences).
    fps = rec.fps
    disp = np.cumsum(t.velocity[:-1, -1], axis=0) / fps
    np.testing.assert_allclose(t.root_pos[-1] - t.root_pos[0], disp[-1], atol=0.05)


@pytest.mark.parametrize("insoles", [True, False])
def test_feature_stream_gives_the_offline_rows_one_frame_later(rec, insoles):
    cfg = FeatureConfig(sites=("L_Foot", "R_Foot", "L_Wrist", "R_Wrist", "Head"),
                        insoles=insoles)  # fmt: skip
    offline = input_features(rec, cfg)
    fs = FeatureStream.for_recording(rec, cfg)
    rows = [fs.push(f) for f in sensor_frames(rec, cfg)]
    assert rows[0] is None  # the first row needs the second frame (central difference)
    rows = [*rows[1:], fs.finish()]
    np.testing.assert_allclose(np.stack(rows), offline, atol=1e-6)


def test_feature_stream_of_one_frame_and_bad_frames(rec):
    one = rec.slice_frames(0, 1)
    fs = FeatureStream.for_recording(one)
    frame = next(sensor_frames(one))
    assert fs.push(frame) is None
    np.testing.assert_allclose(fs.finish(), input_features(one)[0], atol=1e-6)
    fs = FeatureStream.for_recording(rec)
    with pytest.raises(ValueError, match=r"frame 0.*insole"):
        fs.push(SensorFrame(frame.acc, frame.ori, None))
    with pytest.raises(ValueError, match=r"acc \(4, 3\)"):
        fs.push(SensorFrame(frame.acc[:3], frame.ori, frame.insole))
    acc = frame.acc.copy()
    acc[1, 2] = np.nan
    fs.push(frame)
    with pytest.raises(ValueError, match=r"non-finite.*frame 1"):
        fs.push(SensorFrame(acc, frame.ori, frame.insole))
