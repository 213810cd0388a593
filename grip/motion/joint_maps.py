"""Joint maps from capture rigs to the SMPL-topology body: SMPL joint name -> source joint name.

Segment semantics: SMPL joint ``j`` names the segment whose proximal joint is ``j`` (``L_Hip`` =
thigh, ``L_Knee`` = shank, ``L_Ankle`` = foot, ``L_Foot`` = toes, ``L_Elbow`` = forearm,
``L_Wrist`` = hand). A map sends ``j`` to the source joint whose world rotation drives that same
segment: for BVH the joint at the segment's proximal end, for ASF the bone (``L_Knee -> ltibia``).
SMPL joints absent from a map are filled in by the retargeter (identity local rotation, or a share
of the spine bend, see :mod:`grip.motion.retarget`).

Maps for the shared rigs are fixed tables (:data:`RIG_JOINT_MAPS`); unknown BVH rigs go through the
name heuristic :func:`auto_joint_map`; a user can override either with a JSON file
(:func:`load_joint_map`). :func:`resolve_joint_map` picks one and checks it.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from grip.core import skeleton as sk
from grip.motion.source import MotionImportError


def _sided(table: Mapping[str, tuple[str, str]]) -> dict[str, str]:
    """Expand ``{"Hip": (left name, right name)}`` into ``{"L_Hip": ..., "R_Hip": ...}``."""
    out: dict[str, str] = {}
    for part, (left, right) in table.items():
        out[f"L_{part}"] = left
        out[f"R_{part}"] = right
    return out


BANDAI_MAP: dict[str, str] = {
    "Pelvis": "Hips",
    "Spine1": "Spine",
    "Spine3": "Chest",
    "Neck": "Neck",
    "Head": "Head",
    **_sided({
        "Hip": ("UpperLeg_L", "UpperLeg_R"),
        "Knee": ("LowerLeg_L", "LowerLeg_R"),
        "Ankle": ("Foot_L", "Foot_R"),
        "Foot": ("Toes_L", "Toes_R"),
        "Collar": ("Shoulder_L", "Shoulder_R"),
        "Shoulder": ("UpperArm_L", "UpperArm_R"),
        "Elbow": ("LowerArm_L", "LowerArm_R"),
        "Wrist": ("Hand_L", "Hand_R"),
    }),
}  # fmt: skip
"""Bandai Namco Research Motion Dataset BVH (22 joints; Spine2 shares the Spine->Chest bend)."""

CMU_DAZ_MAP: dict[str, str] = {
    "Pelvis": "hip",
    "Spine1": "abdomen",
    "Spine3": "chest",
    "Neck": "neck",
    "Head": "head",
    **_sided({
        "Hip": ("lThigh", "rThigh"),
        "Knee": ("lShin", "rShin"),
        "Ankle": ("lFoot", "rFoot"),
        "Collar": ("lCollar", "rCollar"),
        "Shoulder": ("lShldr", "rShldr"),
        "Elbow": ("lForeArm", "rForeArm"),
        "Wrist": ("lHand", "rHand"),
    }),
}  # fmt: skip
"""cgspeed "Daz-friendly" CMU BVH (no toes: ``L_Foot`` follows the foot; buttocks are helpers
whose rotation is already inside the thighs' world rotation)."""

ASF_MAP: dict[str, str] = {
    "Pelvis": "root",
    "Spine1": "lowerback",
    "Spine2": "upperback",
    "Spine3": "thorax",
    "Neck": "lowerneck",
    "Head": "head",
    **_sided({
        "Hip": ("lfemur", "rfemur"),
        "Knee": ("ltibia", "rtibia"),
        "Ankle": ("lfoot", "rfoot"),
        "Foot": ("ltoes", "rtoes"),
        "Collar": ("lclavicle", "rclavicle"),
        "Shoulder": ("lhumerus", "rhumerus"),
        # The ASF forearm twist (pronation, dof ry) sits on the short wrist bone, which is collinear
        # with the radius: its frame is the distal forearm a watch IMU rides on.
        "Elbow": ("lwrist", "rwrist"),
        "Wrist": ("lhand", "rhand"),
        "Hand": ("lfingers", "rfingers"),
    }),
}  # fmt: skip
"""Acclaim ASF bones of the VICON BodyBuilder skeleton (CMU, HDM05)."""

DEEPMIMIC_MAP: dict[str, str] = {
    "Pelvis": "root",
    # DeepMimic's single torso joint is at the waist; mapping it to Spine3 spreads its bend
    # over Spine1-3 while keeping the chest orientation exact.
    "Spine3": "chest",
    "Neck": "neck",
    **_sided({
        "Hip": ("left_hip", "right_hip"),
        "Knee": ("left_knee", "right_knee"),
        "Ankle": ("left_ankle", "right_ankle"),
        "Shoulder": ("left_shoulder", "right_shoulder"),
        "Elbow": ("left_elbow", "right_elbow"),
        "Wrist": ("left_wrist", "right_wrist"),
    }),
}  # fmt: skip
"""DeepMimic humanoid3d (no collars, toes, separate head or hand joints)."""

ASE_MAP: dict[str, str] = {
    "Pelvis": "pelvis",
    # As DeepMimic's (ASE's humanoid has its bodies and offsets): one torso body from the waist,
    # whose bend Spine1-3 share; the "head" body sits at the neck joint and carries the head.
    "Spine3": "torso",
    "Neck": "head",
    **_sided({
        "Hip": ("left_thigh", "right_thigh"),
        "Knee": ("left_shin", "right_shin"),
        "Ankle": ("left_foot", "right_foot"),
        "Shoulder": ("left_upper_arm", "right_upper_arm"),
        "Elbow": ("left_lower_arm", "right_lower_arm"),
        "Wrist": ("left_hand", "right_hand"),
    }),
}  # fmt: skip
"""NVIDIA ASE's humanoid (poselib clips; its sword and shield are dropped by the importer)."""

SMPL_MAP: dict[str, str] = {name: name for name in sk.JOINT_NAMES}
"""SMPL/AMASS sources and this project's own skeleton: identity."""

RIG_JOINT_MAPS: dict[str, dict[str, str]] = {
    "bandai": BANDAI_MAP,
    "cmu_daz": CMU_DAZ_MAP,
    "asf": ASF_MAP,
    "deepmimic": DEEPMIMIC_MAP,
    "ase": ASE_MAP,
    "smpl": SMPL_MAP,
}
"""Fixed joint maps of the known rigs, keyed by :attr:`SourceMotion.rig`."""

REQUIRED_JOINTS: tuple[tuple[str, ...], ...] = (
    ("Pelvis",), ("L_Hip",), ("R_Hip",), ("L_Knee",), ("R_Knee",), ("L_Ankle",), ("R_Ankle",),
    ("L_Shoulder",), ("R_Shoulder",), ("L_Elbow",), ("R_Elbow",),
    ("Spine1", "Spine2", "Spine3"), ("Neck", "Head"),
)  # fmt: skip
"""Groups of SMPL joints of which at least one must be mapped (spine-or-chest, head-or-neck)."""


# --------------------------------------------------------------------------- checks and files
def missing_required(mapping: Mapping[str, str]) -> list[str]:
    """Required SMPL joints (or ``"A|B"`` alternatives) that ``mapping`` does not map."""
    return ["|".join(group) for group in REQUIRED_JOINTS
            if not any(mapping.get(j) for j in group)]  # fmt: skip


def check_joint_map(
    mapping: Mapping[str, str], joint_names: Sequence[str], where: str | Path = "motion"
) -> dict[str, str]:
    """Validate a joint map against a source skeleton.

    Args:
        mapping: SMPL joint name -> source joint name.
        joint_names: The source's J joint names.
        where: File (or clip id) named in error messages.

    Returns:
        A clean copy of the map.

    Raises:
        MotionImportError: An SMPL name is not one of the 24 joints, a source name is not in the
            skeleton, or required joints are unmapped; the message lists the missing SMPL
            joints and the available source joint names.
    """
    names = set(joint_names)
    bad_smpl = sorted(k for k in mapping if k not in sk.JOINT_INDEX)
    if bad_smpl:
        raise MotionImportError(where, f"joint map has unknown SMPL joint name(s) {bad_smpl}; "
                                       f"valid names: {list(sk.JOINT_NAMES)}")  # fmt: skip
    bad_src = sorted({v for v in mapping.values() if v and v not in names})
    if bad_src:
        raise MotionImportError(
            where,
            f"joint map names source joint(s) {bad_src} that the "
            f"skeleton does not have; available: {list(joint_names)}",
        )
    clean = {k: v for k, v in mapping.items() if v}
    missing = missing_required(clean)
    if missing:
        raise MotionImportError(
            where,
            f"unknown BVH joints: cannot map required SMPL joint(s) {missing}; available source "
            f"joints: {list(joint_names)} (pass a JSON joint map: SMPL name -> source name)",
        )
    return clean


def load_joint_map(path: str | Path) -> dict[str, str]:
    """Read a user joint map from JSON: ``{"Pelvis": "Hips", "L_Hip": "LeftUpLeg", ...}``.

    A ``null`` value leaves that SMPL joint unmapped. An object ``{"joint_map": {...}}`` is also
    accepted.

    Raises:
        MotionImportError: Unreadable file, invalid JSON, or values that are not strings.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise MotionImportError(path, f"cannot read joint map ({exc.strerror or exc})") from exc
    except json.JSONDecodeError as exc:
        raise MotionImportError(path, f"invalid JSON ({exc.msg})", line=exc.lineno) from exc
    if isinstance(data, dict) and isinstance(data.get("joint_map"), dict):
        data = data["joint_map"]
    if not isinstance(data, dict):
        raise MotionImportError(path, "a joint map must be a JSON object {SMPL name: source name}")
    out: dict[str, str] = {}
    for key, value in data.items():
        if value is None:
            continue
        if not isinstance(value, str):
            raise MotionImportError(
                path, f"value must be a joint name or null, got {value!r}", key=key
            )
        out[str(key)] = value
    return out


# --------------------------------------------------------------------------- name heuristic
_NOISE_TOKENS = frozenset({
    "mixamorig", "bip", "bip01", "bip001", "def", "mch", "org", "b", "jnt", "joint", "bone",
    "j", "bn", "sk", "ctrl", "c", "m", "end",
})  # fmt: skip
_LEFT = frozenset({"l", "left", "lft"})
_RIGHT = frozenset({"r", "right", "rt", "rgt"})

# Sided body parts: core name (tokens joined, lower case) -> role. Roles are resolved to SMPL
# joints below, because "shoulder" means a collar in Mixamo and an upper arm in DeepMimic.
_SIDED_ROLES: dict[str, str] = {
    **dict.fromkeys(("upleg", "upperleg", "thigh", "femur", "hip"), "thigh"),
    **dict.fromkeys(("leg", "lowerleg", "shin", "calf", "knee", "tibia", "crus"), "shank"),
    **dict.fromkeys(("foot", "ankle"), "foot"),
    **dict.fromkeys(("toebase", "toe", "toes", "ball", "toe0"), "toes"),
    **dict.fromkeys(("clavicle", "collar", "clav"), "collar"),
    "shoulder": "shoulder",
    **dict.fromkeys(("arm", "upperarm", "uparm", "shldr", "humerus"), "upperarm"),
    **dict.fromkeys(("forearm", "lowerarm", "elbow", "radius", "lowarm"), "forearm"),
    "hand": "hand",
    "wrist": "wrist",
}
_CENTRE_PELVIS = ("hips", "pelvis", "hip", "root")
_SPINE_RE = re.compile(r"^(spine\d*|chest\d*|upperchest|abdomen\d*|torso|back|lowerback|"
                       r"upperback|thorax|waist)$")  # fmt: skip
_NECK_RE = re.compile(r"^(neck\d*|lowerneck|upperneck)$")


def _tokens(name: str) -> list[str]:
    """Lower-case word tokens of a joint name: camelCase, digits and separators split."""
    name = name.split(":")[-1].split("|")[-1]
    parts = re.findall(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+|\d+", name)
    return [p.lower() for p in parts]


def _side_and_core(name: str) -> tuple[str | None, str]:
    """(``"L"``/``"R"``/None, core) of a joint name, e.g. ``LeftUpLeg -> ("L", "upleg")``."""
    toks = [t for t in _tokens(name) if t not in _NOISE_TOKENS]
    while toks and toks[0].isdigit():  # "Bip01 L Thigh" -> "l", "thigh"
        toks = toks[1:]
    side = None
    rest = []
    for t in toks:
        if side is None and t in _LEFT:
            side = "L"
        elif side is None and t in _RIGHT:
            side = "R"
        else:
            rest.append(t)
    core = "".join(rest)
    if side is None and len(core) > 1 and core[0] in "lr":
        # Glued prefixes: "lfemur", "rhumerus", "lshldr".
        tail = core[1:]
        if tail in _SIDED_ROLES or tail.rstrip("0123456789") in _SIDED_ROLES:
            side, core = ("L" if core[0] == "l" else "R"), tail
    return side, core


def auto_joint_map(
    joint_names: Sequence[str], parents: Sequence[int] | np.ndarray | None = None
) -> dict[str, str]:
    """Guess a joint map for an unknown rig from its joint names.

    Understands Mixamo (``mixamorig:LeftUpLeg``), the common BVH set (``LeftUpLeg/LeftLeg/
    LeftFoot/LeftToeBase``, ``LeftShoulder/LeftArm/LeftForeArm/LeftHand``, ``Hips/Spine/Spine1/
    Spine2/Neck/Head``), ``l_thigh``-style, ``UpperLeg_L``-style, CMU Daz and ASF names. Sides
    come from ``Left``/``Right``/``L``/``R`` tokens or an ``l``/``r`` prefix. ``"<parent>_end"``
    joints are ignored. The result is not checked; see :func:`check_joint_map`.

    Args:
        joint_names: The source's J joint names.
        parents: ``(J,)`` parent indices (to order spine joints by depth); default: list order,
            which is depth order for BVH and ASF files.

    Returns:
        SMPL joint name -> source joint name for the joints it recognised.
    """
    n = len(joint_names)
    depth = np.arange(n)
    if parents is not None:
        par = np.asarray(parents, dtype=np.int64)
        depth = np.zeros(n, dtype=np.int64)
        for j in range(n):
            depth[j] = 0 if par[j] < 0 else depth[par[j]] + 1
    by_role: dict[tuple[str, str], list[int]] = {}
    centre: dict[str, list[int]] = {"pelvis": [], "spine": [], "neck": [], "head": []}
    for j, name in enumerate(joint_names):
        if name.endswith("_end"):
            continue
        side, core = _side_and_core(name)
        base = core.rstrip("0123456789") if core not in _SIDED_ROLES else core
        if side is not None:
            role = _SIDED_ROLES.get(core) or _SIDED_ROLES.get(base)
            if role is not None:
                by_role.setdefault((side, role), []).append(j)
            continue
        if core in _CENTRE_PELVIS:
            centre["pelvis"].append(j)
        elif _SPINE_RE.match(core):
            centre["spine"].append(j)
        elif _NECK_RE.match(core):
            centre["neck"].append(j)
        elif core == "head":
            centre["head"].append(j)

    def first(idx: list[int]) -> str | None:
        return joint_names[min(idx, key=lambda k: (depth[k], k))] if idx else None

    out: dict[str, str] = {}
    # Pelvis: prefer an explicit hips/pelvis name over a bare root.
    for key in ("hips", "pelvis", "hip"):
        hits = [j for j in centre["pelvis"] if _side_and_core(joint_names[j])[1] == key]
        if hits:
            out["Pelvis"] = joint_names[min(hits, key=lambda k: (depth[k], k))]
            break
    else:
        if centre["pelvis"]:
            out["Pelvis"] = joint_names[min(centre["pelvis"], key=lambda k: (depth[k], k))]
    for side in ("L", "R"):
        has = {role for (s, role) in by_role if s == side}
        roles: dict[str, str] = {"thigh": "Hip", "shank": "Knee", "foot": "Ankle",
                                 "toes": "Foot", "collar": "Collar", "upperarm": "Shoulder",
                                 "forearm": "Elbow"}  # fmt: skip
        if "shoulder" in has:
            # Mixamo: Shoulder = clavicle, Arm = upper arm; DeepMimic: shoulder = upper arm.
            roles["shoulder"] = "Collar" if "upperarm" in has else "Shoulder"
        if "hand" in has:
            roles["hand"] = "Wrist"
        elif "wrist" in has:
            roles["wrist"] = "Wrist"
        for role, smpl in roles.items():
            name = first(by_role.get((side, role), []))
            if name is not None and f"{side}_{smpl}" not in out:
                out[f"{side}_{smpl}"] = name
    spine = sorted(centre["spine"], key=lambda k: (depth[k], k))
    if len(spine) == 1:
        out["Spine3"] = joint_names[spine[0]]
    elif len(spine) == 2:
        out["Spine1"], out["Spine3"] = joint_names[spine[0]], joint_names[spine[1]]
    elif len(spine) >= 3:
        out["Spine1"] = joint_names[spine[0]]
        out["Spine2"] = joint_names[spine[len(spine) // 2]]
        out["Spine3"] = joint_names[spine[-1]]
    neck = first(centre["neck"])
    if neck is not None:
        out["Neck"] = neck
    head = first(centre["head"])
    if head is not None:
        out["Head"] = head
    return out


def resolve_joint_map(
    rig: str,
    joint_names: Sequence[str],
    parents: Sequence[int] | np.ndarray | None = None,
    override: str | Path | Mapping[str, str] | None = None,
    where: str | Path = "motion",
) -> dict[str, str]:
    """The joint map to use for one source skeleton, checked.

    Order: ``override`` (a JSON path or a dict) if given; else the fixed map of ``rig``, with the
    entries whose source joint the skeleton lacks dropped; else (unknown rig, or a known rig
    whose map misses required joints) :func:`auto_joint_map`.

    Args:
        rig: :attr:`SourceMotion.rig`.
        joint_names: The source's joint names.
        parents: The source's parent indices (for :func:`auto_joint_map`).
        override: A user joint map (JSON file or mapping) that replaces the rig's.
        where: File or clip named in errors.

    Raises:
        MotionImportError: The map is invalid or required joints stay unmapped.
    """
    if override is not None:
        mapping = load_joint_map(override) if isinstance(override, (str, Path)) else dict(override)
        return check_joint_map(mapping, joint_names, where)
    names = set(joint_names)
    if rig in RIG_JOINT_MAPS:
        mapping = {k: v for k, v in RIG_JOINT_MAPS[rig].items() if v in names}
        if not missing_required(mapping):
            return check_joint_map(mapping, joint_names, where)
    return check_joint_map(auto_joint_map(joint_names, parents), joint_names, where)
