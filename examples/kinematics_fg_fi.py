"""Grasper kinematic chain: table of gap and force transmission vs handle angle, and the plot.

Prints theta, jaw gap, gap slope, rod stroke, link angle beta, Fg/Fi of the derived chain and of
Guachi et al.'s (2020) eqs (1)-(4), and the finger force the return spring alone needs; writes
``kinematics_fg_fi.png`` (Fg/Fi in percent vs theta, Guachi et al. (2020) Fig. 6) into ``--out``.

    python examples/kinematics_fg_fi.py --out /tmp/kin
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from grasprom.chain import kinematics as kin


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("."), help="output directory (default .)")
    ap.add_argument("--step", type=float, default=2.0, help="theta step of the table, deg")
    args = ap.parse_args(argv)

    p = kin.ChainParams()
    lo, hi = kin.theta_range_deg(p)
    print(p)
    print(
        f"derived: m = {p.m_mm:.3f} mm, rod stroke = {p.rod_stroke_mm:.3f} mm, "
        f"jaw opening = {p.jaw_open_angle_deg:.1f} deg, beta_open = {p.beta_open_deg:.2f} deg "
        f"(Table 1: 19), first touch at theta = {p.theta_touch_deg:.2f} deg"
    )
    th = np.unique(np.append(np.arange(lo, hi, args.step), [hi, p.theta_touch_deg]))
    gap = kin.gap_mm(th, p)
    dg = kin.dgap_dtheta_mm_per_rad(th, p)
    dx = kin.spring_dx_mm(th, p)
    beta = kin.beta_deg(th, p)
    r = kin.transmission_ratio(th, p)
    rs = kin.seed_transmission_ratio(th, p)
    fsp = kin.spring_handle_force_N(th, p)
    fi50 = kin.handle_force_N(50.0, th, p)
    hdr = (
        f"{'theta_deg':>9} {'gap_mm':>8} {'dgap/dth':>9} {'dx_mm':>7} {'beta_deg':>8} "
        f"{'Fg/Fi_%':>8} {'paper_%':>7} {'dev_%':>7} {'Fi_spr_N':>8} {'Fi@50N':>7}"
    )
    print(hdr)
    for row in zip(th, gap, dg, dx, beta, r, rs, fsp, fi50):
        t, g, d1, u, b, ri, si, f0, f50 = row
        print(
            f"{t:9.3f} {g:8.3f} {d1:9.3f} {u:7.4f} {b:8.3f} {100 * ri:8.2f} {100 * si:7.2f} "
            f"{100 * (si / ri - 1):7.2f} {f0:8.3f} {f50:7.2f}"
        )
    dense = np.linspace(lo, hi, 2201)
    dev = kin.seed_transmission_ratio(dense, p) / kin.transmission_ratio(dense, p) - 1
    i = int(np.argmax(np.abs(dev)))
    print(
        f"Fg/Fi derived: {100 * r[-1]:.1f} % (open) -> {100 * r[0]:.1f} % (closed); "
        f"paper's formula deviation: max {100 * dev[i]:.1f} % at theta = {dense[i]:.2f} deg"
    )
    out = kin.plot_transmission(p, args.out / "kinematics_fg_fi.png")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
