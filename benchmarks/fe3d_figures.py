"""Figures of a 3D sweep: per case the solver effort and the quantities of Guachi et al. (2020),
side by side with the 2D sweep. Prints, asserts nothing; reads the case files, runs no FE.

    python benchmarks/fe3d_figures.py [SWEEP_3D] [SWEEP_2D]   # default fe_data/default fe_data/2d

Columns: wall time (s), DOFs, steps, Newton iterations; force on one jaw (N) at gaps 20, 10, 5
mm (the bending plateau) and the 3D / 2D ratio there; gap (mm) where the force reaches 20 N;
the last state (closed height 1.5 mm or the 200 N cap): gap, force, peak and mean contact
pressure (MPa), tangential share of the jaw reaction.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from grasprom.fe.datafiles import own_wall_time_s, read_case

ROOT = Path(__file__).resolve().parents[1]
GAPS = (20.0, 10.0, 5.0)


def _at(g: np.ndarray, f: np.ndarray, gap: float) -> float:
    if gap < g.min() or gap > g.max():
        return float("nan")
    return float(np.interp(-gap, -g, f))


def _gap_at_force(g: np.ndarray, f: np.ndarray, level: float) -> float:
    if f.max() < level:
        return float("nan")
    return float(np.interp(level, f, g))  # f increases as g decreases


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    d3 = Path(argv[0]) if argv else ROOT / "fe_data" / "default"
    d2 = Path(argv[1]) if len(argv) > 1 else ROOT / "fe_data" / "2d"
    head = " ".join(f"F@{g:g}" for g in GAPS) + " " + " ".join(f"3D/2D@{g:g}" for g in GAPS)
    print(f"3D sweep {d3} vs 2D sweep {d2}")
    cols = ("g@20N", "g_last", "F_last", "p_peak", "p_mean", "tang")
    print(f"{'case':<9} {'wall_s':>7} {'dofs':>6} {'steps':>5} {'newton':>6}  {head}  "
          + " ".join(f"{c:>6}" for c in cols))  # fmt: skip
    for meta_path in sorted(d3.glob("*_t*.json")):
        case = read_case(meta_path)
        meta, tb = case.meta, case.table
        info = meta.get("fe_info", {})
        g, f = tb["gap_mm"].to_numpy(), tb["force_N"].to_numpy()
        f3 = [_at(g, f, x) for x in GAPS]
        p2 = d2 / meta_path.name
        ratio = [float("nan")] * len(GAPS)
        if p2.exists():
            t2 = read_case(p2).table
            g2, ff2 = t2["gap_mm"].to_numpy(), t2["force_N"].to_numpy()
            ratio = [a / _at(g2, ff2, x) for a, x in zip(f3, GAPS)]
        last = tb.iloc[-1]
        print(f"{meta['stem']:<9} {own_wall_time_s(info):7.0f} {info.get('dofs', 0):6d} "
              f"{info.get('steps', 0):5d} {info.get('newton_iterations', 0):6d}  "
              + " ".join(f"{x:5.3f}" for x in f3) + " "
              + " ".join(f"{x:8.2f}" for x in ratio)
              + f"  {_gap_at_force(g, f, 20.0):6.3f} {last['gap_mm']:6.3f} {last['force_N']:7.1f}"
              f" {last['peak_pressure_MPa']:6.3f} {last['mean_pressure_MPa']:6.3f}"
              f" {last.get('tangential_share', np.nan):5.2f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
