"""Fixtures of the PRISM tools' tests."""

from __future__ import annotations

import pytest

from prism_tools.synth.recording import recording_from_motion
from tests.prism_tools.test_devices import jump_motion, write_device_files


@pytest.fixture(scope="module")
def source():
    """The jump take (:func:`test_devices.jump_motion`) as a noise-free recording."""
    return recording_from_motion(jump_motion(), noise=False)


@pytest.fixture(scope="module")
def files(source, tmp_path_factory):
    """``(insole file, {site: IMU CSV})``: the take as the devices export it
    (:func:`test_devices.write_device_files`), written once per test module."""
    return write_device_files(source, tmp_path_factory.mktemp("devices"))
