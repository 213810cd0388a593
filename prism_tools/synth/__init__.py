"""Sensor synthesis: PRISM-format IMU and insole streams from a motion on the body model.

numpy/scipy only (plus the numpy body model of :mod:`grip.core`). Entry point:
:func:`recording_from_motion`; the pure functions of :mod:`~prism_tools.synth.imu`,
:mod:`~prism_tools.synth.insole` (with :mod:`~prism_tools.synth.wrench` and
:mod:`~prism_tools.synth.force_distribution`) and :mod:`~prism_tools.synth.noise` do the work.
"""

from prism_tools.synth.config import (
    ImuSynthConfig,
    InsoleSynthConfig,
    NoiseConfig,
    SynthConfig,
    config_to_json,
)
from prism_tools.synth.force_distribution import distribute_force
from prism_tools.synth.imu import ImuKinematics, ImuReadings, measure_imu, synthesize_imu
from prism_tools.synth.insole import (
    InsoleReadings,
    InsoleSynth,
    insole_readings_from_cells,
    measure_insoles,
    synthesize_insoles,
)
from prism_tools.synth.recording import SensorSynthesis, recording_from_motion, synthesize_sensors
from prism_tools.synth.wrench import Wrench, external_wrench

__all__ = [
    "ImuKinematics",
    "ImuReadings",
    "ImuSynthConfig",
    "InsoleReadings",
    "InsoleSynth",
    "InsoleSynthConfig",
    "NoiseConfig",
    "SensorSynthesis",
    "SynthConfig",
    "Wrench",
    "config_to_json",
    "distribute_force",
    "external_wrench",
    "insole_readings_from_cells",
    "measure_imu",
    "measure_insoles",
    "recording_from_motion",
    "synthesize_imu",
    "synthesize_insoles",
    "synthesize_sensors",
]
