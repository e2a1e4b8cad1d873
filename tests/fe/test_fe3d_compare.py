"""``benchmarks/fe3d_compare.py``, the command docs/fe-sweeps.md and docs/fe-model.md quote for
the two shipped 3D sweeps: it runs on them and prints what the docs' table reads off it (reads
files, runs no FE; a few seconds)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from grasprom.fe.datafiles import read_case

ROOT = Path(__file__).resolve().parents[2]


def _run(*args: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "benchmarks/fe3d_compare.py", *args]
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120)


def test_compares_every_shared_case_and_reads_the_gap_at_20_newton():
    res = _run("fe_data/default", "fe_data/3d_2x12")
    assert res.returncode == 0, res.stderr
    rows: dict[str, list[str]] = {}  # the comparison's line of each case (the cost line follows)
    for ln in res.stdout.splitlines():
        if "_t" in ln[:9]:
            rows.setdefault(ln.split()[0], ln.split())
    stems = {f"{m}_t{t:.2f}" for m in ("mr", "nh", "le") for t in np.arange(0.8, 2.01, 0.2)}
    assert stems <= set(rows)
    # the gap at 20 N (first crossing along the path) of both, read off the tables here
    for name, col in (("default", -3), ("3d_2x12", -2)):
        tb = read_case(ROOT / "fe_data" / name / "mr_t1.40.json").table
        g, f = tb["gap_mm"].to_numpy(), tb["force_N"].to_numpy()
        k = int(np.argmax(f >= 20.0))
        gap = g[k - 1] + (20.0 - f[k - 1]) / (f[k] - f[k - 1]) * (g[k] - g[k - 1])
        assert float(rows["mr_t1.40"][col]) == pytest.approx(gap, abs=1e-3)


def test_usage_error_without_two_sweeps():
    res = _run("fe_data/default")
    assert res.returncode == 2 and "fe3d_compare.py REFERENCE OTHER" in res.stderr
