"""Benchmark of the Arduino export (printed, not asserted).

For table tolerances 0.25 %, 0.5 % (the default of ``grasprom export arduino``), 1 % and 2 % of
the jaw-force full scale, and for both renderings -- the stiffness-clipped field (``clip``, the
default ``ControllerParams().rendering``, :mod:`grasprom.control.field`) and the virtual
coupling (``coup``, ``rendering="coupling"``): table bytes and grid nodes, flash and RAM of
tables + core on the ATmega328P (avr-gcc -Os, avr-size), cycles per controller step under
simavr (max and mean over every material at four thicknesses on a closing/opening sweep of every
encoder count), and the error against the float Python reference (handle force in % of the
full-scale handle force, jaw force in % of the jaw-force full scale, and, issue 17, in % of the
rendered range: the largest |handle force| the reference renders on the vectors, column
``rendN``) over every material, every thickness node and midpoint, every count.  A summary line
gives the default export's figures (clipped rendering, default tolerance), the ones README.md,
docs/arduino.md and docs/verification.md quote.

Then the other build options of the same core (``grasp_core.c``): the tabulated step in float
(``GF_FLOAT``) at the default tolerance, and the run-time step -- the FMU's -- compiled by
avr-gcc (float, surrogate curves in flash) on three materials/thicknesses.  The run-time step
runs with ``rendering="coupling"``: its AVR build leaves the clipped rendering's field table out
(``GC_FIELD_N = 0``, 2 KB of RAM), and ``gc_check_params`` refuses the clipped rendering there
(code -6).  Last, the augmented exports (``grasprom export arduino --augmented``) with the default
rendering and tolerance.

Needs gcc, gcc-avr, avr-libc, binutils-avr, simavr and libsimavr-dev.

Run: ``python benchmarks/bench_arduino.py [SWEEP] [--quick]`` (``SWEEP`` defaults to
``fe_data/default``).  ``--quick`` (about 10 s; ``tests/export/test_bench_arduino.py`` runs it)
measures the default tolerance only, skips the float build, runs the run-time step on one case
and the augmented export with every effect only; its default-export line is the full run's.
"""

from __future__ import annotations

import argparse
import inspect
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from grasprom.control import ControllerParams
from grasprom.export import arduino as ar
from grasprom.surrogate import Surrogate

DEFAULT_TOL = inspect.signature(ar.export_arduino).parameters["tol"].default
"""The table tolerance of ``grasprom export arduino`` and ``grasprom build`` (fraction of the
jaw-force full scale)."""
TOLS = (0.0025, 0.005, 0.01, 0.02)
"""Table tolerances of the full run (fractions of the jaw-force full scale)."""
HEADER = (
    "rend  core  tol%  tableB  nodes m/n/l  flashB  ramB  cycmax cycmean handle%FS"
    " %rendrg  rendN  jaw%jawFS"
)


@dataclass
class Measured:
    """One build's figures: tables, size, AVR run (cycles) and error against the reference."""

    tables: ar.FixedTables
    size: ar.SizeFigures
    avr: ar.AvrRun
    err: ar.ErrorFigures
    fixed: bool


def measure(
    sur: Surrogate, params: ControllerParams, tol: float, fixed: bool, tmp: Path
) -> Measured:
    """Build the tables of ``params`` at ``tol``, measure size and cycles, compute the error.

    The fixed-point build is bit-identical on the host and the AVR, so its dense error run
    (every thickness node and midpoint) is done on the host; the float build's error is the
    AVR run's.
    """
    t = ar.build_tables(sur, params, tol, fixed_point=fixed)
    size = ar.measure_size(t, tmp / "size")
    cases = ar.default_cases(t, sur)
    avr = ar.run_simavr(ar.build_avr_test(t, cases, tmp / "avr"), cases, tmp / "avr")
    if fixed:
        dense = ar.default_cases(t, sur, dense=True)
        err = ar.error_figures(t, sur, dense, ar.run_host(t, dense, tmp / "host"))
    else:
        err = ar.error_figures(t, sur, cases, avr.run)
    return Measured(t, size, avr, err, fixed)


def row(m: Measured) -> str:
    """One line of the table (columns of :data:`HEADER`)."""
    t, e = m.tables, m.err
    nodes = "/".join(str(len(x.x)) for x in t.materials)
    return (
        f"{t.params.rendering[:4]:>4} {'fixed' if m.fixed else 'float':>5} {100 * t.tol:6.2f} "
        f"{t.table_bytes:7d} {nodes:>9} "
        f"{m.size.flash_B:7d} {m.size.ram_B:5d} {int(m.avr.cycles.max()):7d} "
        f"{m.avr.cycles.mean():7.0f} {e.handle_pct_fs:9.3f} {e.handle_pct_rendered:7.3f} "
        f"{e.rendered_max_N:6.1f} {e.jaw_pct_fs:9.3f}"
    )


def summary(m: Measured) -> str:
    """The default export's figures, as README.md and the docs quote them."""
    p, e = m.tables.params, m.err
    cyc = int(m.avr.cycles.max())
    us = cyc / ar.F_CPU_HZ * 1e6
    return (
        f"default export ({p.rendering}, tol {100 * m.tables.tol:g} %): flash {m.size.flash_B} B, "
        f"RAM {m.size.ram_B} B, {cyc} cycles/step max = {us:.1f} us = "
        f"{100 * us * 1e-6 / p.sample_time_s:.1f} % of the {1e3 * p.sample_time_s:g} ms period; "
        f"handle-force error {e.handle_pct_rendered:.3f} % of the rendered range "
        f"({e.rendered_max_N:.1f} N; {e.handle_pct_fs:.3f} % FS), jaw-force error "
        f"{e.jaw_pct_fs:.3f} % of its full scale ({m.tables.jaw_fs_N:.2f} N), {e.steps} steps"
    )


def runtime_line(sur: Surrogate, quick: bool, tmp: Path) -> str:
    """The FMU's run-time step (float) on the AVR, coupling rendering (see the module doc)."""
    params = ControllerParams(rendering="coupling")
    counts = ar.sweep_counts(ar.build_tables(sur, params, DEFAULT_TOL), 9)
    spots = (("mr", 1400),) if quick else (("mr", 1400), ("nh", 2000), ("le", 850))
    cases = [ar.VectorCase(m, th, counts) for m, th in spots]
    rt = ar.run_runtime_avr(sur, params, cases, tmp)
    return (
        f"  run-time float (the FMU's step on the AVR, coupling rendering): flash {rt.flash_B} B, "
        f"cycles max {int(rt.cycles.max())} mean {rt.cycles.mean():.0f} "
        f"({rt.cycles.mean() / ar.CYCLE_BUDGET:.1f} x budget), handle error "
        f"{rt.handle_pct_fs:.1e} % FS, flag mismatches {rt.flag_mismatch}"
    )


AUGMENTED = {
    "backlash 0.3 deg": dict(backlash_deg=0.3),
    "friction 2 N + 0.1 load": dict(friction_coulomb_N=2.0, friction_load_coefficient=0.1),
    "Prony 1 term": dict(prony_g=(0.3,), prony_tau_s=(0.2,)),
    "Prony 2 terms": dict(prony_g=(0.3, 0.2), prony_tau_s=(0.2, 1.0)),
    "all of these + scale 1.3": dict(
        backlash_deg=0.3, friction_coulomb_N=2.0, friction_load_coefficient=0.1,
        prony_g=(0.3, 0.2), prony_tau_s=(0.2, 1.0), tissue_scale=1.3
    ),
}  # fmt: skip
"""Augmented exports: label -> ControllerParams fields (default rendering, i.e. clipped)."""
AUGMENTED["all + jaw 0.01 mm/N"] = {
    **AUGMENTED["all of these + scale 1.3"],
    "jaw_compliance_mm_per_N": 0.01,
}


def augmented_line(sur: Surrogate, label: str, tmp: Path) -> str:
    """Flash, RAM, cycles and error of the augmented export ``label`` of :data:`AUGMENTED`."""
    t = ar.build_tables(sur, ControllerParams(**AUGMENTED[label]), DEFAULT_TOL)
    cases = ar.default_cases(t, sur)
    run = ar.run_simavr(ar.build_avr_test(t, cases, tmp), cases, tmp)
    e = ar.error_figures(t, sur, cases, run.run)
    sz = ar.measure_size(t, tmp / "size")
    return (
        f"  {label:26s} flash {sz.flash_B:5d} B, RAM {sz.ram_B:4d} B, cycles max "
        f"{int(run.cycles.max()):5d} mean {run.cycles.mean():5.0f}, handle error "
        f"{e.handle_pct_fs:.3f} % FS ({e.handle_pct_rendered:.3f} % of the rendered "
        f"{e.rendered_max_N:.1f} N)"
    )


def main(argv: list[str] | None = None) -> Measured:
    """Print the benchmark; return the default export's figures (clipped, default tolerance)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sweep", nargs="?", default="fe_data/default", help="FE sweep folder")
    ap.add_argument("--quick", action="store_true", help="reduced run (see the module doc)")
    args = ap.parse_args(argv)
    sur = Surrogate.build(args.sweep)
    clipped, coupling = ControllerParams(), ControllerParams(rendering="coupling")
    tols = (DEFAULT_TOL,) if args.quick else TOLS
    t0 = time.perf_counter()
    print(
        f"Arduino export, ATmega328P @ {ar.F_CPU_HZ / 1e6:g} MHz, default ControllerParams "
        f"(rendering {clipped.rendering!r}), default tolerance {100 * DEFAULT_TOL:g} %"
    )
    print(
        f"budget: flash {ar.FLASH_BUDGET_B} B, RAM {ar.RAM_BUDGET_B} B, {ar.CYCLE_BUDGET} "
        f"cycles/step, handle-force error {100 * ar.ERROR_BUDGET:g} % of the rendered range"
    )
    print(HEADER)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        runs = []
        for i, tol in enumerate(tols):
            runs.append(measure(sur, clipped, tol, True, d / f"cl{i}"))
            print(row(runs[-1]), flush=True)
        default = runs[tols.index(DEFAULT_TOL)]
        if not args.quick:
            print(row(measure(sur, clipped, DEFAULT_TOL, False, d / "fl")), flush=True)
        for i, tol in enumerate(tols):
            print(row(measure(sur, coupling, tol, True, d / f"co{i}")), flush=True)
        print(summary(default), flush=True)
        print(runtime_line(sur, args.quick, d / "rt"), flush=True)
        print("augmented exports (grasprom export arduino --augmented), default rendering and "
              f"tolerance ({clipped.rendering}, {100 * DEFAULT_TOL:g} %):")  # fmt: skip
        labels = ["all of these + scale 1.3"] if args.quick else list(AUGMENTED)
        for i, label in enumerate(labels):
            print(augmented_line(sur, label, d / f"aug{i}"), flush=True)
    print(f"({time.perf_counter() - t0:.1f} s)")
    return default


if __name__ == "__main__":
    main()
