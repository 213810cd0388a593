"""Every export refuses a reconstruction whose rotations are not rotations (issue 50): zero
matrices and reflections were written as BVH, glTF, MP4 and PNG (only the AMASS export refused
them); now each writer names the file, the joint, the frame and what is wrong, and writes
nothing."""

from __future__ import annotations

import numpy as np
import pytest

from grip.core.body import BodyParams, build_body
from grip.core.fk import forward_kinematics, rest_pose
from grip.core.reconstruction import Reconstruction
from grip.export import export_reconstruction
from grip.export.bvh import write_bvh
from grip.export.common import ExportError, check_rotations
from grip.export.glb import write_pose_glb, write_strobe_glb
from grip.export.summary import write_summary_png
from grip.export.video import write_video


def _recon(bad: str | None) -> Reconstruction:
    body = build_body(BodyParams())
    local, root = rest_pose(6)
    root[:] = [0.0, 0.0, body.pelvis_height]
    rot, pos = forward_kinematics(local, root, body.offsets)
    if bad == "zero":
        rot[3, 5] = 0.0  # frame 3, joint 5 (R_Knee)
    elif bad == "reflection":
        rot[3, 5] = rot[3, 5] @ np.diag([1.0, 1.0, -1.0])
    return Reconstruction(name="r", method="test", fps=50.0, joint_pos=pos, global_rot=rot)


WRITERS = {
    "bvh": lambda r, p: write_bvh(r, p / "x.bvh"),
    "glb": lambda r, p: write_strobe_glb(r, p / "x_strobe.glb"),
    "pose_glb": lambda r, p: write_pose_glb(r, p / "x.glb", 3),
    "png": lambda r, p: write_summary_png(r, p / "x.png"),
    "mp4": lambda r, p: write_video(r, p / "x.mp4"),
}


@pytest.mark.parametrize("bad", ["zero", "reflection"])
@pytest.mark.parametrize("fmt", list(WRITERS))
def test_every_writer_refuses_what_is_not_a_rotation(tmp_path, fmt, bad) -> None:
    with pytest.raises(ExportError, match=r"x[_a-z]*\.(bvh|glb|png|mp4): reconstruction 'r': "
                                          r"global_rot of joint R_Knee at frame 3 is not a "
                                          r"rotation"):  # fmt: skip
        WRITERS[fmt](_recon(bad), tmp_path)
    assert not list(tmp_path.iterdir())


def test_export_reconstruction_refuses_them_in_every_format(tmp_path) -> None:
    written, failed = export_reconstruction(_recon("reflection"), tmp_path,
                                            ["bvh", "glb", "png", "amass", "html"],
                                            stem="x")  # fmt: skip
    assert written == [] and sorted(failed) == ["amass", "bvh", "glb", "html", "png"]
    assert all("R_Knee at frame 3 is not a rotation" in m and "det -1" in m
               for m in failed.values()), failed  # fmt: skip
    assert not list(tmp_path.iterdir())


def test_proper_rotations_pass(tmp_path) -> None:
    check_rotations(_recon(None))
    assert write_bvh(_recon(None), tmp_path / "ok.bvh").is_file()


@pytest.mark.parametrize("command", ["export", "view"])
def test_the_html_commands_refuse_them(tmp_path, capsys, command) -> None:
    from grip.cli.main import main

    path = tmp_path / "r.npz"
    _recon("zero").save(path)
    page = tmp_path / "v.html"
    argv = ["view", str(path), "--out", str(page)]
    if command == "export":
        argv = ["export", str(path), "--formats", "html", "--out", str(tmp_path / "out")]
    assert main(argv) != 0
    err = capsys.readouterr().err
    assert "R_Knee at frame 3 is not a rotation" in err and "Traceback" not in err, err
    assert not page.exists() and not (tmp_path / "out" / "r.html").exists()
