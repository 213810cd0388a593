"""Device files (prism_tools.devices): the Moticon OpenGo and IMU CSV formats read and written,
and bad files refused naming file and line, including unit and quaternion-order claims that
gravity contradicts and a calibration window in the jump (the take's files: conftest.py's
``files``, written as in test_devices.py)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from prism_tools.devices import (
    DeviceFileError,
    ImportOptions,
    ImuCsv,
    ImuCsvOptions,
    import_devices,
    read_imu_csv,
    read_moticon,
    write_imu_csv,
    write_moticon,
)
from prism_tools.streams import GRAVITY
from tests.prism_tools.test_devices import GENERIC, INSOLE_CLOCK, PUSH_S, STILL_S, _clock_at_frame0

# --------------------------------------------------------------------------------- formats
MOTICON_SAMPLE = """\
# Start time: 27.09.2023 10:21:14.922
# Duration: 00:00.030
# Sensor insoles: Left SN0001, Right SN0002
# Size: 7
# Recording type: normal
# Name: sample
# time\t{left}\t{right}\tright steps[]\tleft steps[]
0.00\t{empty}\t{right_row}\t\t
0.01\t{left_row}\t{right_row}\t21\t
0.02\t{left_row}\t{right_row}\t\t15
"""


def _moticon_sample() -> str:
    def names(side):
        return "\t".join([f"{side} pressure {k}[N/cm²]" for k in range(1, 17)]
                         + [f"{side} acceleration {a}[g]" for a in "XYZ"]
                         + [f"{side} angular {a}[dps]" for a in "XYZ"]
                         + [f"{side} total force[N]"]
                         + [f"{side} center of pressure {a}[-0.5...+0.5]"
                            for a in "XY"])  # fmt: skip

    row = "\t".join(["6.50"] * 4 + ["1.25"] * 12 + ["-0.200000", "0.040000", "0.970000",
                     "-2.450000", "-3.430000", "2.380000", "509.00", "-0.201829",
                     "-0.076531"])  # fmt: skip
    return MOTICON_SAMPLE.format(left=names("left"), right=names("right"), empty="\t" * 24,
                                 left_row=row, right_row=row)  # fmt: skip


def test_moticon_reader_units_frames_and_writer(tmp_path) -> None:
    p = tmp_path / "m.txt"
    p.write_text(_moticon_sample(), encoding="utf-8")
    m = read_moticon(p)
    assert m.meta["Size"] == "7" and m.insole_size == "7"
    np.testing.assert_allclose(m.time_s, [0.0, 0.01, 0.02])
    left, right = m.sides["L_Foot"], m.sides["R_Foot"]
    assert left.valid.tolist() == [False, True, True] and right.valid.all()
    assert np.isnan(left.pressure_n_cm2[0]).all() and left.pressure_n_cm2[1, 0] == 6.5
    np.testing.assert_allclose(right.acc_mps2[1], np.array([-0.2, 0.04, 0.97]) * GRAVITY)
    np.testing.assert_allclose(left.acc_mps2[1], np.array([-0.2, -0.04, 0.97]) * GRAVITY)  # y
    np.testing.assert_allclose(np.degrees(left.gyr_rad_s[1]), [2.45, -3.43, -2.38])  # x, z
    np.testing.assert_allclose(right.total_force_n[1], 509.0)
    np.testing.assert_allclose(right.cop_norm[1], [-0.201829, -0.076531])
    assert right.heel_strike_rows.tolist() == [1] and left.toe_off_rows.tolist() == [2]
    # written back and read again: the same
    write_moticon(tmp_path / "w.txt", m)
    w = read_moticon(tmp_path / "w.txt")
    for foot in m.sides:
        a, b = m.sides[foot], w.sides[foot]
        assert (a.valid == b.valid).all()
        for field in ("pressure_n_cm2", "acc_mps2", "gyr_rad_s", "total_force_n", "cop_norm"):
            np.testing.assert_allclose(getattr(b, field), getattr(a, field), atol=1e-9)


def test_imu_csv_formats_and_options(tmp_path) -> None:
    # generic: positional quaternion columns in xyzw, g and deg/s
    p = tmp_path / "g.csv"
    p.write_text("time,ax,ay,az,gx,gy,gz,q0,q1,q2,q3\n"
                 "0.00,0,0,1,0,0,90,0,0,0.7071068,0.7071068\n"
                 "0.01,0,0,1,0,0,90,0,0,0.7071068,0.7071068\n")  # fmt: skip
    c = read_imu_csv(p, ImuCsvOptions(acc_unit="g", gyro_unit="deg", quat_order="xyzw"))
    np.testing.assert_allclose(c.acc_mps2[0], [0, 0, GRAVITY])
    np.testing.assert_allclose(c.gyr_rad_s[0], [0, 0, np.pi / 2])
    np.testing.assert_allclose(c.quat_wxyz[0], [0.7071068, 0, 0, 0.7071068], atol=1e-7)
    assert c.acc_kind == "specific_force" and c.fmt == "generic"
    free = read_imu_csv(p, ImuCsvOptions(acc_has_gravity=False))
    assert free.acc_kind == "free_sensor"
    np.testing.assert_allclose(free.quat_wxyz[0], [0, 0, 0.7071068, 0.7071068], atol=1e-7)
    # Movella DOT: preamble, microsecond clock wrapping at 2^32, own units whatever the options
    rng = np.random.default_rng(0)
    t = 4294.9 + np.arange(20) / 60.0  # crosses 2^32 us = 4294.967296 s
    q = rng.normal(size=(20, 4))
    data = ImuCsv(t, rng.normal(size=(20, 3)), "specific_force", rng.normal(size=(20, 3)),
                  q / np.linalg.norm(q, axis=1, keepdims=True),
                  meta={"DeviceTag": "L_Wrist"})  # fmt: skip
    write_imu_csv(tmp_path / "dot.csv", data, "movella_dot")
    text = (tmp_path / "dot.csv").read_text()
    assert text.startswith("sep=,\nDeviceTag:,L_Wrist,")
    assert "\nPacketCounter,SampleTimeFine,Quat_W," in text
    dot = read_imu_csv(tmp_path / "dot.csv", GENERIC)
    assert dot.fmt == "movella_dot" and dot.meta["OutputRate"] == "60Hz"
    np.testing.assert_allclose(dot.time_s - dot.time_s[0], t - t[0], atol=1e-6)
    np.testing.assert_allclose(dot.acc_mps2, data.acc_mps2, rtol=1e-8)
    np.testing.assert_allclose(dot.gyr_rad_s, data.gyr_rad_s, rtol=1e-8)
    same_sign = np.where(data.quat_wxyz[:, :1] < 0, -1.0, 1.0)
    np.testing.assert_allclose(dot.quat_wxyz, data.quat_wxyz * same_sign, atol=1e-8)
    # a DOT file of free accelerations (earth frame)
    write_imu_csv(tmp_path / "free.csv", dataclasses.replace(data, acc_kind="free_earth"),
                  "movella_dot")  # fmt: skip
    assert read_imu_csv(tmp_path / "free.csv").acc_kind == "free_earth"


# ------------------------------------------------------------------------------- bad files
def _lines(path: Path) -> list[str]:
    return path.read_text(encoding="utf-8").splitlines()


def _write(path: Path, lines: list[str]) -> Path:
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def test_bad_moticon_files_are_refused_naming_file_and_line(files, tmp_path) -> None:
    src = _lines(files[0])
    header = next(i for i, line in enumerate(src) if line.startswith("# time"))
    row = header + 40  # its line number is row + 1; both insoles have a sample there
    bad = src.copy()
    bad[row] = "\t".join(bad[row].split("\t")[:-3])
    with pytest.raises(DeviceFileError, match=rf"short.txt: line {row + 1}: .*wrong column count"):
        read_moticon(_write(tmp_path / "short.txt", bad))
    bad = src.copy()
    fields = bad[row].split("\t")
    fields[3] = "abc"
    bad[row] = "\t".join(fields)
    with pytest.raises(DeviceFileError, match=rf"text.txt: line {row + 1}: column 'left pressure "
                       r"3\[N/cm²\]': 'abc' is not a number"):  # fmt: skip
        read_moticon(_write(tmp_path / "text.txt", bad))
    bad = src.copy()
    fields = bad[row].split("\t")
    fields[2] = ""
    bad[row] = "\t".join(fields)
    with pytest.raises(DeviceFileError, match=rf"line {row + 1}: 15 of the 16 left pressures"):
        read_moticon(_write(tmp_path / "partial.txt", bad))
    bad = src.copy()
    bad[row], bad[row + 1] = bad[row + 1], bad[row]
    with pytest.raises(DeviceFileError, match=rf"order.txt: line {row + 2}: .*non-monotonic"):
        read_moticon(_write(tmp_path / "order.txt", bad))
    with pytest.raises(DeviceFileError, match=r"nohead.txt: no channel header"):
        read_moticon(_write(tmp_path / "nohead.txt", src[header + 1 :]))
    bad = src.copy()
    bad[header] = bad[header].replace("left acceleration X[g]", "left acceleration X[km]")
    with pytest.raises(DeviceFileError, match=r"unit \[km\] is not one of"):
        read_moticon(_write(tmp_path / "unit.txt", bad))


def test_bad_imu_files_are_refused_naming_file_and_line(files, tmp_path) -> None:
    with pytest.raises(DeviceFileError, match=r"noacc.csv: line 1: no acceleration \(ax, ay, az\)"):
        read_imu_csv(_write(tmp_path / "noacc.csv", ["time,gx,gy,gz", "0,0,0,0", "1,0,0,0"]))
    with pytest.raises(DeviceFileError, match=r"noori.csv: line 1: no orientation .* or angular"):
        read_imu_csv(_write(tmp_path / "noori.csv", ["time,ax,ay,az", "0,0,0,9", "1,0,0,9"]))
    with pytest.raises(DeviceFileError, match=r"notime.csv: line 1: expected a header line"):
        read_imu_csv(_write(tmp_path / "notime.csv", ["0,0,0,9,0,0,0", "1,0,0,9,0,0,0"]))
    head = "time,ax,ay,az,gx,gy,gz"
    with pytest.raises(DeviceFileError, match=r"back.csv: line 4: time 0.005 s is not after .*"
                       "non-monotonic"):  # fmt: skip
        read_imu_csv(_write(tmp_path / "back.csv", [head, "0,0,0,9,0,0,0", "0.01,0,0,9,0,0,0",
                                                     "0.005,0,0,9,0,0,0"]))  # fmt: skip
    with pytest.raises(DeviceFileError, match=r"cols.csv: line 3: 6 fields, the header has 7"):
        read_imu_csv(_write(tmp_path / "cols.csv", [head, "0,0,0,9,0,0,0", "0.01,0,0,9,0,0"]))
    with pytest.raises(DeviceFileError, match=r"word.csv: line 2: column 'ay': 'x' is not a"):
        read_imu_csv(_write(tmp_path / "word.csv", [head, "0,0,x,9,0,0,0", "0.01,0,0,9,0,0,0"]))
    with pytest.raises(DeviceFileError, match=r"quat.csv: line 3: quaternion of length 2"):
        read_imu_csv(_write(tmp_path / "quat.csv", ["time,ax,ay,az,qw,qx,qy,qz",
                                                    "0,0,0,9,1,0,0,0",
                                                    "0.01,0,0,9,2,0,0,0"]))  # fmt: skip
    # the same file without its jump, and with a long dropout
    insoles, imus = files
    lines = _lines(imus["R_Wrist"])
    still = _write(tmp_path / "still.csv", lines[:101])  # the first second: no jump in it
    with pytest.raises(DeviceFileError, match=r"still.csv: no jump found in the first 60 s"):
        import_devices(insoles, {"R_Wrist": still}, ImportOptions(subject_mass_kg=70.0), GENERIC)
    gap = _write(tmp_path / "gap.csv", lines[:400] + lines[430:])
    with pytest.raises(DeviceFileError, match=r"gap.csv: IMU: no samples from .* \(0.310 s, 30 "
                       "samples\\) inside the recording"):  # fmt: skip
        import_devices(insoles, {"R_Wrist": gap}, ImportOptions(subject_mass_kg=70.0), GENERIC)
    # no still T-pose before the jump
    moving = _write(tmp_path / "moving.csv", [lines[0]] + [
        _spin(line) if i <= 300 else line for i, line in enumerate(lines[1:], 1)])  # fmt: skip
    with pytest.raises(DeviceFileError, match=r"no still window of 1 s before the jump in "
                       ".*moving.csv"):  # fmt: skip
        import_devices(None, {"R_Wrist": moving}, ImportOptions(subject_mass_kg=70.0), GENERIC)


def _spin(line: str) -> str:
    """A generic CSV row with a fast rotation rate (deg/s) about z."""
    f = line.split(",")
    f[6] = "200"
    return ",".join(f)


# ------------------------------------------------- claims that gravity contradicts (issue 50)
def _claimed(files, tmp_path, options: ImuCsvOptions, header: tuple[str, str] | None = None):
    """Import the round trip's files with the R_Wrist CSV's units claimed as ``options`` (its
    header line edited by ``header``: (old, new))."""
    insoles, imus = files
    imus = dict(imus)
    if header is not None:
        text = imus["R_Wrist"].read_text()
        imus["R_Wrist"] = tmp_path / "R_Wrist_edited.csv"
        imus["R_Wrist"].write_text(text.replace(*header, 1))
    return import_devices(insoles, imus, ImportOptions(), options)


@pytest.mark.parametrize(("claim", "match"), [
    ({"acc_unit": "mps2"}, r"accelerations read 1 m/s\^2 .*the values are in g, not m/s\^2 "
                           r"\(--acc-unit g"),
    ({"gyro_unit": "rad"}, r"gyroscope turns 57.\d times as fast .*deg/s, not rad/s "
                           r"\(--gyro-unit deg"),
    ({"acc_has_gravity": False}, r"accelerations read 9.81 m/s\^2 .*about 1 g, but they are "
                                 r"read as acceleration without gravity: they hold gravity "
                                 r"\(--acc-has-gravity"),
], ids=["acc-unit", "gyro-unit", "gravity"])  # fmt: skip
def test_wrong_units_are_named(files, tmp_path, claim, match) -> None:
    with pytest.raises(DeviceFileError, match=r"R_Wrist\.csv: R_Wrist: the " + match):
        _claimed(files, tmp_path, dataclasses.replace(GENERIC, **claim))


def test_wrong_quaternion_order_is_named(files, tmp_path) -> None:
    """The watch's positional columns q0..q3 hold x, y, z, w; read as w, x, y, z."""
    header = ("qx,qy,qz,qw", "q0,q1,q2,q3")
    assert header[0] in files[1]["R_Wrist"].read_text()
    wrong = dataclasses.replace(GENERIC, quat_order="wxyz")
    with pytest.raises(DeviceFileError, match=r"R_Wrist: rotated by the exported orientation, "
                       r"gravity points \d+ deg apart \(median\) and 100 deg from the reference "
                       r"frame's vertical.*the quaternion columns are xyzw, not wxyz "
                       r"\(--quat-order xyzw"):  # fmt: skip
        _claimed(files, tmp_path, wrong, header)
    rec, _ = _claimed(files, tmp_path, GENERIC, header)  # the right order: imported as before
    assert "R_Wrist" in rec.imu


def test_a_calibration_window_in_the_jump_is_refused(files) -> None:
    insoles, imus = files
    at = _clock_at_frame0(INSOLE_CLOCK) + STILL_S + PUSH_S  # the take-off
    with pytest.raises(DeviceFileError, match=r"calibration window at .* is not still: an IMU "
                                              r"moves from"):  # fmt: skip
        import_devices(insoles, imus, ImportOptions(calib_at_s=at), GENERIC)
