"""Shared fixtures for the sweep-infrastructure tests."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from grasprom.threads import default_blas_threads

ROOT = Path(__file__).resolve().parents[1]

#: One thread per BLAS / OpenMP / MKL pool, in the test processes and every child they start.
#: The suite runs two xdist workers on the machine's two cores; with the libraries' default of
#: one thread per core each worker ran two, and the four busy threads made the 3D tests 2-3x
#: slower (the stick-anchor test: 42 s with one thread and 46 s with two when run alone, 123 s in
#: the slow step beside another test). numpy (OpenBLAS) and MKL read these when they load, which
#: is after this module: nothing imports numpy before it (tests/test_threads.py reads the pools
#: they opened). A value set by the caller wins.
default_blas_threads(1)


@pytest.fixture
def subprocess_env() -> dict[str, str]:
    """Environment for child Pythons: the source tree importable, no progress noise."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env.setdefault("PYTHONUNBUFFERED", "1")
    return env


@pytest.fixture
def python() -> str:
    """The interpreter running the tests."""
    return sys.executable


@pytest.fixture(scope="session")
def surrogate():
    """Surrogate built once from the shipped 2D sweep fe_data/2d: the unit tests of the controller,
    exports and diagnosis run on this fixed, fast data set; the default (3D) data is what the
    end-to-end tests (build, examples, README commands) use."""
    from grasprom.surrogate import Surrogate

    return Surrogate.build(ROOT / "fe_data" / "2d")


@pytest.fixture(scope="session")
def surrogate_mr_le(tmp_path_factory):
    """Surrogate of the shipped 2D sweep without nh (issue 16: exports of a sweep that lacks a
    material; nh, code 1, is the gap between the covered codes 0 mr and 2 le)."""
    from grasprom.surrogate import Surrogate
    from tests.sweep_subset import copy_sweep

    return Surrogate.build(
        copy_sweep("fe_data/2d", tmp_path_factory.mktemp("fe_mr_le"), ["mr", "le"])
    )


def slow_seconds(item: pytest.Item) -> float | None:
    """The ``seconds=`` of a test's ``slow`` marker (its measured cost); None if not slow."""
    mark = item.get_closest_marker("slow")
    return None if mark is None else mark.kwargs.get("seconds")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Every ``slow`` test states its cost, ``@pytest.mark.slow(seconds=S)`` (measured alone
    beside the other worker, this machine), and the slow tests run longest first.

    CI's slow step hands them out in this order to whichever worker runs short of work
    (``--dist loadgroup --no-loadscope-reorder``; without the flag xdist orders the groups by
    size), close to the classic longest-first list schedule: 627 s for the step in collection
    order, 499 s in this order the same day. A ``slow`` test without ``seconds`` stops the
    collection, so a new one cannot fall to the end of the queue unnoticed.
    """
    missing = [i.nodeid for i in items if i.get_closest_marker("slow") and slow_seconds(i) is None]
    if missing:
        raise pytest.UsageError(f"slow tests without @pytest.mark.slow(seconds=...): {missing}")
    items.sort(key=lambda i: -(slow_seconds(i) or 0.0))  # stable: the fast tests keep their order
