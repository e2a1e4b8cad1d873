"""Structured hexahedral mesh of one eighth of a tube and its Q2/P1 discretisation (mm).

The model domain is the tube wall ``R - t <= r <= R``, ``0 <= theta <= 90 deg`` (``x >= 0``,
``y >= 0``), ``0 <= z <= L/2``; the jaws move along ``y`` and the jaw mid-plane is ``z = 0``.
Element layers follow the cylindrical coordinates ``(r, theta, z)``; the trilinear hexahedra are
cut into 27-node triquadratic (Q2) elements (skfem ``ElementHex2``), with a discontinuous
linear (P1, 4 functions) or constant (P0) dilatation/pressure per element, condensed.  Q2/P1 is
the inf-sup stable Crouzeix-Raviart pair on hexahedra.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize as so

from grasprom.fe.model2d import graded_fractions

ELEMENTS_3D = ("Q2/P1", "Q2/P0", "Q2/Q1")


@dataclass(frozen=True)
class MeshSpec3D:
    """Structured Q2 hexahedral mesh of the 1/8 tube.

    Parameters
    ----------
    n_layers : int
        Element layers through the wall thickness.
    n_circ : int
        Element divisions along the quarter circumference.
    n_jaw : int
        Uniform axial divisions over ``0 <= z <= jaw_length/2 + fine_margin_mm`` (the jaw and
        the transition just beyond its edge).
    n_free : int
        Axial divisions over the rest of the half tube, geometrically growing away from the jaw
        (first one as long as a jaw element).
    grading : float
        Ratio of the largest to the smallest circumferential element (> 1 refines toward the
        side fold at ``theta = 0``).
    fine_margin_mm : float
        Length (mm) beyond the jaw edge meshed as finely as the jaw.
    element : str
        ``"Q2/P1"`` (default), ``"Q2/P0"`` or ``"Q2/Q1"`` (discontinuous trilinear).
    beta : float
        Share of the volumetric energy evaluated pointwise, ``(1 - beta) U(theta) + beta U(J)``:
        a small ``beta`` suppresses the spurious pointwise-volume modes of the mixed element in
        tight folds at the cost of a slight stiffening (``beta kappa`` acts on ``J - theta``,
        which vanishes as the mesh is refined).  Default 0.05: with 0 the element buckles
        spuriously in the fold's compression (in plane strain, t = 1.4 mm, -31 % force at gap
        5.5 mm against the 2D model; 0.01 and, on a full tube, 0.02 are not always enough);
        with 0.05 it follows the 2D model within 0.7 % through the crease band
        (``benchmarks/bench_fe3d.py element``).
    radial_grading : float
        Ratio of the outermost to the innermost layer thickness (1 = uniform; > 1 puts thin
        layers at the inner wall, where the fold's inner surface creases, as the 2D mesh).
    """

    n_layers: int = 2
    n_circ: int = 12
    n_jaw: int = 4
    n_free: int = 9
    grading: float = 2.0
    fine_margin_mm: float = 2.0
    element: str = "Q2/P1"
    beta: float = 0.05
    radial_grading: float = 1.0

    def __post_init__(self) -> None:
        for name, least in (("n_layers", 1), ("n_circ", 2), ("n_jaw", 1), ("n_free", 0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < least:
                raise ValueError(f"mesh too coarse: {name}={v!r} (an integer >= {least})")
        if not (np.isfinite(self.fine_margin_mm) and self.fine_margin_mm >= 0):
            raise ValueError(f"invalid fine_margin_mm={self.fine_margin_mm!r}: a length >= 0 mm")
        if self.element not in ELEMENTS_3D:
            raise ValueError(f"unknown element {self.element!r}; valid: {', '.join(ELEMENTS_3D)}")
        for name in ("grading", "radial_grading"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"invalid {name}={v!r}: a ratio of element sizes, > 0")
        if not (np.isfinite(self.beta) and 0.0 <= self.beta <= 1.0):
            raise ValueError(f"invalid beta={self.beta!r}: a share in [0, 1]")


def axial_nodes(half_length: float, z_fine: float, n_jaw: int, n_free: int) -> np.ndarray:
    """Axial node positions (mm) on ``[0, half_length]``: uniform up to ``z_fine``, then graded."""
    if z_fine >= half_length or n_free < 1:
        return np.linspace(0.0, half_length, max(n_jaw, 1) + 1)
    z1 = np.linspace(0.0, z_fine, n_jaw + 1)
    dz0 = z_fine / n_jaw
    rest = half_length - z_fine
    if dz0 * n_free >= rest or n_free == 1:
        z2 = np.linspace(z_fine, half_length, n_free + 1)
    else:  # growth q > 1 with dz0 (1 + q + ... + q^(n_free - 1)) = rest; at q = rest/dz0 the
        # sum exceeds rest (n_free >= 2), so the root is bracketed for any tube length
        q_hi = max(10.0, rest / dz0)
        q = so.brentq(lambda q: dz0 * (q**n_free - 1.0) / (q - 1.0) - rest, 1.0 + 1e-9, q_hi)
        z2 = z_fine + np.concatenate([[0.0], np.cumsum(dz0 * q ** np.arange(n_free))])
        z2[-1] = half_length
    return np.concatenate([z1, z2[1:]])


def ring_nodes(outer_radius: float, thickness: float, mesh: MeshSpec3D):
    """Radii (mm) of the layer interfaces and angles (rad, 0 .. pi/2) of the circumferential
    element boundaries of the 1/8 tube's cross-section."""
    nl, nc = mesh.n_layers, mesh.n_circ  # validated by MeshSpec3D
    if mesh.radial_grading == 1.0:  # bit for bit the uniform layers of before
        r = np.linspace(outer_radius - thickness, outer_radius, nl + 1)
    else:
        r = outer_radius - thickness + thickness * graded_fractions(nl, mesh.radial_grading)
    return r, 0.5 * np.pi * graded_fractions(nc, mesh.grading)


def tube_mesh(outer_radius: float, thickness: float, z_nodes: np.ndarray, mesh: MeshSpec3D):
    """Hexahedral mesh (skfem ``MeshHex``) of the 1/8 tube on the given axial nodes (mm)."""
    import skfem

    r, th = ring_nodes(outer_radius, thickness, mesh)
    m = skfem.MeshHex.init_tensor(r, th, np.asarray(z_nodes, dtype=float))
    rho, t, z = m.p
    x = rho * np.cos(t)
    y = rho * np.sin(t)
    x[np.isclose(t, 0.5 * np.pi)] = 0.0
    y[t == 0.0] = 0.0
    return skfem.MeshHex(np.vstack([x, y, z]), m.t)


@dataclass(frozen=True)
class Disc3D:
    """Precomputed arrays of the 3D discretisation (internal; nodes = Q2 dofs, mm)."""

    ndof: int
    edofs: np.ndarray  # (ne, 81) vector dofs, [3 a + i]
    grads: np.ndarray  # (ne, nq, 27, 3) dN_a/dX_j
    dx: np.ndarray  # (ne, nq) quadrature weight x det J (mm^3)
    psi: np.ndarray  # (ne, nq, npr) pressure basis
    wpsi: np.ndarray  # (ne, nq, npr)
    Minv: np.ndarray  # (ne, npr, npr)
    X: np.ndarray  # (nnode, 3) reference positions
    outer_nodes: np.ndarray  # nodes on the outer wall
    outer_area: np.ndarray  # consistent reference area (mm^2) of each outer node
    inner_nodes: np.ndarray  # nodes on the inner wall, not on y = 0
    on_x0: np.ndarray  # bool over nodes
    on_y0: np.ndarray
    on_z0: np.ndarray
    on_end: np.ndarray  # z = L/2
    rows: np.ndarray
    cols: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    diag_pos: np.ndarray
    transpose_pos: np.ndarray  # CSR position of the entry (j, i) of the entry (i, j)
    grads_t: np.ndarray  # (ne, 27, nq * 3) dN_b/dX_l at [e, b, (q l)] (the tangent's layout)
    scatter_t: np.ndarray  # CSR position of each element-matrix entry in the order [e, b, i, k, a]
    beta: float = 0.0  # pointwise share of the volumetric energy


def _pressure_basis(basis, m, dx: np.ndarray, kind: str):
    """Discontinuous pressure basis at the quadrature points (ne, nq, 1, 4 or 8).

    ``P0``: constant; ``P1``: 1, x, y, z (physical, centred, scaled); ``Q1``: trilinear in the
    reference coordinates of the element.
    """
    ne, nq = dx.shape
    if kind == "P0":
        return np.ones((ne, nq, 1))
    if kind == "Q1":
        xi = 2.0 * np.asarray(basis.X) - 1.0  # (3, nq) reference points in [-1, 1]
        funcs = [np.ones(nq), xi[0], xi[1], xi[2]]
        funcs += [xi[0] * xi[1], xi[1] * xi[2], xi[0] * xi[2], xi[0] * xi[1] * xi[2]]
        return np.broadcast_to(np.stack(funcs, axis=-1), (ne, nq, 8)).copy()
    xq = basis.mapping.F(basis.X)  # (3, ne, nq)
    xc = (xq * dx).sum(axis=2) / dx.sum(axis=1)
    hsz = np.cbrt(dx.sum(axis=1))
    cols = [np.ones((ne, nq))]
    cols += [(xq[i] - xc[i][:, None]) / hsz[:, None] for i in range(3)]
    return np.stack(cols, axis=-1)


def _csr_maps(edofs: np.ndarray, ndof: int):
    """Unique CSR pattern of the element matrices, the scatter map into it, the diagonal's
    positions and each entry's transposed position (the pattern is symmetric)."""
    nd = edofs.shape[1]
    rows = np.repeat(edofs, nd, axis=1).ravel()
    cols = np.tile(edofs, (1, nd)).ravel()
    keys = rows * ndof + cols
    uniq, scatter = np.unique(keys, return_inverse=True)
    urows = uniq // ndof
    ucols = uniq % ndof
    indptr = np.searchsorted(urows, np.arange(ndof + 1))
    transpose_pos = np.searchsorted(uniq, ucols * ndof + urows)
    diag_pos = np.flatnonzero(urows == ucols)
    return urows, ucols, scatter.ravel(), indptr, diag_pos, transpose_pos


def _outer_area(m, element, outer_f) -> np.ndarray:
    """Consistent reference surface area (mm^2) of every node on the outer facets."""
    import skfem

    fb = skfem.FacetBasis(m, element, facets=outer_f, intorder=4)
    return skfem.LinearForm(lambda v, w: v).assemble(fb)


def discretise3d(outer_radius: float, thickness: float, z_nodes: np.ndarray, mesh: MeshSpec3D):
    """Basis, quadrature data, boundary sets and the sparse assembly map of the 1/8 tube."""
    import skfem

    m = tube_mesh(outer_radius, thickness, z_nodes, mesh)
    elem = skfem.ElementHex2()
    basis = skfem.Basis(m, elem, intorder=4)
    nloc = elem.doflocs.shape[0]
    grads = np.stack([basis.basis[a][0].grad for a in range(nloc)])  # (nloc, 3, ne, nq)
    grads = np.ascontiguousarray(grads.transpose(2, 3, 0, 1))
    dx = np.asarray(basis.dx)
    psi = _pressure_basis(basis, m, dx, mesh.element.split("/")[1])
    wpsi = dx[..., None] * psi
    Minv = np.linalg.inv(np.einsum("eqk,eql->ekl", wpsi, psi))
    sdofs = basis.element_dofs.T
    edofs = (3 * sdofs[:, :, None] + np.arange(3)).reshape(sdofs.shape[0], -1)
    X = basis.doflocs.T.copy()
    ndof = 3 * X.shape[0]
    tol = 1e-9 * outer_radius
    half = float(z_nodes[-1])
    rin = outer_radius - thickness
    bf = m.boundary_facets()
    # a facet is on a wall when all its vertices are (the chord midpoint of a coarse
    # circumferential element sags below the wall by R (1 - cos(dtheta / 2)))
    rv = np.hypot(*m.p[:2, m.facets[:, bf]])
    outer_f = bf[np.all(np.abs(rv - outer_radius) < tol, axis=0)]
    inner_f = bf[np.all(np.abs(rv - rin) < tol, axis=0)]
    outer_nodes = np.unique(basis.get_dofs(outer_f).all())
    inner_nodes = np.unique(basis.get_dofs(inner_f).all())
    on_y0 = np.abs(X[:, 1]) < tol
    inner_nodes = inner_nodes[~on_y0[inner_nodes]]
    area = _outer_area(m, elem, outer_f)[outer_nodes]
    rows, cols, scatter, indptr, diag_pos, transpose_pos = _csr_maps(edofs, ndof)
    ne, nq = dx.shape
    # [e, (a i), (b k)] -> [e, b, i, k, a]: the order model3d's element tangent comes out in
    scatter_t = scatter.reshape(ne, nloc, 3, nloc, 3).transpose(0, 3, 2, 4, 1).ravel()
    grads_t = np.ascontiguousarray(grads.transpose(0, 2, 1, 3)).reshape(ne, nloc, nq * 3)
    return Disc3D(
        ndof=ndof,
        edofs=edofs,
        grads=grads,
        dx=dx,
        psi=psi,
        wpsi=wpsi,
        Minv=Minv,
        X=X,
        outer_nodes=outer_nodes,
        outer_area=area,
        inner_nodes=inner_nodes,
        on_x0=np.abs(X[:, 0]) < tol,
        on_y0=on_y0,
        on_z0=np.abs(X[:, 2]) < tol,
        on_end=np.abs(X[:, 2] - half) < tol,
        rows=rows,
        cols=cols,
        indptr=indptr,
        indices=cols.astype(np.int32),
        diag_pos=diag_pos,
        transpose_pos=transpose_pos,
        grads_t=grads_t,
        scatter_t=scatter_t,
        beta=float(mesh.beta),
    )
