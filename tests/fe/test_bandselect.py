"""The crease band's lower-energy state across two starts (grasprom.fe.bandselect).

A coarse 3D case on a short bending stroke, its "band" set to the stroke's last gaps (one branch
of equilibria there): the companion (the far zone coarsened, its own force 3-9 % off the case's)
lands on the case's gaps; each of its states moved to the case's mesh and solved there lands on
the case's own equilibrium (a second path to it: the force and the energy to 1e-4, the stick
anchors set along the two paths apart; ``BAND_ENERGY_RTOL`` is 1e-3), so no row is replaced.
A row given a higher energy than its state's is replaced by the moved state, which restores
the run's own force.  Input errors are clear.
"""

from __future__ import annotations

import json
from dataclasses import replace

import pandas as pd
import pytest

from grasprom.fe.bandselect import (
    BAND_ENERGY_RTOL,
    band_gaps,
    companion_spec,
    companion_states,
    run_case_3d_selected,
    select_lower,
)
from grasprom.fe.mesh3d import MeshSpec3D
from grasprom.fe.model2d import CaseResult, CaseSpec, SolverSettings, run_case
from grasprom.fe.model3d import CaseSpec3D, run_case_3d

SPEC = CaseSpec3D(
    "mr",
    1.4,
    tube_length_mm=60.0,
    closed_gap_mm=20.0,
    mesh=MeshSpec3D(n_layers=2, n_circ=8, n_jaw=3, n_free=3, grading=2.0),
)
#: the gaps (mm) standing in for the crease band (bending: one branch)
BAND = (20.0, 26.0)


def _with_companion(spec, k):
    return replace(spec, solver=replace(spec.solver, band_companion=k))


@pytest.fixture(scope="module")
def selected():
    return run_case_3d_selected(_with_companion(SPEC, 2), band=BAND)


def test_on_one_branch_every_moved_state_is_the_cases_own(selected):
    plain = run_case_3d_selected(SPEC)  # no companion: the plain run
    assert "band_selection" not in plain.info
    pd.testing.assert_frame_equal(selected.table, plain.table)  # nothing replaced
    sel = selected.info["band_selection"]
    gaps = band_gaps(plain.table, SPEC.thickness_mm, BAND)
    assert len(gaps) >= 4 and [c["gap_mm"] for c in sel["choices"]] == gaps
    for c in sel["choices"]:
        assert not c["taken"] and c["error"] == ""
        assert c["moved_force_N"] == pytest.approx(c["own_force_N"], rel=1e-4)
        assert abs(c["moved_energy_mJ"] / c["own_energy_mJ"] - 1.0) < 1e-4  # the anchors: 2.7e-5
        assert abs(c["companion_force_N"] / c["own_force_N"] - 1.0) > 0.03  # can fail
    assert sel["status"] == "complete" and sel["taken_gaps_mm"] == []
    assert sel["energy_rtol"] == BAND_ENERGY_RTOL
    assert sel["far_coarsening"] == 2 and sel["newton_iterations"] > 0
    info = selected.info
    assert info["wall_time_s"] == pytest.approx(info["own_wall_time_s"] + sel["wall_time_s"])
    json.dumps(sel, allow_nan=False)


def test_a_row_of_higher_energy_is_replaced_by_the_moved_state(selected):
    gaps = band_gaps(selected.table, SPEC.thickness_mm, BAND)
    comp = companion_spec(SPEC, gaps, 2)
    assert comp.mesh.far_coarsening == 2 and comp.closed_gap_mm == min(gaps)
    assert comp.solver.band_companion == 0 and set(gaps) <= set(comp.solver.land_on_gaps_mm)
    _, states = companion_states(comp, gaps)
    assert sorted(states) == sorted(gaps)
    table = selected.table.copy()
    k = table.index[table["gap_mm"] == gaps[2]][0]
    table.loc[k, "force_N"] *= 1.5
    table.loc[k, "strain_energy_mJ"] *= 1.01
    out, choices = select_lower(SPEC, CaseResult(table, "complete", {}), comp, states)
    assert [c.taken for c in choices] == [g == gaps[2] for g in gaps]
    true_force = selected.table.loc[k, "force_N"]
    assert out.table.loc[k, "force_N"] == pytest.approx(true_force, rel=1e-4)
    rest = out.table.index != k
    pd.testing.assert_frame_equal(out.table[rest], selected.table[rest])


def test_a_stroke_without_band_gaps_records_so():
    r = run_case_3d_selected(_with_companion(SPEC, 2), band=(1.0, 2.0))
    assert r.info["band_selection"]["status"] == "no band gaps"
    assert r.info["band_selection"]["choices"] == []


@pytest.mark.parametrize("k", [-1, True, 1.5])
def test_band_companion_must_be_a_coarsening_or_zero(k):
    with pytest.raises(ValueError, match="band_companion must be an integer >= 0"):
        SolverSettings(band_companion=k)


def test_the_plain_runs_refuse_a_companion():
    with pytest.raises(ValueError, match="run_case_3d_selected"):
        run_case_3d(_with_companion(SPEC, 2))
    spec2d = CaseSpec("mr", 1.4, solver=SolverSettings(band_companion=2))
    with pytest.raises(ValueError, match="3D only"):
        run_case(spec2d)


def test_companion_spec_checks_its_inputs():
    with pytest.raises(ValueError, match="no band gaps"):
        companion_spec(SPEC, [], 2)
    with pytest.raises(ValueError, match="far_coarsening=3 must divide"):
        companion_spec(SPEC, [21.0], 3)
