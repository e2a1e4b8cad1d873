"""Reduction of FE force-gap curves to PCHIP node tables (the gap direction of the surrogate).

:class:`BuildParams` holds the build settings, :func:`reduce_case` turns one
:class:`~grasprom.surrogate.fedata.FECase` into a :class:`Curve`: the fewest FE points whose
monotone PCHIP reproduces the case (:func:`select_nodes`), their node derivatives
(:func:`pchip_derivatives`) and the wall-contact gap (:func:`contact_gap`).

Units: gaps and thicknesses in mm, forces in N, stiffness in N/mm.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from grasprom.surrogate.fedata import FECase

SCHEMES = ("aligned", "naive")
"""Thickness interpolation schemes: ``aligned`` (gap relative to wall contact) or ``naive``
(fixed gap)."""

CONTACT_GAP_METHODS = ("kink", "2t")
"""How the wall-contact gap ``g_c`` of a case is estimated (see :func:`contact_gap`)."""


@dataclass(frozen=True)
class BuildParams:
    """Parameters of a surrogate build.

    Attributes
    ----------
    tol : float
        Node-selection tolerance (1): every FE point of a case and every midpoint between FE
        points is reproduced within ``tol * max(force_ref_N, F)`` of the PCHIP through all FE
        points, i.e. ``tol`` of the haptic full scale below ``force_ref_N`` and ``tol``
        relative above it.
    force_ref_N : float
        Haptic full-scale force in N (the device force limit); also the end of the haptic
        range in the error figures.
    steep_N_per_mm : float
        Stiffness in N/mm above which the error figures use the gap error at equal force
        instead of the force error at equal gap; also the secant stiffness that marks wall
        contact for ``contact_gap_method="kink"``.
    scheme : str
        Thickness interpolation, one of :data:`SCHEMES`.
    contact_gap_method : str
        One of :data:`CONTACT_GAP_METHODS`.
    """

    tol: float = 0.005
    force_ref_N: float = 20.0
    steep_N_per_mm: float = 20.0
    scheme: str = "aligned"
    contact_gap_method: str = "2t"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.tol) and self.tol >= 0):
            raise ValueError(f"tol must be a finite number >= 0, got {self.tol!r}")
        if not (self.force_ref_N > 0 and self.steep_N_per_mm > 0):
            raise ValueError("force_ref_N and steep_N_per_mm must be > 0")
        if self.scheme not in SCHEMES:
            raise ValueError(f"scheme must be one of {SCHEMES}, got {self.scheme!r}")
        if self.contact_gap_method not in CONTACT_GAP_METHODS:
            raise ValueError(
                f"contact_gap_method must be one of {CONTACT_GAP_METHODS}, "
                f"got {self.contact_gap_method!r}"
            )


@dataclass(frozen=True)
class Curve:
    """One reduced force-gap curve (ascending gap) with its PCHIP Hermite data.

    Attributes
    ----------
    stem : str
        Source FE case.
    thickness_mm : float
        Wall thickness in mm.
    contact_gap_mm : float
        Wall-contact gap ``g_c`` in mm.
    gap_mm : tuple of float
        Nodes in mm, ascending (first = last FE gap, last = diameter).
    force_N : tuple of float
        Force at the nodes in N.
    dforce_dgap_N_per_mm : tuple of float
        dF/dgap at the nodes in N/mm (<= 0; the stiffness is its negative).
    n_fe_points : int
        Load steps of the FE case.
    fit_error : float
        Largest node-selection error, relative as in :attr:`BuildParams.tol`.
    """

    stem: str
    thickness_mm: float
    contact_gap_mm: float
    gap_mm: tuple[float, ...]
    force_N: tuple[float, ...]
    dforce_dgap_N_per_mm: tuple[float, ...]
    n_fe_points: int = 0
    fit_error: float = 0.0

    def coefficients(self) -> tuple[list[float], list[float], list[float], list[float]]:
        """Hermite power-basis coefficients per interval.

        Returns
        -------
        tuple of four lists
            ``c0, c1, c2, c3`` such that on ``[x_k, x_{k+1}]``
            ``F(x) = c0[k] + h (c1[k] + h (c2[k] + h c3[k]))`` with ``h = x - x_k`` (mm, N).
        """
        x, y, d = self.gap_mm, self.force_N, self.dforce_dgap_N_per_mm
        c0, c1, c2, c3 = [], [], [], []
        for k in range(len(x) - 1):
            h = x[k + 1] - x[k]
            m = (y[k + 1] - y[k]) / h
            c0.append(y[k])
            c1.append(d[k])
            c2.append((3.0 * m - 2.0 * d[k] - d[k + 1]) / h)
            c3.append((d[k] + d[k + 1] - 2.0 * m) / (h * h))
        return c0, c1, c2, c3


def pchip_derivatives(x: Sequence[float], y: Sequence[float]) -> np.ndarray:
    """Node derivatives of the monotone PCHIP interpolant (scipy's ``PchipInterpolator``).

    Parameters
    ----------
    x : sequence of float
        Strictly increasing abscissae (gap, mm).
    y : sequence of float
        Ordinates (force, N).

    Returns
    -------
    numpy.ndarray
        dy/dx at each node (N/mm).
    """
    from scipy.interpolate import PchipInterpolator

    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.size == 2:
        m = (y[1] - y[0]) / (x[1] - x[0])
        return np.array([m, m])
    return np.asarray(PchipInterpolator(x, y).derivative()(x), dtype=float)


def _pchip(x: np.ndarray, y: np.ndarray):
    from scipy.interpolate import PchipInterpolator

    return PchipInterpolator(x, y, extrapolate=True)


def select_nodes(
    gap_mm: np.ndarray, force_N: np.ndarray, tol: float, force_ref_N: float = 20.0
) -> tuple[np.ndarray, float]:
    """Fewest FE points whose PCHIP reproduces the FE curve within a tolerance (greedy).

    The reference is the PCHIP through all FE points. Starting from the two end points, the
    FE point at (or next to) the largest error is inserted until the error at every FE point
    and at every midpoint between consecutive FE points is at most
    ``tol * max(force_ref_N, F_ref)``.

    Parameters
    ----------
    gap_mm : numpy.ndarray
        Strictly increasing gaps in mm.
    force_N : numpy.ndarray
        Force at each gap in N.
    tol : float
        Tolerance (1), relative to ``max(force_ref_N, F)``.
    force_ref_N : float
        Force floor of the relative tolerance in N.

    Returns
    -------
    indices : numpy.ndarray
        Sorted indices of the selected FE points (always includes both ends).
    max_error : float
        Largest relative error reached (<= ``tol``).
    """
    x = np.asarray(gap_mm, dtype=float)
    y = np.asarray(force_N, dtype=float)
    n = x.size
    if n < 2:
        raise ValueError("a curve needs at least two points")
    xm = 0.5 * (x[:-1] + x[1:])
    xc = np.concatenate([x, xm])
    ref = _pchip(x, y)(xc)
    scale = np.maximum(force_ref_N, np.abs(ref))
    owner = np.concatenate([np.arange(n), np.arange(n - 1)])  # left FE point of each check
    is_mid = np.concatenate([np.zeros(n, bool), np.ones(n - 1, bool)])
    chosen = np.zeros(n, bool)
    chosen[[0, n - 1]] = True
    while True:
        idx = np.flatnonzero(chosen)
        err = np.abs(_pchip(x[idx], y[idx])(xc) - ref) / scale
        worst = int(np.argmax(err))
        if err[worst] <= tol or chosen.all():
            return idx, float(err[worst])
        k = int(owner[worst])
        if not is_mid[worst]:
            cand = [k]
        else:
            cand = [k, k + 1, k - 1, k + 2]
        for c in cand:
            if 0 <= c < n and not chosen[c]:
                chosen[c] = True
                break
        else:  # both ends of the interval are nodes: refine the nearest free neighbours
            free = np.flatnonzero(~chosen)
            chosen[free[np.argmin(np.abs(free - k))]] = True


def contact_gap(
    gap_mm: np.ndarray,
    force_N: np.ndarray,
    thickness_mm: float,
    method: str = "kink",
    steep_N_per_mm: float = 20.0,
) -> float:
    """Wall-contact gap of an FE curve in mm (where the inner walls meet).

    Parameters
    ----------
    gap_mm, force_N : numpy.ndarray
        The FE curve, any order (mm, N).
    thickness_mm : float
        Wall thickness in mm.
    method : str
        ``"kink"``: the FE load step with the largest jump of the secant stiffness
        ``-dF/dgap`` (ratio of the next to the previous step's secant), among steps whose
        next secant exceeds ``steep_N_per_mm`` -- the slope jump where the inner walls meet
        (the FE solver approaches it in geometrically shrinking steps, so it is located to a
        few um); falls back to ``2 t`` if the curve never gets that steep. ``"2t"``: ``2 t``.
    steep_N_per_mm : float
        Threshold stiffness in N/mm.

    Returns
    -------
    float
        ``g_c`` in mm.
    """
    if method == "2t":
        return 2.0 * float(thickness_mm)
    if method != "kink":
        raise ValueError(f"contact_gap_method must be one of {CONTACT_GAP_METHODS}")
    order = np.argsort(-np.asarray(gap_mm, dtype=float))
    g = np.asarray(gap_mm, dtype=float)[order]
    f = np.asarray(force_N, dtype=float)[order]
    k = -np.diff(f) / np.diff(g)  # secant stiffness of each step, N/mm
    if k.size < 2:
        return 2.0 * float(thickness_mm)
    ratio = k[1:] / np.maximum(k[:-1], 1e-12)  # slope jump at node i + 1
    ratio[k[1:] <= steep_N_per_mm] = 0.0
    if not (ratio > 1.0).any():
        return 2.0 * float(thickness_mm)
    i = int(np.argmax(ratio)) + 1
    return float(g[i])


def snap_interior(gap_mm: np.ndarray, force_N: np.ndarray) -> np.ndarray:
    """Interior points of the snaps of a force-gap curve (mask).

    A snap (the wall creasing or folding over in the FE model) is a force drop as the gap
    closes, i.e. ``force_N`` rising with ``gap_mm``.  Where one spans several FE steps, the
    points inside it are flagged, so the table keeps the snap as one segment: PCHIP gives its
    two end nodes a zero slope, and no node of the table carries a negative stiffness.

    Parameters
    ----------
    gap_mm : ndarray
        Strictly increasing gaps (mm).
    force_N : ndarray
        Forces (N).

    Returns
    -------
    ndarray of bool
        True at the points to leave out.
    """
    up = np.diff(force_N) > 0  # interval i: force rises with the gap (a drop on closing)
    inner = np.zeros(force_N.size, dtype=bool)
    inner[1:-1] = up[:-1] & up[1:]
    return inner


def reduce_case(case: FECase, params: BuildParams) -> Curve:
    """Adaptive PCHIP table of one FE case (see :func:`select_nodes`); the interior points of
    a snap over several FE steps are left out (:func:`snap_interior`).

    Parameters
    ----------
    case : FECase
        The FE curve.
    params : BuildParams
        Tolerance and contact-gap settings.

    Returns
    -------
    Curve
    """
    order = np.argsort(case.gap_mm)
    x = case.gap_mm[order]
    y = case.force_N[order]
    keep = ~snap_interior(x, y)
    x, y = x[keep], y[keep]
    idx, err = select_nodes(x, y, params.tol, params.force_ref_N)
    d = pchip_derivatives(x[idx], y[idx])
    gc = contact_gap(x, y, case.thickness_mm, params.contact_gap_method, params.steep_N_per_mm)
    return Curve(
        stem=case.stem,
        thickness_mm=float(case.thickness_mm),
        contact_gap_mm=gc,
        gap_mm=tuple(float(v) for v in x[idx]),
        force_N=tuple(float(v) for v in y[idx]),
        dforce_dgap_N_per_mm=tuple(float(v) for v in d),
        n_fe_points=int(x.size),
        fit_error=err,
    )
