"""Time a sweep with the real FE runner for 1 and 2 local workers; print the speed-up.

Usage::

    python benchmarks/bench_sweep.py --thickness 0.8:2.0:0.2 --material mr,nh,le
    python benchmarks/bench_sweep.py --model 3d --thickness 1.4,2.0 --material mr,le
    python benchmarks/bench_sweep.py --model 3d --mesh coarse --thickness 1.4 --material mr,le

Each worker count runs into its own fresh directory under ``--out`` (default a temporary
directory), so no case is skipped. Times in s.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from grasprom.fe import build_grid, load_sweep, run_sweep
from grasprom.fe.grid import SweepInputError
from grasprom.fe.grid3d import (
    DEFAULT_MESH_PRESET,
    MESH_PRESETS,
    Model3DOptions,
    check_options,
    to_3d,
)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; returns the process exit code."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--thickness", default="0.8:2.0:0.2", help="wall thicknesses in mm")
    p.add_argument("--material", default="mr,nh,le", help="comma list of materials")
    p.add_argument("--workers", default="1,2", help="comma list of worker counts to time")
    p.add_argument("--out", default=None, help="scratch directory (default: a temp dir)")
    p.add_argument("--progress", action="store_true", help="show progress bars")
    p.add_argument("--model", choices=("2d", "3d"), default="2d", help="FE model (default 2d)")
    p.add_argument("--mesh", choices=tuple(MESH_PRESETS), default=DEFAULT_MESH_PRESET,
                   help=f"3d: named mesh (default {DEFAULT_MESH_PRESET}, as sweep)")  # fmt: skip
    p.add_argument("--band-companion", type=int, default=None, metavar="K",
                   help="3d: as sweep (default: the mesh's; 0: own runs)")  # fmt: skip
    args = p.parse_args(argv)

    specs = build_grid(args.thickness, args.material)
    if args.model == "3d":  # the defaults of `grasprom sweep --model 3d`
        opts = Model3DOptions(mesh=args.mesh, band_companion=args.band_companion)
        try:
            check_options("3d", opts)
        except SweepInputError as exc:
            raise SystemExit(f"bench_sweep: {exc}") from exc
        specs = to_3d(specs, opts, {})
    counts = [int(w) for w in args.workers.split(",")]
    base = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="grasprom-bench-"))
    print(f"{len(specs)} {args.model} cases ({args.material} x {args.thickness} mm), "
          f"cpu_count={os.cpu_count()}")  # fmt: skip
    times: dict[int, float] = {}
    for w in counts:
        out = base / f"workers{w}"
        if out.exists() and any(out.iterdir()):
            raise SystemExit(f"--out: {out} is not empty; give a fresh --out")
        t0 = time.perf_counter()
        summary = run_sweep(specs, out, workers=w, progress=args.progress)
        times[w] = time.perf_counter() - t0
        data = load_sweep(out)
        print(
            f"workers={w}: wall {times[w]:.1f} s, {len(summary.done)} done, "
            f"{len(summary.failed)} failed, {len(summary.partial)} partial, "
            f"{len(data)} load steps"
        )
    if len(times) > 1:
        w0 = min(times)
        for w in sorted(times):
            if w != w0:
                print(f"speed-up {w} vs {w0} workers: {times[w0] / times[w]:.2f}x")
    print(f"outputs in {base}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
