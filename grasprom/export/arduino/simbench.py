"""A simulated bench for the Arduino firmware: build the sketch, run it under simavr, read back.

:func:`build_sketch` builds an exported sketch with arduino-mk (optionally with the fault-
injection hooks, ``-DGF_TEST_HOOKS``); :func:`run_bench` runs the ELF under the libsimavr
harness ``gf_sketch_harness.c`` with a :class:`BenchScript` (encoder motion, input pins,
serial commands, flash corruption) and returns a :class:`BenchRun`: the serial lines with
their times, the timer and port registers every 250 us, the control-step edges of the scope
pin and the MCU resets.  The tests of the firmware (PWM frequency and duty from the Timer1
registers, the interrupt rate, watchdog, homing, serial commands, safe state) read these.
"""

from __future__ import annotations

import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd

from grasprom.export.arduino.firmware import (
    F_CPU_HZ,
    UNO_PINS,
    FirmwareConfig,
    StatusLine,
    parse_status_line,
)
from grasprom.export.arduino.toolchain import need_tool
from grasprom.paths import c_file


def build_sketch(sketch_dir: str | Path, *, test_hooks: bool = False) -> Path:
    """Build an exported sketch with its arduino-mk ``Makefile``; returns the ELF.

    Parameters
    ----------
    sketch_dir : str or Path
        ``<out>/grasprom_controller`` of :func:`~grasprom.export.arduino.export_arduino`.
    test_hooks : bool
        Compile the fault-injection commands (``X loop``, ``X cli``, ``X slow``, ``X enc``).

    Returns
    -------
    Path
    """
    need_tool("make", "make")
    need_tool("avr-gcc", "gcc-avr avr-libc")
    if not Path("/usr/share/arduino/Arduino.mk").is_file():
        raise RuntimeError("arduino-mk not found (Debian: apt-get install arduino-mk)")
    d = Path(sketch_dir)
    cmd = ["make", "-s"] + (["GF_EXTRA_CPPFLAGS=-DGF_TEST_HOOKS"] if test_hooks else [])
    res = subprocess.run(cmd, cwd=d, capture_output=True, text=True, timeout=600)
    if res.returncode != 0:
        raise RuntimeError(f"arduino-mk build of {d} failed:\n{res.stdout[-2000:]}{res.stderr}")
    elfs = sorted((d / "build-uno").glob("*.elf"))
    if not elfs:
        raise RuntimeError(f"arduino-mk built no ELF in {d / 'build-uno'}")
    return elfs[0]


def build_bench_harness(directory: str | Path) -> Path:
    """Compile the libsimavr bench harness (``gf_sketch_harness.c``) with gcc."""
    need_tool("gcc", "gcc")
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    exe = d / "gf_sketch_harness"
    cmd = ["gcc", "-O2", "-Wall", "-Wextra", "-Werror", "-o", str(exe),
           str(c_file("gf_sketch_harness.c")), "-lsimavr"]  # fmt: skip
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(
            "simavr bench harness build failed (Debian: apt-get install simavr libsimavr-dev):\n"
            + res.stderr
        )
    return exe


@dataclass
class BenchScript:
    """What the bench does, in time order (ms of simulated time).

    Build it with the methods, each returning the script (chainable)::

        BenchScript().pin(4, 1, at_ms=0).home(100).encoder(300, to=200).send(400, "S")
    """

    actions: list[tuple[float, str]] = field(default_factory=list)

    def _add(self, t_ms: float, text: str) -> BenchScript:
        if self.actions and t_ms < self.actions[-1][0]:
            raise ValueError(f"bench actions must be in time order ({t_ms} ms after "
                             f"{self.actions[-1][0]} ms)")  # fmt: skip
        self.actions.append((float(t_ms), text))
        return self

    def encoder(self, t_ms: float, to: int) -> BenchScript:
        """Move the raw encoder count linearly to ``to`` by ``t_ms``."""
        return self._add(t_ms, f"enc {int(to)}")

    def pin(self, pin: int, level: int, at_ms: float) -> BenchScript:
        """Drive the Uno input ``pin`` to ``level`` at ``at_ms``."""
        p = UNO_PINS[pin]
        return self._add(at_ms, f"pin {p.port}{p.bit} {int(level)}")

    def home(self, t_ms: float, pin: int = 4, active_low: bool = True) -> BenchScript:
        """Pulse the home input (2 ms active) at ``t_ms``."""
        on, off = (0, 1) if active_low else (1, 0)
        return self.pin(pin, on, t_ms).pin(pin, off, t_ms + 2.0)

    def send(self, t_ms: float, text: str) -> BenchScript:
        """Send one serial line at ``t_ms``."""
        return self._add(t_ms, f"send {text}")

    def corrupt_flash(self, t_ms: float, address: int, value: int) -> BenchScript:
        """Overwrite one flash byte at ``t_ms``."""
        return self._add(t_ms, f"flash {int(address)} {int(value)}")

    def glitch(self, t_ms: float) -> BenchScript:
        """Both encoder channels change at once (an invalid transition) at ``t_ms``."""
        return self._add(t_ms, "glitch")

    def text(self, end_ms: float) -> str:
        """The harness script, ending at ``end_ms``."""
        lines = [f"{t:.4f} {a}" for t, a in self.actions]
        return "\n".join([*lines, f"{end_ms:.4f} end"]) + "\n"


@dataclass
class BenchRun:
    """What the simulated bench recorded.

    Attributes
    ----------
    lines : list of (float, str)
        Serial output lines with the time (ms) of their first byte.
    samples : pandas.DataFrame
        Every 250 us: ``t_ms``, ``encoder`` (the harness's raw count) and the registers
        TCCR1A, TCCR1B, ICR1, OCR1A, OCR1B, TCCR2A, TCCR2B, OCR2A, TIMSK2, WDTCSR, PORTB, DDRB,
        PORTC, PORTD, DDRD.
    step_start_ms, step_end_ms : numpy.ndarray
        Rising / falling edges of the scope pin: the control steps (ms).
    resets_ms : numpy.ndarray
        Times of MCU resets (the watchdog).
    """

    lines: list[tuple[float, str]]
    samples: pd.DataFrame
    step_start_ms: np.ndarray
    step_end_ms: np.ndarray
    resets_ms: np.ndarray

    def status(self) -> list[tuple[float, StatusLine]]:
        """The parsed status lines with their times (ms)."""
        out = []
        for t, text in self.lines:
            s = parse_status_line(text)
            if s is not None:
                out.append((t, s))
        return out

    def after(self, t_ms: float, prefix: str = "") -> list[tuple[float, str]]:
        """Serial lines from ``t_ms`` on that start with ``prefix``."""
        return [(t, s) for t, s in self.lines if t >= t_ms and s.startswith(prefix)]

    def status_after(self, t_ms: float) -> StatusLine:
        """The first status line at or after ``t_ms`` (the answer to an ``S`` sent then)."""
        for t, st in self.status():
            if t >= t_ms:
                return st
        raise LookupError(f"no status line after {t_ms} ms")

    def at(self, t_ms: float) -> SimpleNamespace:
        """The register sample nearest to ``t_ms``: integer attributes named as the columns."""
        i = int(np.argmin(np.abs(self.samples["t_ms"].to_numpy() - t_ms)))
        row = self.samples.iloc[i]
        return SimpleNamespace(
            t_ms=float(row["t_ms"]), **{c: int(row[c]) for c in self.samples.columns[1:]}
        )


def run_bench(
    elf: str | Path,
    script: BenchScript,
    end_ms: float,
    directory: str | Path,
    config: FirmwareConfig | None = None,
) -> BenchRun:
    """Run a sketch ELF under the simavr bench harness.

    Parameters
    ----------
    elf : str or Path
        The firmware (:func:`build_sketch`).
    script : BenchScript
    end_ms : float
        Simulated time to run (ms).
    directory : str or Path
        Working folder (harness, script and recordings).
    config : FirmwareConfig, optional
        The export's firmware configuration (its scope pin is recorded; default config).

    Returns
    -------
    BenchRun
    """
    cfg = config or FirmwareConfig()
    if cfg.scope_pin is None:
        raise ValueError("the bench needs the scope pin (FirmwareConfig.scope_pin)")
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    exe = build_bench_harness(d)
    (d / "script.txt").write_text(script.text(end_ms))
    sp = UNO_PINS[cfg.scope_pin]
    res = subprocess.run([str(exe), str(elf), str(d / "script.txt"), str(d), sp.port,
                          str(sp.bit)], capture_output=True, text=True, timeout=600)  # fmt: skip
    if res.returncode != 0:
        raise RuntimeError(f"simavr bench run failed ({res.returncode}): {res.stderr}")
    ms = 1e3 / F_CPU_HZ
    lines = []
    for raw in (d / "uart.log").read_text(errors="replace").splitlines():
        cyc, _, text = raw.partition("\t")
        if cyc.isdigit():
            lines.append((int(cyc) * ms, text))
    samples = pd.read_csv(d / "samples.csv")
    samples.insert(0, "t_ms", samples.pop("cycle") * ms)
    edges = _ints(d / "scope.txt").reshape(-1, 2)
    resets = _ints(d / "resets.txt")
    return BenchRun(lines, samples, edges[:, 0] * ms, edges[:, 1] * ms, resets * ms)


def _ints(path: Path) -> np.ndarray:
    """Whitespace-separated integers of a recording (empty: no events)."""
    return np.array(path.read_text().split(), dtype=np.int64)
