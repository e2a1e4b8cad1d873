"""Sparse direct solves of the symmetric tangent systems of the FE models.

Two back ends, both direct (and :class:`FactorReuse`, which tries an older factor as the
preconditioner of GMRES before it factors):

- :func:`solve_symmetric` / :class:`SuperLUSolver`: scipy's SuperLU in symmetric mode (always
  available);
- :class:`PardisoLDLT`: Intel MKL PARDISO's symmetric indefinite ``L D L^T`` (matrix type -2)
  on the upper triangle, with the fill-reducing analysis (METIS) kept while the sparsity pattern
  does not change (needs the optional ``pypardiso``, which brings MKL: ``pip install
  'grasprom[fast]'``).

:func:`make_solver` picks one by name; ``"auto"`` is PARDISO when it is installed.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

DIAG_PIVOT_THRESHOLD = 0.01
"""SuperLU keeps the diagonal pivot unless it is below this fraction of the column's largest
entry (1 = partial pivoting by rows, which breaks the symmetric fill-reducing ordering)."""

SOLVERS = ("auto", "superlu", "pardiso")
"""Names accepted by :func:`make_solver`."""


def solve_symmetric(K: sp.spmatrix, rhs: np.ndarray) -> np.ndarray:
    """Solve ``K x = rhs`` for a structurally symmetric sparse ``K`` (SuperLU).

    The fill-reducing ordering is minimum degree on ``K^T + K`` in SuperLU's symmetric mode
    (diagonal pivots preferred, :data:`DIAG_PIVOT_THRESHOLD`), instead of ``spsolve``'s column
    ordering COLAMD with partial pivoting.  Measured on the slow mesh-convergence case of
    ``tests/fe/test_fe_model.py`` (t = 0.8 mm, mr): the default 4 x 64 mesh (3.3k dofs) 35 ->
    26.5 s, its 2x refinement (12.8k dofs) 481 -> 362 s, the forces at the landing gaps equal to
    1e-11 relative.

    Parameters
    ----------
    K : scipy.sparse matrix
        Square system matrix (any sparse format).
    rhs : ndarray
        Right-hand side.

    Returns
    -------
    ndarray
        The solution.

    Raises
    ------
    RuntimeError
        The factor is exactly singular.
    """
    return _splu(K).solve(np.asarray(rhs, dtype=float))


def _splu(K: sp.spmatrix):
    """SuperLU factor of ``K``: minimum degree on ``K^T + K``, symmetric mode."""
    return spla.splu(
        sp.csc_matrix(K),
        permc_spec="MMD_AT_PLUS_A",
        diag_pivot_thresh=DIAG_PIVOT_THRESHOLD,
        options={"SymmetricMode": True},
    )


class SuperLUSolver:
    """:func:`solve_symmetric` that keeps its last factorisation for :meth:`resolve` (the
    protocol :class:`PardisoLDLT` follows too: ``solver(K, rhs)`` factors and solves,
    ``solver.resolve(rhs)`` solves again with that factor, ``solver.factorizations`` counts)."""

    name = "scipy SuperLU (MMD_AT_PLUS_A, symmetric mode)"
    """For sidecars (:func:`solver_name`)."""

    def __init__(self) -> None:
        self._lu = None
        self.factorizations = 0
        """Numerical factorisations done (one per call)."""

    def __call__(self, K: sp.spmatrix, rhs: np.ndarray) -> np.ndarray:
        """Factor ``K`` and solve ``K x = rhs`` (as :func:`solve_symmetric`)."""
        self._lu = None
        self._lu = _splu(K)
        self.factorizations += 1
        return self._lu.solve(np.asarray(rhs, dtype=float))

    def resolve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve with the last factorisation; RuntimeError if there is none."""
        if self._lu is None:
            raise RuntimeError("SuperLU: nothing factored to solve with")
        return self._lu.solve(np.asarray(rhs, dtype=float))


def descent_direction(
    solve: Callable[[sp.spmatrix, np.ndarray], np.ndarray], K: sp.csr_matrix, r: np.ndarray
) -> np.ndarray | None:
    """Newton direction ``du = -K^-1 r``, with a Levenberg shift ``K + s I`` if it is not a
    descent direction (``r . du >= 0``, e.g. past a limit point).

    Parameters
    ----------
    solve : callable
        Linear solver ``solve(K, rhs)`` (:func:`make_solver`).
    K : scipy.sparse.csr_matrix
        Tangent (N/mm), constrained dofs replaced by identity rows/columns.
    r : ndarray
        Residual (N), zero on the constrained dofs.

    Returns
    -------
    ndarray or None
        The direction (mm); None if neither ``K`` nor five growing shifts (from 1e-3 times the
        mean absolute diagonal, x10 each) give a finite descent direction.
    """
    return shifted_descent(solve, K, r)[0]


def shifted_descent(
    solve: Callable[[sp.spmatrix, np.ndarray], np.ndarray], K: sp.csr_matrix, r: np.ndarray
) -> tuple[np.ndarray | None, float]:
    """:func:`descent_direction` and the Levenberg shift it took (N/mm; 0.0: the plain ``K``,
    then the solver's last factor is of ``K``; a factorisation that raised counts as not
    taken).

    Returns
    -------
    du : ndarray or None
        The direction (mm), None if there is none.
    shift : float
        The shift of the ``K + shift I`` that gave ``du`` (N/mm), or the last one tried.
    """
    shift = 0.0
    for _ in range(6):
        Ks = K if shift == 0.0 else shifted(K, shift)
        try:
            du = solve(Ks, -r)
        except RuntimeError:
            du = None
        if du is not None and np.all(np.isfinite(du)) and r @ du < 0:
            return du, shift
        shift = 1e-3 * abs(K.diagonal()).mean() if shift == 0.0 else shift * 10.0
    return None, shift


def shifted(K: sp.spmatrix, shift: float) -> sp.csr_matrix:
    """``K + shift I`` on ``K``'s sparsity pattern, its stored zeros included.

    ``K + shift * identity`` drops the entries that are exactly zero (the rows and columns of
    constrained dofs), so :class:`PardisoLDLT` saw a new pattern and redid its symbolic
    analysis twice per shift (for the shifted matrix and for the next plain one): about 0.8 s
    each on 29,565 dofs, against 0.3 s for a factorisation.

    Parameters
    ----------
    K : scipy.sparse matrix
        Square matrix (N/mm); its diagonal entries should be stored.
    shift : float
        Added to the diagonal (N/mm).

    Returns
    -------
    scipy.sparse.csr_matrix
        A copy; ``K`` is not changed.
    """
    Ks = sp.csr_matrix(K, copy=True)
    Ks.setdiag(Ks.diagonal() + shift)
    return Ks


def pardiso_available() -> bool:
    """Whether ``pypardiso`` (and with it MKL's PARDISO) can be loaded."""
    try:
        _mkl_pardiso()
    except (ImportError, OSError, AttributeError):
        return False
    return True


def _mkl_pardiso():
    """MKL's ``pardiso`` entry point and its thread-count setter (``mkl_set_num_threads_local``),
    located through ``pypardiso`` (which finds ``mkl_rt``)."""
    import pypardiso

    lib = ctypes.CDLL(pypardiso.PyPardisoSolver().libmkl._name)
    fn = lib.pardiso
    i32 = ctypes.POINTER(ctypes.c_int32)
    fn.argtypes = [ctypes.POINTER(ctypes.c_int64), i32, i32, i32, i32, i32, ctypes.c_void_p]
    fn.argtypes += [i32, i32, i32, i32, i32, i32, ctypes.c_void_p, ctypes.c_void_p, i32]
    fn.restype = None
    threads = lib.MKL_Set_Num_Threads_Local
    threads.argtypes = [ctypes.c_int]
    threads.restype = ctypes.c_int
    return fn, threads


class PardisoLDLT:
    """Symmetric indefinite direct solver (MKL PARDISO, matrix type -2), analysis reused.

    Each call factors ``K`` (``L D L^T`` with Bunch-Kaufman pivoting, small pivots perturbed and
    corrected by iterative refinement) and solves; the symbolic analysis (METIS nested
    dissection, the factor's structure) is redone only when ``K``'s sparsity pattern changes.
    Measured on the default 3D case's tangents (10,125 dofs, 1.56M nonzeros, one core):
    analysis 0.08 s, factorisation 0.05 s, solve 0.02 s, against 0.235 s per SuperLU solve
    (:func:`solve_symmetric`).  One instance holds MKL memory: keep it for a run, not shared
    between processes.

    PARDISO runs on one thread (``threads``): with several, its parallel reductions change the
    round-off from run to run, and a case through the crease band (a snap) can then take
    another path; one thread keeps a case reproducible to the bit.

    Symmetric scaling and weighted matching (``matching``, PARDISO's default for matrix type
    -2) are kept on.  Off, a factorisation of the 4 x 36 tangent (60 mm tube, 29,565 dofs)
    takes the same time within 5 % (definite and indefinite; ``python benchmarks/bench_fe3d.py
    assembly`` times both); only the round-off changes (that case's forces within 0.1 %; on the
    240 mm tube it took another creased state, up to 5.5 % in the crease band).

    Parameters
    ----------
    threads : int
        MKL threads for the factorisation and solve (set thread-locally around each call).
    matching : bool
        Symmetric scaling and weighted matching in the analysis (``iparm(11)``, ``iparm(13)``).

    Raises
    ------
    ImportError
        ``pypardiso``/MKL is not installed.
    """

    MTYPE = -2

    def __init__(self, threads: int = 1, matching: bool = True) -> None:
        self._pardiso, self._set_threads = _mkl_pardiso()
        self.threads = int(threads)
        self._pt = np.zeros(64, dtype=np.int64)
        self._iparm = np.zeros(64, dtype=np.int32)
        ip = self._iparm
        ip[0] = 1  # iparm supplied
        ip[1] = 2  # METIS nested dissection
        ip[9] = 8  # pivot perturbation 1e-8
        ip[10] = int(matching)  # symmetric scaling ...
        ip[12] = int(matching)  # ... and weighted matching (saddle-point systems)
        ip[34] = 1  # zero-based indices
        self._pattern: tuple[np.ndarray, np.ndarray] | None = None  # K's (indptr, indices)
        self._upper: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._analysed = False
        self.name = "MKL PARDISO (symmetric indefinite LDL^T, METIS, analysis reused" + (
            ")" if matching else ", no scaling or matching)"
        )
        """For sidecars (:func:`solver_name`; the name without the suffix had them on)."""
        self.analyses = 0
        """Symbolic analyses done (a new sparsity pattern each)."""
        self.factorizations = 0
        """Numerical factorisations done (one per call)."""
        self._factored: np.ndarray | None = None  # upper-triangle values of the last factor

    def _call(self, phase: int, a: np.ndarray, b: np.ndarray, x: np.ndarray) -> None:
        indptr, indices, _ = self._upper
        n = indptr.size - 1
        i32 = ctypes.POINTER(ctypes.c_int32)
        err = ctypes.c_int32(0)

        def ref(v: int):
            return ctypes.byref(ctypes.c_int32(v))

        self._pardiso(
            self._pt.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)),
            ref(1),
            ref(1),
            ref(self.MTYPE),
            ref(phase),
            ref(n),
            a.ctypes.data,
            indptr.ctypes.data_as(i32),
            indices.ctypes.data_as(i32),
            ctypes.POINTER(ctypes.c_int32)(),
            ref(1),
            self._iparm.ctypes.data_as(i32),
            ref(0),
            b.ctypes.data,
            x.ctypes.data,
            ctypes.byref(err),
        )
        if err.value != 0:
            raise RuntimeError(f"PARDISO phase {phase} failed with error {err.value}")

    def _set_pattern(self, K: sp.csr_matrix) -> None:
        """Upper-triangle structure of ``K`` and the positions of its entries in ``K.data``."""
        rows = np.repeat(np.arange(K.shape[0]), np.diff(K.indptr))
        pos = np.flatnonzero(K.indices >= rows)
        counts = np.bincount(rows[pos], minlength=K.shape[0])
        indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
        indices = K.indices[pos].astype(np.int32)
        if self._upper is None or not (
            np.array_equal(indptr, self._upper[0]) and np.array_equal(indices, self._upper[1])
        ):
            self._release()
        self._upper = (indptr, indices, pos)
        self._pattern = (K.indptr.copy(), K.indices.copy())

    def __call__(self, K: sp.spmatrix, rhs: np.ndarray) -> np.ndarray:
        """Solve ``K x = rhs`` as :func:`solve_symmetric` does, reading only the upper triangle
        of the symmetric ``K`` (scipy sparse; every diagonal entry stored, a stored zero is
        fine); returns the solution, raises RuntimeError if PARDISO reports an error."""
        K = sp.csr_matrix(K)
        if not K.has_sorted_indices:
            K = K.sorted_indices()
        same = self._pattern is not None and (
            np.array_equal(K.indptr, self._pattern[0])
            and np.array_equal(K.indices, self._pattern[1])
        )
        if not same:
            self._set_pattern(K)
        a = np.ascontiguousarray(K.data[self._upper[2]], dtype=float)
        b = np.array(rhs, dtype=float, copy=True)
        x = np.zeros_like(b)
        previous = self._set_threads(self.threads)
        try:
            if not self._analysed:
                self._call(11, a, b, x)
                self._analysed = True
                self.analyses += 1
            self._factored = None
            self._call(23, a, b, x)
            self._factored = a
            self.factorizations += 1
        finally:
            self._set_threads(previous)
        return x

    def resolve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve with the last factorisation (no new one): ``K x = rhs`` for the ``K`` of the
        last call, at the cost of the triangular solves (PARDISO phase 33).

        Raises
        ------
        RuntimeError
            Nothing factored yet, or PARDISO reports an error.
        """
        if self._factored is None:
            raise RuntimeError("PARDISO: nothing factored to solve with")
        b = np.array(rhs, dtype=float, copy=True)
        x = np.zeros_like(b)
        previous = self._set_threads(self.threads)
        try:
            self._call(33, self._factored, b, x)
        finally:
            self._set_threads(previous)
        return x

    def _release(self) -> None:
        self._factored = None
        if self._analysed and self._upper is not None:
            z = np.zeros(1)
            self._call(-1, z, z, z)
            self._analysed = False

    def __del__(self) -> None:
        try:
            self._release()
        except Exception:  # noqa: BLE001 -- interpreter shutdown: MKL may be gone
            pass


class FactorReuse:
    """A solver of the :class:`PardisoLDLT` protocol that first solves with its last
    factorisation as the preconditioner of GMRES, and factors only when that does not reach
    ``rtol`` within ``max_iterations``.

    Where the tangent changes little between Newton iterations the previous factor is a
    preconditioner under which GMRES converges in a few iterations, each one triangular solve
    (``resolve``, 13 ms on the 22,983 dofs of the zoned 3D mesh) and one product with ``K``
    (4 ms), against 0.30 s for a new factorisation.  A reused solution meets
    ``|K x - rhs| <= rtol |rhs|`` (checked on the true residual, not GMRES's estimate); a
    factored one is the inner solver's.  Whether it pays depends on how often the reuse
    succeeds (docs/fe-model.md, *Older factor as GMRES preconditioner*).

    Parameters
    ----------
    inner : callable
        The direct solver (:class:`PardisoLDLT` or :class:`SuperLUSolver`).
    rtol : float
        Relative residual a reused solve must reach.
    max_iterations : int
        GMRES iterations (no restart) before the solve falls back to a new factorisation; it
        also falls back after ``give_up_after`` iterations if the residual has not fallen by
        ``rtol ** (give_up_after / (2 max_iterations))`` by then: half the geometric rate that
        reaches ``rtol`` in ``max_iterations`` (GMRES accelerates as it goes).
    give_up_after : int
        See ``max_iterations``.

    Attributes
    ----------
    factorizations : int
        The inner solver's numerical factorisations.
    reuses : int
        Solves that reused an older factor (no factorisation).
    krylov_iterations : int
        GMRES iterations spent, those of the tries that fell back included.
    """

    def __init__(
        self, inner, rtol: float = 1e-9, max_iterations: int = 10, give_up_after: int = 4
    ) -> None:
        if not 0.0 < rtol < 1.0 or max_iterations < 1 or not 0 < give_up_after <= max_iterations:
            raise ValueError(
                "FactorReuse needs 0 < rtol < 1 and 0 < give_up_after <= max_iterations, got "
                f"rtol={rtol}, give_up_after={give_up_after}, max_iterations={max_iterations}"
            )
        self.inner = inner
        self.rtol, self.max_iterations, self.give_up_after = rtol, max_iterations, give_up_after
        self.name = (
            f"{solver_name(inner)}; an older factor preconditions GMRES first (rtol {rtol:g}, "
            f"at most {max_iterations} iterations)"
        )
        """For sidecars (:func:`solver_name`)."""
        self.reuses = 0
        self.krylov_iterations = 0
        self._K: sp.spmatrix | None = None  # the matrix of the last solve
        self._factored = False  # whether the inner factor is of that matrix

    @property
    def factorizations(self) -> int:
        """The inner solver's numerical factorisations."""
        return self.inner.factorizations

    def _krylov(self, K: sp.spmatrix, rhs: np.ndarray) -> np.ndarray | None:
        """GMRES on ``K P y = rhs``, ``x = P y``, with ``P`` the inner factor's solve (right
        preconditioning: GMRES's residual is that of ``K x = rhs``); None if it does not reach
        ``rtol`` (or gives up early, or the inner solve raises)."""
        n = K.shape[0]
        KM = spla.LinearOperator((n, n), matvec=lambda v: K @ self.inner.resolve(v), dtype=float)
        early = self.rtol ** (0.5 * self.give_up_after / self.max_iterations)
        count = [0]

        def watch(rel: float) -> None:
            count[0] += 1
            if count[0] == self.give_up_after and rel > early:
                raise _GiveUp

        try:
            y, _ = spla.gmres(  # right preconditioning: its residual is that of K x = rhs
                KM,
                rhs,
                rtol=self.rtol,
                atol=0.0,
                restart=self.max_iterations,
                maxiter=1,
                callback=watch,
                callback_type="pr_norm",
            )
            x = self.inner.resolve(y)
        except (_GiveUp, RuntimeError):
            x = None
        self.krylov_iterations += count[0]
        if x is None or not np.all(np.isfinite(x)):
            return None
        if np.linalg.norm(K @ x - rhs) > self.rtol * np.linalg.norm(rhs):
            return None
        return x

    def __call__(self, K: sp.spmatrix, rhs: np.ndarray) -> np.ndarray:
        """Solve ``K x = rhs`` (symmetric ``K``, as the inner solver reads it): with the last
        factor if GMRES gets there, else with a new factorisation."""
        rhs = np.asarray(rhs, dtype=float)
        if self._K is not None and self._K.shape == K.shape:
            x = self._krylov(K, rhs)
            if x is not None:
                self.reuses += 1
                self._K, self._factored = K, False
                return x
        self._K = None
        x = self.inner(K, rhs)
        self._K, self._factored = K, True
        return x

    def resolve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve again with the matrix of the last call: the inner factor's triangular solves
        if it is that matrix's, else GMRES as in :meth:`__call__`.

        Raises
        ------
        RuntimeError
            Nothing solved yet, or GMRES does not reach ``rtol``.
        """
        if self._K is None:
            raise RuntimeError("FactorReuse: nothing solved yet")
        if self._factored:
            return self.inner.resolve(rhs)
        x = self._krylov(self._K, np.asarray(rhs, dtype=float))
        if x is None:
            raise RuntimeError("FactorReuse: GMRES with the older factor did not converge")
        return x


class _GiveUp(Exception):
    """GMRES's rate would not reach ``FactorReuse.rtol`` in time (internal)."""


def make_solver(name: str = "auto") -> Callable[[sp.spmatrix, np.ndarray], np.ndarray]:
    """A linear solver ``solve(K, rhs) -> x`` for symmetric sparse tangents.

    Parameters
    ----------
    name : str
        ``"superlu"`` (:func:`solve_symmetric`), ``"pardiso"`` (:class:`PardisoLDLT`, needs
        ``pypardiso``) or ``"auto"`` (PARDISO if installed, else SuperLU).

    Returns
    -------
    callable
        The solver (:class:`SuperLUSolver` or :class:`PardisoLDLT`): ``solver(K, rhs)`` factors
        and solves, ``solver.resolve(rhs)`` solves again with the last factor; each keeps its
        factor (PARDISO also its analysis) between calls, so make one per run.

    Raises
    ------
    ValueError
        Unknown name.
    ImportError
        ``"pardiso"`` without ``pypardiso``.
    """
    if name not in SOLVERS:
        raise ValueError(f"linear solver must be one of {SOLVERS}, got {name!r}")
    if name == "superlu":
        return SuperLUSolver()
    try:
        return PardisoLDLT()
    except (ImportError, OSError, AttributeError):
        if name == "pardiso":
            raise
        return SuperLUSolver()


def solver_name(solve: Callable) -> str:
    """Human-readable name of a solver from :func:`make_solver` (for sidecars)."""
    return getattr(solve, "name", "scipy SuperLU (MMD_AT_PLUS_A, symmetric mode)")
