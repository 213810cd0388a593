"""One self-contained interactive HTML page of a reconstruction (``grip view``).

The page shows, in a three.js scene (z up, metres), the body model posed by the reconstruction
(the simulated humanoid for GRIP), the ground truth of the recording as a translucent green
ghost, and other methods' reconstructions of the same recording, each in its own colour, overlaid
or side by side (toggles); the floor and the recording's objects (props, terrain); the centre of
pressure of each foot with its ground reaction force as an arrow (every method that has them, and
the insoles). Under the 3D view: play/pause, speed and a frame slider; a timeline with one lane
per reconstruction in which GRIP's fall events are marked (shaded: the frames replaced from the
history buffer, i.e. recovered; red: the frame the fall was detected); and the vertical GRF of
each foot against the insole force, with a cursor at the current frame; under the timeline, the
pace: the horizontal distance of the reconstruction's pelvis to the pelvis it followed (GRIP: its
kinematic estimate, also drawn in 3D) and of each body's pelvis to the ground truth's.
``#frame=N`` in the page's address opens it at frame ``N``.

Everything is inlined: three.js (MIT; its minified ES module build and ``OrbitControls`` of the
same release, with its licence, from the folder given to :func:`load_web_assets`), the viewer's
script and the data, so the page works offline and from ``file://``. The browser imports three.js
from a ``blob:`` URL made from the inlined source. The data is one JSON document in
``<script id="grip-data" type="application/json">`` (:func:`viewer_data`, read back with
:func:`embedded_data`), escaped so that no name can end the script element.

Data format ``grip-viewer`` version 1 (lengths in integer millimetres, forces in integer newtons,
world frame z up; ``T`` frames, ``J`` = 24 joints; flat lists are row-major):

==================  ==========================================================================
key                 meaning
==================  ==========================================================================
frames, fps         ``T`` and the frame rate, Hz
skeleton            ``parents (J,)``, ``offsets_mm (J, 3)`` (the body model's rest offsets,
                    :class:`grip.core.body.BodyModel`), ``geoms``: its shapes per joint
                    (``kind``, ``pos_mm``, ``size_mm``, ``axis``), in the joint's frame
bodies              per body: ``key``, ``label``, ``role`` (``"reconstruction"`` or
                    ``"ground_truth"``), ``color``, ``opacity``, ``root_mm (T*3)`` pelvis
                    position, ``quat_wxyz (T*J*4)`` world joint rotations times ``quat_scale``
                    (the page runs the forward kinematics), ``grf_n (T*2*3)`` or ``null``,
                    ``cop_mm (T*2*3)`` (``null`` entries off the ground) or ``null``, ``falls``
                    ``[[first replaced frame, detection frame], ...]``, ``mpjpe_mm`` or ``null``
insole              ``force_n (T*2)`` vertical insole force, ``cop_mm (T*2*3)`` (``null`` where
                    the insole has no contact), or ``null`` without both insoles
objects             ``[{name, vertices_mm (V*3), faces (F*3)}]``
floor               ``center_m (2)``, ``size_m (2)`` of the floor plane at z = 0
travel_dir,         unit vectors (x, y) along and across the first body's walk: the camera's
side_dir            start and the offset of the side-by-side layout (``side_step_m`` apart)
pace                ``null``, or ``series``: ``[{body, label, to, color, dist_mm (T)}]`` the
                    horizontal distance of body ``body``'s pelvis to the pelvis it followed
                    (``to`` = ``"followed"``, from ``Reconstruction.ref_root_pos``) or to the
                    ground truth's (``"truth"``), and ``ref_root_mm (T*3)`` the pelvis the
                    first body followed (``null`` if it follows none)
==================  ==========================================================================

Imports numpy, :mod:`grip.core` and :mod:`grip.kinematics.features` (numpy only); the recording
is read through its attributes (``smpl_params``, ``insole``, ``objects``, ``fps``), never by
importing :mod:`prism_tools`.
"""

from __future__ import annotations

import html
import json
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from grip.core import metrics as M
from grip.core import skeleton as sk
from grip.core.body import GRAVITY, BodyModel, BodyParams
from grip.core.fk import joints_from_global
from grip.core.reconstruction import Reconstruction
from grip.core.rotations import matrix_to_quat, quat_to_matrix
from grip.export.common import ExportError, body_model, check_ground_truth, posed_body, write_file
from grip.kinematics.features import GroundTruth, ground_truth, recording_body

__all__ = [
    "DATA_FORMAT",
    "DATA_VERSION",
    "WEB_FILES",
    "ViewerPage",
    "WebAssets",
    "body_joint_positions",
    "check_compatible",
    "embedded_data",
    "load_web_assets",
    "viewer_data",
    "viewer_html",
    "write_viewer",
]

DATA_FORMAT = "grip-viewer"
DATA_VERSION = 1
QUAT_SCALE = 10_000
"""Quaternion components are stored as integers ``round(q * QUAT_SCALE)`` (1e-4 resolution)."""
NEWTONS_PER_M = 1500.0
"""Length scale of the force arrows: 1 m per 1500 N (body weight ~0.5 m)."""
SIDE_STEP_M = 0.9
"""Distance between neighbouring bodies in the side-by-side layout, m."""

WEB_FILES: dict[str, str] = {
    "three_module": "three.module.min.js",
    "orbit_controls": "OrbitControls.js",
    "plots": "plots.js",
    "pace": "pace.js",
    "viewer": "viewer.js",
    "license": "THREE_LICENSE",
}
"""The files :func:`load_web_assets` reads from its folder (``grip/assets/web`` in the
package), by :class:`WebAssets` field."""

_RECON_COLOR = "#2f6fd6"
_GT_COLOR = "#2ca02c"
_GT_OPACITY = 0.45
_COMPARE_COLORS = ("#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22", "#7f7f7f")
_FLOOR_MARGIN_M = 2.0
_MIN_TRAVEL_M = 0.5  # below this the pelvis' heading at frame 0 gives the camera's direction
_UNSAFE_IN_SCRIPT = re.compile(r"</script|<!--", re.IGNORECASE)
_SPECIFIER = re.compile(r"""\bfrom\s*(['"])([^'"]*)\1|\bimport\s*\(""")
_THREE_IMPORT = "from 'three'"


@dataclass(frozen=True)
class WebAssets:
    """The static files every page inlines (see :data:`WEB_FILES`).

    Attributes:
        three_module: three.js's minified ES module build (one self-contained module).
        orbit_controls: three.js's ``OrbitControls`` ES module of the same release; it imports
            only ``'three'``, which the page points at the inlined build.
        plots: The GRF plots and the falls timeline (defines ``gripPlots``).
        pace: The pace plot and 3D marks (defines ``gripPacePlot``, ``gripPaceMarks``).
        viewer: The viewer's script (defines ``gripViewer``).
        license: three.js's licence text, inlined next to it.
    """

    three_module: str
    orbit_controls: str
    plots: str
    pace: str
    viewer: str
    license: str


def load_web_assets(folder: str | os.PathLike) -> WebAssets:
    """Read and check the files of :data:`WEB_FILES` in ``folder``.

    Raises:
        ExportError: A file is missing or unreadable, holds a sequence that would end the
            page's script element (``</script``, ``<!--``), or imports other modules than the
            page provides; the message names the file.
    """
    folder = Path(folder)
    texts: dict[str, str] = {}
    for key, name in WEB_FILES.items():
        path = folder / name
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as e:
            raise ExportError(f"{path}: cannot read the viewer's web asset ({e})") from e
        if _UNSAFE_IN_SCRIPT.search(text):
            raise ExportError(f"{path}: contains '</script' or '<!--' and cannot be inlined")
        specifiers = [m.group(2) if m.group(2) is not None else "import(" for m in
                      _SPECIFIER.finditer(text)] if key != "license" else []  # fmt: skip
        if key == "orbit_controls":
            if _THREE_IMPORT not in text or any(s != "three" for s in specifiers):
                raise ExportError(f"{path}: expected a module that imports only from 'three', "
                                  f"found imports {sorted(set(specifiers))}")  # fmt: skip
        elif specifiers:
            raise ExportError(f"{path}: must not import other modules, found "
                              f"{sorted(set(specifiers))}")  # fmt: skip
        texts[key] = text
    return WebAssets(**texts)


def check_compatible(recon: Reconstruction, other: Reconstruction) -> None:
    """Raise :class:`ExportError` unless ``other`` covers the same frames as ``recon`` (same
    frame rate and frame count), as a reconstruction shown next to it must."""
    if not np.isclose(other.fps, recon.fps):
        raise ExportError(f"reconstruction {other.name!r} ({other.method}) is at {other.fps:g} "
                          f"Hz but {recon.name!r} ({recon.method}) is at {recon.fps:g} Hz: "
                          "compare reconstructions of the same recording")  # fmt: skip
    if other.n_frames != recon.n_frames:
        raise ExportError(f"reconstruction {other.name!r} ({other.method}) has {other.n_frames} "
                          f"frames but {recon.name!r} ({recon.method}) has {recon.n_frames}: "
                          "compare reconstructions of the same recording")  # fmt: skip


# ---------------------------------------------------------------------------------- encoding
def _ints(a: np.ndarray, scale: float) -> list:
    """``a * scale`` rounded, flattened; non-finite entries become ``None`` (JSON ``null``)."""
    v = np.asarray(a, dtype=np.float64).ravel() * scale
    finite = np.isfinite(v)
    out = np.rint(np.where(finite, v, 0.0)).astype(np.int64).tolist()
    if not finite.all():
        for i in np.flatnonzero(~finite):
            out[i] = None
    return out


def _pose(global_rot: np.ndarray, root_pos: np.ndarray) -> dict[str, list]:
    q = matrix_to_quat(global_rot)  # (T, 24, 4) wxyz
    return {"root_mm": _ints(root_pos, 1000.0), "quat_wxyz": _ints(q, QUAT_SCALE)}


def _skeleton(bm: BodyModel) -> dict[str, Any]:
    geoms = [{"joint": int(g.body), "kind": g.kind, "pos_mm": _ints(g.pos, 1000.0),
              "size_mm": [round(1000.0 * float(s), 2) for s in g.size],
              "axis": [round(float(a), 6) for a in g.axis]} for g in bm.geoms]  # fmt: skip
    return {"names": list(sk.JOINT_NAMES), "parents": [int(p) for p in sk.PARENTS],
            "offsets_mm": [[round(1000.0 * float(v), 3) for v in o] for o in bm.offsets],
            "geoms": geoms}  # fmt: skip


def _insole(recording, mass_kg: float) -> dict[str, list] | None:
    """The insoles' vertical force ``(T, 2)`` N and world CoP ``(T, 2, 3)`` (NaN without
    contact), or ``None`` unless both feet have an insole."""
    insole = getattr(recording, "insole", None) or {}
    if not all(f in insole for f in sk.FEET):
        return None
    force = np.stack([np.asarray(insole[f].force, dtype=np.float64)[:, 0] for f in sk.FEET],
                     axis=1) * (mass_kg * GRAVITY)  # fmt: skip
    cop = np.stack([np.asarray(insole[f].CoP_world, dtype=np.float64) for f in sk.FEET], axis=1)
    contact = np.stack([np.asarray(insole[f].contacts, dtype=bool).any(axis=1) for f in sk.FEET],
                       axis=1)  # fmt: skip
    cop[~contact] = np.nan
    return {"force_n": _ints(np.nan_to_num(force, nan=0.0), 1.0), "cop_mm": _ints(cop, 1000.0)}


def _objects(recording) -> list[dict[str, Any]]:
    objects: Mapping[str, Any] = getattr(recording, "objects", None) or {}
    out = []
    for name, obj in objects.items():
        where = f"object {str(name)!r} of recording {getattr(recording, 'name', '?')!r}"
        try:
            v = np.asarray(obj.vertices, dtype=np.float64)
            f = np.asarray(obj.faces)
        except (AttributeError, TypeError, ValueError) as e:
            raise ExportError(f"{where}: needs numeric vertices and faces ({e})") from e
        if v.ndim != 2 or v.shape[1] != 3 or len(v) < 3 or not np.isfinite(v).all():
            raise ExportError(f"{where}: vertices must be finite with shape (V>=3, 3), got "
                              f"{v.shape}")  # fmt: skip
        if (f.ndim != 2 or f.shape[1] != 3 or not len(f) or not np.issubdtype(f.dtype, np.integer)
                or f.min() < 0 or f.max() >= len(v)):  # fmt: skip
            raise ExportError(f"{where}: faces must be integer vertex indices with shape "
                              f"(F>=1, 3), got {f.shape} {f.dtype}")  # fmt: skip
        out.append({"name": str(name), "vertices_mm": _ints(v, 1000.0),
                    "faces": f.astype(np.int64).ravel().tolist()})  # fmt: skip
    return out


def _directions(root_pos: np.ndarray, global_rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit ``(2,)`` vectors along the pelvis' travel (its heading at frame 0 for a clip that
    stays in place) and to its left."""
    d = root_pos[-1, :2] - root_pos[0, :2]
    if np.linalg.norm(d) < _MIN_TRAVEL_M:
        d = (global_rot[0, 0] @ np.array([0.0, 0.0, 1.0]))[:2]  # body frame: z forward
    if np.linalg.norm(d) < 1e-6:
        d = np.array([1.0, 0.0])
    d = d / np.linalg.norm(d)
    return d, np.array([-d[1], d[0]])


def _floor(points_xy: np.ndarray) -> dict[str, list[float]]:
    lo = points_xy.min(axis=0) - _FLOOR_MARGIN_M
    hi = points_xy.max(axis=0) + _FLOOR_MARGIN_M
    return {"center_m": [round(float(c), 3) for c in (lo + hi) / 2],
            "size_m": [round(float(s), 3) for s in hi - lo]}  # fmt: skip


def _recon_body(key: str, label: str, recon: Reconstruction, bm: BodyModel, color: str,
                gt: GroundTruth | None) -> dict[str, Any]:  # fmt: skip
    g_rot, pos = posed_body(recon, bm)
    falls = [[int(a), int(b)] for a, b in recon.falls]
    detail = (f"{recon.name} ({recon.method}): {recon.n_frames} frames at {recon.fps:g} Hz, "
              f"{len(falls)} fall event(s)")  # fmt: skip
    return {
        "key": key, "label": label, "role": "reconstruction", "method": recon.method,
        "name": recon.name, "detail": detail, "color": color, "opacity": 1.0,
        **_pose(g_rot, pos[:, 0]),
        "grf_n": None if recon.grf is None else _ints(recon.grf, 1.0),
        "cop_mm": None if recon.cop is None else _ints(recon.cop, 1000.0),
        "falls": falls,
        "mpjpe_mm": None if gt is None else round(float(M.mpjpe(recon.joint_pos, gt.joint_pos)), 1),
    }  # fmt: skip


def _pace(bodies: Sequence[dict[str, Any]], recons: Sequence[Reconstruction],
          gt: GroundTruth | None) -> dict[str, Any] | None:  # fmt: skip
    """The ``pace`` block: each reconstruction's pelvis to the pelvis it followed and to the
    truth's (``bodies``: their page entries, in the order of ``recons``); ``None`` if there is
    no such distance."""
    series = []
    for b, r in zip(bodies, recons, strict=True):
        targets = [("followed", "to estimate", r.ref_root_pos)]
        targets.append(("truth", "to truth", None if gt is None else gt.root_pos))
        for to, text, other in targets:
            if other is not None:
                d = M.horizontal_distance(r.root_pos, other)
                series.append({"body": b["key"], "label": f"{b['label']} {text}", "to": to,
                               "color": b["color"], "dist_mm": _ints(d, 1000.0)})  # fmt: skip
    if not series:
        return None
    ref = recons[0].ref_root_pos
    return {"series": series, "ref_root_mm": None if ref is None else _ints(ref, 1000.0)}


def viewer_data(
    recon: Reconstruction,
    *,
    recording=None,
    compare: Sequence[Reconstruction] = (),
    compare_labels: Sequence[str] | None = None,
    body: BodyParams | BodyModel | None = None,
    title: str | None = None,
) -> dict[str, Any]:
    """The page's data (format ``grip-viewer``, see the module docstring).

    Args:
        recon: The reconstruction shown first (GRIP's simulated humanoid).
        recording: The recording it was made from (a :class:`prism_tools.Recording`), or
            ``None``: its ground truth (when it has one) becomes a body, its insoles the
            reference force and CoP, its objects props, its subject the body model.
        compare: Other reconstructions of the same recording (same frames and frame rate).
        compare_labels: Their labels (default: their methods).
        body: Body parameters of the drawn body model, on which every body (the ground truth
            too) is posed (default: the recording's subject, else ``BodyParams()``).
        title: Page title (default: the reconstruction's name).

    Raises:
        ExportError: A compared reconstruction, the recording or its ground truth covers other
            frames, or the recording's objects are malformed.
    """
    compare = list(compare)
    labels = list(compare_labels) if compare_labels is not None else [c.method for c in compare]
    if len(labels) != len(compare):
        raise ValueError(f"{len(labels)} compare_labels for {len(compare)} reconstructions")
    for other in compare:
        check_compatible(recon, other)
    gt = None
    insole = None
    objects: list[dict[str, Any]] = []
    if recording is not None:
        n, fps = int(recording.n_frames), float(recording.fps)
        name = getattr(recording, "name", "?")
        if n != recon.n_frames or not np.isclose(fps, recon.fps):
            raise ExportError(f"recording {name!r} has {n} frames at {fps:g} Hz but "
                              f"reconstruction {recon.name!r} has {recon.n_frames} at "
                              f"{recon.fps:g} Hz: pass the recording (or segment) it was made "
                              "from")  # fmt: skip
        subject = recording_body(recording)
        if getattr(recording, "smpl_params", None) is not None:
            gt = ground_truth(recording)
            check_ground_truth(recon, gt)
        body = body if body is not None else subject
        insole = _insole(recording, subject.mass_kg)
        objects = _objects(recording)
    bm = body_model(body)

    bodies = [_recon_body("recon", recon.method, recon, bm, _RECON_COLOR, gt)]
    if gt is not None:
        bodies.append({
            "key": "gt", "label": "ground truth", "role": "ground_truth", "method": "ground truth",
            "name": gt.name, "detail": f"ground truth of {gt.name} (motion capture)",
            "color": _GT_COLOR, "opacity": _GT_OPACITY, **_pose(gt.global_rot, gt.root_pos),
            "grf_n": None, "cop_mm": None, "falls": [], "mpjpe_mm": None,
        })  # fmt: skip
    for i, (other, label) in enumerate(zip(compare, labels, strict=True)):
        color = _COMPARE_COLORS[i % len(_COMPARE_COLORS)]
        bodies.append(_recon_body(f"compare{i}", str(label), other, bm, color, gt))

    travel, side = _directions(recon.root_pos, recon.global_rot)
    roots = [recon.root_pos[:, :2]]
    if gt is not None:
        roots.append(gt.root_pos[:, :2])
    roots += [c.root_pos[:, :2] for c in compare]
    points = np.concatenate([r + k * SIDE_STEP_M * side for k, r in enumerate(roots)])
    if objects:
        verts = np.concatenate([np.reshape(o["vertices_mm"], (-1, 3))[:, :2] / 1000.0
                                for o in objects])  # fmt: skip
        points = np.concatenate([points, verts])
    return {
        "format": DATA_FORMAT,
        "version": DATA_VERSION,
        "title": str(title if title is not None else recon.name),
        "name": recon.name,
        "fps": float(recon.fps),
        "frames": int(recon.n_frames),
        "quat_scale": QUAT_SCALE,
        "newtons_per_m": NEWTONS_PER_M,
        "side_step_m": SIDE_STEP_M,
        "travel_dir": [round(float(v), 6) for v in travel],
        "side_dir": [round(float(v), 6) for v in side],
        "skeleton": _skeleton(bm),
        "bodies": bodies,
        "insole": insole,
        "objects": objects,
        "floor": _floor(points),
        "pace": _pace([b for b in bodies if b["role"] == "reconstruction"], [recon, *compare], gt),
    }


def body_joint_positions(data: Mapping[str, Any], key: str) -> np.ndarray:
    """``(T, 24, 3)`` world joint positions, m, of body ``key`` of the page data: the forward
    kinematics the page runs (rest offsets rotated by the stored world rotations), in numpy."""
    body = next((b for b in data["bodies"] if b["key"] == key), None)
    if body is None:
        raise KeyError(f"no body {key!r} in the viewer data")
    t = int(data["frames"])
    q = np.asarray(body["quat_wxyz"], dtype=np.float64).reshape(t, sk.N_JOINTS, 4)
    rot = quat_to_matrix(q / np.linalg.norm(q, axis=-1, keepdims=True))
    root = np.asarray(body["root_mm"], dtype=np.float64).reshape(t, 3) / 1000.0
    offsets = np.asarray(data["skeleton"]["offsets_mm"], dtype=np.float64) / 1000.0
    return joints_from_global(rot, offsets) + root[:, None]


# ---------------------------------------------------------------------------------- the page
_CSS = """
* { box-sizing: border-box; }
html, body { margin: 0; height: 100%; font: 13px/1.35 system-ui, sans-serif; color: #222; }
body { display: flex; flex-direction: column; background: #f4f5f7; }
header { display: flex; flex-wrap: wrap; gap: 6px 18px; align-items: center; padding: 6px 10px;
  background: #fff; border-bottom: 1px solid #ddd; }
header h1 { font-size: 14px; margin: 0; font-weight: 600; overflow-wrap: anywhere; }
#legend, #options { display: flex; flex-wrap: wrap; gap: 4px 14px; align-items: center; }
.body-toggle { display: inline-flex; gap: 5px; align-items: center; cursor: pointer; }
.swatch { width: 14px; height: 14px; border-radius: 3px; display: inline-block; }
.stat { color: #666; font-size: 12px; }
#options label { cursor: pointer; color: #444; }
#view { position: relative; flex: 1 1 auto; min-height: 260px; overflow: hidden; }
#view canvas { display: block; }
#error { position: absolute; top: 8px; left: 8px; right: 8px; padding: 8px; color: #fff;
  background: #b3261e; border-radius: 4px; white-space: pre-wrap; }
#controls { display: flex; gap: 10px; align-items: center; padding: 4px 10px; background: #fff;
  border-top: 1px solid #ddd; }
#frame { flex: 1 1 auto; }
#clock { font-variant-numeric: tabular-nums; min-width: 230px; text-align: right; color: #444; }
#timeline { display: block; width: 100%; height: 52px; background: #fff; cursor: pointer; }
#pace { display: block; width: 100%; height: 96px; background: #fff; cursor: pointer;
  border-top: 1px solid #eee; }
#pace[hidden] { display: none; }
#plots { display: flex; gap: 4px; background: #f4f5f7; }
#plots canvas { display: block; flex: 1 1 0; min-width: 0; height: 170px; background: #fff;
  cursor: pointer; }
footer { padding: 2px 10px; font-size: 11px; color: #777; background: #fff; }
"""

_BOOTSTRAP = """
(function () {
  "use strict";
  var shown = false;
  function reportError(message) {
    var box = document.getElementById("error");
    box.hidden = false;
    box.textContent = (shown ? box.textContent + "\\n" : "") + String(message);
    shown = true;
    document.body.dataset.error = box.textContent;
  }
  window.addEventListener("error", function (e) { reportError("error: " + e.message); });
  window.addEventListener("unhandledrejection", function (e) {
    var r = e.reason;
    reportError("error: " + (r && r.stack ? r.stack : r));
  });
  function text(id) { return document.getElementById(id).textContent; }
  function moduleUrl(source) {
    return URL.createObjectURL(new Blob([source], { type: "text/javascript" }));
  }
  var threeUrl = moduleUrl(text("three-module"));
  var orbitUrl = moduleUrl(text("three-orbit-controls")
    .split("from 'three'").join("from " + JSON.stringify(threeUrl)));
  Promise.all([import(threeUrl), import(orbitUrl)]).then(function (mods) {
    gripViewer(mods[0], mods[1].OrbitControls, JSON.parse(text("grip-data")), reportError);
  }).catch(function (e) { reportError("error: " + (e && e.stack ? e.stack : e)); });
})();
"""


def _json_for_script(data: Mapping[str, Any]) -> str:
    """JSON that cannot end or comment out the ``<script>`` element it is placed in: ``<``,
    ``>`` and ``&`` (and the JavaScript line separators) are written as ``\\u`` escapes, which
    only occur inside JSON strings."""
    text = json.dumps(data, separators=(",", ":"), allow_nan=False, ensure_ascii=False)
    for ch, esc in (("<", "\\u003c"), (">", "\\u003e"), ("&", "\\u0026"),
                    ("\u2028", "\\u2028"), ("\u2029", "\\u2029")):  # fmt: skip
        text = text.replace(ch, esc)
    return text


def viewer_html(data: Mapping[str, Any], assets: WebAssets) -> str:
    """The page for ``data`` (:func:`viewer_data`) with ``assets`` inlined."""
    title = html.escape(str(data["title"]))
    speeds = "".join(f"<option value=\"{s}\"{' selected' if s == '1' else ''}>{s}x</option>"
                     for s in ("0.1", "0.25", "0.5", "1", "2", "4"))  # fmt: skip
    parts = [
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n',
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n',
        '<meta name="generator" content="grip view">\n',
        f"<title>{title} - GRIP viewer</title>\n<style>{_CSS}</style>\n</head>\n<body>\n",
        f'<header><h1 id="title">{title}</h1><div id="legend"></div><div id="options">',
        '<label><input type="checkbox" id="opt-side"> side by side</label>',
        '<label><input type="checkbox" id="opt-forces"> CoP and GRF</label>',
        '<label><input type="checkbox" id="opt-props"> props</label>',
        '<label><input type="checkbox" id="opt-follow"> follow</label>',
        "</div></header>\n",
        '<main id="view"><div id="error" hidden></div></main>\n',
        '<div id="controls"><button id="play" type="button">Play</button>',
        '<label>speed <select id="speed">',
        speeds,
        '</select></label><input id="frame" type="range" min="0" value="0" step="1" ',
        'aria-label="frame"><span id="clock"></span></div>\n',
        '<canvas id="timeline" title="recoveries: shaded = frames replaced from the history '
        'buffer, red = a fall or a lost humanoid (--lost-gap) detected"></canvas>\n',
        '<canvas id="pace" title="horizontal pelvis distance: solid = to the pelvis the body '
        'followed (its estimate), dashed = to the ground truth"></canvas>\n',
        '<div id="plots"><canvas id="grf-left"></canvas><canvas id="grf-right"></canvas></div>\n',
        "<footer>GRIP viewer: drag to orbit, right-drag to pan, wheel to zoom; space plays, "
        "arrow keys step. 3D rendering by three.js (MIT licence, inlined below).</footer>\n",
        '<script id="grip-data" type="application/json">',
        _json_for_script(data),
        "</script>\n",
        '<script id="three-license" type="text/plain">',
        assets.license,
        "</script>\n",
        '<script id="three-module" type="text/plain">',
        assets.three_module,
        "</script>\n",
        '<script id="three-orbit-controls" type="text/plain">',
        assets.orbit_controls,
        "</script>\n",
        "<script>",
        assets.plots,
        "\n",
        assets.pace,
        "\n",
        assets.viewer,
        "</script>\n",
        "<script>",
        _BOOTSTRAP,
        "</script>\n</body>\n</html>\n",
    ]
    return "".join(parts)


_DATA_BLOCK = re.compile(r'<script id="grip-data" type="application/json">(.*?)</script>', re.S)


def embedded_data(page: str) -> dict[str, Any]:
    """The data of a page written by :func:`viewer_html` (raises ``ValueError`` if absent)."""
    m = _DATA_BLOCK.search(page)
    if m is None:
        raise ValueError("no grip-data block in the page")
    return json.loads(m.group(1))


@dataclass(frozen=True)
class ViewerPage:
    """What :func:`write_viewer` wrote: ``path``, its size in bytes, frames and body labels."""

    path: Path
    n_bytes: int
    frames: int
    labels: tuple[str, ...]


def write_viewer(
    recon: Reconstruction,
    path: str | os.PathLike,
    assets: WebAssets | None = None,
    *,
    recording=None,
    compare: Sequence[Reconstruction] = (),
    compare_labels: Sequence[str] | None = None,
    body: BodyParams | BodyModel | None = None,
    title: str | None = None,
) -> ViewerPage:
    """Write the page (:func:`viewer_data` + :func:`viewer_html`) atomically; ``assets``: the
    three.js files (default: the shipped ones, ``grip/assets/web``).

    Raises:
        ExportError: As :func:`viewer_data`, or the file cannot be written (naming it).
    """
    data = viewer_data(recon, recording=recording, compare=compare,
                       compare_labels=compare_labels, body=body, title=title)  # fmt: skip
    if assets is None:
        from grip.assets import ASSETS

        assets = load_web_assets(ASSETS / "web")
    page = viewer_html(data, assets).encode("utf-8")
    out = write_file(path, lambda f: f.write(page))
    return ViewerPage(out, len(page), int(data["frames"]),
                      tuple(b["label"] for b in data["bodies"]))  # fmt: skip
