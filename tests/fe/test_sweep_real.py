"""Sweeps with the real FE runner: kill + resume, process pool vs in-process vs Dask.

Cases are shortened (closed gap 12 mm: bending regime only) so each takes about a second.
"""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from grasprom.fe import datafiles as df
from grasprom.fe.grid import build_grid
from grasprom.fe.sweep import run_sweep

# the resume machinery, not the physics, is under test: the earlier, 4x cheaper 2 x 32 mesh
GRID = dict(thickness="0.8:2.0:0.4", materials="mr,le", closed_gap_mm=12.0, n_layers=2, n_circ=32)


def _hashes(d: Path) -> dict[str, str]:
    return {p.name: json.loads(p.read_text())["csv_sha256"] for p in df.case_json_paths(d)}


@pytest.mark.slow(seconds=22)
def test_kill_and_resume_loses_nothing_real_fe(tmp_path):
    out = tmp_path / "killed"
    cmd = [
        sys.executable, "-m", "grasprom", "sweep", "--thickness", GRID["thickness"],
        "--material", GRID["materials"], "--closed-gap", str(GRID["closed_gap_mm"]),
        "--n-layers", str(GRID["n_layers"]), "--n-circ", str(GRID["n_circ"]),
        "--workers", "1", "--quiet", "--out", str(out),
    ]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.time()
    try:
        while len(df.case_json_paths(out)) < 2:
            assert proc.poll() is None, "sweep ended before it could be killed"
            assert time.time() - t0 < 120, "no case finished in 120 s"
            time.sleep(0.05)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    before = _hashes(out)
    assert 2 <= len(before) < 8
    mtimes = {p.name: p.stat().st_mtime_ns for p in df.case_json_paths(out)}
    rerun = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert rerun.returncode == 0, rerun.stderr
    after = _hashes(out)
    assert len(after) == 8
    for name, h in before.items():  # finished cases were kept, not recomputed
        assert after[name] == h
        assert (out / name).stat().st_mtime_ns == mtimes[name]
    clean = tmp_path / "clean"
    run_sweep(build_grid(**GRID), clean, workers=2, progress=False)
    assert _hashes(clean) == after  # bit-identical to an uninterrupted sweep


@pytest.mark.slow(seconds=20)
def test_dask_cluster_equals_process_pool_real_fe(tmp_path):
    from dask.distributed import LocalCluster

    specs = build_grid("0.8,1.6", "nh", closed_gap_mm=12.0)
    run_sweep(specs, tmp_path / "pool", workers=2, progress=False)
    with LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address=None,
        silence_logs=logging.ERROR,
    ) as cluster:
        s = run_sweep(specs, tmp_path / "dask", scheduler=cluster.scheduler_address, progress=False)
    assert s.ok and len(s.done) == 2
    a, b = df.load_sweep(tmp_path / "pool"), df.load_sweep(tmp_path / "dask")
    pd.testing.assert_frame_equal(a, b)
    assert _hashes(tmp_path / "pool") == _hashes(tmp_path / "dask")
