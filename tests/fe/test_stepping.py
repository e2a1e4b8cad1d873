"""Landing on requested gaps (grasprom.fe.stepping.land_on) and both models through a step
that stops just above one: a case once stopped `partial` 4 um above gap 2.7 mm (the default
3D case, landing on the mesh study's gaps), because the step left to land was shorter than
``dh_min_mm``."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from grasprom.fe.mesh3d import MeshSpec3D
from grasprom.fe.model2d import CaseSpec, MeshSpec, SolverSettings, run_case
from grasprom.fe.model3d import CaseSpec3D, run_case_3d
from grasprom.fe.stepping import land_on


@pytest.mark.parametrize(
    ("h", "dh", "landing", "expected"),
    [
        (2.0, 0.5, [1.6, 1.8], 0.2),  # passes two: lands on the higher
        (2.0, 0.1, [1.5], 0.1),  # none in reach
        (1.35, 0.01, [1.35], 0.01),  # the height it stands on is not a target
        (1.3557, 0.0057 - 4.4e-6, [1.35], 0.0057),  # stops 4.4 um above: stretched onto it
        (2.0, 1.0, [0.98], 1.0),  # 20 um short of it is 2 % of the step: not stretched
        (2.0, 1.0, [0.995], 1.005),  # 0.5 % of the step: stretched
    ],
)
def test_land_on(h, dh, landing, expected):
    assert land_on(h, dh, landing, dh_min=1e-5) == pytest.approx(expected, abs=1e-12)


def _just_above(table, k: int) -> float:
    """A gap (mm) 8 um below the k-th step's: a run landing on it first stops 4 um of jaw
    height above it."""
    return float(table["gap_mm"].iloc[k]) - 8e-6


def test_2d_model_lands_on_a_gap_its_step_stops_just_above():
    spec = CaseSpec("le", 1.0, closed_gap_mm=25.0, mesh=MeshSpec(1, 8))
    free = run_case(spec)
    target = _just_above(free.table, len(free.table) // 2)
    landed = run_case(replace(spec, solver=SolverSettings(land_on_gaps_mm=(target,))))
    assert free.status == landed.status == "complete"
    assert np.isclose(landed.table["gap_mm"], target, rtol=0, atol=1e-9).sum() == 1
    assert landed.table["gap_mm"].iloc[-1] == pytest.approx(25.0, abs=1e-9)


def test_3d_model_lands_on_a_gap_its_step_stops_just_above():
    mesh = MeshSpec3D(n_layers=1, n_circ=8, n_jaw=2, n_free=2)
    spec = CaseSpec3D("mr", 1.4, tube_length_mm=30.0, closed_gap_mm=26.0, mesh=mesh)
    free = run_case_3d(spec)
    target = _just_above(free.table, len(free.table) // 2)
    landed = run_case_3d(replace(spec, solver=replace(spec.solver, land_on_gaps_mm=(target,))))
    assert free.status == landed.status == "complete"
    assert np.isclose(landed.table["gap_mm"], target, rtol=0, atol=1e-9).sum() == 1
    assert landed.table["gap_mm"].iloc[-1] == pytest.approx(26.0, abs=1e-9)
