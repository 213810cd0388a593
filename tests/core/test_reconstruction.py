"""The shared output type: validation, derived views, file round trip and bad files."""

from __future__ import annotations

import numpy as np
import pytest

from grip.core.fk import rest_pose
from grip.core.reconstruction import Reconstruction, ReconstructionError


def _motion(t: int) -> tuple[np.ndarray, np.ndarray]:
    rot = rest_pose(t, world=False)[0]
    pos = np.random.default_rng(0).normal(size=(t, 24, 3))
    return pos, rot


def _rec(t: int = 5, **kw) -> Reconstruction:
    pos, rot = _motion(t)
    return Reconstruction(name="seg", method="test", fps=100.0, joint_pos=pos, global_rot=rot, **kw)


def test_round_trip_keeps_every_array(tmp_path) -> None:
    ref = np.arange(15.0).reshape(5, 3)
    r = _rec(grf=np.ones((5, 2, 3)), contacts=np.ones((5, 2), bool), torques=np.zeros((5, 69)),
             falls=[[1, 3]], ms_per_frame=2.5, notes={"qp_failures": 0},
             ref_root_pos=ref)  # fmt: skip
    r.save(tmp_path / "r.npz")
    back = Reconstruction.load(tmp_path / "r.npz")
    np.testing.assert_array_equal(back.joint_pos, r.joint_pos)
    np.testing.assert_array_equal(back.grf, r.grf)
    np.testing.assert_array_equal(back.ref_root_pos, ref)
    np.testing.assert_array_equal(back.slice_frames(1, 3).ref_root_pos, ref[1:3])
    _rec().save(tmp_path / "bare.npz")  # a method that follows nothing has none
    assert Reconstruction.load(tmp_path / "bare.npz").ref_root_pos is None
    assert back.contacts.dtype == bool and back.cop is None and back.residual is None
    assert back.falls.tolist() == [[1, 3]] and back.fell
    assert back.ms_per_frame == 2.5 and back.notes == {"qp_failures": 0}
    eye = np.broadcast_to(np.eye(3), (5, 24, 3, 3))
    np.testing.assert_allclose(back.local_rot, eye, atol=1e-12)


def test_slice_shifts_fall_events() -> None:
    r = _rec(10, falls=[[2, 4], [6, 8]])
    s = r.slice_frames(5, 10)
    assert s.n_frames == 5 and s.falls.tolist() == [[1, 3]]


@pytest.mark.parametrize("kw, match", [
    ({"grf": np.zeros((4, 2, 3))}, "grf has shape"),
    ({"falls": [[3, 9]]}, "fall events"),
    ({"ref_root_pos": np.zeros((5, 2))}, "ref_root_pos has shape"),
])  # fmt: skip
def test_bad_arrays_are_named(kw, match) -> None:
    with pytest.raises(ReconstructionError, match=match):
        _rec(**kw)


def test_non_finite_motion_is_refused() -> None:
    pos, rot = _motion(3)
    pos[1, 4, 0] = np.nan
    with pytest.raises(ReconstructionError, match="joint_pos has non-finite values \\(frame 1\\)"):
        Reconstruction("x", "m", 100.0, pos, rot)


def test_corrupt_file_is_named(tmp_path) -> None:
    p = tmp_path / "bad.npz"
    p.write_bytes(b"not a zip")
    with pytest.raises(ReconstructionError, match=r"bad\.npz"):
        Reconstruction.load(p)
