"""Shared fixtures for the sweep-infrastructure tests."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


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
