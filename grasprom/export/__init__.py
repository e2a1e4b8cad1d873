"""Stage 5, exports: the C core binding, the FMU (FMI 2.0 / 3.0) and the Arduino package."""

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
from grasprom.export.fmu import (
    OUTPUT_COLUMNS,
    build_driver,
    export_fmu,
    start_values,
)

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
