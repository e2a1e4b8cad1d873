"""Thread counts of the numerical libraries in a new process: the one place they are set.

numpy and scipy (OpenBLAS), MKL (PARDISO) and OpenMP size their thread pools from environment
variables when they load, by default one thread per core. Several processes on few cores, each
with a thread per core, oversubscribe the machine: two 3D sweep cases on two cores ran at 60 %
of a core each, and the test suite's slow step took 1084 s instead of 627 s. The sweep's pool
workers, the test processes and ``benchmarks/bench_fe3d.py`` therefore start with one thread
each. This module imports nothing heavy, so a caller can use it before numpy is loaded.
"""

from __future__ import annotations

import os

BLAS_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
"""Environment variables that size the BLAS thread pools of numpy/scipy in a new process."""


def default_blas_threads(n: int = 1) -> None:
    """Give each library ``n`` threads unless the variable is already set (the user's value
    wins).

    Parameters
    ----------
    n : int
        Threads per pool (>= 1). Takes effect for libraries loaded after the call, in this
        process and in the processes it starts; pools already open keep their size.
    """
    if n < 1:
        raise ValueError(f"n must be >= 1 thread, got {n}")
    for var in BLAS_THREAD_VARS:
        os.environ.setdefault(var, str(n))
