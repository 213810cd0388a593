"""Tests for prism_tools.synthetic and the package's import hygiene."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from prism_tools import validate
from prism_tools.streams import FEET, GRAVITY, contacts_from_cells
from prism_tools.synthetic import CONTACT_THRESHOLD_BW, make_recording


def test_deterministic_and_seed_dependent() -> None:
    a, b, c = make_recording(200, 4), make_recording(200, 4), make_recording(200, 5)
    np.testing.assert_array_equal(a.imu["Head"].ori_world, b.imu["Head"].ori_world)
    np.testing.assert_array_equal(a.insole["L_Foot"].forces, b.insole["L_Foot"].forces)
    assert not np.array_equal(a.imu["Head"].ori_world, c.imu["Head"].ori_world)


def test_self_consistent() -> None:
    rec = make_recording(400, seed=1)
    validate(rec)
    total = sum(rec.insole[f].force[:, 0] for f in FEET)
    np.testing.assert_allclose(total[:100], 1.0, atol=0.05)  # still stance: 1 body weight
    for foot in FEET:
        s = rec.insole[foot]
        np.testing.assert_allclose(s.forces.sum(axis=1), s.force[:, 0], atol=1e-12)
        expected = contacts_from_cells(s.forces, CONTACT_THRESHOLD_BW)
        np.testing.assert_array_equal(s.contacts, expected)
        np.testing.assert_allclose(s.force_world[:, 2], s.force[:, 0])
        assert not s.contacts.all() and s.contacts.any()  # the walk has swing phases
        # Accelerometer (specific force, sensor frame) back in the world equals acc + g.
        imu = rec.imu[foot]
        assert imu.acc_local_raw is not None and imu.gyr_local_raw is not None
        acc_world = np.einsum("fij,fj->fi", imu.ori_world, imu.acc_local_raw)
        np.testing.assert_allclose(
            acc_world, imu.acc_world_raw + np.array([0.0, 0.0, GRAVITY]), atol=1e-9
        )
    assert rec.insole_combined is not None
    np.testing.assert_allclose(rec.insole_combined.force_world[:, 2], total)
    gt = rec.imu_gt["Pelvis"]
    np.testing.assert_allclose(np.gradient(gt.pos_world, 0.01, axis=0), gt.vel_world)


def test_parts_subset() -> None:
    rec = make_recording(50, seed=0, parts=("L_Wrist", "Head"))
    assert set(rec.imu) == set(rec.imu_gt) == {"L_Wrist", "Head"}
    assert set(rec.insole) == set(FEET)
    with pytest.raises(ValueError, match="unknown IMU parts"):
        make_recording(50, parts=("Tail",))


def test_no_heavy_imports() -> None:
    code = (
        "import sys, prism_tools, prism_tools.synthetic, prism_tools.chunking\n"
        "heavy = ('torch', 'mujoco', 'gymnasium', 'envs', 'policies')\n"
        "bad = [m for m in heavy if m in sys.modules]\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
