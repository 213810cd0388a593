"""``grip view`` and :mod:`grip.export.html`: the page's data, escaping, input errors, and the
page in a headless Chromium (skipped where no chromium binary is installed)."""

from __future__ import annotations

import dataclasses
import html
import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from grip.assets import ASSETS, SAMPLE_RECORDING
from grip.cli.main import main
from grip.core.reconstruction import Reconstruction
from grip.export.common import ExportError, posed_body
from grip.export.html import (
    QUAT_SCALE,
    WEB_FILES,
    body_joint_positions,
    embedded_data,
    load_web_assets,
    viewer_data,
    viewer_html,
    write_viewer,
)
from grip.kinematics.features import ground_truth
from prism_tools.io import load_recording, save_recording
from prism_tools.streams import box_object
from prism_tools.synthetic import make_recording

T = 240
FALL = (150, 170)
SHIFT_M = np.array([0.0, 0.0, 0.03])
HOSTILE = '</script><script>document.body.dataset.pwned="1"</script><!--<b>&amp;'
WEB = ASSETS / "web"


@pytest.fixture(scope="module")
def rec():
    return make_recording(T, seed=7, with_objects=True)


@pytest.fixture(scope="module")
def gt(rec):
    return ground_truth(rec)


def _recon(gt, rec, method: str, *, name: str | None = None, shift=SHIFT_M, fps=None,
           falls=((0, 0),)) -> Reconstruction:  # fmt: skip
    """The ground truth moved by ``shift``, with the insoles' force and CoP as its own."""
    grf = np.zeros((gt.n_frames, 2, 3))
    grf[:, :, 2] = gt.insole_force_n
    cop = np.stack([rec.insole[f].CoP_world for f in ("L_Foot", "R_Foot")], axis=1).astype(float)
    cop[~gt.insole_contacts] = np.nan
    f = np.asarray(falls, dtype=np.int64).reshape(-1, 2)
    return Reconstruction(name=name or rec.name, method=method, fps=fps or gt.fps,
                          joint_pos=gt.joint_pos + shift, global_rot=gt.global_rot, grf=grf,
                          cop=cop, contacts=gt.insole_contacts,
                          falls=f[f[:, 1] > 0])  # fmt: skip


@pytest.fixture(scope="module")
def recon(gt, rec):
    return _recon(gt, rec, "grip", falls=[FALL])


@pytest.fixture(scope="module")
def assets():
    return load_web_assets(WEB)


# ------------------------------------------------------------------------------ the data
def test_data_has_every_frame_and_body(recon, rec, gt) -> None:
    kin = _recon(gt, rec, "kinematics", shift=np.zeros(3))
    kin = dataclasses.replace(kin, grf=None, cop=None)
    pip = _recon(gt, rec, "pip", shift=np.array([0.1, 0.0, 0.0]))
    data = viewer_data(recon, recording=rec, compare=[kin, pip])
    assert data["frames"] == T and data["fps"] == 100.0
    assert [b["key"] for b in data["bodies"]] == ["recon", "gt", "compare0", "compare1"]
    assert [b["label"] for b in data["bodies"]] == ["grip", "ground truth", "kinematics", "pip"]
    assert [b["role"] for b in data["bodies"]] == ["reconstruction", "ground_truth",
                                                   "reconstruction", "reconstruction"]  # fmt: skip
    for b in data["bodies"]:
        assert len(b["root_mm"]) == T * 3 and len(b["quat_wxyz"]) == T * 24 * 4
    assert len(data["bodies"][0]["grf_n"]) == T * 6 and len(data["bodies"][0]["cop_mm"]) == T * 6
    assert data["bodies"][2]["grf_n"] is None and data["bodies"][2]["cop_mm"] is None
    assert data["bodies"][0]["falls"] == [list(FALL)] and data["bodies"][2]["falls"] == []
    # MPJPE against the ground truth: 30 mm shift, 0 and 100 mm
    assert [b["mpjpe_mm"] for b in data["bodies"]] == [30.0, None, 0.0, 100.0]
    assert len(data["insole"]["force_n"]) == T * 2 and len(data["insole"]["cop_mm"]) == T * 6
    [box] = data["objects"]
    assert box["name"] == "BoxSmall" and len(box["vertices_mm"]) == 8 * 3
    assert len(box["faces"]) == 12 * 3
    np.testing.assert_allclose(np.reshape(box["vertices_mm"], (-1, 3)),
                               1000 * rec.objects["BoxSmall"].vertices, atol=0.5)  # fmt: skip
    assert len(data["skeleton"]["geoms"]) >= 24 and len(data["skeleton"]["parents"]) == 24
    # the floor covers every pelvis (side by side too) and the box
    lo = np.array(data["floor"]["center_m"]) - np.array(data["floor"]["size_m"]) / 2
    hi = lo + np.array(data["floor"]["size_m"])
    side = np.array(data["side_dir"]) * data["side_step_m"]
    for k, b in enumerate(data["bodies"]):
        xy = np.reshape(b["root_mm"], (T, 3))[:, :2] / 1000 + k * side
        assert (xy >= lo).all() and (xy <= hi).all()


def _lagging(recon, gt, lead_mps: float = 0.4) -> Reconstruction:
    """``recon`` following a pelvis that walks away from it along y at ``lead_mps``."""
    ref = recon.root_pos.copy()
    ref[:, 1] += lead_mps * np.arange(gt.n_frames) / gt.fps
    return dataclasses.replace(recon, ref_root_pos=ref)


def test_pace_is_the_pelvis_distance_to_what_it_followed_and_to_the_truth(recon, rec,
                                                                         gt) -> None:  # fmt: skip
    lagging = _lagging(recon, gt)
    kin = _recon(gt, rec, "kinematics", shift=np.array([0.3, 0.4, 0.0]))
    pace = viewer_data(lagging, recording=rec, compare=[kin])["pace"]
    assert [(s["body"], s["to"]) for s in pace["series"]] == [
        ("recon", "followed"), ("recon", "truth"), ("compare0", "truth")]  # fmt: skip
    assert [s["label"] for s in pace["series"]] == ["grip to estimate", "grip to truth",
                                                    "kinematics to truth"]  # fmt: skip
    for s in pace["series"]:
        assert len(s["dist_mm"]) == T
    walked_mm = 400 * np.arange(T) / gt.fps  # 0.4 m/s for T frames
    np.testing.assert_allclose(pace["series"][0]["dist_mm"], walked_mm, atol=0.5)
    np.testing.assert_allclose(pace["series"][1]["dist_mm"], 0.0)  # shifted up only
    np.testing.assert_allclose(pace["series"][2]["dist_mm"], 500.0)
    np.testing.assert_allclose(np.reshape(pace["ref_root_mm"], (T, 3)),
                               1000 * lagging.ref_root_pos, atol=0.5)  # fmt: skip
    # without the truth: only what it followed; following nothing and no truth: no pace
    alone = viewer_data(lagging)["pace"]
    assert [s["to"] for s in alone["series"]] == ["followed"]
    assert viewer_data(recon)["pace"] is None
    assert viewer_data(recon, recording=rec)["pace"]["ref_root_mm"] is None


def test_page_pose_is_the_posed_body_to_a_millimetre(recon, rec, gt) -> None:
    data = viewer_data(recon, recording=rec)
    _, want = posed_body(recon, gt.body)
    got = body_joint_positions(data, "recon")
    assert np.abs(got - want).max() < 1e-3
    assert np.abs(body_joint_positions(data, "gt") - gt.joint_pos).max() < 1e-3
    # the shift of the reconstruction survives the encoding
    np.testing.assert_allclose((got - body_joint_positions(data, "gt"))[..., 2], 0.03, atol=1e-3)
    q = np.reshape(data["bodies"][0]["quat_wxyz"], (T, 24, 4)) / QUAT_SCALE
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=2e-4)
    with pytest.raises(KeyError, match="no body 'nope'"):
        body_joint_positions(data, "nope")


def test_off_ground_cop_is_null_and_forces_are_newtons(recon, rec, gt) -> None:
    data = viewer_data(recon, recording=rec)
    cop = data["bodies"][0]["cop_mm"]
    off = ~gt.insole_contacts
    assert off.any() and (~off).any()
    for t, foot in zip(*np.nonzero(off), strict=True):
        assert cop[t * 6 + foot * 3 : t * 6 + foot * 3 + 3] == [None, None, None]
        assert data["insole"]["cop_mm"][t * 6 + foot * 3] is None
    t, foot = (int(v[0]) for v in np.nonzero(~off))
    assert cop[t * 6 + foot * 3 + 1] == round(1000 * recon.cop[t, foot, 1])
    np.testing.assert_allclose(np.reshape(data["insole"]["force_n"], (T, 2)), gt.insole_force_n,
                               atol=0.5)  # fmt: skip
    grf_z = np.reshape(data["bodies"][0]["grf_n"], (T, 2, 3))[..., 2]
    np.testing.assert_allclose(grf_z, recon.grf[..., 2], atol=0.5)


def test_no_recording_gives_one_body_without_insoles(recon) -> None:
    data = viewer_data(recon)
    assert [b["key"] for b in data["bodies"]] == ["recon"]
    assert data["insole"] is None and data["objects"] == []
    assert data["bodies"][0]["mpjpe_mm"] is None


def test_names_are_escaped_and_read_back_exactly(recon, rec, gt, assets) -> None:
    hostile = dataclasses.replace(recon, name=HOSTILE, method=HOSTILE)
    rec_objects = dataclasses.replace(rec, objects={HOSTILE: box_object(np.zeros(3),
                                                                        np.ones(3))})  # fmt: skip
    other = _recon(gt, rec, "kin")
    data = viewer_data(hostile, recording=rec_objects, compare=[other],
                       compare_labels=[HOSTILE], title=HOSTILE)  # fmt: skip
    page = viewer_html(data, assets)
    assert HOSTILE not in page and "<b>" not in page
    # every '</script' closes one of the page's own 6 script elements
    assert len(re.findall(r"</script", page, re.I)) == page.count("<script") == 6
    assert f"<title>{html.escape(HOSTILE)} - GRIP viewer</title>" in page
    back = embedded_data(page)
    assert back["title"] == HOSTILE and back["name"] == HOSTILE
    assert back["bodies"][0]["method"] == HOSTILE and back["bodies"][2]["label"] == HOSTILE
    assert back["objects"][0]["name"] == HOSTILE


def test_other_frames_are_refused_with_the_reason(recon, rec, gt) -> None:
    slow = _recon(gt, rec, "pip", fps=50.0)
    with pytest.raises(ExportError, match=r"\(pip\) is at 50 Hz.*\(grip\) is at 100 Hz"):
        viewer_data(recon, compare=[slow])
    short = recon.slice_frames(0, T - 10)
    with pytest.raises(ExportError, match=f"{T - 10} frames"):
        viewer_data(recon, compare=[short])
    with pytest.raises(ExportError, match=f"has {T} frames.*has {T - 10}"):
        viewer_data(short, recording=rec)
    with pytest.raises(ValueError, match="2 compare_labels for 1"):
        viewer_data(recon, compare=[recon], compare_labels=["a", "b"])


def test_malformed_objects_are_refused_naming_them(recon, rec) -> None:
    bad = dataclasses.replace(box_object(np.zeros(3), np.ones(3)),
                              faces=np.array([[0, 1, 8]]))  # fmt: skip
    with pytest.raises(ExportError, match=r"object 'Stair'.*faces"):
        viewer_data(recon, recording=dataclasses.replace(rec, objects={"Stair": bad}))
    nan = dataclasses.replace(bad, faces=np.array([[0, 1, 2]]),
                              vertices=np.full((8, 3), np.nan))  # fmt: skip
    with pytest.raises(ExportError, match=r"object 'Chair'.*vertices"):
        viewer_data(recon, recording=dataclasses.replace(rec, objects={"Chair": nan}))


def test_web_assets_are_checked(tmp_path) -> None:
    assets = load_web_assets(WEB)
    assert "three.js authors" in assets.license and "gripViewer" in assets.viewer
    assert "from 'three'" in assets.orbit_controls
    for name in WEB_FILES.values():
        shutil.copy(WEB / name, tmp_path / name)
    viewer = tmp_path / WEB_FILES["viewer"]
    viewer.write_text(assets.viewer + "\n// </SCRIPT>\n")
    with pytest.raises(ExportError, match=r"viewer\.js: contains '</script'"):
        load_web_assets(tmp_path)
    viewer.write_text(assets.viewer)
    orbit = tmp_path / WEB_FILES["orbit_controls"]
    orbit.write_text("import { X } from './elsewhere.js';\n" + assets.orbit_controls)
    with pytest.raises(ExportError, match=r"OrbitControls\.js: .*'\./elsewhere\.js'"):
        load_web_assets(tmp_path)
    orbit.unlink()
    with pytest.raises(ExportError, match=r"OrbitControls\.js: cannot read"):
        load_web_assets(tmp_path)


def test_write_viewer_names_an_unwritable_file(recon, assets, tmp_path) -> None:
    (tmp_path / "file").write_text("x")
    with pytest.raises(ExportError, match=r"file/page\.html"):
        write_viewer(recon, tmp_path / "file" / "page.html", assets)


# ------------------------------------------------------------------------------ the command
@pytest.fixture(scope="module")
def files(tmp_path_factory, rec, gt, recon) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("view_cli")
    out = {"recon": d / "seg.grip.npz", "rec": d / "rec.npz", "kin1": d / "a" / "seg.kin.npz",
           "kin2": d / "b" / "other.kin.npz", "slow": d / "seg.slow.npz"}  # fmt: skip
    recon.save(out["recon"])
    save_recording(rec, out["rec"])
    _recon(gt, rec, "kinematics").save(out["kin1"])
    _recon(gt, rec, "kinematics", shift=np.zeros(3)).save(out["kin2"])
    _recon(gt, rec, "pip", fps=50.0).save(out["slow"])
    return out


def test_command_writes_one_page_with_every_body(files, tmp_path, capsys) -> None:
    page = tmp_path / "new" / "seg.html"
    rc = main(["view", str(files["recon"]), "--gt", str(files["rec"]),
               "--compare", str(files["kin1"]), "--compare", str(files["kin2"]),
               "--out", str(page)])  # fmt: skip
    out = capsys.readouterr().out
    assert rc == 0
    data = embedded_data(page.read_text(encoding="utf-8"))
    assert data["frames"] == T and len(data["bodies"]) == 4
    # the same method twice: told apart by the file name
    assert [b["label"] for b in data["bodies"]] == ["grip", "ground truth",
                                                    "kinematics (seg.kin.npz)",
                                                    "kinematics (other.kin.npz)"]  # fmt: skip
    assert f"wrote {page} (" in out and f"{T} frames, 4 bodies" in out
    assert "1 fall event(s)" in out


def test_command_tells_two_runs_of_one_method_apart(files, recon, tmp_path) -> None:
    """Two policies' reconstructions of one recording (both "grip", the same file name in two
    folders): the compared one is labelled with its folder."""
    other = tmp_path / "shipped" / files["recon"].name
    recon.save(other)
    page = tmp_path / "two.html"
    assert main(["view", str(files["recon"]), "--compare", str(other), "--out", str(page)]) == 0
    data = embedded_data(page.read_text(encoding="utf-8"))
    assert [b["label"] for b in data["bodies"]] == ["grip", "grip (shipped)"]


def test_grip_export_writes_the_page_as_its_html_format(files, tmp_path, capsys) -> None:
    out = tmp_path / "ex"
    assert main(["export", str(files["recon"]), "--gt", str(files["rec"]), "--formats", "html",
                 "--out", str(out)]) == 0  # fmt: skip
    assert sorted(p.name for p in out.iterdir()) == ["seg.grip.html"]
    data = embedded_data((out / "seg.grip.html").read_text(encoding="utf-8"))
    assert data["frames"] == T and len(data["bodies"]) == 2  # the reconstruction and --gt
    assert "2 bodies" in capsys.readouterr().out


@pytest.mark.parametrize("case", ["not_npz", "no_joints", "other_fps", "bad_gt"])
def test_command_errors_name_the_file(case, files, tmp_path, capsys) -> None:
    recon, args = files["recon"], []
    if case == "not_npz":
        recon = tmp_path / "notes.npz"
        recon.write_text("not a zip file")
        want = [str(recon), "not a readable .npz"]
    elif case == "no_joints":
        recon = tmp_path / "nojoints.npz"
        meta = {"format": "grip-reconstruction", "version": 1, "name": "x", "method": "m",
                "fps": 100.0}  # fmt: skip
        np.savez(recon, __meta__=np.array(json.dumps(meta)), falls=np.zeros((0, 2), np.int64),
                 global_rot=np.tile(np.eye(3), (5, 24, 1, 1)))  # fmt: skip
        want = [str(recon), "no joint positions ('joint_pos'"]
    elif case == "other_fps":
        args = ["--compare", str(files["kin1"]), str(files["slow"])]
        want = [f"--compare {files['slow']}", "50 Hz", "100 Hz"]
    else:
        args = ["--gt", str(files["kin1"])]
        want = [str(files["kin1"]), "cannot read the recording"]
    page = tmp_path / "page.html"
    rc = main(["view", str(recon), *args, "--out", str(page)])
    err = capsys.readouterr().err
    assert rc == 2, err
    for text in want:
        assert text in err
    assert "Traceback" not in err and not page.exists()


# ------------------------------------------------------------------------------ in a browser
def _find_chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        path = shutil.which(name)
        if path:
            return path
    return None


CHROMIUM = _find_chromium()
needs_browser = pytest.mark.skipif(
    CHROMIUM is None,
    reason="no chromium binary on PATH (Debian: apt-get install chromium); the page is not "
    "checked in a headless browser",
)
# WebGL messages of the software renderer, not of the page
_GL_NOISE = ('"[.WebGL-', '"[]Automatic fallback to software WebGL')


def _browse(page: Path, tmp: Path, *args: str, fragment: str = "") -> tuple[str, list[str]]:
    """Open ``page`` in headless Chromium (SwiftShader WebGL); returns stdout and the console
    lines of the page (WebGL driver notes left out)."""
    cmd = [CHROMIUM, "--headless=new", "--disable-gpu", "--no-sandbox",
           "--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--enable-logging=stderr",
           "--v=0", f"--user-data-dir={tmp / 'chromium-profile'}", "--virtual-time-budget=5000",
           "--window-size=1200,900", *args, page.as_uri() + fragment]  # fmt: skip
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    assert run.returncode == 0, run.stderr[-3000:]
    console = [ln for ln in run.stderr.splitlines()
               if ":CONSOLE" in ln and not any(n in ln for n in _GL_NOISE)]  # fmt: skip
    return run.stdout, console


def _body_attrs(dom: str) -> dict[str, str]:
    tag = re.search(r"<body([^>]*)>", dom)
    assert tag is not None, dom[:500]
    return {k: html.unescape(v) for k, v in re.findall(r'([\w-]+)="([^"]*)"', tag.group(1))}


@needs_browser
def test_page_builds_its_scene_in_a_browser_without_errors(recon, rec, gt, assets,
                                                           tmp_path) -> None:  # fmt: skip
    hostile = dataclasses.replace(_lagging(recon, gt), name=HOSTILE)  # its estimate drawn too
    other = _recon(gt, rec, "kinematics", shift=np.zeros(3))
    page = write_viewer(hostile, tmp_path / "page.html", assets, recording=rec, compare=[other],
                        compare_labels=[HOSTILE]).path  # fmt: skip
    dom, console = _browse(page, tmp_path, "--dump-dom", fragment="#frame=160&side=1")
    attrs = _body_attrs(dom)
    assert attrs.get("data-ready") == f"{T},3", attrs
    assert "data-error" not in attrs and "data-pwned" not in attrs
    assert console == []
    title = re.search(r'<h1 id="title">(.*?)</h1>', dom, re.S)
    assert title is not None and html.unescape(title.group(1)) == HOSTILE
    assert re.search(r'<span id="clock">frame 160 / 239', dom)
    assert re.search(r'<canvas id="pace"[^>]*>', dom) and not re.search(
        r'<canvas id="pace"[^>]*hidden', dom)  # fmt: skip
    # following nothing, without the truth: no pace plot
    bare = write_viewer(recon, tmp_path / "bare.html", assets).path
    dom, console = _browse(bare, tmp_path, "--dump-dom")
    assert _body_attrs(dom).get("data-ready") == f"{T},1" and console == []
    assert re.search(r'<canvas id="pace"[^>]*hidden', dom)


@needs_browser
def test_a_script_error_in_the_page_is_reported(recon, assets, tmp_path) -> None:
    data = viewer_data(recon)
    data["version"] = 99
    page = tmp_path / "broken.html"
    page.write_text(viewer_html(data, assets), encoding="utf-8")
    dom, _ = _browse(page, tmp_path, "--dump-dom")
    attrs = _body_attrs(dom)
    assert "data-ready" not in attrs
    assert "not a grip-viewer data block" in attrs["data-error"]


@needs_browser
def test_without_webgl_the_timeline_and_plots_still_work(recon, rec, assets, tmp_path) -> None:
    page = write_viewer(recon, tmp_path / "page.html", assets, recording=rec).path
    dom, _ = _browse(page, tmp_path, "--disable-3d-apis", "--dump-dom", fragment="#frame=42")
    attrs = _body_attrs(dom)
    assert "the 3D view needs WebGL" in attrs["data-error"]
    assert attrs["data-ready"] == f"{T},2"
    assert re.search(r'<span id="clock">frame 42 / 239', dom)


def _blue_pixels(png: Path) -> int:
    """Pixels of the reconstruction's blue in the middle of the 3D view (above the controls)."""
    import matplotlib.image

    img = matplotlib.image.imread(png)[..., :3]
    h, w = img.shape[:2]
    mid = img[int(0.12 * h) : int(0.6 * h), int(0.2 * w) : int(0.8 * w)]
    r, g, b = mid[..., 0], mid[..., 1], mid[..., 2]
    return int(((b - r > 0.25) & (b - g > 0.1)).sum())


@needs_browser
def test_screenshot_shows_the_body(assets, tmp_path) -> None:
    # the shipped walk: a standing body (the synthetic recordings' ground truth lies flat)
    sample = load_recording(SAMPLE_RECORDING)
    recon = _recon(ground_truth(sample), sample, "grip", shift=np.array([0.0, 0.3, 0.0]))
    data = viewer_data(recon, recording=sample)
    page = tmp_path / "page.html"
    page.write_text(viewer_html(data, assets), encoding="utf-8")
    png = tmp_path / "shot.png"
    _browse(page, tmp_path, f"--screenshot={png}", fragment="#frame=250")
    assert png.stat().st_size > 10_000
    blue = _blue_pixels(png)
    assert blue > 3000, blue
    # the same page with a grey body: the count sees the body, not the page around it
    data["bodies"][0]["color"] = "#808080"
    grey = tmp_path / "grey.html"
    grey.write_text(viewer_html(data, assets), encoding="utf-8")
    png_grey = tmp_path / "grey.png"
    _browse(grey, tmp_path, f"--screenshot={png_grey}", fragment="#frame=250")
    assert _blue_pixels(png_grey) < blue / 20
