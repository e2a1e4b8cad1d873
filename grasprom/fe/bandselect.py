"""The crease band's lower-energy state across two starts (3D model).

In the crease band (jaw gap ``2 t`` to ``4 t``, ``t`` the wall thickness) the flattened tube
has several equilibria at one gap: the smooth fold and creased states of different patterns.
A run keeps the branch its path reaches, and two meshes' runs can reach different ones (the
shipped default and zoned meshes, which share the jaw zone: up to 19 % apart in the band while
within 0.9 % in bending; docs/fe-model.md).  Moved to a common mesh, the states of two runs
agree within 0.13-0.37 % (*The band on a common start*), so the mesh is not what separates
them: which state is kept is.

:func:`run_case_3d_selected` makes that choice explicit, as Maxwell's rule does along one run
(:mod:`grasprom.fe.crease`): the case runs (:func:`~grasprom.fe.model3d.run_case_3d`), then a
*companion*: the same case on the mesh with the far zone coarsened by
``SolverSettings.band_companion`` (:func:`companion_spec`), landing on the case's band gaps.
Each companion state is moved to the case's mesh
(:func:`~grasprom.fe.transfer3d.transfer_matrix`, built once a case), solved there at its gap
(one :class:`~grasprom.fe.model3d.EquilibriumSolver` a case), and wherever it holds less strain
energy than the case's own state (by more than :data:`BAND_ENERGY_RTOL`), its row replaces the
case's (:func:`select_lower`); a state whose companion force is within
:data:`BAND_MOVE_FORCE_RTOL` of the case's is not moved.  :func:`select_band` does the
companion's part for a case already run (a stored sweep: :mod:`grasprom.fe.reselect`).
Both states are equilibria of the same mesh, so their energies compare
exactly; the two meshes share the jaw zone (the far zone only is coarser), so the stuck contact
nodes move over unchanged.  Gaps in mm, forces in N, energies in mJ.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from grasprom.fe.mesh3d import has_far_zone
from grasprom.fe.model2d import CaseResult
from grasprom.fe.model3d import CaseSpec3D, EquilibriumSolver, axial_grid, run_case_3d
from grasprom.fe.transfer3d import transfer_matrix

__all__ = [
    "BAND_ENERGY_RTOL",
    "BAND_MOVE_FORCE_RTOL",
    "BandChoice",
    "BandSelection",
    "NOT_LANDED",
    "band_gaps",
    "check_companion",
    "companion_spec",
    "companion_states",
    "own_run_spec",
    "run_case_3d_selected",
    "select_band",
    "select_lower",
]

#: A moved state replaces the case's own where its strain energy is lower by more than this
#: share.  With stick contact the anchors are history: states of one branch reached along two
#: paths differ by them (le 1.0 mm, the companion's states moved onto the case's mesh above
#: the crease: 1.9-2.0e-4 of the energy lower on 4 x 36, 2.7-4.2e-4 on 4 x 48, the force
#: within 0.16 %; a coarse case in bending: 2.7e-5, ``tests/fe/test_bandselect.py``), while
#: the crease patterns that separate two runs differ by 0.24-0.77 % (le 1.0 mm, from 0.1 mm
#: past the crease; docs/fe-model.md).  Patterns closer than that stay as each run found them
#: (mr 1.6 mm, default against zoned: 0.06-0.25 %, the forces within 1.5 %).
BAND_ENERGY_RTOL = 1e-3

#: No move where the companion's force (on its own mesh) is within this share of the case's:
#: the row is kept.  A moved state's force follows the companion's (over the 145 moves of
#: five measured cases, moved - own within 0.8 % of companion - own; docs/fe-model.md, *The
#: band's lower state across two starts*), so a kept row is at most about 1.3 % off the moved
#: state's force, inside the band's 3 %, while the states that were taken all had the
#: companion 1.2-8.8 % off the case's force.  It spares the moves of a companion on the
#: case's own branch (61 of those 145, 3-68 Newton iterations each); 0 moves every state.
BAND_MOVE_FORCE_RTOL = 5e-3

#: A companion row counts as landed on a requested gap within this distance (mm): a landing
#: step ends at ``h - (h - h_landing)``, which can differ from the landing height by round-off.
LANDING_TOL_MM = 1e-9


@dataclass(frozen=True)
class BandChoice:
    """The case's own state and the companion's moved state at one band gap.

    Attributes
    ----------
    gap_mm : float
        Jaw gap (mm).
    own_force_N, own_energy_mJ : float
        The case's own state: force on one jaw (N) and strain energy of the tube (mJ).
    companion_force_N : float
        The companion's force on its own mesh (N).
    moved_force_N, moved_energy_mJ : float
        The companion's state solved on the case's mesh (N, mJ); NaN if that failed.
    newton_iterations : int
        Newton iterations of the moved state's solve.
    taken : bool
        Whether the moved state replaced the case's row.
    error : str
        Why the move failed ("" if it did not).
    skipped : bool
        Not moved: the companion's force is within ``move_rtol`` (:func:`select_lower`,
        :data:`BAND_MOVE_FORCE_RTOL`) of the case's, and the row is kept.
    """

    gap_mm: float
    own_force_N: float
    own_energy_mJ: float
    companion_force_N: float
    moved_force_N: float
    moved_energy_mJ: float
    newton_iterations: int
    taken: bool
    error: str = ""
    skipped: bool = False

    def record(self) -> dict[str, Any]:
        """JSON-ready (NaN -> None) for the case sidecar's ``fe_info.band_selection``."""
        out: dict[str, Any] = {}
        for k, v in self.__dict__.items():
            out[k] = None if isinstance(v, float) and not math.isfinite(v) else v
        return out


@dataclass(frozen=True)
class BandSelection:
    """What the companion run found and which rows it replaced.

    Attributes
    ----------
    far_coarsening : int
        The companion mesh's ``MeshSpec3D.far_coarsening``.
    status : str
        The companion run's status (``complete``: it reached the lowest band gap or the force
        cap, ``partial``), ``no band gaps`` (the case has no row in the band) or
        ``error: ...`` (the companion run failed; the case keeps its own rows).
    newton_iterations : int
        Newton iterations of the companion run and of the moved states' solves.
    wall_time_s : float
        Seconds spent on the companion run and the moves.
    crease_gaps_mm : tuple of float
        Where the companion run placed its creases (mm).
    choices : tuple of BandChoice
        One per band gap the companion landed on, in decreasing gap.
    move_force_rtol : float
        The ``move_rtol`` the choices were made with (:data:`BAND_MOVE_FORCE_RTOL`).
    """

    far_coarsening: int
    status: str
    newton_iterations: int
    wall_time_s: float
    crease_gaps_mm: tuple[float, ...]
    choices: tuple[BandChoice, ...]
    move_force_rtol: float = BAND_MOVE_FORCE_RTOL

    @property
    def taken_gaps_mm(self) -> tuple[float, ...]:
        """The gaps (mm) whose row is the companion's moved state."""
        return tuple(c.gap_mm for c in self.choices if c.taken)

    def record(self) -> dict[str, Any]:
        """JSON-ready summary: the sidecar's ``fe_info.band_selection``."""
        return {
            "far_coarsening": self.far_coarsening,
            "status": self.status,
            "newton_iterations": self.newton_iterations,
            "wall_time_s": self.wall_time_s,
            "crease_gaps_mm": list(self.crease_gaps_mm),
            "energy_rtol": BAND_ENERGY_RTOL,
            "move_force_rtol": self.move_force_rtol,
            "taken_gaps_mm": list(self.taken_gaps_mm),
            "choices": [c.record() for c in self.choices],
        }


def band_gaps(table, thickness_mm: float, band: tuple[float, float] | None = None) -> list[float]:
    """The gaps (mm) of a case's table inside the crease band, in decreasing order.

    Parameters
    ----------
    table : pandas.DataFrame
        A 3D case's table (column ``gap_mm``).
    thickness_mm : float
        Wall thickness ``t`` (mm).
    band : (float, float), optional
        ``(lowest, highest)`` gap (mm); default ``(2 t, 4 t)``.

    Returns
    -------
    list of float
    """
    lo, hi = band if band is not None else (2.0 * thickness_mm, 4.0 * thickness_mm)
    g = np.asarray(table["gap_mm"], dtype=float)
    sel = g[(g >= lo - LANDING_TOL_MM) & (g <= hi + LANDING_TOL_MM)]
    return sorted(set(sel.tolist()), reverse=True)


def check_companion(spec: CaseSpec3D, far_coarsening: int) -> None:
    """Whether ``spec`` can have a companion with ``far_coarsening`` (checked before the case
    runs, so that a bad setting does not cost the case's run).

    Raises
    ------
    ValueError
        Coulomb contact (friction dissipates: strain energy does not rank its states, as
        for Maxwell's crease placement), ``far_coarsening`` equal to the case's own (the
        companion would be the same mesh), one the mesh does not take (it must divide the
        layers and the circumferential divisions), or a tube without a far zone to coarsen
        (half its length within half the jaw plus ``fine_margin_mm``, or ``n_free`` 0).
    """
    if spec.contact == "coulomb":
        raise ValueError(
            "not with Coulomb contact (friction dissipates, so the strain energy does not rank "
            "the states)"
        )
    if int(far_coarsening) == spec.mesh.far_coarsening:
        raise ValueError(
            f"band_companion={far_coarsening} is the case's own far_coarsening: the companion "
            "must be another mesh"
        )
    replace(spec.mesh, far_coarsening=int(far_coarsening))  # MeshSpec3D checks it
    if int(far_coarsening) > 1 and not has_far_zone(axial_grid(spec), spec.mesh.n_jaw):
        raise ValueError(
            f"band_companion={far_coarsening}: the tube has no far zone to coarsen beyond the "
            f"jaw and its fine margin (tube_length_mm={spec.tube_length_mm:g}, jaw_length_mm="
            f"{spec.jaw_length_mm:g}, fine_margin_mm={spec.mesh.fine_margin_mm:g}, "
            f"n_free={spec.mesh.n_free})"
        )


def companion_spec(spec: CaseSpec3D, gaps, far_coarsening: int) -> CaseSpec3D:
    """The companion case of ``spec``.

    Parameters
    ----------
    spec : CaseSpec3D
        The case.
    gaps : sequence of float
        The case's band gaps (mm) the companion lands on, besides ``spec``'s own landing gaps.
    far_coarsening : int
        The companion mesh's ``MeshSpec3D.far_coarsening`` (:func:`check_companion`).

    Returns
    -------
    CaseSpec3D
        ``spec`` on the companion mesh, ending at the lowest of ``gaps`` (or ``spec``'s closed
        gap if that is lower), without unloading (``unload_from_N`` 0: it would unload from
        its end in the band) and without a companion of its own.

    Raises
    ------
    ValueError
        No gaps, or :func:`check_companion` refuses.
    """
    gaps = [float(g) for g in gaps]
    if not gaps:
        raise ValueError("companion_spec: no band gaps to land on")
    check_companion(spec, far_coarsening)
    mesh = replace(spec.mesh, far_coarsening=int(far_coarsening))
    landing = tuple(sorted(set(spec.solver.land_on_gaps_mm) | set(gaps), reverse=True))
    solver = replace(spec.solver, land_on_gaps_mm=landing, band_companion=0, unload_from_N=0.0)
    closed = max(spec.closed_gap_mm, min(gaps))
    return replace(spec, mesh=mesh, solver=solver, closed_gap_mm=closed)


def companion_states(companion: CaseSpec3D, gaps, solver: str = "auto"):
    """Run the companion case and keep its state at each of ``gaps`` (mm) it landed on.

    Parameters
    ----------
    companion : CaseSpec3D
        The companion (:func:`companion_spec`, landing on ``gaps``).
    gaps : sequence of float
        Jaw gaps (mm).
    solver : str
        Sparse solver (:func:`~grasprom.fe.model3d.run_case_3d`).

    Returns
    -------
    (CaseResult, dict)
        The companion's run and ``{gap: (force_N, u)}``: its table's force (N) and state
        (``on_row``'s last call there; displacements in mm) at each of ``gaps`` it has a row
        at (a companion stopped early, e.g. at the force cap, lacks the lower ones).
    """
    gaps = [float(g) for g in gaps]
    states: dict[float, tuple[float, np.ndarray]] = {}

    def keep(disc, u, gap, force):
        for g in gaps:
            if abs(gap - g) <= LANDING_TOL_MM:
                states[g] = (force, u.copy())

    res = run_case_3d(companion, solver=solver, on_row=keep)
    rows = np.asarray(res.table["gap_mm"], dtype=float)
    landed = {g: v for g, v in states.items() if np.any(np.abs(rows - g) <= LANDING_TOL_MM)}
    return res, landed


#: What a failed move raises: no equilibrium or an inverted element (RuntimeError), a node
#: outside the other mesh (ValueError), an overflow (FloatingPointError).
_MOVE_ERRORS = (RuntimeError, ValueError, FloatingPointError)


def select_lower(
    spec: CaseSpec3D,
    result: CaseResult,
    companion: CaseSpec3D,
    states: dict[float, tuple[float, np.ndarray]],
    solver: str = "auto",
    gaps=None,
    move_rtol: float = BAND_MOVE_FORCE_RTOL,
) -> tuple[CaseResult, tuple[BandChoice, ...]]:
    """Replace the rows of ``result`` by the companion's states where those, solved on
    ``spec``'s mesh, hold less strain energy.

    Parameters
    ----------
    spec : CaseSpec3D
        The case; ``result`` is its run (table with ``gap_mm``, ``force_N``,
        ``strain_energy_mJ``).
    result : CaseResult
    companion : CaseSpec3D
        The case on another mesh of the same tube (:func:`companion_spec`).
    states : dict
        ``{gap_mm: (force_N, u)}`` (:func:`companion_states`): the companion's force (N) and
        displacements (mm) at gaps of ``result``'s table.
    solver : str
        Sparse solver (:func:`~grasprom.fe.model3d.run_case_3d`).
    gaps : sequence of float, optional
        All the band gaps (mm); those without a companion state are recorded as such.
    move_rtol : float
        A state whose companion force is within this share of the case's force is not moved
        (:data:`BAND_MOVE_FORCE_RTOL`; 0: every state is moved).

    Returns
    -------
    (CaseResult, tuple of BandChoice)
        The table with the replaced rows (the rest unchanged; ``info.max_force_N`` of the
        new table) and the choice at each gap, in decreasing gap.

    Raises
    ------
    ValueError
        A gap of ``states`` (or ``gaps``) that is not a row of ``result``, or a negative
        ``move_rtol``.
    """
    if not (math.isfinite(move_rtol) and move_rtol >= 0):
        raise ValueError(f"invalid move_rtol={move_rtol!r}: a share >= 0")
    table = result.table.copy()
    tab_gaps = table["gap_mm"].to_numpy(dtype=float)
    mover = _Mover(spec, companion, solver)
    choices = []
    for g in sorted(set(states) | set(gaps or ()), reverse=True):
        i = int(np.argmin(np.abs(tab_gaps - g)))
        if abs(tab_gaps[i] - g) > LANDING_TOL_MM:
            raise ValueError(f"select_lower: no row of the case at gap {g} mm")
        own_f, own_e = (float(table.iloc[i][c]) for c in ("force_N", "strain_energy_mJ"))
        nan = math.nan
        if g not in states:
            choices.append(BandChoice(g, own_f, own_e, nan, nan, nan, 0, False, NOT_LANDED))
            continue
        comp_f, u_c = states[g]
        if move_rtol > 0 and abs(comp_f - own_f) <= move_rtol * abs(own_f):
            choices.append(BandChoice(g, own_f, own_e, comp_f, nan, nan, 0, False, "", True))
            continue
        try:
            eq = mover.solve(u_c, float(tab_gaps[i]))
        except _MOVE_ERRORS as exc:
            choices.append(BandChoice(g, own_f, own_e, comp_f, nan, nan, 0, False, str(exc)))
            continue
        taken = eq.strain_energy_mJ < own_e - BAND_ENERGY_RTOL * abs(own_e)
        if taken:
            table.iloc[i] = [eq.row[c] for c in table.columns]
        moved = (eq.force_N, eq.strain_energy_mJ, eq.newton_iterations)
        choices.append(BandChoice(g, own_f, own_e, comp_f, *moved, taken))
    info = {**result.info, "max_force_N": float(table["force_N"].max())}
    return CaseResult(table=table, status=result.status, info=info), tuple(choices)


class _Mover:
    """Companion states moved to the case's mesh and solved there: the interpolation matrix
    and the case's :class:`~grasprom.fe.model3d.EquilibriumSolver`, built on the first move."""

    def __init__(self, spec: CaseSpec3D, companion: CaseSpec3D, solver: str) -> None:
        self.spec, self.companion, self.solver = spec, companion, solver
        self._P = None
        self._eq: EquilibriumSolver | None = None

    def solve(self, u_companion: np.ndarray, gap_mm: float):
        """The case's equilibrium at ``gap_mm`` (mm) from a companion state (mm)."""
        if self._eq is None:
            self._P = transfer_matrix(self.companion, self.spec)
            self._eq = EquilibriumSolver(self.spec, self.solver)
        u0 = np.asarray(self._P @ np.asarray(u_companion).reshape(-1, 3)).ravel()
        return self._eq.solve(u0, gap_mm)


def own_run_spec(spec: CaseSpec3D) -> CaseSpec3D:
    """``spec`` without the companion (``solver.band_companion`` 0): the case's own run."""
    return replace(spec, solver=replace(spec.solver, band_companion=0))


#: ``BandChoice.error`` of a band gap the companion has no state at.
NOT_LANDED = "the companion has no state at this gap"


def run_case_3d_selected(
    spec: CaseSpec3D,
    progress=None,
    solver: str = "auto",
    on_step=None,
    band: tuple[float, float] | None = None,
) -> CaseResult:
    """Run a 3D case and keep, at each crease-band gap, the lower-energy of its own state and a
    companion run's (the module's docstring; ``SolverSettings.band_companion``).

    Parameters
    ----------
    spec : CaseSpec3D
        The case; ``spec.solver.band_companion`` (>= 1) is the companion mesh's
        ``far_coarsening`` (0: the plain run, :func:`~grasprom.fe.model3d.run_case_3d`).
    progress, solver, on_step
        As :func:`~grasprom.fe.model3d.run_case_3d`, for the case's own run (``on_step``
        sees the own run's states, also at the rows the selection replaces).
    band : (float, float), optional
        ``(lowest, highest)`` jaw gap (mm) of the band; default ``(2 t, 4 t)``.

    Returns
    -------
    CaseResult
        The table with the selected rows; ``info`` as the own run's, with ``band_selection``
        (:meth:`BandSelection.record`; its ``status`` is ``error: ...`` and the own rows are
        kept if the companion run fails), ``own_wall_time_s`` and ``wall_time_s`` the total.

    Raises
    ------
    ValueError
        An invalid spec, or a companion :func:`check_companion` refuses (before the run).
    """
    k = spec.solver.band_companion
    if k:
        check_companion(spec, k)
    own_spec = own_run_spec(spec)
    res = run_case_3d(own_spec, progress, solver, on_step)
    if k == 0:
        return res
    return select_band(spec, res, solver, band)


def select_band(
    spec: CaseSpec3D,
    result: CaseResult,
    solver: str = "auto",
    band: tuple[float, float] | None = None,
    move_rtol: float = BAND_MOVE_FORCE_RTOL,
) -> CaseResult:
    """The companion run and the band's selection for a case already run: the second half of
    :func:`run_case_3d_selected` (a case of a sweep without the companion, read back from its
    files, gets the rows it would have had with it).

    Parameters
    ----------
    spec : CaseSpec3D
        The case, ``spec.solver.band_companion`` >= 1.
    result : CaseResult
        Its own run: :func:`~grasprom.fe.model3d.run_case_3d` of ``spec`` with
        ``band_companion`` 0 (table with ``gap_mm``, ``force_N``, ``strain_energy_mJ``;
        ``info.wall_time_s`` its wall time in s).
    solver : str
        Sparse solver (:func:`~grasprom.fe.model3d.run_case_3d`).
    band : (float, float), optional
        ``(lowest, highest)`` jaw gap (mm) of the band; default ``(2 t, 4 t)``.
    move_rtol : float
        :func:`select_lower`'s (recorded as ``band_selection.move_force_rtol``).

    Returns
    -------
    CaseResult
        As :func:`run_case_3d_selected`.

    Raises
    ------
    ValueError
        ``band_companion`` is 0, or :func:`check_companion` refuses.
    """
    k = spec.solver.band_companion
    if k == 0:
        raise ValueError("select_band: spec.solver.band_companion is 0 (no companion asked)")
    check_companion(spec, k)
    own_spec = own_run_spec(spec)
    t0 = time.perf_counter()
    gaps = band_gaps(result.table, spec.thickness_mm, band)
    if not gaps:
        sel = BandSelection(k, "no band gaps", 0, 0.0, (), (), move_rtol)
        return _with_selection(result, sel, 0.0)
    comp = companion_spec(own_spec, gaps, k)
    try:
        comp_res, states = companion_states(comp, gaps, solver)
    except _MOVE_ERRORS as exc:
        sel = BandSelection(k, f"error: {exc}", 0, 0.0, (), (), move_rtol)
        return _with_selection(result, sel, time.perf_counter() - t0)
    out, choices = select_lower(own_spec, result, comp, states, solver, gaps, move_rtol)
    newton = comp_res.info["newton_iterations"] + sum(c.newton_iterations for c in choices)
    creases = tuple(float(c["placed_gap_mm"]) for c in comp_res.info.get("creases", ()))
    sel = BandSelection(k, comp_res.status, newton, 0.0, creases, choices, move_rtol)
    return _with_selection(out, sel, time.perf_counter() - t0)


def _with_selection(res: CaseResult, sel: BandSelection, seconds: float) -> CaseResult:
    """``res`` with ``info.band_selection``, the spec's ``band_companion`` in ``info.solver``
    and the wall times (s) of the run and the selection."""
    sel = replace(sel, wall_time_s=seconds)
    own = float(res.info.get("wall_time_s", 0.0))
    info = {**res.info, "band_selection": sel.record(), "own_wall_time_s": own}
    if isinstance(info.get("solver"), dict):
        info["solver"] = {**info["solver"], "band_companion": sel.far_coarsening}
    info["wall_time_s"] = own + seconds
    return CaseResult(table=res.table, status=res.status, info=info)
