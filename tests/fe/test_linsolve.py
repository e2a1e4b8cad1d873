"""The sparse symmetric solve of the FE tangents against a dense LAPACK solve."""

import numpy as np
import pytest
import scipy.sparse as sp

from grasprom.fe.linsolve import solve_symmetric


def _laplacian_2d(n: int) -> sp.csr_matrix:
    """5-point Laplacian on an n x n grid (SPD, FE-like sparsity)."""
    t = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    return sp.csr_matrix(sp.kron(sp.identity(n), t) + sp.kron(t, sp.identity(n)))


@pytest.mark.parametrize("shift", [0.0, -1.5])
def test_solve_symmetric_matches_dense_solve(shift):
    """SPD (shift 0) and symmetric indefinite (shift -1.5: eigenvalues on both sides of 0, as a
    tangent past a buckling point) systems agree with ``numpy.linalg.solve`` to 1e-10."""
    K = _laplacian_2d(15) + shift * sp.identity(225)
    rhs = np.random.default_rng(1).standard_normal(225)
    eig = np.linalg.eigvalsh(K.toarray())
    assert (eig.min() < 0 < eig.max()) == (shift != 0.0)
    x = solve_symmetric(K, rhs)
    ref = np.linalg.solve(K.toarray(), rhs)
    assert np.abs(x - ref).max() <= 1e-10 * np.abs(ref).max()


def test_singular_system_raises():
    """An exactly singular factor raises RuntimeError (the Newton solver then shifts)."""
    K = sp.csr_matrix(np.diag([1.0, 2.0, 0.0]))
    with pytest.raises(RuntimeError):
        solve_symmetric(K, np.ones(3))


def _pardiso(**kw):
    """PARDISO's wrapper; its package is a dev dependency, so CI never skips these tests."""
    import os

    from grasprom.fe.linsolve import PardisoLDLT, pardiso_available

    if not pardiso_available():
        if os.environ.get("CI") == "true":
            pytest.fail("pypardiso (MKL) is missing: pip install -e '.[dev]'")
        pytest.skip("pypardiso not installed")
    return PardisoLDLT(**kw)


@pytest.mark.parametrize("matching", [True, False])
@pytest.mark.parametrize("shift", [0.0, -1.5])
def test_pardiso_ldlt_matches_dense_solve(shift, matching):
    """MKL PARDISO's symmetric indefinite factor on the same SPD and indefinite systems agrees
    with LAPACK to 1e-10 (a second, independent direct solver), with scaling and matching (the
    default) and without them."""
    solve = _pardiso(matching=matching)
    K = _laplacian_2d(15) + shift * sp.identity(225)
    rhs = np.random.default_rng(2).standard_normal(225)
    ref = np.linalg.solve(K.toarray(), rhs)
    x = solve(K, rhs)
    assert np.abs(x - ref).max() <= 1e-10 * np.abs(ref).max()


def test_pardiso_reuses_its_analysis_until_the_pattern_changes():
    """New values on the same pattern reuse the symbolic analysis; a new pattern (an extra
    off-diagonal pair) is analysed afresh; each answer equals LAPACK's."""
    solve = _pardiso()
    rng = np.random.default_rng(3)
    K = _laplacian_2d(10)
    rhs = rng.standard_normal(100)
    for scale in (1.0, 2.0, 0.5):
        x = solve(scale * K, rhs)
        assert np.allclose(x, np.linalg.solve(scale * K.toarray(), rhs), rtol=0, atol=1e-10)
    assert solve.analyses == 1
    K2 = K.tolil()
    K2[0, 57] = K2[57, 0] = -0.3
    K2 = sp.csr_matrix(K2)
    x = solve(K2, rhs)
    assert np.allclose(x, np.linalg.solve(K2.toarray(), rhs), rtol=0, atol=1e-10)
    assert solve.analyses == 2


@pytest.mark.parametrize("name", ["superlu", "pardiso"])
def test_resolve_solves_with_the_last_factor(name):
    """``solver.resolve(rhs)`` solves with the matrix of the last call, not a new one, and
    agrees with LAPACK for that matrix to 1e-10 (SPD and indefinite); it counts no
    factorisation; before any call it raises."""
    from grasprom.fe.linsolve import SuperLUSolver

    solve = SuperLUSolver() if name == "superlu" else _pardiso()
    rng = np.random.default_rng(7)
    with pytest.raises(RuntimeError, match="nothing factored"):
        solve.resolve(np.ones(225))
    for shift in (0.0, -1.5):
        K = _laplacian_2d(15) + shift * sp.identity(225, format="csr")
        solve(K, rng.standard_normal(225))
        n = solve.factorizations
        rhs = rng.standard_normal(225)
        x = solve.resolve(rhs)
        ref = np.linalg.solve(K.toarray(), rhs)
        assert np.abs(x - ref).max() <= 1e-10 * np.abs(ref).max()
        assert solve.factorizations == n
    assert solve.factorizations == 2


def test_make_solver_names():
    from grasprom.fe.linsolve import (
        PardisoLDLT,
        SuperLUSolver,
        make_solver,
        pardiso_available,
        solver_name,
    )

    assert isinstance(make_solver("superlu"), SuperLUSolver)
    assert solver_name(make_solver("superlu")).startswith("scipy SuperLU")
    assert isinstance(make_solver("auto"), PardisoLDLT) == pardiso_available()
    with pytest.raises(ValueError, match="superlu"):
        make_solver("umfpack")


def test_3d_case_is_the_same_with_either_solver():
    """A coarse 3D stick case to gap 26 mm: PARDISO and SuperLU give the same forces to 1e-8
    (round-off only), step for step."""
    from dataclasses import replace

    from grasprom.fe.mesh3d import MeshSpec3D
    from grasprom.fe.model3d import CaseSpec3D, run_case_3d

    _pardiso()
    spec = CaseSpec3D(
        "mr",
        1.4,
        tube_length_mm=30.0,
        closed_gap_mm=26.0,
        mesh=MeshSpec3D(n_layers=1, n_circ=8, n_jaw=3, n_free=3),
    )
    spec = replace(spec, solver=replace(spec.solver, land_on_gaps_mm=(28.0, 26.0)))
    a = run_case_3d(spec, solver="superlu")
    b = run_case_3d(spec, solver="pardiso")
    assert len(a.table) == len(b.table)
    assert np.allclose(b.table["force_N"], a.table["force_N"], rtol=1e-8, atol=1e-12)
    assert b.info["linear_solver"].startswith("MKL PARDISO")
    assert a.info["linear_solver"].startswith("scipy SuperLU")


def test_2d_case_is_the_same_with_either_solver():
    """The 2D model (stick, t = 1.4 mm) through bending and the walls meeting to gap 2.6 mm:
    PARDISO and SuperLU give the same forces to 1e-7 (round-off only), step for step."""
    from grasprom.fe.model2d import CaseSpec, MeshSpec, SolverSettings, run_case

    _pardiso()
    spec = CaseSpec(
        "mr",
        1.4,
        closed_gap_mm=2.6,
        mesh=MeshSpec(n_layers=2, n_circ=24),
        solver=SolverSettings(land_on_gaps_mm=(10.0, 2.7)),
    )
    a = run_case(spec, solver="superlu")
    b = run_case(spec, solver="pardiso")
    assert len(a.table) == len(b.table)
    assert np.allclose(b.table["gap_mm"], a.table["gap_mm"], rtol=0, atol=1e-9)
    assert np.allclose(b.table["force_N"], a.table["force_N"], rtol=1e-7, atol=1e-12)
    assert b.info["linear_solver"].startswith("MKL PARDISO")
    assert a.info["linear_solver"].startswith("scipy SuperLU")


def test_descent_direction_newton_step_then_levenberg_shift():
    """``-K^-1 r`` when it descends; on a negative definite ``K = -I`` the shifts 1e-3, 1e-2,
    0.1, 1 do not descend and 10 does: ``du = -r / 9``; a curvature of -1e6 among 99 ones is
    beyond the largest shift (10 x the mean diagonal, 1e5) along its own direction (None)."""
    from grasprom.fe.linsolve import descent_direction, solve_symmetric

    rng = np.random.default_rng(4)
    B = rng.standard_normal((6, 6))
    K = sp.csr_matrix(B @ B.T + 6 * np.eye(6))
    r = rng.standard_normal(6)
    du = descent_direction(solve_symmetric, K, r)
    np.testing.assert_allclose(du, -np.linalg.solve(K.toarray(), r), rtol=1e-12)
    du = descent_direction(solve_symmetric, -sp.identity(6, format="csr"), r)
    np.testing.assert_allclose(du, -r / 9.0, rtol=1e-12)
    d = np.ones(100)
    d[0] = -1e6
    e0 = np.zeros(100)
    e0[0] = 1.0
    assert descent_direction(solve_symmetric, sp.diags(d, format="csr"), e0) is None


def test_shifted_descent_reports_the_shift_it_took():
    """``shifted_descent`` returns the direction with its shift: 0.0 for the plain Newton step,
    10 (10 x the mean diagonal 1) for ``K = -I`` (as above), and the shift, not a failed
    factorisation, decides: a solver that raises on the plain ``K`` (singular) gives the
    first shift, 1e-3 x the mean diagonal, with ``(K + 1e-3 I)^-1``'s direction."""
    from grasprom.fe.linsolve import shifted_descent, solve_symmetric

    rng = np.random.default_rng(5)
    B = rng.standard_normal((6, 6))
    K = sp.csr_matrix(B @ B.T + 6 * np.eye(6))
    r = rng.standard_normal(6)
    du, shift = shifted_descent(solve_symmetric, K, r)
    assert shift == 0.0 and np.allclose(du, -np.linalg.solve(K.toarray(), r), rtol=1e-12)
    du, shift = shifted_descent(solve_symmetric, -sp.identity(6, format="csr"), r)
    assert shift == pytest.approx(10.0) and np.allclose(du, -r / 9.0, rtol=1e-12)
    calls = []

    def singular_first(A, b):
        calls.append(1)
        if len(calls) == 1:
            raise RuntimeError("factor is exactly singular")
        return solve_symmetric(A, b)

    du, shift = shifted_descent(singular_first, K, r)
    m = float(np.abs(K.diagonal()).mean())
    assert shift == pytest.approx(1e-3 * m)
    ref = -np.linalg.solve(K.toarray() + 1e-3 * m * np.eye(6), r)
    np.testing.assert_allclose(du, ref, rtol=1e-10)


def test_a_levenberg_shift_keeps_the_pardiso_analysis():
    """A constrained tangent stores zeros in its fixed rows and columns; the shifted matrix
    ``K + s I`` keeps them, so PARDISO reuses its analysis through the shifts and back (one
    analysis; ``K + s * identity`` dropped the zeros and cost two per shift), and the direction
    equals LAPACK's ``-(K + s I)^-1 r`` for the first shift of the rule that descends (``K``
    negative definite on the free dofs, so the plain Newton step does not)."""
    from grasprom.fe.linsolve import descent_direction

    solve = _pardiso()
    n = 100
    fixed = np.zeros(n, dtype=bool)
    fixed[[0, 17, 55]] = True
    Kd = -_laplacian_2d(10).toarray()
    Kd[fixed, :] = 0.0
    Kd[:, fixed] = 0.0
    Kd[fixed, fixed] = 1.0
    K = sp.csr_matrix(_laplacian_2d(10), copy=True)
    K.data[:] = Kd[K.nonzero()]  # the Laplacian's pattern, zeros stored
    assert np.count_nonzero(K.data == 0.0) > 0
    r = np.where(fixed, 0.0, np.random.default_rng(6).standard_normal(n))
    du = descent_direction(solve, K, r)
    m = np.abs(np.diag(Kd)).mean()
    for s in (0.0, 1e-3 * m, 1e-2 * m, 0.1 * m, m, 10.0 * m):
        ref = -np.linalg.solve(Kd + s * np.eye(n), r)
        if r @ ref < 0:
            break
    assert s > 0.0
    np.testing.assert_allclose(du, ref, rtol=0, atol=1e-10 * np.abs(ref).max())
    solve(K, r)
    assert solve.analyses == 1


@pytest.mark.parametrize("name", ["superlu", "pardiso"])
def test_factor_reuse_solves_a_nearby_matrix_with_the_older_factor(name):
    """:class:`FactorReuse`: a matrix 5 % off the factored one is solved without a new
    factorisation to its ``rtol`` against LAPACK for *that* matrix (not the factored one), and
    so is ``resolve``; a matrix far off (indefinite) is factored afresh and solved to round-off."""
    from grasprom.fe.linsolve import FactorReuse, SuperLUSolver

    inner = SuperLUSolver() if name == "superlu" else _pardiso()
    solve = FactorReuse(inner, rtol=1e-9, max_iterations=10)
    rng = np.random.default_rng(11)
    n = 225
    K0 = _laplacian_2d(15)
    solve(K0, rng.standard_normal(n))
    assert (solve.factorizations, solve.reuses) == (1, 0)
    K1 = sp.csr_matrix(K0 + sp.diags(0.05 * rng.random(n) * K0.diagonal()))
    for call in (solve, lambda _, b: solve.resolve(b)):
        rhs = rng.standard_normal(n)
        x = call(K1, rhs)
        ref = np.linalg.solve(K1.toarray(), rhs)
        assert np.linalg.norm(K1 @ x - rhs) <= 1e-9 * np.linalg.norm(rhs)
        assert np.abs(x - ref).max() <= 1e-7 * np.abs(ref).max()
        assert np.abs(x - np.linalg.solve(K0.toarray(), rhs)).max() > 1e-3 * np.abs(ref).max()
    assert (solve.factorizations, solve.reuses) == (1, 1)
    assert 0 < solve.krylov_iterations <= 2 * 10
    K2 = sp.csr_matrix(K0 - 3.5 * sp.identity(n))  # indefinite: the old factor is no help
    rhs = rng.standard_normal(n)
    x = solve(K2, rhs)
    assert np.allclose(x, np.linalg.solve(K2.toarray(), rhs), rtol=0, atol=1e-10)
    assert (solve.factorizations, solve.reuses) == (2, 1)
    np.testing.assert_allclose(solve.resolve(rhs), x, rtol=0, atol=1e-12)  # its own factor


def test_factor_reuse_checks_its_settings_and_needs_a_solve_to_resolve():
    from grasprom.fe.linsolve import FactorReuse, SuperLUSolver, solver_name

    for kw in ({"rtol": 0.0}, {"rtol": 1.0}, {"max_iterations": 0}, {"give_up_after": 11}):
        with pytest.raises(ValueError, match="FactorReuse needs"):
            FactorReuse(SuperLUSolver(), **kw)
    solve = FactorReuse(SuperLUSolver())
    assert solver_name(solve).startswith("scipy SuperLU") and "GMRES" in solver_name(solve)
    with pytest.raises(RuntimeError, match="nothing solved"):
        solve.resolve(np.ones(4))
