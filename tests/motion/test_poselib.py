"""poselib ``SkeletonMotion`` clips (ASE): hand-computed kinematics, hostile and malformed files,
the catalog and retargeting, on synthetic files only (``tests/motion/poselib_files.py``)."""

from __future__ import annotations

import builtins
import os
import pickle
import shlex
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from grip.core.safe_pickle import npy_header
from grip.motion.catalog import find_clips, load_category_map, load_clip, scan_clips
from grip.motion.joint_maps import ASE_MAP
from grip.motion.poselib import ASE_BODIES, is_poselib_npy, load_poselib
from grip.motion.quality import foot_metrics
from grip.motion.retarget import retarget
from grip.motion.source import MotionImportError
from tests.motion.poselib_files import (
    ASE_PARENTS,
    ase_offsets,
    poselib_dict,
    standing_quats,
    write_poselib,
    write_standing_clip,
)

B = {name: j for j, name in enumerate(ASE_BODIES)}
REPO = Path(__file__).resolve().parents[2]


def _xyzw(axis: str, deg: float) -> np.ndarray:
    return Rotation.from_euler(axis, deg, degrees=True).as_quat()  # SciPy's default: (x, y, z, w)


def test_hand_computed_kinematics_and_the_xyzw_order(tmp_path: Path) -> None:
    q = standing_quats(3)
    q[1, B["pelvis"]] = _xyzw("z", 90)  # turn left: the body's left (+y) now points to -x
    q[2, B["right_shin"]] = _xyzw("y", 90)  # knee flexed 90 deg: the shank points back (-x)
    root = np.array([[0.0, 0.0, 0.9], [1.0, 0.0, 0.9], [2.0, 0.0, 0.9]])
    m = load_poselib(write_poselib(tmp_path / "clip.npy", poselib_dict(q, root, fps=30.0)))
    assert (m.fmt, m.rig, m.up_axis, m.unit_m, m.rest_is_tpose) == ("poselib", "ase", 2, 1.0, True)
    assert m.name == "clip" and m.category == "unknown"
    np.testing.assert_allclose(m.times_s, [0.0, 1 / 30, 2 / 30])
    # The sword and the shield are gone; end sites at the head top, hand tips and toe tips.
    assert m.joint_names == (*(b for b in ASE_BODIES if b not in ("sword", "shield")),
                             "head_end", "right_hand_end", "left_hand_end", "right_foot_end",
                             "left_foot_end")  # fmt: skip
    assert [m.joint_names[p] for p in m.parents[-5:]] == [
        "head", "right_hand", "left_hand", "right_foot", "left_foot"]  # fmt: skip
    J = m.joint_index
    hip, thigh, shank = 0.084887, 0.421546, 0.40987
    np.testing.assert_allclose(m.global_pos[0, J("left_thigh")], [0, hip, 0.9], atol=1e-6)
    np.testing.assert_allclose(m.global_pos[1, J("left_thigh")], [1 - hip, 0, 0.9], atol=1e-6)
    np.testing.assert_allclose(m.global_rot[1, 0], Rotation.from_euler("z", 90, degrees=True)
                               .as_matrix(), atol=1e-12)  # fmt: skip
    ankle = np.array([2 - shank, -hip, 0.9 - thigh])
    np.testing.assert_allclose(m.global_pos[2, J("right_foot")], ankle, atol=1e-6)
    # The toe tip (0.1335, 0, -0.05) in the foot frame, turned 90 deg about y with the shank.
    toe = ankle + np.array([-0.05, 0.0, -0.1335])
    np.testing.assert_allclose(m.global_pos[2, J("right_foot_end")], toe, atol=1e-6)
    # Rest pose: the skeleton tree, head top 1.73 m and soles 0.12 m above the pelvis origin.
    assert m.rest_height_m() == pytest.approx(0.236151 + 0.223894 + 0.27 + thigh + shank + 0.05,
                                              abs=1e-6)  # fmt: skip


def test_global_rotations_give_the_same_motion(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    local = Rotation.from_rotvec(rng.normal(scale=0.4, size=(4 * 17, 3))).as_matrix()
    local = local.reshape(4, 17, 3, 3)
    glob = local.copy()
    for j in range(1, 17):
        glob[:, j] = glob[:, ASE_PARENTS[j]] @ local[:, j]
    root = rng.normal(size=(4, 3)) + np.array([0.0, 0.0, 1.0])

    def quats(r: np.ndarray) -> np.ndarray:
        return Rotation.from_matrix(r.reshape(-1, 3, 3)).as_quat().reshape(4, 17, 4)

    a = load_poselib(write_poselib(tmp_path / "a.npy", poselib_dict(quats(local), root)))
    b = load_poselib(write_poselib(tmp_path / "b.npy", poselib_dict(quats(glob), root,
                                                                   is_local=False)))  # fmt: skip
    np.testing.assert_allclose(a.global_pos, b.global_pos, atol=1e-9)
    np.testing.assert_allclose(a.global_rot, b.global_rot, atol=1e-9)


def test_ase_without_props_is_the_same_rig_and_other_skeletons_map_by_name(
    tmp_path: Path,
) -> None:
    q, root = standing_quats(20), np.tile([0.0, 0.0, 0.89], (20, 1))
    full = load_poselib(write_poselib(tmp_path / "full.npy", poselib_dict(q, root)))
    keep = [j for j, b in enumerate(ASE_BODIES) if b not in ("sword", "shield")]
    new = {old: k for k, old in enumerate(keep)}
    parents = np.array([-1 if ASE_PARENTS[j] < 0 else new[ASE_PARENTS[j]] for j in keep])
    bare = load_poselib(write_poselib(tmp_path / "bare.npy", poselib_dict(
        q[:, keep], root, offsets=ase_offsets()[keep], names=[ASE_BODIES[j] for j in keep],
        parents=parents)))  # fmt: skip
    assert bare.rig == "ase" and bare.joint_names == full.joint_names
    np.testing.assert_allclose(bare.global_pos, full.global_pos, atol=1e-6)
    # Another skeleton (a body renamed): no rig map, no end sites; the name heuristic maps it.
    names = [{"torso": "chest"}.get(b, b) for b in ASE_BODIES]
    other = load_poselib(write_poselib(tmp_path / "other.npy", poselib_dict(q, root, names=names)))
    assert other.rig == "unknown" and "chest" in other.joint_names
    assert not any(n.endswith("_end") for n in other.joint_names)
    out = retarget(other)
    assert out.meta["joint_map"]["Spine3"] == "chest"
    _, p = out.fk()
    assert np.all(p[:, 15, 2] > p[:, 0, 2] + 0.4)


class _Payload:
    """Unpickling it runs ``call(*args)``, which writes a marker file."""

    def __init__(self, call, *args) -> None:
        self.call, self.args = call, args

    def __reduce__(self):
        return (self.call, self.args)


def _payloads(marker: Path) -> dict[str, _Payload]:
    return {
        "os.system": _Payload(os.system, f"touch {shlex.quote(str(marker))}"),
        "builtins.eval": _Payload(builtins.eval, f"open({str(marker)!r}, 'w')"),
        "pathlib.Path.touch": _Payload(Path.touch, marker),
    }


@pytest.mark.parametrize("kind", ["os.system", "builtins.eval", "pathlib.Path.touch"])
def test_a_planted_payload_is_refused_naming_the_file_and_never_runs(
    tmp_path: Path, kind: str
) -> None:
    marker, live = tmp_path / "PWNED", tmp_path / "LIVE"
    d = poselib_dict(standing_quats(2), np.zeros((2, 3)))
    d["rotation"] = {"arr": _payloads(marker)[kind]}  # where an array should be
    path = write_poselib(tmp_path / "motions" / "evil" / "clip.npy", d)
    # The payload is live: an unrestricted unpickle of such a file runs it (the control).
    d["rotation"] = {"arr": _payloads(live)[kind]}
    data = write_poselib(tmp_path / "live.npy", d).read_bytes()
    pickle.loads(data[npy_header(data)[1] :])
    assert live.exists()

    with pytest.raises(MotionImportError) as err:
        load_poselib(path)
    msg = str(err.value)
    assert msg.startswith(str(path)) and "refused to unpickle global" in msg
    assert kind.rsplit(".", 1)[-1] in msg
    with pytest.raises(MotionImportError, match="refused to unpickle global") as err:
        load_clip(path)
    assert str(path) in str(err.value)
    clips, skipped = scan_clips(tmp_path / "motions")
    assert clips == [] and [s.path for s in skipped] == [path]
    assert "refused to unpickle global" in skipped[0].reason
    assert not marker.exists()


def _malformed(case: str, tmp_path: Path) -> Path:
    q, root = standing_quats(4), np.tile([0.0, 0.0, 0.9], (4, 1))
    d = poselib_dict(q, root)
    path = tmp_path / f"{case}.npy"
    if case == "no fps":
        del d["fps"]
    elif case == "shapes":
        d["rotation"]["arr"] = q[:, :16]
    elif case == "parents":
        d["skeleton_tree"]["parent_indices"]["arr"] = np.roll(ASE_PARENTS, 1)
    elif case == "zero quaternion":
        d["rotation"]["arr"][2, 5] = 0.0
    elif case == "nan":
        d["root_translation"]["arr"][1, 2] = np.nan
    elif case == "y-up":
        d["skeleton_tree"]["local_translation"]["arr"] = ase_offsets()[:, [0, 2, 1]]
    elif case == "fps":
        d["fps"] = np.float64(0.0)
    elif case == "names":
        d["skeleton_tree"]["node_names"] = list(ASE_BODIES[:-1])
    elif case == "a list":
        d = [1, 2, 3]
    write_poselib(path, d)
    if case == "truncated":
        path.write_bytes(path.read_bytes()[:300])
    return path


MALFORMED = {
    "no fps": "not a poselib SkeletonMotion", "shapes": "do not fit 17 bodies",
    "parents": "parent_indices", "zero quaternion": "zero quaternion", "nan": "non-finite",
    "y-up": "not z-up", "fps": "frame rate", "names": "do not agree",
    "a list": "not a poselib SkeletonMotion", "truncated": "not a readable poselib .npy",
}  # fmt: skip


@pytest.mark.parametrize(("case", "why"), list(MALFORMED.items()))
def test_malformed_files_are_refused_naming_the_file(tmp_path: Path, case: str, why: str) -> None:
    path = _malformed(case, tmp_path)
    with pytest.raises(MotionImportError, match=why) as err:
        load_poselib(path)
    assert str(err.value).startswith(str(path))


def test_the_catalog_finds_poselib_clips_and_leaves_other_npy_files(tmp_path: Path) -> None:
    root = tmp_path / "motions"
    write_standing_clip(root / "lab" / "takes" / "stand.npy")
    write_standing_clip(root / "lab" / "takes" / "stand2.npy")
    np.save(root / "lab" / "takes" / "weights.npy", np.zeros((3, 4)))  # a numeric array
    write_poselib(root / "lab" / "takes" / "notes.npy", {"text": "a pickled dict, not a clip"})
    (root / "lab" / "clips.csv").write_text("file,category,person\n"
                                            "takes/stand.npy,walk (in place),alice\n")  # fmt: skip
    assert not is_poselib_npy(root / "lab" / "takes" / "weights.npy")
    assert not is_poselib_npy(root / "lab" / "takes" / "notes.npy")
    refs, skipped = scan_clips(root, load_category_map(REPO / "configs" / "categories.toml"))
    assert skipped == []
    got = {r.clip_id: (r.fmt, r.category, r.person, r.group) for r in refs}
    assert got == {"lab/stand": ("poselib", "walk", "alice", "lab/alice"),
                   "lab/stand2": ("poselib", "unknown", "", "lab/stand2")}  # fmt: skip
    m = load_clip(refs[0])
    assert m.name == "lab/stand" and m.category == "walk" and m.num_frames == 12
    assert [r.clip_id for r in find_clips(root / "lab" / "takes")] == ["takes/stand",
                                                                      "takes/stand2"]  # fmt: skip


def test_a_standing_clip_retargets_flat_onto_the_floor(tmp_path: Path) -> None:
    """The retarget-quality check of every importer (grip.motion.quality) on the ASE rig."""
    out = retarget(load_poselib(write_standing_clip(tmp_path / "stand.npy", n_frames=30)))
    assert set(out.meta["joint_map"]) == set(ASE_MAP) and out.meta["source_rig"] == "ase"
    m = foot_metrics(out)
    assert m["fp_max_mm"] < 1.0 and abs(m["stance_height_median_m"]) < 0.005
    assert m["contact_fraction"] == 1.0 and m["fs_mps"] < 0.01
    _, p = out.fk()
    assert np.all(p[:, 15, 2] > p[:, 0, 2] + 0.4)  # upright: head well above the pelvis
    # Standing with the arms down: the wrists hang below the shoulders.
    assert np.all(p[:, [20, 21], 2] < p[:, [16, 17], 2] - 0.3)
