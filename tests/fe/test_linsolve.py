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
