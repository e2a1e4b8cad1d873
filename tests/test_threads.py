"""The test processes run their numerical libraries on one thread each (``tests/conftest.py``).

Two xdist workers share the machine's two cores; a library that starts one thread per core in
each worker puts four busy threads on two cores, and the 3D tests of the slow step took 2-3x as
long (1084 s for the step against 627 s). These tests read the thread pools the libraries
actually opened (threadpoolctl), in a worker and in a child process, rather than the
environment variables alone.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from threadpoolctl import threadpool_info

from grasprom.fe.linsolve import pardiso_available
from grasprom.threads import BLAS_THREAD_VARS, default_blas_threads

#: threadpoolctl's ``internal_api`` -> the variable that sets its pool's size.
POOL_VARIABLE = {
    "openblas": "OPENBLAS_NUM_THREADS",
    "mkl": "MKL_NUM_THREADS",
    "openmp": "OMP_NUM_THREADS",
}


def _check(info: list[dict], mkl: bool) -> None:
    """Every pool of a known library has the size its variable sets (1 unless the caller set
    it). On this 2-core machine a library loaded before the setting opens 2 and fails this."""
    pools = [(p["internal_api"], p["num_threads"], p["filepath"]) for p in info]
    expected = {"openblas", "mkl"} if mkl else {"openblas"}
    assert expected <= {api for api, _, _ in pools}, pools
    for api, n, path in pools:
        if api in POOL_VARIABLE:
            assert n == int(os.environ[POOL_VARIABLE[api]]), (api, n, path)


def _mkl() -> bool:
    """Whether MKL (pypardiso, a dev dependency on x86-64) is there; required under CI=true."""
    if os.environ.get("CI") == "true":
        assert pardiso_available()
    return pardiso_available()


def test_the_callers_value_wins_and_a_count_below_one_is_refused(monkeypatch):
    for var in BLAS_THREAD_VARS:
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv("MKL_NUM_THREADS", "3")
    default_blas_threads(2)
    assert [os.environ[v] for v in BLAS_THREAD_VARS] == ["2", "2", "3"]
    with pytest.raises(ValueError, match="n must be >= 1"):
        default_blas_threads(0)


def test_the_worker_pools_have_the_set_size():
    np.ones((200, 200)) @ np.ones((200, 200))  # OpenBLAS is loaded and used
    mkl = _mkl()  # loads MKL first
    _check(threadpool_info(), mkl)


def test_a_child_process_inherits_the_size():
    code = (
        "import json, numpy; from threadpoolctl import threadpool_info; "
        "from grasprom.fe.linsolve import pardiso_available; pardiso_available(); "
        "print(json.dumps(threadpool_info()))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    mkl = _mkl()
    _check(json.loads(out.stdout), mkl)
