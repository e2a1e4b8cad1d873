"""Moving a 3D displacement field from one mesh of the tube to another.

The 3D meshes (:mod:`grasprom.fe.mesh3d`) are tensor meshes in ``(r, theta, z)`` mapped to
trilinear hexahedra, with a 27-node (Q2) displacement field.  A :class:`FieldProbe` evaluates
that field at any reference points of the tube, so a state computed on one mesh (e.g. a creased
state of the crease band) can start a solve on another: the two meshes' forces on a *common*
branch of equilibria measure the discretisation error, apart from which branch each run reached
(docs/fe-model.md, *The band on a common start*).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from grasprom.fe.mesh3d import ring_nodes
from grasprom.fe.model3d import axial_grid, build_disc

#: Newton iterations of the inverse trilinear map (converges quadratically from the polar
#: guess; the elements are nearly affine)
INVERSE_ITERATIONS = 12

#: A point belongs to the element whose local coordinates leave [0, 1] by the least; points
#: outside the faceted tube (a finer mesh's node on the circle beyond the coarse chord) are
#: extrapolated from the nearest element, by at most this share of its local extent (else an
#: error).  The meshes' walls are faceted differently: a coarse far zone's chord (2 x 12 graded
#: 4:1, halved) sags 0.27 of its layer inside the outer circle, and the midpoint of its
#: inner-wall chord lies 0.72 of a 3-layer mesh's inner layer inside that mesh's inner wall
MAX_EXTRAPOLATION = 1.0


@dataclass(frozen=True)
class _Zone:
    """One tensor zone of a mesh: its grids and ``cell[ir, ith, iz]`` -> element."""

    r: np.ndarray
    th: np.ndarray
    z: np.ndarray
    cell: np.ndarray


def _lagrange_basis(elem, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values ``(nloc, n)`` and reference gradients ``(nloc, 3, n)`` of a skfem element's
    nodal basis at reference points ``xi`` ``(3, n)`` in [0, 1]^3."""
    vals, grads = zip(*(elem.lbasis(xi, a) for a in range(elem.doflocs.shape[0])), strict=True)
    return np.array(vals), np.array(grads)


class FieldProbe:
    """Interpolation of a 3D case's nodal field at reference points (mm).

    Parameters
    ----------
    spec : grasprom.fe.model3d.CaseSpec3D
        The case whose mesh carries the field (its coarsened far zone included).

    Notes
    -----
    Each point is located in its ``(r, theta, z)`` cell (then in the neighbouring layer if the
    trilinear element's chord face puts it there), its local coordinates come from Newton on the
    trilinear map, and the 27 quadratic basis functions are evaluated there.  Nodes tied at a
    zone interface are expanded from the solver nodes (``Disc3D.output_mesh``), so the matrix
    acts on the solver's nodal values.
    """

    def __init__(self, spec) -> None:
        import skfem

        self._disc = build_disc(spec)
        X, _, cells = self._disc.output_mesh(np.zeros(self._disc.ndof))
        self._X, self._cells = X, cells
        self._expand = self._disc.out_expand
        self._e1, self._e2 = skfem.ElementHex1(), skfem.ElementHex2()
        self._centres = X[cells[:, :8]].mean(axis=1)  # of every element's vertices
        r, th = ring_nodes(0.5 * spec.diameter_mm, spec.thickness_mm, spec.mesh)
        z = axial_grid(spec)
        k = spec.mesh.far_coarsening
        n_fine = spec.mesh.n_jaw if k > 1 else len(z) - 1
        self._zones = [self._zone(r, th, z[: n_fine + 1])]
        if k > 1:
            self._zones.append(self._zone(r[::k], th[::k], z[n_fine:]))
        self._z_if = z[n_fine]

    @property
    def n_nodes(self) -> int:
        """Number of solver nodes (columns of :meth:`matrix`)."""
        return self._disc.ndof // 3

    def _zone(self, r, th, z) -> _Zone:
        """The elements of a tensor zone, keyed by their cell indices."""
        cen = self._centres
        rho, ang = np.hypot(cen[:, 0], cen[:, 1]), np.arctan2(cen[:, 1], cen[:, 0])
        inside = (cen[:, 2] > z[0]) & (cen[:, 2] < z[-1])
        cell = -np.ones((len(r) - 1, len(th) - 1, len(z) - 1), dtype=np.int64)
        ir = np.searchsorted(r, rho[inside]) - 1
        it = np.searchsorted(th, ang[inside]) - 1
        iz = np.searchsorted(z, cen[inside, 2]) - 1
        cell[ir, it, iz] = np.flatnonzero(inside)
        return _Zone(r, th, z, cell)

    def _candidates(self, pts: np.ndarray) -> np.ndarray:
        """Three candidate elements per point (its polar cell and the layers either side)."""
        rho, ang = np.hypot(pts[:, 0], pts[:, 1]), np.arctan2(pts[:, 1], pts[:, 0])
        out = np.empty((3, len(pts)), dtype=np.int64)
        far = pts[:, 2] > self._z_if if len(self._zones) > 1 else np.zeros(len(pts), bool)
        for zone, sel in zip(self._zones, (~far, far), strict=False):

            def idx(grid, v):
                return np.clip(np.searchsorted(grid, v) - 1, 0, len(grid) - 2)

            ir = idx(zone.r, rho[sel])
            it, iz = idx(zone.th, ang[sel]), idx(zone.z, pts[sel, 2])
            for j, d in enumerate((0, -1, 1)):
                out[j, sel] = zone.cell[np.clip(ir + d, 0, len(zone.r) - 2), it, iz]
        return out

    def _local(self, pts: np.ndarray, elems: np.ndarray) -> np.ndarray:
        """Local coordinates ``(3, n)`` of ``pts`` in the trilinear elements ``elems``."""
        V = self._X[self._cells[elems, :8]]  # (n, 8, 3)
        xi = np.full((3, len(pts)), 0.5)
        for _ in range(INVERSE_ITERATIONS):
            N, dN = _lagrange_basis(self._e1, xi)
            x = np.einsum("an,nai->ni", N, V)
            J = np.einsum("ajn,nai->nij", dN, V)
            xi = xi - np.linalg.solve(J, (x - pts)[..., None])[..., 0].T
        return xi

    def matrix(self, points: np.ndarray) -> sp.csr_matrix:
        """Interpolation matrix ``(n_points, n_nodes)``: nodal values -> values at ``points``.

        Parameters
        ----------
        points : ndarray, shape (n, 3)
            Reference positions (mm) in or next to the tube.

        Returns
        -------
        scipy.sparse.csr_matrix

        Raises
        ------
        ValueError
            A point lies farther outside the tube than :data:`MAX_EXTRAPOLATION` of an element's
            local extent.
        """
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        cand = self._candidates(pts)
        best_xi, best_el = None, None
        best_v = np.full(len(pts), np.inf)
        for elems in cand:
            xi = self._local(pts, elems)
            v = np.maximum(xi - 1.0, -xi).max(axis=0)
            take = v < best_v
            best_v = np.where(take, v, best_v)
            best_xi = xi if best_xi is None else np.where(take, xi, best_xi)
            best_el = elems if best_el is None else np.where(take, elems, best_el)
        if np.any(best_v > MAX_EXTRAPOLATION):
            k = int(np.argmax(best_v))
            raise ValueError(
                f"point {pts[k].round(4).tolist()} (mm) lies outside the tube's mesh "
                f"({best_v[k]:.2f} of an element's extent)"
            )
        N, _ = _lagrange_basis(self._e2, best_xi)
        rows = np.repeat(np.arange(len(pts)), N.shape[0])
        P = sp.csr_matrix(
            (N.T.ravel(), (rows, self._cells[best_el].ravel())), shape=(len(pts), len(self._X))
        )
        return P if self._expand is None else (P @ self._expand).tocsr()


def transfer_matrix(spec_from, spec_to) -> sp.csr_matrix:
    """The interpolation of one mesh's nodal field at the nodes of another mesh of the tube.

    Parameters
    ----------
    spec_from, spec_to : grasprom.fe.model3d.CaseSpec3D
        The cases of the source and the target mesh: the same tube (diameter, wall thickness,
        tube length), any cross-section, axial grid or far-zone coarsening.

    Returns
    -------
    scipy.sparse.csr_matrix
        ``(n_nodes_to, n_nodes_from)``: ``P @ u.reshape(-1, 3)`` are the target's nodal
        displacements (mm) of the source's ``u`` (mm); build it once to move many states.

    Raises
    ------
    ValueError
        The two cases describe different tubes, or a target node lies outside the source mesh.
    """
    for name in ("diameter_mm", "thickness_mm", "tube_length_mm"):
        a, b = getattr(spec_from, name), getattr(spec_to, name)
        if not np.isclose(a, b, rtol=1e-12, atol=0.0):
            raise ValueError(f"different tubes: {name} {a} (from) vs {b} (to)")
    return FieldProbe(spec_from).matrix(build_disc(spec_to).X)


def transfer_displacement(spec_from, u_from: np.ndarray, spec_to) -> np.ndarray:
    """A 3D displacement field (mm) of one mesh interpolated at the nodes of another.

    Parameters
    ----------
    spec_from, spec_to : grasprom.fe.model3d.CaseSpec3D
        The cases of the source and the target mesh: the same tube (diameter, wall thickness,
        tube length), any cross-section, axial grid or far-zone coarsening.
    u_from : ndarray
        Nodal displacements (mm) on ``spec_from``'s mesh, ``3 n_nodes``.

    Returns
    -------
    ndarray
        Nodal displacements (mm) on ``spec_to``'s mesh, ``3 n_nodes``.

    Raises
    ------
    ValueError
        The two cases describe different tubes, or ``u_from`` has the wrong length.
    """
    P = transfer_matrix(spec_from, spec_to)
    u = np.asarray(u_from, dtype=float)
    if u.shape != (3 * P.shape[1],):
        raise ValueError(f"u_from has {u.size} values; the source mesh has {3 * P.shape[1]}")
    return np.asarray(P @ u.reshape(-1, 3)).ravel()
