"""Stage 5, exports: the C core binding, the FMU (FMI 2.0 / 3.0) and the Arduino package.

Layout: :mod:`~grasprom.export.variables` is the one description of the interface (FMU
variables, C structures, units, flags, Prony terms); :mod:`~grasprom.export.codegen` generates
every header, ctypes structure, XML and HTML from it; :mod:`~grasprom.export.ccore` builds the
C core for the host (ctypes); :mod:`~grasprom.export.fmu` packs the FMU;
:mod:`grasprom.export.arduino` is the fixed-point Arduino export.
"""

from __future__ import annotations

from grasprom.export.arduino import (
    CYCLE_BUDGET,
    ERROR_BUDGET,
    FLASH_BUDGET_B,
    RAM_BUDGET_B,
    ArduinoExport,
    build_tables,
    export_arduino,
    export_main,
    measure_size,
)
from grasprom.export.fmu import build_driver, export_fmu
from grasprom.export.variables import OUTPUT_COLUMNS, start_values

__all__ = [
    "ArduinoExport",
    "CYCLE_BUDGET",
    "ERROR_BUDGET",
    "FLASH_BUDGET_B",
    "OUTPUT_COLUMNS",
    "RAM_BUDGET_B",
    "build_driver",
    "build_tables",
    "export_arduino",
    "export_fmu",
    "export_main",
    "measure_size",
    "start_values",
]
