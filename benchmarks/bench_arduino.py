"""Benchmark of the Arduino export (printed, not asserted).

For table tolerances 0.25 %, 0.5 %, 1 % (default) and 2 % of the jaw-force full scale: table
bytes and grid nodes, flash and RAM of tables + core on the ATmega328P (avr-gcc -Os, avr-size),
cycles per controller step under simavr (max and mean over every material at four thicknesses
on a closing/opening sweep of every encoder count), and the error against the float Python
reference (handle force in % of the full-scale handle force, jaw force in % of the jaw-force
full scale, and, issue 17, in % of the rendered range: the largest |handle force| the reference
renders on the vectors) over every material, every thickness node and midpoint, every count,
for the virtual-coupling rendering (default) and the stiffness-clipped one
(``rendering="clipped"``, :mod:`grasprom.control.field`).  Then the
other build options of the same core (``grasp_core.c``): the tabulated step in float
(``GF_FLOAT``) at the default tolerance, and the run-time step -- the FMU's -- compiled by avr-gcc
(float, surrogate curves in flash), on three materials/thicknesses.

Needs gcc, gcc-avr, avr-libc, binutils-avr, simavr and libsimavr-dev.

Run: ``python benchmarks/bench_arduino.py [fe_data/default]``
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from grasprom.control import ControllerParams
from grasprom.export import arduino as ar
from grasprom.surrogate import Surrogate


def row(sur: Surrogate, params: ControllerParams, tol: float, fixed: bool, tmp: Path) -> str:
    t = ar.build_tables(sur, params, tol, fixed_point=fixed)
    size = ar.measure_size(t, tmp / "size")
    cases = ar.default_cases(t, sur)
    avr = ar.run_simavr(ar.build_avr_test(t, cases, tmp / "avr"), cases, tmp / "avr")
    if fixed:  # host == AVR bit for bit: the dense error run is done on the host
        dense = ar.default_cases(t, sur, dense=True)
        err = ar.error_figures(t, sur, dense, ar.run_host(t, dense, tmp / "host"))
    else:
        err = ar.error_figures(t, sur, cases, avr.run)
    nodes = "/".join(str(len(m.x)) for m in t.materials)
    return (
        f"{params.rendering[:4]:>4} {'fixed' if fixed else 'float':>5} {100 * tol:6.2f} "
        f"{t.table_bytes:7d} {nodes:>9} "
        f"{size.flash_B:7d} {size.ram_B:5d} {int(avr.cycles.max()):7d} "
        f"{avr.cycles.mean():7.0f} {err.handle_pct_fs:9.3f} {err.handle_pct_rendered:7.3f} "
        f"{err.jaw_pct_fs:9.3f}"
    )


def main(argv: list[str]) -> None:
    sweep = argv[0] if argv else "fe_data/default"
    sur = Surrogate.build(sweep)
    params = ControllerParams()
    t0 = time.perf_counter()
    print(f"Arduino export, ATmega328P @ {ar.F_CPU_HZ / 1e6:g} MHz, default ControllerParams")
    print(
        f"budget: flash {ar.FLASH_BUDGET_B} B, RAM {ar.RAM_BUDGET_B} B, "
        f"{ar.CYCLE_BUDGET} cycles/step, handle-force error {100 * ar.ERROR_BUDGET:g} % FS"
    )
    print(
        "rend  core  tol%  tableB  nodes m/n/l  flashB  ramB  cycmax cycmean handle%FS"
        " %rendrg  jaw%jawFS"
    )
    clipped = ControllerParams(rendering="clipped")
    with tempfile.TemporaryDirectory() as tmp:
        for i, tol in enumerate((0.0025, 0.005, 0.01, 0.02)):
            print(row(sur, params, tol, True, Path(tmp) / f"fx{i}"), flush=True)
        print(row(sur, params, 0.01, False, Path(tmp) / "fl"), flush=True)
        for i, tol in enumerate((0.0025, 0.005, 0.01, 0.02)):
            print(row(sur, clipped, tol, True, Path(tmp) / f"cl{i}"), flush=True)
        t = ar.build_tables(sur, params, 0.01)
        counts = ar.sweep_counts(t, 9)
        cases = [
            ar.VectorCase(m, th, counts) for m, th in (("mr", 1400), ("nh", 2000), ("le", 850))
        ]
        rt = ar.run_runtime_avr(sur, params, cases, Path(tmp) / "rt")
        print(
            f"  run-time float (the FMU's step on the AVR): flash {rt.flash_B} B, cycles max "
            f"{int(rt.cycles.max())} mean {rt.cycles.mean():.0f} "
            f"({rt.cycles.mean() / ar.CYCLE_BUDGET:.1f} x budget), handle error "
            f"{rt.handle_pct_fs:.1e} % FS, flag mismatches {rt.flag_mismatch}",
            flush=True,
        )
        print("augmented exports (grasprom export arduino --augmented), default tolerance:")
        aug = {
            "backlash 0.3 deg": dict(backlash_deg=0.3),
            "friction 2 N + 0.1 load": dict(friction_coulomb_N=2.0,
                                            friction_load_coefficient=0.1),
            "Prony 1 term": dict(prony_g=(0.3,), prony_tau_s=(0.2,)),
            "Prony 2 terms": dict(prony_g=(0.3, 0.2), prony_tau_s=(0.2, 1.0)),
            "all of these + scale 1.3": dict(
                backlash_deg=0.3, friction_coulomb_N=2.0, friction_load_coefficient=0.1,
                prony_g=(0.3, 0.2), prony_tau_s=(0.2, 1.0), tissue_scale=1.3
            ),
        }  # fmt: skip
        aug["all + clipped rendering"] = {**aug["all of these + scale 1.3"], **dict(
            rendering="clipped", jaw_compliance_mm_per_N=0.01)}  # fmt: skip
        for i, (label, kw) in enumerate(aug.items()):
            pa = ControllerParams(**kw)
            ta = ar.build_tables(sur, pa, 0.01)
            ca = ar.default_cases(ta, sur)
            d = Path(tmp) / f"aug{i}"
            run = ar.run_simavr(ar.build_avr_test(ta, ca, d), ca, d)
            ea = ar.error_figures(ta, sur, ca, run.run)
            sz = ar.measure_size(ta, d / "size")
            print(
                f"  {label:26s} flash {sz.flash_B:5d} B, RAM {sz.ram_B:4d} B, cycles max "
                f"{int(run.cycles.max()):5d} mean {run.cycles.mean():5.0f}, handle error "
                f"{ea.handle_pct_fs:.3f} % FS ({ea.handle_pct_rendered:.3f} % of the rendered "
                f"{ea.rendered_max_N:.1f} N)",
                flush=True,
            )
    print(f"({time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    main(sys.argv[1:])
