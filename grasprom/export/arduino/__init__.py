"""Arduino (ATmega328P) export of the impedance controller, verified with avr-gcc and simavr.

The Arduino Uno has no FPU, 2 KB RAM and 16 MHz; a 1 kHz loop leaves 1,600 cycles per step for
the controller.  The export compiles the one C core of the controller, ``fmu/src/grasp_core.c`` (the
FMU's core), with its build options (see ``grasp_core.h``):

* **default: tabulated, fixed point** (``GC_TABULATED``, set by the generated ``grasp_build.h``):
  what the run-time step computes with trigonometry and Newton iterations is tabulated along the
  handle angle by this module (double precision, the Python reference) and evaluated in integer
  arithmetic;
* **tabulated, float** (``GF_FLOAT`` in the generated config): the same tables, float arithmetic;
* **run-time, float**: the FMU's step itself, compiled by avr-gcc (whose ``double`` is 32-bit),
  surrogate curves in PROGMEM (:func:`run_runtime_avr`) -- the literal FMU code on the
  microcontroller.

Measured with simavr (README, ``benchmarks/bench_arduino.py``): only the fixed-point build meets
the 1,600-cycle budget, hence the default.  The tables:

* the static rendered jaw force along the handle angle (in encoder counts) for every thickness
  node of every material, on a dyadic grid per material (segment widths 2^k counts, chosen so
  that linear interpolation reproduces every curve within ``tol`` of the jaw-force full scale,
  the largest jaw force the export renders); thickness is a run-time parameter, blended
  linearly between nodes at ``gf_init()``.  The curve is that of ``params.rendering``: with
  ``"coupling"`` the jaw force through the virtual coupling, ``Fg = k_c (g_p - g)``
  with the proxy ``g_p`` solved *to convergence* on the float surrogate; with ``"clipped"``
  (default) the stiffness-clipped field of :mod:`grasprom.control.field` (the tissue's static
  force, slopes bounded by the stiffness limit, no coupling) at the count's angle;
* the chain on a uniform grid: ``a = g'(theta) / L3`` (handle force per jaw force) and the
  return-spring handle force;
* the flag thresholds (tissue warning, coupling active) in counts per thickness node; with the
  clipped rendering ``GF_COUPLING_ACTIVE`` means *stiffness limit active* (the field is
  clipped).

Error budget: the rendered handle force (= torque / pulley radius) of the fixed-point core
against the Python reference on the float surrogate, in percent of the device's full-scale
handle force ``torque_limit / pulley_radius`` (the force that saturates the motor), over every
encoder position of the handle's range, every material and thicknesses on and between the
nodes.  The jaw-force error in percent of the jaw-force full scale (the quantity ``tol``
bounds on the thickness nodes) is reported too, and the handle-force error in percent of the
rendered range (the largest |handle force| the reference renders on the test vectors).

The host build (gcc) of the same code gives bit-identical outputs to the AVR run (simavr),
so most checks run on the host.

Modules: :mod:`.reference` (the Python reference on encoder counts), :mod:`.tables` (the
fixed-point tables and their headers), :mod:`.vectors` (test vectors and output records),
:mod:`.toolchain` (gcc / avr-gcc / simavr runners, size and cycle measurement),
:mod:`.budget` (budgets and error figures), :mod:`.sketch` (sketch, Makefile,
:func:`export_arduino`, :func:`export_main`).
"""

from __future__ import annotations

from grasprom.export.arduino.budget import (
    CYCLE_BUDGET,
    ERROR_BUDGET,
    FLASH_BUDGET_B,
    RAM_BUDGET_B,
    ErrorFigures,
    error_figures,
)
from grasprom.export.arduino.firmware import (
    COMMANDS,
    DRIVERS,
    HOMING_MODES,
    STATUS_BITS,
    ControlTimer,
    FirmwareConfig,
    FirmwareError,
    StatusLine,
    control_timer,
    firmware_header,
    parse_status_line,
)
from grasprom.export.arduino.reference import (
    ReferenceRun,
    chain_terms,
    clipped_field,
    coupled_jaw_force,
    encoder_quantum_rad,
    reference_run,
    rendered_jaw_force,
)
from grasprom.export.arduino.sketch import (
    BUILDER_SCRIPT,
    MAKEFILE_TEMPLATE,
    README_TEMPLATE,
    SKETCH_NAME,
    ArduinoExport,
    export_arduino,
    export_main,
    readme_text,
    rendering_description,
    sketch_template,
)
from grasprom.export.arduino.tables import (
    BUILD_HEADER,
    FixedTables,
    MaterialTable,
    build_tables,
    crc16_ccitt,
    write_core,
)
from grasprom.export.arduino.toolchain import (
    AVR_CFLAGS,
    F_CPU_HZ,
    MCU,
    AvrRun,
    RuntimeAvrRun,
    SizeFigures,
    build_avr_test,
    build_harness,
    measure_size,
    run_host,
    run_runtime_avr,
    run_simavr,
)
from grasprom.export.arduino.vectors import (
    OUT_DTYPE,
    RT_OUT_DTYPE,
    CoreRun,
    VectorCase,
    clamp_thickness_cases,
    default_cases,
    parse_output,
    runtime_vectors_source,
    sweep_counts,
    vectors_source,
)
from grasprom.export.variables import FLAG_NAMES

__all__ = [
    "AVR_CFLAGS",
    "ArduinoExport",
    "AvrRun",
    "BUILDER_SCRIPT",
    "BUILD_HEADER",
    "COMMANDS",
    "CYCLE_BUDGET",
    "ControlTimer",
    "CoreRun",
    "DRIVERS",
    "ERROR_BUDGET",
    "ErrorFigures",
    "FLAG_NAMES",
    "FLASH_BUDGET_B",
    "F_CPU_HZ",
    "FirmwareConfig",
    "FirmwareError",
    "FixedTables",
    "HOMING_MODES",
    "MAKEFILE_TEMPLATE",
    "MCU",
    "MaterialTable",
    "OUT_DTYPE",
    "RAM_BUDGET_B",
    "README_TEMPLATE",
    "RT_OUT_DTYPE",
    "ReferenceRun",
    "RuntimeAvrRun",
    "SKETCH_NAME",
    "STATUS_BITS",
    "SizeFigures",
    "StatusLine",
    "VectorCase",
    "build_avr_test",
    "build_harness",
    "build_tables",
    "chain_terms",
    "clamp_thickness_cases",
    "clipped_field",
    "control_timer",
    "coupled_jaw_force",
    "crc16_ccitt",
    "default_cases",
    "encoder_quantum_rad",
    "error_figures",
    "export_arduino",
    "export_main",
    "firmware_header",
    "measure_size",
    "parse_output",
    "parse_status_line",
    "readme_text",
    "reference_run",
    "rendered_jaw_force",
    "rendering_description",
    "run_host",
    "run_runtime_avr",
    "run_simavr",
    "runtime_vectors_source",
    "sketch_template",
    "sweep_counts",
    "vectors_source",
    "write_core",
]
