"""Structured hexahedral mesh of one eighth of a tube and its Q2/P1 discretisation (mm).

The model domain is the tube wall ``R - t <= r <= R``, ``0 <= theta <= 90 deg`` (``x >= 0``,
``y >= 0``), ``0 <= z <= L/2``; the jaws move along ``y`` and the jaw mid-plane is ``z = 0``.
Element layers follow the cylindrical coordinates ``(r, theta, z)``; the trilinear hexahedra are
cut into 27-node triquadratic (Q2) elements (skfem ``ElementHex2``), with a discontinuous
linear (P1, 4 functions) or constant (P0) dilatation/pressure per element, condensed.  Q2/P1 is
the inf-sup stable Crouzeix-Raviart pair on hexahedra.  With ``MeshSpec3D.far_coarsening`` > 1
the tube beyond the fine zone over the jaw has a coarser cross-section, and the fine zone's
nodes on the interface plane are tied to the coarse face (hanging nodes, eliminated).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

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
    far_coarsening : int
        Beyond the fine zone (``z > jaw_length/2 + fine_margin_mm``) the cross-section has
        ``n_layers / k`` layers and ``n_circ / k`` circumferential divisions (every k-th layer
        and circumferential boundary of the fine zone's, so the grading is kept), ``k`` this
        factor; 1 (default) is one cross-section along the whole tube.  The two zones meet at a
        plane where the fine face's nodes are tied to the coarse face (their displacement is the
        coarse face's quadratic interpolation; the tied nodes are eliminated): a linear
        displacement field passes the interface exactly.  The folds and the contact are in the
        fine zone; beyond it the tube only ovalises, which the coarse cross-section resolves
        (``benchmarks/bench_fe3d.py transition``).  Needs a far zone (a tube longer than the
        jaw plus twice ``fine_margin_mm`` > 0, ``n_free`` >= 1).  Known limitation: with two
        or more coarse layers, a fine node on the arc where two coarse layers meet lies off
        their common chord, and each side's face interpolates it (a linear field alike, a
        field with a kink at that chord not), so the tie is not exactly conforming there.
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
    far_coarsening: int = 1

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
        k = self.far_coarsening
        if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 1:
            raise ValueError(f"invalid far_coarsening={k!r}: an integer >= 1")
        if k > 1 and not self.fine_margin_mm > 0:
            raise ValueError(
                f"far_coarsening={k} needs fine_margin_mm > 0 (the tied plane off the jaw)"
            )
        if self.n_layers % k or self.n_circ % k:
            raise ValueError(
                f"far_coarsening={k} must divide n_layers={self.n_layers} and "
                f"n_circ={self.n_circ} (the coarse zone takes every {k}-th boundary)"
            )


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


def _tube_points(r: np.ndarray, th: np.ndarray, z_nodes: np.ndarray):
    """Cartesian vertices (3, n) and hexahedra (8, ne) of the tensor mesh on radii ``r``,
    angles ``th`` (rad) and axial positions ``z_nodes`` (mm)."""
    import skfem

    m = skfem.MeshHex.init_tensor(r, th, np.asarray(z_nodes, dtype=float))
    rho, t, z = m.p
    x = rho * np.cos(t)
    y = rho * np.sin(t)
    x[np.isclose(t, 0.5 * np.pi)] = 0.0
    y[t == 0.0] = 0.0
    return np.vstack([x, y, z]), m.t


def tube_mesh(outer_radius: float, thickness: float, z_nodes: np.ndarray, mesh: MeshSpec3D):
    """Hexahedral mesh (skfem ``MeshHex``) of the 1/8 tube on the given axial nodes (mm)."""
    import skfem

    r, th = ring_nodes(outer_radius, thickness, mesh)
    return skfem.MeshHex(*_tube_points(r, th, z_nodes))


def transition_mesh(
    outer_radius: float, thickness: float, z_nodes: np.ndarray, mesh: MeshSpec3D, n_fine: int
):
    """The 1/8 tube meshed finely over the first ``n_fine`` axial divisions and with the
    cross-section coarsened ``mesh.far_coarsening`` times beyond (mm).

    Returns the skfem ``MeshHex`` of both zones -- disjoint: the vertices of the interface plane
    appear once in each zone -- and the number of fine-zone elements (numbered first).
    """
    import skfem

    r, th = ring_nodes(outer_radius, thickness, mesh)
    k = mesh.far_coarsening
    z = np.asarray(z_nodes, dtype=float)
    pf, tf = _tube_points(r, th, z[: n_fine + 1])
    pc, tc = _tube_points(r[::k], th[::k], z[n_fine:])
    m = skfem.MeshHex(np.hstack([pf, pc]), np.hstack([tf, tc + pf.shape[1]]))
    return m, tf.shape[1]


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
    # with a coarsened far zone (MeshSpec3D.far_coarsening > 1): all mesh nodes, the tied ones
    # included, for output (VTU); None when every mesh node is a solver node
    out_X: np.ndarray | None = None  # (n_out, 3) reference positions
    out_cells: np.ndarray | None = None  # (ne, 27) node ids into out_X, skfem's Hex2 order
    out_expand: Any = None  # scipy.sparse (n_out, nnode): nodal values -> all mesh nodes

    def output_mesh(self, u: np.ndarray):
        """Reference positions (mm), displacements (mm) and 27-node cells of every mesh node.

        Parameters
        ----------
        u : numpy.ndarray
            Solver displacements (mm), ``3 n_nodes``.

        Returns
        -------
        tuple of numpy.ndarray
            ``(X, displacement, cells)``: ``(n, 3)``, ``(n, 3)``, ``(ne, 27)``; the nodes tied at
            a zone interface get the coarse face's interpolation.
        """
        disp = np.asarray(u, dtype=float).reshape(-1, 3)
        if self.out_X is None:
            return self.X, disp, self.edofs[:, ::3] // 3
        return self.out_X, np.asarray(self.out_expand @ disp), self.out_cells


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


def _lagrange3(x: np.ndarray) -> np.ndarray:
    """The three 1D quadratic Lagrange functions on the nodes -1, 0, 1 at ``x`` (..., 3)."""
    return np.stack([0.5 * x * (x - 1.0), (1.0 - x) * (1.0 + x), 0.5 * x * (x + 1.0)], axis=-1)


def _bilinear_inverse(corners: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Reference coordinates ``(xi, eta)`` of points ``pts`` (n, 2) of the plane quadrilateral
    with ``corners[i, j]`` at ``xi = 2 i - 1``, ``eta = 2 j - 1`` (Newton; points slightly
    outside the quadrilateral, e.g. on the arc beyond a chord, extrapolate)."""
    c = corners.reshape(4, 2)  # (0,0) (0,1) (1,0) (1,1)
    sx = np.array([-1.0, -1.0, 1.0, 1.0])
    se = np.array([-1.0, 1.0, -1.0, 1.0])
    xe = np.zeros((len(pts), 2))
    for _ in range(50):
        a, b = xe[:, :1], xe[:, 1:]
        N = 0.25 * (1 + sx * a) * (1 + se * b)  # (n, 4)
        r = pts - N @ c
        Ja = (0.25 * sx * (1 + se * b)) @ c  # d x / d xi, (n, 2)
        Jb = (0.25 * se * (1 + sx * a)) @ c
        det = Ja[:, 0] * Jb[:, 1] - Ja[:, 1] * Jb[:, 0]
        xe[:, 0] += (r[:, 0] * Jb[:, 1] - r[:, 1] * Jb[:, 0]) / det
        xe[:, 1] += (Ja[:, 0] * r[:, 1] - Ja[:, 1] * r[:, 0]) / det
        if np.abs(r).max() <= 1e-12 * np.abs(c).max():
            return xe
    raise RuntimeError("zone interface: the inverse map of a coarse face did not converge")


def _polar_key(xy: np.ndarray, scale: float) -> np.ndarray:
    """Rounded (radius, angle) of points, to sort and match positions on the 1/8 ring."""
    radius = np.hypot(xy[:, 0], xy[:, 1]) / scale
    return np.round(np.stack([radius, np.arctan2(xy[:, 1], xy[:, 0])]), 9)


def _interface_corners(m, elements: np.ndarray, z_if: float, tol: float) -> np.ndarray:
    """``(n, 4, 2)``: x, y (mm) of each element's 4 vertices on the plane ``z = z_if``."""
    p = m.p[:, m.t[:, elements]]  # (3, 8, n)
    on = np.abs(p[2] - z_if) < tol
    return p[:2].transpose(2, 1, 0)[on.T].reshape(len(elements), 4, 2)


def _interface_ties(
    m, sdofs: np.ndarray, X: np.ndarray, n_fine: int, z_if: float, tol: float, wall: np.ndarray
):
    """Tie the fine zone's nodes on the plane ``z = z_if`` to the coarse zone's face.

    For every fine element with a face on the plane: the local slots of its 9 face nodes, the 9
    nodes of the coarse face that contains it, and the weights ``W[s, m]`` (the coarse face's
    2D quadratic Lagrange functions at the fine nodes, in the coarse face's own bilinear
    reference coordinates, so a linear field is reproduced exactly); and ``Wa``, the same with
    the radial coordinate of a wall node set to its wall (``wall`` per node: 1 outer, -1 inner,
    0 neither), which passes a wall node's outer area on to the nodes of that wall only (the
    fine nodes on the wall lie off the coarse face's chords, where ``W`` reaches into the next
    layer).

    Returns
    -------
    tuple
        ``(elements (n,), slots (n, 9), masters (n, 9), W (n, 9, 9), Wa (n, 9, 9))``; node
        ids of ``X``.
    """
    on = np.abs(X[:, 2] - z_if) < tol
    face = on[sdofs].sum(axis=1) == 9
    fine = np.flatnonzero(face[:n_fine])
    coarse = n_fine + np.flatnonzero(face[n_fine:])
    scale = np.abs(X[:, :2]).max()
    # each coarse face by the (radius, angle) box of its 4 corners, each fine face by their mean
    cc = _interface_corners(m, coarse, z_if, tol)
    key = _polar_key(cc.reshape(-1, 2), scale).reshape(2, coarse.size, 4)
    lo, hi = key.min(axis=2).T, key.max(axis=2).T
    order = np.lexsort((key[1], key[0]), axis=-1)
    corners_all = np.take_along_axis(cc, order[..., None], axis=1).reshape(-1, 2, 2, 2)
    fc = _interface_corners(m, fine, z_if, tol)
    centre = _polar_key(fc.reshape(-1, 2), scale).reshape(2, fine.size, 4).mean(axis=2).T
    hits = np.all((lo <= centre[:, None]) & (centre[:, None] <= hi), axis=2)
    bad = np.flatnonzero(hits.sum(axis=1) != 1)
    if bad.size:
        n = int(hits[bad[0]].sum())
        raise RuntimeError(f"zone interface: fine face {fine[bad[0]]} lies in {n} coarse faces")
    slots = np.empty((fine.size, 9), dtype=np.int64)
    masters = np.empty((fine.size, 9), dtype=np.int64)
    W = np.empty((fine.size, 9, 9))
    Wa = np.empty((fine.size, 9, 9))
    for i, (e, j) in enumerate(zip(fine, hits.argmax(axis=1))):
        loc = np.flatnonzero(on[sdofs[e]])
        mloc = np.flatnonzero(on[sdofs[coarse[j]]])
        corners = corners_all[j]
        xm = np.round(_bilinear_inverse(corners, X[sdofs[coarse[j], mloc], :2])).astype(int) + 1
        xs = _bilinear_inverse(corners, X[sdofs[e, loc], :2])
        W[i] = _lagrange3(xs[:, 0])[:, xm[:, 0]] * _lagrange3(xs[:, 1])[:, xm[:, 1]]
        # the wall share: a node of the inner or outer wall on that wall of the coarse face
        xr = np.where(wall[sdofs[e, loc]] != 0, wall[sdofs[e, loc]], xs[:, 0])
        Wa[i] = _lagrange3(xr)[:, xm[:, 0]] * _lagrange3(xs[:, 1])[:, xm[:, 1]]
        slots[i] = loc
        masters[i] = sdofs[coarse[j], mloc]
    return fine, slots, masters, W, Wa


def _eliminate_ties(grads, sdofs, X, outer_area_all, ties):
    """Express the tied nodes by their masters: element gradients of the fine interface
    elements recombined (``dN_m = sum_s W[s, m] dN_s``), the tied nodes' outer area passed on
    to the wall's masters (``Wa``), the tied nodes removed and the rest renumbered.

    Returns ``(grads, node ids per element, renumbering, area of all nodes, expand)``: the node
    ids are of all nodes, ``renumbering`` maps them to the kept ones (-1 for a tied node) and
    ``expand`` the kept nodes' values to all nodes (the tied ones interpolated).
    """
    import scipy.sparse as sp

    elements, slots, masters, W, Wa = ties
    grads = grads.copy()
    sd = sdofs.copy()
    for e, loc, mst, w in zip(elements, slots, masters, W):
        grads[e][:, loc, :] = np.einsum("sm,qsj->qmj", w, grads[e][:, loc, :])
        sd[e, loc] = mst
    # one weight row per tied node (a node shared by two fine faces has the same interpolation)
    tied, first = np.unique(sdofs[elements[:, None], slots].ravel(), return_index=True)
    rows_m = np.repeat(masters, 9, axis=0)[first]
    rows_w = W.reshape(-1, 9)[first]
    area = np.asarray(outer_area_all, dtype=float).copy()
    np.add.at(area, rows_m.ravel(), (Wa.reshape(-1, 9)[first] * area[tied, None]).ravel())
    area[tied] = 0.0
    n_all = X.shape[0]
    keep = np.setdiff1d(np.arange(n_all), tied)
    renum = np.full(n_all, -1)
    renum[keep] = np.arange(keep.size)
    ri = np.concatenate([keep, np.repeat(tied, 9)])
    ci = np.concatenate([renum[keep], renum[rows_m.ravel()]])
    vals = np.concatenate([np.ones(keep.size), rows_w.ravel()])
    expand = sp.csr_matrix((vals, (ri, ci)), shape=(n_all, keep.size))
    return grads, sd, renum, area, expand


def _wall_facets(m, outer_radius: float, inner_radius: float, tol: float):
    """The boundary facets on the outer and on the inner wall (mm): those whose vertices all
    are (the chord midpoint of a coarse circumferential element sags below the wall by
    ``R (1 - cos(dtheta / 2))``, so the Q2 nodes cannot tell)."""
    bf = m.boundary_facets()
    rv = np.hypot(*m.p[:2, m.facets[:, bf]])
    outer = bf[np.all(np.abs(rv - outer_radius) < tol, axis=0)]
    inner = bf[np.all(np.abs(rv - inner_radius) < tol, axis=0)]
    return outer, inner


class _ZoneArrays(NamedTuple):
    """The node-indexed arrays that tying the zones renumbers."""

    grads: np.ndarray
    sdofs: np.ndarray
    X: np.ndarray
    area: np.ndarray
    outer_nodes: np.ndarray
    inner_nodes: np.ndarray


def _tie_zones(m, basis, a: _ZoneArrays, n_fine_elements: int, z_if: float, tol: float):
    """Tie the fine zone's interface nodes to the coarse face and drop them: the arrays on the
    solver nodes, and the output fields of :class:`Disc3D` (every mesh node)."""
    wall = np.zeros(a.X.shape[0])
    wall[a.outer_nodes], wall[a.inner_nodes] = 1.0, -1.0
    ties = _interface_ties(m, a.sdofs, a.X, n_fine_elements, z_if, tol, wall)
    grads, sdofs, renum, area, expand = _eliminate_ties(a.grads, a.sdofs, a.X, a.area, ties)
    out = {"out_X": a.X, "out_cells": basis.element_dofs.T.copy(), "out_expand": expand}
    keep = renum >= 0
    outer = renum[a.outer_nodes]
    inner = renum[a.inner_nodes]
    kept = _ZoneArrays(
        np.ascontiguousarray(grads),
        renum[sdofs],
        a.X[keep],
        area[keep],
        outer[outer >= 0],
        inner[inner >= 0],
    )
    return kept, out


def _outer_area(m, element, outer_f) -> np.ndarray:
    """Consistent reference surface area (mm^2) of every node on the outer facets."""
    import skfem

    fb = skfem.FacetBasis(m, element, facets=outer_f, intorder=4)
    return skfem.LinearForm(lambda v, w: v).assemble(fb)


def has_far_zone(z_nodes, n_fine: int | None) -> bool:
    """Whether the axial grid ``z_nodes`` (mm) has divisions beyond the fine zone's first
    ``n_fine``: a far zone that ``MeshSpec3D.far_coarsening`` > 1 can coarsen."""
    return n_fine is not None and 0 < n_fine < len(z_nodes) - 1


def _zoned_mesh(outer_radius: float, thickness: float, z_nodes, mesh: MeshSpec3D, n_fine):
    """The tube's mesh and, with a coarsened far zone, the number of fine-zone elements (None
    for one cross-section along the tube)."""
    if mesh.far_coarsening == 1:
        return tube_mesh(outer_radius, thickness, z_nodes, mesh), None
    if not has_far_zone(z_nodes, n_fine):
        raise ValueError(
            f"far_coarsening={mesh.far_coarsening} needs a far zone beyond the fine one: a tube "
            "longer than the jaw plus twice fine_margin_mm, n_free >= 1 and the fine zone's "
            "divisions (n_fine)"
        )
    return transition_mesh(outer_radius, thickness, z_nodes, mesh, n_fine)


def discretise3d(
    outer_radius: float,
    thickness: float,
    z_nodes: np.ndarray,
    mesh: MeshSpec3D,
    n_fine: int | None = None,
):
    """Basis, quadrature data, boundary sets and the sparse assembly map of the 1/8 tube.

    ``n_fine`` is the number of axial divisions of the fine zone (from ``z = 0``): with
    ``mesh.far_coarsening > 1`` the cross-section is coarsened beyond it and the interface
    nodes of the fine zone are tied to the coarse face and eliminated (:class:`MeshSpec3D`).
    """
    import skfem

    z_nodes = np.asarray(z_nodes, dtype=float)
    m, n_fine_elements = _zoned_mesh(outer_radius, thickness, z_nodes, mesh, n_fine)
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
    X = basis.doflocs.T.copy()
    tol = 1e-9 * outer_radius
    half = float(z_nodes[-1])
    outer_f, inner_f = _wall_facets(m, outer_radius, outer_radius - thickness, tol)
    outer_nodes = np.unique(basis.get_dofs(outer_f).all())
    inner_nodes = np.unique(basis.get_dofs(inner_f).all())
    area_all = _outer_area(m, elem, outer_f)
    out = {}
    if n_fine_elements is not None:
        z_if = float(z_nodes[n_fine])
        zones = _ZoneArrays(grads, sdofs, X, area_all, outer_nodes, inner_nodes)
        zones, out = _tie_zones(m, basis, zones, n_fine_elements, z_if, tol)
        grads, sdofs, X, area_all, outer_nodes, inner_nodes = zones
    edofs = (3 * sdofs[:, :, None] + np.arange(3)).reshape(sdofs.shape[0], -1)
    ndof = 3 * X.shape[0]
    on_y0 = np.abs(X[:, 1]) < tol
    inner_nodes = inner_nodes[~on_y0[inner_nodes]]
    area = area_all[outer_nodes]
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
        **out,
    )
