"""Print the FE figures quoted in README from a sweep directory (default: fe_data/default).

Usage::

    python benchmarks/fe_figures.py [fe_data/default]

Bending-regime forces (N) at gap 20 mm, 10 mm and 2t + 1 mm, the gap where the force first
passes 10 N relative to 2t, and the largest MR/NH difference where the force exceeds 0.05 N.
"""

from __future__ import annotations

import sys

import numpy as np

from grasprom.fe import load_sweep


def main(argv: list[str] | None = None) -> int:
    """Print the table; returns the exit code."""
    argv = sys.argv[1:] if argv is None else argv
    path = argv[0] if argv else "fe_data/default"
    d = load_sweep(path)
    cols = ("F@20mm_N", "F@10mm_N", "F@2t+1_N")
    head = " ".join(f"{c:>9}" for c in cols)
    print(f"{'mat':>4} {'t_mm':>5} {head} {'gap@10N-2t_mm':>13}")
    curves = {}
    for (m, t), c in d.groupby(["material", "thickness_mm"]):
        g, f = c["gap_mm"].to_numpy(), c["force_N"].to_numpy()
        curves[m, t] = (g, f)
        at = [np.interp(-x, -g, f) for x in (20.0, 10.0, 2 * t + 1.0)]
        g10 = g[np.argmax(f >= 10.0)] - 2 * t if f.max() >= 10.0 else float("nan")
        print(f"{m:>4} {t:5.2f} {at[0]:9.4f} {at[1]:9.4f} {at[2]:9.4f} {g10:13.3f}")
    worst = 0.0
    for (m, t), (g, f) in curves.items():
        if m != "mr" or ("nh", t) not in curves:
            continue
        gn, fn = curves["nh", t]
        grid = np.linspace(max(g.min(), gn.min()), g.max(), 400)
        a, b = np.interp(-grid, -g, f), np.interp(-grid, -gn, fn)
        sel = np.maximum(a, b) > 0.05
        worst = max(worst, float(np.max(np.abs(a[sel] / b[sel] - 1))))
    print(f"max |F_mr / F_nh - 1| where F > 0.05 N: {100 * worst:.2f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
