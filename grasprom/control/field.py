r"""The stiffness-clipped rendering: a conservative handle-force field tabulated along the angle.

With ``rendering = "clipped"`` (:class:`~grasprom.control.params.ControllerParams`) the
controller renders the tissue's own static handle force wherever its stiffness is below what the
device renders passively, and the stiffest passive wall beyond, with no virtual coupling in
series (the coupling softens even the soft bending regime, ``k_c k_t / (k_c + k_t)``).

The field is a table of the static handle force on ``N = FIELD_POINTS`` nodes spaced uniformly
in the handle angle over the chain's range, ``theta_j = theta_lo + j dtheta``:

1. the static handle force of the tissue (and of the return spring, when rendered) at each node,
   ``Fi_s,j = F_t(g_j) a_j + S_j`` (N at the grip), with the jaw gap ``g_j = g(theta_j)``,
   ``a_j = g'(theta_j) / L3`` (virtual work) and ``F_t`` the (scaled) surrogate tissue force;
   with a series jaw compliance ``C`` the tissue sees the gap ``g + C F``, so ``F_t`` solves
   ``F = s F_sur(g_j + C F)`` (bisection, :data:`COMPLIANCE_BISECTIONS` halvings);
2. a slope-limited track of that curve from the open end: ``Fi_r,N-1 = Fi_s,N-1`` and, going
   toward the closed end, ``Fi_r,j = min(max(Fi_s,j, Fi_r,j+1 - l), Fi_r,j+1 + l)``, where
   ``l = K_g dtheta`` and ``K_g = K_lim / (L3 (1 + sum g_i))`` is the stiffness limit in N per
   rad at the grip (``K_lim`` at the pivot, N m/rad, divided by the instantaneous factor of the
   rendered Prony series).  The track equals the tissue curve wherever it can follow it with a
   slope of at most ``K_g``; where the tissue is stiffer it climbs at ``K_g`` (the stiffest
   passive wall) and rejoins the tissue as soon as it can;
3. the table stores the rendered *jaw* force ``Fr_j = max((Fi_r,j - S_j) / a_j, 0)`` (the jaws
   cannot pull: where the limit is below the return spring's own stiffness the track can fall
   below the spring's force, and the field then renders the spring alone); the step
   interpolates it linearly at the chain angle and renders ``Fi = Fr a + S`` as the coupling
   scheme renders its coupled jaw force (Prony series, friction, spring and damping on top).

Every node-to-node slope of the track is bounded by ``K_g`` (unless ``K_g`` is below the
return spring's own handle stiffness, which no passive rendering of the spring can meet), so the
sampled-data passivity condition of the tuner, ``b > K T/2 + |B|`` (Colgate & Schenkel 1997;
for a nonlinear static environment with slopes in ``[-K, K]``: Miller, Colgate & Freeman 2000),
holds with ``K = K_lim`` up to two things the tuner checks on the rendered slopes
(:func:`grasprom.control.stiffness.field_stiffness_extremes`): the table is linear in the *jaw*
force, so inside an interval the handle force ``Fr a + S`` departs from the chord by the chain's
curvature (its slope up to ~0.04 % above ``K_lim`` at the closed end), and where the field
renders the spring alone its slope is the spring's.  Lengths mm, forces N, angles rad inside.

The table is built with scalar Python floats in the order written above: the C core of the
FMU builds the same table in ``gc_init`` operation for operation (tests compare them).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from grasprom.chain import kinematics as kin

if TYPE_CHECKING:
    from grasprom.control.params import ControllerParams

__all__ = [
    "COMPLIANCE_BISECTIONS",
    "FIELD_POINTS",
    "Field",
    "build_field",
    "compliant_force_N",
    "jaw_stiffness_limit_N_per_mm",
    "prony_factor",
]

FIELD_POINTS = 1025
"""Nodes of the field table along the handle angle (1024 intervals over the chain's range)."""

COMPLIANCE_BISECTIONS = 60
"""Halvings of the bisection for the tissue force behind a series jaw compliance."""


@dataclass(frozen=True)
class Field:
    """The tabulated field of one operating case (angles rad, forces N).

    Attributes
    ----------
    theta_lo_rad, dtheta_rad : float
        First node and node spacing (rad).
    force_jaw_N : tuple of float
        Rendered jaw force ``Fr_j`` at the nodes (N).
    force_tissue_N : tuple of float
        Tissue jaw force ``F_t(g_j)`` at the nodes (N), for reports.
    clipped : tuple of bool
        Whether the track differs from the tissue curve at the node (the stiffness limit acts).
    stiffness_limit_N_per_rad : float
        ``K_g``: the bound on the slope of the handle force (N per rad at the grip).
    """

    theta_lo_rad: float
    dtheta_rad: float
    force_jaw_N: tuple[float, ...]
    force_tissue_N: tuple[float, ...]
    clipped: tuple[bool, ...]
    stiffness_limit_N_per_rad: float

    def jaw_force_N(self, theta_rad: float) -> tuple[float, bool]:
        """Rendered jaw force (N) at the chain angle ``theta_rad`` and whether it is clipped.

        Linear interpolation between the bracketing nodes; the interval is *clipped* if either
        node is.  Angles outside the range use the end interval (the controller clamps first).
        """
        u = (theta_rad - self.theta_lo_rad) / self.dtheta_rad
        j = int(math.floor(u))
        n = len(self.force_jaw_N)
        if j < 0:
            j = 0
        elif j > n - 2:
            j = n - 2
        w = u - j
        f0 = self.force_jaw_N[j]
        f = f0 + w * (self.force_jaw_N[j + 1] - f0)
        return f, self.clipped[j] or self.clipped[j + 1]

    def jaw_force_array(self, theta_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`jaw_force_N` on an array of chain angles (rad), vectorised.

        The same operations in the same order as the scalar method (bit-identical in double).

        Returns
        -------
        (ndarray, ndarray)
            Rendered jaw force (N) and whether the interval is clipped.
        """
        th = np.asarray(theta_rad, dtype=float)
        fr = np.asarray(self.force_jaw_N, dtype=float)
        cl = np.asarray(self.clipped, dtype=bool)
        u = (th - self.theta_lo_rad) / self.dtheta_rad
        j = np.clip(np.floor(u).astype(np.int64), 0, len(fr) - 2)
        w = u - j
        f0 = fr[j]
        return f0 + w * (fr[j + 1] - f0), cl[j] | cl[j + 1]


def compliant_force_N(tissue: Callable[[float], float], gap_mm: float, compliance: float) -> float:
    """Tissue force ``F`` (N) behind a series compliance: ``F = tissue(gap + C F)``.

    ``tissue`` is decreasing in the gap, so ``F - tissue(g + C F)`` increases in ``F`` and the
    root lies in ``[0, tissue(g)]``; found by :data:`COMPLIANCE_BISECTIONS` halvings.

    Parameters
    ----------
    tissue : callable
        Tissue jaw force (N) at a gap (mm).
    gap_mm : float
        Kinematic jaw gap (mm).
    compliance : float
        Series compliance ``C`` (mm/N); 0 returns ``tissue(gap_mm)``.
    """
    f0 = tissue(gap_mm)
    if compliance == 0.0 or f0 <= 0.0:
        return f0
    lo, hi = 0.0, f0
    for _ in range(COMPLIANCE_BISECTIONS):
        mid = 0.5 * (lo + hi)
        if mid - tissue(gap_mm + compliance * mid) > 0.0:
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)


def _non_negative(x: float) -> float:
    """``x`` clipped at 0 (the jaws cannot pull; as the C core: -0.0 and NaN give 0.0)."""
    return x if x > 0.0 else 0.0


def prony_factor(prony_g: tuple[float, ...]) -> float:
    """Instantaneous stiffness factor ``1 + sum g_i`` of a Prony series (1).

    Summed left to right from 0 with plain float additions, as the C core does (Python 3.12's
    ``sum`` of floats is compensated and could differ by an ulp).
    """
    acc = 0.0
    for g in prony_g:
        acc += g
    return 1.0 + acc


def build_field(
    tissue: Callable[[float], float],
    chain: kin.ChainParams,
    stiffness_limit_Nm_per_rad: float,
    *,
    render_spring: bool = True,
    compliance_mm_per_N: float = 0.0,
    prony_factor: float = 1.0,
    n: int = FIELD_POINTS,
) -> Field:
    """Tabulate the stiffness-clipped field (module docstring) for one operating case.

    Parameters
    ----------
    tissue : callable
        Tissue jaw force (N, already scaled) at a gap (mm), e.g. the controller's surrogate.
    chain : ChainParams
        The linkage (with the controller's spring rate).
    stiffness_limit_Nm_per_rad : float
        ``K_lim``: the largest handle stiffness rendered, N m/rad at the pivot (> 0).
    render_spring : bool
        Whether the return spring's handle force is part of the rendered field.
    compliance_mm_per_N : float
        Series jaw compliance ``C`` (mm/N, >= 0).
    prony_factor : float
        Instantaneous stiffness factor ``1 + sum g_i`` of the rendered Prony series (>= 1).
    n : int
        Number of nodes (>= 2).

    Returns
    -------
    Field
    """
    lo_deg, hi_deg = kin.theta_range_deg(chain)
    th_lo, th_hi = math.radians(lo_deg), math.radians(hi_deg)
    dth = (th_hi - th_lo) / (n - 1)
    L3 = chain.L3_mm
    kg = stiffness_limit_Nm_per_rad / (L3 * 1e-3) / prony_factor
    lim = kg * dth
    ft, a, s = [], [], []
    for j in range(n):
        th_deg = math.degrees(th_lo + j * dth) if j < n - 1 else hi_deg
        g = kin.gap_mm(th_deg, chain)
        ft.append(compliant_force_N(tissue, g, compliance_mm_per_N))
        a.append(kin.dgap_dtheta_mm_per_rad(th_deg, chain) / L3)
        s.append(kin.spring_handle_force_N(th_deg, chain) if render_spring else 0.0)
    fis = [ft[j] * a[j] + s[j] for j in range(n)]
    fir = list(fis)
    for j in range(n - 2, -1, -1):
        v = fis[j]
        lo, hi = fir[j + 1] - lim, fir[j + 1] + lim
        if v < lo:
            v = lo
        elif v > hi:
            v = hi
        fir[j] = v
    fr = tuple(_non_negative((fir[j] - s[j]) / a[j]) for j in range(n))
    clipped = tuple(fir[j] != fis[j] for j in range(n))
    return Field(th_lo, dth, fr, tuple(ft), clipped, kg)


def jaw_stiffness_limit_N_per_mm(params: ControllerParams, theta_deg: np.ndarray) -> np.ndarray:
    """The rendering's bound on the jaw stiffness at chain angles ``theta_deg`` (N/mm).

    Clipped rendering: the handle-stiffness limit mapped to the jaw through the chain,
    ``K_g L3 / g'(theta)^2`` (``K_g`` as in :func:`build_field`, N/rad at the grip; the term of
    the chain's curvature, ``F a'``, is left out; with the passivity observer the limit is
    ``field_stiffness_limit_Nm_per_rad``, the bound times the observer's factor); coupling: the
    effective coupling stiffness
    ``k_c,eff`` (the rendered jaw stiffness ``k_c k_t / (k_c + k_t)`` stays below it).

    Parameters
    ----------
    params : ControllerParams
    theta_deg : array_like
        Chain angles (deg).

    Returns
    -------
    numpy.ndarray
    """
    th = np.asarray(theta_deg, dtype=float)
    if params.rendering != "clipped":
        return np.full(th.shape, params.coupling_effective_N_per_mm)
    chain = params.chain_params
    L3 = chain.L3_mm
    kg = params.field_stiffness_limit_Nm_per_rad / (L3 * 1e-3) / prony_factor(params.prony_g)
    g1 = np.asarray(kin.dgap_dtheta_mm_per_rad(th, chain), dtype=float)
    return kg * L3 / (g1 * g1)
