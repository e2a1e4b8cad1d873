"""Benchmark of the exported FMU (printed, not asserted).

Prints, for FMI 2.0 and 3.0:

* the C controller step time (ns) measured in the C driver (``fmu_driver bench``, dlopen, no
  Python) over 1e6 steps -- ``core_step_ns`` from doSteps of 1000 samples (the FMI call cost
  amortised; target <= 100 ns) and ``fmi_step_ns`` for one SetReal + DoStep + GetReal per
  sample;
* the wall time of an fmpy co-simulation of 10 s at 1 kHz (input from a structured array,
  every output recorded each step; target <= 0.3 s);
* the FMU size.

Run: ``python benchmarks/bench_fmu.py [--steps 1000000] [--rendering clipped]`` (the clipped
rendering: the step interpolates the field table instead of the coupling's Newton iterations).
"""

from __future__ import annotations

import argparse
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from grasprom.control import ControllerParams, grasp_trajectory
from grasprom.control.params import RENDERINGS
from grasprom.export import OUTPUT_COLUMNS, build_driver, export_fmu
from grasprom.surrogate import load_surrogate


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=1_000_000, help="C driver steps")
    ap.add_argument("--rendering", choices=RENDERINGS, default="coupling", help="tissue rendering")
    args = ap.parse_args(argv)

    from fmpy import extract, read_model_description, simulate_fmu

    sur = load_surrogate(None, None)
    params = ControllerParams(rendering=args.rendering)
    traj = grasp_trajectory(close_s=3.0, hold_s=4.0, open_s=3.0)
    n = 10_000
    sig = np.zeros(n, dtype=[(c, np.float64) for c in ("time", "theta", "theta_dot")])
    sig["time"] = 1e-3 * np.arange(n)
    sig["theta"] = np.radians(traj["theta_deg"].to_numpy()[:n])
    with tempfile.TemporaryDirectory() as tmp:
        driver = build_driver(tmp)
        for version in (2, 3):
            fmu = export_fmu(Path(tmp) / f"G{version}.fmu", params, sur, fmi_version=version)
            md = read_model_description(str(fmu))
            unz = extract(str(fmu), str(Path(tmp) / f"x{version}"))
            plat = "linux64" if version == 2 else "x86_64-linux"
            lib = Path(unz) / "binaries" / plat / "GraspController.so"
            vr = {v.name: v.valueReference for v in md.modelVariables}
            token = md.guid if version == 2 else md.instantiationToken
            reals = [k for k, (_, f) in OUTPUT_COLUMNS.items() if f is not None]
            bools = [k for k, (_, f) in OUTPUT_COLUMNS.items() if f is None]
            res = subprocess.run(
                [str(driver), str(version), str(lib), token, "bench", str(args.steps),
                 "-t", str(vr["theta"]), "-o", ",".join(str(vr[k]) for k in reals),
                 "-O", ",".join(str(vr[k]) for k in bools)],
                capture_output=True, text=True, check=True,
            )  # fmt: skip
            figures = dict(line.split()[:2] for line in res.stdout.splitlines())
            best = float("inf")
            for _ in range(3):
                t0 = time.perf_counter()
                out = simulate_fmu(
                    unz, model_description=md, start_time=0.0, stop_time=10.0,
                    output_interval=1e-3, input=sig, output=reals + bools,
                )  # fmt: skip
                best = min(best, time.perf_counter() - t0)
            assert out.shape[0] == n + 1
            print(
                f"FMI {version}.0 ({args.rendering}): C core step "
                f"{float(figures['core_step_ns']):.0f} ns (target <= 100 ns), FMI step incl. "
                f"set/get {float(figures['fmi_step_ns']):.0f} ns ({args.steps:.0e} steps, C "
                f"driver); fmpy 10 s at 1 kHz: {best:.3f} s (target <= 0.3 s); FMU size "
                f"{fmu.stat().st_size / 1024:.0f} KiB"
            )


if __name__ == "__main__":
    main()
