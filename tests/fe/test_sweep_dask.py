"""The Dask path: a LocalCluster on loopback gives the same results as the process pool."""

from __future__ import annotations

import json
import logging

import pandas as pd

from grasprom.fe import datafiles as df
from grasprom.fe.grid import SweepInputError, build_grid
from grasprom.fe.sweep import run_sweep
from tests import fake_runner as fr


def test_dask_local_cluster_equals_process_pool(tmp_path):
    from dask.distributed import LocalCluster

    specs = build_grid("0.8:1.4:0.2", "mr,le")
    pool = run_sweep(specs, tmp_path / "pool", workers=2, progress=False, runner=fr.sleepy_runner)
    assert pool.ok

    with LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address=None,
        silence_logs=logging.ERROR,
    ) as cluster:
        addr = cluster.scheduler_address
        assert addr.startswith("tcp://127.0.0.1:")
        s = run_sweep(
            specs, tmp_path / "dask", scheduler=addr, progress=False, runner=fr.sleepy_runner
        )
        assert s.ok and len(s.done) == len(specs)
        # resume through the cluster: nothing to run
        s2 = run_sweep(
            specs, tmp_path / "dask", scheduler=addr, progress=False, runner=fr.sleepy_runner
        )
        assert len(s2.skipped) == len(specs) and not s2.done
        # a failing case on the cluster is recorded, the others finish
        s3 = run_sweep(
            specs, tmp_path / "dask_fail", scheduler=addr, progress=False, runner=fr.failing_runner
        )
        assert [stem for stem, _ in s3.failed] == ["mr_t1.00", "le_t1.00"]
        assert (tmp_path / "dask_fail" / "mr_t1.00.error.txt").exists()

    pd.testing.assert_frame_equal(
        df.load_sweep(tmp_path / "pool"), df.load_sweep(tmp_path / "dask")
    )
    for p in df.case_json_paths(tmp_path / "pool"):
        a = json.loads(p.read_text())
        b = json.loads((tmp_path / "dask" / p.name).read_text())
        assert (a["csv_sha256"], a["input_hash"]) == (b["csv_sha256"], b["input_hash"])
    assert (
        json.loads((tmp_path / "dask" / "sweep.json").read_text())["last_run"]["scheduler"] == addr
    )


def test_unreachable_scheduler_is_input_error(tmp_path):
    import socket

    with socket.socket() as sock:  # a free port nobody listens on
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    specs = build_grid("1.0", "mr")
    try:
        run_sweep(
            specs,
            tmp_path,
            scheduler=f"tcp://127.0.0.1:{port}",
            progress=False,
            runner=fr.fast_runner,
            scheduler_timeout_s=2,
        )
    except SweepInputError as exc:
        assert f"127.0.0.1:{port}" in str(exc)
    else:
        raise AssertionError("expected SweepInputError")
    assert not df.case_json_paths(tmp_path)
