"""``grip export`` end to end: in-process with a forced OpenGL failure, and one subprocess run."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from grip.cli.main import main
from grip.core.reconstruction import Reconstruction
from grip.kinematics.features import ground_truth
from prism_tools.io import save_recording
from prism_tools.synthetic import make_recording

T = 200
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("export_cli")
    rec = make_recording(T, seed=5)
    gt = ground_truth(rec)
    grf = np.zeros((T, 2, 3))
    grf[:, :, 2] = gt.insole_force_n
    recon = Reconstruction(name=rec.name, method="test", fps=gt.fps, joint_pos=gt.joint_pos,
                           global_rot=gt.global_rot, grf=grf, contacts=gt.insole_contacts,
                           falls=np.array([[60, 70]]))  # fmt: skip
    recon.save(d / "seg_test.npz")
    save_recording(rec, d / "rec.npz")
    return d / "seg_test.npz", d / "rec.npz"


def test_export_writes_every_format_but_the_video_without_gl(files, tmp_path, monkeypatch,
                                                              capsys) -> None:  # fmt: skip
    import mujoco

    def no_gl(*args, **kwargs):
        raise mujoco.FatalError("an OpenGL platform library has not been loaded")

    monkeypatch.setattr(mujoco, "Renderer", no_gl)
    monkeypatch.setenv("MUJOCO_GL", "egl")  # the command sets it when unset; keep ours clean
    recon, rec = files
    out = tmp_path / "out"
    rc = main(["export", str(recon), "--out", str(out), "--gt", str(rec), "--strobe-every", "40",
               "--glb-frames", "0,-1", "--width", "64", "--height", "48"])  # fmt: skip
    captured = capsys.readouterr()
    assert rc == 1
    assert "MUJOCO_GL=egl" in captured.err and "mp4 of" in captured.err
    assert "Traceback" not in captured.err
    written = sorted(p.name for p in out.iterdir())
    assert written == ["seg_test.bvh", "seg_test.png", "seg_test_f000000.glb",
                       f"seg_test_f{T - 1:06d}.glb", "seg_test_strobe.glb"]  # fmt: skip
    assert "MPJPE_mm 0" in captured.out and "vGRF_N 0" in captured.out
    assert "subject of" in captured.out  # the body came from --gt


def test_export_refuses_bad_input_with_clear_errors(files, tmp_path, capsys) -> None:
    recon, rec = files
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as info:
        main(["export", str(recon), "--out", str(out), "--formats", "bvh,fbx"])
    assert info.value.code == 2 and "fbx" in capsys.readouterr().err
    bad = tmp_path / "broken.npz"
    bad.write_bytes(b"PK\x03\x04 truncated")
    assert main(["export", str(bad), "--out", str(out)]) == 2
    assert "broken.npz" in capsys.readouterr().err
    short = tmp_path / "short.npz"
    Reconstruction.load(recon).slice_frames(0, 50).save(short)
    assert main(["export", str(short), "--out", str(out), "--gt", str(rec)]) == 2
    err = capsys.readouterr().err
    assert "short.npz" in err and "50" in err and str(T) in err
    assert main(["export", str(recon), "--out", str(out), "--glb-frames", str(T)]) == 2
    assert "--glb-frames" in capsys.readouterr().err
    assert not out.exists(), "nothing is written when the input is refused"
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    assert main(["export", str(recon), "--out", str(blocker), "--formats", "bvh"]) == 2
    assert "a_file" in capsys.readouterr().err


def test_console_export_renders_a_video_or_says_why_not(files, tmp_path) -> None:
    """The real command in a fresh process (MUJOCO_GL unset: the command picks EGL)."""
    recon, rec = files
    out = tmp_path / "out"
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    proc = subprocess.run(
        [sys.executable, "-m", "grip.cli.main", "export", str(recon), "--out", str(out),
         "--formats", "mp4,bvh", "--gt", str(rec), "--fps-video", "10", "--width", "96",
         "--height", "64"],
        capture_output=True, text=True, env=env, cwd=REPO, timeout=120,
    )  # fmt: skip
    assert (out / "seg_test.bvh").is_file(), proc.stderr
    if proc.returncode == 1 and "offscreen OpenGL rendering is not available" in proc.stderr:
        pytest.skip("no OpenGL backend on this machine: " + proc.stderr.strip().splitlines()[-2])
    assert proc.returncode == 0, proc.stderr
    import imageio.v2 as imageio

    reader = imageio.get_reader(out / "seg_test.mp4")
    frames = np.stack([f for f in reader])  # (the reader's len() is inf)
    reader.close()
    assert frames.shape == (20, 64, 96, 3)  # 1.99 s at 10 fps -> frames 0..19
    assert frames.std() > 5.0, "the image is not blank"
    assert np.abs(frames[-1].astype(int) - frames[0]).mean() > 1.0, "the body moves"
