r"""Transparency of a tuning: how much of the tissue force the user feels, per operating case.

For every operating case (material x thickness) :func:`transparency_table` gives, quasi-static
(no velocity, Prony relaxed), the ratio of the rendered jaw force to the tissue jaw force at the
jaw gap where the tissue force reaches each level of :data:`FORCE_LEVELS_N`:

* coupling rendering: the converged proxy of the virtual coupling, ``k_c (g_p - g)`` against
  ``F(g)``;
* clipped rendering: the field's jaw force against the tissue force at the same angle.

It also gives the rendered wall stiffness against the passive bound: the median rendered
handle stiffness where the tissue is stiffer than the bound (clipped: measured on the field's
nodes, the median slope of its clipped intervals), and what it would take to render the
tissue exactly up to 20 N: ``K_20``, the largest tissue handle stiffness while the tissue force
is below 20 N, the physical damping ``b_needed`` and the sample rate ``rate_needed`` for which
``K_20`` is passive (with the same safety factor, ``B`` and cutoff re-optimised).

``b_needed = b K_20 / K_pass``: the passivity condition is homogeneous in ``(K, B, b)``, so with
``B`` scaled along the passive stiffness scales with ``b`` (exact without rendered viscous
friction, whose share of ``B`` is fixed).  ``rate_needed`` interpolates the passive stiffness
over the rates ``1 kHz x 2^i`` (log-log; beyond the last one it grows like the rate, the
Colgate ``2 b / T``).

Forces N, stiffness N m/rad at the handle pivot, gaps mm, angles deg, rates Hz.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from grasprom.chain import kinematics as kin
from grasprom.control.device import DeviceParams
from grasprom.control.params import ControllerParams
from grasprom.control.passivity import best_filter
from grasprom.control.stiffness import (
    OperatingPoints,
    clipped_field,
    prony_stiffness_factor,
    rendered_stiffness,
)
from grasprom.surrogate import Surrogate

__all__ = [
    "FORCE_LEVELS_N",
    "PLOT_CASES",
    "RATE_GRID_HZ",
    "case_transparency",
    "force_curves",
    "passive_stiffness_at_rates",
    "transparency_table",
]

FORCE_LEVELS_N = (0.5, 2.0, 5.0, 20.0)
"""Tissue force levels of the transparency ratios, N."""

EXACT_UP_TO_N = 20.0
"""Tissue force up to which ``b_needed`` / ``rate_needed`` render the tissue exactly, N."""

RATE_GRID_HZ = tuple(1000.0 * 2.0**i for i in range(11))
"""Sample rates of the passive-stiffness curve behind ``rate_needed`` (1 kHz to 1.02 MHz)."""

PLOT_CASES = (("mr", 0.8), ("mr", 1.4), ("mr", 2.0), ("le", 2.0))
"""Cases of the force-over-gap figure (those present in the tuning)."""

_N_FINE = 1601  # angle samples bracketing the level crossings
_BISECTIONS = 30  # halvings of a bracket (0.014 deg -> 1e-11 deg)


def _tissue_force(s: Surrogate, p: ControllerParams, th_deg: np.ndarray) -> np.ndarray:
    """(Scaled) tissue jaw force at the kinematic gap of the angles ``th_deg``, N."""
    g = np.asarray(kin.gap_mm(th_deg, p.chain_params), dtype=float)
    return p.tissue_scale * np.asarray(s.force(g, p.thickness_mm, p.material), dtype=float)


def _level_angles(s: Surrogate, p: ControllerParams, levels: Sequence[float]) -> list[float | None]:
    """Angle (deg) where the tissue force first reaches each level when closing (None: never)."""
    lo, hi = kin.theta_range_deg(p.chain_params)
    th = np.linspace(lo, hi, _N_FINE)
    f = _tissue_force(s, p, th)
    out: list[float | None] = []
    for L in levels:
        above = np.flatnonzero(f >= L)
        if above.size == 0:
            out.append(None)
            continue
        j = int(above.max())  # the most open angle still at >= L
        if j == _N_FINE - 1 or f[j] == L:
            out.append(float(th[j]))
            continue
        a, b = float(th[j]), float(th[j + 1])  # f(a) >= L > f(b): bisect the crossing
        for _ in range(_BISECTIONS):
            mid = 0.5 * (a + b)
            if _tissue_force(s, p, np.array([mid]))[0] >= L:
                a = mid
            else:
                b = mid
        out.append(a)
    return out


def case_transparency(
    s: Surrogate,
    p: ControllerParams,
    op: OperatingPoints,
    k_pass: float,
    levels: Sequence[float] = FORCE_LEVELS_N,
) -> dict[str, Any]:
    """Transparency figures of one case (``p`` at its material/thickness, ``op`` its points).

    Parameters
    ----------
    s : Surrogate
    p : ControllerParams
        Tuned parameters at the case's material and thickness.
    op : OperatingPoints
        Its rendered stiffness along the angle.
    k_pass : float
        Passive stiffness bound with the safety margin, N m/rad.
    levels : sequence of float
        Tissue force levels, N.

    Returns
    -------
    dict
        ``material``, ``thickness_mm``, ``ratios`` (level -> rendered/tissue or None),
        ``theta_deg`` at the levels, ``max_rendered_N`` / ``max_tissue_N`` (closed end),
        ``wall_K_Nm_per_rad`` (median rendered K where ``K_raw > k_pass``, None if nowhere),
        ``bound_K_Nm_per_rad``, ``wall_over_bound``, ``K20_Nm_per_rad`` (the largest tissue
        handle stiffness while the tissue force is at most 20 N, on a fine angle grid).
    """
    lo, _hi = kin.theta_range_deg(p.chain_params)
    ths = _level_angles(s, p, levels)
    probe = [t for t in ths if t is not None] + [lo]
    fr = rendered_stiffness(s, p, np.array(probe)).force_jaw_N
    ft = _tissue_force(s, p, np.array(probe))
    ratios: dict[str, float | None] = {}
    k = 0
    for L, t in zip(levels, ths):
        if t is None:
            ratios[f"{L:g}"] = None
            continue
        ratios[f"{L:g}"] = float(fr[k] / ft[k]) if ft[k] > 0 else None
        k += 1
    wall = op.K_raw_Nm_per_rad > k_pass
    wall_K = float(np.median(op.K_Nm_per_rad[wall])) if np.any(wall) else None
    if p.rendering == "clipped" and wall_K is not None:
        wall_K = _field_wall_K(s, p)
    k20 = _k20(s, p)
    return {
        "material": p.material,
        "thickness_mm": float(p.thickness_mm),
        "ratios": ratios,
        "theta_deg": {f"{L:g}": t for L, t in zip(levels, ths)},
        "max_rendered_N": float(fr[-1]),
        "max_tissue_N": float(ft[-1]),
        "wall_K_Nm_per_rad": wall_K,
        "bound_K_Nm_per_rad": k_pass,
        "wall_over_bound": None if wall_K is None else wall_K / k_pass,
        "K20_Nm_per_rad": k20,
    }


def _k20(s: Surrogate, p: ControllerParams) -> float:
    """Largest tissue handle stiffness (N m/rad) while the tissue force is in (0, 20 N].

    On :data:`_N_FINE` angles over the chain's range and at the 20 N crossing itself
    (independent of the tuning's grid).
    """
    lo, hi = kin.theta_range_deg(p.chain_params)
    th = np.linspace(lo, hi, _N_FINE)
    t20 = _level_angles(s, p, [EXACT_UP_TO_N])[0]
    if t20 is not None:  # the stiffest point below 20 N is usually at 20 N itself
        th = np.sort(np.append(th, t20))
    f = _tissue_force(s, p, th)
    below = (f > 0) & (f <= EXACT_UP_TO_N * (1 + 1e-9))
    if not np.any(below):
        return 0.0
    k_raw = rendered_stiffness(
        s, replace(p, rendering="coupling", passivity_observer=False), th[below]
    ).K_raw_Nm_per_rad
    return float(np.max(k_raw))


def _field_wall_K(s: Surrogate, p: ControllerParams) -> float | None:
    """Median handle stiffness of the clipped field where it is clipped, N m/rad (measured).

    From the field's nodes: handle force ``Fr a + S`` (N), its slope over the intervals whose
    both nodes are clipped, times ``L3`` and the Prony factor (instantaneous).
    """
    f = clipped_field(s, p)
    chain = p.chain_params
    n = len(f.force_jaw_N)
    deg = np.degrees(f.theta_lo_rad + f.dtheta_rad * np.arange(n))
    deg[-1] = kin.theta_range_deg(chain)[1]
    a = np.asarray(kin.dgap_dtheta_mm_per_rad(deg, chain), dtype=float) / chain.L3_mm
    spring = np.asarray(kin.spring_handle_force_N(deg, chain), dtype=float)
    fi = np.asarray(f.force_jaw_N) * a + (spring if p.render_spring else 0.0)
    clipped = np.asarray(f.clipped)
    steps = clipped[:-1] & clipped[1:]
    if not np.any(steps):
        return None
    slope = np.abs(np.diff(fi))[steps] / f.dtheta_rad  # N/rad at the grip
    return float(np.median(slope)) * chain.L3_mm * 1e-3 * prony_stiffness_factor(p)


def passive_stiffness_at_rates(
    device: DeviceParams,
    safety: float,
    cutoffs_Hz: Sequence[float],
    rates_Hz: Sequence[float] = RATE_GRID_HZ,
    B_min: float = 0.0,
) -> list[float]:
    """Passive stiffness with the safety margin (N m/rad) at each rate, ``B`` and cutoff
    re-optimised (:func:`~grasprom.control.passivity.best_filter`, cutoffs below Nyquist).

    Parameters
    ----------
    device : DeviceParams
    safety : float
    cutoffs_Hz : sequence of float
    rates_Hz : sequence of float
    B_min : float
        Smallest total virtual damping (rendered viscous friction), N m s/rad.

    Returns
    -------
    list of float
    """
    out = []
    for r in rates_Hz:
        cut = [c for c in cutoffs_Hz if c < 0.5 * r] or [0.25 * r]
        _B, _fc, k = best_filter(
            device.damping_Nms_per_rad, 1.0 / r, device.delay_samples, safety, cut, 21, B_min
        )
        out.append(max(k, 0.0))
    return out


def _rate_needed(K: float, rates: Sequence[float], kpass: Sequence[float]) -> float:
    """Smallest rate (Hz) whose passive stiffness reaches ``K`` (log-log interpolation)."""
    r = np.asarray(rates, dtype=float)
    k = np.asarray(kpass, dtype=float)
    if K <= k[0]:
        return float(r[0] * max(K, 1e-12) / k[0]) if k[0] > 0 else math.inf
    if K > k[-1]:
        return float(r[-1] * K / k[-1]) if k[-1] > 0 else math.inf
    j = int(np.flatnonzero(k >= K)[0])
    w = (math.log(K) - math.log(k[j - 1])) / (math.log(k[j]) - math.log(k[j - 1]))
    return float(math.exp(math.log(r[j - 1]) + w * (math.log(r[j]) - math.log(r[j - 1]))))


def transparency_table(
    s: Surrogate,
    params: ControllerParams,
    pts: Sequence[OperatingPoints],
    device: DeviceParams,
    k_pass: float,
    rate_curve: tuple[Sequence[float], Sequence[float]],
) -> dict[str, Any]:
    """The transparency entry of the tuning summary: one row per operating case.

    Parameters
    ----------
    s : Surrogate
    params : ControllerParams
        Tuned parameters (their rendering decides the rendered force).
    pts : sequence of OperatingPoints
        The tuning's operating points (one per case).
    device : DeviceParams
    k_pass : float
        Passive stiffness with the safety margin at the tuned rate, N m/rad.
    rate_curve : tuple of sequences
        ``(rates Hz, passive stiffness N m/rad)`` of :func:`passive_stiffness_at_rates`.

    Returns
    -------
    dict
        ``rendering``, ``levels_N``, ``exact_up_to_N``, ``cases`` (:func:`case_transparency`
        plus ``b_needed_Nms_per_rad``, ``rate_needed_Hz`` and ``exact_up_to_20N_now``).
    """
    b = device.damping_Nms_per_rad
    cases = []
    for op in pts:
        p = replace(params, material=op.material, thickness_mm=op.thickness_mm)
        row = case_transparency(s, p, op, k_pass)
        k20 = row["K20_Nm_per_rad"]
        row["b_needed_Nms_per_rad"] = b * k20 / k_pass if k_pass > 0 else math.inf
        row["rate_needed_Hz"] = _rate_needed(k20, *rate_curve)
        row["exact_up_to_20N_now"] = bool(params.rendering == "clipped" and k20 <= k_pass)
        cases.append(row)
    return {
        "rendering": params.rendering,
        "levels_N": list(FORCE_LEVELS_N),
        "exact_up_to_N": EXACT_UP_TO_N,
        "rate_curve": {"rates_Hz": list(rate_curve[0]), "K_pass_Nm_per_rad": list(rate_curve[1])},
        "cases": cases,
    }


def force_curves(
    s: Surrogate, params: ControllerParams, n: int = 301
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quasi-static ``(gap mm, tissue force N, rendered jaw force N)`` along the angle.

    Parameters
    ----------
    s : Surrogate
    params : ControllerParams
        At the case's material and thickness.
    n : int
        Angle samples over the chain's range.

    Returns
    -------
    tuple of ndarray
    """
    lo, hi = kin.theta_range_deg(params.chain_params)
    th = np.linspace(lo, hi, n)
    op = rendered_stiffness(s, params, th)
    return op.gap_mm, _tissue_force(s, params, th), op.force_jaw_N
