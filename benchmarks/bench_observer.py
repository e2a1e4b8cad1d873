"""Time-domain passivity observer (issue 13, "Beyond the Colgate bound"): measured figures.

The energy simulation of ``tests/control/test_observer.py`` (device J, b + the hand at the grip,
zero-order-held torque with one sample of delay, 20 sub-steps per period; le 2.0 mm of the
shipped surrogate; close at three speeds, hold at 20 N of tissue force, release, rest open), at
1 kHz, for the clipped field at the Colgate bound, at 5x the bound without the observer and at
5x with it.  Prints per run: the controller's net work over the cycle ``W_c(end)`` (J, > 0:
energy generated), its peak ``max W_c`` (J), the handle-angle std in the first and the last
0.2 s of the hold (rad; one encoder count is 2.84e-4 rad), the largest added damping (N m s/rad)
and the integrator's balance error (J); then the rendered/tissue jaw-force ratio at 20 N of a
quasi-static closing (22 -> 0 deg over 20 s).

Usage::

    python benchmarks/bench_observer.py

About 10 s.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from grasprom.surrogate import load_surrogate  # noqa: E402
from tests.control.test_observer import (  # noqa: E402
    FIXED_BOUND,
    SPEEDS_S,
    plain_5x,
    ratio_at_force,
    simulate_energy,
    wall_params,
    with_observer,
)


def _hold_std(run, T: float = 1e-3) -> tuple[float, float]:
    """Handle-angle std over the first and the last 0.2 s of the 1 s hold (rad)."""
    i, m = run.release_index, int(round(0.2 / T))
    hold = run.theta_rad[i - int(round(1.0 / T)) : i]
    return float(hold[:m].std()), float(hold[-m:].std())


def main() -> None:
    """Run the energy simulations and the quasi-static closings; print the tables."""
    t0 = time.perf_counter()
    s = load_surrogate(None, None)
    cases = {
        f"clipped, K_lim = {FIXED_BOUND:g} (bound)": wall_params(),
        f"clipped, K_lim = {5 * FIXED_BOUND:g} (5x), no observer": plain_5x(),
        f"clipped, K_lim = {5 * FIXED_BOUND:g} (5x), observer": with_observer(),
    }
    print("energy runs, le 2.0 mm, 1 kHz, hold at 20 N tissue force")
    head = f"{'case':46s} {'close s':>7s} {'W_c(end) J':>11s} {'max W_c J':>10s} "
    print(head + f"{'hold std first':>14s} {'last rad':>9s} {'max alpha':>9s} {'balance J':>9s}")
    for name, p in cases.items():
        for close_s in SPEEDS_S:
            r = simulate_energy(p, s, close_s)
            first, last = _hold_std(r)
            print(f"{name:46s} {close_s:7.2f} {r.work_controller_J[-1]:+11.3e} "
                  f"{r.work_controller_J.max():10.3e} {first:14.2e} {last:9.2e} "
                  f"{r.alpha_Nms_per_rad.max():9.3g} {r.balance_error_J:9.1e}")  # fmt: skip
    print()
    print("rendered / tissue jaw force at 20 N (quasi-static closing, 22 -> 0 deg over 20 s)")
    for name, p in cases.items():
        print(f"{name:46s} {ratio_at_force(p, s):.3f}")
    print(f"\n{time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
