"""Two 3D sweeps case by case, e.g. the default mesh against the converged cross-section.
Prints, asserts nothing; reads the case files, runs no FE.

    python benchmarks/fe3d_compare.py REFERENCE OTHER   # e.g. fe_data/default fe_data/3d_2x12

For every case both sweeps have: the reference's force on one jaw (N) at gaps 20, 10 and 5 mm
and at 4t, 3t, 2.5t and 2t (t the wall thickness: the crease band 2t..4t and the walls
meeting), the other's deviation there (%), over the band 2t..4t (400 gaps, log-interpolated
between the steps) the largest and the median deviation, and the gap (mm) where each reaches
20 N (the top of the haptic range) with their difference (um).  Then the gap at equal force
(the other's minus the reference's, um, at 2, 5, 10, 20, 50 and 100 N: the measure that stays
well posed through the crease band, where the two may take different paths), and the cost of
each case.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from grasprom.fe.datafiles import own_wall_time_s, read_case

GAPS = (20.0, 10.0, 5.0)
BAND = (4.0, 3.0, 2.5, 2.0)  # multiples of t
FORCES = (2.0, 5.0, 10.0, 20.0, 50.0, 100.0)  # N, for the gap at equal force


def _curve(path: Path) -> tuple[np.ndarray, np.ndarray, dict]:
    case = read_case(path)
    tb = case.table
    return tb["gap_mm"].to_numpy(), tb["force_N"].to_numpy(), case.meta


def _at(g: np.ndarray, f: np.ndarray, gaps) -> np.ndarray:
    """Force (N) at ``gaps`` (mm), log-interpolated along the load path; NaN off the path."""
    gaps = np.asarray(gaps, float)
    out = np.exp(np.interp(-gaps, -g, np.log(np.maximum(f, 1e-12))))
    return np.where((gaps >= g.min() - 1e-9) & (gaps <= g.max() + 1e-9), out, np.nan)


def _gap_at(g: np.ndarray, f: np.ndarray, level: float = 20.0) -> float:
    """First gap (mm) along the path where the force reaches ``level`` (N)."""
    k = int(np.argmax(f >= level))
    if f[k] < level:
        return float("nan")
    if k == 0:
        return float(g[0])
    s = (level - f[k - 1]) / (f[k] - f[k - 1])
    return float(g[k - 1] + s * (g[k] - g[k - 1]))


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2:
        print("usage: python benchmarks/fe3d_compare.py REFERENCE OTHER", file=sys.stderr)
        return 2
    ref_dir, other_dir = (Path(a) for a in argv)
    print(f"reference {ref_dir} vs {other_dir}: force (N) and deviation (%)")
    head = [f"@{g:g}" for g in GAPS] + [f"@{m:g}t" for m in BAND]
    tail = f" {'band max':>9} {'median':>7} {'g@20N ref':>9} {'other':>7} {'d (um)':>7}"
    print(f"{'case':<9} " + " ".join(f"{h:>15}" for h in head) + tail)
    costs = []
    for path in sorted(ref_dir.glob("*_t*.json")):
        other = other_dir / path.name
        if not other.exists():
            continue
        g1, f1, m1 = _curve(path)
        g2, f2, m2 = _curve(other)
        t = float(m1["thickness_mm"])
        gaps = np.array(GAPS + tuple(m * t for m in BAND))
        a, b = _at(g1, f1, gaps), _at(g2, f2, gaps)
        grid = np.linspace(2 * t + 0.02 * t, 4 * t, 400)
        band = _at(g2, f2, grid) / _at(g1, f1, grid) - 1.0
        z1, z2 = _gap_at(g1, f1), _gap_at(g2, f2)
        cells = " ".join(f"{x:7.3f} {100 * (y / x - 1):+6.1f}%" for x, y in zip(a, b))
        print(f"{m1['stem']:<9} {cells} {100 * np.nanmax(np.abs(band)):8.1f}% "
              f"{100 * np.nanmedian(np.abs(band)):6.1f}% {z1:9.3f} {z2:7.3f} "
              f"{1000 * (z2 - z1):+7.0f}")  # fmt: skip
        costs.append((m1, m2, (g1, f1), (g2, f2)))
    print("gap at equal force, other - reference (um): " + " ".join(f"{x:g} N" for x in FORCES))
    for m1, _, (g1, f1), (g2, f2) in costs:
        d = [1000 * (_gap_at(g2, f2, x) - _gap_at(g1, f1, x)) for x in FORCES]
        print(f"{m1['stem']:<9} " + " ".join(f"{x:+8.1f}" for x in d))
    print("cost (own-run wall s, DOFs, steps, Newton iterations, failed steps; + the band "
          "selection's wall s where it has one): reference | other")  # fmt: skip
    for m1, m2, _, _ in costs:
        i1, i2 = m1.get("fe_info", {}), m2.get("fe_info", {})
        cells = [
            f"{own_wall_time_s(i):6.0f} {i.get('dofs', 0):6d} "
            f"{i.get('steps', 0):4d} {i.get('newton_iterations', 0):5d} {i.get('failures', 0):3d}"
            + (f" +{i['band_selection']['wall_time_s']:5.0f}" if "band_selection" in i else "")
            for i in (i1, i2)
        ]
        print(f"{m1['stem']:<9} {cells[0]} | {cells[1]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
