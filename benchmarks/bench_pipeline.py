"""Benchmark of the main job ``grasprom build`` (printed, not asserted).

Runs ``grasprom build`` (full and ``--fast``) on the shipped data as a fresh process, as a user
would (imports included), ``--repeat`` times each into new temporary folders, and prints the
wall time of each run, the per-stage times from ``build.json`` and the median.  Target: the full
job under 60 s on the 2-core machine.

Run: ``python benchmarks/bench_pipeline.py [--repeat 3]``
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from grasprom.pipeline import STAGES


def run_once(fast: bool) -> tuple[float, dict[str, float]]:
    """Wall time (s) of one ``grasprom build`` process and its stage times (s)."""
    with tempfile.TemporaryDirectory(prefix="grasprom_bench_") as tmp:
        out = Path(tmp) / "build"
        cmd = [sys.executable, "-m", "grasprom", "build", "--out", str(out), "--quiet"]
        if fast:
            cmd.append("--fast")
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True, cwd=tmp)
        wall = time.perf_counter() - t0
        stages = json.loads((out / "build.json").read_text())["provenance"]["stage_times_s"]
    return wall, stages


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="runs per mode")
    args = ap.parse_args(argv)
    print(f"{'mode':6s} {'run':>3s} {'wall s':>7s} " + " ".join(f"{s:>9s}" for s in STAGES))
    for fast in (False, True):
        mode = "fast" if fast else "full"
        walls = []
        for i in range(args.repeat):
            wall, st = run_once(fast)
            walls.append(wall)
            print(f"{mode:6s} {i + 1:3d} {wall:7.1f} "
                  + " ".join(f"{st.get(s, float('nan')):9.1f}" for s in STAGES))  # fmt: skip
        print(f"{mode:6s} median {statistics.median(walls):.1f} s (target < 60 s)")


if __name__ == "__main__":
    main()
