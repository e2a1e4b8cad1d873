r"""Closed-loop damping and margins with the hand at every operating point of a tuning.

The loop of :func:`~grasprom.control.loop.closed_loop` (device + hand + ZOH + delay + the
rendered ``K`` and filtered ``B``) depends on the operating point only through ``K``, so
:func:`operating_margins` evaluates it (python-control) on a grid of :data:`N_GRID` stiffnesses
spanning every case's range, and gives each case the worst damping ratio and phase margin over
its own ``K`` range (grid points inside it, and the ends interpolated in ``log K``).

The target, stated in the report: **damping ratio >= :data:`ZETA_TARGET` with the hand at every
operating point** (the dominant pair then overshoots a step by at most
``exp(-pi zeta / sqrt(1 - zeta^2))`` = 37 %).  :func:`damping_needed` says which physical
device damping ``b`` would meet it at the stiffest point (virtual ``B`` and cutoff unchanged).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from grasprom.control.device import DeviceParams, HandParams
from grasprom.control.loop import closed_loop
from grasprom.control.stiffness import OperatingPoints

__all__ = [
    "N_GRID",
    "ZETA_TARGET",
    "damping_needed",
    "operating_margins",
    "overshoot",
]

ZETA_TARGET = 0.3
"""Target closed-loop damping ratio with the hand at every operating point (1)."""

N_GRID = 12
"""Stiffness samples of the closed-loop grid."""


def overshoot(zeta: float) -> float:
    """Step overshoot of a second-order pair with damping ratio ``zeta`` (fraction, 0..1)."""
    if zeta >= 1.0:
        return 0.0
    if zeta <= 0.0:
        return 1.0
    return math.exp(-math.pi * zeta / math.sqrt(1.0 - zeta * zeta))


def _grid(pts: Sequence[OperatingPoints]) -> np.ndarray:
    """Stiffness grid (N m/rad): geometric from ``K_max / 200`` to ``K_max``, plus ``K_min``."""
    kmax = max(float(np.max(o.K_Nm_per_rad)) for o in pts)
    kmin = min(float(np.min(o.K_Nm_per_rad)) for o in pts)
    lo = max(kmax / 200.0, 1e-6)
    g = np.geomspace(lo, kmax, N_GRID) if kmax > lo else np.array([kmax])
    if kmin < lo:
        g = np.concatenate([[kmin], g])
    return g


def _worst(grid: np.ndarray, vals: np.ndarray, k_lo: float, k_hi: float) -> float:
    """Smallest of ``vals`` over ``[k_lo, k_hi]``: grid points inside, ends interpolated."""
    inside = (grid >= k_lo) & (grid <= k_hi)
    cand = list(vals[inside])
    finite = np.isfinite(vals)
    if np.count_nonzero(finite) >= 2:
        cand += list(np.interp([k_lo, k_hi], grid[finite], vals[finite]))
    return float(min(cand)) if cand else math.inf


def operating_margins(
    pts: Sequence[OperatingPoints],
    B: float,
    cutoff_Hz: float,
    T: float,
    device: DeviceParams,
    hand: HandParams,
    L3_mm: float,
    zeta_target: float = ZETA_TARGET,
) -> dict[str, Any]:
    """Damping ratio and phase margin with the hand at every operating point.

    Parameters
    ----------
    pts : sequence of OperatingPoints
        Rendered stiffness along the angle per case (N m/rad).
    B : float
        Total virtual damping, N m s/rad.
    cutoff_Hz : float
        Velocity cutoff, Hz.
    T : float
        Sample time, s.
    device : DeviceParams
    hand : HandParams
    L3_mm : float
        Grip radius, mm.
    zeta_target : float
        Target damping ratio (1).

    Returns
    -------
    dict
        ``target`` (statement and value), ``grid`` (``K``, damping ratio, phase margin,
        frequency), ``cases`` (worst damping ratio / phase margin per case), ``worst``,
        ``meets_target``, ``K_max_meeting_target_Nm_per_rad`` (largest grid ``K`` still
        meeting it, 0 if none).
    """
    grid = _grid(pts)
    cls = [closed_loop(float(K), B, cutoff_Hz, T, device, hand, L3_mm) for K in grid]
    zeta = np.array([c["damping_ratio"] for c in cls])
    pm = np.array([c["phase_margin_deg"] for c in cls], dtype=float)
    cases = []
    for o in pts:
        lo, hi = float(np.min(o.K_Nm_per_rad)), float(np.max(o.K_Nm_per_rad))
        z = _worst(grid, zeta, lo, hi)
        cases.append({"material": o.material, "thickness_mm": o.thickness_mm,
                      "K_min_Nm_per_rad": lo, "K_max_Nm_per_rad": hi, "damping_ratio_min": z,
                      "phase_margin_min_deg": _worst(grid, pm, lo, hi),
                      "meets_target": bool(z >= zeta_target)})  # fmt: skip
    ok = grid[zeta >= zeta_target]
    worst = min(cases, key=lambda c: c["damping_ratio_min"])
    return {
        "target": {
            "damping_ratio_min": zeta_target,
            "overshoot_max": overshoot(zeta_target),
            "statement": f"closed-loop damping ratio >= {zeta_target:g} with the hand at every "
            f"operating point (step overshoot <= {100 * overshoot(zeta_target):.0f} %)",
        },
        "grid": {
            "K_Nm_per_rad": grid.tolist(),
            "damping_ratio": zeta.tolist(),
            "phase_margin_deg": pm.tolist(),
            "frequency_Hz": [c["damping_ratio_frequency_Hz"] for c in cls],
            "stable": [c["stable"] for c in cls],
        },
        "cases": cases,
        "worst": worst,
        "meets_target": bool(all(c["meets_target"] for c in cases)),
        "K_max_meeting_target_Nm_per_rad": float(ok.max()) if ok.size else 0.0,
    }


def damping_needed(
    K: float,
    B: float,
    cutoff_Hz: float,
    T: float,
    device: DeviceParams,
    hand: HandParams,
    L3_mm: float,
    zeta_target: float = ZETA_TARGET,
    b_max: float = 10.0,
) -> float:
    """Physical device damping ``b`` (N m s/rad) giving ``zeta_target`` at stiffness ``K``.

    Bisection (log scale, 14 halvings) on ``b`` with the closed loop with the hand, ``B`` and
    the cutoff unchanged; ``inf`` if even ``b_max`` does not meet it.

    Parameters
    ----------
    K : float
        Rendered stiffness, N m/rad.
    B, cutoff_Hz, T : float
        Virtual damping (N m s/rad), velocity cutoff (Hz), sample time (s).
    device : DeviceParams
    hand : HandParams
    L3_mm : float
        Grip radius, mm.
    zeta_target : float
    b_max : float
        Largest damping tried, N m s/rad.

    Returns
    -------
    float
    """

    def zeta(b: float) -> float:
        d = replace(device, damping_Nms_per_rad=b)
        return closed_loop(K, B, cutoff_Hz, T, d, hand, L3_mm)["damping_ratio"]

    lo = device.damping_Nms_per_rad
    if zeta(lo) >= zeta_target:
        return lo
    if zeta(b_max) < zeta_target:
        return math.inf
    hi = b_max
    for _ in range(14):
        mid = math.sqrt(lo * hi)
        if zeta(mid) >= zeta_target:
            hi = mid
        else:
            lo = mid
    return hi
