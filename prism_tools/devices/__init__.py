"""Importers from the formats real devices export into PRISM-format recordings without ground
truth (docs/devices.md): Moticon OpenGo insole text exports (:mod:`~prism_tools.devices.moticon`),
wrist and foot IMU CSVs, Movella DOT or generic (:mod:`~prism_tools.devices.imu_csv`), clock
synchronisation by a jump (:mod:`~prism_tools.devices.sync`), an orientation filter for sensors
that export none (:mod:`~prism_tools.devices.orientation`), the still-pose calibration
(:mod:`~prism_tools.devices.calibrate`) and the assembly (:func:`import_devices`).

numpy, scipy (the synthetic data's low-pass filter) and :mod:`grip.core` only; importing
:mod:`prism_tools` does not import this package.
"""

from prism_tools.devices.common import DeviceFileError
from prism_tools.devices.importer import ImportOptions, ImportReport, import_devices
from prism_tools.devices.imu_csv import ImuCsv, ImuCsvOptions, read_imu_csv, write_imu_csv
from prism_tools.devices.moticon import MoticonExport, MoticonSide, read_moticon, write_moticon

__all__ = [
    "DeviceFileError",
    "ImportOptions",
    "ImportReport",
    "ImuCsv",
    "ImuCsvOptions",
    "MoticonExport",
    "MoticonSide",
    "import_devices",
    "read_imu_csv",
    "read_moticon",
    "write_imu_csv",
    "write_moticon",
]
