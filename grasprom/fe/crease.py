"""Placing a crease by energy (Maxwell's rule), shared by the 2D and 3D models.

In the crease band the inner wall of the flattened tube can fold smoothly or crease; the
creased state has less strain energy below some jaw height.  A model follows the smooth fold
until it loses stability and snaps; the crease is placed instead where the creased state first
has less energy than the smooth fold at the same jaw height.  The smooth fold's energy between
steps comes from :func:`hermite_energy` (jaw and floor are rigid and do no work, so
``dE/dh = -F``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np


def hermite_energy(branch: list[tuple[float, float, float]], h: float) -> float:
    """Strain energy of the followed branch at jaw height ``h`` (mm), cubic Hermite through the
    recorded steps.

    Parameters
    ----------
    branch : list of (h, energy, force)
        Steps in decreasing ``h`` (mm): the model's strain energy and its jaw reaction, with
        ``dE/dh = -force`` (2D: N mm/mm and N/mm of the quarter model; 3D: N mm and N of the
        1/8 model).
    h : float
        Jaw height (mm); below the last step the last interval is extrapolated.

    Returns
    -------
    float
        The energy, in the units of ``branch``.
    """
    hs = np.array([b[0] for b in branch])
    i = int(np.clip(np.searchsorted(-hs, -h) - 1, 0, len(branch) - 2))
    (h0, e0, f0), (h1, e1, f1) = branch[i], branch[i + 1]
    d = h1 - h0
    s = (h - h0) / d
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * e0 + h10 * d * (-f0) + h01 * e1 + h11 * d * (-f1)


#: Relative force drop over a step that marks a snap (:func:`is_snap`).
SNAP_FORCE_DROP = 1e-4

#: Energy released over a step, as a fraction of the jaws' work over it, that marks a snap
#: (:func:`is_snap`).  Along a smooth branch the strain energy gained is the work up to the
#: trapezoid rule's error: at most 1.4 % of a step's work inside the crease band of a 4 x 36,
#: 240 mm, mr 1.4 mm case; a snap there that raised the force (+0.9 %) released 35 %.
SNAP_RELEASE_FRACTION = 0.05


def released_energy(prev: tuple[float, float, float], cur: tuple[float, float, float]) -> float:
    """Energy released over a step: the jaws' work (trapezoid rule of the force over the jaw
    travel) minus the strain energy gained.

    Parameters
    ----------
    prev, cur : (h, energy, force)
        Branch entries before and after the step (as :func:`hermite_energy`'s): jaw height
        (mm), strain energy and jaw reaction in consistent units (e.g. N mm and N).

    Returns
    -------
    float
        The released energy (units of ``energy``): about zero along an equilibrium branch
        (nothing dissipates), positive where the step snapped to a state of less energy.
    """
    (h0, e0, f0), (h1, e1, f1) = prev, cur
    return 0.5 * (f0 + f1) * (h0 - h1) - (e1 - e0)


def is_snap(
    prev: tuple[float, float, float],
    cur: tuple[float, float, float],
    release_fraction: float = SNAP_RELEASE_FRACTION,
) -> bool:
    """Did the step from ``prev`` to ``cur`` (branch entries ``(h, energy, force)``) leave the
    branch?  Yes if the force dropped by more than :data:`SNAP_FORCE_DROP` of itself, or if
    it released more than ``release_fraction`` of the jaws' work (:func:`released_energy`):
    a snap that lands on a stiffer state raises the force but still releases energy."""
    (h0, _, f0), (h1, _, f1) = prev, cur
    if f1 < f0 * (1.0 - SNAP_FORCE_DROP):
        return True
    work = 0.5 * (f0 + f1) * (h0 - h1)
    return work > 0 and released_energy(prev, cur) > release_fraction * work


@dataclass(frozen=True)
class CreaseOnset:
    """Result of :func:`crease_onset`.

    Attributes
    ----------
    states : list of (h, state, newton_iterations)
        The creased states continued back, from the largest jaw height ``h`` (mm) down to just
        above the snap; empty if the snapped state has no less energy than the branch one back
        step up.
    newton_iterations : int
        Every Newton iteration the placement spent, the rejected probe and the bisections
        included (a solve that fails raises and leaves no count).
    """

    states: list[tuple[float, Any, int]] = field(default_factory=list)
    newton_iterations: int = 0


def crease_onset(
    solve: Callable[[Any, float], tuple[Any, int]],
    below: Callable[[Any, float], bool],
    snapped: Any,
    h_snap: float,
    dh: float,
    h_top: float,
    landing: Sequence[float] = (),
    errors: tuple[type[BaseException], ...] = (ArithmeticError,),
    n_bisect: int = 10,
    n_halve: int = 0,
    first_step: bool = False,
) -> CreaseOnset:
    """Continue a snapped (creased) state back to larger jaw heights while it stays below the
    smooth branch in energy; the crossing is the Maxwell point.

    Parameters
    ----------
    solve : callable
        ``solve(state, h) -> (state, newton_iterations)``: equilibrium at jaw height ``h`` (mm)
        from ``state``; raises one of ``errors`` if it fails.
    below : callable
        ``below(state, h)``: the state's strain energy is below the smooth branch's at ``h``
        (e.g. :func:`hermite_energy` of the followed steps).
    snapped : object
        The creased state at ``h_snap`` (mm).
    dh : float
        Back step (mm).
    h_top : float
        Largest jaw height (mm) to continue to (the top of the crease band).
    landing : sequence of float
        Jaw heights (mm) to land on when a back step passes them.
    errors : tuple of exception types
        What a failed solve raises (the continuation stops there).
    n_bisect : int
        Bisections of the crossing.
    n_halve : int
        A failed back step is retried from the same state with half the step, down to
        ``dh / 2**n_halve``, before the creased branch is taken to end there; after a halved
        step the next one is twice as long (up to ``dh``), not ``dh`` at once.  Without retries
        the first failed step of ``dh`` stopped the continuation wherever the energies stood
        (4 x 36, mr 1.4 mm: at gap 4.25 mm, 0.2 % below the smooth branch in energy).  Doubling
        back instead of retrying ``dh`` after a halved step: near the end of a branch every
        longer step fails again (4 x 36, mr 1.4 mm: two failed back steps, 33 s, saved at the
        first crease, the same states).
    first_step : bool
        Also bisect a crossing within the first back step, if the snapped state is below the
        smooth branch (extrapolated) at ``h_snap``; otherwise a snap within one back step of
        its Maxwell point is placed nowhere.

    Returns
    -------
    CreaseOnset
        The states from the largest ``h`` down to just above ``h_snap`` (none if the snapped
        state has no less energy than the branch one back step up: a force drop along one
        branch, not a jump to another) and the Newton iterations spent.
    """
    out: list[tuple[float, Any, int]] = []
    spent_total = 0
    cur, h = snapped, h_snap
    dh_min = dh / 2**n_halve
    dh_try = dh
    while h + dh <= h_top:
        step = _back_step(solve, cur, h, dh_try, dh_min, landing, errors)
        if step is None:
            break
        h_next, nxt, it, dh_used = step
        dh_try = min(dh, 2.0 * dh_used)  # after a halved step: double back, not jump to dh
        spent_total += it
        if not below(nxt, h_next):
            if out or (first_step and below(cur, h)):
                crossing, spent = _bisect_crossing(solve, below, cur, h, h_next, errors, n_bisect)
                spent_total += spent
                if crossing[0] > h:
                    out.append((*crossing, spent + it))
            break
        out.append((h_next, nxt, it))
        cur, h = nxt, h_next
    out.sort(key=lambda r: -r[0])
    return CreaseOnset(out, spent_total)


def _bisect_crossing(solve, below, state, lo: float, hi: float, errors, n_bisect: int):
    """Bisect the energy crossing between jaw heights ``lo`` (``state`` there, below the smooth
    branch) and ``hi`` (above it), ``n_bisect`` times.  Returns ``((h, state), iterations)``:
    the largest height found below, with its state, and the Newton iterations spent."""
    spent = 0
    for _ in range(n_bisect):
        mid = 0.5 * (lo + hi)
        try:
            sm, it = solve(state, mid)
        except errors:
            break
        spent += it
        if below(sm, mid):
            lo, state = mid, sm
        else:
            hi = mid
    return (lo, state), spent


def _back_step(solve, cur, h: float, dh: float, dh_min: float, landing, errors):
    """One back step of :func:`crease_onset` from ``cur`` at jaw height ``h`` (mm): to
    ``h + dh`` or the first landing height before it, halving the step on failure while it is
    at least ``dh_min`` (mm).  Returns ``(h_next, state, newton_iterations, dh)`` with the step
    taken, or None if every try failed."""
    while dh >= dh_min * (1.0 - 1e-9):
        h_next = min([hc for hc in landing if h + 1e-12 < hc < h + dh], default=h + dh)
        try:
            nxt, it = solve(cur, h_next)
        except errors:
            dh *= 0.5
            continue
        return h_next, nxt, it, dh
    return None


@dataclass(frozen=True)
class Unloading:
    """Result of :func:`unload_band`.

    Attributes
    ----------
    states : list of (h, state, newton_iterations)
        Unloaded states with less strain energy than the loaded ones at the same jaw height
        ``h`` (mm), in increasing ``h``; the last may be the bisected crossing (a height the
        loading did not visit).
    top_mm : float
        The largest jaw height (mm) the unloading reached.
    newton_iterations : int
        Every Newton iteration spent, the bisections included.
    """

    states: list[tuple[float, Any, int]] = field(default_factory=list)
    top_mm: float = 0.0
    newton_iterations: int = 0


def unload_band(
    solve: Callable[[Any, float], tuple[Any, int]],
    energy_of: Callable[[Any], float],
    branch: Sequence[tuple[float, float, float]],
    start: Any,
    h_start: float,
    h_top: float,
    dh: float,
    errors: tuple[type[BaseException], ...] = (ArithmeticError,),
    n_halve: int = 0,
    n_bisect: int = 0,
    rtol: float = 1e-4,
) -> Unloading:
    """Unload a state back up through the crease band and keep it where it holds less strain
    energy than the loaded branch: a search for the lower-energy branch from the other side.

    Loading follows one branch through the band (the smooth fold, or a crease placed by
    :func:`crease_onset` after a snap); which one it reaches depends on where the smooth fold
    loses stability, and so on the mesh and round-off.  Once the walls have met, the state is
    continued back to larger jaw heights, landing on every loaded height in the band, and
    compared there with the loaded state (exactly, at the same height).  The continuation goes
    on while the unloaded state's energy is not above the loaded one's (the same state, or a
    lower branch: the hysteresis of a snap, or a crease the loading never found) and stops at
    the first height where it is above (its Maxwell point, bisected against the loaded
    branch's :func:`hermite_energy`), at ``h_top`` or where a back step fails.

    Parameters
    ----------
    solve : callable
        ``solve(state, h) -> (state, newton_iterations)``: equilibrium at jaw height ``h`` (mm)
        from ``state``; raises one of ``errors`` if it fails.
    energy_of : callable
        Strain energy of a state, in the units of ``branch``.
    branch : sequence of (h, energy, force)
        The loaded steps in decreasing ``h`` (mm), as :func:`hermite_energy`'s.
    start : object
        The state to unload, at jaw height ``h_start`` (mm).
    h_top : float
        Largest jaw height (mm) to continue to (the top of the crease band).
    dh : float
        Largest back step (mm); every loaded height in ``(h_start, h_top]`` is landed on.
    errors : tuple of exception types
        What a failed solve raises.
    n_halve, n_bisect : int
        Halvings of a failed back step (down to ``dh / 2**n_halve``); bisections of the
        crossing between the last height below and the first above.
    rtol : float
        Relative energy difference that counts as another state (lower below ``1 - rtol``
        of the loaded energy, higher above ``1 + rtol``).  The same fold reached along two
        paths differs by 1e-5 to 2.5e-4 where stick anchors differ; two crease states by
        5e-4 and more (measured, docs/fe-model.md).

    Returns
    -------
    Unloading
    """
    heights = sorted(b[0] for b in branch if h_start + 1e-12 < b[0] <= h_top)
    loaded = {b[0]: b[1] for b in branch}
    out: list[tuple[float, Any, int]] = []
    spent = 0
    cur, h, lower = start, h_start, False  # lower: the last height's state was kept
    for hk in heights:
        h, cur, it = _walk_to(solve, cur, h, hk, dh, dh / 2**n_halve, errors)
        spent += it
        if h < hk - 1e-12:
            return Unloading(out, h, spent)
        e_u, e_l = energy_of(cur), loaded[hk]
        if e_u > e_l + rtol * abs(e_l):
            if lower and n_bisect:
                crossing = _unload_crossing(
                    solve, energy_of, branch, out[-1], hk, errors, n_bisect, rtol
                )
                spent += crossing[2]
                if crossing[0] > out[-1][0]:
                    out.append(crossing)
            return Unloading(out, h, spent)
        lower = e_u < e_l - rtol * abs(e_l)
        if lower:
            out.append((hk, cur, it))
    return Unloading(out, h, spent)


def _walk_to(solve, cur, h: float, hk: float, dh: float, dh_min: float, errors):
    """Back steps of at most ``dh`` (mm) from ``cur`` at jaw height ``h`` up to ``hk`` (mm),
    each halved on failure down to ``dh_min``.  Returns ``(h, state, newton_iterations)``
    with the height reached: ``hk``, or less where a step failed at every size."""
    spent = 0
    while h < hk - 1e-12:
        dh_k = min(dh, hk - h)
        step = _back_step(solve, cur, h, dh_k, min(dh_min, dh_k), (hk,), errors)
        if step is None:
            break
        h, cur, it, _ = step
        spent += it
    return h, cur, spent


def _unload_crossing(solve, energy_of, branch, prev, hk: float, errors, n_bisect: int, rtol):
    """Bisect where the unloaded branch, lower at ``prev`` = ``(h, state, its)`` and higher at
    ``hk`` (mm), crosses the loaded ``branch``'s :func:`hermite_energy`.  Returns
    ``(h, state, newton_iterations)`` of the last height found lower."""

    def below(state, hh):
        e_s = hermite_energy(list(branch), hh)
        return energy_of(state) < e_s - rtol * abs(e_s)

    (hc, sc), it = _bisect_crossing(solve, below, prev[1], prev[0], hk, errors, n_bisect)
    return hc, sc, it


def splice_crease(
    rows: list, branch: list, back: CreaseOnset, entry: Callable
) -> tuple[list, list]:
    """Replace the rows (and ``branch`` entries) below the crossing ``back[0]`` by the creased
    states of :func:`crease_onset`; unchanged if ``back`` is empty.

    Parameters
    ----------
    rows, branch : list
        The table rows and the ``(h, energy, force)`` entries so far, one per row, in
        decreasing jaw height ``h`` (mm).
    back : CreaseOnset
        :func:`crease_onset`'s result.
    entry : callable
        ``entry(h, state, newton_iterations) -> (row, branch_entry)`` of a creased state.

    Returns
    -------
    rows, branch : list
    """
    if not back.states:
        return rows, branch
    keep = [k for k, b in enumerate(branch) if b[0] > back.states[0][0]]
    rows = [rows[k] for k in keep]
    branch = [branch[k] for k in keep]
    for hb, sb, itb in back.states:
        row, b = entry(hb, sb, itb)
        rows.append(row)
        branch.append(b)
    return rows, branch
