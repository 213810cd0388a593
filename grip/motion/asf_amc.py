"""Acclaim ASF (skeleton) / AMC (motion) reader, as used by the CMU and HDM05 databases.

Conventions followed (Acclaim / CMU usage):

* ``:units``: ``length L`` means one file unit is ``0.0254 / L`` metres (``length 0.45`` ->
  (1/0.45) inch = 0.05644 m, the CMU/HDM05 value); ``angle deg|rad``.
* An Euler triple with an order string (root ``axis XYZ``, bone ``axis a b c XYZ``) is applied in
  the order of the letters about fixed (global) axes, so ``XYZ`` -> ``Rz(c) @ Ry(b) @ Rx(a)``.
  The values are taken to be about the letters' axes in the order written (the same thing for
  ``XYZ``, the only order in CMU/HDM05 files).
* A bone's motion rotation ``M`` composes its dof values (``rx ry rz`` subset) in the bone's axis
  order; ``C`` is the bone's ``axis`` rotation. World (rest-relative) rotation:
  ``Delta_bone = Delta_parent @ C @ M @ C^T`` and the bone's end is
  ``start + length * Delta_bone @ direction``. The root: ``Delta_root = C_root @ M_root @ C_root^T``
  with ``C_root`` from ``:root orientation``; its AMC ``TX TY TZ`` are its absolute position
  (``:root position`` when the order has no translations).
* Translation dofs on bones (``tx ty tz l``) are read but ignored, with a warning.

Joints of the resulting :class:`~grip.motion.source.SourceMotion`: the root, then one joint per
bone placed at the bone's START (the parent bone's end; bones hanging off the root start at the
root), then for each leaf bone a ``"<bone>_end"`` joint at its end. ``global_rot`` is the
rest-relative ``Delta`` of the joint's bone, so ``rest_rot`` is identity and ``rest_pos`` is the ASF
rest pose (arms out, facing +z, y up for CMU/HDM05).
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from grip.core.limits import InputLimits, active_limits
from grip.motion.source import (
    MotionImportError,
    SourceMotion,
    check_finite,
    clean_import_errors,
    identity_rotations,
    read_text_bounded,
)

_INCH_M = 0.0254
_ROT_DOFS = {"rx": "X", "ry": "Y", "rz": "Z"}
_TRANS_DOFS = ("tx", "ty", "tz", "l")
_KNOWN_FPS = (24, 25, 30, 50, 60, 100, 120, 240, 480)
_HDM05_NAME = re.compile(r"^HDM_([A-Za-z0-9]+)_")
DEFAULT_FPS = 120.0


@dataclass(frozen=True)
class AsfBone:
    """One ASF bone.

    Attributes:
        name: Bone name.
        parent: Name of the parent bone (``"root"`` for bones attached to the root).
        direction: (3,) unit direction of the bone in the global rest frame.
        length_m: Bone length, metres (already scaled by the ASF's length unit).
        axis_rot: (3, 3) the bone's ``axis`` rotation C (local frame in the global rest frame).
        order: Axis order string of the ``axis`` line, e.g. ``"XYZ"``.
        dofs: The bone's dof names in file order (``rx``, ``ry``, ``rz``, ``tx``, ...).
    """

    name: str
    parent: str
    direction: np.ndarray
    length_m: float
    axis_rot: np.ndarray
    order: str
    dofs: tuple[str, ...]


@dataclass(frozen=True)
class AsfSkeleton:
    """A parsed ASF file.

    Attributes:
        path: The ASF file.
        unit_m: Metres per ASF length unit.
        angle_deg: True if angles are in degrees (``:units angle deg``).
        root_order: Channel names of the root in the AMC, e.g. ``("TX", "TY", "TZ", "RX", ...)``.
        root_axis: Rotation order of the root, e.g. ``"XYZ"``.
        root_position_m: (3,) root rest position, metres.
        root_axis_rot: (3, 3) C of the root from ``:root orientation``.
        bones: Bones in depth-first hierarchy order (parents before children).
    """

    path: str
    unit_m: float
    angle_deg: bool
    root_order: tuple[str, ...]
    root_axis: str
    root_position_m: np.ndarray
    root_axis_rot: np.ndarray
    bones: tuple[AsfBone, ...]

    @property
    def bone_names(self) -> tuple[str, ...]:
        """Bone names in hierarchy order."""
        return tuple(b.name for b in self.bones)


def _euler(order: str, angles: np.ndarray, degrees: bool) -> np.ndarray:
    """Matrices for fixed-axis Euler angles applied in ``order``. (..., n) -> (..., 3, 3)."""
    angles = np.asarray(angles, dtype=np.float64)
    lead = angles.shape[:-1]
    mats = Rotation.from_euler(order.lower(), angles.reshape(-1, len(order)), degrees=degrees)
    return mats.as_matrix().reshape(*lead, 3, 3)


def _strip_comment(line: str) -> str:
    k = line.find("#")
    return line if k < 0 else line[:k]


@clean_import_errors
def load_asf(
    path: str | Path, *, unit_m: float | None = None, limits: InputLimits | None = None
) -> AsfSkeleton:
    """Parse an Acclaim ASF skeleton.

    Args:
        path: The ``.asf`` file.
        unit_m: Metres per length unit; ``None`` derives it from ``:units length`` (0.0254 /
            length; 0.05644 for ``length 0.45``; inches if ``:units`` has no length).
        limits: Size limits (file size, bones); default
            :func:`grip.core.limits.active_limits`.

    Returns:
        The skeleton, bones in depth-first order of ``:hierarchy``.

    Raises:
        MotionImportError: Missing sections, bad numbers, unknown bones in the hierarchy, cycles.
    """
    path_s = str(path)
    raw_lines = read_text_bounded(path, limits or active_limits()).splitlines()

    def err(problem: str, line: int | None = None, key: str | None = None) -> MotionImportError:
        return MotionImportError(path_s, problem, line=line, key=key)

    def floats(toks: list[str], n: int, what: str, line: int) -> list[float]:
        if len(toks) < n:
            raise err(f"{what}: expected {n} numbers, got {len(toks)}", line)
        try:
            vals = [float(t) for t in toks[:n]]
        except ValueError:
            raise err(f"{what}: non-numeric value in {' '.join(toks[:n])!r}", line) from None
        if not np.all(np.isfinite(vals)):
            raise err(f"{what}: non-finite value", line)
        return vals

    length_unit: float | None = None
    angle_deg = True
    root: dict[str, tuple[list[str], int]] = {}
    bone_blocks: list[dict[str, tuple[list[str], int]]] = []
    hierarchy: list[tuple[list[str], int]] = []
    section = ""
    current: dict[str, tuple[list[str], int]] | None = None
    in_hier_block = False
    for k, raw in enumerate(raw_lines):
        ln = k + 1
        toks = _strip_comment(raw).split()
        if not toks:
            continue
        if toks[0].startswith(":"):
            # Sections other than units/root/bonedata/hierarchy (name, version,
            # documentation, ...) are read past.
            section = toks[0][1:].lower()
            continue
        if section == "units":
            if toks[0].lower() == "length":
                length_unit = floats(toks[1:], 1, "units length", ln)[0]
                if length_unit <= 0:
                    raise err("units length must be > 0", ln, key="length")
            elif toks[0].lower() == "angle":
                if len(toks) < 2 or toks[1].lower() not in (
                    "deg",
                    "degree",
                    "degrees",
                    "rad",
                    "radian",
                    "radians",
                ):
                    raise err(f"unknown angle unit {' '.join(toks[1:])!r}", ln, key="angle")
                angle_deg = toks[1].lower().startswith("deg")
        elif section == "root":
            root[toks[0].lower()] = (toks[1:], ln)
        elif section == "bonedata":
            word = toks[0].lower()
            if word == "begin":
                current = {"begin": ([], ln)}
            elif word == "end":
                if current is None:
                    raise err("'end' without 'begin' in :bonedata", ln)
                bone_blocks.append(current)
                current = None
            elif current is None:
                raise err(f"{toks[0]!r} outside a begin/end block in :bonedata", ln)
            elif word == "limits" or word.startswith("("):
                continue  # joint limits are not needed here
            else:
                current[word] = (toks[1:], ln)
        elif section == "hierarchy":
            word = toks[0].lower()
            if word == "begin":
                in_hier_block = True
            elif word == "end":
                in_hier_block = False
            elif in_hier_block:
                hierarchy.append((toks, ln))
    if current is not None:
        raise err("unterminated bone block (file truncated?)", current["begin"][1])
    if not root:
        raise err("no :root section", key=":root")
    if not bone_blocks:
        raise err("no bones in :bonedata", key=":bonedata")
    if not hierarchy:
        raise err("no :hierarchy section (file truncated?)", key=":hierarchy")

    if unit_m is None:
        unit_m = _INCH_M / (length_unit if length_unit is not None else 1.0)

    root_order = tuple(
        t.upper() for t in root.get("order", (["TX", "TY", "TZ", "RX", "RY", "RZ"], 0))[0]
    )
    for ch in root_order:
        if ch not in ("TX", "TY", "TZ", "RX", "RY", "RZ"):
            raise err(f"unknown root channel {ch!r}", root["order"][1], key="order")
    axis_toks = root.get("axis", (["XYZ"], 0))[0]
    root_axis = axis_toks[0].upper() if axis_toks else "XYZ"
    if sorted(root_axis) != ["X", "Y", "Z"]:
        raise err(f"root axis must be a permutation of XYZ, got {root_axis!r}", key="axis")
    pos_toks, pos_line = root.get("position", (["0", "0", "0"], 0))
    root_position = np.array(floats(pos_toks, 3, "root position", pos_line)) * unit_m
    ori_toks, ori_line = root.get("orientation", (["0", "0", "0"], 0))
    root_c = _euler(
        root_axis, np.array(floats(ori_toks, 3, "root orientation", ori_line)), angle_deg
    )

    bones: dict[str, AsfBone] = {}
    for block in bone_blocks:
        begin_line = block["begin"][1]
        if "name" not in block or not block["name"][0]:
            raise err("bone without a name", begin_line)
        bname = block["name"][0][0]
        if bname in bones or bname == "root":
            raise err(f"duplicate bone name {bname!r}", block["name"][1])
        for key in ("direction", "length"):
            if key not in block:
                raise err(f"bone {bname!r} has no {key}", begin_line, key=key)
        direction = np.array(
            floats(block["direction"][0], 3, f"{bname} direction", block["direction"][1])
        )
        norm = np.linalg.norm(direction)
        length = floats(block["length"][0], 1, f"{bname} length", block["length"][1])[0]
        if norm > 0:
            direction = direction / norm
        elif length != 0:
            raise err(f"bone {bname!r} has a zero direction", block["direction"][1])
        if "axis" in block:
            axis_toks, axis_line = block["axis"]
            angles = floats(axis_toks, 3, f"{bname} axis", axis_line)
            order = axis_toks[3].upper() if len(axis_toks) > 3 else "XYZ"
            if sorted(order) != ["X", "Y", "Z"]:
                raise err(
                    f"bone {bname!r}: axis order must be a permutation of XYZ, got {order!r}",
                    axis_line,
                )
            axis_rot = _euler(order, np.array(angles), angle_deg)
        else:
            order, axis_rot = "XYZ", np.eye(3)
        dofs = tuple(t.lower() for t in block.get("dof", ([], 0))[0])
        for d in dofs:
            if d not in _ROT_DOFS and d not in _TRANS_DOFS:
                raise err(f"bone {bname!r}: unknown dof {d!r}", block["dof"][1], key="dof")
        if len(set(dofs)) != len(dofs):
            raise err(f"bone {bname!r}: repeated dof", block["dof"][1], key="dof")
        bones[bname] = AsfBone(
            name=bname,
            parent="",
            direction=direction,
            length_m=length * unit_m,
            axis_rot=axis_rot,
            order=order,
            dofs=dofs,
        )

    children: dict[str, list[str]] = {}
    parent_of: dict[str, str] = {}
    for toks, ln in hierarchy:
        par = toks[0]
        if par != "root" and par not in bones:
            raise err(f"hierarchy names unknown bone {par!r}", ln)
        for child in toks[1:]:
            if child not in bones:
                raise err(f"hierarchy names unknown bone {child!r}", ln)
            if child in parent_of:
                raise err(f"bone {child!r} has two parents", ln)
            parent_of[child] = par
            children.setdefault(par, []).append(child)
    ordered: list[AsfBone] = []
    stack = list(reversed(children.get("root", [])))
    while stack:
        bname = stack.pop()
        b = bones[bname]
        ordered.append(
            AsfBone(
                name=b.name,
                parent=parent_of[bname],
                direction=b.direction,
                length_m=b.length_m,
                axis_rot=b.axis_rot,
                order=b.order,
                dofs=b.dofs,
            )
        )
        stack.extend(reversed(children.get(bname, [])))
        if len(ordered) > len(bones):
            raise err("cycle in :hierarchy", key=":hierarchy")
    missing = [n for n in bones if n not in parent_of]
    if missing:
        raise err(
            f"bones not reachable from root in :hierarchy: {', '.join(missing)}", key=":hierarchy"
        )
    return AsfSkeleton(
        path=path_s,
        unit_m=float(unit_m),
        angle_deg=angle_deg,
        root_order=root_order,
        root_axis=root_axis,
        root_position_m=root_position,
        root_axis_rot=root_c,
        bones=tuple(ordered),
    )


def find_asf_for_amc(amc_path: str | Path) -> Path:
    """Locate the ASF that belongs to an AMC file.

    Search order: for HDM05 names (``HDM_<actor>_...``) ``HDM_<actor>.asf``; then an ASF with the
    AMC's stem, or with its part before the first ``_`` (CMU ``02_01.amc`` -> ``02.asf``); then the
    single ASF present (not for HDM05 names, whose actor must match). Folders searched: the
    AMC's own folder, then the sibling ``asf/`` folder of the AMC's folder
    (``<amc folder>/../asf``).

    Raises:
        MotionImportError: No ASF found, or several candidates and no way to choose.
    """
    amc = Path(amc_path)
    folders = [amc.parent, amc.parent.parent / "asf"]
    candidates: list[str] = []
    m = _HDM05_NAME.match(amc.stem)
    if m:
        candidates.append(f"HDM_{m.group(1)}")
    candidates.append(amc.stem)
    if "_" in amc.stem:  # CMU: 02_01.amc -> 02.asf
        candidates.append(amc.stem.split("_")[0])
    for folder in folders:
        if not folder.is_dir():
            continue
        asfs = {p.stem: p for p in folder.iterdir() if p.suffix.lower() == ".asf"}
        lower = {k.lower(): v for k, v in asfs.items()}
        for cand in candidates:
            if cand.lower() in lower:
                return lower[cand.lower()]
        if m is None and len(asfs) == 1:
            return next(iter(asfs.values()))
        if len(asfs) > 1 or (m is not None and asfs):
            raise MotionImportError(
                amc,
                f"cannot choose an ASF among {len(asfs)} in {folder} "
                f"(looked for {', '.join(c + '.asf' for c in candidates)}); pass asf_path",
            )
    raise MotionImportError(
        amc,
        f"no ASF skeleton found (looked for {', '.join(c + '.asf' for c in candidates)} in "
        f"{' and '.join(str(f) for f in folders)}); pass asf_path",
    )


def _fps_from_name(stem: str) -> float | None:
    m = re.search(r"_(\d{2,3})$", stem)
    if m and int(m.group(1)) in _KNOWN_FPS:
        return float(m.group(1))
    return None


def _read_amc(
    path_s: str, lines: list[str], expected: dict[str, int]
) -> tuple[dict[str, np.ndarray], list[int], bool | None]:
    """Parse AMC frames. Returns per-channel-group (F, n) arrays, frame numbers, degrees flag."""
    values: dict[str, list[list[str]]] = {name: [] for name in expected}
    frame_numbers: list[int] = []
    degrees: bool | None = None
    seen: set[str] = set()
    current: int | None = None
    current_line = 0

    def close_frame() -> None:
        if current is None:
            return
        missing = [n for n in expected if n not in seen]
        if missing:
            raise MotionImportError(
                path_s, f"bone(s) missing: {', '.join(missing)}", line=current_line, frame=current
            )

    for k, raw in enumerate(lines):
        toks = _strip_comment(raw).split()
        if not toks:
            continue
        head = toks[0]
        if head.startswith(":"):
            word = head.upper()
            if word in (":DEGREES", ":DEG"):
                degrees = True
            elif word in (":RADIANS", ":RAD"):
                degrees = False
            continue
        if len(toks) == 1 and head.isdigit():
            close_frame()
            num = int(head)
            if current is not None and num != current + 1:
                raise MotionImportError(path_s, f"frame number {num} follows {current}", line=k + 1)
            current, current_line = num, k + 1
            frame_numbers.append(num)
            seen = set()
            continue
        if current is None:
            raise MotionImportError(
                path_s, f"data before the first frame number: {head!r}", line=k + 1
            )
        if head not in expected:
            raise MotionImportError(
                path_s,
                f"unknown bone {head!r} (not in the ASF, or it has no dof)",
                line=k + 1,
                frame=current,
            )
        if head in seen:
            raise MotionImportError(
                path_s, f"bone {head!r} appears twice", line=k + 1, frame=current
            )
        if len(toks) - 1 != expected[head]:
            raise MotionImportError(
                path_s,
                f"bone {head!r}: expected {expected[head]} values, got {len(toks) - 1}",
                line=k + 1,
                frame=current,
            )
        seen.add(head)
        values[head].append(toks[1:])
    close_frame()
    if not frame_numbers:
        raise MotionImportError(path_s, "no frames")
    out: dict[str, np.ndarray] = {}
    for name, rows in values.items():
        try:
            arr = np.array(rows, dtype=np.float64).reshape(len(frame_numbers), expected[name])
        except ValueError:
            for f, row in enumerate(rows):
                for tok in row:
                    try:
                        float(tok)
                    except ValueError:
                        raise MotionImportError(
                            path_s,
                            f"bone {name!r}: non-numeric value {tok!r}",
                            frame=frame_numbers[f],
                        ) from None
            raise
        bad = ~np.isfinite(arr)
        if bad.any():
            f = int(np.argwhere(bad)[0][0])
            raise MotionImportError(
                path_s, f"bone {name!r}: non-finite value", frame=frame_numbers[f]
            )
        out[name] = arr
    return out, frame_numbers, degrees


@clean_import_errors
def load_amc(
    amc_path: str | Path,
    asf_path: str | Path | None = None,
    *,
    fps: float | None = None,
    name: str | None = None,
    category: str = "unknown",
    limits: InputLimits | None = None,
) -> SourceMotion:
    """Read an AMC motion with its ASF skeleton into a :class:`SourceMotion`.

    Args:
        amc_path: The ``.amc`` file (frames numbered consecutively; blank lines tolerated).
        asf_path: Its skeleton; ``None`` looks it up with :func:`find_asf_for_amc`.
        fps: Frame rate. ``None``: from a ``_<fps>`` name suffix (``_120`` for HDM05), else 120.
        name: Clip id to store; default: the AMC's stem.
        category: Motion category to store.
        limits: Size and rate limits (:class:`grip.core.limits.InputLimits`): frame rate,
            frames, duration and frames x joints are checked before the clip's arrays are
            built; default :func:`grip.core.limits.active_limits`.

    Returns:
        The clip in the ASF's world axes (y up for CMU/HDM05), metres; ``rig="asf"``.

    Raises:
        MotionImportError: Missing ASF, bad numbers, a bone missing from a frame or with the wrong
            number of values (message names file, line and frame).
    """
    amc_s = str(amc_path)
    limits = limits or active_limits()
    if asf_path is None:
        asf_path = find_asf_for_amc(amc_path)
    skel = load_asf(asf_path, limits=limits)
    if fps is None:
        fps = _fps_from_name(Path(amc_path).stem) or DEFAULT_FPS
    if not fps > 0:
        raise MotionImportError(amc_s, f"fps must be > 0, got {fps}")
    limits.check_fps(float(fps))
    lines = read_text_bounded(amc_path, limits).splitlines()

    expected = {"root": len(skel.root_order)}
    trans_bones = []
    for b in skel.bones:
        if b.dofs:
            expected[b.name] = len(b.dofs)
        if any(d in _TRANS_DOFS for d in b.dofs):
            trans_bones.append(b.name)
    if trans_bones:
        warnings.warn(
            f"{amc_s}: translation dofs of {', '.join(trans_bones)} are ignored", stacklevel=2
        )
    data, frame_numbers, amc_deg = _read_amc(amc_s, lines, expected)
    degrees = skel.angle_deg if amc_deg is None else amc_deg
    n_frames = len(frame_numbers)
    parent_names = {b.parent for b in skel.bones}
    n_leaves = sum(b.name not in parent_names for b in skel.bones)
    limits.check_take(n_frames, float(fps), 1 + len(skel.bones) + n_leaves)

    # Root.
    root_vals = data["root"]
    col = {ch: k for k, ch in enumerate(skel.root_order)}
    root_pos = np.broadcast_to(skel.root_position_m, (n_frames, 3)).copy()
    for axis, ch in enumerate(("TX", "TY", "TZ")):
        if ch in col:
            root_pos[:, axis] = root_vals[:, col[ch]] * skel.unit_m
    root_angles = np.zeros((n_frames, 3))
    for ch in ("RX", "RY", "RZ"):
        if ch in col:
            root_angles[:, "XYZ".index(ch[1])] = root_vals[:, col[ch]]
    order_idx = ["XYZ".index(a) for a in skel.root_axis]
    m_root = _euler(skel.root_axis, root_angles[:, order_idx], degrees)
    delta_root = skel.root_axis_rot @ m_root @ skel.root_axis_rot.T

    # Joints: root, each bone at its start, "_end" joints after leaf bones (DFS order).
    has_child = {b.parent for b in skel.bones}
    joint_names: list[str] = ["root"]
    parents: list[int] = [-1]
    joint_of_bone: dict[str, int] = {"root": 0}
    deltas: list[np.ndarray] = [delta_root]
    offsets: list[np.ndarray] = [skel.root_position_m]
    bone_by_name = {b.name: b for b in skel.bones}
    for b in skel.bones:
        pj = joint_of_bone[b.parent]
        parent_vec = (
            np.zeros(3)
            if b.parent == "root"
            else bone_by_name[b.parent].length_m * bone_by_name[b.parent].direction
        )
        rot_dofs = [d for d in b.dofs if d in _ROT_DOFS]
        if rot_dofs:
            vals = data[b.name]
            angles = np.zeros((n_frames, 3))
            for k, d in enumerate(b.dofs):
                if d in _ROT_DOFS:
                    angles[:, "XYZ".index(_ROT_DOFS[d])] = vals[:, k]
            m = _euler(b.order, angles[:, ["XYZ".index(a) for a in b.order]], degrees)
            delta = deltas[pj] @ (b.axis_rot @ m @ b.axis_rot.T)
        else:
            delta = deltas[pj]
        joint_of_bone[b.name] = len(joint_names)
        joint_names.append(b.name)
        parents.append(pj)
        deltas.append(delta)
        offsets.append(parent_vec)
        if b.name not in has_child:
            joint_names.append(f"{b.name}_end")
            parents.append(joint_of_bone[b.name])
            deltas.append(delta)
            offsets.append(b.length_m * b.direction)

    n_joints = len(joint_names)
    global_rot = np.empty((n_frames, n_joints, 3, 3))
    global_pos = np.empty((n_frames, n_joints, 3))
    rest_pos = np.empty((n_joints, 3))
    global_pos[:, 0] = root_pos
    rest_pos[0] = skel.root_position_m
    for j in range(n_joints):
        global_rot[:, j] = deltas[j]
        p = parents[j]
        if p >= 0:
            # The bone vector is fixed in the rest frame and turned by the parent joint's Delta.
            global_pos[:, j] = global_pos[:, p] + global_rot[:, p] @ offsets[j]
            rest_pos[j] = rest_pos[p] + offsets[j]
    check_finite(amc_s, "joint positions", global_pos)
    return SourceMotion(
        name=name if name is not None else Path(amc_path).stem,
        path=amc_s,
        fmt="asf_amc",
        rig="asf",
        joint_names=tuple(joint_names),
        parents=np.array(parents, dtype=np.int64),
        times_s=np.arange(n_frames, dtype=np.float64) / float(fps),
        global_rot=global_rot,
        global_pos=global_pos,
        rest_rot=identity_rotations(n_joints),
        rest_pos=rest_pos,
        up_axis=1,
        unit_m=skel.unit_m,
        rest_is_tpose=True,
        category=category,
    )
