"""Retargeting: exact round trips on our own skeleton, rig invariance, joint maps, real clips."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from grip.core import skeleton as sk
from grip.core.body import CANONICAL_TO_WORLD, BodyParams, build_body
from grip.core.fk import forward_kinematics, sole_points
from grip.core.rotations import (
    axis_angle_to_matrix,
    geodesic_angle,
    matrix_to_axis_angle,
    matrix_to_euler_xyz,
    matrix_to_quat,
    quat_to_matrix,
    rot_z,
    rotation_between,
)
from grip.motion.joint_maps import (
    RIG_JOINT_MAPS,
    auto_joint_map,
    check_joint_map,
    load_joint_map,
    resolve_joint_map,
)
from grip.motion.motion import Motion
from grip.motion.quality import foot_metrics
from grip.motion.retarget import RetargetConfig, retarget
from grip.motion.retarget_bones import world_from_source
from grip.motion.retarget_feet import fit_floor_tilt, leg_ik
from grip.motion.source import MotionImportError, SourceMotion

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "motions"

#: Pure orientation transfer: no foot calibration, levelling, smoothing, IK or lift.
EXACT = RetargetConfig(flatten_feet=False, level_floor=False, foot_ik=False,
                       fix_penetration=False, smooth_hz=None)  # fmt: skip
BODY = BodyParams(height_m=1.75, mass_kg=72.0)


# ------------------------------------------------------------------------------------ helpers
def _random_local(seed: int, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Smooth random local rotations ``(T, 24, 3, 3)`` and root ``(T, 3)`` at times ``t`` (s):
    sums of sinusoids on every joint, a slowly turning upright root walking forward."""
    rng = np.random.default_rng(seed)
    freq = rng.uniform(0.3, 1.5, size=(3, sk.N_JOINTS, 3))
    phase = rng.uniform(0, 2 * np.pi, size=(3, sk.N_JOINTS, 3))
    amp = rng.uniform(0.05, 0.35, size=(3, sk.N_JOINTS, 3))
    arg = 2 * np.pi * freq[:, None] * t[None, :, None, None] + phase[:, None]
    local = axis_angle_to_matrix(np.sum(amp[:, None] * np.sin(arg), axis=0))
    heading = rot_z(rng.uniform(-np.pi, np.pi) + 0.3 * np.sin(t))
    local[:, 0] = heading @ CANONICAL_TO_WORLD @ local[:, 0]
    root = np.stack([0.8 * t, 0.1 * np.sin(t), 0.9 + 0.02 * np.sin(3 * t)], axis=-1)
    return local, root


def _random_motion(seed: int, n: int = 120, fps: float = 100.0) -> Motion:
    """A smooth random motion on our body."""
    local, root = _random_local(seed, np.arange(n) / fps)
    return Motion(fps=fps, root_pos=root, local_quat=matrix_to_quat(local), body=BODY,
                  name="synthetic/random", category="test")  # fmt: skip


def _source_from_motion(
    motion: Motion,
    world_to_src: np.ndarray | None = None,
    up_axis: int = 2,
    frame_offsets: np.ndarray | None = None,
) -> SourceMotion:
    """The SourceMotion our own skeleton would produce for ``motion``.

    Args:
        motion: The motion (z-up world).
        world_to_src: Rotation from our world to the source world (default identity).
        up_axis: The source's up axis.
        frame_offsets: ``(24, 3, 3)`` constant rotation of each joint frame (a Bandai-like rig:
            same motion in the world, joint frames rotated, rest pose no longer a T-pose).
    """
    body = build_body(motion.body)
    g, p = motion.fk(body)
    a = np.eye(3) if world_to_src is None else world_to_src
    g = a @ g
    p = p @ a.T
    offsets = body.offsets.copy()
    offsets[0] = 0.0
    rest_is_tpose = True
    if frame_offsets is not None:
        g = g @ frame_offsets
        # Zero pose of the rotated rig: identity globals, offsets in the rotated parent frames.
        offsets[1:] = np.einsum("jba,jb->ja", frame_offsets[sk.PARENTS[1:]], offsets[1:])
        rest_is_tpose = False
    rest_pos = np.zeros_like(offsets)
    for j in range(1, sk.N_JOINTS):
        rest_pos[j] = rest_pos[sk.PARENTS[j]] + offsets[j]
    # With a z-up source the zero pose lies along y (like SMPL/AMASS); with y-up it stands.
    return SourceMotion(
        name=motion.name, path="<synthetic>", fmt="amass", rig="smpl",
        joint_names=sk.JOINT_NAMES, parents=sk.PARENTS.copy(),
        times_s=np.arange(motion.n_frames) / motion.fps, global_rot=g, global_pos=p,
        rest_rot=np.broadcast_to(np.eye(3), (sk.N_JOINTS, 3, 3)).copy(), rest_pos=rest_pos,
        up_axis=up_axis, unit_m=1.0, rest_is_tpose=rest_is_tpose, category=motion.category,
    )  # fmt: skip


def _bone_dirs(motion: Motion) -> np.ndarray:
    """``(T, 23, 3)`` world directions of all bones (parent joint -> joint)."""
    _, p = motion.fk()
    d = p[:, 1:] - p[:, sk.PARENTS[1:]]
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


# ------------------------------------------------------------------------------------ round trips
@pytest.mark.parametrize("align", [True, False])
def test_round_trip_own_skeleton_is_exact(align: bool) -> None:
    motion = _random_motion(0)
    cfg = dataclasses.replace(EXACT, align_bones=align)
    out = retarget(_source_from_motion(motion), body=BODY, cfg=cfg)
    assert out.fps == 100.0 and out.n_frames == motion.n_frames
    angle = geodesic_angle(motion.local_rot(), out.local_rot())
    np.testing.assert_allclose(angle, 0.0, atol=1e-6)
    offset = out.root_pos - motion.root_pos
    np.testing.assert_allclose(offset[:, :2], 0.0, atol=1e-9)
    np.testing.assert_allclose(offset[:, 2], offset[0, 2], atol=1e-9)
    assert out.meta["scale"] == pytest.approx(1.0)
    assert out.meta["reference_frame"] == "rest"


@pytest.mark.parametrize("align", [True, False])
def test_round_trip_y_up_source_gives_the_same_motion(align: bool) -> None:
    motion = _random_motion(1)
    cfg = dataclasses.replace(EXACT, align_bones=align)
    z_up = retarget(_source_from_motion(motion), body=BODY, cfg=cfg)
    y_up_src = _source_from_motion(motion, world_to_src=CANONICAL_TO_WORLD.T, up_axis=1)
    np.testing.assert_allclose(world_from_source(1) @ CANONICAL_TO_WORLD.T, np.eye(3), atol=1e-12)
    y_up = retarget(y_up_src, body=BODY, cfg=cfg)
    np.testing.assert_allclose(geodesic_angle(z_up.local_rot(), y_up.local_rot()), 0, atol=1e-6)
    np.testing.assert_allclose(y_up.root_pos, z_up.root_pos, atol=1e-9)


def test_amass_poses_apply_joint_by_joint(tmp_path: Path) -> None:
    amass = pytest.importorskip("grip.motion.amass")
    motion = _random_motion(11, n=50)
    path = tmp_path / "clip.npz"
    poses = matrix_to_axis_angle(motion.local_rot()).reshape(50, 72)
    trans = motion.root_pos - amass.SMPL_PELVIS_M
    np.savez(path, poses=poses, trans=trans, mocap_framerate=np.array(100.0))
    src = amass.load_amass_npz(path)
    out = retarget(src, body=BODY, cfg=EXACT)
    assert out.meta["aligned_bones"] is False
    np.testing.assert_allclose(geodesic_angle(motion.local_rot(), out.local_rot()), 0, atol=1e-6)
    aligned = retarget(src, body=BODY, cfg=dataclasses.replace(EXACT, align_bones=True))
    # Aligning bone directions to the approximate SMPL skeleton would change the poses.
    assert np.degrees(geodesic_angle(motion.local_rot(), aligned.local_rot())).max() > 1.0


def test_round_trip_resamples_60_hz_to_100_hz() -> None:
    motion = _random_motion(2, n=61, fps=60.0)
    out = retarget(_source_from_motion(motion), body=BODY, cfg=EXACT)
    assert out.fps == 100.0 and out.n_frames == 101  # 1 s at 100 Hz, both ends included
    np.testing.assert_allclose(geodesic_angle(motion.local_rot()[::3], out.local_rot()[::5]), 0,
                               atol=1e-6)  # fmt: skip


def test_variable_frame_times_are_resampled_to_100_hz() -> None:
    rng = np.random.default_rng(3)
    times = np.concatenate([[0.0], np.cumsum(rng.uniform(1 / 60, 1 / 20, size=40))])
    local, root = _random_local(9, times)
    irregular = Motion(fps=100.0, root_pos=root, local_quat=matrix_to_quat(local), body=BODY)
    src = dataclasses.replace(_source_from_motion(irregular), times_s=times)
    out = retarget(src, body=BODY, cfg=EXACT)
    assert out.n_frames == int(np.floor(times[-1] * 100 + 1e-6)) + 1
    truth, _ = _random_local(9, np.arange(out.n_frames) / 100.0)
    err = np.degrees(geodesic_angle(truth, out.local_rot()))
    assert err.max() < 2.0  # slerp between samples up to 50 ms apart


def test_contact_steps_keep_the_upper_body_and_put_feet_on_the_floor() -> None:
    motion = _random_motion(3)
    cfg = dataclasses.replace(RetargetConfig(), smooth_hz=None)  # defaults but the low-pass
    out = retarget(_source_from_motion(motion), body=BODY, cfg=cfg)
    upper = [j for j in range(sk.N_JOINTS) if j not in (1, 2, 4, 5, 7, 8, 10, 11)]
    angle = geodesic_angle(motion.local_rot()[:, upper], out.local_rot()[:, upper])
    np.testing.assert_allclose(angle, 0.0, atol=1e-6)
    body = build_body(BODY)
    g, p = out.fk(body)
    assert sole_points(g, p, body)[..., 2].min() >= -1e-9  # no penetration after the lift


def test_non_tpose_rig_gives_the_same_bone_directions() -> None:
    motion = _random_motion(4)
    # Frame 0: neutral standing (arms hanging) so the neutral-frame search has a clear winner.
    local = motion.local_rot()
    body = build_body(BODY)
    local[0, 1:] = np.eye(3)
    for sh, el in ((16, 18), (17, 19)):
        local[0, sh] = rotation_between(body.offsets[el], np.array([0.0, -1.0, 0.0]))
    neutral = dataclasses.replace(motion, local_quat=matrix_to_quat(local))
    rng = np.random.default_rng(7)
    frames = axis_angle_to_matrix(rng.normal(size=(sk.N_JOINTS, 3)) * 1.5)
    plain = retarget(_source_from_motion(neutral), body=BODY, cfg=EXACT)
    rotated = retarget(_source_from_motion(neutral, frame_offsets=frames), body=BODY, cfg=EXACT)
    assert rotated.meta["reference_frame"] == 0
    np.testing.assert_allclose(_bone_dirs(rotated), _bone_dirs(plain), atol=1e-3)
    # Twist comes from the neutral frame: close to the T-pose rig's, not only the directions.
    g_plain, _ = plain.fk(body)
    g_rot, _ = rotated.fk(body)
    assert np.degrees(geodesic_angle(g_plain, g_rot)).max() < 3.0


def test_rotated_world_keeps_heading_and_only_moves_the_up_axis() -> None:
    assert np.allclose(world_from_source(2), np.eye(3))
    w = world_from_source(1)
    np.testing.assert_allclose(w @ np.array([0.0, 1.0, 0.0]), [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(w @ np.array([0.0, 0.0, 1.0]), [0, 1, 0], atol=1e-12)
    assert np.isclose(np.linalg.det(world_from_source(0)), 1.0)


# ------------------------------------------------------------------------------------ pieces
def test_leg_ik_moves_ankles_vertically_and_keeps_foot_orientation() -> None:
    motion = _random_motion(5, n=20)
    body = build_body(BODY)
    local = motion.local_rot()
    lift = np.stack([np.full(20, 0.03), np.full(20, -0.01)], axis=-1)
    # Bend the knees so that both directions are reachable.
    local[:, 4] = local[:, 5] = axis_angle_to_matrix(np.array([0.6, 0.0, 0.0]))
    g0, p0 = forward_kinematics(local, motion.root_pos, body.offsets)
    g1, p1 = forward_kinematics(leg_ik(local, motion.root_pos, body, lift), motion.root_pos,
                                body.offsets)  # fmt: skip
    expected = np.zeros((20, 2, 3))
    expected[..., 2] = lift
    np.testing.assert_allclose(p1[:, [7, 8]] - p0[:, [7, 8]], expected, atol=1e-9)
    np.testing.assert_allclose(geodesic_angle(g0[:, 7:9], g1[:, 7:9]), 0, atol=1e-6)
    np.testing.assert_allclose(p1[:, [1, 2]], p0[:, [1, 2]], atol=1e-12)


def test_floor_tilt_fit_levels_a_sloped_walk_and_rejects_stairs() -> None:
    rng = np.random.default_rng(0)
    xy = np.stack([np.linspace(0, 4, 200), rng.normal(0, 0.1, 200)], axis=-1)
    z = 0.02 * xy[:, 0] + rng.normal(0, 0.003, 200)  # 1.15 deg slope
    level = fit_floor_tilt(np.c_[xy, z])
    assert level is not None
    pts = np.c_[xy, z] @ level[:3, :3].T + level[:3, 3]
    assert np.std(pts[:, 2]) < 0.005
    steps = np.c_[xy, 0.2 * np.floor(xy[:, 0])]  # 20 cm steps: far too steep
    assert fit_floor_tilt(steps) is None
    assert fit_floor_tilt(np.c_[xy[:, :2] * 0.1, z]) is None  # too short to tell


# ------------------------------------------------------------------------------------ joint maps
def test_missing_required_joints_name_file_joints_and_available_names() -> None:
    names = ("Hips", "Spine", "Head", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftArm")
    with pytest.raises(MotionImportError) as err:
        resolve_joint_map("unknown", names, where="odd.bvh")
    msg = str(err.value)
    assert msg.startswith("odd.bvh")
    for needed in ("R_Hip", "R_Knee", "R_Ankle", "R_Shoulder", "L_Elbow", "R_Elbow"):
        assert needed in msg
    assert "LeftUpLeg" in msg  # the available source names are listed
    motion = _random_motion(6, n=5)
    src = _source_from_motion(motion)
    bad = dataclasses.replace(src, rig="unknown",
                              joint_names=tuple("J" + n for n in src.joint_names))  # fmt: skip
    with pytest.raises(MotionImportError, match="L_Hip"):
        retarget(bad)


def test_auto_joint_map_understands_common_naming_schemes() -> None:
    mixamo = ["mixamorig:Hips", "mixamorig:Spine", "mixamorig:Spine1", "mixamorig:Spine2",
              "mixamorig:Neck", "mixamorig:Head"] + [
        f"mixamorig:{s}{p}" for s in ("Left", "Right") for p in
        ("Shoulder", "Arm", "ForeArm", "Hand", "UpLeg", "Leg", "Foot", "ToeBase")]  # fmt: skip
    m = auto_joint_map(mixamo)
    assert m["L_Collar"] == "mixamorig:LeftShoulder" and m["L_Shoulder"] == "mixamorig:LeftArm"
    assert m["R_Knee"] == "mixamorig:RightLeg" and m["L_Foot"] == "mixamorig:LeftToeBase"
    assert (m["Spine1"], m["Spine2"], m["Spine3"]) == ("mixamorig:Spine", "mixamorig:Spine1",
                                                      "mixamorig:Spine2")  # fmt: skip
    snake = ["pelvis", "spine", "neck", "head"] + [
        f"{s}_{p}" for s in "lr" for p in ("thigh", "calf", "foot", "upperarm", "forearm", "hand")
    ]
    m = auto_joint_map(snake)
    assert m["L_Hip"] == "l_thigh" and m["R_Elbow"] == "r_forearm" and m["Pelvis"] == "pelvis"
    check_joint_map(m, snake)
    # The fixed maps of the shared rigs agree with the heuristic where both apply.
    bandai = (*RIG_JOINT_MAPS["bandai"].values(), "joint_Root")
    assert auto_joint_map(bandai) == RIG_JOINT_MAPS["bandai"]


def test_load_joint_map_override(tmp_path: Path) -> None:
    path = tmp_path / "map.json"
    path.write_text(json.dumps({"Pelvis": "Hips", "L_Hand": None}), encoding="utf-8")
    assert load_joint_map(path) == {"Pelvis": "Hips"}
    path.write_text("{bad json", encoding="utf-8")
    with pytest.raises(MotionImportError, match=r"map\.json"):
        load_joint_map(path)
    # An override replaces the rig map: mapping only the required joints still works.
    motion = _random_motion(8, n=10)
    required = [
        "Pelvis",
        "L_Hip",
        "R_Hip",
        "L_Knee",
        "R_Knee",
        "L_Ankle",
        "R_Ankle",
        "L_Shoulder",
        "R_Shoulder",
        "L_Elbow",
        "R_Elbow",
        "Spine3",
        "Head",
    ]
    path.write_text(json.dumps({j: j for j in required}), encoding="utf-8")
    out = retarget(_source_from_motion(motion), cfg=RetargetConfig(joint_map_path=str(path)))
    assert set(out.meta["joint_map"]) == set(required)
    np.testing.assert_allclose(out.local_quat[:, 13, 0], 1.0)  # unmapped collar: identity


# ------------------------------------------------------------------------------------ real clips
def _clip(rel_path: str) -> SourceMotion:
    catalog = pytest.importorskip("grip.motion.catalog")
    path = DATA / rel_path
    if not path.is_file():
        pytest.skip(f"shared motion {path} not found")
    return catalog.load_clip(path)


#: Clip -> largest foot sliding (m/s) expected, None for clips that are not walks.
REAL_CLIPS = {
    "bandai_namco/dataset-1/dataset-1_walk_normal_001.bvh": 0.3,
    "cmu/bvh/12_01.bvh": 0.3,
    "hdm05/amc/HDM_bk_sneak2StepsLStart_004_120.amc": 0.3,
    "deepmimic/humanoid3d_walk.txt": 0.3,
    "ase_reallusion/RL_Avatar_WalkRight02_Motion.npy": 0.3,  # poselib; a forward walk in the body
    "ase_reallusion/RL_Avatar_Atk_Kick_Motion.npy": None,
    "hdm05/amc/HDM_bd_squat1Reps_001_120.amc": None,
}


@pytest.mark.parametrize(("rel_path", "max_fs"), list(REAL_CLIPS.items()))
def test_real_clip_is_plausible(rel_path: str, max_fs: float | None) -> None:
    out = retarget(_clip(rel_path))
    assert out.fps == 100.0 and np.all(np.isfinite(out.local_quat))
    assert np.all(np.isfinite(out.root_pos))
    m = foot_metrics(out)
    assert abs(m["stance_height_median_m"]) < 0.02  # feet on the floor in stance
    assert m["fp_max_mm"] < 1.0
    # Knees bend forward: flexion is a positive rotation about +x (canonical left).
    knee_x = matrix_to_euler_xyz(out.local_rot()[:, [4, 5]])[..., 0]
    flexed = np.abs(knee_x) > np.radians(15)
    assert np.mean(knee_x[flexed] > 0) > 0.95
    # Knee hinges stay a hinge: little rotation about the other axes.
    knee = quat_to_matrix(out.local_quat[:, [4, 5]])
    assert np.median(np.abs(matrix_to_euler_xyz(knee)[..., 1:])) < np.radians(15)
    _, p = out.fk()
    assert np.mean(p[:, 15, 2] > p[:, 0, 2] + 0.3) > 0.99  # upright: head well above pelvis
    if max_fs is not None:  # a walk
        assert m["fs_mps"] < max_fs
        assert m["contact_fraction"] > 0.8


@pytest.mark.slow
def test_all_shared_clips_retarget(request: pytest.FixtureRequest) -> None:
    if "slow" not in (request.config.getoption("markexpr") or ""):
        pytest.skip("whole shared dataset: run with -m slow")
    catalog = pytest.importorskip("grip.motion.catalog")
    if not DATA.is_dir():
        pytest.skip(f"shared motions not found at {DATA}")
    refs = catalog.find_clips(DATA)
    assert len(refs) >= 200
    failures = []
    for ref in refs:
        try:
            out = retarget(catalog.load_clip(ref))
            assert np.all(np.isfinite(out.root_pos)) and out.n_frames > 0
        except Exception as exc:  # collect them all, report at once
            failures.append(f"{ref.clip_id}: {exc!r}")
    assert not failures, "\n".join(failures)
