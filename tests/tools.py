"""External tools the tests need (compilers, simulators, a second FE code).

CI installs them (``.ci/run``); with ``CI=true`` a missing tool is a failure, never a skip.
"""

from __future__ import annotations

import os
import shutil

import pytest

CI = os.environ.get("CI") == "true"


def need(tool: str, package: str) -> None:
    """Skip locally, fail on CI, when ``tool`` is not on the PATH (``package``: its apt name)."""
    if shutil.which(tool) is None:
        msg = f"{tool} not found: apt-get install {package}"
        if CI:
            pytest.fail(msg)
        pytest.skip(msg)
