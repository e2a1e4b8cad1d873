"""Toolchain runners of the Arduino export: gcc (host), avr-gcc, avr-size and simavr.

The host build (gcc) of the tabulated core gives bit-identical outputs to the AVR run (simavr),
so most checks run on the host (:func:`run_host`); :func:`build_avr_test` / :func:`run_simavr`
run the same test vectors on the simulated ATmega328P and count the cycles of every step;
:func:`measure_size` gives flash and RAM; :func:`run_runtime_avr` runs the FMU's run-time step
itself (float) on the AVR.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from grasprom.control import ControllerParams, ImpedanceController
from grasprom.export.arduino.firmware import F_CPU_HZ
from grasprom.export.arduino.reference import encoder_quantum_rad
from grasprom.export.arduino.tables import FixedTables, write_core
from grasprom.export.arduino.vectors import (
    RT_OUT_DTYPE,
    CoreRun,
    VectorCase,
    parse_output,
    runtime_vectors_source,
    vectors_source,
)
from grasprom.export.codegen import CORE_SOURCES, tables_source
from grasprom.export.variables import FLAG_NAMES
from grasprom.paths import c_file
from grasprom.surrogate import Surrogate

MCU = "atmega328p"


def _run(cmd: list[str], what: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    res = subprocess.run(cmd, capture_output=True, cwd=cwd)
    if res.returncode != 0:
        raise RuntimeError(
            f"{what} failed:\n{' '.join(cmd)}\n{res.stderr.decode(errors='replace')}"
        )
    return res


def need_tool(tool: str, package: str) -> str:
    """Path of ``tool``; a RuntimeError naming the Debian package when it is missing."""
    path = shutil.which(tool)
    if path is None:
        raise RuntimeError(f"{tool} not found (Debian: apt-get install {package})")
    return path


def run_host(tables: FixedTables, cases: Sequence[VectorCase], directory: str | Path) -> CoreRun:
    """Build the core + test driver for the host (gcc -Wall -Wextra -Werror) and run it."""
    need_tool("gcc", "gcc")
    d = Path(directory)
    write_core(tables, d)
    shutil.copy(c_file("gf_test_main.c"), d / "gf_test_main.c")
    (d / "gf_vectors.h").write_text(vectors_source(tables, cases))
    exe = d / "gf_host_test"
    _run(["gcc", "-O2", "-std=c99", "-Wall", "-Wextra", "-Werror", "-o", str(exe),
          str(d / "grasp_core.c"), str(d / "gf_test_main.c"), "-lm"], "host build")  # fmt: skip
    return parse_output(_run([str(exe)], "host run").stdout, cases)


AVR_CFLAGS = ["-mmcu=" + MCU, "-Os", "-std=gnu99", "-Wall", "-Wextra", "-Werror",
              f"-DF_CPU={F_CPU_HZ}UL"]  # fmt: skip


def build_avr_test(
    tables: FixedTables, cases: Sequence[VectorCase], directory: str | Path, mcu: str = MCU
) -> Path:
    """Cross-compile the core + test driver (vectors in flash) with avr-gcc; returns the ELF."""
    need_tool("avr-gcc", "gcc-avr avr-libc")
    d = Path(directory)
    write_core(tables, d)
    shutil.copy(c_file("gf_test_main.c"), d / "gf_test_main.c")
    (d / "gf_vectors.h").write_text(vectors_source(tables, cases))
    elf = d / "gf_avr_test.elf"
    flags = [f if not f.startswith("-mmcu") else f"-mmcu={mcu}" for f in AVR_CFLAGS]
    _run(["avr-gcc", *flags, "-o", str(elf), str(d / "grasp_core.c"),
          str(d / "gf_test_main.c"), "-lm"], "avr-gcc build of the test firmware")  # fmt: skip
    return elf


def build_harness(directory: str | Path) -> Path:
    """Compile the libsimavr harness (:file:`gf_simavr_harness.c`) with gcc."""
    need_tool("gcc", "gcc")
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    exe = d / "gf_simavr_harness"
    _run(["gcc", "-O2", "-Wall", "-Wextra", "-Werror", "-o", str(exe),
          str(c_file("gf_simavr_harness.c")), "-lsimavr"],
         "simavr harness build (Debian: apt-get install simavr libsimavr-dev)")  # fmt: skip
    return exe


@dataclass
class AvrRun:
    """Outputs and per-step cycle counts of a simavr run."""

    run: CoreRun
    cycles: NDArray  # per step, calibration subtracted


def run_simavr(
    elf: str | Path, cases: Sequence[VectorCase], directory: str | Path, mcu: str = MCU
) -> AvrRun:
    """Run a test firmware under libsimavr; outputs and cycles per ``gf_step`` call."""
    data, cycles = _simavr_bytes(elf, Path(directory), mcu)
    return AvrRun(parse_output(data, cases), cycles)


def _simavr_bytes(elf: str | Path, d: Path, mcu: str) -> tuple[bytes, NDArray]:
    """Run a test firmware under the libsimavr harness: the bytes it reported and the cycles
    of every marked step (the first, empty measurement subtracted as calibration)."""
    harness = build_harness(d)
    out, cyc = d / "avr_out.bin", d / "avr_cycles.txt"
    _run([str(harness), str(elf), mcu, str(F_CPU_HZ), str(out), str(cyc)], "simavr run")
    cycles = np.loadtxt(cyc, dtype=np.int64, ndmin=1)
    return out.read_bytes(), cycles[1:] - cycles[0]


@dataclass
class SizeFigures:
    """Flash and RAM of the core + tables on the AVR (bytes), from avr-size."""

    flash_B: int  # text + data of a firmware with the core, minus an empty one
    ram_static_B: int  # data + bss, minus the empty firmware
    stack_B: int  # stack of gf_step (avr-gcc -fstack-usage), + 2 bytes return address
    ram_B: int  # static + stack


def _avr_size(elf: Path) -> tuple[int, int, int]:
    res = _run(["avr-size", "-A", str(elf)], "avr-size")
    sec = {}
    for line in res.stdout.decode().splitlines():
        parts = line.split()
        if len(parts) >= 2 and parts[0].startswith(".") and parts[1].isdigit():
            sec[parts[0]] = int(parts[1])
    return sec.get(".text", 0), sec.get(".data", 0), sec.get(".bss", 0)


def _size_over_empty(
    d: Path,
    core_main: str,
    io_decl: str,
    name: str,
    flags: Sequence[str],
    extra: Sequence[str] = (),
) -> tuple[int, int]:
    """Flash (text + data) and static RAM (data + bss) of ``grasp_core.c`` + ``core_main`` (a C
    main that uses the core) minus an empty firmware with the same volatile ``in``/``out``
    declarations ``io_decl``, bytes; builds in ``d``."""
    (d / f"{name}.c").write_text(core_main)
    (d / "empty_main.c").write_text(io_decl + "int main(void) {\n    for (;;) { out = in; }\n}\n")
    _run(["avr-gcc", *flags, *extra, "-o", str(d / f"{name}.elf"), str(d / "grasp_core.c"),
          str(d / f"{name}.c"), "-lm"], f"avr-gcc size build ({name})", cwd=d)  # fmt: skip
    _run(["avr-gcc", *flags, "-o", str(d / "empty.elf"), str(d / "empty_main.c")],
         "avr-gcc empty build")  # fmt: skip
    t1, d1, b1 = _avr_size(d / f"{name}.elf")
    t0, d0, b0 = _avr_size(d / "empty.elf")
    return (t1 + d1) - (t0 + d0), (d1 + b1) - (d0 + b0)


def measure_size(tables: FixedTables, directory: str | Path) -> SizeFigures:
    """Flash/RAM of the core + tables: a minimal firmware with and without the core."""
    need_tool("avr-gcc", "gcc-avr avr-libc")
    need_tool("avr-size", "binutils-avr")
    d = Path(directory)
    write_core(tables, d)
    flash, static = _size_over_empty(
        d,
        '#include "grasp_core.h"\n'
        "static gf_state_t s;\nvolatile int16_t in;\nvolatile int32_t out;\n"
        "int main(void) {\n    gf_output_t o;\n    gf_init(&s, 0, 1400);\n"
        "    for (;;) { gf_step(&s, in, &o); out = o.torque_uNm + o.flags; }\n}\n",
        "#include <stdint.h>\nvolatile int16_t in;\nvolatile int32_t out;\n",
        "size_main",
        AVR_CFLAGS,
        ["-fstack-usage"],
    )
    stack = 0
    for su in d.glob("*.su"):
        for line in su.read_text().splitlines():
            m = re.match(r".*:(gf_step|gf_segment|mulq16)\s+(\d+)", line)
            if m:
                stack += int(m.group(2)) + 2
    return SizeFigures(flash, static, stack, static + stack)


@dataclass
class RuntimeAvrRun:
    """The FMU's run-time step compiled for the AVR (float), run under simavr."""

    outputs: list[NDArray]  # RT_OUT_DTYPE records per case
    cycles: NDArray  # per step, calibration subtracted
    flash_B: int  # text + data of the core + surrogate curves (avr-size, minus an empty firmware)
    handle_pct_fs: float  # max |dFi| vs the Python reference (double), % of full scale
    jaw_max_abs_N: float  # max |dFg| vs the Python reference (N)
    flag_mismatch: int  # steps where any flag differs


_RT_SIZE_MAIN = (
    '#include "grasp_core.h"\n#include "grasp_tables.h"\n'
    "static gc_state_t s;\nstatic gc_params_t p;\nvolatile double in;\nvolatile double out;\n"
    "int main(void) {\n    gc_output_t o;\n    double t;\n    int c;\n    const char *m;\n"
    "    p.material = (int)in;\n"
    "    gc_check_params(&p, GC_MATERIALS, GC_N_MATERIALS, &t, &c, &m);\n"
    "    gc_init(&s, &p, &GC_CHAIN);\n"
    "    for (;;) { gc_step(&s, &p, &GC_CHAIN, &GC_MATERIALS[p.material], in, &o);"
    " out = o.torque; }\n}\n"
)
"""A firmware that only initialises and steps the run-time core (its flash measurement)."""


def _build_runtime_avr(
    surrogate: Surrogate,
    params: ControllerParams,
    cases: Sequence[VectorCase],
    d: Path,
    mcu: str,
) -> tuple[Path, int]:
    """Cross-compile the run-time core test firmware in ``d``: the ELF and the flash (bytes)
    of core + curves (a firmware that only initialises and steps, minus an empty one)."""
    d.mkdir(parents=True, exist_ok=True)
    for f in (*CORE_SOURCES, "gc_runtime_test_main.c"):
        shutil.copy(c_file(f), d / f)
    (d / "grasp_tables.h").write_text(tables_source(surrogate, params.chain_params))
    (d / "gc_rt_vectors.h").write_text(runtime_vectors_source(params, cases))
    elf = d / "gc_rt_avr_test.elf"
    flags = [f if not f.startswith("-mmcu") else f"-mmcu={mcu}" for f in AVR_CFLAGS]
    _run(["avr-gcc", *flags, "-o", str(elf), str(d / "grasp_core.c"),
          str(d / "gc_runtime_test_main.c"), "-lm"],
         "avr-gcc build of the run-time core test firmware")  # fmt: skip
    flash, _ = _size_over_empty(
        d,
        _RT_SIZE_MAIN,
        "volatile double in;\nvolatile double out;\n",
        "rt_size_main",
        flags,
    )
    return elf, flash


def _flag_bits(step) -> int:
    """The ``flags`` byte of a :class:`~grasprom.control.StepOutput` (bit i: FLAG_NAMES[i])."""
    return sum(int(bool(getattr(step, name))) << bit for bit, name in enumerate(FLAG_NAMES))


def run_runtime_avr(
    surrogate: Surrogate,
    params: ControllerParams,
    cases: Sequence[VectorCase],
    directory: str | Path,
    mcu: str = MCU,
) -> RuntimeAvrRun:
    """Compile the run-time step of ``grasp_core.c`` (the FMU's) for the AVR and run it.

    avr-gcc's ``double`` is 32-bit, so this is the float build of the FMU's core; the
    surrogate curves go to flash (``GC_TABLE`` = PROGMEM).  Outputs are compared with
    :class:`grasprom.control.ImpedanceController` (double) on the same encoder counts.

    Raises
    ------
    ValueError
        If ``params.rendering`` is not ``"coupling"``: the AVR build leaves the clipped
        rendering's field table out (``GC_FIELD_N = 0``) and ``gc_check_params`` refuses it.
    RuntimeError
        If a tool fails, the core refuses a case's parameters, or an output is not finite.
    """
    if params.rendering != "coupling":
        raise ValueError(
            f"run_runtime_avr needs rendering='coupling' (got {params.rendering!r}): the AVR "
            "build of the run-time core has no field table (GC_FIELD_N = 0), so gc_check_params "
            "refuses the clipped rendering (code -6)"
        )
    need_tool("avr-gcc", "gcc-avr avr-libc")
    need_tool("avr-size", "binutils-avr")
    d = Path(directory)
    elf, flash = _build_runtime_avr(surrogate, params, cases, d, mcu)
    data, cycles = _simavr_bytes(elf, d, mcu)
    pos, outs = 0, []
    fs = params.torque_limit_Nm / (params.pulley_radius_mm * 1e-3)
    q = encoder_quantum_rad(params)
    e_h = e_j = 0.0
    mism = 0
    for c in cases:
        rc = int(np.frombuffer(data, np.int8, 1, pos)[0])  # gc_check_params' code, signed
        if rc != 0:
            raise RuntimeError(
                f"run-time core rejected the parameters of case {c.material} "
                f"{c.thickness_um} um (gc_check_params code {rc})"
            )
        pos += 2
        rec = np.frombuffer(data, RT_OUT_DTYPE, len(c.counts), pos)
        pos += len(c.counts) * RT_OUT_DTYPE.itemsize
        bad = sum(int(np.sum(~np.isfinite(rec[k]))) for k in ("torque", "fi", "fg", "gp"))
        if bad:
            raise RuntimeError(
                f"run-time core output not finite ({bad} values) in case {c.material} "
                f"{c.thickness_um} um: on the AVR, RAM exhausted (stack into the state)?"
            )
        outs.append(rec)
        lo, hi = surrogate.thickness_range(c.material)
        t = min(max(c.thickness_um / 1000.0, lo), hi)
        ctl = ImpedanceController(replace(params, material=c.material, thickness_mm=t), surrogate)
        ref = [ctl.step(int(n) * q) for n in c.counts]
        fi = np.array([r.force_handle_N for r in ref])
        fg = np.array([r.force_jaw_N for r in ref])
        e_h = max(e_h, float(np.max(np.abs(rec["fi"] - fi))))
        e_j = max(e_j, float(np.max(np.abs(rec["fg"] - fg))))
        mism += int(np.sum(np.array([_flag_bits(r) for r in ref]) != rec["flags"]))
    if pos != len(data):
        raise RuntimeError(f"run-time core output has {len(data)} bytes, expected {pos}")
    return RuntimeAvrRun(outs, cycles, flash, 100.0 * e_h / fs, e_j, mism)
