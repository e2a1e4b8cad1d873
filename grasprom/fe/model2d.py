"""Plane-strain FE model of a tube (colon wall) clamped flat between rigid jaws.

Model (Guachi et al.'s "CS" cylindrical approximation):

* cross-section of a tube of outer diameter ``D`` and wall thickness ``t``, plane strain, quarter
  symmetry (``x >= 0, y >= 0``); symmetry ``u_x = 0`` on ``x = 0`` and ``u_y = 0`` on ``y = 0``;
* a rigid flat jaw ``y = h`` descends from first touch (``h = D/2``) to ``h = closed_gap / 2``;
  the jaw gap is ``2 h``; node-to-plane contact with the outer wall, ``frictionless`` (default)
  ``stick`` (Guachi et al.'s "no sliding at the interface": a node that touches the jaw keeps its
  ``x`` until it lifts off) or ``coulomb`` (stuck until the tangential reaction passes ``mu``
  times the normal one, then sliding against a friction force ``mu N``);
* self-contact of the inner wall with its mirror image is contact with the rigid plane ``y = 0``
  (frictionless), which the inner wall reaches once the walls meet (``gap ~ 2 t``);
* contact is solved exactly with a primal active set: active nodes get a prescribed normal
  displacement and are released when their reaction turns tensile;
* P2 triangles + cubic bubble with a linear discontinuous pressure / dilatation per element
  (P2B/P1, default; or the P2/P0 mean dilatation) against volumetric locking; the
  structured mesh puts the diagonal through the inner fold corner so that two triangles share it;
* Newton-Raphson on the total potential energy with consistent tangent, an energy line search,
  a Levenberg shift when the tangent is not positive definite, and adaptive displacement
  stepping (cut on divergence, grow on easy convergence).

Forces: the 2D model gives a force per unit tube length (N/mm); the jaw force is that times
``jaw_length_mm`` (the length of tube the jaw squeezes, i.e. the jaw width across the tube).
This neglects the ends of the squeezed zone (the tube outside the jaws), see README.

Lengths in mm, forces in N, stresses in MPa.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import pandas as pd
import scipy.sparse as sp

from grasprom.fe.crease import CreaseOnset, crease_onset, hermite_energy, splice_crease
from grasprom.fe.linsolve import descent_direction, make_solver, solver_name
from grasprom.fe.materials import Material, cofactor, get_material, pointwise_tangent
from grasprom.fe.stepping import land_on

#: columns every case CSV must hold (a contract other tools rely on)
CONTRACT_COLUMNS = (
    "gap_mm",
    "jaw_displacement_mm",
    "force_N",
    "force_per_length_N_per_mm",
    "contact_width_mm",
    "peak_pressure_MPa",
    "min_J",
)

#: the columns the 2D and 3D models share, in order
COLUMNS = (
    *CONTRACT_COLUMNS[:-1],
    "mean_pressure_MPa",
    "inner_contact_width_mm",
    "min_J",
    "newton_iterations",
)

#: all columns a 2D case writes, in order: :data:`COLUMNS`, the stick reaction's share and the
#: strain energy
COLUMNS_2D = (*COLUMNS, "tangential_share", "strain_energy_mJ")

CONTACTS_2D = ("frictionless", "stick", "coulomb")
"""Jaw contact laws of the 2D model (:attr:`CaseSpec.contact`)."""

#: "unit, meaning" of every column
COLUMN_DESCRIPTIONS = {
    "gap_mm": "mm, jaw gap (distance between the two jaw faces)",
    "jaw_displacement_mm": "mm, travel of one jaw from first touch",
    "force_N": "N, clamping force on one jaw = force_per_length_N_per_mm * jaw_length_mm",
    "force_per_length_N_per_mm": "N/mm, clamping force per unit tube length (2D result)",
    "contact_width_mm": "mm, width of the jaw-tissue contact (full width, both halves)",
    "peak_pressure_MPa": "MPa, largest nodal contact pressure on the jaw",
    "mean_pressure_MPa": "MPa, force_per_length / contact_width",
    "inner_contact_width_mm": "mm, width over which the inner walls touch (full width)",
    "min_J": "1, smallest det(F) over all quadrature points (volume ratio)",
    "newton_iterations": "1, Newton iterations of the step (all active-set passes)",
    "tangential_share": "1, sum of |tangential| / sum of normal nodal jaw reactions (0 if "
    "frictionless)",
    "strain_energy_mJ": "mJ, strain energy of the ring (N mm/mm of the whole cross-section x "
    "jaw_length_mm); = the jaws' work, the integral of force_N over the gap closed, along a "
    "smooth branch",
}


@dataclass(frozen=True)
class MeshSpec:
    """Structured polar mesh of the quarter ring, split into P2 triangles.

    Parameters
    ----------
    n_layers : int
        Element layers through the wall thickness (default 4).
    n_circ : int
        Element divisions along the quarter circumference (default 64).
    grading : float
        Ratio of the largest to the smallest circumferential element (geometric progression,
        1 = uniform; default 8); > 1 refines toward the side fold (``theta = 0``), where the
        wall bends hardest and the inner surface creases, and coarsens toward the top, which
        only flattens.
    element : str
        ``"P2B/P1"`` (default) or ``"P2/P0"``, see :func:`discretise`.
    radial_grading : float
        Ratio of the outermost to the innermost layer thickness (default 4): thin layers at the
        inner wall, where the fold's inner surface creases.
    corner_aspect : float
        Smallest ratio (default 0.6) of the fold corner element's circumferential length to its
        radial thickness (the innermost layer): where ``grading`` would make the corner element
        flatter than that (thick walls, whose innermost layer is thick), the circumferential
        grading is lowered until it is not (:meth:`circ_grading`); 0 keeps ``grading``.

    Notes
    -----
    In the crease band (gap 2 t .. 4 t) the inner surface of the side fold is compressed past
    the creasing threshold of a rubber-like solid and a crease forms at the fold corner.  How
    early a mesh lets it form is set by the element size at that corner (a uniform 4 x 64 mesh,
    0.35 mm there, holds the smooth fold to gap 4.5 mm at t = 1.4 mm and then snaps by 5.5 %;
    8 x 128 creases at 4.82 mm by 1.6 %).  The default grades both ways toward the corner
    (about 0.1 mm there) and places the crease by energy (:attr:`SolverSettings.maxwell_crease`).
    A thick wall's innermost layer is thicker than that (0.22 mm at t = 2.0 mm): with 8:1 the
    corner element was 0.43 times as long as thick and the band missed 3 % (5.1 %), so the
    circumferential grading is lowered until the corner element's aspect is ``corner_aspect``
    (0.6; t >= 1.5 mm, :meth:`for_wall`).  Against its 2x refinement the band converges within
    3 % at every thickness (max 2.4 / 1.4 / 1.8 % at t = 0.8 / 1.4 / 2.0 mm;
    ``python benchmarks/bench_fe.py --crease``, docs/fe-model.md).
    """

    n_layers: int = 4
    n_circ: int = 64
    grading: float = 8.0
    element: str = "P2B/P1"
    radial_grading: float = 4.0
    corner_aspect: float = 0.6

    def refined(self, factor: int = 2) -> MeshSpec:
        """The same mesh with every element split ``factor`` times in each direction."""

        def ratio(r: float, n: int) -> float:  # the same progression with n * factor elements
            return r ** ((n * factor - 1) / max(n - 1, 1) / factor)

        nl, nc = self.n_layers, self.n_circ
        g, rg = ratio(self.grading, nc), ratio(self.radial_grading, nl)
        return MeshSpec(nl * factor, nc * factor, g, self.element, rg, self.corner_aspect)

    def layer_edges(self, inner_radius: float, thickness: float) -> np.ndarray:
        """Radii (mm) of the layer boundaries, inner to outer wall."""
        return inner_radius + thickness * graded_fractions(self.n_layers, self.radial_grading)

    def for_wall(self, inner_radius: float, thickness: float) -> MeshSpec:
        """This mesh with its circumferential grading resolved for one wall.

        The corner element at the inner fold is ``inner_radius * pi/2 * f1`` long (``f1`` the
        first fraction of :func:`graded_fractions`, mm) and as thick as the innermost layer
        (mm); the grading becomes the largest ``<= grading`` whose corner element is at least
        ``corner_aspect`` times as long as thick (1 if even a uniform division is flatter), and
        ``corner_aspect`` becomes 0 (resolved).  Refine the resolved mesh,
        ``for_wall(...).refined(2)``, for a refinement of exactly this mesh.

        Parameters
        ----------
        inner_radius, thickness : float
            Inner radius and wall thickness (mm).

        Returns
        -------
        MeshSpec
        """
        g = float(self.grading)
        if self.corner_aspect <= 0 or g <= 1:
            return self
        h_in = thickness * graded_fractions(self.n_layers, self.radial_grading)[1]
        need = self.corner_aspect * h_in / (0.5 * np.pi * inner_radius)

        def first(gg: float) -> float:
            return float(graded_fractions(self.n_circ, gg)[1])

        if first(g) < need:
            lo, hi = 0.0, np.log(g)  # first() falls with the grading: bisect on log(grading)
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if first(np.exp(mid)) >= need else (lo, mid)
            g = float(np.exp(lo))
        return replace(self, grading=g, corner_aspect=0.0)


def graded_fractions(n: int, ratio: float) -> np.ndarray:
    """Node positions in ``[0, 1]`` of ``n`` elements in geometric progression, the last
    ``ratio`` times as long as the first (1 = uniform)."""
    n = int(n)
    q = float(ratio) ** (1.0 / max(n - 1, 1))
    ds = q ** np.arange(n)
    return np.concatenate([[0.0], np.cumsum(ds)]) / ds.sum()


@dataclass(frozen=True)
class SolverSettings:
    """Newton-Raphson / load-stepping settings (lengths in mm).

    Parameters
    ----------
    dh_initial_mm : float
        First jaw step.
    dh_min_mm : float
        Smallest step before the case is declared partial.
    dh_max_mm : float
        Largest step in the low-force bending regime.
    max_rel_force_step : float
        Target relative force change per step once the force exceeds ``force_floor_N``
        (keeps the steep rise resolved).
    force_floor_N : float
        Below this force the relative-change control is off.
    approach_fraction : float
        While the walls have not met (``h > t``), a step is at most this fraction of the
        remaining distance ``h - t`` to the walls meeting (but not below ``0.01 t``).
    max_newton : int
        Newton iterations per active-set pass.
    max_active_set : int
        Active-set passes per step.
    rtol : float
        Residual tolerance relative to the force scale ``mu * t`` (N/mm).
    land_on_gaps_mm : tuple of float
        Jaw gaps (mm) the stepping lands on exactly (a converged step at each), e.g. to compare
        meshes at fixed gaps without interpolation error; a step that would stop just above one
        is stretched onto it (:func:`grasprom.fe.stepping.land_on`).
    relax_below_mm : float
        A jaw step this small (mm) that Newton cannot solve is taken as a snap of the wall and
        solved by proximal-point relaxation (:func:`_relax`); 0 turns that off.
    max_relax : int
        Proximal steps allowed for one snap.
    crease_step_fraction : float
        2D: in the crease band (walls not met, gap below 4 t) a jaw step is at most this fraction
        of the wall thickness, so the fold is followed closely and the crease onset is located;
        the back steps of the crease placement are a quarter of it.  3D: only the back steps,
        this fraction of the wall thickness (the forward steps are not capped: a 3D step costs
        too much).
    maxwell_crease : bool
        Place a snap in the crease band where the snapped (creased) state first has less
        strain energy than the smooth fold at the same jaw height (Maxwell's rule,
        :func:`_crease_onset`), not where the smooth fold loses stability: that point depends
        on the mesh (a finer fold tip holds the metastable smooth fold longer and snaps harder).
    predict_contact_below_mm : float
        3D only, experimental: below this jaw gap (mm) a Newton step cut at the first touch
        also adds the nodes its uncut step would push into the jaw or the floor (predicted
        contact, :func:`grasprom.fe.model3d._update_active`), so a flat wall closing onto the
        floor enters the active set at once, not node by node.  0 (default) turns it off; on
        through the crease band it changes the path of the crease (docs/fe-model.md).
    predict_contact_below_t : float
        3D only, experimental: the same in wall thicknesses (predicted contact below a jaw gap
        of this times the case's thickness); the larger of the two gaps counts.  One value
        serves a thickness sweep (``grasprom sweep --predict-contact-below``), whose cases must
        share their solver settings.
    unload_from_N : float
        3D only: once the walls have met (gap below 2 t) and the jaw force has reached this
        (N), or at the end of a case that ends inside the crease band, the state is unloaded
        back up through the band (to gap 4 t) and replaces the loaded rows where it holds less
        strain energy (:func:`grasprom.fe.crease.unload_band`: a lower branch the loading did
        not reach).  0 (default) turns it off; not with Coulomb friction (it dissipates).
    band_companion : int
        3D only: after the case, a companion run on its mesh with the far zone coarsened by
        this factor (``MeshSpec3D.far_coarsening``; the shipped default mesh's zoned twin for
        2) lands on the case's crease-band gaps, and wherever its state, moved to the case's
        mesh and solved there, holds less strain energy, it replaces the case's row
        (:func:`grasprom.fe.bandselect.run_case_3d_selected`, which the sweep runs).  0
        (default) turns it off.
    """

    dh_initial_mm: float = 0.05
    dh_min_mm: float = 1e-5
    dh_max_mm: float = 0.5
    max_rel_force_step: float = 0.25
    force_floor_N: float = 0.05
    approach_fraction: float = 0.2
    max_newton: int = 30
    max_active_set: int = 30
    rtol: float = 1e-9
    land_on_gaps_mm: tuple[float, ...] = ()
    relax_below_mm: float = 2e-3
    max_relax: int = 200
    crease_step_fraction: float = 0.025
    maxwell_crease: bool = True
    predict_contact_below_mm: float = 0.0
    predict_contact_below_t: float = 0.0
    unload_from_N: float = 0.0
    band_companion: int = 0

    def __post_init__(self):
        if not self.unload_from_N >= 0.0:  # NaN fails too
            raise ValueError(
                f"SolverSettings.unload_from_N must be >= 0 N (0 = off), got {self.unload_from_N!r}"
            )
        k = self.band_companion
        if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 0:
            raise ValueError(
                "SolverSettings.band_companion must be an integer >= 0 (a far_coarsening; "
                f"0 = off), got {k!r}"
            )


@dataclass(frozen=True)
class CaseSpec:
    """One FE case: a tube of one wall thickness and material clamped by flat jaws.

    Parameters
    ----------
    material : str
        ``mr``, ``nh`` or ``le`` (see :mod:`grasprom.fe.materials`).
    thickness_mm : float
        Wall thickness (mm).
    diameter_mm : float
        Outer diameter of the tube (mm).
    jaw_length_mm : float
        Length of tube squeezed by the jaws (mm): out-of-plane depth of the 2D model.
    closed_gap_mm : float
        Jaw gap at full closure (mm); Guachi et al. (2020): 1.5 mm staple cartridge.
    force_cap_N : float
        Stop once the jaw force passes this (N).
    mesh : MeshSpec
    solver : SolverSettings
    nu : float or None
        Poisson ratio override for the material (None: material default 0.49).
    contact : str
        Jaw contact law, one of :data:`CONTACTS_2D`: ``"frictionless"`` (default: the shipped
        2D data set), ``"stick"`` (no sliding once a node touches the jaw, Guachi et al. (2020))
        or ``"coulomb"`` (stuck until the tangential reaction passes ``friction`` times the
        normal one, then sliding against a friction force of that size).
    friction : float
        Coulomb coefficient (-), only with ``contact="coulomb"`` (> 0 there, 0 otherwise).
    """

    material: str
    thickness_mm: float
    diameter_mm: float = 30.0
    jaw_length_mm: float = 10.0
    closed_gap_mm: float = 1.5
    force_cap_N: float = 200.0
    mesh: MeshSpec = field(default_factory=MeshSpec)
    solver: SolverSettings = field(default_factory=SolverSettings)
    nu: float | None = None
    contact: str = "frictionless"
    friction: float = 0.0

    def make_material(self) -> Material:
        """The material object of this case."""
        kw = {} if self.nu is None else {"nu": self.nu}
        return get_material(self.material, **kw)


@dataclass
class CaseResult:
    """Result of :func:`run_case`.

    Attributes
    ----------
    table : pandas.DataFrame
        One row per converged load step, columns :data:`COLUMNS` (units in
        :data:`COLUMN_DESCRIPTIONS`).
    status : str
        ``"complete"`` (closed gap or force cap reached) or ``"partial"``.
    info : dict
        JSON-serialisable solver record: steps, newton_iterations, failures,
        last_gap_mm, dofs, wall_time_s, material constants, mesh, solver settings.
    """

    table: pd.DataFrame
    status: str
    info: dict


# ----------------------------------------------------------------------------------------------
# mesh and discretisation
# ----------------------------------------------------------------------------------------------


def ring_mesh(outer_radius: float, thickness: float, mesh: MeshSpec):
    """Quarter-ring triangle mesh (skfem ``MeshTri``), lengths in mm.

    Node ``(i, j)``: layer ``i`` from the inner wall, circumferential index ``j`` from the side
    (``theta = 0``, on ``y = 0``) to the top (``theta = 90 deg``, on ``x = 0``).  Every quad is cut
    along the diagonal through its ``(i, j)``-``(i+1, j+1)`` corners, so the inner fold corner
    (``i = j = 0``) is shared by two triangles.
    """
    import skfem

    nl, nc = int(mesh.n_layers), int(mesh.n_circ)
    if nl < 1 or nc < 4:
        raise ValueError(f"mesh too coarse: n_layers={nl} (>= 1), n_circ={nc} (>= 4)")
    mesh = mesh.for_wall(outer_radius - thickness, thickness)
    r = mesh.layer_edges(outer_radius - thickness, thickness)
    th = 0.5 * np.pi * graded_fractions(nc, mesh.grading)
    R, T = np.meshgrid(r, th, indexing="ij")
    x = R * np.cos(T)
    y = R * np.sin(T)
    x[:, -1] = 0.0
    y[:, 0] = 0.0
    pts = np.vstack([x.ravel(), y.ravel()])
    idx = np.arange((nl + 1) * (nc + 1)).reshape(nl + 1, nc + 1)
    a = idx[:-1, :-1].ravel()
    b = idx[1:, :-1].ravel()
    c = idx[1:, 1:].ravel()
    d = idx[:-1, 1:].ravel()
    tris = np.hstack([np.vstack([a, b, c]), np.vstack([a, c, d])])
    return skfem.MeshTri(pts, tris)


ELEMENTS = ("P2B/P1", "P2/P0")

ELEMENT_DESCRIPTIONS = {
    "P2B/P1": "P2 triangle + cubic bubble, 6-point rule, linear discontinuous pressure and "
    "dilatation per element (P2B/P1)",
    "P2/P0": "P2 triangle, 6-point rule, per-element mean dilatation (P2/P0)",
}
"""The ``fe_info.element`` text of a case sidecar, per :attr:`MeshSpec.element`."""


@dataclass(frozen=True)
class _Discretisation:
    """Precomputed arrays of the discretisation (internal)."""

    ndof: int
    edofs: np.ndarray  # (ne, nd) vector dofs
    B: np.ndarray  # (ne, nq, 4, nd) gradient operator: vec(grad u)[2 i + j] = B @ u_e
    Bt: np.ndarray  # (ne, nq, nd, 4) its transpose, contiguous
    dx: np.ndarray  # (ne, nq) quadrature weights x |det J|
    psi: np.ndarray  # (ne, nq, npr) discontinuous pressure/dilatation basis at the points
    wpsi: np.ndarray  # (ne, nq, npr) dx * psi
    Minv: np.ndarray  # (ne, npr, npr) inverse element mass matrix of psi
    X: np.ndarray  # (nnode, 2) reference coordinates of the nodes (bubbles: centroid)
    bubble_nodes: np.ndarray  # ids of the interior bubble "nodes" (coefficients, not positions)
    sym_x: np.ndarray  # vector dofs with u_x = 0
    sym_y: np.ndarray  # vector dofs with u_y = 0
    outer_nodes: np.ndarray  # nodes on the outer wall (jaw contact candidates)
    inner_nodes: np.ndarray  # nodes on the inner wall (floor contact candidates)
    outer_edges: np.ndarray  # (nedge, 3) node triples (end, end, mid) on the outer wall
    rows: np.ndarray  # CSR assembly maps
    cols: np.ndarray
    scatter: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    diag_pos: np.ndarray  # position of the diagonal entries in CSR data


def discretise(outer_radius: float, thickness: float, mesh: MeshSpec) -> _Discretisation:
    """Build basis, quadrature data, boundary sets and the sparse assembly map.

    ``mesh.element`` selects the displacement/dilatation pair: ``"P2B/P1"`` (quadratic +
    cubic bubble displacement, linear discontinuous pressure and dilatation per element,
    Crouzeix-Raviart, inf-sup stable, captures the linear through-thickness dilatation of
    bending) or ``"P2/P0"`` (quadratic displacement, constant per element: classic mean
    dilatation, too soft in bending with few layers).
    """
    import skfem

    if mesh.element not in ELEMENTS:
        raise ValueError(f"unknown element {mesh.element!r}; valid: {', '.join(ELEMENTS)}")
    m = ring_mesh(outer_radius, thickness, mesh)
    bubble = mesh.element == "P2B/P1"
    elem = skfem.ElementTriP2B() if bubble else skfem.ElementTriP2()
    basis = skfem.Basis(m, elem, intorder=4)
    nloc = elem.doflocs.shape[0]
    B, dx = _gradient_operator(basis, nloc)
    psi = _pressure_basis(m, basis, dx, bubble)
    wpsi = dx[..., None] * psi
    Minv = np.linalg.inv(np.einsum("eqk,eql->ekl", wpsi, psi))
    sdofs = basis.element_dofs.T  # (ne, nloc) scalar dofs = node ids
    edofs = np.empty((sdofs.shape[0], 2 * nloc), dtype=np.int64)
    edofs[:, 0::2] = 2 * sdofs
    edofs[:, 1::2] = 2 * sdofs + 1
    X = basis.doflocs.T.copy()
    if bubble:
        X[basis.interior_dofs[0]] = m.p[:, m.t].mean(axis=1).T
    ndof = 2 * X.shape[0]
    sym_x, sym_y, on_y0 = _symmetry_dofs(basis, X, outer_radius, bubble)
    outer_edges, outer_nodes, inner_nodes = _wall_nodes(
        m,
        basis,
        outer_radius,
        thickness,
        float(np.diff(mesh.layer_edges(0.0, thickness)).min()),
        on_y0,
    )
    rows, cols, scatter, indptr, diag_pos = _csr_map(edofs, ndof)
    return _Discretisation(
        ndof=ndof,
        edofs=edofs,
        B=B,
        Bt=np.ascontiguousarray(B.transpose(0, 1, 3, 2)),
        dx=dx,
        psi=psi,
        wpsi=wpsi,
        Minv=Minv,
        X=X,
        bubble_nodes=np.asarray(basis.interior_dofs[0]) if bubble else np.zeros(0, dtype=int),
        sym_x=sym_x,
        sym_y=sym_y,
        outer_nodes=outer_nodes,
        inner_nodes=inner_nodes,
        outer_edges=outer_edges,
        rows=rows,
        cols=cols,
        scatter=scatter.ravel(),
        indptr=indptr,
        indices=cols.astype(np.int32),
        diag_pos=diag_pos,
    )


def _gradient_operator(basis, nloc: int) -> tuple[np.ndarray, np.ndarray]:
    """``B`` (ne, nq, 4, 2 nloc) with ``vec(grad u) = B @ u_e`` (1/mm), and ``dx`` (ne, nq)."""
    grads = np.stack([basis.basis[a][0].grad for a in range(nloc)])  # (nloc, 2, ne, nq)
    grads = grads.transpose(2, 3, 0, 1)  # (ne, nq, nloc, 2)
    ne, nq = grads.shape[:2]
    B = np.zeros((ne, nq, 2, 2, nloc, 2))  # [i, j, a, k] = delta_ik dN_a/dX_j
    for i in range(2):
        B[:, :, i, :, :, i] = grads.transpose(0, 1, 3, 2)
    B = B.reshape(ne, nq, 4, 2 * nloc)
    return B, np.asarray(basis.dx)


def _pressure_basis(m, basis, dx: np.ndarray, bubble: bool) -> np.ndarray:
    """Discontinuous pressure/dilatation basis at the quadrature points, (ne, nq, npr).

    P1 (1, scaled x and y about the centroid) with the bubble element, else P0 (1).
    """
    ne, nq = dx.shape
    if not bubble:
        return np.ones((ne, nq, 1))
    xq = basis.mapping.F(basis.X)  # (2, ne, nq) physical quadrature points
    xc = m.p[:, m.t].mean(axis=1)  # (2, ne)
    hsz = np.sqrt(dx.sum(axis=1))
    return np.stack(
        [
            np.ones((ne, nq)),
            (xq[0] - xc[0][:, None]) / hsz[:, None],
            (xq[1] - xc[1][:, None]) / hsz[:, None],
        ],
        axis=-1,
    )


def _symmetry_dofs(basis, X: np.ndarray, outer_radius: float, bubble: bool):
    """Vector dofs with ``u_x = 0`` (on ``x = 0``), with ``u_y = 0`` (on ``y = 0``), and the
    node mask of ``y = 0`` (bubble coefficients excluded)."""
    tol = 1e-9 * outer_radius
    on_x0 = np.abs(X[:, 0]) < tol
    on_y0 = np.abs(X[:, 1]) < tol
    if bubble:
        on_x0[basis.interior_dofs[0]] = False
        on_y0[basis.interior_dofs[0]] = False
    return 2 * np.flatnonzero(on_x0), 2 * np.flatnonzero(on_y0) + 1, on_y0


def _wall_nodes(m, basis, outer_radius: float, thickness: float, h_r: float, on_y0):
    """Outer-wall edges (end, end, mid node triples) and nodes, and the inner-wall nodes off
    ``y = 0`` (contact candidates with the jaw and the symmetry floor)."""
    rin = outer_radius - thickness
    on_bnd = np.zeros(m.facets.shape[1], dtype=bool)
    on_bnd[m.boundary_facets()] = True
    rmid = np.hypot(*m.p[:, m.facets].mean(axis=1))
    outer_f = np.flatnonzero(on_bnd & (rmid > outer_radius - 0.25 * h_r))
    inner_f = np.flatnonzero(on_bnd & (rmid < rin + 0.25 * h_r))

    def edge_nodes(facets):
        return np.hstack([m.facets[:, facets].T, basis.facet_dofs[:, facets].T])

    outer_edges = edge_nodes(outer_f)
    outer_nodes = np.unique(outer_edges)
    inner_nodes = np.unique(edge_nodes(inner_f))
    inner_nodes = inner_nodes[~on_y0[inner_nodes]]  # the fold corner is on y = 0 already
    return outer_edges, outer_nodes, inner_nodes


def _csr_map(edofs: np.ndarray, ndof: int):
    """CSR pattern of the element dofs: unique rows/cols, element-entry -> CSR position map,
    row pointer and the positions of the diagonal."""
    nd = edofs.shape[1]
    rows = np.repeat(edofs, nd, axis=1).ravel()
    cols = np.tile(edofs, (1, nd)).ravel()
    keys = rows * ndof + cols
    uniq, scatter = np.unique(keys, return_inverse=True)
    urows = uniq // ndof
    ucols = uniq % ndof
    indptr = np.searchsorted(urows, np.arange(ndof + 1))
    diag_pos = np.flatnonzero(urows == ucols)
    return urows, ucols, scatter, indptr, diag_pos


# ----------------------------------------------------------------------------------------------
# vectorised element kernels
# ----------------------------------------------------------------------------------------------


def _kinematics(disc: _Discretisation, u: np.ndarray):
    ue = u[disc.edofs]  # (ne, nd)
    F = np.matmul(disc.B, ue[:, None, :, None]).reshape(ue.shape[0], -1, 2, 2)
    F[..., 0, 0] += 1.0
    F[..., 1, 1] += 1.0
    J = F[..., 0, 0] * F[..., 1, 1] - F[..., 0, 1] * F[..., 1, 0]
    return F, J


def _dilatation(disc: _Discretisation, J: np.ndarray) -> np.ndarray:
    """Element-wise L2 projection of det F on the pressure space, at the points (ne, nq)."""
    c = np.einsum("ekl,eql,eq->ek", disc.Minv, disc.wpsi, J)
    return np.einsum("eqk,ek->eq", disc.psi, c)


def energy(disc: _Discretisation, material: Material, u: np.ndarray) -> float:
    """Strain energy per unit length (N mm / mm) of the quarter model; inf if inverted."""
    F, J = _kinematics(disc, u)
    if not np.all(J > 0):
        return np.inf
    theta = _dilatation(disc, J)
    if not np.all(theta > 0):
        return np.inf
    a = np.einsum("eqij,eqij->eq", F, F)
    W = material.pointwise(a, J)[0] + material.volumetric(theta)[0]
    return float((disc.dx * W).sum())


def assemble(disc: _Discretisation, material: Material, u: np.ndarray, tangent: bool = True):
    """Internal force (N/mm), optionally the CSR tangent (N/mm^2), and min det F.

    Returns ``(None, None, minJ)`` if an element is inverted.
    """
    F, J = _kinematics(disc, u)
    minJ = float(J.min())
    if minJ <= 0:
        return None, None, minJ
    theta = _dilatation(disc, J)
    if not np.all(theta > 0):
        return None, None, minJ
    a = np.einsum("eqij,eqij->eq", F, F)
    cof = cofactor(F)
    _, W_a, W_J, W_aa, W_aJ, W_JJ = material.pointwise(a, J)
    _, dU, ddU = material.volumetric(theta)
    # pressure: projection of U'(theta) on the pressure space
    pc = np.einsum("ekl,eql,eq->ek", disc.Minv, disc.wpsi, dU)
    p = np.einsum("eqk,ek->eq", disc.psi, pc)
    W_Jt = W_J + p
    P = 2.0 * W_a[..., None, None] * F + W_Jt[..., None, None] * cof
    ne, nq = disc.dx.shape
    dx = disc.dx[..., None, None]
    fe = (np.matmul(disc.Bt, P.reshape(ne, nq, 4, 1)) * dx).sum(axis=1)[..., 0]
    f = np.bincount(disc.edofs.ravel(), weights=fe.ravel(), minlength=disc.ndof)
    if not tangent:
        return f, None, minJ
    A = pointwise_tangent(F, cof, W_a, W_Jt, W_aa, W_aJ, W_JJ).reshape(ne, nq, 4, 4) * dx
    Ke = np.matmul(disc.Bt, np.matmul(A, disc.B)).sum(axis=1)
    # volumetric coupling: G = int psi dJ/du, K += G^T Minv D Minv G
    gq = np.matmul(disc.Bt, cof.reshape(ne, nq, 4, 1))[..., 0]  # (ne, nq, nd)
    G = np.einsum("eqk,eqd->ekd", disc.wpsi, gq)
    D = np.einsum("eqk,eql,eq->ekl", disc.wpsi, disc.psi, ddU)
    MG = np.matmul(disc.Minv, G)
    Ke += np.matmul(MG.transpose(0, 2, 1), np.matmul(D, MG))
    data = np.bincount(disc.scatter, weights=Ke.ravel(), minlength=disc.rows.size)
    K = sp.csr_matrix((data, disc.indices, disc.indptr), shape=(disc.ndof, disc.ndof))
    return f, K, minJ


# ----------------------------------------------------------------------------------------------
# contact + Newton
# ----------------------------------------------------------------------------------------------


def _constrained_system(disc: _Discretisation, K: sp.csr_matrix, fixed: np.ndarray):
    """Copy of K with rows/cols of ``fixed`` dofs replaced by identity."""
    keep = ~(fixed[disc.rows] | fixed[disc.cols])
    data = K.data * keep
    data[disc.diag_pos[fixed]] = 1.0
    return sp.csr_matrix((data, disc.indices, disc.indptr), shape=K.shape)


class _NewtonFailure(Exception):
    pass


def check_friction(contact: str, friction: float) -> None:
    """Refuse a friction coefficient that does not fit the contact law (2D and 3D models).

    Parameters
    ----------
    contact : str
        The jaw contact law.
    friction : float
        Coulomb coefficient (-): > 0 and finite with ``contact="coulomb"``, 0 otherwise.

    Raises
    ------
    ValueError
        Naming ``friction`` and the contact law.
    """
    mu = friction
    if contact == "coulomb" and not (np.isfinite(mu) and mu > 0):
        raise ValueError(f"invalid friction={mu!r}: contact='coulomb' needs a coefficient > 0")
    if contact != "coulomb" and mu != 0:
        raise ValueError(f"invalid friction={mu!r}: only used with contact='coulomb'")


def _plus_diagonal(disc: _Discretisation, K: sp.csr_matrix, D: sp.spmatrix) -> sp.csr_matrix:
    """``K + D`` for a diagonal ``D``, kept on the discretisation's CSR pattern.

    A scipy sum drops the explicit zeros of ``K``, after which ``K.data`` no longer lines up
    with ``disc.rows`` / ``disc.diag_pos`` (:func:`_constrained_system` relies on it).
    """
    data = K.data.copy()
    data[disc.diag_pos] += D.diagonal()
    return sp.csr_matrix((data, disc.indices, disc.indptr), shape=K.shape)


def _prox_terms(disc, fixed: np.ndarray, prox):
    """Energy, force and tangent of the proximal term ``c/2 |u - u_ref|^2`` on the free dofs
    (:func:`_relax`); ``prox`` is ``(c, u_ref)`` or None (no term)."""
    if prox is None:
        return (lambda u: 0.0), (lambda u: 0.0), None
    c, u_ref = prox
    free = (~fixed).astype(float)

    def e(u):
        d = (u - u_ref) * free
        return 0.5 * c * float(d @ d)

    return e, (lambda u: c * (u - u_ref) * free), sp.diags(c * free, format="csr")


def _newton(
    disc,
    material,
    u,
    fixed,
    settings: SolverSettings,
    fscale: float,
    prox=None,
    extra=None,
    *,
    solve,
):
    """Newton-Raphson with energy line search on the free dofs; returns (u, f, K, iters).

    ``prox = (c, u_ref)`` adds ``c/2 |u - u_ref|^2`` (N/mm per mm^2) to the energy: one step
    of the proximal-point iteration of :func:`_relax`; ``f`` and ``K`` returned are then the
    regularised ones.  ``extra = (energy, force, tangent)`` (functions of ``u``, or None) adds
    a potential of the contact (the Coulomb friction of :class:`_Friction`); ``f`` returned
    is without its force (the internal force: at a node in contact its ``x`` part is the
    jaw's tangential reaction, as at a fixed dof).  ``solve(K, rhs)``: the linear solver
    (:func:`grasprom.fe.linsolve.make_solver`).
    """
    e_prox, f_prox, k_prox = _prox_terms(disc, fixed, prox)
    e_x, f_x, k_x = extra if extra is not None else (None, None, None)

    def assemble_p(u, tangent=True):
        f, K, minJ = assemble(disc, material, u, tangent)
        if f is None:
            return f, K, minJ
        if prox is not None:
            f, K = f + f_prox(u), (_plus_diagonal(disc, K, k_prox) if K is not None else None)
        if extra is not None:
            f, K = f + f_x(u), (_plus_diagonal(disc, K, k_x(u)) if K is not None else None)
        return f, K, minJ

    def energy_p(u):
        e = energy(disc, material, u) + e_prox(u)
        return e + e_x(u) if extra is not None else e

    f, K, minJ = assemble_p(u)
    if f is None:
        raise _NewtonFailure("inverted element at start of Newton")
    tol = settings.rtol * fscale
    for it in range(1, settings.max_newton + 1):
        r = f.copy()
        r[fixed] = 0.0
        rnorm = np.linalg.norm(r)
        if rnorm <= tol:
            return u, (f - f_x(u) if extra is not None else f), K, it - 1
        du = descent_direction(solve, _constrained_system(disc, K, fixed), r)
        if du is None:
            raise _NewtonFailure("no descent direction")
        du[fixed] = 0.0
        e0 = energy_p(u)
        slope = r @ du
        alpha = 1.0
        accepted = False
        for _ in range(12):
            ut = u + alpha * du
            et = energy_p(ut)
            if np.isfinite(et):
                if et <= e0 + 1e-4 * alpha * slope:
                    accepted = True
                    break
                if alpha == 1.0:
                    ft, _, _ = assemble_p(ut, tangent=False)
                    rt = ft.copy()
                    rt[fixed] = 0.0
                    if np.linalg.norm(rt) < 0.5 * rnorm:
                        accepted = True
                        break
            alpha *= 0.5
        if not accepted:
            raise _NewtonFailure("line search failed")
        u = ut
        f, K, minJ = assemble_p(u)
        if f is None:  # pragma: no cover - energy check prevents this
            raise _NewtonFailure("inverted element")
    raise _NewtonFailure("Newton did not converge")


@dataclass
class _State:
    u: np.ndarray
    jaw_active: np.ndarray  # bool over disc.outer_nodes
    floor_active: np.ndarray  # bool over disc.inner_nodes
    anchor_x: np.ndarray  # x (mm) where each outer node stuck to the jaw (stick contact)
    stick: bool = False
    f: np.ndarray | None = None
    K: sp.csr_matrix | None = None
    mu: float = np.inf  # Coulomb coefficient (finite: contact="coulomb", :class:`_Friction`)
    lag_newton: int = 0  # Newton iterations spent re-solving for the lagged friction normal
    h: float = np.nan  # jaw height (mm) of the state (touch points of the next step)


FRICTION_EPS_MM = 1e-3
"""Stick regularisation of ``contact="coulomb"`` (mm): a node in contact creeps by up to about
this before its friction force reaches ``mu N`` (a micrometre: 1 % of the 2D mesh's smallest
element, far below the surrogate's 0.02 mm gap budget)."""


@dataclass
class _Friction:
    """Coulomb friction of the outer nodes on the jaw during one load step (internal).

    Each node in contact with the jaw is held at its anchor ``a`` (where it was at the start of
    the step, or where it touched) by the regularised Coulomb potential
    ``c (sqrt(d^2 + e^2) - e)``, ``d = x - a``, ``c = mu N``, ``e`` = :data:`FRICTION_EPS_MM`:
    its force ``c d / sqrt(d^2 + e^2)`` is stiff (``c / e``) about ``d = 0`` (stick) and tends
    to ``c`` (sliding); smooth and convex, so Newton with the energy line search handles stick
    and slip without an active set.  ``N`` is the normal reaction of the previous solve
    (lagged: the step is re-solved until ``N`` settles).  At the end of a step the anchor
    follows the slide beyond ``e``.  The jaw does not move in ``x``.
    """

    mu: float
    eps: float  # mm, the stick regularisation (slide at which the force is c / sqrt(2))
    anchor: np.ndarray  # x (mm) of each outer node's anchor for this step
    normal: np.ndarray  # N (N/mm, >= 0) of each outer node, as used in the cap

    @classmethod
    def start(cls, disc, state: _State) -> _Friction | None:
        """The friction state at the start of a step (None unless Coulomb contact)."""
        if not np.isfinite(state.mu):
            return None
        on = disc.outer_nodes
        normal = np.zeros(on.size) if state.f is None else np.maximum(-state.f[2 * on + 1], 0)
        return cls(state.mu, FRICTION_EPS_MM, state.anchor_x.copy(), normal)

    def terms(self, disc, jaw_active: np.ndarray):
        """Energy (N mm/mm), force (N/mm) and tangent (N/mm^2) of the friction potential as
        functions of ``u`` (the ``extra`` of :func:`_newton`)."""
        sel = jaw_active & (self.normal > 0)
        on = disc.outer_nodes[sel]
        a, c = self.anchor[sel], self.mu * self.normal[sel]
        eps = self.eps  # mm: the slide at which the force reaches c / sqrt(2)
        X0 = disc.X[on, 0]

        def root(u):
            d = X0 + u[2 * on] - a
            return d, np.sqrt(d * d + eps * eps)

        def e(u):
            d, r = root(u)
            return float((c * (r - eps)).sum())

        def f(u):
            d, r = root(u)
            out = np.zeros(disc.ndof)
            out[2 * on] = c * d / r
            return out

        def K(u):
            d, r = root(u)
            diag = np.zeros(disc.ndof)
            diag[2 * on] = c * eps * eps / r**3
            return sp.diags(diag, format="csr")

        return e, f, K

    def settled(self, disc, f: np.ndarray, jaw_active: np.ndarray, rtol: float = 1e-5) -> bool:
        """Take the normal reactions of the last solve; True if they moved by at most ``rtol``
        of the largest one (the cap it used is then the cap of this solution)."""
        n_new = np.maximum(-f[2 * disc.outer_nodes + 1], 0.0)
        scale = max(float(n_new[jaw_active].max(initial=0.0)), 1e-12)
        moved = np.abs(n_new - self.normal)[jaw_active].max(initial=0.0) > rtol * scale
        self.normal = n_new
        return not moved

    def step_end_anchor(self, disc, jaw_active: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Anchors (mm) for the next step: moved by the slide beyond the elastic part."""
        on = disc.outer_nodes
        x = disc.X[on, 0] + u[2 * on]
        e = self.eps
        d = x - self.anchor
        out = self.anchor.copy()
        out[jaw_active] = (x - np.clip(d, -e, e))[jaw_active]
        return out


def _fixed_and_values(disc, state: _State, h: float):
    fixed = np.zeros(disc.ndof, dtype=bool)
    values = np.zeros(disc.ndof)
    fixed[disc.sym_x] = True
    fixed[disc.sym_y] = True
    jn = disc.outer_nodes[state.jaw_active]
    fixed[2 * jn + 1] = True
    values[2 * jn + 1] = h - disc.X[jn, 1]
    if state.stick:
        fixed[2 * jn] = True
        values[2 * jn] = state.anchor_x[state.jaw_active] - disc.X[jn, 0]
    fnode = disc.inner_nodes[state.floor_active]
    fixed[2 * fnode + 1] = True
    values[2 * fnode + 1] = -disc.X[fnode, 1]
    return fixed, values


def touch_x(disc, u0: np.ndarray, u1: np.ndarray, nodes: np.ndarray, h0, h1: float):
    """Stick anchors (x, mm) where outer ``nodes`` first touch the flat jaw on their way
    through a step (the 2D counterpart of :func:`grasprom.fe.model3d.touch_points`).

    Each node moves on the straight path from its position under ``u0`` (mm, the step's start)
    to its position under ``u1`` (the end, above the jaw), while the jaw face ``y = h`` moves
    from ``h0`` to ``h1`` (mm), both linear in a path parameter ``s``.  The node touches where
    ``y(s) = h(s)``: ``s = (h0 - y0) / ((h0 - y0) + (y1 - h1))``, clipped to [0, 1].  A node
    already on the jaw at the start (``y0 >= h0``: released there, by this step's passes or
    the last step's, and back) keeps the projection rule, the end position's x: anchored at its
    start it would be held where it just pulled off, released again and re-added, without end
    (the 2D default case, t = 0.8 mm, crawled at gap 17.88 mm).  Where ``h0`` is unknown (NaN)
    the projection rule too.

    Parameters
    ----------
    disc : discretisation
        Its reference coordinates ``X`` (mm).
    u0, u1 : ndarray
        Nodal displacements (mm) at the step's start and end, interleaved ``(ux, uy)``.
    nodes : ndarray of int
        The nodes that entered the contact.
    h0 : float or ndarray
        Jaw height (mm) at the start, one for all nodes or one each (NaN: the node's start does
        not count, e.g. it was released during the step).
    h1 : float
        Jaw height (mm) at the end.

    Returns
    -------
    ndarray
        x (mm) of each node's touch point.
    """
    X = disc.X[nodes]
    x0, y0 = X[:, 0] + u0[2 * nodes], X[:, 1] + u0[2 * nodes + 1]
    x1, y1 = X[:, 0] + u1[2 * nodes], X[:, 1] + u1[2 * nodes + 1]
    below, above = h0 - y0, y1 - h1  # NaN where h0 is: "below > 0" is then False
    denom = below + above
    s = np.clip(np.divide(below, denom, out=np.ones_like(denom), where=denom > 0), 0.0, 1.0)
    return np.where(below > 0.0, x0 + s * (x1 - x0), x1)


def _solve_step(
    disc,
    material,
    state: _State,
    h: float,
    settings: SolverSettings,
    fscale,
    prox=None,
    *,
    solve,
):
    """Solve equilibrium at jaw height ``h`` (mm) with the active-set loop.

    ``prox = (c, u_ref)``: solve the proximally regularised problem instead (:func:`_relax`).
    Returns the state and the Newton iterations that measure the step's effort (step control);
    Coulomb contact's re-solves for the lagged normal force are in ``state.lag_newton``.
    """
    jaw_active = state.jaw_active.copy()
    floor_active = state.floor_active.copy()
    anchor_x = state.anchor_x.copy()
    fric = _Friction.start(disc, state)
    u = state.u.copy()
    K_old = state.K
    iters = lag = 0
    lagged = False  # this pass only re-solves for the friction normal of the last pass
    released = np.zeros_like(jaw_active)  # jaw nodes this step's passes released
    tol_pen = 1e-9 * max(1.0, h)
    for _ in range(settings.max_active_set):
        trial = _State(u, jaw_active, floor_active, anchor_x, state.stick, mu=state.mu)
        fixed, values = _fixed_and_values(disc, trial, h)
        jump = np.where(fixed, values - u, 0.0)
        if np.any(jump != 0.0):
            # tangent predictor: free dofs follow the prescribed jump to first order
            if K_old is not None:
                rhs = -(K_old @ jump)
                rhs[fixed] = 0.0
                Kc = _constrained_system(disc, K_old, fixed)
                try:
                    dfree = solve(Kc, rhs)
                except RuntimeError:  # singular tangent: no predictor
                    dfree = np.full_like(rhs, np.nan)
                dfree[fixed] = 0.0
                if np.all(np.isfinite(dfree)):
                    u = u + dfree
            u = u + jump
        extra = fric.terms(disc, jaw_active) if fric is not None else None
        u, f, K, it = _newton(disc, material, u, fixed, settings, fscale, prox, extra, solve=solve)
        lag, iters = (lag + it, iters) if lagged else (lag, iters + it)
        K_old = K
        y = disc.X[:, 1] + u[1::2]
        fy = f[1::2]
        # jaw: release tensile (jaw pulling the tissue up), add penetrating nodes
        on = disc.outer_nodes
        new_jaw = np.where(jaw_active, fy[on] <= 0.0, y[on] > h + tol_pen)
        inn = disc.inner_nodes
        new_floor = np.where(floor_active, fy[inn] >= 0.0, y[inn] < -tol_pen)
        settled = fric is None or fric.settled(disc, f, jaw_active)
        same = np.array_equal(new_jaw, jaw_active) and np.array_equal(new_floor, floor_active)
        lagged = same and not settled
        if same and settled:
            done = _State(u, jaw_active, floor_active, anchor_x, state.stick, f, K, state.mu)
            done.h = h
            if fric is not None:  # the anchors follow the slide
                done.anchor_x = fric.step_end_anchor(disc, jaw_active, u)
                done.lag_newton = lag
            return done, iters
        added = new_jaw & ~jaw_active
        # stick where it touched on the way from the step's start; a node this step already
        # released comes back at its end position (a touch anchor that did not hold would cycle)
        released |= jaw_active & ~new_jaw
        h0 = np.where(released[added], np.nan, state.h)
        anchor_x[added] = touch_x(disc, state.u, u, on[added], h0, h)
        if fric is not None:
            fric.anchor[added] = anchor_x[added]
        jaw_active, floor_active = new_jaw, new_floor
    raise _NewtonFailure("active set did not settle")


_STEP_ERRORS = (_NewtonFailure, RuntimeError, ValueError, FloatingPointError)
"""What a failed load step raises (cut the step and retry)."""


def _advance(disc, material, state: _State, h: float, settings: SolverSettings, fscale, dh, solve):
    """The step to jaw height ``h`` (mm): Newton with the active set, and if a jaw step ``dh``
    (mm) of at most ``settings.relax_below_mm`` fails, the snap by :func:`_relax`."""
    try:
        return _solve_step(disc, material, state, h, settings, fscale, solve=solve)
    except _STEP_ERRORS:
        if dh > settings.relax_below_mm:
            raise
    return _relax(disc, material, state, h, settings, fscale, solve)


def _crease_onset(
    disc,
    material,
    snapped: _State,
    h_snap: float,
    branch,
    t: float,
    settings,
    fscale,
    landing,
    solve,
):
    """Continue a snapped (creased) state back to larger jaw heights while its strain energy
    stays below the smooth branch's (``branch``, :func:`grasprom.fe.crease.hermite_energy`), up
    to the top of the crease band (``h = 2 t``, ``t`` the wall thickness in mm):
    :func:`grasprom.fe.crease.crease_onset` with back steps of a quarter of the band's forward
    step, landing on ``landing`` (mm), the crossing bisected 10 times.
    """

    def below(state: _State, hh: float) -> bool:
        e_s = hermite_energy(branch, hh)
        return energy(disc, material, state.u) < e_s - 1e-10 * abs(e_s)

    def step(state: _State, hh: float):
        return _solve_step(disc, material, state, hh, settings, fscale, solve=solve)

    dh = 0.25 * settings.crease_step_fraction * t
    return crease_onset(step, below, snapped, h_snap, dh, 2.0 * t, landing, _STEP_ERRORS, 10)


def _splice_crease(disc, material, rows: list, branch: list, back: CreaseOnset, R: float, scale_N):
    """Replace the rows (and ``branch`` entries) below the Maxwell point ``back[0]`` by the
    creased states of :func:`_crease_onset` (:func:`grasprom.fe.crease.splice_crease`)."""

    def entry(hb: float, sb: _State, itb: int):
        eb = energy(disc, material, sb.u)
        rb = _step_row(disc, sb, hb, R, scale_N, itb, eb)
        return rb, (hb, eb, rb["force_N"] / scale_N)

    return splice_crease(rows, branch, back, entry)


def _relax(disc, material, state: _State, h: float, settings: SolverSettings, fscale, solve):
    """Equilibrium at jaw height ``h`` (mm) past a snap, by proximal-point iteration.

    Where the wall snaps (the flattened wall buckles inward in the crease band), no equilibrium
    lies near the last one and Newton fails however small the jaw step.  Each proximal step
    minimises ``energy + c/2 |u - u_k|^2`` (strongly convex for ``c`` above the negative
    curvature, so Newton converges), with the contact active set updated, and moves the state a
    bounded distance along the descent path of the energy; ``c`` shrinks while the steps
    converge, and the plain problem is tried after every step.  Quasi-statically this is the
    snap: the state the wall jumps to.  Raises :class:`_NewtonFailure` if it does not land.
    """
    K = state.K if state.K is not None else assemble(disc, material, state.u)[1]
    c = 1e-2 * float(np.abs(K.diagonal()).mean())
    current = state
    for _ in range(settings.max_relax):
        try:
            current, _ = _solve_step(
                disc, material, current, h, settings, fscale, (c, current.u), solve=solve
            )
        except _STEP_ERRORS:
            c *= 4.0
            continue
        try:
            return _solve_step(disc, material, current, h, settings, fscale, solve=solve)
        except _STEP_ERRORS:
            c *= 0.7
    raise _NewtonFailure(f"no equilibrium within {settings.max_relax} proximal steps")


def _contact_measures(disc, state: _State):
    """Jaw force per length of the quarter (N/mm), contact widths (mm), peak pressure (MPa)."""
    u, f = state.u, state.f
    x = disc.X[:, 0] + u[0::2]
    jn = disc.outer_nodes[state.jaw_active]
    force_q = float(-f[2 * jn + 1].sum()) if jn.size else 0.0
    width_q = float(x[jn].max()) if jn.size else 0.0
    peak = 0.0
    if jn.size:
        w = np.zeros(x.size)
        e = disc.outer_edges
        L = np.abs(x[e[:, 1]] - x[e[:, 0]])
        np.add.at(w, e[:, 0], L / 6.0)
        np.add.at(w, e[:, 1], L / 6.0)
        np.add.at(w, e[:, 2], 2.0 * L / 3.0)
        sel = w[jn] > 0
        if np.any(sel):
            peak = float(np.max(-f[2 * jn[sel] + 1] / w[jn][sel]))
    fn = disc.inner_nodes[state.floor_active]
    inner_w = float(x[fn].max() - x[fn].min()) if fn.size else 0.0
    normal = float(np.abs(f[2 * jn + 1]).sum()) if jn.size else 0.0
    tangential = state.stick or np.isfinite(state.mu)
    tang = float(np.abs(f[2 * jn[disc.X[jn, 0] > 0]]).sum()) if tangential and jn.size else 0.0
    share = tang / normal if normal > 0 else 0.0
    return force_q, width_q, peak, inner_w, share


def run_case(spec: CaseSpec, progress=None, solver: str = "auto") -> CaseResult:
    """Run one clamping case: drive the jaw from first touch to the closed gap or force cap.

    Parameters
    ----------
    spec : CaseSpec
        Geometry (mm), material, limits, mesh and solver settings.
    progress : callable, optional
        Called as ``progress(gap_mm, force_N)`` after each converged step.
    solver : str
        Sparse solver (:func:`grasprom.fe.linsolve.make_solver`): ``"auto"`` (MKL PARDISO if
        ``pypardiso`` is installed, else scipy SuperLU), ``"superlu"`` or ``"pardiso"``.  The
        choice changes the forces only by round-off (tested); ``info["linear_solver"]``.

    Returns
    -------
    CaseResult
        Table of converged steps (mm, N, MPa), status and solver record.
    """
    t0 = time.perf_counter()
    _validate_spec(spec)
    material = spec.make_material()
    R = 0.5 * spec.diameter_mm
    t = spec.thickness_mm
    disc = discretise(R, t, spec.mesh)
    solve = make_solver(solver)
    s = spec.solver
    fscale = material.mu * t
    scale_N = 2.0 * spec.jaw_length_mm  # quarter N/mm -> one jaw N
    h_end = 0.5 * spec.closed_gap_mm
    state = _initial_state(disc, material, spec.contact == "stick", R)
    if spec.contact == "coulomb":
        state.mu = float(spec.friction)
    rows = [dict(zip(COLUMNS_2D, (2 * R, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0, 0.0, 0.0)))]
    h, dh = R, s.dh_initial_mm
    landing = sorted((0.5 * g for g in s.land_on_gaps_mm), reverse=True)
    total_newton, force_prev = 0, 0.0
    fail_log: list[dict] = []
    branch = [(h, 0.0, 0.0)]  # (jaw height mm, strain energy, quarter force N/mm) per row
    status, reason = "partial", ""
    while True:
        dh = _limit_step(dh, h, t, h_end, s, landing)
        if dh < s.dh_min_mm and h - h_end > s.dh_min_mm:
            reason = f"step below dh_min_mm={s.dh_min_mm} at gap {2 * h:.4f} mm"
            break
        h_new = h - dh
        try:
            new_state, iters = _advance(disc, material, state, h_new, s, fscale, dh, solve)
        except _STEP_ERRORS as exc:
            fail_log.append({"gap_mm": 2 * h_new, "dh_mm": dh, "reason": str(exc)})
            dh *= 0.25
            continue
        total_newton += iters + new_state.lag_newton
        e_new = energy(disc, material, new_state.u)
        row = _step_row(disc, new_state, h_new, R, scale_N, iters, e_new)
        if s.maxwell_crease and t < h_new < 2.0 * t and row["force_N"] < force_prev * (1 - 1e-4):
            back = _crease_onset(
                disc, material, new_state, h_new, branch, t, s, fscale, landing, solve
            )
            rows, branch = _splice_crease(disc, material, rows, branch, back, R, scale_N)
            total_newton += back.newton_iterations
        state = new_state
        h = h_new
        rows.append(row)
        branch.append((h, e_new, row["force_N"] / scale_N))
        force_N = row["force_N"]
        if progress is not None:
            progress(2 * h, force_N)
        if force_N >= spec.force_cap_N:
            status, reason = "complete", "force cap reached"
            break
        if h <= h_end + 1e-12:
            status, reason = "complete", "closed gap reached"
            break
        dh = _grow_step(dh, iters, force_N, force_prev, s)
        force_prev = force_N
    table = pd.DataFrame(rows, columns=list(COLUMNS_2D))
    info = _solver_record(spec, disc, material, table, reason, total_newton, fail_log, h, t0)
    info["linear_solver"] = solver_name(solve)
    return CaseResult(table=table, status=status, info=info)


def _solver_record(
    spec: CaseSpec,
    disc: _Discretisation,
    material: Material,
    table: pd.DataFrame,
    reason: str,
    total_newton: int,
    fail_log: list[dict],
    h: float,
    t0: float,
) -> dict:
    """The JSON-serialisable ``CaseResult.info`` of a finished run (``h``: last jaw height,
    mm; ``t0``: :func:`time.perf_counter` at the start)."""
    return {
        "status_reason": reason,
        "steps": len(table) - 1,
        "newton_iterations": int(total_newton),
        "failures": len(fail_log),
        "failure_log": fail_log[-20:],
        "last_gap_mm": float(2 * h),
        "max_force_N": float(table["force_N"].max()),
        "dofs": int(disc.ndof),
        "elements": int(disc.edofs.shape[0]),
        "wall_time_s": time.perf_counter() - t0,
        "material_constants": material.constants(),
        "mesh": asdict(spec.mesh),
        "mesh_circ_grading": spec.mesh.for_wall(
            0.5 * spec.diameter_mm - spec.thickness_mm, spec.thickness_mm
        ).grading,
        "solver": asdict(spec.solver),
        "element": ELEMENT_DESCRIPTIONS[spec.mesh.element],
        "force_definition": "force_N = 2 x quarter-model reaction (N/mm) x jaw_length_mm",
    }


def _initial_state(disc: _Discretisation, material: Material, stick: bool, h: float) -> _State:
    """Undeformed state at first touch (jaw height ``h``, mm): the top outer node(s) on the jaw,
    no floor contact."""
    state = _State(
        np.zeros(disc.ndof),
        np.zeros(disc.outer_nodes.size, dtype=bool),
        np.zeros(disc.inner_nodes.size, dtype=bool),
        disc.X[disc.outer_nodes, 0].copy(),
        stick,
        h=h,
    )
    top = np.flatnonzero(np.isclose(disc.X[disc.outer_nodes, 0], 0.0, atol=1e-12))
    state.jaw_active[top] = True
    state.f, state.K, _ = assemble(disc, material, state.u)
    return state


def _limit_step(
    dh: float, h: float, t: float, h_end: float, s: SolverSettings, landing: list[float]
) -> float:
    """Jaw step (mm) from jaw height ``h`` (mm): capped by ``dh_max_mm`` and the closed height,
    geometric on the approach to the walls meeting (``h = t``), landing on the requested gaps."""
    dh = min(dh, s.dh_max_mm, h - h_end)
    if h > t:  # resolve the walls meeting: approach h = t geometrically
        dh = min(dh, max(0.01 * t, s.approach_fraction * (h - t)))
    if t < h <= 2.0 * t + 1e-12:  # crease band
        dh = min(dh, s.crease_step_fraction * t)
    return land_on(h, dh, landing, s.dh_min_mm)


def _step_row(
    disc: _Discretisation,
    state: _State,
    h: float,
    R: float,
    scale_N: float,
    iters: int,
    energy_q: float,
) -> dict:
    """Table row (:data:`COLUMNS_2D`) of a converged step at jaw height ``h`` (mm);
    ``energy_q`` is the quarter model's strain energy (N mm/mm, :func:`energy`)."""
    force_q, width_q, peak, inner_w, share = _contact_measures(disc, state)
    force_N = force_q * scale_N
    _, J = _kinematics(disc, state.u)
    return dict(
        zip(
            COLUMNS_2D,
            (
                2 * h,
                R - h,
                force_N,
                2 * force_q,
                2 * width_q,
                peak,
                force_q / width_q if width_q > 0 else 0.0,
                2 * inner_w,
                float(J.min()),
                iters,
                share,
                2.0 * scale_N * energy_q,  # 4 quarters x jaw length
            ),
        )
    )


def _grow_step(
    dh: float, iters: int, force_N: float, force_prev: float, s: SolverSettings
) -> float:
    """Next jaw step (mm): step control by Newton effort and relative force change."""
    grow = 1.5 if iters <= 6 else (1.0 if iters <= 12 else 0.6)
    dh_next = dh * grow
    if force_N > s.force_floor_N and force_prev > 0:
        rel = (force_N - force_prev) / force_prev
        if rel > 0:
            dh_next = min(dh_next, dh * s.max_rel_force_step / rel)
    return max(dh_next, 2 * s.dh_min_mm)


def _validate_spec(spec: CaseSpec) -> None:
    R = 0.5 * spec.diameter_mm
    checks = (
        ("diameter_mm", spec.diameter_mm, spec.diameter_mm > 0),
        ("thickness_mm", spec.thickness_mm, 0 < spec.thickness_mm < R),
        ("jaw_length_mm", spec.jaw_length_mm, spec.jaw_length_mm > 0),
        ("closed_gap_mm", spec.closed_gap_mm, 0 < spec.closed_gap_mm < spec.diameter_mm),
        ("force_cap_N", spec.force_cap_N, spec.force_cap_N > 0),
    )
    for name, value, ok in checks:
        if not (np.isfinite(value) and ok):
            raise ValueError(f"invalid {name}={value!r} (diameter_mm={spec.diameter_mm})")
    if spec.contact not in CONTACTS_2D:
        raise ValueError(f"invalid contact={spec.contact!r}; valid: {', '.join(CONTACTS_2D)}")
    check_friction(spec.contact, spec.friction)
    for name in ("predict_contact_below_mm", "predict_contact_below_t"):
        value = getattr(spec.solver, name)
        if value != 0.0:
            raise ValueError(
                f"invalid solver.{name}={value!r}: "
                "predicted contact is 3D only (--model 3d); the 2D model takes 0"
            )
    if spec.solver.band_companion != 0:
        raise ValueError(
            f"invalid solver.band_companion={spec.solver.band_companion!r}: the band's companion "
            "run is 3D only (--model 3d); the 2D model takes 0"
        )
