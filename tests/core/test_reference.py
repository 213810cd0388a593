import numpy as np
import pytest

from grip.core.reference import ReferenceClip, ReferenceError, ReferenceSet
from grip.kinematics.reference import oracle_reference_clip
from prism_tools.synthetic import make_recording


@pytest.fixture(scope="module")
def clip() -> ReferenceClip:
    return oracle_reference_clip(make_recording(60, seed=4))


def test_round_trip_keeps_the_arrays_and_derives_the_rest(clip, tmp_path) -> None:
    rs = ReferenceSet([clip], ("L_Foot", "R_Foot", "L_Wrist", "R_Wrist"), True)
    rs.save(tmp_path / "r.npz")
    back = ReferenceSet.load(tmp_path / "r.npz").clip(0)
    np.testing.assert_allclose(back.gt_qpos, clip.gt_qpos)
    np.testing.assert_allclose(back.est_pos, clip.est_pos, atol=1e-6)
    np.testing.assert_allclose(back.gt_pos, clip.gt_pos, atol=1e-9)
    # perfect estimate: the estimated root-relative joints are the ground truth's
    np.testing.assert_allclose(clip.est_pos, clip.gt_pos - clip.gt_pos[:, :1], atol=1e-5)
    assert back.gt_qvel.shape == (60, 75) and back.est_hinge_vel.shape == (60, 69)


def test_bad_clips_and_files_are_refused_with_the_key_named(clip, tmp_path) -> None:
    bad = clip.est_vel.copy()
    bad[7, 0, 0] = np.nan
    with pytest.raises(ReferenceError, match=r"est_vel.*frame 7"):
        ReferenceClip(clip.name, clip.category, clip.fps, clip.body, clip.gt_qpos, clip.est_pos,
                      clip.est_rot6d, bad, clip.sensor)  # fmt: skip
    with pytest.raises(ReferenceError, match="est_pos"):
        ReferenceClip(clip.name, clip.category, clip.fps, clip.body, clip.gt_qpos,
                      clip.est_pos[:-1], clip.est_rot6d, clip.est_vel, clip.sensor)  # fmt: skip
    with pytest.raises(ReferenceError, match="sensor width"):
        ReferenceSet([clip], ("L_Foot",), False)
    np.savez(tmp_path / "x.npz", a=np.zeros(3))
    with pytest.raises(ReferenceError, match=r"x\.npz.*__meta__"):
        ReferenceSet.load(tmp_path / "x.npz")
