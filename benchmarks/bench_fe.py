"""Wall time of one FE clamping case per material at several wall thicknesses.

Usage::

    python benchmarks/bench_fe.py [--thickness 0.8,1.4,2.0] [--material mr,nh,le]

Prints, per case: DOFs, load steps, Newton iterations, failures (step cuts), status, wall time
(s), and the time share of the vectorised assembly, the sparse solves and the rest. Printed, not
asserted: timings depend on the machine (target on the 2-core reference machine: <= 20 s, aim 10 s).
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time

from grasprom.fe import CaseSpec, MeshSpec, run_case


def _share(stats: pstats.Stats, name: str, total: float) -> float:
    """Cumulative-time share (%) of functions whose name contains ``name``."""
    cum = sum(v[3] for k, v in stats.stats.items() if name in k[2])
    return 100.0 * cum / total if total > 0 else 0.0


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; returns the exit code."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--thickness", default="0.8,1.4,2.0", help="comma list, mm")
    p.add_argument("--material", default="mr,nh,le", help="comma list of materials")
    p.add_argument("--n-layers", type=int, default=MeshSpec().n_layers)
    p.add_argument("--n-circ", type=int, default=MeshSpec().n_circ)
    p.add_argument("--profile", action="store_true", help="report assembly/solve time shares")
    args = p.parse_args(argv)
    mesh = MeshSpec(n_layers=args.n_layers, n_circ=args.n_circ)
    print(f"mesh: {mesh}")
    hdr = f"{'mat':>4} {'t_mm':>5} {'dofs':>6} {'steps':>5} {'newton':>6} {'cuts':>4} "
    hdr += f"{'status':>9} {'last_gap_mm':>11} {'wall_s':>7}"
    if args.profile:
        hdr += f" {'assembly%':>9} {'solve%':>6}"
    print(hdr)
    walls = []
    for mat in args.material.split(","):
        for t in (float(x) for x in args.thickness.split(",")):
            spec = CaseSpec(mat, t, mesh=mesh)
            prof = cProfile.Profile() if args.profile else None
            t0 = time.perf_counter()
            if prof:
                prof.enable()
            res = run_case(spec)
            if prof:
                prof.disable()
            wall = time.perf_counter() - t0
            walls.append(wall)
            i = res.info
            line = (
                f"{mat:>4} {t:5.2f} {i['dofs']:6d} {i['steps']:5d} {i['newton_iterations']:6d} "
                f"{i['failures']:4d} {res.status:>9} {i['last_gap_mm']:11.3f} {wall:7.2f}"
            )
            if prof:
                st = pstats.Stats(prof)
                line += f" {_share(st, 'assemble', wall):9.0f} {_share(st, 'spsolve', wall):6.0f}"
            print(line, flush=True)
    print(f"max {max(walls):.2f} s, mean {sum(walls) / len(walls):.2f} s per case")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
