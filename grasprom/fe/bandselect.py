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
(:func:`~grasprom.fe.transfer3d.transfer_displacement`), solved there at its gap
(:func:`~grasprom.fe.model3d.equilibrium_from`), and wherever it holds less strain energy than
the case's own state (by more than :data:`BAND_ENERGY_RTOL`), its row replaces the case's
(:func:`select_lower`).  Both states are equilibria of the same mesh, so their energies compare
exactly; the two meshes share the jaw zone (the far zone only is coarser), so the stuck contact
nodes move over unchanged.  Gaps in mm, forces in N, energies in mJ.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from grasprom.fe.model2d import CaseResult
from grasprom.fe.model3d import CaseSpec3D, equilibrium_from, run_case_3d
from grasprom.fe.transfer3d import transfer_displacement

__all__ = [
    "BAND_ENERGY_RTOL",
    "BandChoice",
    "BandSelection",
    "band_gaps",
    "companion_spec",
    "companion_states",
    "run_case_3d_selected",
    "select_lower",
]

#: A moved state replaces the case's own where its strain energy is lower by more than this
#: share.  With stick contact the anchors are history: states of one branch reached along two
#: paths differ by them (le 1.0 mm, the default mesh's states against the zoned companion's
#: moved onto it, above the crease: 1.9e-4 to 2.5e-4 of the energy, the force within
#: 0.03 %; a coarse case in bending: 2.7e-5, ``tests/fe/test_bandselect.py``), while the
#: crease patterns that separate two runs differ by 0.24-1.6 % from 0.1 mm past the crease on
#: (le 1.0 mm and mr 1.6 mm, docs/fe-model.md).
BAND_ENERGY_RTOL = 1e-3

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
        The companion run's status (``complete``: it reached the lowest band gap).
    newton_iterations : int
        Newton iterations of the companion run and of the moved states' solves.
    wall_time_s : float
        Seconds spent on the companion run and the moves.
    crease_gaps_mm : tuple of float
        Where the companion run placed its creases (mm).
    choices : tuple of BandChoice
        One per band gap the companion landed on, in decreasing gap.
    """

    far_coarsening: int
    status: str
    newton_iterations: int
    wall_time_s: float
    crease_gaps_mm: tuple[float, ...]
    choices: tuple[BandChoice, ...]

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


def companion_spec(spec: CaseSpec3D, gaps, far_coarsening: int) -> CaseSpec3D:
    """The companion of ``spec``: its mesh with ``far_coarsening``, landing on ``gaps`` (mm)
    besides ``spec``'s own landing gaps, and ending at the lowest of them (or ``spec``'s
    closed gap if that is lower); no companion of its own.

    Raises
    ------
    ValueError
        No gaps, or the mesh does not take ``far_coarsening``.
    """
    gaps = [float(g) for g in gaps]
    if not gaps:
        raise ValueError("companion_spec: no band gaps to land on")
    mesh = replace(spec.mesh, far_coarsening=int(far_coarsening))
    landing = tuple(sorted(set(spec.solver.land_on_gaps_mm) | set(gaps), reverse=True))
    solver = replace(spec.solver, land_on_gaps_mm=landing, band_companion=0)
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
        (``on_row``'s last call there; displacements in mm) at each gap it has a row at.
    """
    gaps = [float(g) for g in gaps]
    states: dict[float, tuple[float, np.ndarray]] = {}
    lo, hi = min(gaps) - LANDING_TOL_MM, max(gaps) + LANDING_TOL_MM

    def keep(disc, u, gap, force):
        if lo <= gap <= hi:
            states[gap] = (force, u.copy())

    res = run_case_3d(companion, solver=solver, on_row=keep)
    rows = np.asarray(res.table["gap_mm"], dtype=float)
    landed = {}
    for g in gaps:
        near = [k for k in states if abs(k - g) <= LANDING_TOL_MM]
        if near and np.any(np.abs(rows - g) <= LANDING_TOL_MM):  # a row of its table there
            landed[g] = states[min(near, key=lambda k: abs(k - g))]
    return res, landed


def select_lower(
    spec: CaseSpec3D,
    result: CaseResult,
    companion: CaseSpec3D,
    states: dict[float, np.ndarray],
    solver: str = "auto",
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

    Returns
    -------
    (CaseResult, tuple of BandChoice)
        The table with the replaced rows (the rest unchanged) and the choice at each gap, in
        decreasing gap.
    """
    table = result.table.copy()
    tab_gaps = table["gap_mm"].to_numpy(dtype=float)
    choices = []
    for g in sorted(states, reverse=True):
        i = int(np.argmin(np.abs(tab_gaps - g)))
        if abs(tab_gaps[i] - g) > LANDING_TOL_MM:
            raise ValueError(f"select_lower: no row of the case at gap {g} mm")
        own_f, own_e = (float(table.iloc[i][c]) for c in ("force_N", "strain_energy_mJ"))
        comp_f, u_c = states[g]
        try:
            u0 = transfer_displacement(companion, u_c, spec)
            eq = equilibrium_from(spec, u0, float(tab_gaps[i]), solver)
        except RuntimeError as exc:
            nan = math.nan
            choices.append(BandChoice(g, own_f, own_e, comp_f, nan, nan, 0, False, str(exc)))
            continue
        taken = eq.strain_energy_mJ < own_e - BAND_ENERGY_RTOL * abs(own_e)
        if taken:
            table.iloc[i] = [eq.row[c] for c in table.columns]
        moved = (eq.force_N, eq.strain_energy_mJ, eq.newton_iterations)
        choices.append(BandChoice(g, own_f, own_e, comp_f, *moved, taken))
    return CaseResult(table=table, status=result.status, info=dict(result.info)), tuple(choices)


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
        As :func:`~grasprom.fe.model3d.run_case_3d`, for the case's own run.
    band : (float, float), optional
        ``(lowest, highest)`` jaw gap (mm) of the band; default ``(2 t, 4 t)``.

    Returns
    -------
    CaseResult
        The table with the selected rows; ``info`` as the own run's, with ``band_selection``
        (:meth:`BandSelection.record`), ``own_wall_time_s`` and ``wall_time_s`` the total.
    """
    k = spec.solver.band_companion
    own_spec = replace(spec, solver=replace(spec.solver, band_companion=0))
    res = run_case_3d(own_spec, progress, solver, on_step)
    if k == 0:
        return res
    t0 = time.perf_counter()
    gaps = band_gaps(res.table, spec.thickness_mm, band)
    if not gaps:
        sel = BandSelection(k, "no band gaps", 0, 0.0, (), ())
        return _with_selection(res, sel, 0.0)
    comp = companion_spec(own_spec, gaps, k)
    comp_res, states = companion_states(comp, gaps, solver)
    out, choices = select_lower(own_spec, res, comp, states, solver)
    newton = comp_res.info["newton_iterations"] + sum(c.newton_iterations for c in choices)
    creases = tuple(float(c["placed_gap_mm"]) for c in comp_res.info.get("creases", ()))
    sel = BandSelection(k, comp_res.status, newton, 0.0, creases, choices)
    return _with_selection(out, sel, time.perf_counter() - t0)


def _with_selection(res: CaseResult, sel: BandSelection, seconds: float) -> CaseResult:
    """``res`` with ``info.band_selection`` and the wall times (s) of the run and the selection."""
    sel = replace(sel, wall_time_s=seconds)
    own = float(res.info.get("wall_time_s", 0.0))
    info = {**res.info, "band_selection": sel.record(), "own_wall_time_s": own}
    info["wall_time_s"] = own + seconds
    return CaseResult(table=res.table, status=res.status, info=info)
