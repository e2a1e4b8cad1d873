"""The wheel is self-contained: built from a copy of the checkout, installed (not editable) into
a fresh virtual environment, ``grasprom build`` runs from an unrelated directory.

The venv sees the machine's site-packages for the dependencies (numpy, scipy, scikit-fem, ...),
so only the wheel itself is installed; the test asserts that ``grasprom`` is imported from the
venv, not from the checkout, and that the shipped FE data and C sources come from inside the
installed package (``grasprom/_shipped``).  Marked ``slow`` (about a minute); CI runs it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.checkout import copy_checkout

ROOT = Path(__file__).resolve().parents[1]


def _run(cmd: list[str], cwd: Path, env: dict[str, str], timeout: float) -> str:
    res = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert res.returncode == 0, (
        f"{cmd} failed ({res.returncode}):\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}"
    )
    return res.stdout


@pytest.mark.slow(seconds=37)
def test_wheel_installs_and_builds_from_another_directory(tmp_path):
    repo = tmp_path / "repo"
    repo.mkdir()
    copy_checkout(repo)
    venv = tmp_path / "venv"
    subprocess.run(
        [sys.executable, "-m", "venv", "--system-site-packages", str(venv)], check=True, timeout=120
    )
    py = str(venv / "bin" / "python")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env["PATH"] = os.pathsep.join([str(venv / "bin"), env.get("PATH", "")])
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    wheels = tmp_path / "wheels"
    _run(
        [py, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(wheels), str(repo)],
        tmp_path,
        env,
        600,
    )
    (wheel,) = wheels.glob("grasprom-*.whl")
    _run(
        [py, "-m", "pip", "install", "--no-deps", "--force-reinstall", "-q", str(wheel)],
        tmp_path,
        env,
        600,
    )

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    probe = (
        "import json, grasprom, grasprom.paths as p; print(json.dumps({'file': grasprom.__file__, "
        "'shipped': str(p.shipped_root()), 'core': str(p.c_file('grasp_core.c'))}))"
    )
    where = json.loads(_run([py, "-c", probe], elsewhere, env, 120))
    site = str(venv)
    assert where["file"].startswith(site), where  # the installed wheel, not the checkout
    assert where["shipped"].startswith(site) and where["shipped"].endswith("_shipped"), where
    assert where["core"].startswith(where["shipped"]), where

    grasprom = str(venv / "bin" / "grasprom")
    _run([grasprom, "build", "--out", "out", "--fast", "--quiet"], elsewhere, env, 900)
    out = elsewhere / "out"
    for name in ("report.html", "surrogate.json", "controller.json", "GraspController.fmu",
                 "GraspController_fmi3.fmu", "build.json", "cosim.csv"):  # fmt: skip
        assert (out / name).is_file(), name
    sur = json.loads((out / "surrogate.json").read_text())
    assert sur["fe_source"].startswith(site), sur["fe_source"]  # shipped data of the wheel
    assert not (ROOT / "out").exists()
