"""Bad trajectories for ``simulate`` (issue 14): a unit mistake or unbounded work is an error
that names the column and the limit, raised before any step runs."""

from __future__ import annotations

import time

import pandas as pd
import pytest

from grasprom.cli import main
from grasprom.control import ControllerParams, simulate


def _traj(t, th):
    return pd.DataFrame({"time_s": t, "theta_deg": th})


def test_angles_in_radians_are_an_error(surrogate):
    with pytest.raises(ValueError, match=r"theta_deg.*radians\?"):
        simulate(_traj([0.0, 1.0], [0.38, 0.0]), ControllerParams(), surrogate)


@pytest.mark.parametrize("t_end", [1e5, 4000.0])  # 1e5 s, and a 4 s grasp written in ms
def test_too_many_steps_is_an_error_before_any_work(surrogate, t_end):
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=r"time_s.*over the limit of 2000000 steps.*in ms"):
        simulate(_traj([0.0, t_end], [22.0, 0.0]), ControllerParams(), surrogate)
    assert time.perf_counter() - t0 < 5.0  # refused up front, not after minutes


def test_the_step_limit_can_be_raised_and_must_be_an_integer(surrogate, monkeypatch):
    monkeypatch.setenv("GRASPROM_MAX_STEPS", "100")
    with pytest.raises(ValueError, match="limit of 100 steps"):
        simulate(_traj([0.0, 1.0], [22.0, 0.0]), ControllerParams(), surrogate)
    monkeypatch.setenv("GRASPROM_MAX_STEPS", "2000")
    assert len(simulate(_traj([0.0, 1.0], [22.0, 0.0]), ControllerParams(), surrogate)) == 1001
    monkeypatch.setenv("GRASPROM_MAX_STEPS", "many")
    with pytest.raises(ValueError, match="GRASPROM_MAX_STEPS"):
        simulate(_traj([0.0, 1.0], [22.0, 0.0]), ControllerParams(), surrogate)


def test_cli_simulate_names_the_file_and_writes_nothing(tmp_path, capsys):
    src = tmp_path / "rad.csv"
    _traj([0.0, 1.0], [0.38, 0.0]).to_csv(src, index=False)
    out = tmp_path / "sim.csv"
    assert main(["simulate", "--trajectory", str(src), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "rad.csv" in err and "radians" in err and "Traceback" not in err
    assert not out.exists()


def test_time_in_milliseconds_is_an_error_but_waypoints_pass(surrogate):
    """A 1 kHz record written in ms (step 1, span 1000) is refused naming the column; a few
    waypoints one second apart are a valid trajectory."""
    import numpy as np

    t = np.arange(0.0, 1000.0, 1.0)
    with pytest.raises(ValueError, match=r"time_s.*milliseconds"):
        simulate(_traj(t, np.linspace(22.0, 4.0, t.size)), ControllerParams(), surrogate)
    out = simulate(_traj([0.0, 1.0, 2.0, 3.0], [22.0, 10.0, 4.0, 22.0]), ControllerParams(),
                   surrogate)  # fmt: skip
    assert len(out) == 3001


def test_outputs_are_0644_whatever_the_umask(tmp_path):
    """simulate's CSV and tune's controller.json were created 0600 (mkstemp); now 0644."""
    import os

    from grasprom.control import save_params

    traj = tmp_path / "t.csv"
    _traj([0.0, 0.5], [22.0, 5.0]).to_csv(traj, index=False)
    old = os.umask(0o077)
    try:
        assert main(["simulate", "--trajectory", str(traj), "--out", str(tmp_path / "o.csv")]) == 0
        save_params(ControllerParams(), tmp_path / "controller.json")
    finally:
        os.umask(old)
    for name in ("o.csv", "controller.json"):
        assert (tmp_path / name).stat().st_mode & 0o777 == 0o644, name
    assert not list(tmp_path.glob("*.tmp")) and not list(tmp_path.glob(".*.tmp"))
