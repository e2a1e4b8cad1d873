"""Benchmark of the force surrogate (printed, not asserted).

Prints vectorised evaluations per second on 1e6 random points (gap and thickness random, and
one thickness with random gaps), the scalar call time, and the table size (nodes, bytes) for
node tolerances 0.5 %, 1 % and 2 %.

Run: ``python benchmarks/bench_surrogate.py [fe_data/default]``
"""

from __future__ import annotations

import json
import sys
import time
import timeit

import numpy as np

from grasprom.surrogate import BuildParams, Surrogate, read_fe_cases


def _rate(fn, n: int, repeat: int = 5) -> float:
    fn()
    best = min(timeit.repeat(fn, number=1, repeat=repeat))
    return n / best


def main(argv: list[str]) -> None:
    sweep = argv[0] if argv else "fe_data/default"
    cases, _ = read_fe_cases(sweep)
    s = Surrogate.from_cases(cases, BuildParams(tol=0.005), source=sweep)
    rng = np.random.default_rng(0)
    n = 1_000_000
    g = rng.uniform(1.0, 31.0, n)
    t = rng.uniform(0.8, 2.0, n)
    print(f"vectorised, {n:.0e} random (gap, thickness) points, one core:")
    for m in s.materials:
        rf = _rate(lambda m=m: s.force(g, t, m), n)
        rk = _rate(lambda m=m: s.stiffness(g, t, m), n)
        r1 = _rate(lambda m=m: s.force(g, 1.25, m), n)
        print(
            f"  {m}: force {rf / 1e6:6.1f} M/s, stiffness {rk / 1e6:6.1f} M/s, "
            f"force at one thickness {r1 / 1e6:6.1f} M/s"
        )
    k = 200_000
    gl, tl = g[:k].tolist(), t[:k].tolist()
    fs = s.force_scalar
    t0 = time.perf_counter()
    for a, b in zip(gl, tl):
        fs(a, b, "mr")
    dt = (time.perf_counter() - t0) / k
    ev = s.evaluate_scalar
    t0 = time.perf_counter()
    for a, b in zip(gl, tl):
        ev(a, b, "mr")
    dt2 = (time.perf_counter() - t0) / k
    print(
        f"scalar (pure Python): force_scalar {dt * 1e6:.2f} us/call, "
        f"evaluate_scalar (F, k, flag) {dt2 * 1e6:.2f} us/call"
    )
    print("table size (all materials):")
    print(f"  {'tol':>6} {'nodes':>6} {'float32 x,F,dF/dg':>18} {'JSON table':>11}")
    for tol in (0.005, 0.01, 0.02):
        st = Surrogate.from_cases(cases, BuildParams(tol=tol))
        nodes = st.node_count()
        d = st.to_dict()
        d["errors"] = {}
        js = len(json.dumps(d, separators=(",", ":")).encode())
        print(f"  {tol:6.3f} {nodes:6d} {12 * nodes:15d} B {js:9d} B")
        for m in st.materials:
            print(f"         {m}: nodes per curve {st.errors['fit'][m]['nodes']}")


if __name__ == "__main__":
    main(sys.argv[1:])
