"""Motion-clip importers: hand-computed tiny files, round trips, error messages, shared data."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from grip.motion.amass import SMPL_JOINT_NAMES, SMPL_PELVIS_M, SMPL_REST_OFFSETS, load_amass_npz
from grip.motion.asf import load_asf
from grip.motion.asf_amc import load_amc
from grip.motion.bvh import load_bvh
from grip.motion.catalog import clip_ref, find_clips, load_clip
from grip.motion.deepmimic import (
    HUMANOID3D_JOINTS,
    humanoid3d_skeleton,
    load_deepmimic,
    load_deepmimic_skeleton,
)
from grip.motion.source import MotionImportError, SourceMotion, source_fk

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "motions"
INCH_PER_045 = 0.0254 / 0.45


def _rx(deg: float) -> np.ndarray:
    return Rotation.from_euler("x", deg, degrees=True).as_matrix()


def _ry(deg: float) -> np.ndarray:
    return Rotation.from_euler("y", deg, degrees=True).as_matrix()


def _rz(deg: float) -> np.ndarray:
    return Rotation.from_euler("z", deg, degrees=True).as_matrix()


# --------------------------------------------------------------------------------------- BVH
TINY_BVH = """HIERARCHY
ROOT Hips
{
\tOFFSET 0 0 0
\tCHANNELS 6 Xposition Yposition Zposition Xrotation Zrotation Yrotation
\tJOINT Chest
\t{
\t\tOFFSET 0 50 0
\t\tCHANNELS 3 Xrotation Zrotation Yrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 0 20
\t\t}
\t}
}
MOTION
Frames: 2
Frame Time: 0.5
0 0 0 0 0 0 0 0 0
100 50 0 90 90 0 0 0 90
"""


def _write(path: Path, text: str, crlf: bool = False) -> Path:
    path.write_bytes(text.replace("\n", "\r\n" if crlf else "\n").encode())
    return path


@pytest.mark.parametrize("crlf", [False, True])
def test_bvh_tiny_hand_computed(tmp_path: Path, crlf: bool) -> None:
    m = load_bvh(_write(tmp_path / "tiny.bvh", TINY_BVH, crlf))
    assert m.joint_names == ("Hips", "Chest", "Chest_end")
    np.testing.assert_array_equal(m.parents, [-1, 0, 1])
    assert m.unit_m == 0.01  # rest height 50 units > 10 -> centimetres
    assert m.fmt == "bvh" and m.rig == "unknown" and m.up_axis == 1
    np.testing.assert_allclose(m.times_s, [0.0, 0.5])
    np.testing.assert_allclose(m.rest_pos, [[0, 0, 0], [0, 0.5, 0], [0, 0.5, 0.2]], atol=1e-12)
    np.testing.assert_allclose(m.rest_rot, np.broadcast_to(np.eye(3), (3, 3, 3)))
    np.testing.assert_allclose(m.global_pos[0], m.rest_pos, atol=1e-12)
    # Frame 1: root R = Rx(90) @ Rz(90) (channel order, intrinsic). Chest offset (0, .5, 0):
    # Rz(90) y -> -x, Rx(90) keeps -x -> chest at root + (-.5, 0, 0). Chest adds Ry(90):
    # end offset (0, 0, .2): Ry(90) z -> x, Rz(90) x -> y, Rx(90) y -> z -> end at chest + .2 z.
    np.testing.assert_allclose(
        m.global_pos[1], [[1.0, 0.5, 0.0], [0.5, 0.5, 0.0], [0.5, 0.5, 0.2]], atol=1e-12
    )
    np.testing.assert_allclose(m.global_rot[1, 0], _rx(90) @ _rz(90), atol=1e-12)
    np.testing.assert_allclose(m.global_rot[1, 1], _rx(90) @ _rz(90) @ _ry(90), atol=1e-12)
    np.testing.assert_allclose(m.global_rot[1, 2], m.global_rot[1, 1])


def test_bvh_position_channels_replace_offset_and_units(tmp_path: Path) -> None:
    text = (
        TINY_BVH.replace(
            "CHANNELS 3 Xrotation Zrotation Yrotation",
            "CHANNELS 4 Yposition Xrotation Zrotation Yrotation",
        )
        .replace("0 0 0 0 0 0 0 0 0\n", "0 0 0 0 0 0 7 0 0 0\n")
        .replace("100 50 0 90 90 0 0 0 90\n", "1 2 3 0 0 0 9 0 0 0\n")
    )
    m = load_bvh(_write(tmp_path / "pos.bvh", text), unit_m=1.0)
    assert m.unit_m == 1.0
    # Chest's Yposition replaces its OFFSET's y (50 -> 7, then 9); x and z keep the OFFSET's.
    np.testing.assert_allclose(m.global_pos[:, 1], [[0, 7, 0], [1, 11, 3]])
    np.testing.assert_allclose(m.rest_pos[1], [0, 50, 0])


def test_bvh_rig_detection_and_first_frame_drop(tmp_path: Path) -> None:
    text = TINY_BVH.replace("Hips", "hip").replace("Chest", "abdomen")
    m = load_bvh(_write(tmp_path / "t.bvh", text), rig="cmu_daz")
    assert m.rig == "cmu_daz" and m.num_frames == 1 and m.rest_is_tpose
    np.testing.assert_allclose(m.global_pos[0, 0], [1.0, 0.5, 0.0])
    assert load_bvh(tmp_path / "t.bvh", rig="cmu_daz", drop_first_frame=False).num_frames == 2


def _assert_bvh_error(tmp_path: Path, text: str, *fragments: str) -> MotionImportError:
    path = _write(tmp_path / "broken_clip.bvh", text)
    with pytest.raises(MotionImportError) as info:
        load_bvh(path)
    msg = str(info.value)
    assert "broken_clip.bvh" in msg
    for frag in fragments:
        assert frag in msg, msg
    return info.value


def test_bvh_errors_name_file_and_line(tmp_path: Path) -> None:
    lines = TINY_BVH.splitlines(keepends=True)
    # Truncated inside the hierarchy: no MOTION section.
    _assert_bvh_error(tmp_path, "".join(lines[:8]), "MOTION")
    # Truncated in the middle of the last frame line.
    err = _assert_bvh_error(tmp_path, TINY_BVH[:-8], "line 20", "expected 9 channel values")
    assert err.line == 20
    # A frame line with too many values.
    _assert_bvh_error(
        tmp_path,
        TINY_BVH.replace("0 0 90\n", "0 0 90 4\n"),
        "line 20",
        "expected 9 channel values, got 10",
    )
    # Fewer frame lines than declared.
    _assert_bvh_error(tmp_path, TINY_BVH.replace("Frames: 2", "Frames: 3"), "Frames: 3")
    _assert_bvh_error(tmp_path, TINY_BVH.replace("100 50", "1e999 50"), "line 20", "non-finite")
    _assert_bvh_error(tmp_path, TINY_BVH.replace("100 50", "nan 50"), "line 20", "non-finite")
    _assert_bvh_error(tmp_path, TINY_BVH.replace("100 50", "abc 50"), "line 20", "'abc'")
    _assert_bvh_error(
        tmp_path,
        TINY_BVH.replace(
            "Xrotation Zrotation Yrotation\n\t\tEnd", "Xrotation Zrotation Wrotation\n\t\tEnd"
        ),
        "line 9",
        "Wrotation",
    )
    _assert_bvh_error(tmp_path, TINY_BVH.replace("MOTION", "MOTON"), "MOTION")


def test_bvh_allow_truncated_warns(tmp_path: Path) -> None:
    path = _write(tmp_path / "short.bvh", TINY_BVH.replace("Frames: 2", "Frames: 5"))
    with pytest.warns(UserWarning, match="short.bvh"):
        m = load_bvh(path, allow_truncated=True)
    assert m.num_frames == 2


# ----------------------------------------------------------------------------------- ASF/AMC
TINY_ASF = """# test skeleton
:version 1.10
:name tiny
:units
  mass 1.0
  length 0.45
  angle deg
:documentation
  hand written
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name upper
     direction 0 1 0
     length 10
     axis 0 0 90 XYZ
    dof rx ry rz
    limits (-180.0 180.0)
           (-180.0 180.0)
           (-180.0 180.0)
  end
  begin
     id 2
     name lower
     direction 1 0 0
     length 5
     axis 0 0 0 XYZ
    dof rx
    limits (-180.0 180.0)
  end
:hierarchy
  begin
    root upper
    upper lower
  end
"""

TINY_AMC = """#!OML:ASF tiny.asf
:FULLY-SPECIFIED
:DEGREES
1
root 0 0 0 0 0 0
upper 0 0 0
lower 0

2
root 10 0 0 0 90 0
upper 90 0 0
lower 90
"""


def _asf_amc_tree(tmp_path: Path, amc_text: str = TINY_AMC) -> Path:
    (tmp_path / "asf").mkdir(parents=True, exist_ok=True)
    (tmp_path / "amc").mkdir(parents=True, exist_ok=True)
    _write(tmp_path / "asf" / "tiny.asf", TINY_ASF)
    return _write(tmp_path / "amc" / "tiny_clip.amc", amc_text, crlf=True)


def test_asf_amc_tiny_hand_computed(tmp_path: Path) -> None:
    amc = _asf_amc_tree(tmp_path)
    skel = load_asf(tmp_path / "asf" / "tiny.asf")
    assert skel.bone_names == ("upper", "lower")
    np.testing.assert_allclose(skel.unit_m, INCH_PER_045)
    m = load_amc(amc)  # ASF found in the sibling asf/ folder (the only one there)
    u = INCH_PER_045
    assert m.joint_names == ("root", "upper", "lower", "lower_end")
    np.testing.assert_array_equal(m.parents, [-1, 0, 1, 2])
    assert m.rig == "asf" and m.fmt == "asf_amc" and m.rest_is_tpose
    np.testing.assert_allclose(m.times_s, [0.0, 1 / 120])
    np.testing.assert_allclose(
        m.rest_pos, [[0, 0, 0], [0, 0, 0], [0, 10 * u, 0], [5 * u, 10 * u, 0]], atol=1e-12
    )
    np.testing.assert_allclose(m.global_pos[0], m.rest_pos, atol=1e-12)
    # Frame 2: root Ry(90). upper: C = Rz(90), M = Rx(90) -> C M C^T = Ry(90): Delta = Ry(180);
    # its y-bone is unchanged. lower: Delta = Ry(180) @ Rx(90) turns its x-bone to -x.
    np.testing.assert_allclose(m.global_rot[1, 0], _ry(90), atol=1e-12)
    np.testing.assert_allclose(m.global_rot[1, 1], _ry(180), atol=1e-12)
    np.testing.assert_allclose(m.global_rot[1, 2], _ry(180) @ _rx(90), atol=1e-12)
    np.testing.assert_allclose(
        m.global_pos[1],
        [[10 * u, 0, 0], [10 * u, 0, 0], [10 * u, 10 * u, 0], [5 * u, 10 * u, 0]],
        atol=1e-12,
    )


def test_amc_errors(tmp_path: Path) -> None:
    amc = _asf_amc_tree(tmp_path, TINY_AMC.replace("upper 90 0 0\n", ""))
    with pytest.raises(MotionImportError, match=r"tiny_clip\.amc.*frame 2.*upper"):
        load_amc(amc)
    amc = _asf_amc_tree(tmp_path, TINY_AMC.replace("lower 90", "lower 90 1"))
    with pytest.raises(MotionImportError, match=r"tiny_clip\.amc.*frame 2.*expected 1 values"):
        load_amc(amc)
    amc = _asf_amc_tree(tmp_path, TINY_AMC.replace("lower 90", "lower nan"))
    with pytest.raises(MotionImportError, match=r"tiny_clip\.amc.*frame 2.*non-finite"):
        load_amc(amc)


def test_amc_missing_asf(tmp_path: Path) -> None:
    amc = _write(tmp_path / "HDM_zz_walk_001_120.amc", TINY_AMC)
    with pytest.raises(MotionImportError, match=r"HDM_zz_walk_001_120\.amc.*HDM_zz\.asf"):
        load_amc(amc)


# --------------------------------------------------------------------------------- DeepMimic
def _quat_wxyz(rot: Rotation) -> list[float]:
    return rot.as_quat(scalar_first=True).tolist()


def test_deepmimic_round_trip(tmp_path: Path) -> None:
    ident = [1.0, 0.0, 0.0, 0.0]
    root_rot = Rotation.from_euler("y", 30, degrees=True)
    frames = []
    for dt, root_pos, knee in (
        (0.1, [0, 0.9, 0], 0.0),
        (0.2, [1, 0.8, 2], -np.pi / 2),
        (0.0, [1, 0.8, 2], -np.pi / 2),
    ):
        frames.append(
            [
                dt,
                *root_pos,
                *_quat_wxyz(root_rot),
                *ident,
                *ident,  # root chest neck
                *ident,
                knee,
                *ident,
                *ident,
                0.0,  # right hip knee ankle shoulder elbow
                *ident,
                0.0,
                *ident,
                *ident,
                0.0,
            ]
        )  # left
    path = tmp_path / "humanoid3d_test.txt"
    path.write_text(json.dumps({"Loop": "none", "Frames": frames}))
    m = load_deepmimic(path)  # no character file next to it: built-in humanoid3d
    assert m.name == "test" and m.rig == "deepmimic" and m.unit_m == 1.0
    np.testing.assert_allclose(m.times_s, [0.0, 0.1, 0.3])
    J = m.joint_index
    r = root_rot.as_matrix()
    np.testing.assert_allclose(m.global_rot[:, 0], np.broadcast_to(r, (3, 3, 3)), atol=1e-12)
    np.testing.assert_allclose(m.global_pos[1, 0], [1, 0.8, 2])
    hip = np.array([1, 0.8, 2]) + r @ [0, 0, 0.084887]
    knee = hip + r @ [0, -0.421546, 0]
    # A knee angle of -90 deg about local z swings the shank backwards (-x, the character
    # faces +x), the way a knee bends.
    ankle = knee + r @ [-0.40987, 0, 0]
    np.testing.assert_allclose(m.global_pos[1, J("right_knee")], knee, atol=1e-9)
    np.testing.assert_allclose(m.global_pos[1, J("right_ankle")], ankle, atol=1e-9)
    # Fixed wrists: identity local rotation; end sites share their parent's rotation.
    np.testing.assert_allclose(m.global_rot[:, J("right_wrist")], m.global_rot[:, J("right_elbow")])
    np.testing.assert_allclose(
        m.global_rot[:, J("right_ankle_end")], m.global_rot[:, J("right_ankle")]
    )
    assert {"neck_end", "left_wrist_end", "left_ankle_end"} <= set(m.joint_names)
    assert 1.0 < m.rest_height_m() < 2.2
    # Frame 0 (all identity, root at 0.9 m): the toe tips are on the floor plane of the soles.
    np.testing.assert_allclose(
        m.global_pos[0, J("right_ankle_end"), 1], 0.9 - 0.421546 - 0.40987 - 0.05, atol=1e-9
    )


def test_deepmimic_errors(tmp_path: Path) -> None:
    path = tmp_path / "humanoid3d_bad.txt"
    path.write_text(json.dumps({"Frames": [[0.1] * 43]}))
    with pytest.raises(MotionImportError, match=r"humanoid3d_bad\.txt.*frame 0.*expected 44"):
        load_deepmimic(path)
    path.write_text('{"Frames": [[' + ", ".join(["NaN"] * 44) + "]]}")
    with pytest.raises(MotionImportError, match=r"humanoid3d_bad\.txt.*non-finite"):
        load_deepmimic(path)


# ------------------------------------------------------------------------------------- AMASS
def _write_amass(path: Path, n_frames: int = 3, width: int = 156, **overrides) -> dict:
    rng = np.random.default_rng(0)
    arrays = {
        "poses": rng.normal(scale=0.3, size=(n_frames, width)),
        "trans": rng.normal(size=(n_frames, 3)),
        "mocap_framerate": np.array(60.0),
        "betas": np.zeros(16),
        "gender": np.array("neutral"),
    }
    arrays.update(overrides)
    arrays = {k: v for k, v in arrays.items() if v is not None}
    np.savez(path, **arrays)
    return arrays


@pytest.mark.parametrize("width", [72, 156, 165])
def test_amass_round_trip(tmp_path: Path, width: int) -> None:
    arrays = _write_amass(tmp_path / "clip.npz", width=width)
    m = load_amass_npz(tmp_path / "clip.npz")
    assert m.joint_names == SMPL_JOINT_NAMES and m.rig == "smpl" and m.up_axis == 2
    assert m.rest_is_tpose and m.fmt == "amass"
    np.testing.assert_allclose(m.times_s, np.arange(3) / 60.0)
    poses = arrays["poses"]
    root = Rotation.from_rotvec(poses[:, :3]).as_matrix()
    np.testing.assert_allclose(m.global_rot[:, 0], root, atol=1e-12)
    np.testing.assert_allclose(m.global_pos[:, 0], arrays["trans"] + SMPL_PELVIS_M, atol=1e-12)
    # Left hip hangs off the pelvis by the rest offset turned by the root rotation.
    expect = m.global_pos[:, 0] + np.einsum("tab,b->ta", root, SMPL_REST_OFFSETS[1])
    np.testing.assert_allclose(m.global_pos[:, 1], expect, atol=1e-12)
    left_knee = root @ Rotation.from_rotvec(poses[:, 3:6]).as_matrix()
    np.testing.assert_allclose(m.global_rot[:, 1], left_knee, atol=1e-12)
    if width != 72:  # hands are identity for SMPL-H/X
        np.testing.assert_allclose(m.global_rot[:, 22], m.global_rot[:, 20], atol=1e-12)
    # Rest: upright in the z-up world.
    assert 1.0 < m.rest_height_m() < 2.2
    assert m.rest_pos[15, 2] > m.rest_pos[0, 2] > m.rest_pos[7, 2]


def test_amass_errors(tmp_path: Path) -> None:
    _write_amass(tmp_path / "nokey.npz", poses=None)
    with pytest.raises(MotionImportError, match=r"nokey\.npz.*'poses'"):
        load_amass_npz(tmp_path / "nokey.npz")
    _write_amass(tmp_path / "shape.npz", trans=np.zeros((2, 3)))
    with pytest.raises(MotionImportError, match=r"shape\.npz.*'trans'"):
        load_amass_npz(tmp_path / "shape.npz")
    _write_amass(tmp_path / "nan.npz", trans=np.full((3, 3), np.nan))
    with pytest.raises(MotionImportError, match=r"nan\.npz.*'trans'.*non-finite"):
        load_amass_npz(tmp_path / "nan.npz")
    _write_amass(tmp_path / "rate.npz", mocap_framerate=None)
    with pytest.raises(MotionImportError, match=r"rate\.npz.*mocap_framerate"):
        load_amass_npz(tmp_path / "rate.npz")
    _write_amass(tmp_path / "alt.npz", mocap_framerate=None, mocap_frame_rate=np.array(30.0))
    assert load_amass_npz(tmp_path / "alt.npz").times_s[1] == pytest.approx(1 / 30)


# ------------------------------------------------------------------------------ source / FK
def test_source_fk_batched_matches_manual() -> None:
    rng = np.random.default_rng(1)
    parents = np.array([-1, 0, 1, 0])
    local_rot = Rotation.random(5 * 4, random_state=2).as_matrix().reshape(5, 4, 3, 3)
    local_pos = rng.normal(size=(4, 3))  # broadcast over frames
    g_rot, g_pos = source_fk(parents, local_rot, local_pos)
    assert g_rot.shape == (5, 4, 3, 3) and g_pos.shape == (5, 4, 3)
    np.testing.assert_allclose(g_rot[:, 2], local_rot[:, 0] @ local_rot[:, 1] @ local_rot[:, 2])
    expect = (
        local_pos[0]
        + local_rot[:, 0] @ local_pos[1]
        + (local_rot[:, 0] @ local_rot[:, 1] @ local_pos[2])
    )
    np.testing.assert_allclose(g_pos[:, 2], expect)


def test_motion_import_error_message() -> None:
    err = MotionImportError("clip.bvh", "expected 132 channel values, got 130", line=57)
    assert str(err) == "clip.bvh: line 57: expected 132 channel values, got 130"
    assert isinstance(err, ValueError)
    import pickle

    assert str(pickle.loads(pickle.dumps(err))) == str(err)


# ---------------------------------------------------------------------------------- catalog
def test_catalog_on_a_small_tree(tmp_path: Path) -> None:
    root = tmp_path / "motions"
    (root / "mocap" / "bvh").mkdir(parents=True)
    _write(root / "mocap" / "bvh" / "01_01.bvh", TINY_BVH)
    (root / "mocap" / "clips.csv").write_text(
        'file,category\nbvh/01_01.bvh,"jump (forward; two-foot); balance"\n'
    )
    bandai = root / "bandai" / "dataset-1"
    (bandai / "cfg").mkdir(parents=True)
    (bandai / "cfg" / "content_label.txt").write_text("dataset-1_walk\ndataset-1_walk-back\n")
    _write(bandai / "dataset-1_walk-back_x_001.bvh", TINY_BVH)
    (bandai / "dataset-1_walk-back_x_001.json").write_text('{"content": 1, "style": 0}')
    _asf_amc_tree(root / "acclaim")
    dm = root / "dm"
    dm.mkdir()
    (dm / "README.txt").write_text("not a clip")
    joints = [
        {
            "ID": k,
            "Name": n,
            "Type": t,
            "Parent": p,
            "AttachX": a[0],
            "AttachY": a[1],
            "AttachZ": a[2],
        }
        for k, (n, t, p, a) in enumerate(HUMANOID3D_JOINTS)
    ]
    (dm / "humanoid3d_character_skeleton.txt").write_text(
        json.dumps({"Skeleton": {"Joints": joints}})
    )  # no BodyDefs: no end sites
    frame = [
        0.1,
        0,
        0.9,
        0,
        1,
        0,
        0,
        0,
        *[1, 0, 0, 0] * 2,
        1,
        0,
        0,
        0,
        0.0,
        *[1, 0, 0, 0] * 2,
        0.0,
        1,
        0,
        0,
        0,
        0.0,
        *[1, 0, 0, 0] * 2,
        0.0,
    ]
    (dm / "humanoid3d_getup_faceup.txt").write_text(json.dumps({"Frames": [frame, frame]}))
    (root / "amass").mkdir()
    _write_amass(root / "amass" / "s1.npz")
    np.savez(root / "amass" / "not_motion.npz", x=np.zeros(2))

    refs = find_clips(root)
    got = {r.clip_id: (r.fmt, r.category) for r in refs}
    assert got == {
        "acclaim/tiny_clip": ("asf_amc", "unknown"),
        "amass/s1": ("amass", "unknown"),
        "bandai/dataset-1_walk-back_x_001": ("bvh", "walk-back"),
        "dm/getup_faceup": ("deepmimic", "getup"),
        "mocap/01_01": ("bvh", "jump"),
    }
    assert [r.clip_id for r in refs] == sorted(got)
    for ref in refs:
        motion = load_clip(ref)
        assert isinstance(motion, SourceMotion) and motion.name == ref.clip_id
        assert motion.category == ref.category
        if ref.fmt == "deepmimic":  # the character file next to the clip was used
            assert motion.num_joints == len(HUMANOID3D_JOINTS)
    # A bare path is named as find_clips would, from its dataset folder (marked by clips.csv).
    single = clip_ref(root / "mocap" / "bvh" / "01_01.bvh")
    assert (single.clip_id, single.category) == ("mocap/01_01", "jump")


# ------------------------------------------------------------------------------ shared data
@pytest.fixture(scope="module")
def shared_clips() -> list:
    if not DATA.is_dir():
        pytest.skip(f"shared motion data not found at {DATA}")
    return find_clips(DATA)


def test_shared_data_catalog(shared_clips: list) -> None:
    """Every clip file of the shared folder is found once, named uniquely and categorised.

    Properties of the catalog, not today's counts: the folder grows (issue 49)."""
    refs = shared_clips
    deepmimic = [p for p in DATA.rglob("*.txt") if p.read_bytes()[:1] == b"{"
                 and b'"Frames"' in p.read_bytes()[:4096]]  # fmt: skip
    on_disk = {"bvh": len(list(DATA.rglob("*.bvh"))), "asf_amc": len(list(DATA.rglob("*.amc"))),
               "deepmimic": len(deepmimic), "poselib": len(list(DATA.rglob("*.npy")))}  # fmt: skip
    fmts = Counter(ref.fmt for ref in refs)
    for fmt, n in on_disk.items():
        assert fmts.get(fmt, 0) == n, fmt
    assert {r.path.resolve() for r in refs} >= {p.resolve() for p in deepmimic}
    assert len({r.clip_id for r in refs}) == len(refs)
    assert len({r.path.resolve() for r in refs}) == len(refs)
    assert {
        "cmu/02_01",
        "hdm05/HDM_bd_squat1Reps_001_120",
        "deepmimic/walk",
        "bandai_namco/dataset-1_walk_normal_001",
    } <= {r.clip_id for r in refs}
    assert all(r.category != "unknown" for r in refs)
    assert all(r.group for r in refs)


def _check_loads(refs: list) -> None:
    for ref in refs:
        m = load_clip(ref)
        for arr in (m.times_s, m.global_rot, m.global_pos, m.rest_rot, m.rest_pos):
            assert np.isfinite(arr).all(), ref.clip_id
        assert m.num_frames >= 2, ref.clip_id
        assert np.all(np.diff(m.times_s) > 0), ref.clip_id
        # Units sanity check: a standing rest skeleton is 1-2.2 m tall. Bandai's zero pose is
        # not a T-pose (bones along x; its height is the hip height plus half the hip width,
        # 0.978-1.005 m), so it gets a slightly lower bound; a cm/m mix-up is off by 100x.
        low = 1.0 if m.rest_is_tpose else 0.95
        assert low <= m.rest_height_m() <= 2.2, (ref.clip_id, m.rest_height_m())


def test_shared_data_sample_loads(shared_clips: list) -> None:
    """Every format and source folder: a seeded sample of 40 clips (all of them: ``slow``)."""
    rng = np.random.default_rng(0)
    by_top: dict[str, list] = {}
    for ref in shared_clips:
        by_top.setdefault(ref.clip_id.split("/")[0] + ref.fmt, []).append(ref)
    sample = [g[int(i)] for g in by_top.values()
              for i in rng.choice(len(g), size=min(len(g), 10), replace=False)]  # fmt: skip
    _check_loads(sample)


@pytest.mark.slow
def test_shared_data_all_clips_load(shared_clips: list) -> None:
    _check_loads(shared_clips)


def test_shared_data_specifics(shared_clips: list) -> None:
    by_id = {r.clip_id: r for r in shared_clips}
    cmu = load_clip(by_id["cmu/02_01"])
    assert cmu.rig == "cmu_daz" and cmu.num_frames == 343  # 344 minus the T-pose frame
    assert cmu.joint_names[0] == "hip" and cmu.category == "walking_variety"
    bandai = load_clip(by_id["bandai_namco/dataset-1_walk_normal_001"])
    assert bandai.rig == "bandai" and not bandai.rest_is_tpose and bandai.category == "walk"
    hdm = load_clip(by_id["hdm05/HDM_bd_squat1Reps_001_120"])
    assert hdm.category == "squat" and hdm.times_s[1] == pytest.approx(1 / 120)
    np.testing.assert_allclose(hdm.unit_m, INCH_PER_045)
    dm_skel = load_deepmimic_skeleton(DATA / "deepmimic" / "humanoid3d_character_skeleton.txt")
    builtin = humanoid3d_skeleton()
    assert dm_skel.names == builtin.names == tuple(j[0] for j in HUMANOID3D_JOINTS)
    np.testing.assert_allclose(dm_skel.offsets, builtin.offsets)
    for (ja, a), (jb, b) in zip(dm_skel.end_sites, builtin.end_sites, strict=True):
        assert ja == jb
        np.testing.assert_allclose(a, b)
    walk = load_clip(by_id["deepmimic/walk"])
    J = walk.joint_index
    # Walking: the knees are flexed, the feet stay below the knees, travel along +x.
    assert np.all(walk.global_pos[:, J("right_ankle"), 1] < walk.global_pos[:, J("right_knee"), 1])
    assert walk.global_pos[-1, 0, 0] - walk.global_pos[0, 0, 0] > 0.5
