"""Biovision Hierarchy (BVH) reader.

A general reader: any number of joints and End Sites, any Euler channel order per joint, optional
position channels on any joint, CRLF/LF line endings, tabs and blank lines. Conventions:

* A joint's local rotation is the product of its rotation channels *in the order listed*
  (``Zrotation Xrotation Yrotation`` -> ``Rz(z) @ Rx(x) @ Ry(y)``, i.e. intrinsic ZXY), degrees.
* Position channels, where present, *replace* the matching component of the joint's OFFSET for
  that frame (BVH exporters write the absolute local position there, e.g. the root trajectory).
* The zero pose (``rest_rot``/``rest_pos``) has every rotation channel at zero and every joint at
  its OFFSET; its global rotations are therefore identity.
* End Sites become extra joints named ``"<parent>_end"`` that share their parent's rotation.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from grip.core.limits import InputLimits, active_limits
from grip.motion.source import (
    MotionImportError,
    SourceMotion,
    clean_import_errors,
    identity_rotations,
    read_text_bounded,
    rest_fk,
    source_fk,
)

_ROT_CHANNELS = {"xrotation": "X", "yrotation": "Y", "zrotation": "Z"}
_POS_CHANNELS = {"xposition": 0, "yposition": 1, "zposition": 2}

_BANDAI_JOINTS = frozenset({"joint_Root", "Hips", "UpperLeg_L", "UpperLeg_R", "LowerLeg_L"})
_CMU_DAZ_JOINTS = frozenset({"hip", "abdomen", "chest", "lThigh", "rThigh", "lShin", "rShin"})

#: Rigs whose zero pose is an anatomical T-pose / standing pose.
_TPOSE_RIGS = {"cmu_daz": True, "bandai": False}
#: Height ratio (up extent / largest horizontal extent) above which an unknown rig's zero pose is
#: taken to be a standing pose: a T-pose's arm span is about its height, a lying rig is far below.
_STANDING_RATIO = 0.8
#: Rest skeletons taller than this many file units are taken to be in centimetres.
_CM_HEIGHT_THRESHOLD = 10.0


@dataclass
class _Joint:
    name: str
    parent: int
    offset: np.ndarray
    line: int
    rot_order: str = ""  # e.g. "ZXY", rotation channels in listed order
    rot_cols: list[int] = field(default_factory=list)  # channel column of each rotation channel
    pos_axes: list[int] = field(default_factory=list)  # 0/1/2 of each position channel
    pos_cols: list[int] = field(default_factory=list)


def detect_bvh_rig(joint_names: tuple[str, ...] | list[str]) -> str:
    """Rig key for a BVH joint list: ``"bandai"``, ``"cmu_daz"`` or ``"unknown"``."""
    names = set(joint_names)
    if _BANDAI_JOINTS <= names:
        return "bandai"
    if _CMU_DAZ_JOINTS <= names:
        return "cmu_daz"
    return "unknown"


def _tokenize(lines: list[str], first: int, last: int) -> list[tuple[str, int]]:
    """Whitespace tokens of ``lines[first:last]`` with their 1-based line numbers; braces split."""
    out: list[tuple[str, int]] = []
    for i in range(first, last):
        line = lines[i]
        if "{" in line or "}" in line:
            line = line.replace("{", " { ").replace("}", " } ")
        out.extend((tok, i + 1) for tok in line.split())
    return out


def _parse_hierarchy(path: str, lines: list[str], end: int) -> tuple[list[_Joint], int]:
    """Parse HIERARCHY up to line index ``end`` (the MOTION line). Returns joints and #channels."""
    toks = _tokenize(lines, 0, end)
    # ROOT/JOINT names run to the end of their line (a name may contain spaces).
    pos = 0
    n_tok = len(toks)

    def err(problem: str, line: int | None) -> MotionImportError:
        return MotionImportError(path, problem, line=line)

    def next_tok(what: str) -> tuple[str, int]:
        nonlocal pos
        if pos >= n_tok:
            raise err(
                f"unexpected end of HIERARCHY while reading {what}", toks[-1][1] if toks else 1
            )
        tok = toks[pos]
        pos += 1
        return tok

    def next_float(what: str) -> float:
        tok, line = next_tok(what)
        try:
            val = float(tok)
        except ValueError:
            raise err(f"expected a number for {what}, got {tok!r}", line) from None
        if not np.isfinite(val):
            raise err(f"non-finite value {tok!r} in {what}", line)
        return val

    if not toks or toks[0][0].upper() != "HIERARCHY":
        raise err("file does not start with HIERARCHY", toks[0][1] if toks else 1)
    pos = 1
    joints: list[_Joint] = []
    n_channels = 0
    # Stack of joint indices whose '{' block is open; -2 marks an End Site block.
    stack: list[int] = []
    expect_root = True
    while pos < n_tok:
        tok, line = next_tok("a keyword")
        key = tok.upper()
        if key in ("ROOT", "JOINT"):
            if key == "ROOT" and stack:
                raise err("ROOT inside another joint's block", line)
            if key == "JOINT" and not stack:
                raise err("JOINT outside any ROOT block", line)
            if key == "ROOT" and not expect_root:
                raise err("more than one ROOT is not supported", line)
            expect_root = False
            name_parts = []
            while pos < n_tok and toks[pos][1] == line and toks[pos][0] not in "{}":
                name_parts.append(toks[pos][0])
                pos += 1
            if not name_parts:
                raise err(f"{tok} without a name", line)
            name = " ".join(name_parts)
            if stack and stack[-1] == -2:
                raise err("JOINT inside an End Site block", line)
            parent = stack[-1] if stack else -1
            brace, bline = next_tok("'{'")
            if brace != "{":
                raise err(f"expected '{{' after {tok} {name}, got {brace!r}", bline)
            joints.append(_Joint(name=name, parent=parent, offset=np.zeros(3), line=line))
            stack.append(len(joints) - 1)
        elif key == "END":
            site, sline = next_tok("'Site'")
            if site.upper() != "SITE":
                raise err(f"expected 'End Site', got 'End {site}'", sline)
            if not stack or stack[-1] == -2:
                raise err("End Site outside a joint block", line)
            parent = stack[-1]
            brace, bline = next_tok("'{'")
            if brace != "{":
                raise err(f"expected '{{' after End Site, got {brace!r}", bline)
            joints.append(
                _Joint(
                    name=f"{joints[parent].name}_end", parent=parent, offset=np.zeros(3), line=line
                )
            )
            stack.append(-2)
            # The End Site's OFFSET belongs to the joint just appended.
            tok2, line2 = next_tok("End Site OFFSET")
            if tok2.upper() != "OFFSET":
                raise err(f"expected OFFSET in End Site, got {tok2!r}", line2)
            joints[-1].offset = np.array([next_float("OFFSET") for _ in range(3)])
        elif key == "OFFSET":
            if not stack or stack[-1] == -2:
                raise err("OFFSET outside a joint block", line)
            joints[stack[-1]].offset = np.array([next_float("OFFSET") for _ in range(3)])
        elif key == "CHANNELS":
            if not stack or stack[-1] == -2:
                raise err("CHANNELS outside a joint block", line)
            joint = joints[stack[-1]]
            if joint.rot_cols or joint.pos_cols:
                raise err(f"second CHANNELS line for joint {joint.name!r}", line)
            count_tok, cline = next_tok("channel count")
            try:
                count = int(count_tok)
            except ValueError:
                raise err(f"expected a channel count, got {count_tok!r}", cline) from None
            if count < 0:
                raise err(f"negative channel count {count}", cline)
            for _ in range(count):
                ch, chline = next_tok("channel name")
                low = ch.lower()
                if low in _ROT_CHANNELS:
                    joint.rot_order += _ROT_CHANNELS[low]
                    joint.rot_cols.append(n_channels)
                elif low in _POS_CHANNELS:
                    if _POS_CHANNELS[low] in joint.pos_axes:
                        raise err(f"duplicate channel {ch!r}", chline)
                    joint.pos_axes.append(_POS_CHANNELS[low])
                    joint.pos_cols.append(n_channels)
                else:
                    raise err(f"unknown channel name {ch!r} (CHANNELS {count} declared)", chline)
                n_channels += 1
        elif tok == "}":
            if not stack:
                raise err("unbalanced '}'", line)
            stack.pop()
            if not stack and pos < n_tok:
                tok3, line3 = toks[pos]
                raise err(f"unexpected {tok3!r} after the ROOT block", line3)
        else:
            raise err(f"unexpected token {tok!r} in HIERARCHY", line)
    if stack:
        raise err(
            "HIERARCHY ends with an unclosed '{' (file truncated?)", toks[-1][1] if toks else 1
        )
    if not joints:
        raise err("HIERARCHY has no ROOT", toks[0][1])
    names = [j.name for j in joints]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise err(f"duplicate joint name {dup!r}", joints[names.index(dup)].line)
    return joints, n_channels


def _parse_motion(
    path: str,
    lines: list[str],
    motion_line: int,
    n_channels: int,
    allow_truncated: bool,
    n_joints: int,
    limits: InputLimits,
) -> tuple[np.ndarray, float]:
    """Parse the MOTION block starting at line index ``motion_line``. Returns (F, C) values, dt.

    The declared frame count and frame time are checked against ``limits`` (frame rate,
    frames, duration, frames x joints) before any frame line is parsed."""
    i = motion_line + 1

    def header(keyword: str) -> tuple[str, int]:
        nonlocal i
        while i < len(lines) and not lines[i].strip():
            i += 1
        if i >= len(lines):
            raise MotionImportError(path, f"MOTION section ends before '{keyword}'", line=i)
        text = lines[i].strip()
        if not text.lower().startswith(keyword.lower()):
            raise MotionImportError(path, f"expected '{keyword}', got {text[:40]!r}", line=i + 1)
        i += 1
        return text[len(keyword) :].strip(), i

    value, fline = header("Frames:")
    try:
        n_frames = int(value)
    except ValueError:
        raise MotionImportError(path, f"bad frame count {value!r}", line=fline) from None
    if n_frames < 0:
        raise MotionImportError(path, f"negative frame count {n_frames}", line=fline)
    value, tline = header("Frame Time:")
    try:
        dt = float(value)
    except ValueError:
        raise MotionImportError(path, f"bad frame time {value!r}", line=tline) from None
    if not np.isfinite(dt) or dt <= 0:
        raise MotionImportError(path, f"frame time must be > 0, got {value!r}", line=tline)
    limits.check_take(n_frames, 1.0 / dt, n_joints)
    n_lines = sum(1 for k in range(i, len(lines)) if not lines[k].isspace() and lines[k])
    if n_lines > n_frames:
        raise MotionImportError(
            path, f"'Frames: {n_frames}' but {n_lines} frame lines follow", line=fline - 1
        )

    rows: list[list[str]] = []
    row_lines: list[int] = []
    for k in range(i, len(lines)):
        toks = lines[k].split()
        if toks:
            rows.append(toks)
            row_lines.append(k + 1)
    counts = np.fromiter((len(r) for r in rows), dtype=np.int64, count=len(rows))
    bad = np.flatnonzero(counts != n_channels)
    if bad.size:
        k = int(bad[0])
        is_last = k == len(rows) - 1
        if is_last and allow_truncated and counts[k] < n_channels:
            rows.pop()
            row_lines.pop()
        else:
            hint = " (file truncated?)" if is_last and counts[k] < n_channels else ""
            raise MotionImportError(
                path,
                f"expected {n_channels} channel values, got {int(counts[k])}{hint}",
                line=row_lines[k],
            )
    if len(rows) > n_frames:
        raise MotionImportError(
            path, f"'Frames: {n_frames}' but {len(rows)} frame lines follow", line=fline - 1
        )
    if len(rows) < n_frames:
        msg = (
            f"'Frames: {n_frames}' but only {len(rows)} complete frame lines present "
            "(file truncated?)"
        )
        if not allow_truncated:
            raise MotionImportError(
                path, msg + "; pass allow_truncated=True to load them", line=fline - 1
            )
        warnings.warn(f"{path}: {msg}; loading {len(rows)} frames", stacklevel=3)
    flat = [tok for row in rows for tok in row]
    try:
        values = np.array(flat, dtype=np.float64)
    except ValueError:
        for row, ln in zip(rows, row_lines, strict=True):
            for tok in row:
                try:
                    float(tok)
                except ValueError:
                    raise MotionImportError(
                        path, f"non-numeric channel value {tok!r}", line=ln
                    ) from None
        raise  # pragma: no cover - numpy rejected something float() accepts
    values = values.reshape(len(rows), n_channels)
    nonfinite = ~np.isfinite(values)
    if nonfinite.any():
        r, c = np.argwhere(nonfinite)[0]
        raise MotionImportError(
            path, f"non-finite value {rows[r][c]!r} in channel {int(c)}", line=row_lines[r]
        )
    return values, dt


@clean_import_errors
def load_bvh(
    path: str | Path,
    *,
    rig: str | None = None,
    drop_first_frame: bool | None = None,
    unit_m: float | None = None,
    name: str | None = None,
    category: str = "unknown",
    allow_truncated: bool = False,
    limits: InputLimits | None = None,
) -> SourceMotion:
    """Read a BVH file into a :class:`SourceMotion` (Y-up world, metres).

    Args:
        path: The ``.bvh`` file.
        rig: Rig key to report; ``None`` detects it from the joint names (``"bandai"``:
            joint_Root/Hips/UpperLeg_L..., ``"cmu_daz"``: hip/abdomen/lThigh..., else
            ``"unknown"``).
        drop_first_frame: Drop frame 0 (the T-pose frame the CMU Daz converter prepends).
            ``None``: drop exactly when the rig is ``"cmu_daz"``.
        unit_m: Metres per file unit. ``None`` infers it: if the zero-pose skeleton's extent along
            y is more than 10 units the file is in centimetres (0.01), otherwise metres (1.0).
        name: Clip id to store; default: the file stem.
        category: Motion category to store.
        allow_truncated: Accept a file with fewer frame lines than ``Frames:`` declares (and a
            cut-off last line), loading the complete frames with a warning. Off by default: such
            a file raises.
        limits: Size and rate limits (:class:`grip.core.limits.InputLimits`), checked on the
            header before any frame is parsed; default :func:`grip.core.limits.active_limits`.

    Returns:
        The clip. ``times_s`` is ``k * Frame Time`` (restarting at 0 after a dropped frame),
        ``rest_rot`` is identity, ``rest_pos`` is the OFFSET skeleton with the root at its OFFSET.

    Raises:
        MotionImportError: Unreadable or inconsistent file, or values above ``limits`` (the
            message names file and line).
    """
    path_s = str(path)
    limits = limits or active_limits()
    text = read_text_bounded(path, limits)
    lines = text.splitlines()
    motion_line = next((k for k, ln in enumerate(lines) if ln.strip().upper() == "MOTION"), None)
    if motion_line is None:
        raise MotionImportError(path_s, "no MOTION section (file truncated?)", line=len(lines))
    joints, n_channels = _parse_hierarchy(path_s, lines, motion_line)
    values, dt = _parse_motion(path_s, lines, motion_line, n_channels, allow_truncated,
                               len(joints), limits)  # fmt: skip

    joint_names = tuple(j.name for j in joints)
    parents = np.array([j.parent for j in joints], dtype=np.int64)
    offsets = np.stack([j.offset for j in joints])
    rig_key = rig if rig is not None else detect_bvh_rig(joint_names)
    if drop_first_frame is None:
        drop_first_frame = rig_key == "cmu_daz"
    if drop_first_frame:
        values = values[1:]
    n_frames = values.shape[0]
    if n_frames == 0:
        raise MotionImportError(path_s, "no frames to load")

    rest_units = rest_fk(parents, offsets)
    if unit_m is None:
        height_units = float(np.ptp(rest_units[:, 1]))
        unit_m = 0.01 if height_units > _CM_HEIGHT_THRESHOLD else 1.0

    n_joints = len(joints)
    local_rot = identity_rotations(n_frames, n_joints)
    local_pos = np.broadcast_to(offsets, (n_frames, n_joints, 3)).copy()
    # One scipy call per distinct Euler order, vectorised over frames and joints.
    by_order: dict[str, list[int]] = {}
    for k, joint in enumerate(joints):
        if joint.rot_order:
            by_order.setdefault(joint.rot_order, []).append(k)
        for axis, col in zip(joint.pos_axes, joint.pos_cols, strict=True):
            local_pos[:, k, axis] = values[:, col]
    for order, idx in by_order.items():
        cols = np.array([joints[k].rot_cols for k in idx])  # (Jg, n_rot)
        angles = values[:, cols]  # (T, Jg, n_rot)
        try:
            mats = Rotation.from_euler(order, angles.reshape(-1, len(order)), degrees=True)
        except ValueError as exc:
            raise MotionImportError(
                path_s,
                f"unsupported rotation channel order {order!r} ({exc})",
                line=joints[idx[0]].line,
            ) from None
        local_rot[:, idx] = mats.as_matrix().reshape(n_frames, len(idx), 3, 3)
    global_rot, global_pos = source_fk(parents, local_rot, local_pos * unit_m)

    rest_pos = rest_units * unit_m
    if rig_key in _TPOSE_RIGS:
        rest_is_tpose = _TPOSE_RIGS[rig_key]
    else:
        extents = np.ptp(rest_pos, axis=0)
        rest_is_tpose = bool(extents[1] >= _STANDING_RATIO * max(extents[0], extents[2]))
    return SourceMotion(
        name=name if name is not None else Path(path).stem,
        path=path_s,
        fmt="bvh",
        rig=rig_key,
        joint_names=joint_names,
        parents=parents,
        times_s=np.arange(n_frames, dtype=np.float64) * dt,
        global_rot=global_rot,
        global_pos=global_pos,
        rest_rot=identity_rotations(n_joints),
        rest_pos=rest_pos,
        up_axis=1,
        unit_m=float(unit_m),
        rest_is_tpose=rest_is_tpose,
        category=category,
    )
