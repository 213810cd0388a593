"""grip.export: BVH round trip, GLB meshes, MP4 (no-GL path), PNG summary, ground truth."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

from grip.core import skeleton as sk
from grip.core.body import CANONICAL_TO_WORLD, build_body
from grip.core.fk import forward_kinematics, rest_pose
from grip.core.reconstruction import Reconstruction
from grip.core.reference import pose_vector
from grip.export.bvh import hierarchy_order, motion_channels, write_bvh
from grip.export.common import (
    Y_UP_FROM_WORLD,
    ExportError,
    check_ground_truth,
    fk_mismatch_m,
    posed_body,
)
from grip.export.glb import body_mesh, write_pose_glb, write_strobe_glb
from grip.export.summary import per_joint_errors, summary_stats, write_summary_png
from grip.kinematics.features import ground_truth
from grip.motion.bvh import load_bvh
from prism_tools.synthetic import make_recording

T = 160
SHIFT_M = np.array([0.05, 0.0, 0.0])
GRF_BIAS_N = 10.0
FLIPPED = np.array([3, 50, 51, 140])  # frames whose left contact state is flipped
FALL = (115, 125)


@pytest.fixture(scope="module")
def rec():
    return make_recording(T, seed=3)


@pytest.fixture(scope="module")
def gt(rec):
    return ground_truth(rec)


@pytest.fixture(scope="module")
def recon(gt):
    """The ground truth shifted 5 cm along x, GRF = insole + 10 N, 4 left contacts flipped."""
    grf = np.zeros((T, 2, 3))
    grf[:, :, 2] = gt.insole_force_n + GRF_BIAS_N
    contacts = gt.insole_contacts.copy()
    contacts[FLIPPED, 0] = ~contacts[FLIPPED, 0]
    return Reconstruction(name="seg", method="test", fps=gt.fps,
                          joint_pos=gt.joint_pos + SHIFT_M, global_rot=gt.global_rot, grf=grf,
                          contacts=contacts, falls=np.array([FALL]))  # fmt: skip


def _rest_recon(body, root_xy=(0.1, 0.2), n=3) -> Reconstruction:
    local, root = rest_pose(n)
    root[:] = [*root_xy, body.pelvis_height]
    rot, pos = forward_kinematics(local, root, body.offsets)
    return Reconstruction(name="rest", method="test", fps=50.0, joint_pos=pos, global_rot=rot)


# ----------------------------------------------------------------------------------------- BVH
def test_bvh_zero_channels_are_the_rest_pose_standing_y_up(gt, tmp_path) -> None:
    body = build_body(gt.body)
    r = _rest_recon(body)
    values = motion_channels(r, "cm")
    np.testing.assert_allclose(values[:, 3:], 0.0, atol=1e-9)  # every rotation channel 0
    # world (0.1, 0.2, h) -> y up (-x, z, y), in cm
    np.testing.assert_allclose(values[0, :3], [-10.0, 100 * body.pelvis_height, 20.0], atol=1e-9)
    text = write_bvh(r, tmp_path / "rest.bvh", gt.body).read_text()
    hip = text.split("JOINT L_Hip", 1)[1].split("OFFSET", 1)[1].split("\n", 1)[0]
    np.testing.assert_allclose(np.array(hip.split(), dtype=float), 100 * body.offsets[1],
                               atol=1e-6)  # fmt: skip
    assert "Frames: 3\nFrame Time: 0.02000000\n" in text


@pytest.mark.parametrize("unit", ["cm", "m"])
def test_bvh_round_trip_reproduces_the_body_fk(recon, gt, tmp_path, unit) -> None:
    path = write_bvh(recon, tmp_path / f"seg_{unit}.bvh", gt.body, unit=unit)
    m = load_bvh(path)
    assert m.unit_m == {"cm": 0.01, "m": 1.0}[unit]
    assert m.global_pos.shape[0] == T
    np.testing.assert_allclose(np.diff(m.times_s), 1.0 / recon.fps)
    idx = [m.joint_names.index(n) for n in sk.JOINT_NAMES]
    assert sorted(set(m.joint_names) - set(sk.JOINT_NAMES)) == sorted(
        f"{sk.JOINT_NAMES[j]}_end" for j in (10, 11, 15, 22, 23)
    )
    world = m.global_pos[:, idx] @ Y_UP_FROM_WORLD  # row vectors: v_world = Y^T v_yup
    _, fk = posed_body(recon, gt.body)
    err = np.linalg.norm(world - fk, axis=-1).max()
    assert err < 1e-3, f"BVH joints deviate from FK by {err * 1000:.3f} mm"
    # on the subject's own body the export reproduces the reconstruction itself
    assert fk_mismatch_m(recon, gt.body) < 1e-9
    np.testing.assert_allclose(world, recon.joint_pos, atol=1e-3)


def test_bvh_channels_are_the_humanoid_hinge_angles(recon) -> None:
    values = motion_channels(recon, "m")
    hinges = pose_vector(recon.local_rot, recon.root_pos)[:, 7:].reshape(T, 23, 3)
    order = hierarchy_order()
    assert order[0] == 0 and sorted(order) == list(range(sk.N_JOINTS))
    for k, j in enumerate(order[1:]):
        got = np.deg2rad(values[:, 6 + 3 * k : 9 + 3 * k])
        wrapped = np.angle(np.exp(1j * (got - hinges[:, j - 1])))  # equal modulo 2 pi
        np.testing.assert_allclose(wrapped, 0.0, atol=1e-9, err_msg=sk.JOINT_NAMES[j])
    assert np.abs(np.diff(values[:, 3:], axis=0)).max() < 180.0, "angles are unwrapped"


def test_bvh_bad_unit_and_unwritable_path(recon, tmp_path) -> None:
    with pytest.raises(ValueError, match="unit"):
        write_bvh(recon, tmp_path / "x.bvh", unit="mm")  # type: ignore[arg-type]
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(ExportError, match=r"file/x\.bvh"):
        write_bvh(recon, blocker / "x.bvh")


# ----------------------------------------------------------------------------------------- GLB
def test_pose_glb_of_the_rest_pose_stands_on_the_floor(gt, tmp_path) -> None:
    body = build_body(gt.body)
    r = _rest_recon(body, root_xy=(0.0, 0.0))
    path = write_pose_glb(r, tmp_path / "rest.glb", 1, gt.body)
    scene = trimesh.load(path, force="scene")
    assert list(scene.graph.nodes_geometry) == ["body"]
    lo, hi = scene.bounds
    assert abs(lo[1]) < 0.005, f"soles at y = {lo[1]:.4f} m, expected the floor"
    assert 0.95 * gt.body.height_m < hi[1] < 1.05 * gt.body.height_m
    # T-pose facing +z: the arm span lies along x and is symmetric
    assert hi[0] - lo[0] > 0.9 * gt.body.height_m and abs(hi[0] + lo[0]) < 0.01
    with pytest.raises(ValueError, match="outside"):
        write_pose_glb(r, tmp_path / "bad.glb", 3, gt.body)


def test_strobe_glb_has_one_node_per_pose_along_the_trajectory(recon, gt, tmp_path) -> None:
    path = write_strobe_glb(recon, tmp_path / "strobe.glb", gt.body, every=40)
    scene = trimesh.load(path, force="scene")
    frames = [0, 40, 80, 120, T - 1]
    names = {f"frame_{t:06d}" for t in frames}
    assert set(scene.graph.nodes_geometry) == names | {"floor"}
    mesh = body_mesh(gt.body)
    rot, pos = posed_body(recon, gt.body)
    root_yup = recon.root_pos @ Y_UP_FROM_WORLD.T
    for t in frames:
        tf, geom = scene.graph[f"frame_{t:06d}"]
        np.testing.assert_allclose(tf, np.eye(4))
        g = scene.geometry[geom]
        expected = mesh.pose(rot[t], pos[t]) @ Y_UP_FROM_WORLD.T
        np.testing.assert_allclose(g.vertices, expected, atol=1e-5)  # float32 in the file
        lo, hi = g.bounds
        assert np.all(lo <= root_yup[t]) and np.all(root_yup[t] <= hi), "pelvis inside its pose"
        red = (g.visual.vertex_colors[0, :3] == [220, 30, 30]).all()
        assert red == (FALL[0] <= t <= FALL[1]), f"frame {t}: fall colouring"
    _, floor_geom = scene.graph["floor"]
    flo, fhi = scene.geometry[floor_geom].bounds
    assert abs(fhi[1]) < 1e-6, "floor top at y = 0"
    assert np.all(flo[[0, 2]] < root_yup[:, [0, 2]].min(axis=0))
    assert np.all(fhi[[0, 2]] > root_yup[:, [0, 2]].max(axis=0))


# ----------------------------------------------------------------------------------------- MP4
def test_video_frame_sampling_and_camera_track() -> None:
    from grip.export.video import camera_track, video_frames

    idx = video_frames(101, 100.0, 30.0)  # 1 s at 100 Hz -> 31 frames at 30 fps
    assert len(idx) == 31 and idx[0] == 0 and idx[-1] == 100
    np.testing.assert_array_equal(idx[:4], [0, 3, 7, 10])
    root = np.zeros((50, 3))
    root[25:, 0] = 1.0  # a 1 m step
    smooth = camera_track(root, 100.0, 0.2)
    assert 0.0 < smooth[24, 0] < 1.0 and smooth[0, 0] == 0.0 and smooth[-1, 0] == 1.0
    np.testing.assert_array_equal(camera_track(root, 100.0, 0.0), root)


def test_video_without_gl_raises_a_clear_error(recon, gt, tmp_path, monkeypatch) -> None:
    import mujoco

    from grip.export.video import RenderBackendError, VideoConfig, write_video

    def no_gl(*args, **kwargs):
        raise mujoco.FatalError("an OpenGL platform library has not been loaded")

    monkeypatch.setattr(mujoco, "Renderer", no_gl)
    out = tmp_path / "v.mp4"
    with pytest.raises(RenderBackendError) as info:
        write_video(recon, out, gt.body, gt=gt, cfg=VideoConfig(width=64, height=48))
    msg = str(info.value)
    assert "MUJOCO_GL=egl" in msg and "osmesa" in msg and "OpenGL platform library" in msg
    assert not out.exists() and not list(tmp_path.iterdir())
    with pytest.raises(ValueError, match="even"):
        VideoConfig(width=65)


# ------------------------------------------------------------------------------------- summary
def test_summary_numbers_follow_the_metric_definitions(recon, gt, tmp_path) -> None:
    stats = write_summary_png(recon, tmp_path / "s.png", gt=gt)
    assert (tmp_path / "s.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (tmp_path / "s.png").stat().st_size > 50_000
    np.testing.assert_allclose(stats["MPJPE_mm"], 50.0, atol=1e-6)  # 5 cm shift everywhere
    np.testing.assert_allclose(stats["PEL_MPJPE_mm"], 0.0, atol=1e-6)
    np.testing.assert_allclose(stats["vGRF_N"], GRF_BIAS_N, atol=1e-9)
    np.testing.assert_allclose(stats["contact_agreement"], 1 - len(FLIPPED) / (2 * T))
    assert stats["falls"] == 1 and stats["frames"] == T
    world, pel = per_joint_errors(recon, gt)
    np.testing.assert_allclose(world, 50.0, atol=1e-6)
    np.testing.assert_allclose(pel, 0.0, atol=1e-6)


def test_summary_without_ground_truth_or_forces(gt, tmp_path) -> None:
    bare = Reconstruction(name="k", method="kinematics", fps=gt.fps, joint_pos=gt.joint_pos,
                          global_rot=gt.global_rot)  # fmt: skip
    stats = write_summary_png(bare, tmp_path / "k.png")
    assert set(stats) == {"frames", "duration_s", "falls", "ms_per_frame"}
    assert (tmp_path / "k.png").stat().st_size > 20_000
    with_gt = summary_stats(bare, gt)
    assert "vGRF_N" not in with_gt and "contact_agreement" not in with_gt
    assert with_gt["MPJPE_mm"] < 1e-6


# -------------------------------------------------------------------------------- ground truth
def test_ground_truth_from_a_recording(rec, gt, recon, tmp_path) -> None:
    sp = rec.smpl_params
    np.testing.assert_allclose(gt.root_pos, sp.trans + sp.root_offset, atol=1e-9)
    weight_n = rec.subject.weight_kg * 9.81
    np.testing.assert_allclose(gt.insole_force_n[:, 1], rec.insole["R_Foot"].force[:, 0] * weight_n)
    np.testing.assert_array_equal(gt.insole_contacts[:, 0],
                                  rec.insole["L_Foot"].contacts.any(axis=1))  # fmt: skip
    assert gt.body.height_m == rec.subject.height_m
    check_ground_truth(recon, gt)
    short = recon.slice_frames(0, 100)
    with pytest.raises(ExportError, match=f"{T} frames.*100"):
        check_ground_truth(short, gt)
    with pytest.raises(ExportError, match="frames"):
        write_summary_png(short, tmp_path / "x.png", gt=gt)
    assert not (tmp_path / "x.png").exists()
    with pytest.raises(ExportError, match="Hz"):
        check_ground_truth(dataclasses.replace(recon, fps=50.0), gt)


def test_rest_root_rotation_maps_to_identity_in_the_export_frame() -> None:
    np.testing.assert_allclose(Y_UP_FROM_WORLD @ CANONICAL_TO_WORLD, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(Y_UP_FROM_WORLD), 1.0)
