"""Hostile and absurd input files (issue 30, items 4 and 6): every loader refuses them quickly,
with the project's own error type naming the file, the value and the limit, and the batch
commands report a bad file, skip it and exit non-zero at the end.

Every fixture is tiny and made here; nothing large is ever allocated (a "2 GB" npz member is an
npy header that claims it).
"""

from __future__ import annotations

import json
import struct
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from grip.core.limits import LIMITS_ENV, InputLimits
from prism_tools.errors import RecordingError
from prism_tools.io import _npz_writer, load_prism_dict, load_recording, save_recording
from prism_tools.synthetic import make_recording


@pytest.fixture(autouse=True)
def _default_limits(monkeypatch) -> None:
    """Every test starts from the default limits and leaves ``$GRIP_LIMITS`` as it was."""
    monkeypatch.delenv(LIMITS_ENV, raising=False)


def _write_raw_npz(rec_dict: dict, path: Path) -> Path:
    """Writes a PRISM dict as our npz without validating it (as a foreign tool might)."""
    with path.open("wb") as f:
        _npz_writer(rec_dict, path)(f)
    return path


def _npy_header(shape: tuple[int, ...], descr: str = "<f8") -> bytes:
    header = f"{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape!r}, }}"
    header += " " * (63 - (10 + len(header)) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode("latin1")


# ------------------------------------------------------------------------ pickles (item 4, 6)
def test_tiny_pickle_cannot_ask_for_a_huge_bytearray(tmp_path) -> None:
    path = tmp_path / "bomb.pkl"
    path.write_bytes(b"c__builtin__\nbytearray\n(I5300000000\ntR.")  # 38 bytes -> 5.3 GB
    t0 = time.perf_counter()
    with pytest.raises(RecordingError, match=r"bomb\.pkl: .*bytearray.*max_array_bytes"):
        load_prism_dict(path)
    assert time.perf_counter() - t0 < 1.0


def test_pickle_sizes_follow_the_limits(tmp_path, monkeypatch) -> None:
    path = tmp_path / "big.pkl"
    path.write_bytes(b"c__builtin__\nbytearray\n(I50000000\ntR.")  # 50 MB
    monkeypatch.setenv(LIMITS_ENV, "max_array_bytes=1e6")
    with pytest.raises(RecordingError, match=r"big\.pkl: .*max_array_bytes=1000000"):
        load_prism_dict(path)
    # Containers built from a range and numpy arrays declared by shape are bounded too.
    monkeypatch.setenv(LIMITS_ENV, "max_array_bytes=1e6,max_elements=1e5")
    path.write_bytes(b"c__builtin__\nlist\n(c__builtin__\nrange\n(I2000000\ntRtR.")
    with pytest.raises(RecordingError, match="max_elements"):
        load_prism_dict(path)
    path.write_bytes(b"cnumpy\nndarray\n((I1000000\ntS'f8'\ntR.")
    with pytest.raises(RecordingError, match="max_array_bytes"):
        load_prism_dict(path)


def test_pickle_with_an_unknown_codec_is_a_clean_error(tmp_path) -> None:
    path = tmp_path / "codec.pkl"
    path.write_bytes(b"c_codecs\nencode\n(Vabc\nVno-such-codec\ntR.")
    with pytest.raises(RecordingError, match=r"codec\.pkl: .*_codecs\.encode"):
        load_recording(path)


def test_deeply_nested_pickle_is_refused(tmp_path) -> None:
    n = 200_000
    key = b"info"
    data = (b"\x80\x02}X" + struct.pack("<I", len(key)) + key + b"]" * n + b"a" * (n - 1)
            + b"s.")  # fmt: skip
    path = tmp_path / "deep.pkl"
    path.write_bytes(data)
    with pytest.raises(RecordingError, match=r"deep\.pkl: .*max_depth=64"):
        load_recording(path)


def test_pickle_memo_slot_bomb_is_refused_before_unpickling(tmp_path) -> None:
    """A damaged pickle storing to memo slot 499,103,675 (found by tests/test_fuzz_inputs.py: the
    C unpickler grows its memo array to that size, 4 GB and 20 s) is refused by the opcode scan."""
    path = tmp_path / "memo.pkl"
    path.write_bytes(b"\x80\x04N" + b"r" + struct.pack("<I", 499_103_675) + b".")
    t0 = time.perf_counter()
    with pytest.raises(RecordingError, match=r"memo\.pkl: .*memo slot 499103675"):
        load_recording(path)
    assert time.perf_counter() - t0 < 1.0


# ------------------------------------------------------------------------------ npz (item 4, 6)
def test_npz_member_claiming_2gb_is_refused_before_loading(tmp_path) -> None:
    path = tmp_path / "zeros.npz"
    rec = make_recording(20, seed=0)
    _write_raw_npz(rec.to_prism_dict(), path)
    with zipfile.ZipFile(path, "a") as zf:
        zf.writestr("extra/zeros.npy", _npy_header((2**28, 1)) + b"\0" * 4096)
    t0 = time.perf_counter()
    with pytest.raises(RecordingError, match=r"zeros\.npz: .*'extra/zeros'.*max_array_bytes"):
        load_recording(path)
    assert time.perf_counter() - t0 < 2.0


@pytest.mark.parametrize(
    ("meta", "match"),
    [
        ("[" * 200_000 + "]" * 200_000, "max_depth=64"),
        ('{"format": "grip-prism-npz", "version": 1, "tree": {"x": ' + "9" * 5000 + "}}",
         "max_int_digits=100"),
    ],
    ids=["deep", "digits"],
)
def test_npz_metadata_depth_and_digits(tmp_path, meta, match) -> None:
    path = tmp_path / "meta.npz"
    np.savez(path, **{"__meta__.json": np.array(meta)})
    with pytest.raises(RecordingError, match=rf"meta\.npz: .*{match}"):
        load_recording(path)


def test_truncated_and_corrupt_npz_are_clean_errors(tmp_path) -> None:
    good = tmp_path / "good.npz"
    save_recording(make_recording(50, seed=1), good)
    data = good.read_bytes()
    cut = tmp_path / "cut.npz"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(RecordingError, match=r"cut\.npz"):
        load_recording(cut)
    flipped = bytearray(data)
    for k in range(200, 260):  # inside the first member's deflate stream
        flipped[k] ^= 0xFF
    bad = tmp_path / "flipped.npz"
    bad.write_bytes(bytes(flipped))
    with pytest.raises(RecordingError, match=r"flipped\.npz"):
        load_recording(bad)


# ------------------------------------------------------------------- rotations and plausibility
def test_every_frame_rotation_is_checked(tmp_path) -> None:
    n = 5000
    old_sample = set(np.unique(np.linspace(0, n - 1, 4096).astype(np.int64)).tolist())
    frame = next(k for k in range(1, n) if k not in old_sample)
    d = make_recording(n, seed=2).to_prism_dict()
    d["imu"]["L_Wrist"]["ori_world"][frame] = 0.0
    path = _write_raw_npz(d, tmp_path / "zero_rot.npz")
    with pytest.raises(RecordingError, match=rf"imu\.L_Wrist\.ori_world: not a rotation matrix "
                                             rf"at frame {frame}\b"):  # fmt: skip
        load_recording(path)


def test_rotation_check_is_fast() -> None:
    from prism_tools.validation import _check_rotations

    rot = np.broadcast_to(np.eye(3), (200_000, 3, 3))
    t0 = time.perf_counter()
    _check_rotations(rot, "x")
    assert time.perf_counter() - t0 < 2.0


def _scaled(tmp_path: Path, name: str, edit) -> Path:
    d = make_recording(120, seed=3).to_prism_dict()
    edit(d)
    return _write_raw_npz(d, tmp_path / name)


def test_absurd_values_name_the_probable_unit(tmp_path) -> None:
    def acc(d):
        d["imu"]["L_Foot"]["acc_local_raw"] *= 1000.0

    def force(d):
        d["insole"]["R_Foot"]["force"] *= 700.0

    def trans(d):
        walk = np.linspace(0.0, 1.8, len(d["smpl_params"]["trans"]))
        d["smpl_params"]["trans"] = (d["smpl_params"]["trans"] + walk[:, None]) * 1000.0

    def spike(d):
        d["imu"]["L_Foot"]["acc_local_raw"][7] = 1e30

    cases = [(acc, r"median acc magnitude .* m/s\^2 .*mm/s\^2.*max_typical_acc_mps2"),
             (spike, r"acc magnitude 1.73e\+30 m/s\^2 .*corrupt samples.*max_acc_mps2"),
             (force, r"insole force .* body weights .*newtons.*max_force_bw"),
             (trans, r"trans: spans .* m \(millimetres\?\).*max_position_m")]  # fmt: skip
    for k, (edit, match) in enumerate(cases):
        path = _scaled(tmp_path, f"absurd{k}.npz", edit)
        with pytest.raises(RecordingError, match=rf"absurd{k}\.npz: .*{match}"):
            load_recording(path)
    path = _scaled(tmp_path, "grams.npz", lambda d: d["insole"]["L_Foot"].update(
        force=d["insole"]["L_Foot"]["force"] * 7e5))  # fmt: skip
    with pytest.raises(RecordingError, match="grams or Pa"):
        load_recording(path)
    # A genuine outlier take loads with the limit raised.
    lifted = InputLimits(max_acc_mps2=float("inf"), max_typical_acc_mps2=float("inf"))
    assert load_recording(tmp_path / "absurd0.npz", limits=lifted).n_frames == 120
    # A glitch of motion capture differentiated twice (700 g at one sample) is no unit error.
    glitch = _scaled(tmp_path, "glitch.npz", lambda d: d["imu"]["L_Foot"]["acc_local_raw"].
                     __setitem__(7, [7000.0, 0.0, 0.0]))  # fmt: skip
    assert load_recording(glitch).n_frames == 120


def test_recording_duration_and_rate_limits(tmp_path, monkeypatch) -> None:
    path = tmp_path / "long.npz"
    save_recording(make_recording(300, seed=4), path)
    monkeypatch.setenv(LIMITS_ENV, "max_duration_s=2")
    with pytest.raises(RecordingError, match=r"long\.npz: .*3 s is above the limit "
                                             r"max_duration_s=2"):  # fmt: skip
        load_recording(path)
    monkeypatch.setenv(LIMITS_ENV, "max_fps=50")
    with pytest.raises(RecordingError, match="max_fps=50"):
        load_recording(path)
    monkeypatch.delenv(LIMITS_ENV)
    assert load_recording(path).n_frames == 300


# -------------------------------------------------------------------------- motion importers
def _bvh(frames: int, frame_time: float, lines: int) -> str:
    return ("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition "
            "Zposition Zrotation Xrotation Yrotation\n  End Site\n  {\n    OFFSET 0 10 0\n  }\n}\n"
            f"MOTION\nFrames: {frames}\nFrame Time: {frame_time}\n"
            + "0 90 0 0 0 0\n" * lines)  # fmt: skip


def test_bvh_rate_and_duration_are_checked_before_parsing(tmp_path) -> None:
    from grip.motion.bvh import load_bvh
    from grip.motion.source import MotionImportError

    slow = tmp_path / "slow.bvh"
    slow.write_text(_bvh(3, 1800, 3))  # 3 frames -> a 1-hour clip
    with pytest.raises(MotionImportError, match=r"slow\.bvh: frame rate 0\.000556 Hz .*min_fps"):
        load_bvh(slow)
    long = tmp_path / "long.bvh"
    long.write_text(_bvh(2_000_000, 0.01, 3))
    with pytest.raises(MotionImportError, match=r"long\.bvh: .*max_frames=500000"):
        load_bvh(long)
    genuine = InputLimits(min_fps=1e-4, max_duration_s=1e4)
    assert load_bvh(tmp_path / "slow.bvh", limits=genuine).num_frames == 3


def test_amass_low_rate_and_corrupt_member(tmp_path) -> None:
    from grip.motion.amass import load_amass_npz
    from grip.motion.source import MotionImportError

    path = tmp_path / "slow.npz"
    np.savez(path, poses=np.zeros((3, 72)), trans=np.zeros((3, 3)), mocap_framerate=0.01)
    with pytest.raises(MotionImportError, match=r"slow\.npz: frame rate 0\.01 Hz .*min_fps"):
        load_amass_npz(path)
    big = tmp_path / "big.npz"
    with zipfile.ZipFile(big, "w") as zf:
        zf.writestr("poses.npy", _npy_header((2**24, 72)) + b"\0" * 64)
    with pytest.raises(MotionImportError, match=r"big\.npz: .*'poses'.*max_array_bytes"):
        load_amass_npz(big)
    good = tmp_path / "good.npz"
    np.savez_compressed(good, poses=np.random.default_rng(0).normal(size=(400, 72)),
                        trans=np.zeros((400, 3)), mocap_framerate=120.0)  # fmt: skip
    data = bytearray(good.read_bytes())
    for k in range(300, 400):
        data[k] ^= 0xFF
    bad = tmp_path / "bad.npz"
    bad.write_bytes(bytes(data))
    with pytest.raises(MotionImportError, match=r"bad\.npz"):
        load_amass_npz(bad)


def test_deepmimic_rate_and_depth(tmp_path) -> None:
    from grip.motion.deepmimic import humanoid3d_skeleton, load_deepmimic
    from grip.motion.source import MotionImportError

    size = humanoid3d_skeleton().frame_size
    frame = [1800.0, 0, 0.9, 0, 1, 0, 0, 0] + [1.0, 0, 0, 0] * 20
    frames = [frame[:size] for _ in range(3)]
    slow = tmp_path / "slow.txt"
    slow.write_text(json.dumps({"Loop": "none", "Frames": frames}))
    with pytest.raises(MotionImportError, match=r"slow\.txt: .*min_fps"):
        load_deepmimic(slow)
    deep = tmp_path / "deep.txt"
    deep.write_text('{"Frames": ' + "[" * 200_000 + "]" * 200_000 + "}")
    with pytest.raises(MotionImportError, match=r"deep\.txt: .*max_depth"):
        load_deepmimic(deep)


def test_amc_rate_is_checked(tmp_path) -> None:
    from grip.motion.asf_amc import load_amc
    from grip.motion.source import MotionImportError

    amc = tmp_path / "clip.amc"
    amc.write_text(":FULLY-SPECIFIED\n:DEGREES\n1\nroot 0 0 0 0 0 0\n")
    asf = tmp_path / "clip.asf"
    asf.write_text(":version 1.10\n:name t\n:units\n  length 1\n  angle deg\n:root\n"
                   "  order TX TY TZ RX RY RZ\n  axis XYZ\n  position 0 0 0\n"
                   "  orientation 0 0 0\n:bonedata\n  begin\n    id 1\n    name a\n"
                   "    direction 0 1 0\n    length 1\n    axis 0 0 0 XYZ\n  end\n"
                   ":hierarchy\n  begin\n    root a\n  end\n")  # fmt: skip
    with pytest.raises(MotionImportError, match=r"clip\.amc: frame rate 0\.01 Hz .*min_fps"):
        load_amc(amc, asf, fps=0.01)
    assert load_amc(amc, asf, fps=120.0).num_frames == 1


# --------------------------------------------------------------- project files (npz + JSON)
def test_motion_reconstruction_and_reference_files(tmp_path) -> None:
    from grip.core.reconstruction import Reconstruction, ReconstructionError
    from grip.core.reference import ReferenceError, ReferenceSet
    from grip.motion.motion import Motion, MotionError

    deep = "[" * 200_000 + "]" * 200_000
    digits = '{"format": "grip-reconstruction", "version": 1, "fps": ' + "9" * 5000 + "}"
    p = tmp_path / "motion.npz"
    np.savez(p, fps=100.0, root_pos=np.zeros((2, 3)), local_quat=np.zeros((2, 24, 4)),
             body=np.zeros(2), meta_json=np.array(deep))  # fmt: skip
    with pytest.raises(MotionError, match=r"motion\.npz: .*max_depth"):
        Motion.load(p)
    p = tmp_path / "recon.npz"
    np.savez(p, joint_pos=np.zeros((2, 24, 3)), __meta__=np.array(digits))
    with pytest.raises(ReconstructionError, match=r"recon\.npz: .*max_int_digits"):
        Reconstruction.load(p)
    p = tmp_path / "slow_recon.npz"
    np.savez(p, joint_pos=np.zeros((3, 24, 3)), global_rot=np.zeros((3, 24, 3, 3)),
             __meta__=np.array(json.dumps({"format": "grip-reconstruction", "version": 1,
                                           "fps": 1 / 1800, "name": "x", "method": "y"})))
    with pytest.raises(ReconstructionError, match=r"slow_recon\.npz: .*min_fps"):
        Reconstruction.load(p)
    p = tmp_path / "ref.npz"
    np.savez(p, __meta__=np.array(deep))
    with pytest.raises(ReferenceError, match=r"ref\.npz: .*max_depth"):
        ReferenceSet.load(p)
    p.write_bytes(b"PK\x03\x04" + b"\0" * 40)
    with pytest.raises(ReferenceError, match=r"ref\.npz"):
        ReferenceSet.load(p)


# ------------------------------------------------------------------------------ batch level
def _dataset(tmp_path: Path) -> tuple[Path, list[Path]]:
    d = tmp_path / "ds"
    d.mkdir()
    files = []
    for i in range(2):
        f = d / f"rec{i}.npz"
        save_recording(make_recording(150, seed=i), f)
        files.append(f)
    bad = d / "bad.pkl"
    bad.write_bytes(b"c_codecs\nencode\n(Vabc\nVno-such-codec\ntR.")
    files.append(bad)
    return d, files


def test_load_recordings_reports_skips_and_collects(tmp_path, capsys) -> None:
    from grip.cli.recordings import exit_status, load_recordings

    _, files = _dataset(tmp_path)
    errors: list[tuple[str, str]] = []
    recs = load_recordings(files, errors=errors)
    assert len(recs) == 2
    assert [f for f, _ in errors] == [str(files[2])]
    err = capsys.readouterr().err
    assert f"grip: error: {files[2]}: corrupt or truncated pickle" in err
    assert exit_status(errors, 3) == 1 and "1 of 3 input file(s)" in capsys.readouterr().err
    assert exit_status([]) == 0


def test_data_info_skips_bad_files_and_exits_1(tmp_path, capsys) -> None:
    from grip.cli.main import main

    d, files = _dataset(tmp_path)
    assert main(["data", "info", str(d)]) == 1
    out, err = capsys.readouterr()
    assert "recordings: 2" in out
    assert f"grip: error: {files[2]}:" in err
    # Limits from the command line apply to every file; a bad name is a usage error.
    assert main(["data", "info", str(d), "--input-limit", "max_duration_s=1"]) == 1
    out, err = capsys.readouterr()
    assert "recordings: 0" in out and err.count("max_duration_s=1") == 2
    assert main(["data", "info", str(d), "--input-limit", "bogus=1"]) == 2
    assert "unknown limit 'bogus'" in capsys.readouterr().err


def test_data_plot_of_a_hostile_file_is_a_clean_error(tmp_path, capsys) -> None:
    from grip.cli.main import main

    _, files = _dataset(tmp_path)
    assert main(["data", "plot", str(files[2]), "--out", str(tmp_path / "p.png")]) == 2
    assert f"grip: error: {files[2]}:" in capsys.readouterr().err


def test_export_skips_an_unreadable_reconstruction(tmp_path, capsys) -> None:
    from grip.cli.main import main
    from grip.core.reconstruction import Reconstruction

    good = tmp_path / "good.npz"
    rot = np.broadcast_to(np.eye(3), (20, 24, 3, 3)).copy()
    pos = np.zeros((20, 24, 3))
    pos[..., 2] = np.linspace(0.1, 1.7, 24)
    Reconstruction(name="g", method="m", fps=100.0, joint_pos=pos, global_rot=rot).save(good)
    bad = tmp_path / "bad.npz"
    np.savez(bad, __meta__=np.array("[" * 100_000 + "]" * 100_000))
    out = tmp_path / "out"
    assert main(["export", str(good), str(bad), "--out", str(out), "--formats", "bvh"]) == 1
    err = capsys.readouterr().err
    assert f"grip: error: {bad}:" in err and "max_depth" in err
    assert (out / "good.bvh").is_file()


def test_bench_segments_skip_unreadable_files(tmp_path) -> None:
    from grip.eval.segments import BenchError, list_segments

    _, files = _dataset(tmp_path)
    errors: list[tuple[str, str]] = []
    segs = list_segments(files, 100, errors=errors)
    assert len(segs) == 2 and [f for f, _ in errors] == [str(files[2])]
    assert "_codecs.encode" in errors[0][1]
    with pytest.raises(BenchError, match=r"bad\.pkl"):
        list_segments(files, 100)


def _split_dataset(tmp_path: Path) -> tuple[Path, Path]:
    d = tmp_path / "data"
    (d / "sequences").mkdir(parents=True)
    save_recording(make_recording(260, seed=7), d / "sequences" / "good.npz")
    bad = d / "sequences" / "bad.npz"
    np.savez(bad, **{"__meta__.json": np.array("[" * 100_000 + "]" * 100_000)})
    (d / "split.json").write_text(json.dumps({"train": [], "test": ["bad", "good"]}))
    return d, bad


def test_eval_kin_skips_a_bad_file_and_exits_1(tmp_path, capsys) -> None:
    from grip.cli.main import main

    d, bad = _split_dataset(tmp_path)
    assert main(["kin", "eval", "--data", str(d), "--segment-frames", "100"]) == 1
    out, err = capsys.readouterr()
    assert "PEL_MPJPE" in out or "MPJPE" in out
    assert f"grip: error: {bad}:" in err and "max_depth" in err


def test_eval_policy_skips_a_bad_file_and_exits_1(tmp_path, capsys) -> None:
    from grip.assets import SHIPPED_POLICY
    from grip.cli.main import main

    if not (SHIPPED_POLICY).is_file():
        pytest.skip("no shipped policy")
    d, bad = _split_dataset(tmp_path)
    assert main(["policy", "eval", "--data", str(d), "--segment-frames", "40",
                 "--segments", "1"]) == 1  # fmt: skip
    assert f"grip: error: {bad}:" in capsys.readouterr().err
