"""Transparency of the coupling and the clipped rendering, side by side, per controller rate.

Usage::

    python benchmarks/bench_transparency.py
    python benchmarks/bench_transparency.py --rates 1000,2000,5000,10000 --cases mr:0.8,le:2.0

For each rate the controller is tuned over the whole shipped sweep (every thickness x
material, the default device and hand, safety 1.25) once per rendering: the coupling
(``k_c``) and the clipped field (``K_lim``, which scales with the rate).  Printed, per case:
the quasi-static rendered / tissue jaw force where the tissue force reaches 0.5, 2, 5 and
20 N and the largest rendered force at the closed end (from the tuning's transparency table,
the same figures ``grasprom tune`` reports); per rate: the stiffness bound, ``B`` and cutoff,
the passivity margin ``b / b_required`` and the worst damping ratio / phase margin with the
hand over every operating point.  Printed, not asserted.
"""

from __future__ import annotations

import argparse
import time
import warnings
from dataclasses import replace
from pathlib import Path

from grasprom.control import ControllerParams, tune
from grasprom.surrogate import Surrogate

ROOT = Path(__file__).resolve().parents[1]
LEVELS = ("0.5", "2", "5", "20")


def _parse_cases(text: str) -> list[tuple[str, float]]:
    """``mr:0.8,le:2.0`` -> ``[("mr", 0.8), ("le", 2.0)]``."""
    out = []
    for item in text.split(","):
        m, t = item.split(":")
        out.append((m.strip(), float(t)))
    return out


def _tuned(sur: Surrogate, rate: float, rendering: str) -> tuple[dict, float]:
    """Tuning summary at ``rate`` Hz for ``rendering`` and its wall time (s)."""
    t0 = time.perf_counter()
    base = replace(ControllerParams(rendering=rendering), sample_time_s=1.0 / rate)
    r = tune(sur, base, verify=False)
    return r.summary, time.perf_counter() - t0


def _bound(sm: dict) -> str:
    """The stiffness bound of a summary, with its unit."""
    c = sm["chosen"]
    if c.get("rendering") == "clipped":
        return f"K_lim {c['stiffness_limit_Nm_per_rad']:g} N m/rad"
    return f"k_c {c['coupling_stiffness_N_per_mm']:g} N/mm"


def _row(case: dict | None) -> str:
    """Ratios and the largest rendered force of one case (``-`` where not reached)."""
    if case is None:
        return " ".join(f"{'-':>5s}" for _ in LEVELS) + f" {'-':>6s}"
    cells = " ".join(
        f"{case['ratios'][L]:5.2f}" if case["ratios"][L] is not None else f"{'-':>5s}"
        for L in LEVELS
    )
    return f"{cells} {case['max_rendered_N']:6.2f}"


def _print_rate(rate: float, sums: dict[str, dict], cases: list[tuple[str, float]]) -> None:
    """The side-by-side table and the passivity figures of one rate."""
    print(f"\n=== {rate / 1000:g} kHz ===")
    for name, sm in sums.items():
        om = sm["operating_margins"]["worst"]
        print(
            f"  {name:8s}: {_bound(sm)}, B {sm['chosen']['damping_Nms_per_rad']:.4g} N m s/rad, "
            f"cutoff {sm['chosen']['velocity_cutoff_Hz']:g} Hz, passive bound "
            f"{sm['passive_stiffness_with_margin_Nm_per_rad']:.3g} N m/rad (with safety), "
            f"margin b/b_req {sm['passivity_margin']:.3f}; with the hand: worst damping ratio "
            f"{om['damping_ratio_min']:.3f}, phase margin {om['phase_margin_min_deg']:.3g} deg"
        )
    head = " ".join(f"{L + ' N':>5s}" for L in LEVELS) + f" {'max N':>6s}"
    print(f"  {'case':10s} | coupling: {head} | clipped:  {head}")
    for m, t in cases:
        rows = []
        for sm in sums.values():
            hit = [c for c in sm["transparency"]["cases"]
                   if c["material"] == m and abs(c["thickness_mm"] - t) < 1e-9]  # fmt: skip
            rows.append(_row(hit[0] if hit else None))
        print(f"  {m} {t:<7g} |           {rows[0]} |           {rows[1]}")


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; returns the process exit code."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rates", default="1000,2000,5000,10000", help="controller rates, Hz")
    p.add_argument("--cases", default="mr:0.8,mr:1.4,mr:2.0,le:2.0", help="material:thickness list")
    p.add_argument("--fe", default=str(ROOT / "fe_data" / "default"), help="FE sweep")
    args = p.parse_args(argv)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        sur = Surrogate.build(args.fe)
    cases = _parse_cases(args.cases)
    print(
        "rendered / tissue jaw force (quasi-static) where the tissue force reaches the level; "
        "max N: rendered force at the closed end"
    )
    total = 0.0
    for rate in (float(r) for r in args.rates.split(",")):
        sums = {}
        for rendering in ("coupling", "clipped"):
            sums[rendering], dt = _tuned(sur, rate, rendering)
            total += dt
        _print_rate(rate, sums, cases)
    print(f"\n(tuning wall time {total:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
