"""Moving a 3D state to another mesh (grasprom.fe.transfer3d) and solving from it
(grasprom.fe.model3d.equilibrium_from).

References: polynomial fields the Q2 element on trilinear hexahedra holds exactly (analytic),
and each mesh's own forward run (the restart from the other mesh's state must land on the same
frictionless equilibrium: a second path to it)."""

from dataclasses import replace

import numpy as np
import pytest

from grasprom.fe.mesh3d import MeshSpec3D
from grasprom.fe.model2d import SolverSettings
from grasprom.fe.model3d import (
    CaseSpec3D,
    EquilibriumSolver,
    build_disc,
    equilibrium_from,
    run_case_3d,
)
from grasprom.fe.transfer3d import FieldProbe, transfer_displacement

A = CaseSpec3D(
    "mr",
    1.4,
    tube_length_mm=60.0,
    mesh=MeshSpec3D(n_layers=2, n_circ=12, n_jaw=4, n_free=4, grading=4.0),
)
#: another cross-section, layer count and axial grid; and A with its far zone coarsened
B = replace(A, mesh=MeshSpec3D(n_layers=3, n_circ=16, n_jaw=6, n_free=5, grading=6.0))
Z = replace(A, mesh=replace(A.mesh, far_coarsening=2))


def _linear(X):
    return np.column_stack([1 + 2 * X[:, 0] - X[:, 2], 3 * X[:, 1] + 0.5 * X[:, 0], 0.1 * X[:, 2]])


def _quadratic(X):
    """Products of two coordinates: in the Q2 space of every trilinear element."""
    x, y, z = X.T
    return np.column_stack([x * y, 0.01 * z * z, x * x - y * z])


@pytest.mark.parametrize(("src", "dst"), [(A, B), (B, A), (Z, B), (B, Z), (A, A)])
@pytest.mark.parametrize("field", [_linear, _quadratic])
def test_polynomial_fields_move_between_meshes_exactly(src, dst, field):
    """Fields the Q2 element holds exactly on trilinear hexahedra arrive exactly (to 1e-10 mm),
    across cross-sections, layer counts, axial grids and a coarsened far zone (tied nodes)."""
    u = transfer_displacement(src, field(build_disc(src).X).ravel(), dst)
    expected = field(build_disc(dst).X).ravel()
    assert np.abs(u - expected).max() < 1e-10


def test_transfer_rejects_another_tube_and_a_wrong_length():
    u = np.zeros(build_disc(A).ndof)
    with pytest.raises(ValueError, match="thickness_mm"):
        transfer_displacement(A, u, replace(B, thickness_mm=1.2))
    with pytest.raises(ValueError, match="u_from has"):
        transfer_displacement(A, u[:-3], B)


def test_a_point_far_outside_the_tube_is_an_error():
    probe = FieldProbe(A)
    assert probe.matrix(np.array([[0.0, 14.3, 1.0]])).shape == (1, probe.n_nodes)
    with pytest.raises(ValueError, match="outside the tube"):
        probe.matrix(np.array([[0.0, 17.0, 1.0]]))


#: a coarse bending stroke landing on two gaps (mm)
GAPS = (20.0, 14.0)


def _landing(spec):
    """``spec`` stroked to the last of :data:`GAPS`, landing on each."""
    spec = replace(spec, closed_gap_mm=GAPS[-1])
    return replace(spec, solver=replace(spec.solver, land_on_gaps_mm=list(GAPS)))


def _states(spec):
    """Each landing gap's force (N) and displacements (mm) of the forward run of ``spec``
    (``on_row``, whose last state at each gap is the table's row there)."""
    spec = _landing(spec)
    out = {}

    def on_row(disc, u, gap, force):
        out[round(gap, 9)] = (force, u.copy())

    r = run_case_3d(spec, on_row=on_row)
    assert [out[round(g, 9)][0] for g in r.table["gap_mm"][1:]] == list(r.table["force_N"][1:])
    return spec, {g: out[g] for g in GAPS}


COARSE_A = replace(A, mesh=MeshSpec3D(n_layers=1, n_circ=8, n_jaw=3, n_free=3, grading=2.0))
#: another layer count, cross-section and axial grid, in the jaw zone too (n_jaw 2 against 3:
#: the moves interpolate along the tube where the contact is); its forward run takes 5 s (with
#: n_jaw 4 it took 38 s: 24 steps against 17)
COARSE_B = replace(A, mesh=MeshSpec3D(n_layers=2, n_circ=10, n_jaw=2, n_free=4, grading=3.0))


@pytest.mark.parametrize("contact", ["frictionless", "stick"])
def test_a_restart_on_the_same_mesh_is_the_state_itself(contact):
    """The forward run's state, restarted at its gap, is already in equilibrium (no Newton
    iteration, the same force): the contact set and the stick anchors read off it are the run's."""
    spec, states = _states(replace(COARSE_A, contact=contact))
    for gap, (force, u) in states.items():
        eq = equilibrium_from(spec, u, gap)
        assert eq.newton_iterations == 0
        assert eq.force_N == pytest.approx(force, rel=1e-9)
        assert eq.gap_mm == gap
        assert eq.row["force_N"] == eq.force_N


def test_another_meshs_frictionless_state_lands_on_this_meshs_equilibrium():
    """Frictionless contact has no history: moved from mesh A to B and solved there, A's state
    lands on B's own forward-run equilibrium (force to 1e-7), and B's on A's; the two meshes'
    forces differ by more than that (the check can fail)."""
    sa, a = _states(replace(COARSE_A, contact="frictionless"))
    sb, b = _states(replace(COARSE_B, contact="frictionless"))
    for gap in GAPS:
        on_b = equilibrium_from(sb, transfer_displacement(sa, a[gap][1], sb), gap)
        on_a = equilibrium_from(sa, transfer_displacement(sb, b[gap][1], sa), gap)
        assert on_b.force_N == pytest.approx(b[gap][0], rel=1e-7)
        assert on_a.force_N == pytest.approx(a[gap][0], rel=1e-7)
        assert abs(a[gap][0] / b[gap][0] - 1.0) > 1e-4


def test_one_solver_for_many_moves_equals_a_fresh_set_up_each():
    """An :class:`EquilibriumSolver` kept over several moves (one set-up) gives each state as a
    fresh :func:`equilibrium_from` does, to the bit (each solve its own sparse solver). That
    a fresh one lands on the target mesh's own forward run (the reference) is the test above,
    on the same moves; B's forward run (most of that test's time) is not repeated here."""
    sa, a = _states(replace(COARSE_A, contact="frictionless"))
    sb = _landing(replace(COARSE_B, contact="frictionless"))
    kept = EquilibriumSolver(sb)
    assert kept.ndof == build_disc(sb).ndof
    for gap in GAPS:
        u0 = transfer_displacement(sa, a[gap][1], sb)
        reused, fresh = kept.solve(u0, gap), equilibrium_from(sb, u0, gap)
        assert reused.force_N == fresh.force_N
        assert reused.strain_energy_mJ == fresh.strain_energy_mJ
        assert np.array_equal(reused.u, fresh.u)
        assert reused.newton_iterations == fresh.newton_iterations > 0
    with pytest.raises(ValueError, match="gap_mm"):
        kept.solve(u0, 0.0)


def test_equilibrium_from_checks_its_inputs():
    n = build_disc(COARSE_A).ndof
    with pytest.raises(ValueError, match="u0 has"):
        equilibrium_from(COARSE_A, np.zeros(n + 3), 20.0)
    with pytest.raises(ValueError, match="gap_mm"):
        equilibrium_from(COARSE_A, np.zeros(n), -1.0)
    folded = np.zeros((n // 3, 3))
    folded[build_disc(COARSE_A).X[:, 1] < 7.5, 1] = 40.0  # the lower half up through the upper
    folded = folded.ravel()
    with pytest.raises(RuntimeError, match="inverts an element"):
        equilibrium_from(COARSE_A, folded, 20.0)


def test_solver_settings_do_not_matter_to_the_transfer():
    """The probe depends on the mesh only (solver settings differ, same matrix)."""
    other = replace(A, solver=SolverSettings(dh_initial_mm=0.05))
    pts = build_disc(B).X[::7]
    assert abs(FieldProbe(A).matrix(pts) - FieldProbe(other).matrix(pts)).max() == 0.0
