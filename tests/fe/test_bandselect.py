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

from grasprom.fe import datafiles as df
from grasprom.fe.bandselect import (
    BAND_ENERGY_RTOL,
    BAND_MOVE_FORCE_RTOL,
    NOT_LANDED,
    BandChoice,
    band_gaps,
    check_companion,
    companion_spec,
    companion_states,
    run_case_3d_selected,
    select_band,
    select_lower,
)
from grasprom.fe.grid import SweepInputError
from grasprom.fe.mesh3d import MeshSpec3D
from grasprom.fe.model2d import CaseResult, CaseSpec, SolverSettings, run_case
from grasprom.fe.model3d import CaseSpec3D, run_case_3d
from grasprom.fe.reselect import StoredOwnRuns, check_own_runs, read_own_run
from grasprom.fe.sweep import PRIOR_WALL_TIME_KEY, split_prior_time

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
    assert info["solver"]["band_companion"] == 2  # the spec's, not the own run's 0
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
    assert out.info["max_force_N"] == out.table["force_N"].max()
    rest = out.table.index != k
    pd.testing.assert_frame_equal(out.table[rest], selected.table[rest])
    # a gap without a companion state, and one whose state inverts an element here: both
    # recorded (NaN -> None in the record), neither taken, the table unchanged
    states = dict(states)
    del states[gaps[0]]
    force, u = states[gaps[1]]
    states[gaps[1]] = (force, 1e3 * u)
    out, choices = select_lower(SPEC, selected, comp, states, gaps=gaps)
    assert choices[0].error == NOT_LANDED and "element" in choices[1].error
    assert not any(c.taken for c in choices)
    pd.testing.assert_frame_equal(out.table, selected.table)
    json.dumps([c.record() for c in choices], allow_nan=False)
    assert choices[0].record()["moved_force_N"] is None


def test_a_companion_state_as_strong_as_the_cases_is_not_moved(selected):
    """Where the companion's force is within ``move_rtol`` of the case's the state is not moved
    (recorded as skipped, no Newton iteration, the row kept); the test's companion is 3-9 %
    off, so at the default (0.5 %) every state moves, at 10 % none."""
    gaps = band_gaps(selected.table, SPEC.thickness_mm, BAND)
    comp = companion_spec(SPEC, gaps, 2)
    _, states = companion_states(comp, gaps)
    off = [abs(states[g][0] / c["own_force_N"] - 1.0) for g, c in
           zip(gaps, selected.info["band_selection"]["choices"])]  # fmt: skip
    assert min(off) > BAND_MOVE_FORCE_RTOL and max(off) < 0.1
    assert not any(c["skipped"] for c in selected.info["band_selection"]["choices"])
    assert selected.info["band_selection"]["move_force_rtol"] == BAND_MOVE_FORCE_RTOL
    out, choices = select_lower(SPEC, selected, comp, states, move_rtol=0.1)
    assert all(c.skipped and c.newton_iterations == 0 and not c.taken for c in choices)
    assert [c.companion_force_N for c in choices] == [states[g][0] for g in gaps]
    pd.testing.assert_frame_equal(out.table, selected.table)
    json.dumps([c.record() for c in choices], allow_nan=False)
    # between the smallest and the largest offset: those within are kept, the others moved
    # as before (to the bit: each solve is independent of the ones before it)
    rtol = 0.5 * (min(off) + max(off))
    _, mixed = select_lower(SPEC, selected, comp, states, move_rtol=rtol)
    assert [c.skipped for c in mixed] == [x <= rtol for x in off]
    assert 0 < sum(c.skipped for c in mixed) < len(mixed)
    for c, ref in zip(mixed, selected.info["band_selection"]["choices"]):
        if not c.skipped:
            assert c.moved_force_N == ref["moved_force_N"]
            assert c.newton_iterations == ref["newton_iterations"] > 0
    with pytest.raises(ValueError, match="move_rtol"):
        select_lower(SPEC, selected, comp, states, move_rtol=-0.1)


def test_the_selection_of_a_stored_run_is_the_selected_runs(selected, tmp_path):
    """A case of a sweep without the companion, read back from its files
    (:class:`StoredOwnRuns`), gets the rows, choices and spec record the run with the companion
    has (parity of the two paths; the own run round-trips its CSV exactly); its wall time adds
    the own run's, whose provenance is kept."""
    plain = run_case_3d(SPEC)
    df.write_case(tmp_path, SPEC, plain)
    spec2 = _with_companion(SPEC, 2)
    check_own_runs([spec2], tmp_path)
    out = StoredOwnRuns(str(tmp_path), band=BAND)(spec2)
    pd.testing.assert_frame_equal(out.table, selected.table, check_exact=True)
    mine, theirs = out.info["band_selection"], selected.info["band_selection"]
    for key in ("choices", "taken_gaps_mm", "crease_gaps_mm", "newton_iterations", "status"):
        assert mine[key] == theirs[key]
    meta = df.read_case(tmp_path / "mr_t1.40.json").meta
    assert out.info[PRIOR_WALL_TIME_KEY] == meta["wall_time_s"]
    assert out.info["own_wall_time_s"] == meta["fe_info"]["wall_time_s"]
    assert out.info["own_run"]["source"] == str(tmp_path)
    assert out.info["own_run"]["git_revision"] == meta["git_revision"]
    assert out.info["wall_time_s"] > out.info["own_wall_time_s"]
    with pytest.raises(ValueError, match="band_companion is 0"):
        select_band(SPEC, plain)


def test_a_stored_row_of_higher_energy_is_replaced_as_in_a_run(selected, tmp_path):
    """A stored own run whose row holds 1 % too much energy gets the moved state there, as
    :func:`select_lower` gives it on the same table (to the bit), the rest kept."""
    gaps = band_gaps(selected.table, SPEC.thickness_mm, BAND)
    table = selected.table.copy()
    k = table.index[table["gap_mm"] == gaps[1]][0]
    table.loc[k, "strain_energy_mJ"] *= 1.01
    df.write_case(tmp_path, SPEC, CaseResult(table, "complete", {"wall_time_s": 1.0}))
    out = StoredOwnRuns(str(tmp_path), band=BAND)(_with_companion(SPEC, 2))
    assert out.info["band_selection"]["taken_gaps_mm"] == [gaps[1]]
    comp = companion_spec(SPEC, gaps, 2)
    _, states = companion_states(comp, gaps)
    ref, _ = select_lower(SPEC, CaseResult(table, "complete", {}), comp, states, gaps=gaps)
    pd.testing.assert_frame_equal(out.table, ref.table, check_exact=True)
    assert out.table.loc[k, "force_N"] == pytest.approx(selected.table.loc[k, "force_N"], 1e-4)


def test_a_stored_run_of_other_inputs_is_refused(selected, tmp_path):
    df.write_case(tmp_path, SPEC, CaseResult(selected.table, "complete", {}))
    other = replace(_with_companion(SPEC, 2), tube_length_mm=80.0)
    with pytest.raises(SweepInputError, match="tube_length_mm"):
        read_own_run(other, tmp_path)
    with pytest.raises(SweepInputError, match="no case mr_t1.20.json"):
        read_own_run(replace(other, thickness_mm=1.2), tmp_path)
    with pytest.raises(SweepInputError, match="--band-companion K >= 1"):
        check_own_runs([SPEC], tmp_path)


@pytest.mark.parametrize("bad", [-1.0, float("nan"), "soon", None])
def test_a_prior_wall_time_is_split_off_and_checked(bad):
    res = CaseResult(pd.DataFrame(), "complete", {PRIOR_WALL_TIME_KEY: 12.5, "x": 1})
    out, prior = split_prior_time(res)
    assert prior == 12.5 and out.info == {"x": 1}
    assert split_prior_time(CaseResult(pd.DataFrame(), "complete", {}))[1] == 0.0
    with pytest.raises(ValueError, match=PRIOR_WALL_TIME_KEY):
        split_prior_time(CaseResult(pd.DataFrame(), "complete", {PRIOR_WALL_TIME_KEY: bad}))


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


def test_the_companion_ends_in_the_band_without_unloading():
    spec = replace(SPEC, closed_gap_mm=10.0)
    spec = replace(spec, solver=replace(spec.solver, unload_from_N=5.0, land_on_gaps_mm=(25.0,)))
    comp = companion_spec(spec, [22.0, 21.0], 2)
    assert comp.closed_gap_mm == 21.0 and comp.solver.unload_from_N == 0.0
    assert comp.solver.land_on_gaps_mm == (25.0, 22.0, 21.0)
    assert companion_spec(replace(SPEC, closed_gap_mm=21.5), [22.0, 21.0], 2).closed_gap_mm == 21.5


def test_a_companion_that_cannot_help_is_refused_before_the_run():
    zoned = replace(SPEC, mesh=replace(SPEC.mesh, far_coarsening=2))
    with pytest.raises(ValueError, match="must be another mesh"):
        run_case_3d_selected(_with_companion(zoned, 2))
    coulomb = replace(SPEC, contact="coulomb", friction=0.2)
    with pytest.raises(ValueError, match="not with Coulomb contact"):
        run_case_3d_selected(_with_companion(coulomb, 2))
    check_companion(zoned, 1)  # the zoned case's companion on one cross-section is fine
    short = replace(SPEC, tube_length_mm=SPEC.jaw_length_mm + 2 * SPEC.mesh.fine_margin_mm)
    with pytest.raises(ValueError, match="no far zone"):  # before the run, not after it
        check_companion(short, 2)
    check_companion(replace(short, tube_length_mm=short.tube_length_mm + 1.0), 2)


def test_a_choice_records_json_ready():
    c = BandChoice(3.0, 1.0, 2.0, 1.1, float("nan"), float("nan"), 0, False, "no equilibrium")
    assert json.loads(json.dumps(c.record(), allow_nan=False))["moved_energy_mJ"] is None
