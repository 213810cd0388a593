"""Acclaim ASF (skeleton) / AMC (motion) reader, as used by the CMU and HDM05 databases; the ASF
parser itself is :mod:`grip.motion.asf`.

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
from pathlib import Path

import numpy as np

from grip.core.limits import InputLimits, active_limits
from grip.motion.asf import _ROT_DOFS, _TRANS_DOFS, _euler, _strip_comment, load_asf
from grip.motion.source import (
    MotionImportError,
    SourceMotion,
    check_finite,
    clean_import_errors,
    identity_rotations,
    read_text_bounded,
)

_KNOWN_FPS = (24, 25, 30, 50, 60, 100, 120, 240, 480)
_HDM05_NAME = re.compile(r"^HDM_([A-Za-z0-9]+)_")
DEFAULT_FPS = 120.0


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
