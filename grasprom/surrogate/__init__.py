"""Tabulated force surrogate F(gap, thickness, material) built from an FE sweep.

The surrogate stores, per material, one reduced force-gap curve per swept wall thickness and
interpolates between them.

Along the gap
    Monotone piecewise cubic Hermite interpolation (PCHIP, the derivatives of
    :class:`scipy.interpolate.PchipInterpolator`) through a subset of the FE load steps chosen
    adaptively (:func:`select_nodes`). Force never wiggles or turns negative, the stiffness is
    continuous. Evaluation uses precomputed Hermite coefficients, vectorised with numpy
    (:meth:`Surrogate.force`) or in pure Python floats (:meth:`Surrogate.force_scalar`).
Along the thickness (scheme ``"aligned"``, the default)
    The steep rise where the inner walls meet sits at the wall-contact gap ``g_c(t)``
    (about 2 t). Both neighbouring thickness curves are evaluated at the same *aligned*
    coordinate ``u = (gap - g_c(t)) / (D - g_c(t))`` (0 at wall contact, 1 at first touch
    ``gap = D``) and blended linearly in t; ``g_c(t)`` is interpolated linearly in t.
    Scheme ``"naive"`` blends the two curves at equal gap (the baseline of the error figures).
Outside the table
    * ``gap >= D`` (the outer diameter, first touch): 0 N, stiffness 0.
    * ``gap`` below the last FE gap of a curve (closed height or force cap reached): linear
      continuation with the curve's stiffness at its last node (force and stiffness stay
      continuous, force keeps rising, never negative); such points are flagged out of range
      (``return_flag=True`` or :meth:`Surrogate.in_range`).
    * thickness outside the swept range: :class:`ValueError` (see :func:`clamp_thickness` for
      the clamp + flag used by exported controllers).

Sign convention: ``stiffness = -dF/dgap`` in N/mm, positive when closing the jaws (gap
decreasing) raises the force.

Units: gaps and thicknesses in mm, forces in N, stiffness in N/mm.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import warnings
from bisect import bisect_right
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

FORMAT_NAME = "grasprom-surrogate"
FORMAT_VERSION = 1
"""Version of the surrogate JSON layout; bump on incompatible change."""

SCHEMES = ("aligned", "naive")
"""Thickness interpolation schemes: ``aligned`` (gap relative to wall contact) or ``naive``
(fixed gap)."""

CONTACT_GAP_METHODS = ("kink", "2t")
"""How the wall-contact gap ``g_c`` of a case is estimated (see :func:`contact_gap`)."""

_MAX_BUCKETS = 32768  # uniform lookup buckets per curve (replace binary search)
_CHUNK = 16384  # vectorised evaluation works on cache-sized chunks
_T_EPS = 1e-9  # thickness tolerance (mm) at the ends of the swept range

_REQUIRED_KEYS = (
    "format",
    "format_version",
    "scheme",
    "params",
    "diameter_mm",
    "fe_hash",
    "materials",
    "errors",
)
_REQUIRED_MAT_KEYS = ("thickness_mm", "contact_gap_mm", "curves")
_REQUIRED_CURVE_KEYS = ("stem", "gap_mm", "force_N", "dforce_dgap_N_per_mm")


class SurrogateFileError(ValueError):
    """A surrogate file is unreadable, from another format version, or inconsistent.

    Parameters
    ----------
    path : str or os.PathLike
        The offending file.
    reason : str
        What is wrong with it.
    """

    def __init__(self, path: str | os.PathLike[str], reason: str) -> None:
        self.path = Path(path)
        self.reason = reason
        super().__init__(f"surrogate file {self.path}: {reason}")


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
class FECase:
    """One FE force-gap curve as read from a sweep directory.

    Attributes
    ----------
    stem : str
        Case stem, e.g. ``mr_t0.80``.
    material : str
        Material key.
    thickness_mm : float
        Wall thickness in mm.
    gap_mm : numpy.ndarray
        Jaw gaps in mm, in load-step order (decreasing from the diameter).
    force_N : numpy.ndarray
        Jaw force in N at each gap.
    diameter_mm : float
        Outer tube diameter in mm (gap of first touch).
    force_cap_N : float
        Force cap of the FE run in N (full scale of the full-range error figures).
    csv_sha256 : str
        SHA-256 of the case CSV.
    status : str
        ``complete`` or ``partial``.
    """

    stem: str
    material: str
    thickness_mm: float
    gap_mm: np.ndarray = field(repr=False)
    force_N: np.ndarray = field(repr=False)
    diameter_mm: float
    force_cap_N: float
    csv_sha256: str
    status: str


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


# --------------------------------------------------------------------------- gap direction


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


def reduce_case(case: FECase, params: BuildParams) -> Curve:
    """Adaptive PCHIP table of one FE case (see :func:`select_nodes`).

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


# --------------------------------------------------------------------------- reading FE data


def read_fe_cases(directory: str | os.PathLike[str]) -> tuple[list[FECase], list[str]]:
    """Read and validate the FE cases of a sweep directory.

    Parameters
    ----------
    directory : str or os.PathLike
        Sweep directory (e.g. ``fe_data/default``).

    Returns
    -------
    complete : list of FECase
        Complete cases, sorted by material and thickness.
    partial : list of str
        Stems of partial cases (not returned in ``complete``).

    Raises
    ------
    FileNotFoundError
        If the directory does not exist or holds no case.
    grasprom.fe.datafiles.CorruptCaseError
        If a case file fails validation (hash, columns).
    ValueError
        If a CSV holds NaN/inf in ``gap_mm`` or ``force_N``, or its gaps do not decrease
        strictly (the message names the file).
    """
    from grasprom.fe import datafiles

    d = Path(directory)
    if not d.is_dir():
        raise FileNotFoundError(f"FE sweep directory {d} does not exist")
    cases: list[FECase] = []
    partial: list[str] = []
    for jp in datafiles.case_json_paths(d):
        lc = datafiles.read_case(jp)
        meta = lc.meta
        stem = str(meta.get("stem", jp.stem))
        if meta["status"] != "complete":
            partial.append(stem)
            continue
        g = lc.table["gap_mm"].to_numpy(dtype=float)
        f = lc.table["force_N"].to_numpy(dtype=float)
        if not (np.isfinite(g).all() and np.isfinite(f).all()):
            raise ValueError(f"{lc.files.csv}: NaN or inf in gap_mm/force_N")
        if g.size < 2 or not (np.diff(g) < 0).all():
            raise ValueError(f"{lc.files.csv}: gap_mm must decrease strictly (>= 2 rows)")
        cases.append(
            FECase(
                stem=stem,
                material=str(meta["material"]),
                thickness_mm=float(meta["thickness_mm"]),
                gap_mm=g,
                force_N=f,
                diameter_mm=float(meta.get("diameter_mm", g[0])),
                force_cap_N=float(meta.get("force_cap_N") or 200.0),
                csv_sha256=str(meta["csv_sha256"]),
                status="complete",
            )
        )
    if not cases and not partial:
        raise FileNotFoundError(f"FE sweep directory {d} holds no case files")
    cases.sort(key=lambda c: (c.material, c.thickness_mm))
    return cases, partial


def fe_hash(cases: Iterable[FECase]) -> str:
    """Combined SHA-256 of the FE data: hash of the sorted ``stem:csv_sha256`` lines.

    Parameters
    ----------
    cases : iterable of FECase

    Returns
    -------
    str
        Hex digest.
    """
    lines = sorted(f"{c.stem}:{c.csv_sha256}" for c in cases)
    return hashlib.sha256("\n".join(lines).encode()).hexdigest()


def fe_dir_hash(directory: str | os.PathLike[str]) -> str:
    """:func:`fe_hash` of the complete cases of a sweep directory (partial ones excluded)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cases, _ = read_fe_cases(directory)
    return fe_hash(cases)


# --------------------------------------------------------------------------- the surrogate


class SplineTable:
    """Evaluation tables of one material (numpy arrays and pure-Python lists)."""

    def __init__(self, curves: Sequence[Curve], diameter_mm: float) -> None:
        self.curves = tuple(curves)
        n = len(self.curves)
        self.D = float(diameter_mm)
        self.t = [c.thickness_mm for c in self.curves]
        self.gc = [c.contact_gap_mm for c in self.curves]
        self.inv_dt = [1.0 / (self.t[i + 1] - self.t[i]) for i in range(n - 1)] or [0.0]
        # scalar path: per curve (xs, c0, c1, c2, c3, x0, xn)
        self.s_curves = []
        xs, c0s, c1s, c2s, c3s, start, last = [], [], [], [], [], [], []
        for c in self.curves:
            c0, c1, c2, c3 = c.coefficients()
            x = list(c.gap_mm)
            self.s_curves.append((x, c0, c1, c2, c3, x[0], x[-1]))
            start.append(len(xs))
            last.append(len(xs) + len(c0) - 1)
            xs.extend(x[:-1])
            c0s += c0
            c1s += c1
            c2s += c2
            c3s += c3
        self.a_t = np.array(self.t)
        self.a_gc = np.array(self.gc)
        self.a_inv_dt = np.array(self.inv_dt)
        self.a_x = np.array(xs)
        # right end of each interval; +inf for the last interval of a curve
        self.a_xnext = np.array(xs[1:] + [math.inf])
        self.a_xnext[np.array(last)] = math.inf
        self.a_c0 = np.array(c0s)
        self.a_c1 = np.array(c1s)
        self.a_c2 = np.array(c2s)
        self.a_c3 = np.array(c3s)
        self.a_x0 = np.array([c.gap_mm[0] for c in self.curves])
        self.a_xn = np.array([c.gap_mm[-1] for c in self.curves])
        # uniform bucket tables replace binary search: bucket -> interval index
        bstart, binvw, bidx = [], [], []
        for i, c in enumerate(self.curves):
            x = np.asarray(c.gap_mm)
            span = x[-1] - x[0]
            nb = int(min(_MAX_BUCKETS, math.ceil(2.0 * span / np.diff(x).min()) + 1))
            invw = nb / span
            edges = x[0] + np.arange(nb + 1) / invw
            loc = np.clip(np.searchsorted(x, edges, side="right") - 1, 0, len(x) - 2)
            bstart.append(sum(len(v) for v in bidx))
            binvw.append(invw)
            bidx.append(loc + start[i])
        self.a_bstart = np.array(bstart)
        self.a_binvw = np.array(binvw)
        self.a_bidx = np.concatenate(bidx).astype(np.intp)
        self.a_bmax = np.array([bstart[i] + len(bidx[i]) - 1 for i in range(n)])
        # thickness buckets
        ta = self.a_t
        if n > 1:
            nbt = int(min(_MAX_BUCKETS, math.ceil(2.0 * (ta[-1] - ta[0]) / np.diff(ta).min()) + 1))
            self.t_invw = nbt / (ta[-1] - ta[0])
            tedges = ta[0] + np.arange(nbt + 1) / self.t_invw
            self.t_bidx = np.clip(np.searchsorted(ta, tedges, side="right") - 1, 0, n - 2)
            self.t_next = np.append(ta[1:-1], math.inf)  # right end of interval i (inf last)
        self.tmin = self.t[0]
        self.tmax = self.t[-1]

    # ---------------------------------------------------------------- vectorised
    def eval_curves(self, ci: np.ndarray, x: np.ndarray, want_d: bool):
        """Force, dF/dgap and out-of-range mask of curves ``ci`` at gaps ``x`` (flat arrays)."""
        x0 = self.a_x0[ci]
        xn = self.a_xn[ci]
        xc = np.minimum(np.maximum(x, x0), xn)
        b = ((xc - x0) * self.a_binvw[ci]).astype(np.intp)
        b += self.a_bstart[ci]
        np.minimum(b, self.a_bmax[ci], out=b)
        k = self.a_bidx[b]
        # the bucket may round by one: exact correction against the node gaps
        k -= xc < self.a_x[k]
        while True:
            up = xc >= self.a_xnext[k]
            if not up.any():
                break
            k += up
        h = xc - self.a_x[k]
        c1 = self.a_c1[k]
        c2 = self.a_c2[k]
        c3 = self.a_c3[k]
        f = c3 * h
        f += c2
        f *= h
        f += c1
        f *= h
        f += self.a_c0[k]
        below = x < x0
        # linear continuation below the last FE gap (h = 0 there, slope c1 = node derivative)
        f += c1 * (x - xc)
        inside = x < xn
        f *= inside  # 0 N at and above first touch
        np.maximum(f, 0.0, out=f)
        if not want_d:
            return f, None, below
        df = 3.0 * c3 * h
        df += 2.0 * c2
        df *= h
        df += c1
        df *= inside
        return f, df, below

    def evaluate(self, gap, thickness, scheme: str, want_d: bool, want_flag: bool):
        g = np.asarray(gap, dtype=float)
        t = np.asarray(thickness, dtype=float)
        shape = np.broadcast_shapes(g.shape, t.shape)
        g = np.broadcast_to(g, shape).ravel()
        t = np.broadcast_to(t, shape).ravel()
        if not np.isfinite(g).all():
            raise ValueError("gap_mm must be finite")
        if t.size and not (t.min() >= self.tmin - _T_EPS and t.max() <= self.tmax + _T_EPS):
            raise ValueError(
                f"thickness_mm outside the swept range [{self.tmin:g}, {self.tmax:g}] mm "
                f"(got {t.min():g}..{t.max():g}); use clamp_thickness() to clamp and flag"
            )
        size = g.size
        f = np.empty(size)
        d = np.empty(size) if want_d else None
        fl = np.empty(size, dtype=bool)
        for a in range(0, size, _CHUNK):  # cache-sized chunks
            sl = slice(a, a + _CHUNK)
            fc, dc, flc = self._evaluate_flat(g[sl], t[sl], scheme, want_d)
            f[sl] = fc
            fl[sl] = flc
            if want_d:
                d[sl] = dc
        return (
            f.reshape(shape),
            None if d is None else d.reshape(shape),
            fl.reshape(shape) if want_flag else None,
        )

    def _evaluate_flat(self, g: np.ndarray, t: np.ndarray, scheme: str, want_d: bool):
        n = len(self.t)
        if n == 1:
            ci = np.zeros(g.size, dtype=np.intp)
            return self.eval_curves(ci, g, want_d)
        tb = ((t - self.tmin) * self.t_invw).astype(np.intp)
        np.clip(tb, 0, self.t_bidx.size - 1, out=tb)
        i = self.t_bidx[tb]
        i -= (t < self.a_t[i]) & (i > 0)
        i += t >= self.t_next[i]
        w = (t - self.a_t[i]) * self.a_inv_dt[i]
        np.clip(w, 0.0, 1.0, out=w)
        v = 1.0 - w
        j = i + 1
        if scheme == "aligned":
            gca = self.a_gc[i]
            gcb = self.a_gc[j]
            dgc = gca - gcb
            gct = gca - w * dgc
            idn = 1.0 / (self.D - gct)
            r = (self.D - g) * idn
            r *= dgc
            xa = g + w * r
            xb = g - v * r
        else:
            xa = xb = g
        fa, da, ba = self.eval_curves(i, xa, want_d)
        fb, db, bb = self.eval_curves(j, xb, want_d)
        f = v * fa
        f += w * fb
        dfdg = None
        if want_d:
            if scheme == "aligned":
                ra = (self.D - gca) * idn
                rb = (self.D - gcb) * idn
                dfdg = v * (da * ra) + w * (db * rb)
            else:
                dfdg = v * da + w * db
        flag = (ba & (v > 0)) | (bb & (w > 0))
        return f, dfdg, flag

    # ---------------------------------------------------------------- scalar
    def _curve_scalar(self, i: int, x: float) -> tuple[float, float, bool]:
        xs, c0, c1, c2, c3, x0, xn = self.s_curves[i]
        if x >= xn:
            return 0.0, 0.0, False
        if x < x0:
            f = c0[0] + c1[0] * (x - x0)  # linear continuation, flagged
            return (f if f > 0.0 else 0.0), c1[0], True
        k = bisect_right(xs, x) - 1
        last = len(c0) - 1
        if k > last:
            k = last
        h = x - xs[k]
        a1 = c1[k]
        a2 = c2[k]
        a3 = c3[k]
        f = ((a3 * h + a2) * h + a1) * h + c0[k]
        return (f if f > 0.0 else 0.0), (3.0 * a3 * h + 2.0 * a2) * h + a1, False

    def scalar(self, gap: float, t: float, scheme: str) -> tuple[float, float, bool]:
        if not (gap == gap and gap not in (math.inf, -math.inf)):
            raise ValueError(f"gap_mm must be finite, got {gap!r}")
        if not (self.tmin - _T_EPS <= t <= self.tmax + _T_EPS):
            raise ValueError(
                f"thickness_mm {t!r} outside the swept range [{self.tmin:g}, {self.tmax:g}] mm;"
                " use clamp_thickness() to clamp and flag"
            )
        ts = self.t
        n = len(ts)
        if n == 1:
            return self._curve_scalar(0, gap)
        i = bisect_right(ts, t) - 1
        if i < 0:
            i = 0
        elif i > n - 2:
            i = n - 2
        w = (t - ts[i]) * self.inv_dt[i]
        if w < 0.0:
            w = 0.0
        elif w > 1.0:
            w = 1.0
        v = 1.0 - w
        if scheme == "aligned":
            D = self.D
            gca = self.gc[i]
            gcb = self.gc[i + 1]
            dgc = gca - gcb
            gct = gca - w * dgc
            idn = 1.0 / (D - gct)
            r = (D - gap) * idn * dgc
            fa, da, ba = self._curve_scalar(i, gap + w * r)
            fb, db, bb = self._curve_scalar(i + 1, gap - v * r)
            dfdg = v * (da * ((D - gca) * idn)) + w * (db * ((D - gcb) * idn))
        else:
            fa, da, ba = self._curve_scalar(i, gap)
            fb, db, bb = self._curve_scalar(i + 1, gap)
            dfdg = v * da + w * db
        flag = (ba and v > 0.0) or (bb and w > 0.0)
        return v * fa + w * fb, dfdg, flag


class Surrogate:
    """Tabulated jaw force F(gap, thickness, material) from an FE sweep.

    Build with :meth:`build` (from a sweep directory) or :meth:`load` (from a file written by
    :meth:`save`). See the module docstring for the interpolation scheme and the behaviour
    outside the table.

    Parameters
    ----------
    curves : mapping of str to sequence of Curve
        Reduced curves per material, each sorted by thickness.
    diameter_mm : float
        Outer tube diameter in mm (gap of first touch).
    params : BuildParams
        Build parameters (holds the thickness scheme).
    fe_hash : str
        :func:`fe_hash` of the FE data the table came from.
    errors : dict, optional
        Error figures (see :func:`error_figures`).
    source : str, optional
        Where the FE data came from (informative).
    """

    def __init__(
        self,
        curves: Mapping[str, Sequence[Curve]],
        diameter_mm: float,
        params: BuildParams,
        fe_hash: str,
        errors: dict | None = None,
        source: str = "",
    ) -> None:
        if not curves:
            raise ValueError("a surrogate needs at least one material")
        self.params = params
        self.diameter_mm = float(diameter_mm)
        self.fe_hash = fe_hash
        self.errors: dict = dict(errors or {})
        self.source = source
        self._curves = {
            m: tuple(sorted(c, key=lambda k: k.thickness_mm)) for m, c in curves.items()
        }
        for m, cs in self._curves.items():
            if not cs:
                raise ValueError(f"material {m!r} has no curve")
            ts = [c.thickness_mm for c in cs]
            if len(set(ts)) != len(ts):
                raise ValueError(f"material {m!r}: duplicate thickness in {ts}")
        self._tables = {m: SplineTable(cs, self.diameter_mm) for m, cs in self._curves.items()}

    # ---------------------------------------------------------------- construction
    @classmethod
    def build(
        cls,
        sweep_dir: str | os.PathLike[str],
        tol: float = 0.005,
        *,
        params: BuildParams | None = None,
        holdout_dir: str | os.PathLike[str] | None = None,
    ) -> Surrogate:
        """Build the surrogate from a sweep directory.

        Partial cases are left out of the grid with a :class:`UserWarning` naming them.
        Leave-one-thickness-out figures (both schemes) are always computed; held-out
        figures too when ``holdout_dir`` is given.

        Parameters
        ----------
        sweep_dir : str or os.PathLike
            FE sweep directory (e.g. ``fe_data/default``).
        tol : float
            Node tolerance (see :class:`BuildParams`); ignored if ``params`` is given.
        params : BuildParams, optional
            All build parameters.
        holdout_dir : str or os.PathLike, optional
            Directory of extra FE cases for the held-out error figures.

        Returns
        -------
        Surrogate
        """
        params = params or BuildParams(tol=tol)
        cases, partial = read_fe_cases(sweep_dir)
        if partial:
            warnings.warn(
                f"{sweep_dir}: partial FE cases left out of the surrogate grid: "
                f"{', '.join(partial)}",
                UserWarning,
                stacklevel=2,
            )
        s = cls.from_cases(cases, params, source=str(sweep_dir))
        s.errors["loo"] = leave_one_out(s, cases)
        if holdout_dir is not None:
            s.errors["holdout"] = s.check(holdout_dir)
        return s

    @classmethod
    def from_cases(
        cls, cases: Sequence[FECase], params: BuildParams | None = None, source: str = ""
    ) -> Surrogate:
        """Build from already-read FE cases (complete ones only; see :func:`read_fe_cases`).

        Parameters
        ----------
        cases : sequence of FECase
        params : BuildParams, optional
        source : str
            Informative origin of the data.

        Returns
        -------
        Surrogate
        """
        params = params or BuildParams()
        if not cases:
            raise ValueError(f"no complete FE case to build a surrogate from ({source})")
        diam = {c.diameter_mm for c in cases}
        if len(diam) != 1:
            raise ValueError(f"FE cases of {source} have different diameters {sorted(diam)}")
        curves: dict[str, list[Curve]] = {}
        for c in cases:
            curves.setdefault(c.material, []).append(reduce_case(c, params))
        s = cls(curves, diam.pop(), params, fe_hash(cases), source=source)
        s.errors["fit"] = {
            m: {
                "nodes": [len(c.gap_mm) for c in cs],
                "fe_points": [c.n_fe_points for c in cs],
                "max_fit_error": max(c.fit_error for c in cs),
            }
            for m, cs in s._curves.items()
        }
        return s

    def with_scheme(self, scheme: str) -> Surrogate:
        """The same table with another thickness scheme (one of :data:`SCHEMES`)."""
        return Surrogate(
            self._curves,
            self.diameter_mm,
            replace(self.params, scheme=scheme),
            self.fe_hash,
            self.errors,
            self.source,
        )

    def without(self, material: str, thickness_mm: float) -> Surrogate:
        """The same table without the curve of one thickness (for leave-one-out)."""
        curves = dict(self._curves)
        curves[material] = tuple(
            c for c in curves[material] if abs(c.thickness_mm - thickness_mm) > 1e-9
        )
        return Surrogate(curves, self.diameter_mm, self.params, self.fe_hash, {}, self.source)

    # ---------------------------------------------------------------- introspection
    @property
    def materials(self) -> tuple[str, ...]:
        """Material keys in the table."""
        return tuple(self._curves)

    @property
    def scheme(self) -> str:
        """Thickness interpolation scheme (``aligned`` or ``naive``)."""
        return self.params.scheme

    def thickness_range(self, material: str) -> tuple[float, float]:
        """Swept thickness range ``(min, max)`` of a material, in mm."""
        tab = self.table(material)
        return tab.tmin, tab.tmax

    def thicknesses(self, material: str) -> tuple[float, ...]:
        """Grid thicknesses of a material, in mm."""
        return tuple(self.table(material).t)

    def curves(self, material: str) -> tuple[Curve, ...]:
        """Reduced curves of a material, sorted by thickness."""
        self.table(material)
        return self._curves[material]

    def node_count(self) -> int:
        """Total number of gap nodes over all curves."""
        return sum(len(c.gap_mm) for cs in self._curves.values() for c in cs)

    def table(self, material: str) -> SplineTable:
        """The evaluation table of one material (Hermite intervals per curve; for code generation).

        Raises
        ------
        ValueError
            If the surrogate has no such material.
        """
        try:
            return self._tables[material]
        except KeyError:
            raise ValueError(
                f"unknown material {material!r}; this surrogate has {list(self._tables)}"
            ) from None

    # ---------------------------------------------------------------- evaluation
    def force(self, gap_mm, thickness_mm, material: str, *, return_flag: bool = False):
        """Jaw force in N (numpy broadcasting over gap and thickness).

        Parameters
        ----------
        gap_mm : float or array_like
            Jaw gap in mm (finite).
        thickness_mm : float or array_like
            Wall thickness in mm, within :meth:`thickness_range`.
        material : str
            Material key.
        return_flag : bool
            Also return the out-of-range flag (gap below the FE range, extrapolated).

        Returns
        -------
        force : numpy.ndarray
            Force in N (0-d array for scalar inputs).
        flag : numpy.ndarray of bool
            Only if ``return_flag``: True where extrapolated below the FE gap range.

        Raises
        ------
        ValueError
            Unknown material, non-finite gap, or thickness outside the swept range.
        """
        f, _, flag = self.table(material).evaluate(
            gap_mm, thickness_mm, self.params.scheme, False, return_flag
        )
        return (f, flag) if return_flag else f

    def stiffness(self, gap_mm, thickness_mm, material: str, *, return_flag: bool = False):
        """Stiffness ``-dF/dgap`` in N/mm (>= 0; numpy broadcasting over gap and thickness).

        Parameters and errors as :meth:`force`.

        Returns
        -------
        stiffness : numpy.ndarray
            N/mm, positive when closing the jaws raises the force; 0 above first touch.
        flag : numpy.ndarray of bool
            Only if ``return_flag``.
        """
        _, d, flag = self.table(material).evaluate(
            gap_mm, thickness_mm, self.params.scheme, True, return_flag
        )
        k = -d
        return (k, flag) if return_flag else k

    def in_range(self, gap_mm, thickness_mm, material: str) -> np.ndarray:
        """True where the gap lies within the FE range (no extrapolation), bool array."""
        _, flag = self.force(gap_mm, thickness_mm, material, return_flag=True)
        return ~flag

    def evaluate_scalar(
        self, gap_mm: float, thickness_mm: float, material: str
    ) -> tuple[float, float, bool]:
        """Force (N), stiffness (N/mm) and out-of-range flag of one point, pure Python floats.

        No numpy and no array allocation: bisection on precomputed lists, for the controller
        loop. Gives the same numbers as :meth:`force` / :meth:`stiffness`.

        Parameters
        ----------
        gap_mm : float
            Jaw gap in mm.
        thickness_mm : float
            Wall thickness in mm, within :meth:`thickness_range`.
        material : str
            Material key.

        Returns
        -------
        tuple of (float, float, bool)
            ``(force_N, stiffness_N_per_mm, out_of_range)``.
        """
        f, d, flag = self.table(material).scalar(
            float(gap_mm), float(thickness_mm), self.params.scheme
        )
        return f, -d, flag

    def force_scalar(self, gap_mm: float, thickness_mm: float, material: str) -> float:
        """Force in N at one point, pure Python (see :meth:`evaluate_scalar`)."""
        return self.table(material).scalar(gap_mm, thickness_mm, self.params.scheme)[0]

    def stiffness_scalar(self, gap_mm: float, thickness_mm: float, material: str) -> float:
        """Stiffness ``-dF/dgap`` in N/mm at one point, pure Python (:meth:`evaluate_scalar`)."""
        return -self.table(material).scalar(gap_mm, thickness_mm, self.params.scheme)[1]

    # ---------------------------------------------------------------- accuracy
    def check(self, fe_dir: str | os.PathLike[str], schemes: Sequence[str] = SCHEMES) -> dict:
        """Error figures against the FE cases of a directory, for each scheme.

        Parameters
        ----------
        fe_dir : str or os.PathLike
            Directory of FE cases (e.g. ``fe_data/holdout``); partial cases and cases outside
            the surrogate's materials or thickness range are skipped with a warning.
        schemes : sequence of str
            Schemes to measure.

        Returns
        -------
        dict
            ``{"source": str, "skipped": [stems], "schemes": {scheme: error_figures(...)}}``.
        """
        cases, partial = read_fe_cases(fe_dir)
        if partial:
            warnings.warn(
                f"{fe_dir}: partial FE cases skipped: {', '.join(partial)}",
                UserWarning,
                stacklevel=2,
            )
        keep, skipped = [], []
        for c in cases:
            ok = c.material in self._tables
            if ok:
                lo, hi = self.thickness_range(c.material)
                ok = lo - _T_EPS <= c.thickness_mm <= hi + _T_EPS
            (keep if ok else skipped).append(c)
        if skipped:
            warnings.warn(
                f"{fe_dir}: FE cases outside the surrogate's materials/thickness range "
                f"skipped: {', '.join(c.stem for c in skipped)}",
                UserWarning,
                stacklevel=2,
            )
        cases = keep
        return {
            "source": str(fe_dir),
            "skipped": [c.stem for c in skipped],
            "schemes": {
                sc: error_figures(self.with_scheme(sc), cases, self.params) for sc in schemes
            },
        }

    # ---------------------------------------------------------------- I/O
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready representation (see :meth:`save`)."""
        mats = {}
        for m, cs in self._curves.items():
            mats[m] = {
                "thickness_mm": [c.thickness_mm for c in cs],
                "contact_gap_mm": [c.contact_gap_mm for c in cs],
                "curves": [
                    {
                        "stem": c.stem,
                        "n_fe_points": c.n_fe_points,
                        "fit_error": c.fit_error,
                        "gap_mm": list(c.gap_mm),
                        "force_N": list(c.force_N),
                        "dforce_dgap_N_per_mm": list(c.dforce_dgap_N_per_mm),
                    }
                    for c in cs
                ],
            }
        return {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "scheme": {
                "gap": "pchip (monotone cubic Hermite, scipy PchipInterpolator derivatives)",
                "thickness": self.params.scheme,
                "aligned_coordinate": "u = (gap - g_c(t)) / (D - g_c(t)), g_c linear in t",
                "contact_gap_method": self.params.contact_gap_method,
                "below_fe_range": "linear with the stiffness at the last node; flagged",
                "above_first_touch": "0 N for gap >= diameter_mm",
                "stiffness_sign": "stiffness = -dF/dgap (N/mm), >= 0",
            },
            "params": asdict(self.params),
            "diameter_mm": self.diameter_mm,
            "units": {"gap": "mm", "thickness": "mm", "force": "N", "stiffness": "N/mm"},
            "fe_source": self.source,
            "fe_hash": self.fe_hash,
            "fe_hash_method": "sha256 of sorted '<stem>:<csv_sha256>' lines, complete cases",
            "node_count": self.node_count(),
            "errors": self.errors,
            "materials": mats,
        }

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the surrogate as versioned JSON (atomically).

        Parameters
        ----------
        path : str or os.PathLike
            Output file (``.json``).

        Returns
        -------
        pathlib.Path
        """
        from grasprom.fe import atomic_write_bytes

        p = Path(path)
        text = json.dumps(self.to_dict(), indent=1, allow_nan=False, default=_json_default)
        atomic_write_bytes(p, (text + "\n").encode())
        return p

    @classmethod
    def load(
        cls, path: str | os.PathLike[str], fe_dir: str | os.PathLike[str] | None = None
    ) -> Surrogate:
        """Read a surrogate written by :meth:`save`.

        Parameters
        ----------
        path : str or os.PathLike
            Surrogate JSON file.
        fe_dir : str or os.PathLike, optional
            The FE sweep it was built from; if given, its :func:`fe_dir_hash` must match.

        Returns
        -------
        Surrogate

        Raises
        ------
        SurrogateFileError
            Missing/unparsable file, other format or version, missing keys, inconsistent
            table, or FE hash mismatch (the message names the file).
        """
        p = Path(path)
        try:
            d = json.loads(p.read_text())
        except FileNotFoundError:
            raise SurrogateFileError(p, "file not found") from None
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise SurrogateFileError(p, f"does not parse as JSON ({exc})") from None
        if not isinstance(d, dict) or d.get("format") != FORMAT_NAME:
            raise SurrogateFileError(p, f"not a {FORMAT_NAME} file")
        if d.get("format_version") != FORMAT_VERSION:
            raise SurrogateFileError(
                p,
                f"format_version {d.get('format_version')!r}, this grasprom reads "
                f"{FORMAT_VERSION}; rebuild it with 'grasprom surrogate build'",
            )
        missing = [k for k in _REQUIRED_KEYS if k not in d]
        if missing:
            raise SurrogateFileError(p, f"missing keys {missing}")
        try:
            params = BuildParams(**d["params"])
            curves: dict[str, list[Curve]] = {}
            for m, md in d["materials"].items():
                miss = [k for k in _REQUIRED_MAT_KEYS if k not in md]
                if miss:
                    raise SurrogateFileError(p, f"material {m!r} lacks keys {miss}")
                lst = []
                for t, gc, cd in zip(md["thickness_mm"], md["contact_gap_mm"], md["curves"]):
                    miss = [k for k in _REQUIRED_CURVE_KEYS if k not in cd]
                    if miss:
                        raise SurrogateFileError(p, f"material {m!r} curve lacks keys {miss}")
                    x = tuple(float(v) for v in cd["gap_mm"])
                    y = tuple(float(v) for v in cd["force_N"])
                    dd = tuple(float(v) for v in cd["dforce_dgap_N_per_mm"])
                    if not (len(x) == len(y) == len(dd) >= 2) or any(
                        b <= a for a, b in zip(x, x[1:])
                    ):
                        raise SurrogateFileError(
                            p, f"curve {cd['stem']!r}: bad node arrays (length/order)"
                        )
                    lst.append(
                        Curve(
                            str(cd["stem"]),
                            float(t),
                            float(gc),
                            x,
                            y,
                            dd,
                            int(cd.get("n_fe_points", 0)),
                            float(cd.get("fit_error", 0.0)),
                        )
                    )
                if len(lst) != len(md["thickness_mm"]):
                    raise SurrogateFileError(p, f"material {m!r}: curve count mismatch")
                curves[m] = lst
            s = cls(
                curves,
                float(d["diameter_mm"]),
                params,
                str(d["fe_hash"]),
                d["errors"],
                str(d.get("fe_source", "")),
            )
        except SurrogateFileError:
            raise
        except (TypeError, ValueError, KeyError, AttributeError) as exc:
            raise SurrogateFileError(p, f"inconsistent content ({exc})") from None
        if fe_dir is not None:
            h = fe_dir_hash(fe_dir)
            if h != s.fe_hash:
                raise SurrogateFileError(
                    p,
                    f"FE data hash mismatch: the file was built from FE data "
                    f"{s.fe_hash[:12]}..., {fe_dir} hashes to {h[:12]}...; rebuild it",
                )
        return s


def _json_default(obj: Any) -> Any:
    if hasattr(obj, "tolist"):
        return obj.tolist()
    raise TypeError(f"object of type {type(obj).__name__} is not JSON serialisable")


def clamp_thickness(surrogate: Surrogate, thickness_mm: float, material: str) -> tuple[float, bool]:
    """Clamp a thickness into the swept range, as the exported controllers do.

    Parameters
    ----------
    surrogate : Surrogate
    thickness_mm : float
        Wall thickness in mm.
    material : str
        Material key.

    Returns
    -------
    tuple of (float, bool)
        The clamped thickness in mm and True if it was clamped.
    """
    lo, hi = surrogate.thickness_range(material)
    if thickness_mm < lo:
        return lo, True
    if thickness_mm > hi:
        return hi, True
    if thickness_mm != thickness_mm:
        raise ValueError("thickness_mm is NaN")
    return float(thickness_mm), False


# --------------------------------------------------------------------------- error figures


def fe_point_stiffness(gap_mm: np.ndarray, force_N: np.ndarray) -> np.ndarray:
    """FE stiffness ``-dF/dgap`` at each load step, N/mm: the larger adjacent secant.

    Parameters
    ----------
    gap_mm, force_N : numpy.ndarray
        The FE curve in load-step order (mm, N).

    Returns
    -------
    numpy.ndarray
        N/mm per point (the steeper side counts, so a point at the slope jump of the walls
        meeting is classed as steep).
    """
    sec = -np.diff(force_N) / np.diff(gap_mm)
    k = np.empty(len(gap_mm))
    k[0] = sec[0]
    k[-1] = sec[-1]
    k[1:-1] = np.maximum(sec[:-1], sec[1:])
    return k


def invert_gap(
    s: Surrogate,
    force_N: np.ndarray,
    thickness_mm: float,
    material: str,
    lo_mm: float,
    iters: int = 60,
) -> np.ndarray:
    """Gap (mm) where the surrogate force reaches ``force_N`` (vectorised bisection).

    Parameters
    ----------
    s : Surrogate
    force_N : numpy.ndarray
        Target forces in N (> 0).
    thickness_mm : float
        Thickness in mm.
    material : str
        Material key.
    lo_mm : float
        Lower bracket in mm (the surrogate force there must exceed the targets).
    iters : int
        Bisection steps.

    Returns
    -------
    numpy.ndarray
        Gaps in mm (largest gap with ``F >= force_N`` up to bisection accuracy).
    """
    target = np.asarray(force_N, dtype=float)
    lo = np.full(target.shape, float(lo_mm))
    hi = np.full(target.shape, s.diameter_mm)
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        above = s.force(mid, thickness_mm, material) >= target
        lo = np.where(above, mid, lo)
        hi = np.where(above, hi, mid)
    return 0.5 * (lo + hi)


def _summ(force_pct: list[np.ndarray], gap_mm: list[np.ndarray]) -> dict[str, Any]:
    fp = np.concatenate(force_pct) if force_pct else np.zeros(0)
    gp = np.concatenate(gap_mm) if gap_mm else np.zeros(0)
    return {
        "force_rms_pct": float(np.sqrt(np.mean(fp**2))) if fp.size else None,
        "force_max_pct": float(np.max(np.abs(fp))) if fp.size else None,
        "n_force": int(fp.size),
        "gap_rms_mm": float(np.sqrt(np.mean(gp**2))) if gp.size else None,
        "gap_max_mm": float(np.max(np.abs(gp))) if gp.size else None,
        "n_gap": int(gp.size),
    }


def case_errors(s: Surrogate, case: FECase, params: BuildParams) -> dict[str, dict]:
    """Errors of the surrogate on one FE case, haptic and full range.

    Points with FE stiffness (:func:`fe_point_stiffness`) below ``params.steep_N_per_mm``
    get the force error at equal gap in % of full scale (``force_ref_N`` in the haptic range,
    the case's ``force_cap_N`` in the full range); steeper points get the gap error at equal
    force in mm. The haptic range is first touch to the first load step where the FE force
    reaches ``force_ref_N``.

    Parameters
    ----------
    s : Surrogate
    case : FECase
    params : BuildParams

    Returns
    -------
    dict
        ``{"haptic": {...}, "full": {...}}`` each with the raw arrays
        ``force_pct``, ``gap_mm`` and ``n_extrapolated``.
    """
    g, f = case.gap_mm, case.force_N
    k = fe_point_stiffness(g, f)
    fs, flag = s.force(g, case.thickness_mm, case.material, return_flag=True)
    steep = k >= params.steep_N_per_mm
    reach = np.flatnonzero(f >= params.force_ref_N)
    n_hap = (reach[0] + 1) if reach.size else g.size
    hap = np.zeros(g.size, bool)
    hap[:n_hap] = True
    gap_err = np.zeros(g.size)
    if steep.any():
        lo = min(float(g.min()), s.curves(case.material)[0].gap_mm[0]) - 2.0
        gi = invert_gap(s, f[steep], case.thickness_mm, case.material, lo)
        gap_err[steep] = gi - g[steep]
    out = {}
    for name, sel, fsc in (
        ("haptic", hap, params.force_ref_N),
        ("full", np.ones_like(hap), case.force_cap_N),
    ):
        out[name] = {
            "force_pct": 100.0 * (fs - f)[sel & ~steep] / fsc,
            "gap_mm": gap_err[sel & steep],
            "n_extrapolated": int((flag & sel).sum()),
        }
    return out


def error_figures(
    s: Surrogate, cases: Sequence[FECase], params: BuildParams | None = None
) -> dict[str, Any]:
    """Error figures of a surrogate on FE cases, per material and overall.

    Parameters
    ----------
    s : Surrogate
        The surrogate (its scheme is used).
    cases : sequence of FECase
        Reference FE cases (not necessarily grid thicknesses).
    params : BuildParams, optional
        Thresholds (default ``s.params``).

    Returns
    -------
    dict
        ``{"haptic": {"all": summary, "<material>": summary, ...}, "full": {...},
        "cases": [per-case summaries]}``, a summary holding ``force_rms_pct``,
        ``force_max_pct``, ``n_force``, ``gap_rms_mm``, ``gap_max_mm``, ``n_gap`` and
        ``n_extrapolated``.
    """
    params = params or s.params
    return _aggregate(s.scheme, ((s, c) for c in cases), params)


def _aggregate(scheme: str, pairs, params: BuildParams) -> dict[str, Any]:
    """Error figures over ``(surrogate, case)`` pairs: per material, all, and per case."""
    acc: dict[str, dict[str, tuple[list, list, list]]] = {"haptic": {}, "full": {}}
    per_case = []
    for sur, c in pairs:
        e = case_errors(sur, c, params)
        row: dict[str, Any] = {
            "stem": c.stem,
            "material": c.material,
            "thickness_mm": c.thickness_mm,
        }
        for rng in ("haptic", "full"):
            r = e[rng]
            for key in (c.material, "all"):
                a = acc[rng].setdefault(key, ([], [], []))
                a[0].append(r["force_pct"])
                a[1].append(r["gap_mm"])
                a[2].append(r["n_extrapolated"])
            row[rng] = {
                **_summ([r["force_pct"]], [r["gap_mm"]]),
                "n_extrapolated": r["n_extrapolated"],
            }
        per_case.append(row)
    out: dict[str, Any] = {"scheme": scheme}
    for rng, d in acc.items():
        out[rng] = {
            key: {**_summ(a[0], a[1]), "n_extrapolated": int(sum(a[2]))} for key, a in d.items()
        }
    out["cases"] = per_case
    return out


def leave_one_out(
    s: Surrogate, cases: Sequence[FECase], schemes: Sequence[str] = SCHEMES
) -> dict[str, Any]:
    """Leave-one-thickness-out error figures over the interior grid thicknesses.

    Each interior curve is dropped in turn (its neighbours are then 2 grid steps apart) and
    the reduced surrogate is compared with that FE case (:func:`error_figures`).

    Parameters
    ----------
    s : Surrogate
        Surrogate built from ``cases``.
    cases : sequence of FECase
        The FE cases of the grid.
    schemes : sequence of str
        Schemes to measure.

    Returns
    -------
    dict
        ``{"schemes": {scheme: error_figures-like dict}}``.
    """
    res = {}
    for sc in schemes:
        base = s.with_scheme(sc)

        def pairs(base=base):
            for c in cases:
                ts = base.thicknesses(c.material)
                if ts[0] < c.thickness_mm < ts[-1]:
                    yield base.without(c.material, c.thickness_mm), c

        res[sc] = _aggregate(sc, pairs(), base.params)
    return {"schemes": res}


def format_errors(fig: Mapping[str, Any], title: str = "") -> str:
    """Plain-text table of error figures (output of :func:`error_figures`, or of
    :meth:`Surrogate.check` / :func:`leave_one_out` with several schemes).

    Parameters
    ----------
    fig : mapping
        Error figures.
    title : str
        Heading line.

    Returns
    -------
    str
    """
    figs = fig["schemes"] if "schemes" in fig else {fig.get("scheme", "?"): fig}
    lines = [title] if title else []
    hdr = (
        f"{'scheme':8s} {'range':7s} {'material':8s} {'F rms %':>8s} {'F max %':>8s} "
        f"{'nF':>5s} {'gap rms':>8s} {'gap max':>8s} {'nG':>5s} {'extrap':>6s}"
    )
    lines.append(hdr)
    lines.append("-" * len(hdr))

    def f(v, fmt):
        return "-" if v is None else format(v, fmt)

    for sc, fg in figs.items():
        for rng in ("haptic", "full"):
            rows = fg.get(rng, {})
            for mat in sorted(rows, key=lambda k: (k == "all", k)):
                r = rows[mat]
                lines.append(
                    f"{sc:8s} {rng:7s} {mat:8s} {f(r['force_rms_pct'], '8.3f')} "
                    f"{f(r['force_max_pct'], '8.3f')} {r['n_force']:5d} "
                    f"{f(r['gap_rms_mm'], '8.4f')} {f(r['gap_max_mm'], '8.4f')} "
                    f"{r['n_gap']:5d} {r.get('n_extrapolated', 0):6d}"
                )
    lines.append(
        "F: force error at equal gap, % of full scale (haptic: force_ref_N, full: "
        "force cap), where FE stiffness < steep_N_per_mm; gap: gap error at equal "
        "force (mm) where steeper; extrap: points below the FE gap range (flagged)"
    )
    return "\n".join(lines)


def plot_surrogate(
    s: Surrogate,
    path: str | os.PathLike[str],
    fe_dir: str | os.PathLike[str] | None = None,
    *,
    n_gap: int = 600,
) -> Path:
    """Force (log scale) and stiffness vs gap, one panel column per material (PNG).

    Curves are drawn at the thicknesses of the FE cases in ``fe_dir`` (else at the grid
    thicknesses), with the FE points over them; the gap axis spans first touch down to the
    closed height, zoomed on the wall contact in the lower row.

    Parameters
    ----------
    s : Surrogate
    path : str or os.PathLike
        PNG file to write.
    fe_dir : str or os.PathLike, optional
        FE cases to overlay (e.g. ``fe_data/holdout``).
    n_gap : int
        Evaluation points per curve.

    Returns
    -------
    pathlib.Path
    """
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    cases: list[FECase] = []
    if fe_dir is not None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            cases, _ = read_fe_cases(fe_dir)
    mats = list(s.materials)
    fig, axes = plt.subplots(3, len(mats), figsize=(5.0 * len(mats), 11.0), squeeze=False)
    cmap = plt.get_cmap("viridis")
    for col, m in enumerate(mats):
        lo, hi = s.thickness_range(m)
        mc = [c for c in cases if c.material == m and lo <= c.thickness_mm <= hi]
        ts = [c.thickness_mm for c in mc] if mc else list(s.thicknesses(m))
        x_lo = min(c.gap_mm[0] for c in s.curves(m))
        for t in ts:
            col_t = cmap(0.0 if hi == lo else (t - lo) / (hi - lo))
            g = np.concatenate(
                [
                    np.geomspace(x_lo, s.diameter_mm, n_gap),
                    np.linspace(2 * t - 0.6, 2 * t + 0.3, n_gap),
                ]
            )
            g.sort()
            f = s.force(g, t, m)
            k = s.stiffness(g, t, m)
            keep = f > 0
            axes[0][col].plot(g[keep], f[keep], "-", color=col_t, lw=1.0, label=f"{t:.2f} mm")
            axes[1][col].plot(g - 2 * t, f, "-", color=col_t, lw=1.0)
            axes[2][col].plot(g[k > 0], k[k > 0], "-", color=col_t, lw=1.0)
        for c in mc:
            col_t = cmap(0.0 if hi == lo else (c.thickness_mm - lo) / (hi - lo))
            keep = c.force_N > 0
            axes[0][col].plot(c.gap_mm[keep], c.force_N[keep], "o", ms=2.5, mfc="none", color=col_t)
            axes[1][col].plot(
                c.gap_mm - 2 * c.thickness_mm, c.force_N, "o", ms=2.5, mfc="none", color=col_t
            )
            kf = fe_point_stiffness(c.gap_mm, c.force_N)
            axes[2][col].plot(c.gap_mm[kf > 0], kf[kf > 0], "o", ms=2.0, mfc="none", color=col_t)
        ax = axes[0][col]
        ax.set_yscale("log")
        ax.set_xscale("log")
        ax.set_title(f"{m} ({s.scheme}): force, lines = surrogate, o = FE")
        ax.set_xlabel("jaw gap (mm)")
        ax.set_ylabel("force (N)")
        ax.legend(fontsize=6, ncol=2, title="thickness", title_fontsize=6)
        ax = axes[1][col]
        ax.set_xlim(-0.5, 0.3)
        ax.set_ylim(0, 2 * s.params.force_ref_N)
        ax.set_title("haptic range, zoom on wall contact")
        ax.set_xlabel("gap - 2 t (mm)")
        ax.set_ylabel("force (N)")
        ax = axes[2][col]
        ax.set_yscale("log")
        ax.set_xscale("log")
        ax.set_title("stiffness -dF/dgap (FE: larger adjacent secant)")
        ax.set_xlabel("jaw gap (mm)")
        ax.set_ylabel("stiffness (N/mm)")
        for a in axes[:, col]:
            a.grid(True, alpha=0.3, which="both")
    fig.suptitle(f"Surrogate ({s.source}) vs FE ({fe_dir})")
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def load_surrogate(
    surrogate: str | os.PathLike[str] | None, fe: str | os.PathLike[str] | None
) -> Surrogate:
    """Load a surrogate file, or build one from an FE sweep (default: the shipped sweep).

    Parameters
    ----------
    surrogate : str or path-like or None
        A surrogate JSON file (``grasprom surrogate build``); wins over ``fe``.
    fe : str or path-like or None
        An FE sweep directory; None: the shipped ``fe_data/default``.

    Returns
    -------
    Surrogate
    """
    from grasprom.paths import DEFAULT_SWEEP_DIR, resolve_data_dir

    if surrogate:
        return Surrogate.load(surrogate)
    return Surrogate.build(resolve_data_dir(fe or DEFAULT_SWEEP_DIR))
