"""grip.export.amass: the AMASS-style npz round trip (our forward kinematics, the project's AMASS
reader), its conventions on hand-built poses, bad input, and ``grip export --formats amass``."""

from __future__ import annotations

import numpy as np
import pytest

from grip.assets import SAMPLE_RECORDING
from grip.cli.main import main
from grip.core import skeleton as sk
from grip.core.body import CANONICAL_TO_WORLD, BodyParams, build_body
from grip.core.fk import forward_kinematics, rest_pose
from grip.core.reconstruction import Reconstruction
from grip.core.rotations import axis_angle_to_matrix
from grip.export.amass import N_BETAS, SMPL_NEUTRAL_PELVIS_M, amass_arrays, write_amass
from grip.export.common import ExportError
from grip.kinematics.features import ground_truth
from grip.motion.amass import SMPL_PELVIS_M, SMPL_TO_ZUP, load_amass_npz
from grip.motion.catalog import load_clip
from prism_tools.io import load_recording

TALL = BodyParams(height_m=1.86, mass_kg=92.0, leg_length_m=0.95)


def _recon(local_rot: np.ndarray, root_pos: np.ndarray, body: BodyParams,
           fps: float = 60.0) -> Reconstruction:  # fmt: skip
    rot, pos = forward_kinematics(local_rot, root_pos, build_body(body).offsets)
    return Reconstruction(name="r", method="test", fps=fps, joint_pos=pos, global_rot=rot)


def _random_motion(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations up to 3 rad (past 90 deg, near the pi wrap) and a wandering root."""
    rng = np.random.default_rng(seed)
    aa = rng.normal(size=(n, sk.N_JOINTS, 3))
    angle = rng.uniform(0.0, 3.1, size=(n, sk.N_JOINTS, 1))
    aa *= angle / np.linalg.norm(aa, axis=-1, keepdims=True)
    root = np.cumsum(rng.normal(scale=0.02, size=(n, 3)), axis=0) + np.array([0.3, -1.2, 0.9])
    return axis_angle_to_matrix(aa), root


def _fk_of_file(path) -> tuple[np.ndarray, np.ndarray]:
    """Forward kinematics of an AMASS-style file on the GRIP body it names."""
    with np.load(path, allow_pickle=False) as d:
        poses, trans = d["poses"], d["trans"]
        body = build_body(BodyParams.from_array(d["grip_body_params"]))
        pelvis = trans + d["grip_trans_to_pelvis_m"]
    local = axis_angle_to_matrix(poses.reshape(len(poses), sk.N_JOINTS, 3))
    return forward_kinematics(local, pelvis, body.offsets)


@pytest.fixture(scope="module")
def sample_truth():
    """The sample recording's ground truth as a reconstruction (real motion, its subject)."""
    gt = ground_truth(load_recording(SAMPLE_RECORDING))
    recon = Reconstruction(name="sample", method="truth", fps=gt.fps, joint_pos=gt.joint_pos,
                           global_rot=gt.global_rot)  # fmt: skip
    return recon, gt.body


def test_the_file_holds_amass_keys_shapes_and_the_note(tmp_path) -> None:
    recon = _recon(*_random_motion(7, seed=0), TALL, fps=120.0)
    path = write_amass(recon, tmp_path / "m_amass.npz", TALL)
    with np.load(path, allow_pickle=False) as d:  # no object arrays: readable without pickle
        assert d["poses"].shape == (7, 72) and d["trans"].shape == (7, 3)
        assert d["poses"].dtype == np.float64 and d["trans"].dtype == np.float64
        assert float(d["mocap_framerate"]) == 120.0 and d["mocap_framerate"].shape == ()
        np.testing.assert_array_equal(d["betas"], np.zeros(N_BETAS))
        assert str(d["gender"]) == "neutral"
        note = str(d["note"])
        assert "not SMPL" in note and "SMPL topology" in note and "differ" in note
        assert BodyParams.from_array(d["grip_body_params"]) == TALL


@pytest.mark.parametrize("which", ["random", "sample"])
def test_forward_kinematics_of_the_file_gives_back_the_joints(which, sample_truth,
                                                              tmp_path) -> None:  # fmt: skip
    """(a): poses/trans posed on our body reproduce the reconstruction's joints (< 1e-5 m)."""
    recon, body = (_recon(*_random_motion(50, seed=1), TALL), TALL) if which == "random" \
        else sample_truth  # fmt: skip
    rot, pos = _fk_of_file(write_amass(recon, tmp_path / "a.npz", body))
    assert np.abs(pos - recon.joint_pos).max() < 1e-5
    np.testing.assert_allclose(rot, recon.global_rot, atol=1e-9)


def test_the_project_amass_reader_reads_it(sample_truth, tmp_path) -> None:
    """(b): the clip loader detects the file as AMASS and reads the same motion: the same
    global rotations, the pelvis where the reconstruction has it, the frame times. Its other
    joints hang off its approximate SMPL skeleton, a few cm from our body's."""
    np.testing.assert_array_equal(SMPL_NEUTRAL_PELVIS_M, SMPL_PELVIS_M)  # one J_0 for both
    recon, body = sample_truth
    path = write_amass(recon, tmp_path / "walk_amass.npz", body)
    for clip in (load_clip(path), load_amass_npz(path)):
        assert clip.fmt == "amass" and clip.rig == "smpl" and clip.up_axis == 2
        assert clip.global_rot.shape == (recon.n_frames, 24, 3, 3)
        np.testing.assert_allclose(clip.global_rot, recon.global_rot, atol=1e-9)
        np.testing.assert_allclose(clip.global_pos[:, 0], recon.root_pos, atol=1e-9)
        np.testing.assert_allclose(clip.times_s, np.arange(recon.n_frames) / recon.fps)
        gap = np.linalg.norm(clip.global_pos - recon.joint_pos, axis=-1).max()
        assert 0.005 < gap < 0.15  # another skeleton, the same pose


def test_standing_upright_is_the_rotation_between_the_canonical_frame_and_the_world(
        tmp_path) -> None:  # fmt: skip
    """Hand-computed: the rest pose upright facing +y has the root rotation CANONICAL_TO_WORLD,
    a half turn about (0, 1, 1) / sqrt 2, every other joint zero; trans is the pelvis less
    SMPL's rest pelvis. AMASS's own upright pose (root Rx(90 deg), facing -y) stands in the
    same z-up world: the head above the pelvis."""
    body = build_body(TALL)
    local, root = rest_pose(3)
    root[:] = [0.4, 0.5, body.pelvis_height]
    recon = _recon(local, root, TALL)
    arr = amass_arrays(recon, TALL)
    aa = arr["poses"].reshape(3, 24, 3)
    np.testing.assert_allclose(aa[:, 1:], 0.0, atol=1e-12)
    axis = np.array([0.0, 1.0, 1.0]) / np.sqrt(2.0)
    np.testing.assert_allclose(np.abs(aa[:, 0] @ axis), np.pi, atol=1e-9)  # (either sign)
    for m in axis_angle_to_matrix(aa[:, 0]):
        np.testing.assert_allclose(m, CANONICAL_TO_WORLD, atol=1e-9)
    np.testing.assert_allclose(arr["trans"], root - [0.0, -0.22, 0.03], atol=1e-12)
    # an AMASS clip standing in its own convention, read by the project's reader
    amass_up = np.zeros((2, 72))
    amass_up[:, :3] = [np.pi / 2, 0.0, 0.0]
    np.testing.assert_allclose(axis_angle_to_matrix(amass_up[0, :3]), SMPL_TO_ZUP, atol=1e-12)
    path = tmp_path / "upright.npz"
    np.savez(path, poses=amass_up, trans=np.zeros((2, 3)), mocap_framerate=30.0)
    clip = load_amass_npz(path)
    head, pelvis = clip.global_pos[0, sk.JOINT_INDEX["Head"]], clip.global_pos[0, 0]
    assert head[2] - pelvis[2] > 0.4 and abs(head[0] - pelvis[0]) < 0.05
    # ... and our body with that root rotation stands in the world just as upright
    local[:, 0] = SMPL_TO_ZUP
    _, pos = forward_kinematics(local, root, body.offsets)
    assert pos[0, sk.JOINT_INDEX["Head"], 2] - pos[0, 0, 2] > 0.4


def test_bad_rotations_and_unwritable_paths_are_refused(tmp_path) -> None:
    recon = _recon(*_random_motion(4, seed=2), TALL)
    recon.global_rot[2, 5] *= 1.1  # frame 2, joint 5 (R_Knee): no longer a rotation
    with pytest.raises(ExportError, match=r"bad_amass\.npz.*R_Knee at frame 2.*not a rotation"):
        write_amass(recon, tmp_path / "bad_amass.npz")
    assert not (tmp_path / "bad_amass.npz").exists()
    mirrored = _recon(*_random_motion(4, seed=3), TALL)
    mirrored.global_rot[0, 0] = -mirrored.global_rot[0, 0]  # det -1: a reflection
    with pytest.raises(ExportError, match="Pelvis at frame 0"):
        write_amass(mirrored, tmp_path / "m.npz")
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(ExportError, match="cannot write"):
        write_amass(_recon(*_random_motion(4, seed=4), TALL), blocker / "x_amass.npz")


def test_grip_export_writes_stem_amass_npz(sample_truth, tmp_path, capsys) -> None:
    recon, body = sample_truth
    src = tmp_path / "seq_grip.npz"
    recon.save(src)
    out = tmp_path / "out"
    args = ["export", str(src), "--out", str(out), "--formats", "amass",
            "--body-height", str(body.height_m), "--body-mass", str(body.mass_kg)]  # fmt: skip
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert sorted(p.name for p in out.iterdir()) == ["seq_grip_amass.npz"]
    assert "seq_grip_amass.npz" in printed and "not SMPL" in printed
    _, pos = _fk_of_file(out / "seq_grip_amass.npz")
    assert np.abs(pos - recon.joint_pos).max() < 1e-5  # the subject's body from the options
    # a plain 'grip export' writes the visual formats only
    from grip.cli.export import DEFAULT_FORMATS, FORMATS

    assert "amass" in FORMATS and "amass" not in DEFAULT_FORMATS
    import grip.export

    assert FORMATS == grip.export.FORMATS  # (the CLI spells the library's list)
