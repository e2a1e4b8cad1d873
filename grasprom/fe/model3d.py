"""3D FE model of a tube (colon wall) clamped between two rigid flat jaws of finite length.

Model (issue #18; Guachi et al.'s "CS" cylinder with finite jaws):

* tube of outer diameter ``D``, wall ``t``, length ``L``; 1/8 symmetry: ``u_x = 0`` on ``x = 0``,
  ``u_y = 0`` on ``y = 0`` (the jaws move along ``y``), ``u_z = 0`` on the jaw mid-plane
  ``z = 0``; the free end ``z = L/2`` is either ``"free"`` or ``"seed"`` (``u_x = u_y = 0``,
  axial translation free: Guachi et al.'s edge condition; rotations are not dofs of a solid);
* a rigid jaw of length ``jaw_length_mm``: flat (``y = h``) for ``|z| <= jaw_length/2 - r``,
  rounded off with the edge radius ``r`` beyond, so its edge does not cut the mesh;
* contact of the outer-wall nodes with the jaw, exact primal active set: ``"stick"`` (default,
  Guachi et al.'s "no sliding at the interface": a touching node is tied to the jaw at its touch
  point, all three components prescribed, released when its normal reaction turns tensile),
  ``"frictionless"`` (the node's normal displacement is prescribed, the tangential one free; on
  the rounded edge in a rotated frame with the node projected back onto the arc,
  :class:`SlidingFrame`) or ``"coulomb"`` (frictionless plus a regularised Coulomb potential,
  :class:`CoulombFriction`);
* self-contact of the inner walls = contact of the inner wall with the plane ``y = 0``; the two
  walls are mirror images, so mirror points never slip relative to each other and this contact
  is exact for any friction law;
* Q2 hexahedra (27 nodes) with a discontinuous P1 dilatation/pressure condensed per element
  (three-field Hu-Washizu, as model2d's P2B/P1 in 2D); the same materials as the 2D model;
* Newton-Raphson on the potential energy with an energy line search and adaptive stepping
  (the 2D model's step control, :class:`grasprom.fe.model2d.SolverSettings`).

Forces: ``force_N`` is the total force on one jaw: the 1/8 model's jaw reaction times 4 (two
halves in ``x``, two in ``z``; the ``y`` symmetry separates the two jaws).  Lengths in mm,
forces in N, stresses in MPa.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import pandas as pd
import scipy.sparse as sp

from grasprom.fe.crease import (
    SNAP_FORCE_DROP,
    SNAP_RELEASE_FRACTION,
    CreaseOnset,
    Unloading,
    crease_onset,
    hermite_energy,
    is_snap,
    splice_crease,
    unload_band,
)
from grasprom.fe.hyperelastic3d import invariants as _invariants
from grasprom.fe.hyperelastic3d import pointwise3d, stress_and_tangent
from grasprom.fe.linsolve import FactorReuse, make_solver, shifted_descent, solver_name
from grasprom.fe.materials import Material, get_material
from grasprom.fe.mesh3d import Disc3D, MeshSpec3D, axial_nodes, discretise3d
from grasprom.fe.model2d import (
    COLUMN_DESCRIPTIONS,
    COLUMNS,
    CaseResult,
    SolverSettings,
    check_friction,
)
from grasprom.fe.stepping import land_on

ENDS = ("free", "seed")
CONTACTS = ("stick", "frictionless", "coulomb")

FRICTION_EPS_MM = 1e-3
"""Stick regularisation of ``contact="coulomb"`` (mm): a node in contact creeps by up to about
this before its friction force reaches ``mu N`` (as the 2D model's
:data:`grasprom.fe.model2d.FRICTION_EPS_MM`)."""

#: extra 3D columns appended after the 2D :data:`COLUMNS`
EXTRA_COLUMNS_3D = (
    "contact_area_mm2",
    "contact_length_mm",
    "tangential_share",
    "strain_energy_mJ",
)
COLUMNS_3D = (*COLUMNS, *EXTRA_COLUMNS_3D)
COLUMN_DESCRIPTIONS_3D = {
    **COLUMN_DESCRIPTIONS,
    "force_N": "N, total clamping force on one jaw (4 x the 1/8 model's jaw reaction)",
    "force_per_length_N_per_mm": "N/mm, force_N / jaw_length_mm",
    "contact_width_mm": "mm, width of the jaw contact across the tube at the jaw mid-plane",
    "mean_pressure_MPa": "MPa, force_N / contact_area_mm2",
    "inner_contact_width_mm": "mm, width over which the inner walls touch at the mid-plane",
    "contact_area_mm2": "mm^2, jaw contact area (reference area of the nodes in contact)",
    "contact_length_mm": "mm, axial length of the jaw contact (full, both halves)",
    "tangential_share": "1, sum of tangential / sum of normal nodal jaw reactions",
    "strain_energy_mJ": "mJ, strain energy of the whole tube (8 x the 1/8 model's, N mm); = "
    "the jaws' work, the integral of force_N over the gap closed, along a smooth branch",
}


def _default_solver() -> SolverSettings:
    return SolverSettings(dh_initial_mm=0.1, dh_max_mm=1.0, rtol=1e-8)


@dataclass(frozen=True)
class CaseSpec3D:
    """One 3D clamping case (mm, N, MPa).

    Parameters
    ----------
    material, thickness_mm, diameter_mm, jaw_length_mm, closed_gap_mm, force_cap_N, nu
        As :class:`grasprom.fe.model2d.CaseSpec`; ``jaw_length_mm`` is the jaw's extent along
        the tube axis.
    tube_length_mm : float
        Length of the modelled tube (mm); half of it is meshed.  Default 240 mm (8 D) with
        free ends: the colon continues beyond the jaws, and the ovalisation (n = 2) mode decays
        over ``1/beta_2 = [48 (1 - nu^2) R^6 / (144 t^2)]^(1/4)`` = 32 mm (t = 1.4) to 44 mm
        (t = 0.8) from the jaw.  Measured (t = 1.4, mr, stick): L = 120 -> 240 mm raises the
        force by 5.1, 4.4, 1.4, 0.4 % at gaps 20, 10, 5, 2.9 mm; at L = 240 free and seed ends
        agree within 0.15 % (the end condition no longer matters), see bench_fe3d ``length``.
    ends : str
        ``"free"`` (default) or ``"seed"`` (``u_x = u_y = 0`` at ``z = L/2``, Guachi et al.'s edge
        condition; it clamps the ovalisation at the end, so the force depends on ``L``).
    contact : str
        ``"stick"`` (default, Guachi et al.'s no sliding), ``"frictionless"`` or ``"coulomb"``
        (stuck until the tangential reaction reaches ``friction`` times the normal one, then
        sliding against it; regularised as the 2D model's, :data:`FRICTION_EPS_MM`).
    friction : float
        Coulomb coefficient (-), only with ``contact="coulomb"`` (> 0 there, 0 otherwise).
    jaw_edge_radius_mm : float
        Radius (mm) rounding off the jaw's edges at ``|z| = jaw_length/2``.
    plane_strain : bool
        Hold ``u_z = 0`` everywhere (verification against the 2D model; needs a jaw at least
        as long as the tube).
    mesh : MeshSpec3D
    solver : SolverSettings
    """

    material: str
    thickness_mm: float
    diameter_mm: float = 30.0
    jaw_length_mm: float = 10.0
    closed_gap_mm: float = 1.5
    force_cap_N: float = 200.0
    tube_length_mm: float = 240.0
    ends: str = "free"
    contact: str = "stick"
    friction: float = 0.0
    jaw_edge_radius_mm: float = 1.0
    plane_strain: bool = False
    mesh: MeshSpec3D = field(default_factory=MeshSpec3D)
    solver: SolverSettings = field(default_factory=_default_solver)
    nu: float | None = None

    def make_material(self) -> Material:
        """The material object of this case."""
        kw = {} if self.nu is None else {"nu": self.nu}
        return get_material(self.material, **kw)

    @property
    def flat_half_length_mm(self) -> float:
        """Half length (mm) of the flat part of the jaw face."""
        return 0.5 * self.jaw_length_mm - self.jaw_edge_radius_mm


def axial_grid(spec: CaseSpec3D) -> np.ndarray:
    """Axial node positions (mm) of the case's half tube, refined over the jaw and its edge."""
    half = 0.5 * spec.tube_length_mm
    z_fine = min(half, 0.5 * spec.jaw_length_mm + spec.mesh.fine_margin_mm)
    return axial_nodes(half, z_fine, spec.mesh.n_jaw, spec.mesh.n_free)


def build_disc(spec: CaseSpec3D) -> Disc3D:
    """Discretisation of the case's 1/8 tube (axial mesh refined over the jaw; with
    ``mesh.far_coarsening > 1`` the cross-section is coarsened beyond the fine zone)."""
    return discretise3d(
        0.5 * spec.diameter_mm,
        spec.thickness_mm,
        axial_grid(spec),
        spec.mesh,
        n_fine=spec.mesh.n_jaw,
    )


# ----------------------------------------------------------------------------------------------
# vectorised element kernels
# ----------------------------------------------------------------------------------------------


def kinematics(disc: Disc3D, u: np.ndarray) -> np.ndarray:
    """Deformation gradients ``F[e, q, i, j]`` at the quadrature points."""
    ne, nq, nloc, _ = disc.grads.shape
    ue = u[disc.edofs].reshape(ne, 1, nloc, 3).transpose(0, 1, 3, 2)
    F = np.matmul(ue, disc.grads)
    F[..., 0, 0] += 1.0
    F[..., 1, 1] += 1.0
    F[..., 2, 2] += 1.0
    return F


def _project(disc: Disc3D, q: np.ndarray) -> np.ndarray:
    """Element-wise L2 projection of a point field ``q[e, q]`` on the pressure space."""
    c = np.einsum("ekl,eql,eq->ek", disc.Minv, disc.wpsi, q)
    return np.einsum("eqk,ek->eq", disc.psi, c)


def energy(disc: Disc3D, material: Material, u: np.ndarray) -> float:
    """Strain energy (N mm) of the 1/8 model; ``inf`` if an element is inverted."""
    F = kinematics(disc, u)
    I1, I2, J, _, _ = _invariants(F)
    if not np.all(J > 0):
        return np.inf
    theta = _project(disc, J)
    if not np.all(theta > 0):
        return np.inf
    beta = disc.beta
    W = pointwise3d(material, I1, I2, J)[0] + (1.0 - beta) * material.volumetric(theta)[0]
    if beta > 0:
        W = W + beta * material.volumetric(J)[0]
    return float((disc.dx * W).sum())


#: Elements per block of the tangent assembly: the intermediate arrays of a block (about
#: 0.2 MB an element) stay in cache; the element matrices come out 3x faster than in one
#: pass over all elements, the whole assembly 1.4-1.7x (``python benchmarks/bench_fe3d.py
#: assembly``).
ASSEMBLY_BLOCK = 16


def _element_stiffness(G, Gt, A: np.ndarray, dx: np.ndarray, out=None) -> np.ndarray:
    """``K[e, b, i, k, a] = sum_q G[a, j] A[i, j, k, l] G[b, l] dx`` (N/mm): the element
    tangent ``K[e, (a i), (b k)]`` in the order of ``disc.scatter_t``, shape (ne, 27, 9 * 27).

    ``G`` is ``disc.grads`` and ``Gt`` ``disc.grads_t`` of the same elements.  Two batched
    products: ``T[e, q, (l i k), a]`` over ``j``, then ``K = G_t[e, b, (q l)] T[e, (q l), (i k
    a)]``; called on blocks of :data:`ASSEMBLY_BLOCK` elements so that ``T`` stays in cache.
    """
    ne, nq, nloc, _ = G.shape
    Adx = A * dx[..., None, None, None, None]
    At = Adx.transpose(0, 1, 5, 2, 4, 3).reshape(ne, nq, 27, 3)  # [(l i k), j]
    T = np.matmul(At, G.transpose(0, 1, 3, 2)).reshape(ne, nq * 3, 9 * nloc)
    return np.matmul(Gt, T, out=out)


def _element_forces(G: np.ndarray, P: np.ndarray, dx: np.ndarray) -> np.ndarray:
    """Element nodal forces ``f[e, a, i] = sum_q P[i, j] G[a, j] dx`` (N) of the gradients
    ``G = disc.grads`` and the stress ``P`` (MPa) of the same elements."""
    return (np.matmul(G, P.transpose(0, 1, 3, 2)) * dx[..., None, None]).sum(axis=1)


def _volumetric_stiffness(disc: Disc3D, e: slice, H: np.ndarray, ddU: np.ndarray) -> np.ndarray:
    """Tangent of the projected volumetric energy, ``[e, (a i), (b k)]`` (N/mm), elements ``e``."""
    G = disc.grads[e]
    ne, nq, nloc, _ = G.shape
    gq = np.matmul(G, H.transpose(0, 1, 3, 2)).reshape(ne, nq, 3 * nloc)  # d det F / du
    wpsi = disc.wpsi[e]
    Gm = np.matmul(wpsi.transpose(0, 2, 1), gq)
    D = np.einsum("eqk,eql,eq->ekl", wpsi, disc.psi[e], ddU)
    MG = np.matmul(disc.Minv[e], Gm)
    return np.matmul(MG.transpose(0, 2, 1), np.matmul(D, MG))


def assemble(disc: Disc3D, material: Material, u: np.ndarray, tangent: bool = True, block: int = 0):
    """Internal force (N), optionally the CSR tangent (N/mm), and min det F.

    Returns ``(None, None, minJ)`` if an element is inverted.  The tangent is built in blocks
    of ``block`` elements (default :data:`ASSEMBLY_BLOCK`; the block size changes round-off
    only, and memory traffic).
    """
    F = kinematics(disc, u)
    J = np.linalg.det(F)
    minJ = float(J.min())
    if minJ <= 0:
        return None, None, minJ
    theta = _project(disc, J)
    if not np.all(theta > 0):
        return None, None, minJ
    beta = disc.beta
    _, dU, ddU = material.volumetric(theta)
    p = (1.0 - beta) * _project(disc, dU)
    ddU = (1.0 - beta) * ddU
    k_pt = None
    if beta > 0:
        _, dUj, ddUj = material.volumetric(J)
        p = p + beta * dUj
        k_pt = beta * ddUj
    G = disc.grads
    ne, nq, nloc, _ = G.shape
    if not tangent:
        P = stress_and_tangent(material, F, p, False)[0]
        fe = _element_forces(G, P, disc.dx)
        return np.bincount(disc.edofs.ravel(), weights=fe.ravel(), minlength=disc.ndof), None, minJ
    fe = np.empty((ne, nloc, 3))
    Ke = np.empty((ne, nloc, 9 * nloc))
    block = block or ASSEMBLY_BLOCK
    for s in range(0, ne, block):
        e = slice(s, min(s + block, ne))
        kb = None if k_pt is None else k_pt[e]
        P, A, _, H = stress_and_tangent(material, F[e], p[e], True, kb)
        fe[e] = _element_forces(G[e], P, disc.dx[e])
        Kb = _element_stiffness(G[e], disc.grads_t[e], A, disc.dx[e], out=Ke[e])
        Kp = _volumetric_stiffness(disc, e, H, ddU[e])
        Kb.reshape(-1, nloc, 3, 3, nloc)[...] += Kp.reshape(-1, nloc, 3, nloc, 3).transpose(
            0, 3, 2, 4, 1
        )
    f = np.bincount(disc.edofs.ravel(), weights=fe.ravel(), minlength=disc.ndof)
    data = np.bincount(disc.scatter_t, weights=Ke.ravel(), minlength=disc.rows.size)
    K = sp.csr_matrix((data, disc.indices, disc.indptr), shape=(disc.ndof, disc.ndof))
    return f, K, minJ


# ----------------------------------------------------------------------------------------------
# jaw geometry and contact constraints
# ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class JawProfile:
    """Jaw face in the ``(y, z)`` plane: flat ``y = h`` for ``z <= a``, arc of radius ``r``.

    Parameters
    ----------
    a : float
        Half length (mm) of the flat part.
    r : float
        Edge radius (mm); the jaw ends at ``z = a + r``.
    """

    a: float
    r: float

    def project(self, y: np.ndarray, z: np.ndarray, h: float):
        """Gap (mm, < 0 penetrating), closest point ``(yp, zp)`` and outward normal ``(ny, nz)``.

        The normal points from the jaw into the tissue; nodes beyond the jaw get ``gap = inf``.
        """
        gap = np.full(z.shape, np.inf)
        yp = np.full(z.shape, float(h))
        zp = z.astype(float).copy()
        ny = -np.ones(z.shape)
        nz = np.zeros(z.shape)
        flat = z <= self.a
        gap[flat] = h - y[flat]
        if self.r > 0:
            dy = y - (h + self.r)
            dz = z - self.a
            arc = (~flat) & (dz < self.r) & (dy <= 0)
            dist = np.hypot(dy[arc], dz[arc])
            gap[arc] = dist - self.r
            ny[arc] = dy[arc] / dist
            nz[arc] = dz[arc] / dist
            yp[arc] = h + self.r + self.r * ny[arc]
            zp[arc] = self.a + self.r * nz[arc]
        return gap, yp, zp, ny, nz

    def normal_at(self, z: np.ndarray):
        """Outward normal ``(ny, nz)`` of the jaw face at axial position ``z`` on the face."""
        s = np.clip((z - self.a) / self.r, 0.0, 1.0) if self.r > 0 else np.zeros(z.shape)
        nz = np.where(z > self.a, s, 0.0)
        return -np.sqrt(1.0 - nz * nz), nz


@dataclass
class _Contact:
    """Contact state: active jaw nodes (over ``disc.outer_nodes``), stick anchors, floor;
    ``normal``: with Coulomb contact (None otherwise), the jaw's normal reaction (N) at each
    outer node in the last solution (the lagged normal force of the friction); ``h``: the jaw
    height (mm) of the state it belongs to (NaN if none: anchors then at the projection)."""

    jaw_active: np.ndarray
    anchor: np.ndarray  # (n_outer, 3): x, y - h, z of the stick point / friction anchor
    floor_active: np.ndarray
    normal: np.ndarray | None = None
    h: float = np.nan

    def copy(self) -> _Contact:
        normal = None if self.normal is None else self.normal.copy()
        return _Contact(
            self.jaw_active.copy(), self.anchor.copy(), self.floor_active.copy(), normal, self.h
        )


#: The tangent predictor of an active-set pass solves with the factor of the last Newton
#: iteration instead of factoring its own tangent, where that factor belongs to the tangent the
#: predictor starts from (the state Newton converged to, one iteration on) and to the same
#: constraints: the first pass of a step whose contact set is the last step's.  Newton corrects
#: the difference; the converged states are the same to ``SolverSettings.rtol``.
#: ``python benchmarks/bench_fe3d.py reuse`` runs both (bending on 4 x 36: 1.18 x).  Off by
#: default: in the crease band the older factor's predictor can lead Newton to another state
#: (plane strain, 4 x 24 graded: +4.9 % at gap 5 mm against the 2D model, +0.1 % without).
PREDICTOR_REUSES_FACTOR = False


@dataclass
class _FactorMemo:
    """What the solver's last factorisation is (internal): the constrained Newton tangent of
    the state before the one :func:`_newton` returned with ``K`` (identity), with the fixed
    dofs ``mask``; valid while the solver's factorisation count is still ``count``."""

    K: object = None
    mask: np.ndarray | None = None
    count: int = -1

    def record(self, solver, K, mask: np.ndarray) -> None:
        self.K, self.mask, self.count = K, mask, getattr(solver, "factorizations", -2)

    def fits(self, solver, K, mask: np.ndarray) -> bool:
        """Whether ``solver``'s last factor serves the predictor of ``K`` with ``mask``."""
        return (
            PREDICTOR_REUSES_FACTOR
            and self.K is K
            and getattr(solver, "factorizations", -3) == self.count
            and np.array_equal(mask, self.mask)
        )


@dataclass(frozen=True)
class _Setup:
    """Everything fixed during a case (internal; ``factor`` is the solver's state)."""

    disc: Disc3D
    material: Material
    jaw: JawProfile
    stick: bool
    base_fixed: np.ndarray  # symmetry, ends, plane strain
    settings: SolverSettings
    fscale: float
    solver: Callable[[sp.spmatrix, np.ndarray], np.ndarray]  # linsolve.make_solver
    disc_thickness: float
    mu: float = np.inf  # Coulomb coefficient (finite: contact="coulomb")
    factor: _FactorMemo = field(default_factory=_FactorMemo)
    on_row: Callable | None = None  # run_case_3d's on_row


@dataclass(frozen=True)
class CoulombFriction:
    """Regularised Coulomb friction of the sliding jaw nodes during one pass.

    Each node in contact with a normal force ``N`` (lagged: the previous solve's) is held at
    its anchor ``a`` by ``c (sqrt(|d|^2 + e^2) - e)``, ``d = x - a`` (3-vector, mm), ``c = mu
    N``, ``e`` = :data:`FRICTION_EPS_MM`: stiff (``c / e``) about ``d = 0`` (stick), a force
    tending to ``c`` (sliding); smooth and convex, so Newton with the energy line search
    handles stick and slip without an active set, as the 2D model's friction.  On the flat face
    ``d`` is tangential (the node's normal position is prescribed); on the edge arc it is the
    chord, whose normal part is second order in the slide.

    Parameters
    ----------
    nodes : ndarray of int
        The nodes with friction.
    anchor : ndarray (n, 3)
        Their anchors, absolute positions (mm).
    c : ndarray (n,)
        ``mu N`` of each node (N).
    eps : float
        Stick regularisation (mm).
    """

    nodes: np.ndarray  # outer nodes with friction
    anchor: np.ndarray  # (n, 3) absolute anchor positions (mm)
    c: np.ndarray  # mu N (N)
    eps: float = FRICTION_EPS_MM

    @classmethod
    def of(cls, st: _Setup, c: _Contact, h: float) -> CoulombFriction | None:
        """The friction of the contact state ``c`` at jaw height ``h`` (None: no friction)."""
        if c.normal is None:  # not Coulomb contact
            return None
        sel = c.jaw_active & (c.normal > 0)
        if not np.any(sel):
            return None
        on = st.disc.outer_nodes[sel]
        anchor = c.anchor[sel] + np.array([0.0, h, 0.0])
        return cls(on, anchor, st.mu * c.normal[sel])

    def _slide(self, X, u):
        d = X[self.nodes] + u.reshape(-1, 3)[self.nodes] - self.anchor
        return d, np.sqrt((d * d).sum(axis=1) + self.eps**2)

    def energy(self, X, u) -> float:
        """Friction potential (N mm)."""
        _, r = self._slide(X, u)
        return float((self.c * (r - self.eps)).sum())

    def force(self, X, u) -> np.ndarray:
        """Its gradient (N) over all dofs."""
        d, r = self._slide(X, u)
        out = np.zeros(u.size)
        idx = 3 * self.nodes[:, None] + np.arange(3)
        out[idx] = (self.c / r)[:, None] * d
        return out

    def add_tangent(self, disc: Disc3D, K: sp.csr_matrix, u) -> sp.csr_matrix:
        """``K`` plus its Hessian (N/mm), ``c (I / r - d d^T / r^3)`` per node, on the
        discretisation's CSR pattern (a scipy sum would drop ``K``'s explicit zeros, and
        :func:`_constrained` relies on the pattern).  A node's 3 x 3 block sits in each of its
        rows at the diagonal's position + (j - i): the columns of one node are adjacent.
        """
        d, r = self._slide(disc.X, u)
        blk = (self.c / r)[:, None, None] * (
            np.eye(3) - d[:, :, None] * d[:, None, :] / (r * r)[:, None, None]
        )
        i = np.arange(3)
        pos = disc.diag_pos[3 * self.nodes[:, None, None] + i[:, None]] + (i[None, :] - i[:, None])
        data = K.data.copy()
        np.add.at(data, pos.ravel(), blk.ravel())
        return sp.csr_matrix((data, disc.indices, disc.indptr), shape=K.shape)


@dataclass(frozen=True)
class ProximalTerm:
    """Proximal-point term ``c/2 |u - u_ref|^2`` (N mm) of a relaxation step (:func:`_relax`).

    Parameters
    ----------
    c : float
        Its stiffness (N/mm), added to every diagonal entry of the tangent.
    u_ref : ndarray
        The displacements it pulls toward (mm).
    """

    c: float
    u_ref: np.ndarray

    def energy(self, X, u) -> float:
        """``c/2 |u - u_ref|^2`` (N mm)."""
        d = u - self.u_ref
        return 0.5 * self.c * float(d @ d)

    def force(self, X, u) -> np.ndarray:
        """Its gradient (N)."""
        return self.c * (u - self.u_ref)

    def add_tangent(self, disc: Disc3D, K: sp.csr_matrix, u) -> sp.csr_matrix:
        """``K + c I`` on the discretisation's CSR pattern."""
        data = K.data.copy()
        data[disc.diag_pos] += self.c
        return sp.csr_matrix((data, disc.indices, disc.indptr), shape=K.shape)


@dataclass(frozen=True)
class _Potentials:
    """Sum of extra potentials (friction, proximal) with the interface of each."""

    parts: tuple

    @staticmethod
    def of(*parts):
        """The sum of the parts that are not None (None if there are none)."""
        kept = tuple(p for p in parts if p is not None)
        if not kept:
            return None
        return kept[0] if len(kept) == 1 else _Potentials(kept)

    def energy(self, X, u) -> float:
        return sum(p.energy(X, u) for p in self.parts)

    def force(self, X, u) -> np.ndarray:
        return sum(p.force(X, u) for p in self.parts)

    def add_tangent(self, disc: Disc3D, K: sp.csr_matrix, u) -> sp.csr_matrix:
        for p in self.parts:
            K = p.add_tangent(disc, K, u)
        return K


def _assemble_x(st: _Setup, u, fric, tangent: bool = True):
    """Internal force plus the extra potential's force (N) and tangent (N/mm); ``(None, None)``
    if inverted.  ``fric``: :class:`CoulombFriction`, :class:`ProximalTerm`, their sum or None."""
    f, K, _ = assemble(st.disc, st.material, u, tangent)
    if f is None or fric is None:
        return f, K
    f = f + fric.force(st.disc.X, u)
    if K is not None:
        K = fric.add_tangent(st.disc, K, u)
    return f, K


def _energy_x(st: _Setup, u, fric) -> float:
    """Strain energy plus the extra potential (N mm; ``fric`` as in :func:`_assemble_x`)."""
    e = energy(st.disc, st.material, u)
    return e if fric is None or not np.isfinite(e) else e + fric.energy(st.disc.X, u)


def _base_fixed(disc: Disc3D, ends: str, plane_strain: bool) -> np.ndarray:
    fixed = np.zeros(disc.ndof, dtype=bool)
    fixed[3 * np.flatnonzero(disc.on_x0)] = True
    fixed[3 * np.flatnonzero(disc.on_y0) + 1] = True
    fixed[3 * np.flatnonzero(disc.on_z0) + 2] = True
    if ends == "seed":
        end = np.flatnonzero(disc.on_end)
        fixed[3 * end] = True
        fixed[3 * end + 1] = True
    if plane_strain:
        fixed[2::3] = True
    return fixed


def _targets(st: _Setup, c: _Contact, h: float, u: np.ndarray):
    """Dirichlet set and values (stick, floor, symmetry) and the frictionless jaw nodes."""
    d = st.disc
    fixed = st.base_fixed.copy()
    values = np.where(fixed, 0.0, u)
    jn = d.outer_nodes[c.jaw_active]
    fr = np.zeros(0, dtype=np.int64)
    if st.stick:
        anc = c.anchor[c.jaw_active]
        for i in range(3):
            fixed[3 * jn + i] = True
        values[3 * jn] = anc[:, 0] - d.X[jn, 0]
        values[3 * jn + 1] = h + anc[:, 1] - d.X[jn, 1]
        values[3 * jn + 2] = anc[:, 2] - d.X[jn, 2]
    else:
        fr = jn
    fn = d.inner_nodes[c.floor_active]
    fixed[3 * fn + 1] = True
    values[3 * fn + 1] = -d.X[fn, 1]
    values[st.base_fixed] = 0.0
    return fixed, values, fr


def _enforce(st: _Setup, u, fixed, values, fr, h):
    """Displacements with the Dirichlet values set and frictionless nodes on the jaw face."""
    u = np.where(fixed, values, u)
    if fr.size:
        X = st.disc.X
        y = X[fr, 1] + u[3 * fr + 1]
        z = X[fr, 2] + u[3 * fr + 2]
        _, yp, zp, _, _ = st.jaw.project(y, z, h)
        u[3 * fr + 1] = yp - X[fr, 1]
        zfree = ~st.base_fixed[3 * fr + 2]
        u[3 * fr[zfree] + 2] = zp[zfree] - X[fr[zfree], 2]
    return u


@dataclass(frozen=True)
class SlidingFrame:
    """Newton frame of the frictionless (sliding) jaw nodes.

    Parameters
    ----------
    fixed : ndarray of bool (ndof,)
        Fixed dofs in the rotated frame.
    Q : scipy.sparse.csr_matrix or None
        Rotation from the frame to Cartesian dofs (``du = Q dv``); ``None`` if no node is on the
        rounded edge.
    tangential : ndarray of int
        The rotated tangential dofs of the edge nodes (the ``z`` slot of each node).
    normal : tuple of ndarray
        Their outward jaw normals ``(ny, nz)``.
    """

    fixed: np.ndarray
    Q: sp.csr_matrix | None = None
    tangential: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    normal: tuple = (np.zeros(0), np.zeros(0))

    @classmethod
    def on_jaw(cls, jaw: JawProfile, X, u, fixed, nodes, h: float, z_fixed=None):
        """Frame of the sliding ``nodes`` on the jaw at height ``h`` (mm).

        Nodes on the flat face have their ``y`` dof fixed; those on the rounded edge get their
        ``(y, z)`` dofs rotated into (normal, tangent), the normal one fixed.  ``z_fixed``
        (bool per node): nodes whose ``z`` is held by symmetry stay unrotated.
        """
        fx = fixed.copy()
        if nodes.size == 0:
            return cls(fx)
        _, _, _, ny, nz = jaw.project(
            X[nodes, 1] + u[3 * nodes + 1], X[nodes, 2] + u[3 * nodes + 2], h
        )
        fx[3 * nodes + 1] = True
        rot = nz != 0.0
        if z_fixed is not None:
            rot &= ~z_fixed
        if not np.any(rot):
            return cls(fx)
        nodes, ny, nz = nodes[rot], ny[rot], nz[rot]
        iy, iz = 3 * nodes + 1, 3 * nodes + 2
        n = fixed.size
        keep = np.ones(n, dtype=bool)
        keep[iy] = False
        keep[iz] = False
        idx = np.flatnonzero(keep)
        rows = np.concatenate([idx, iy, iy, iz, iz])
        cols = np.concatenate([idx, iy, iz, iy, iz])
        vals = np.concatenate([np.ones(idx.size), ny, -nz, nz, ny])
        Q = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
        return cls(fx, Q, iz, (ny, nz))

    def residual(self, f: np.ndarray) -> np.ndarray:
        """The internal force ``f`` (N) in the frame, zero on the fixed dofs."""
        r = f if self.Q is None else self.Q.T @ f
        return np.where(self.fixed, 0.0, r)

    def tangent(self, K: sp.csr_matrix, f: np.ndarray, radius: float) -> sp.csr_matrix:
        """The tangent ``K`` (N/mm) in the frame, with the edge's curvature term.

        A node sliding on the edge arc (radius ``r``, mm) under the normal reaction
        ``lam = f . n`` (N) loses ``lam / r`` of tangential stiffness: with ``x(s)`` on the arc,
        ``d2 Pi / ds2 = t.K.t + f.x''`` and ``x'' = -n / r``.  Without it Newton converges only
        linearly while nodes slide over the edge.
        """
        if self.Q is None:
            return K
        Kr = (self.Q.T @ K @ self.Q).tocsr()
        if radius <= 0:
            return Kr
        iz = self.tangential
        ny, nz = self.normal
        lam = f[iz - 1] * ny + f[iz] * nz
        n = K.shape[0]
        return (Kr - sp.csr_matrix((lam / radius, (iz, iz)), shape=(n, n))).tocsr()


def _frame(st: _Setup, u, fixed, fr, h) -> SlidingFrame:
    """Newton frame of the frictionless jaw nodes ``fr`` at the displacements ``u``."""
    z_fixed = st.base_fixed[3 * fr + 2]
    return SlidingFrame.on_jaw(st.jaw, st.disc.X, u, fixed, fr, h, z_fixed)


def _row_positions(indptr: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """CSR positions of all entries in ``rows``."""
    starts = indptr[rows]
    lens = indptr[rows + 1] - starts
    offsets = np.repeat(starts - np.cumsum(lens) + lens, lens)
    return offsets + np.arange(int(lens.sum()))


def _constrained(st: _Setup, K: sp.csr_matrix, fixed: np.ndarray, rotated: bool):
    """K with the rows/cols of ``fixed`` replaced by identity.

    Unrotated (``K`` on the discretisation's pattern): only the entries of the fixed rows and,
    through the symmetric pattern, of the fixed columns are touched, not a mask over all
    entries (4 x 36, 60 mm tube: 38 ms a call before).  The pattern is kept, stored zeros
    included, so the sparse solver's analysis is reused.
    """
    d = st.disc
    if not rotated:
        data = K.data.copy()
        pos = _row_positions(d.indptr, np.flatnonzero(fixed))
        data[pos] = 0.0
        data[d.transpose_pos[pos]] = 0.0
        data[d.diag_pos[fixed]] = 1.0
        Kc = sp.csr_matrix((data, d.indices, d.indptr), shape=K.shape)
        Kc.has_sorted_indices = True
        return Kc
    free = sp.diags((~fixed).astype(float))
    return (free @ K @ free + sp.diags(fixed.astype(float))).tocsr()


class _NewtonFailure(Exception):
    pass


def _line_search(st: _Setup, u, du, slope, rnorm, cons, h, amax: float = 1.0, fric=None):
    """Energy line search along ``du`` (projected on the constraints) from ``alpha = amax``.

    Returns the new displacements and the accepted step length.
    """
    fixed, values, fr = cons
    e0 = _energy_x(st, u, fric)
    alpha = amax
    for _ in range(12):
        ut = _enforce(st, u + alpha * du, fixed, values, fr, h)
        et = _energy_x(st, ut, fric)
        if np.isfinite(et):
            if et <= e0 + 1e-4 * alpha * slope:
                return ut, alpha
            if alpha == 1.0:
                ft, _ = _assemble_x(st, ut, fric, tangent=False)
                if np.linalg.norm(_frame(st, ut, fixed, fr, h).residual(ft)) < 0.5 * rnorm:
                    return ut, alpha
        alpha *= 0.5
    raise _NewtonFailure("line search failed")


def _penetration(st: _Setup, c: _Contact, u, h) -> float:
    """Largest penetration (mm) of an inactive outer node into the jaw or inner node below 0."""
    d = st.disc
    on = d.outer_nodes[~c.jaw_active]
    inn = d.inner_nodes[~c.floor_active]
    pen = 0.0
    if on.size:
        gap = st.jaw.project(d.X[on, 1] + u[3 * on + 1], d.X[on, 2] + u[3 * on + 2], h)[0]
        pen = max(pen, float(-gap.min()))
    if inn.size:
        pen = max(pen, float(-(d.X[inn, 1] + u[3 * inn + 1]).min()))
    return pen


def _feasible_alpha(st: _Setup, c: _Contact, u, du, cons, h) -> float:
    """Largest step length <= 1 that pushes no inactive node deeper than ``0.02 t``."""
    fixed, values, fr = cons
    tol = 0.02 * st.disc_thickness

    def pen(alpha):
        return _penetration(st, c, _enforce(st, u + alpha * du, fixed, values, fr, h), h)

    if pen(1.0) <= tol:
        return 1.0
    lo, hi = 0.0, 1.0
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if pen(mid) <= tol else (lo, mid)
    return hi


def _predicting(st: _Setup, h: float) -> bool:
    """Predicted contact at jaw height ``h`` (mm): the gap ``2 h`` is below
    ``SolverSettings.predict_contact_below_mm`` (or ``predict_contact_below_t`` times the wall
    thickness).  Where the inner walls meet on a fine mesh it
    ends the node-by-node crawl of the active set (mr, t = 1.4 mm, 4 x 36, 240 mm tube,
    switched on at gap 3.42 mm: to gap 2.70 mm in 907 s; off: at 3.13 mm after 1815 s).  On
    from the first step it takes another path through the crease (a snap: the uncut step is
    wild there) and, on the 240 mm tube, stalled in it (``python benchmarks/bench_fe3d.py
    wallsmeet``).  ``SolverSettings.predict_contact_below_t`` gives the gap in wall
    thicknesses; the larger gap counts."""
    s = st.settings
    return 2.0 * h < max(s.predict_contact_below_mm, s.predict_contact_below_t * st.disc_thickness)


#: relative residual to which Newton solves while the active set may still change; once it
#: has settled, Newton tightens to ``SolverSettings.rtol`` and the set is checked again.  1e-2
#: (was 1e-4): a pass that only decides which nodes to release or add needs one or two
#: iterations, not three.  4 x 36, 240 mm tube, mr t = 1.4 mm, stick: 604 instead of 866 Newton
#: iterations, 863 s instead of 1545 s (each beside another run), forces within 0.12 % of a
#: round-off sibling from gap 20 to 2.8 mm (``python benchmarks/bench_fe3d.py activeset``).
ACTIVE_SET_RTOL = 1e-2

#: A solve with an iteration budget (a back step of the crease placement, a plain attempt of
#: :func:`_relax`) fails as soon as its residual has risen this many iterations in a row,
#: instead of spending the rest of its budget.  The back steps that failed on 4 x 36 (240 mm
#: tube, mr 1.4 mm, stick) fell for two to four iterations and then rose at every one until
#: the budget ran out (e.g. 1.5e-4 -> 2.4e-4 N over 16); of the 157 back-step passes that
#: converged none rose more than three in a row (one cut at a contact event rose twelve, and
#: its step failed in the next pass).  Solves without a budget (the forward steps, where a
#: pass that ends at a contact event can rise eleven in a row) use
#: :data:`FORWARD_STALL_RISES`.
STALL_RISES = 6

#: A forward step's solve (no budget) fails once its residual has risen this many iterations
#: in a row, instead of running to ``SolverSettings.max_newton`` (the step is then cut, as
#: before).  Passes that converged rose at most eleven in a row (one ending at a contact
#: event); the two failed steps of 4 x 36 (240 mm tube, mr 1.4 mm, stick) spent 61 Newton
#: iterations and 111 factorisations of Levenberg shifts rising to the limit.
FORWARD_STALL_RISES = 15


def _newton(
    st: _Setup,
    u,
    cons,
    h,
    c: _Contact,
    rtol: float | None = None,
    fric=None,
    start=None,
    max_it: int | None = None,
    stall: int | None = None,
    unshifted: bool = False,
):
    """Newton-Raphson on the free dofs; returns ``(u, f, K, iterations, contact_event, probe)``.

    Converges to ``rtol`` (default ``SolverSettings.rtol``) times the force scale (N).  A step
    that would push inactive nodes deeper than ``0.02 t`` into the jaw or the floor is cut at
    the touch and the solve returns early (``contact_event``) for the active set.  ``fric``
    (:class:`CoulombFriction`) adds the friction potential; ``f`` returned is the internal force
    without it (at a node in contact: the jaw's reaction), ``K`` the tangent with it.
    ``start = (u0, f0, K0)``: an assembly without extra potential at ``u0``, reused if the
    constrained start is ``u0`` (the next active-set pass from the same displacements).
    ``probe``: after a contact event with predicted contact on (:func:`_predicting`), the
    displacements of the uncut step (for :func:`_update_active`); None otherwise.
    ``max_it``: at most this many iterations (default ``SolverSettings.max_newton``).
    ``stall``: fail once the residual has risen this many iterations in a row (default never).
    ``unshifted``: fail at the first direction that needs a Levenberg shift (:func:`_direction`).
    """
    fixed, values, fr = cons
    u = _enforce(st, u, fixed, values, fr, h)
    if start is not None and fric is None and np.array_equal(u, start[0]):
        f, K = start[1], start[2]
    else:
        f, K = _assemble_x(st, u, fric)
    if f is None:
        raise _NewtonFailure("inverted element at start of Newton")
    tol = (st.settings.rtol if rtol is None else rtol) * st.fscale

    def internal(f, u):
        return f if fric is None else f - fric.force(st.disc.X, u)

    n_max = st.settings.max_newton if max_it is None else max_it
    rises, last = 0, np.inf
    for it in range(1, n_max + 2):  # n_max updates, each state checked
        fr_ = _frame(st, u, fixed, fr, h)
        r = fr_.residual(f)
        rnorm = np.linalg.norm(r)
        if rnorm <= tol:
            return u, internal(f, u), K, it - 1, False, None
        rises, last = (rises + 1 if rnorm > last else 0), rnorm
        if it > n_max:
            break
        if stall is not None and rises >= stall:
            raise _NewtonFailure(f"residual rose {rises} iterations in a row")
        Kr = fr_.tangent(K, f, st.jaw.r)
        Kc = _constrained(st, Kr, fr_.fixed, fr_.Q is not None)
        dv, one = _direction(st, Kc, r, unshifted)
        plain = fr_.Q is None and one
        dv[fr_.fixed] = 0.0
        du = dv if fr_.Q is None else fr_.Q @ dv
        amax = _feasible_alpha(st, c, u, du, cons, h)
        event = amax < 1.0
        ut = _enforce(st, u + amax * du, fixed, values, fr, h) if event else None
        if ut is None or not np.isfinite(energy(st.disc, st.material, ut)):
            ut, alpha = _line_search(st, u, du, r @ dv, rnorm, cons, h, amax, fric)
            event = event and alpha == amax
        predict = event and _predicting(st, h)
        probe = _enforce(st, u + du, fixed, values, fr, h) if predict else None
        u = ut
        f, K = _assemble_x(st, u, fric)
        if f is None:
            raise _NewtonFailure("inverted element")
        if plain and fric is None:  # the factor is of this K one iteration back
            st.factor.record(st.solver, K, fr_.fixed)
        if event:
            return u, internal(f, u), K, it, True, probe
    raise _NewtonFailure("Newton did not converge")


def _direction(st: _Setup, Kc, r, unshifted: bool):
    """The Newton direction of the constrained tangent ``Kc`` and residual ``r`` (N)
    (:func:`grasprom.fe.linsolve.shifted_descent`) and whether it came from ``Kc`` itself,
    without a Levenberg shift (the solver's last factor is then ``Kc``'s).  Raises
    :class:`_NewtonFailure` if there is none, or, with ``unshifted``, if it needed a shift
    (read off the shift, not the factorisation count, which a factorisation that raised does
    not advance)."""
    dv, shift = shifted_descent(st.solver, Kc, r)
    if dv is None:
        raise _NewtonFailure("no descent direction")
    if unshifted and shift != 0.0:
        raise _NewtonFailure("the tangent needs a Levenberg shift")
    return dv, shift == 0.0


def _predict(st: _Setup, u, K, fixed, jump):
    """Tangent predictor: the free dofs follow a prescribed jump to first order (with the
    last Newton factor where it fits, :data:`PREDICTOR_REUSES_FACTOR`)."""
    mask = fixed | (jump != 0.0)
    rhs = np.where(mask, 0.0, -(K @ jump))
    if st.factor.fits(st.solver, K, mask):
        du = st.solver.resolve(rhs)
    else:
        du = st.solver(_constrained(st, K, mask, False), rhs)
    if np.all(np.isfinite(du)):
        up = u + np.where(mask, 0.0, du) + jump
        if np.isfinite(energy(st.disc, st.material, up)):
            return up
    return u + jump  # near a limit point the linear predictor can invert elements


def _jaw_normals(st: _Setup, c: _Contact, u, h):
    """Outward jaw normals ``(ny, nz)`` at all outer nodes (stick: at the anchor)."""
    d = st.disc
    on = d.outer_nodes
    if st.stick:
        ny, nz = st.jaw.normal_at(c.anchor[:, 2])
        return ny, nz
    _, _, _, ny, nz = st.jaw.project(d.X[on, 1] + u[3 * on + 1], d.X[on, 2] + u[3 * on + 2], h)
    return ny, nz


def _jaw_reactions(st: _Setup, c: _Contact, u, f, h) -> np.ndarray:
    """Normal jaw reaction (N, > 0 pressing) at every outer node, from the internal force."""
    on = st.disc.outer_nodes
    ny, nz = _jaw_normals(st, c, u, h)
    return f[3 * on + 1] * ny + f[3 * on + 2] * nz


def _jaw_touch(st: _Setup, xyz, h, tol):
    """Outer nodes at positions ``xyz`` (mm) that penetrate the jaw at height ``h`` by more than
    ``tol`` (mm), and each outer node's stick anchor there (x, y - h, z of its jaw projection)."""
    on = st.disc.outer_nodes
    gap, yp, zp, _, _ = st.jaw.project(xyz[on, 1], xyz[on, 2], h)
    return gap < -tol, np.column_stack([xyz[on, 0], yp - h, zp])


#: Bisections of a node's path for the point where it touches the jaw (:func:`touch_points`):
#: 2^-40 of the step's travel.
TOUCH_BISECTIONS = 40


def touch_points(jaw: JawProfile, x0, x1, h0: float | np.ndarray, h1: float) -> np.ndarray:
    """Stick anchors where nodes first touch the jaw on their way through a step.

    Each node moves on the straight path ``x0 -> x1`` while the jaw moves from height ``h0`` to
    ``h1`` (both linear in a path parameter ``s`` in [0, 1]).  The touch point is where the
    node's jaw gap reaches zero, bisected :data:`TOUCH_BISECTIONS` times between the start
    (outside) and the end (penetrating); if the gap changes sign more than once along the path
    it is one of the crossings.  A node that touches during a step is stuck where it touched,
    not where the step's end state (which may have snapped through the jaw) puts its
    projection.  A node already touching at the start (released there, by this step's passes or
    the last step's, and back) keeps the projection of its end position, as where ``h0`` is NaN
    (the node's start does not count: this step already released it): anchored where it just
    pulled off, it would be released again and re-added without end (the 2D rule,
    :func:`grasprom.fe.model2d.touch_x`; 4 x 36, ``beta`` 0.2, 240 mm tube: "active set did not
    settle" three times at gap 15.06 mm without it).

    Parameters
    ----------
    jaw : JawProfile
        The jaw face (its shape depends on ``y - h`` and ``z`` only).
    x0, x1 : ndarray, shape (n, 3)
        Node positions (mm) at the start and the end of the step; ``x1`` penetrates the jaw.
    h0 : float or ndarray, shape (n,)
        Jaw height (mm) at the start, one for all nodes or one each (NaN: the projection rule).
    h1 : float
        Jaw height (mm) at the end.

    Returns
    -------
    ndarray, shape (n, 3)
        Anchors ``(x, y - h, z)`` (mm) of the touch points on the jaw face.
    """
    x0, x1 = np.asarray(x0, float), np.asarray(x1, float)
    h0 = np.broadcast_to(np.asarray(h0, float), (len(x0),))
    counts = np.isfinite(h0)
    h0 = np.where(counts, h0, h1)

    def at(s):
        p = x0 + s[:, None] * (x1 - x0)
        hh = h0 + s * (h1 - h0)
        gap, yp, zp, _, _ = jaw.project(p[:, 1] - hh, p[:, 2], 0.0)
        return gap, np.column_stack([p[:, 0], yp, zp])

    lo, hi = np.zeros(len(x0)), np.ones(len(x0))
    outside = counts & (at(lo)[0] > 0.0)
    for _ in range(TOUCH_BISECTIONS):
        mid = 0.5 * (lo + hi)
        out = at(mid)[0] > 0.0
        lo, hi = np.where(out, mid, lo), np.where(out, hi, mid)
    return at(np.where(outside, hi, 1.0))[1]


def _update_active(
    st: _Setup, c: _Contact, u, f, h, add_only: bool = False, probe=None, start=None, released=None
):
    """New contact state from a converged solution (release tensile, add penetrating).

    ``start``: positions (mm) of the step's start state, whose jaw height is ``c.h``; an added
    node is then stuck where its path from there touches the jaw (:func:`touch_points`), not at
    the projection of its penetrating position.  ``released``: bool over the outer nodes, jaw
    nodes the step's earlier passes released; such a node comes back at its projection (a
    touch anchor that did not hold would cycle).

    ``add_only``: the state is not in equilibrium (a cut Newton step); only add nodes.
    ``probe``: displacements (mm) of the uncut Newton step of such a state; nodes it would push
    into the jaw or the floor are added too (touching at the probe's projection), so a wall
    closing onto the floor over a wide strip enters the set in one pass, not node by node.
    """
    d = st.disc
    inn = d.inner_nodes
    lam = _jaw_reactions(st, c, u, f, h)
    tol = 1e-9 * max(1.0, h)
    new = c.copy()
    keep = np.ones_like(c.jaw_active) if add_only else lam >= 0.0
    keep_f = np.ones_like(c.floor_active) if add_only else f[3 * inn + 1] >= 0.0
    new.jaw_active &= keep
    new.floor_active &= keep_f
    for v in (u,) if probe is None else (u, probe):  # the probe adds what u did not
        xyz = d.X + v.reshape(-1, 3)
        jaw_hit, anchor = _jaw_touch(st, xyz, h, tol)
        added = jaw_hit & ~new.jaw_active & ~c.jaw_active
        new.jaw_active |= added
        if start is not None and np.isfinite(c.h) and np.any(added):
            nodes = d.outer_nodes[added]
            h0 = c.h if released is None else np.where(released[added], np.nan, c.h)
            anchor[added] = touch_points(st.jaw, start[nodes], xyz[nodes], h0, h)
        new.anchor[added] = anchor[added]
        new.floor_active |= ~c.floor_active & (xyz[inn, 1] < -tol)
    same = np.array_equal(new.jaw_active, c.jaw_active)
    return new, same and np.array_equal(new.floor_active, c.floor_active)


#: the lagged normal force of Coulomb friction has settled when no node's moved by more than
#: this share of the largest (as the 2D model)
FRICTION_NORMAL_RTOL = 1e-5


def _normal_forces(st: _Setup, c: _Contact, u, f, h) -> np.ndarray:
    """The jaw's normal reaction (N, >= 0) at each outer node in contact, 0 elsewhere."""
    return np.where(c.jaw_active, np.maximum(_jaw_reactions(st, c, u, f, h), 0.0), 0.0)


def _slide_anchors(st: _Setup, c: _Contact, u, h) -> np.ndarray:
    """Friction anchors for the next step: moved by the slide beyond the stick creep."""
    on = st.disc.outer_nodes
    x = st.disc.X[on] + u.reshape(-1, 3)[on] - np.array([0.0, h, 0.0])
    d = x - c.anchor
    n = np.linalg.norm(d, axis=1)
    scale = np.where(n > FRICTION_EPS_MM, FRICTION_EPS_MM / np.maximum(n, 1e-300), 1.0)
    out = c.anchor.copy()
    act = c.jaw_active
    out[act] = (x - d * scale[:, None])[act]
    return out


def _solve_step(
    st: _Setup,
    u,
    K_old,
    c: _Contact,
    h: float,
    prox: ProximalTerm | None = None,
    budget: int | None = None,
    unshifted: bool = False,
):
    """Equilibrium at jaw height ``h`` (mm) with the active-set loop (of the energy plus
    ``prox``, if given: a step of :func:`_relax`).  ``budget``: at most this many Newton
    iterations over all passes (raises :class:`_NewtonFailure` beyond, or once a pass's
    residual has risen :data:`STALL_RISES` iterations in a row; default: no limit but
    ``SolverSettings.max_newton`` per pass, and :data:`FORWARD_STALL_RISES` rises in a row
    without ``prox``).  ``unshifted``: fail at the first Newton direction that needs a
    Levenberg shift (:func:`_newton`; the plain attempts of :func:`_relax`).

    Inexact passes: while the active set changes, Newton stops at ``ACTIVE_SET_RTOL``; once a
    pass leaves the set unchanged, the same set is solved to ``SolverSettings.rtol`` and
    checked again, so the returned state is as exact as with full solves in every pass.
    Coulomb contact: the friction's normal force is that of the previous pass, and the step is
    re-solved until it settles (:data:`FRICTION_NORMAL_RTOL`); then the anchors follow the
    slide.
    """
    iters = 0
    loose = max(ACTIVE_SET_RTOL, st.settings.rtol)
    if budget is not None:  # a back step of the crease placement, a plain attempt of _relax
        stall = STALL_RISES
    elif prox is None:  # a forward step
        stall = FORWARD_STALL_RISES
    else:  # a proximal step of _relax: strongly convex, runs to max_newton
        stall = None
    exact = False
    coulomb = c.normal is not None  # Coulomb contact (:func:`_initial_contact`)
    last = None  # (u, f, K) of the last pass, to start the next one without reassembling
    start = st.disc.X + u.reshape(-1, 3)  # where nodes that touch during the step come from
    released = np.zeros_like(c.jaw_active)  # jaw nodes this step's passes released
    for _ in range(st.settings.max_active_set):
        fixed, values, fr = _targets(st, c, h, u)
        jump = _enforce(st, u, fixed, values, fr, h) - u
        if K_old is not None and np.any(jump != 0.0):
            u = _predict(st, u, K_old, fixed, jump)
        fric = _Potentials.of(CoulombFriction.of(st, c, h), prox)
        cons = (fixed, values, fr)
        left = None if budget is None else min(st.settings.max_newton, budget - iters)
        tol = None if exact else loose
        u, f, K, it, event, probe = _newton(
            st, u, cons, h, c, tol, fric, last, left, stall, unshifted
        )
        last = (u, f, K) if fric is None else None
        iters += it
        K_old = K
        new, settled = _update_active(st, c, u, f, h, event, probe, start, released)
        released |= c.jaw_active & ~new.jaw_active
        if coulomb and not event:
            lam = _normal_forces(st, c, u, f, h)
            scale = max(float(lam.max(initial=0.0)), 1e-12)
            moved = np.abs(lam - c.normal)[c.jaw_active].max(initial=0.0)
            new.normal = np.where(new.jaw_active, lam, 0.0)
            settled = settled and moved <= FRICTION_NORMAL_RTOL * scale
        if settled and not event:
            if exact:
                if coulomb:
                    new.anchor = _slide_anchors(st, new, u, h)
                new.h = h
                return u, f, K, new, iters
            exact = True
        c = new
    raise _NewtonFailure("active set did not settle")


# ----------------------------------------------------------------------------------------------
# measures and the case driver
# ----------------------------------------------------------------------------------------------


def contact_measures(st: _Setup, c: _Contact, u, f, h) -> dict:
    """Jaw force of the 1/8 model (N), contact extents (mm), pressures (MPa), shares."""
    d = st.disc
    act = c.jaw_active
    jn = d.outer_nodes[act]
    xyz = d.X + u.reshape(-1, 3)
    out = {"force_q": 0.0, "width": 0.0, "length": 0.0, "peak": 0.0, "area": 0.0}
    out.update({"share": 0.0, "inner_width": 0.0})
    if jn.size:
        ny, nz = _jaw_normals(st, c, u, h)
        # symmetry reactions (u_x on x = 0, u_z on z = 0) are not contact forces
        fj = np.where(st.base_fixed.reshape(-1, 3)[jn], 0.0, f.reshape(-1, 3)[jn])
        lam = fj[:, 1] * ny[act] + fj[:, 2] * nz[act]
        ft = fj - lam[:, None] * np.column_stack([np.zeros(jn.size), ny[act], nz[act]])
        area = d.outer_area[act]
        mid = d.on_z0[jn]
        out["force_q"] = float(-f[3 * jn + 1].sum())
        out["width"] = 2.0 * float(xyz[jn[mid], 0].max()) if np.any(mid) else 0.0
        out["length"] = 2.0 * float(xyz[jn, 2].max())
        out["area"] = 4.0 * float(area.sum())
        pos = area > 0
        out["peak"] = float(np.max(lam[pos] / area[pos])) if np.any(pos) else 0.0
        if lam.sum() > 1e-9 * st.fscale:
            out["share"] = float(np.linalg.norm(ft, axis=1).sum() / lam.sum())
    fn = d.inner_nodes[c.floor_active]
    fn = fn[d.on_z0[fn]]
    if fn.size:
        out["inner_width"] = 2.0 * float(xyz[fn, 0].max() - xyz[fn, 0].min())
    return out


def _row(spec: CaseSpec3D, h: float, m: dict, minJ: float, iters: int, e: float) -> dict:
    """Table row (:data:`COLUMNS_3D`) at jaw height ``h`` (mm): ``m`` from
    :func:`contact_measures`, ``e`` the 1/8 model's strain energy (N mm, :func:`energy`)."""
    force = 4.0 * m["force_q"]
    vals = (
        2 * h,
        0.5 * spec.diameter_mm - h,
        force,
        force / spec.jaw_length_mm,
        m["width"],
        m["peak"],
        force / m["area"] if m["area"] > 0 else 0.0,
        m["inner_width"],
        minJ,
        iters,
        m["area"],
        m["length"],
        m["share"],
        8.0 * e,
    )
    return dict(zip(COLUMNS_3D, vals))


def _state_row(spec: CaseSpec3D, st: _Setup, h: float, u, f, c: _Contact, iters: int):
    """Table row of a converged state at jaw height ``h`` (mm) and its 1/8 model's strain energy
    (N mm): ``(row, energy)``."""
    minJ = float(np.linalg.det(kinematics(st.disc, u)).min())
    e = energy(st.disc, st.material, u)
    return _row(spec, h, contact_measures(st, c, u, f, h), minJ, iters, e), e


#: The Newton solves first try the last factorisation as the preconditioner of GMRES
#: (:class:`grasprom.fe.linsolve.FactorReuse`) and factor only if that does not reach
#: :data:`FACTOR_REUSE_RTOL` within :data:`FACTOR_REUSE_ITERATIONS` iterations.  The directions
#: are those of a direct solve up to that residual (the zoned mesh, nh 2.0 mm: the table above
#: the crease band the same to 1.1e-9).  Off by default: it does not pay.  On the zoned sweep's
#: cases a Newton iteration costs between 15 % less (nh 2.0 mm) and 8 % more (le 1.4 mm), and
#: the path through the crease band changes as with any change of round-off, with it the
#: case's cost (nh 2.0 mm: 869 -> 542 s, 1374 -> 585 factorisations, 580 -> 423 Newton
#: iterations; mr 0.8 mm: 729 -> 901 iterations, slower);
#: ``python benchmarks/bench_fe3d.py factorreuse`` (docs/fe-model.md).
FACTOR_REUSE = False

#: Relative residual ``|K x - r| / |r|`` a solve with an older factor must reach.
FACTOR_REUSE_RTOL = 1e-9

#: GMRES iterations a solve with an older factor may take before it factors.
FACTOR_REUSE_ITERATIONS = 10


def _make_solver(name: str):
    """The run's linear solver: :func:`grasprom.fe.linsolve.make_solver`, wrapped in
    :class:`grasprom.fe.linsolve.FactorReuse` while :data:`FACTOR_REUSE`."""
    inner = make_solver(name)
    if not FACTOR_REUSE:
        return inner
    return FactorReuse(inner, FACTOR_REUSE_RTOL, FACTOR_REUSE_ITERATIONS)


def _setup(spec: CaseSpec3D, solver: str, on_row=None) -> _Setup:
    _validate_spec(spec)
    material = spec.make_material()
    disc = build_disc(spec)
    jaw = JawProfile(spec.flat_half_length_mm, spec.jaw_edge_radius_mm)
    t = spec.thickness_mm
    return _Setup(
        disc=disc,
        material=material,
        jaw=jaw,
        stick=spec.contact == "stick",
        mu=float(spec.friction) if spec.contact == "coulomb" else np.inf,
        base_fixed=_base_fixed(disc, spec.ends, spec.plane_strain),
        settings=spec.solver,
        fscale=material.mu * t * t,
        solver=_make_solver(solver),
        disc_thickness=t,
        on_row=on_row,
    )


def _initial_contact(st: _Setup, R: float) -> _Contact:
    d = st.disc
    on = d.outer_nodes
    X = d.X[on]
    c = _Contact(
        np.zeros(on.size, dtype=bool),
        np.zeros((on.size, 3)),
        np.zeros(d.inner_nodes.size, bool),
        h=R,
    )
    top = np.isclose(X[:, 0], 0.0, atol=1e-12) & (X[:, 2] <= st.jaw.a + 1e-12)
    c.jaw_active[top] = True
    c.anchor[:, 0] = X[:, 0]
    c.anchor[:, 1] = X[:, 1] - R
    c.anchor[:, 2] = X[:, 2]
    if np.isfinite(st.mu):  # Coulomb: the lagged normal force, none yet
        c.normal = np.zeros(on.size)
    return c


def _next_step(spec: CaseSpec3D, h, dh, iters, force, force_prev) -> float:
    """Next jaw step (mm) from the Newton effort and the relative force change."""
    s = spec.solver
    grow = 1.5 if iters <= 6 else (1.0 if iters <= 12 else 0.6)
    dh_next = dh * grow
    if force > s.force_floor_N and force_prev > 0:
        rel = (force - force_prev) / force_prev
        if rel > 0:
            dh_next = min(dh_next, dh * s.max_rel_force_step / rel)
    return max(dh_next, 2 * s.dh_min_mm)


def _limit_step(spec: CaseSpec3D, h, dh, h_end, landing) -> float:
    s, t = spec.solver, spec.thickness_mm
    dh = min(dh, s.dh_max_mm, h - h_end)
    if h > t:  # resolve the walls meeting: approach h = t geometrically
        dh = min(dh, max(0.01 * t, s.approach_fraction * (h - t)))
    return land_on(h, dh, landing, s.dh_min_mm)


_STEP_ERRORS = (_NewtonFailure, RuntimeError, ValueError, FloatingPointError)

#: Bisections of the crease crossing: the back step ``crease_step_fraction * t`` of jaw height
#: (0.035 mm at t = 1.4 mm, 0.07 mm of gap) over 2^4 places the crease to 4.4 um of gap, a
#: fifth of the surrogate's 20 um gap budget.  Eight (0.27 um) spent 124 s of a 720 s case on
#: the 4 x 36 mesh; on the default case four move the crease row by 3.3 um and no other row.
CREASE_BISECTIONS = 4

#: Halvings of a back step of the crease placement that fails before the creased branch is
#: taken to end there (:func:`grasprom.fe.crease.crease_onset`'s ``n_halve``): down to an
#: eighth of the step (4.4 um of jaw height at t = 1.4 mm).  Without them, 4 x 36 (240 mm tube,
#: mr 1.4 mm, stick) stopped the continuation at gap 4.25 mm, where one back step failed to
#: converge with the creased state still 0.2 % below the smooth fold in energy.
CREASE_BACK_HALVINGS = 3

#: Newton iterations (over all active-set passes) a back step of the crease placement may
#: spend before it counts as failed (and is halved).  The back steps that converged took 2-13
#: (one 26) on 4 x 36 and 4 x 48; a failing one spent up to 30 a pass, over several passes.
CREASE_BACK_BUDGET = 20


def _back_solver(st: _Setup):
    """``solve(state, h) -> (state, newton_iterations)`` of a back step to jaw height ``h``
    (mm) from ``state = (u, f, K, c)``, within :data:`CREASE_BACK_BUDGET` Newton iterations
    (the crease placement's and the unloading's)."""

    def solve(state, hh: float):
        u, _, K, c = state
        u, f, K, c, it = _solve_step(st, u, K, c, hh, budget=CREASE_BACK_BUDGET)
        return (u, f, K, c), it

    return solve


def _crease_onset(st: _Setup, snapped, h_snap: float, branch, t: float, landing):
    """Continue a snapped (creased) state back to larger jaw heights while its strain energy
    stays below the smooth branch's (:func:`grasprom.fe.crease.hermite_energy`), up to the top
    of the crease band (``h = 2 t``, ``t`` the wall thickness in mm): the 3D counterpart of the
    2D model's crease placement (Maxwell's rule, :func:`grasprom.fe.crease.crease_onset`).

    ``snapped = (u, f, K, c)``.  Back steps are ``crease_step_fraction * t``, landing on
    ``landing`` (mm); a back step that fails within :data:`CREASE_BACK_BUDGET` Newton
    iterations is halved up to :data:`CREASE_BACK_HALVINGS` times (then the creased branch
    ends there); the crossing is bisected :data:`CREASE_BISECTIONS` times.  With stick
    contact the jaw moves along its normal only, so its work is still ``F dh`` and ``dE/dh = -F``.
    """

    def below(state, hh: float) -> bool:
        e_s = hermite_energy(branch, hh)
        return energy(st.disc, st.material, state[0]) < e_s - 1e-10 * abs(e_s)

    dh = st.settings.crease_step_fraction * t
    return crease_onset(
        _back_solver(st),
        below,
        snapped,
        h_snap,
        dh,
        2.0 * t,
        landing,
        _STEP_ERRORS,
        CREASE_BISECTIONS,
        CREASE_BACK_HALVINGS,
        first_step=True,
    )


#: Largest back step of the unloading (:func:`_unload`), in wall thicknesses of jaw height:
#: twice the crease placement's.  Every loaded height in the band is landed on as well.
UNLOAD_STEP_FRACTION = 0.05


def _unload(st: _Setup, state, h: float, branch, t: float) -> Unloading:
    """Unload ``state = (u, f, K, c)`` at jaw height ``h`` (mm, the walls met) back up through
    the crease band to ``h = 2 t`` (:func:`grasprom.fe.crease.unload_band`): the states that
    hold less strain energy than the loaded ``branch`` at its heights, and the crossing."""
    return unload_band(
        _back_solver(st),
        lambda s: energy(st.disc, st.material, s[0]),
        branch,
        state,
        h,
        2.0 * t,
        UNLOAD_STEP_FRACTION * t,
        _STEP_ERRORS,
        CREASE_BACK_HALVINGS,
        CREASE_BISECTIONS,
    )


def _row_entry(spec: CaseSpec3D, st: _Setup, h: float, state, iters: int):
    """The table row of ``state = (u, f, K, c)`` at jaw height ``h`` (mm) and its ``branch``
    entry ``(h, strain energy, 1/8 jaw reaction)`` (mm, N mm, N)."""
    u, f, _, c = state
    row, e = _state_row(spec, st, h, u, f, c, iters)
    if st.on_row is not None:
        st.on_row(st.disc, u, 2.0 * h, row["force_N"])
    return row, (h, e, 0.25 * row["force_N"])


def _splice_unloading(spec: CaseSpec3D, st: _Setup, rows: list, branch: list, un: Unloading):
    """Put the unloaded states of :func:`_unload` in place of the loaded rows at their jaw
    heights (a bisected crossing is inserted in order); returns ``(rows, branch)``."""
    rows, branch = list(rows), list(branch)
    for hb, state, itb in un.states:
        rb, entry = _row_entry(spec, st, hb, state, itb)
        k = next((i for i, b in enumerate(branch) if b[0] == hb), None)
        if k is None:
            k = next(i for i, b in enumerate(branch) if b[0] < hb)
            rows.insert(k, rb)
            branch.insert(k, entry)
        else:
            rows[k], branch[k] = rb, entry
    return rows, branch


def _splice_crease(spec: CaseSpec3D, st: _Setup, rows: list, branch: list, back: CreaseOnset):
    """Replace the rows (and ``branch`` entries) below the crossing ``back[0]`` by the creased
    states of :func:`_crease_onset` (:func:`grasprom.fe.crease.splice_crease`)."""

    def entry(hb: float, state, itb: int):
        return _row_entry(spec, st, hb, state, itb)

    return splice_crease(rows, branch, back, entry)


#: Newton iterations (over all active-set passes) a plain attempt of :func:`_relax` may spend
#: before the next proximal step.  At the smooth fold's stability limit (4 x 36, 240 mm tube,
#: mr 1.4 mm, gap 4.066 mm) each failing attempt cost 67-74 s with the per-pass limit alone and
#: 15-21 s with this; the proximal steps are the same (they start from the proximal iterate).
RELAX_PLAIN_BUDGET = 10

#: A plain attempt of :func:`_relax` fails at its first Newton iteration whose direction needs a
#: Levenberg shift (the tangent is not positive definite there: the proximal iterate is not yet
#: in the basin of a stable equilibrium), instead of running on to its budget.  4 x 36 -> 2 x 18
#: (``far_coarsening`` 2), 240 mm tube, mr 0.8 mm, stick: the snap at gap 1.92 mm took 17 plain
#: attempts; the 16 that failed had all needed a shift from their second or third iteration on
#: and spent 304 factorisations, 64 with this rule; the one that landed needed none, and the
#: case's table is the same to the bit (2065 -> 1825 factorisations).  The proximal steps keep
#: their shifts: failing them at the first shift (``c`` x 4) took 46 plain attempts, not 17.
RELAX_PLAIN_UNSHIFTED = True


def _relax(st: _Setup, u, K, c: _Contact, h: float):
    """Equilibrium at jaw height ``h`` (mm) past a snap, by proximal-point iteration (as the 2D
    model's ``_relax``): each step minimises ``energy + c/2 |u - u_k|^2`` (:class:`ProximalTerm`,
    strongly convex for ``c`` above the negative curvature) with the contact set updated, then
    the plain problem is tried (within :data:`RELAX_PLAIN_BUDGET` Newton iterations, and only
    while its tangent needs no Levenberg shift: :data:`RELAX_PLAIN_UNSHIFTED`); ``c``
    shrinks while the steps converge.  Returns
    :func:`_solve_step`'s ``(u, f, K, contact, newton_iterations)``, the proximal steps'
    iterations included; raises :class:`_NewtonFailure` if it does not land.
    """
    cp = 1e-2 * float(np.abs(K.diagonal()).mean())
    spent = 0
    for _ in range(st.settings.max_relax):
        try:
            u, _, K, c, it = _solve_step(st, u, K, c, h, ProximalTerm(cp, u.copy()))
        except _STEP_ERRORS:
            cp *= 4.0
            continue
        spent += it
        try:
            u, f, K, c, it = _solve_step(
                st, u, K, c, h, budget=RELAX_PLAIN_BUDGET, unshifted=RELAX_PLAIN_UNSHIFTED
            )
        except _STEP_ERRORS:
            cp *= 0.7
            continue
        return u, f, K, c, spent + it
    raise _NewtonFailure(f"no equilibrium within {st.settings.max_relax} proximal steps")


def _advance(st: _Setup, u, K, c: _Contact, h: float, dh: float):
    """The step to jaw height ``h`` (mm): Newton with the active set, and if a jaw step ``dh``
    (mm) of at most ``SolverSettings.relax_below_mm`` fails, the snap by :func:`_relax`."""
    try:
        return _solve_step(st, u, K, c, h)
    except _STEP_ERRORS:
        if dh > st.settings.relax_below_mm:
            raise
    return _relax(st, u, K, c, h)


def _first_touch(spec: CaseSpec3D, st: _Setup):
    """The undeformed state at first touch (jaw height = the tube radius, mm):
    ``((u, f, K, contact), [row])``; a ValueError if ``spec`` asks for a companion run (not
    :func:`run_case_3d`'s job)."""
    if spec.solver.band_companion != 0:
        raise ValueError(
            f"solver.band_companion={spec.solver.band_companion}: a case with a companion run "
            "is run by grasprom.fe.bandselect.run_case_3d_selected (run_case_3d is its own run)"
        )
    R = 0.5 * spec.diameter_mm
    c = _initial_contact(st, R)
    u = np.zeros(st.disc.ndof)
    f, K, _ = assemble(st.disc, st.material, u)
    return (u, f, K, c), [_row(spec, R, contact_measures(st, c, u, f, R), 1.0, 0, 0.0)]


def _finished(spec: CaseSpec3D, h: float, force_N: float) -> str:
    """Why a case ends at jaw height ``h`` (mm) and jaw force ``force_N`` (N), or ``""``."""
    if force_N >= spec.force_cap_N:
        return "force cap reached"
    if h <= 0.5 * spec.closed_gap_mm + 1e-12:
        return "closed gap reached"
    return ""


def _unload_due(spec: CaseSpec3D, h: float, force_N: float, end: bool) -> bool:
    """Whether the unloading of :attr:`SolverSettings.unload_from_N` starts at jaw height ``h``
    (mm): in the crease band (gap below 4t) once the walls have met (h <= t) and the force
    reached the threshold (N), or at the last step (``end``) of a case that ends in the band."""
    t = spec.thickness_mm
    deep = h <= t and force_N >= spec.solver.unload_from_N
    return h < 2.0 * t and (deep or end)


def _crease_rows(spec: CaseSpec3D, st, state, h: float, rows: list, branch: list, landing):
    """Place the crease of a state that snapped at jaw height ``h`` (mm; :func:`_crease_onset`)
    and splice its creased states into ``rows``/``branch``.  Returns ``(rows, branch, record)``
    with the record of ``fe_info.creases``: the gap of the snap and of the placed crease (mm;
    the snap's if nothing was placed), rows replaced, Newton iterations."""
    back = _crease_onset(st, state, h, branch, spec.thickness_mm, landing)
    rows, branch = _splice_crease(spec, st, rows, branch, back)
    placed = back.states[0][0] if back.states else h
    record = {"snap_gap_mm": 2 * h, "placed_gap_mm": 2 * placed, "rows": len(back.states)}
    return rows, branch, record | {"newton_iterations": back.newton_iterations}


def _unload_rows(spec: CaseSpec3D, st, state, h: float, rows: list, branch: list):
    """Unload ``state`` at jaw height ``h`` (mm) through the band and splice the lower rows it
    finds into ``rows``/``branch``.  Returns ``(rows, branch, record)`` with the record of
    ``fe_info.unloading`` (gaps in mm)."""
    un = _unload(st, state, h, branch, spec.thickness_mm)
    rows, branch = _splice_unloading(spec, st, rows, branch, un)
    record = {"from_gap_mm": 2 * h, "to_gap_mm": 2 * un.top_mm}
    record |= {"rows_replaced": len(un.states), "newton_iterations": un.newton_iterations}
    return rows, branch, record


def _report(progress, on_step, disc: Disc3D, u, h: float, force_N: float) -> None:
    """Call :func:`run_case_3d`'s ``progress`` and ``on_step`` (if given) after a forward step
    to jaw height ``h`` (mm) with the jaw force ``force_N`` (N)."""
    if progress is not None:
        progress(2 * h, force_N)
    if on_step is not None:
        on_step(disc, u, 2 * h, force_N)


def run_case_3d(
    spec: CaseSpec3D, progress=None, solver: str = "auto", on_step=None, on_row=None
) -> CaseResult:
    """Run one 3D clamping case from first touch to the closed gap or the force cap.

    Parameters
    ----------
    spec : CaseSpec3D
        Geometry (mm), material, contact, limits, mesh and solver settings.
    progress : callable, optional
        Called as ``progress(gap_mm, force_N)`` after each converged forward step.
    solver : str
        Sparse solver (:func:`grasprom.fe.linsolve.make_solver`; ``"auto"``: PARDISO if there).
    on_step : callable, optional
        Called as ``on_step(disc, u, gap_mm, force_N)`` after each converged forward step (the
        nodal displacements in mm), e.g. a :class:`grasprom.fe.snapshots3d.SectionRecorder`.
    on_row : callable, optional
        As ``on_step``, for every state after first touch that enters the table, crease
        placement and unloading included (the last call at a table gap is the table's state).

    Returns
    -------
    CaseResult
        Table (:data:`COLUMNS_3D`, units :data:`COLUMN_DESCRIPTIONS_3D`), status and record.

    Raises
    ------
    ValueError
        An invalid spec, or ``solver.band_companion`` set (:mod:`grasprom.fe.bandselect`).
    """
    t0 = time.perf_counter()
    st = _setup(spec, solver, on_row)
    s = spec.solver
    R = 0.5 * spec.diameter_mm
    h_end = 0.5 * spec.closed_gap_mm
    (u, f, K, c), rows = _first_touch(spec, st)
    branch = [(R, 0.0, 0.0)]  # (h, strain energy, 1/8 jaw reaction) of every row
    maxwell = s.maxwell_crease and spec.contact != "coulomb"  # friction dissipates
    h, dh = R, s.dh_initial_mm
    landing = sorted((0.5 * g for g in s.land_on_gaps_mm), reverse=True)
    n_fail, total_newton, force_prev = 0, 0, 0.0
    t = spec.thickness_mm
    unload = s.unload_from_N > 0.0 and spec.contact != "coulomb"
    unloaded, fail_log, creases = {}, [], []
    status, reason = "partial", ""
    while True:
        dh = _limit_step(spec, h, dh, h_end, landing)
        if dh < s.dh_min_mm and h - h_end > s.dh_min_mm:
            reason = f"step below dh_min_mm={s.dh_min_mm} at gap {2 * h:.4f} mm"
            break
        try:
            u_new, f_new, K_new, c_new, iters = _advance(st, u, K, c, h - dh, dh)
        except _STEP_ERRORS as exc:
            n_fail += 1
            fail_log.append({"gap_mm": 2 * (h - dh), "dh_mm": dh, "reason": str(exc)})
            dh *= 0.25
            continue
        u, f, K, c, h = u_new, f_new, K_new, c_new, h - dh
        total_newton += iters
        row, entry = _row_entry(spec, st, h, (u, f, K, c), iters)
        if maxwell and t < h < 2.0 * t and is_snap(branch[-1], entry):
            rows, branch, rec = _crease_rows(spec, st, (u, f, K, c), h, rows, branch, landing)
            creases.append(rec)
            total_newton += rec["newton_iterations"]
        rows.append(row)
        branch.append(entry)
        done = _finished(spec, h, row["force_N"])
        if unload and not unloaded and _unload_due(spec, h, row["force_N"], bool(done)):
            rows, branch, unloaded = _unload_rows(spec, st, (u, f, K, c), h, rows, branch)
            total_newton += unloaded["newton_iterations"]
        _report(progress, on_step, st.disc, u, h, row["force_N"])
        if done:
            status, reason = "complete", done
            break
        dh = _next_step(spec, h, dh, iters, row["force_N"], force_prev)
        force_prev = row["force_N"]
    table = pd.DataFrame(rows, columns=list(COLUMNS_3D))
    info = _info(spec, st, table, reason, total_newton, n_fail, fail_log, h, t0)
    info |= {"creases": creases} | ({"unloading": unloaded} if unload else {})
    return CaseResult(table=table, status=status, info=info)


@dataclass(frozen=True)
class Equilibrium3D:
    """A converged state of a 3D case at one jaw gap (:func:`equilibrium_from`).

    Attributes
    ----------
    gap_mm : float
        Jaw gap (mm).
    force_N : float
        Total force on one jaw (N).
    strain_energy_mJ : float
        Strain energy of the whole tube (mJ).
    u : ndarray
        Nodal displacements (mm) of the case's mesh, ``3 n_nodes``.
    newton_iterations : int
        Newton iterations the solve took.
    row : dict
        The state's table row (:data:`COLUMNS_3D`).
    """

    gap_mm: float
    force_N: float
    strain_energy_mJ: float
    u: np.ndarray
    newton_iterations: int
    row: dict


#: Start states of :func:`equilibrium_from`: an outer node within this share of the wall
#: thickness of the jaw (or an inner node of the plane ``y = 0``) starts in contact; the
#: active-set loop releases it if it pulls.
RESTART_CONTACT_TOL = 1e-3


def _contact_at(st: _Setup, u: np.ndarray, h: float) -> _Contact:
    """Contact state read off a displacement field (mm) at jaw height ``h`` (mm): nodes on or
    through the jaw and the floor are active, stuck at their jaw projection."""
    d = st.disc
    tol = RESTART_CONTACT_TOL * st.disc_thickness
    xyz = d.X + u.reshape(-1, 3)
    c = _initial_contact(st, h)
    c.jaw_active, c.anchor = _jaw_touch(st, xyz, h, -tol)
    c.floor_active = xyz[d.inner_nodes, 1] < tol
    c.h = np.nan  # nodes added by the solve stick at their projection
    return c


class EquilibriumSolver:
    """Equilibria of one 3D case at given gaps from given start states, on one set-up.

    The mesh, quadrature and material are built once (a few seconds on the sweep's meshes) and
    serve every :meth:`solve`; each solve gets a new sparse solver (PARDISO's analysis scales
    and matches by the first matrix's values), so a solve does not depend on the ones before
    it and equals :func:`equilibrium_from`, one solve on a fresh set-up, to the bit.

    Parameters
    ----------
    spec : CaseSpec3D
        The case (its mesh is the one solved on).
    solver : str
        Sparse solver, see :func:`run_case_3d`.

    Raises
    ------
    ValueError
        An invalid spec.
    """

    def __init__(self, spec: CaseSpec3D, solver: str = "auto") -> None:
        self.spec = spec
        self._solver = solver
        self._st = _setup(spec, solver)

    @property
    def ndof(self) -> int:
        """Degrees of freedom of the case's mesh (``3 n_nodes``)."""
        return int(self._st.disc.ndof)

    def solve(self, u0: np.ndarray, gap_mm: float) -> Equilibrium3D:
        """Equilibrium at jaw gap ``gap_mm`` (mm) from the start displacements ``u0`` (mm).

        The contact state is read off ``u0`` (:data:`RESTART_CONTACT_TOL`; with stick contact
        every node on the jaw is stuck where it is), then Newton with the active set runs at
        the jaw height ``gap_mm / 2`` (and the proximal relaxation of a snap if that fails).
        With a state of another mesh (:func:`grasprom.fe.transfer3d.transfer_displacement`)
        as ``u0``, the result is this mesh's state on the same branch of equilibria, if the
        branch exists here.

        Parameters
        ----------
        u0 : ndarray
            Start displacements (mm) on the case's mesh, ``3 n_nodes``.
        gap_mm : float
            Jaw gap (mm).

        Returns
        -------
        Equilibrium3D

        Raises
        ------
        ValueError
            ``u0`` has the wrong length or the gap is not positive.
        RuntimeError
            ``u0`` inverts an element (a sharp fold of a finer mesh moved to a coarser one
            can), or no equilibrium was found from it.
        """
        if not (np.isfinite(gap_mm) and gap_mm > 0):
            raise ValueError(f"invalid gap_mm={gap_mm!r}: a positive jaw gap (mm)")
        st = replace(self._st, solver=_make_solver(self._solver), factor=_FactorMemo())
        u = np.asarray(u0, dtype=float)
        if u.shape != (st.disc.ndof,):
            raise ValueError(f"u0 has {u.size} values; the mesh has {st.disc.ndof} dofs")
        h = 0.5 * float(gap_mm)
        c = _contact_at(st, u, h)
        _, K, minJ = assemble(st.disc, st.material, u)
        if K is None:
            msg = f"the start state inverts an element of this mesh (min det F = {minJ:.3g})"
            raise RuntimeError(msg)
        try:
            u, f, K, c, it = _advance(st, u, K, c, h, 0.0)  # no jaw step: relaxed on failure
        except _STEP_ERRORS as exc:
            msg = f"no equilibrium at gap {gap_mm} mm from the given state: {exc}"
            raise RuntimeError(msg) from exc
        row, e = _state_row(self.spec, st, h, u, f, c, it)
        return Equilibrium3D(2.0 * h, row["force_N"], 8.0 * e, u, it, row)


def equilibrium_from(
    spec: CaseSpec3D, u0: np.ndarray, gap_mm: float, solver: str = "auto"
) -> Equilibrium3D:
    """Equilibrium of a 3D case at one jaw gap, from a given start state:
    ``EquilibriumSolver(spec, solver).solve(u0, gap_mm)`` (:meth:`EquilibriumSolver.solve`;
    for several solves on one mesh keep the :class:`EquilibriumSolver`).

    Parameters
    ----------
    spec : CaseSpec3D
        The case (its mesh is the one solved on).
    u0 : ndarray
        Start displacements (mm) on ``spec``'s mesh, ``3 n_nodes``.
    gap_mm : float
        Jaw gap (mm).
    solver : str
        Sparse solver, see :func:`run_case_3d`.

    Returns
    -------
    Equilibrium3D
        As :meth:`EquilibriumSolver.solve`, which also lists what it raises (ValueError for
        bad input, RuntimeError where no equilibrium is found).
    """
    if not (np.isfinite(gap_mm) and gap_mm > 0):  # before the set-up's seconds
        raise ValueError(f"invalid gap_mm={gap_mm!r}: a positive jaw gap (mm)")
    return EquilibriumSolver(spec, solver).solve(u0, gap_mm)


def solver_rules() -> dict:
    """The module constants that choose the solution path (``fe_info.solver_rules`` of a case
    sidecar, beside ``solver``, the :class:`SolverSettings` of the spec): a case re-run with
    other values may take another path through the crease band, whose states differ by
    round-off-sized changes (docs/fe-model.md).

    Returns
    -------
    dict
        Lower-case constant name -> value: counts, relative tolerances (of a force or of a
        step's work; each constant's comment says which), ``friction_eps_mm`` in mm,
        ``assembly_block`` in elements.
    """
    return {
        "assembly_block": ASSEMBLY_BLOCK,
        "predictor_reuses_factor": PREDICTOR_REUSES_FACTOR,
        "active_set_rtol": ACTIVE_SET_RTOL,
        "stall_rises": STALL_RISES,
        "forward_stall_rises": FORWARD_STALL_RISES,
        "touch_bisections": TOUCH_BISECTIONS,
        "friction_normal_rtol": FRICTION_NORMAL_RTOL,
        "friction_eps_mm": FRICTION_EPS_MM,
        "crease_bisections": CREASE_BISECTIONS,
        "crease_back_halvings": CREASE_BACK_HALVINGS,
        "crease_back_budget": CREASE_BACK_BUDGET,
        "relax_plain_budget": RELAX_PLAIN_BUDGET,
        "relax_plain_unshifted": RELAX_PLAIN_UNSHIFTED,
        "factor_reuse": FACTOR_REUSE,
        "factor_reuse_rtol": FACTOR_REUSE_RTOL,
        "factor_reuse_iterations": FACTOR_REUSE_ITERATIONS,
        "snap_force_drop": SNAP_FORCE_DROP,
        "snap_release_fraction": SNAP_RELEASE_FRACTION,
    }


def _info(spec, st: _Setup, table, reason, total_newton, n_fail, fail_log, h, t0) -> dict:
    d = st.disc
    return {
        "model": "3d",
        "status_reason": reason,
        "steps": len(table) - 1,
        "newton_iterations": int(total_newton),
        "factorizations": int(getattr(st.solver, "factorizations", -1)),
        "factor_reuses": int(getattr(st.solver, "reuses", 0)),
        "krylov_iterations": int(getattr(st.solver, "krylov_iterations", 0)),
        "failures": n_fail,
        "failure_log": fail_log[-20:],
        "last_gap_mm": float(2 * h),
        "max_force_N": float(table["force_N"].max()),
        "dofs": int(d.ndof),
        "elements": int(d.edofs.shape[0]),
        "wall_time_s": time.perf_counter() - t0,
        "material_constants": st.material.constants(),
        "mesh": asdict(spec.mesh),
        "solver": asdict(spec.solver),
        "solver_rules": solver_rules(),
        "linear_solver": solver_name(st.solver),
        "contact": spec.contact,
        "tube_length_mm": spec.tube_length_mm,
        "ends": spec.ends,
        "jaw_edge_radius_mm": spec.jaw_edge_radius_mm,
        "plane_strain": spec.plane_strain,
        "element": "Q2 hexahedron (27 nodes, 3x3x3 Gauss), discontinuous "
        + ("P1" if spec.mesh.element == "Q2/P1" else "P0")
        + " dilatation/pressure condensed per element",
        "force_definition": "force_N = 4 x the 1/8 model's jaw reaction (N)",
    }


def _validate_spec(spec: CaseSpec3D) -> None:
    R = 0.5 * spec.diameter_mm
    checks = (
        ("diameter_mm", spec.diameter_mm, spec.diameter_mm > 0),
        ("thickness_mm", spec.thickness_mm, 0 < spec.thickness_mm < R),
        ("jaw_length_mm", spec.jaw_length_mm, spec.jaw_length_mm > 0),
        ("jaw_edge_radius_mm", spec.jaw_edge_radius_mm, 0 <= spec.flat_half_length_mm),
        ("closed_gap_mm", spec.closed_gap_mm, 0 < spec.closed_gap_mm < spec.diameter_mm),
        ("force_cap_N", spec.force_cap_N, spec.force_cap_N > 0),
        ("tube_length_mm", spec.tube_length_mm, spec.tube_length_mm > 0),
        (
            "solver.predict_contact_below_mm",
            spec.solver.predict_contact_below_mm,
            spec.solver.predict_contact_below_mm >= 0,
        ),
        (
            "solver.predict_contact_below_t",
            spec.solver.predict_contact_below_t,
            spec.solver.predict_contact_below_t >= 0,
        ),
    )
    for name, value, ok in checks:
        if not (np.isfinite(value) and ok):
            raise ValueError(f"invalid {name}={value!r}")
    if spec.ends not in ENDS:
        raise ValueError(f"unknown ends {spec.ends!r}; valid: {', '.join(ENDS)}")
    if spec.contact not in CONTACTS:
        raise ValueError(f"unknown contact {spec.contact!r}; valid: {', '.join(CONTACTS)}")
    check_friction(spec.contact, spec.friction)
    if spec.plane_strain and spec.flat_half_length_mm < 0.5 * spec.tube_length_mm:
        raise ValueError("plane_strain needs a flat jaw at least as long as the tube")


def solve_dirichlet(
    disc: Disc3D,
    material: Material,
    fixed: np.ndarray,
    values: np.ndarray,
    settings: SolverSettings | None = None,
    solver: str = "auto",
):
    """Static equilibrium with prescribed displacements only (no contact), e.g. for checks.

    Parameters
    ----------
    disc : Disc3D
    material : Material
    fixed : ndarray of bool (ndof,)
        Prescribed dofs.
    values : ndarray (ndof,)
        Their displacements (mm).
    settings : SolverSettings, optional
    solver : str
        See :func:`run_case_3d`.

    Returns
    -------
    u, f : ndarray
        Displacements (mm) and internal nodal forces (N) = the reactions at ``fixed``.
    """
    settings = settings or _default_solver()
    t = float(np.ptp(np.hypot(disc.X[:, 0], disc.X[:, 1])))
    jaw = JawProfile(0.0, 0.0)
    solve = make_solver(solver)
    st = _Setup(disc, material, jaw, False, fixed, settings, material.mu * t * t, solve, t)
    cons = (fixed, np.where(fixed, values, 0.0), np.zeros(0, dtype=np.int64))
    u, f, *_ = _newton(st, cons[1].copy(), cons, 0.0, _no_contact(disc))
    return u, f


def _no_contact(disc: Disc3D) -> _Contact:
    """A contact state with every candidate active, so no penetration check applies."""
    return _Contact(
        np.ones(disc.outer_nodes.size, bool),
        np.zeros((disc.outer_nodes.size, 3)),
        np.ones(disc.inner_nodes.size, bool),
    )


def semi_membrane_jaw_stiffness(
    R: float, t: float, E: float, nu: float, a: float, n_max: int = 400, n_pts: int = 81
) -> float:
    """Jaw stiffness F/d (N/mm) of a long tube pinched by two rigid flat punches, semi-membrane.

    Vlasov's semi-membrane theory: every circumferential mode ``cos(n theta)`` (n even) is a
    beam on an elastic foundation along the axis, ``EI_n W'''' + k_n W = 2 p(z)``, with
    ``EI_n = pi E t R^3 / n^4`` (axial membrane), ``k_n = pi D (n^2 - 1)^2 / R^3`` (ring bending,
    ``D = E t^3 / 12 (1 - nu^2)``); the factor 2: both line loads (top, bottom) load even modes
    alike.  A uniform load gives ring theory exactly.  The punch (half length ``a``, mm) imposes
    the same travel ``d`` (one jaw) on ``|z| <= a``: collocation with point loads at ``n_pts``
    nodes; returns the total force on one jaw per unit travel.
    """
    n = np.arange(2, n_max + 1, 2, dtype=float)
    D = E * t**3 / (12 * (1 - nu**2))
    EI = np.pi * E * t * R**3 / n**4
    k = np.pi * D * (n**2 - 1) ** 2 / R**3
    beta = (k / (4 * EI)) ** 0.25
    z = np.linspace(-a, a, n_pts)
    s = np.abs(z[:, None] - z[None, :])[..., None] * beta
    G = (2 * beta / (2 * k) * np.exp(-s) * (np.cos(s) + np.sin(s))).sum(axis=-1)
    P = np.linalg.solve(G, np.ones(n_pts))  # point loads for unit travel
    return float(P.sum())
