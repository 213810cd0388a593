import numpy as np
import pytest

from grip.core.rotations import sixd_to_matrix
from grip.kinematics.features import FeatureConfig, input_features, targets
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
