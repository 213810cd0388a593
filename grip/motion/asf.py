"""Acclaim ASF skeleton parser (CMU and HDM05 databases); the conventions it follows are in
:mod:`grip.motion.asf_amc`, which reads the AMC motion on top of it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from grip.core.limits import InputLimits, active_limits
from grip.motion.source import MotionImportError, clean_import_errors, read_text_bounded

_INCH_M = 0.0254
_ROT_DOFS = {"rx": "X", "ry": "Y", "rz": "Z"}
_TRANS_DOFS = ("tx", "ty", "tz", "l")


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
