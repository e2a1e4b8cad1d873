"""Closed-loop stability of device (+ hand) and controller, with python-control.

ZOH-discretised device + hand (``c2d``), delay and controller, ``feedback`` / ``poles`` /
``stability_margins``.  ``import control`` here is python-control (absolute import), not
:mod:`grasprom.control`.
"""

from __future__ import annotations

import math
import warnings
from typing import TYPE_CHECKING, Any

import numpy as np

from grasprom.control.device import DeviceParams, HandParams

if TYPE_CHECKING:  # python-control is imported when used (about 0.5 s)
    import control as ct

__all__ = ["closed_loop", "damping_ratio", "environment_tf"]


def damping_ratio(poles: np.ndarray, T: float) -> tuple[float, float | None]:
    """Smallest damping ratio (1) of the oscillatory discrete poles and its frequency (Hz).

    Each pole ``z`` maps to ``s = ln(z) / T``; ``zeta = -Re(s) / |s|``.  Poles at the origin
    (the delay) and real poles are left out; ``(1.0, None)`` when no pole oscillates.

    Parameters
    ----------
    poles : ndarray
        Closed-loop poles in the z-plane.
    T : float
        Sample time, s.

    Returns
    -------
    tuple of float and (float or None)
        ``(zeta_min, natural frequency of that pole in Hz)``.
    """
    z = np.asarray(poles, dtype=complex)
    z = z[(np.abs(z) > 1e-9) & (np.abs(z.imag) > 1e-12)]
    if z.size == 0:
        return 1.0, None
    sp = np.log(z) / T
    zeta = -sp.real / np.abs(sp)
    i = int(np.argmin(zeta))
    return float(zeta[i]), float(np.abs(sp[i]) / (2 * math.pi))


def environment_tf(
    K: float, B: float, T: float, cutoff_Hz: float, delay: int
) -> ct.TransferFunction:
    """Discrete environment ``H(z)`` (N m/rad) as a python-control transfer function."""
    import control as ct

    a = math.exp(-2.0 * math.pi * cutoff_Hz * T)
    z = ct.tf([1.0, 0.0], [1.0], T)
    h = K + B * (1.0 - a) * (z - 1) / (T * (z - a))
    for _ in range(int(delay)):
        h = h * ct.tf([1.0], [1.0, 0.0], T)
    return ct.minreal(h, verbose=False) if B == 0 else h


def closed_loop(
    K: float,
    B: float,
    cutoff_Hz: float,
    T: float,
    device: DeviceParams,
    hand: HandParams | None,
    L3_mm: float,
) -> dict[str, Any]:
    """Poles and margins of the sampled-data loop: device (+ hand) + ZOH + delay + controller.

    Plant ``1 / ((J + J_h) s^2 + (b + b_h) s + k_h)`` (torque -> angle) discretised with a ZOH
    (``control.c2d``), closed by ``tau = -H(z) theta`` (``control.feedback``).

    Returns
    -------
    dict
        ``max_pole_mag`` (stable iff < 1), ``stable``, ``gain_margin`` (factor on the loop gain;
        ``inf`` if none), ``phase_margin_deg``, ``gain_crossover_Hz``, ``phase_crossover_Hz``,
        ``damping_ratio`` (smallest of the oscillatory poles, :func:`damping_ratio`) and
        ``damping_ratio_frequency_Hz`` (its natural frequency).
    """
    import control as ct

    jh, bh, kh = hand.at_pivot(L3_mm) if hand is not None else (0.0, 0.0, 0.0)
    plant = ct.tf([1.0], [device.inertia_kg_m2 + jh, device.damping_Nms_per_rad + bh, kh])
    pd = ct.c2d(plant, T, method="zoh")
    h = environment_tf(K, B, T, cutoff_Hz, device.delay_samples)
    cl = ct.feedback(pd, h)
    poles = np.asarray(cl.poles())
    pmax = float(np.max(np.abs(poles)))
    loop = h * pd
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # 'poly' -> 'frd' fallback notice
        gm, pm, _sm, wpc, wgc, _wms = ct.stability_margins(loop, returnall=False)

    def _hz(w: float) -> float | None:
        return None if w is None or not np.isfinite(w) else float(w) / (2 * math.pi)

    zeta, f_zeta = damping_ratio(poles, T)
    return {
        "max_pole_mag": pmax,
        "stable": bool(pmax < 1.0),
        "gain_margin": float(gm) if gm is not None and np.isfinite(gm) else math.inf,
        "phase_margin_deg": float(pm) if pm is not None and np.isfinite(pm) else math.inf,
        "gain_crossover_Hz": _hz(wgc),
        "phase_crossover_Hz": _hz(wpc),
        "damping_ratio": zeta,
        "damping_ratio_frequency_Hz": f_zeta,
    }
