r"""Sampled-data passivity of the rendered impedance: Colgate, Abbott-Okamura, Z-width.

Conditions on the device damping ``b`` (N m s/rad) for a rendered stiffness ``K`` (N m/rad) and
virtual damping ``B`` (N m s/rad) at the handle pivot; the model of ``K`` and ``B`` is in
:mod:`grasprom.control.stiffness`.

Discrete environment (torque per angle): ``H(z) = z^-d [K + B (1 - a)(z - 1) / (T (z - a))]``.

Passivity (device alone, any passive user)
------------------------------------------
* Colgate & Schenkel (1997), sampled-data passivity of a mass with viscous damping ``b`` driven
  through a ZOH by ``H(z)``:  ``b > T / (2 (1 - cos wT)) Re{(1 - e^{-jwT}) H(e^{jwT})}`` for
  ``0 < w <= pi/T`` (:func:`required_damping`).  For ``d = 0`` and ``a = 0`` it reduces to the
  closed form ``b > K T / 2 + |B|`` (Colgate & Brown 1994, :func:`colgate_required_damping`);
  with a one-sample delay and ``B = 0`` to ``b > 3 K T / 2``.  With the delay, virtual damping
  on a *filtered* velocity cancels the delay's negative damping at low frequency (its
  contribution is ``-B`` at ``w -> 0`` and ``+B`` only near Nyquist, which the filter
  attenuates), so a well-chosen ``(B, f_c)`` raises the passive stiffness; this is what the tuner
  optimises.
* Abbott & Okamura (2005), with Coulomb friction ``f_c`` and the encoder quantum ``Delta``
  (no delay, ``B = 0``): passive iff ``K <= max(2 b / T, 2 f_c / Delta)``
  (:func:`abbott_okamura_bound`).  Reported, but **not** used to choose ``k_c``: it has no
  computation delay and counts on Coulomb friction, which varies and vanishes on a
  well-run-in drive; the tuner keeps the viscous, delay-aware bound.

Z-width: the set of ``(K, B)`` passive for the device (:func:`zwidth_boundary`), plotted with the
operating points.  Closed-loop poles and margins with the hand: :mod:`grasprom.control.loop`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = [
    "abbott_okamura_bound",
    "best_filter",
    "colgate_required_damping",
    "max_passive_stiffness",
    "required_damping",
    "zwidth_boundary",
]

_N_OMEGA = 2000  # frequency samples of the passivity condition on (0, pi/T]


def colgate_required_damping(K: float, B: float, T: float) -> float:
    """Closed form ``K T / 2 + |B|`` (N m s/rad): Colgate's condition ``b > K T/2 + |B|``.

    Backward-difference velocity, no filter, no computation delay.
    """
    return 0.5 * K * T + abs(B)


def _basis(
    T: float, cutoff_Hz: float | None, delay: int, n: int = _N_OMEGA
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frequency grid x = wT in (0, pi] and the K- and B-coefficients of the passivity sum."""
    x = np.linspace(math.pi / n, math.pi, n)
    zi = np.exp(-1j * x)  # z^-1
    a = 0.0 if cutoff_Hz is None else math.exp(-2.0 * math.pi * cutoff_Hz * T)
    hk = zi**delay
    hb = zi**delay * (1.0 - a) * (1.0 - zi) / (T * (1.0 - a * zi))
    scale = T / (2.0 * (1.0 - np.cos(x)))
    ck = scale * np.real((1.0 - zi) * hk)
    cb = scale * np.real((1.0 - zi) * hb)
    return x, ck, cb


def required_damping(
    K: float | np.ndarray,
    B: float,
    T: float,
    cutoff_Hz: float | None = None,
    delay: int = 0,
) -> float | np.ndarray:
    """Physical damping the device needs for the rendering to be passive, N m s/rad.

    Colgate & Schenkel (1997): ``b > max_w T/(2(1 - cos wT)) Re{(1 - e^{-jwT}) H(e^{jwT})}``
    with ``H(z) = z^-delay [K + B (1-a)(1 - z^-1)/(T (1 - a z^-1))]``, evaluated on 2000
    frequencies in ``(0, pi/T]``.

    Parameters
    ----------
    K : float or ndarray
        Rendered stiffness, N m/rad.
    B : float
        Virtual damping, N m s/rad.
    T : float
        Sample time, s.
    cutoff_Hz : float, optional
        Velocity low-pass cutoff, Hz (None: raw backward difference).
    delay : int
        Computation delay, samples.

    Returns
    -------
    float or ndarray
        Required ``b`` (N m s/rad), same shape as ``K``.
    """
    _x, ck, cb = _basis(T, cutoff_Hz, delay)
    k = np.asarray(K, dtype=float)
    req = np.max(k[..., None] * ck + B * cb, axis=-1)
    return float(req) if req.ndim == 0 else req


def max_passive_stiffness(
    b: float, B: float, T: float, cutoff_Hz: float | None = None, delay: int = 0
) -> float:
    """Largest ``K >= 0`` (N m/rad) passive for device damping ``b`` (0 if none is).

    The passive set is an intersection of half-planes in ``(K, B)``; this solves it for ``K``.
    """
    _x, ck, cb = _basis(T, cutoff_Hz, delay)
    rhs = b - B * cb
    if np.any((ck <= 0) & (rhs <= 0)):
        return 0.0
    pos = ck > 0
    kmax = float(np.min(rhs[pos] / ck[pos])) if np.any(pos) else math.inf
    return max(kmax, 0.0)


def abbott_okamura_bound(b: float, T: float, coulomb_Nm: float, quantum_rad: float) -> float:
    """Abbott & Okamura (2005): passive iff ``K <= max(2 b / T, 2 f_c / Delta)``, N m/rad.

    ``quantum_rad = 0`` (no quantisation) gives ``inf`` when ``f_c > 0``.
    """
    viscous = 2.0 * b / T
    if coulomb_Nm <= 0:
        return viscous
    coul = math.inf if quantum_rad <= 0 else 2.0 * coulomb_Nm / quantum_rad
    return max(viscous, coul)


def zwidth_boundary(
    b: float, T: float, cutoff_Hz: float | None, delay: int, B_max: float, n: int = 81
) -> tuple[np.ndarray, np.ndarray]:
    """Z-width: ``(B, K_max(B))`` over ``B`` in ``[0, B_max]`` (N m s/rad, N m/rad)."""
    Bs = np.linspace(0.0, B_max, n)
    return Bs, np.array([max_passive_stiffness(b, B, T, cutoff_Hz, delay) for B in Bs])


def best_filter(
    b: float,
    T: float,
    delay: int,
    safety: float,
    cutoffs: Sequence[float],
    n_B: int = 61,
    B_min: float = 0.0,
) -> tuple[float, float, float]:
    """``(B, f_c, K)`` maximising the passive stiffness for the damping ``b / safety``.

    A grid search: every cutoff of ``cutoffs`` (Hz) x ``n_B`` virtual dampings in
    ``[0, 2 b / safety]`` (N m s/rad, raised to ``B_min``); :func:`max_passive_stiffness` of
    each.

    Parameters
    ----------
    b : float
        Device damping, N m s/rad.
    T : float
        Sample time, s.
    delay : int
        Computation delay, samples.
    safety : float
        Required ``b / b_required`` (>= 1).
    cutoffs : sequence of float
        Candidate velocity cutoffs, Hz.
    n_B : int
        Virtual dampings per cutoff.
    B_min : float
        Smallest virtual damping (the rendered viscous friction), N m s/rad.

    Returns
    -------
    tuple of float
        ``(B N m s/rad, f_c Hz, K N m/rad)``; ``K = -1`` when none is passive.
    """
    beff = b / safety
    best = (0.0, float(cutoffs[0]), -1.0)
    for fc in cutoffs:
        for B in np.linspace(0.0, 2.0 * beff, n_B):
            Bt = max(float(B), B_min)
            k = max_passive_stiffness(beff, Bt, T, fc, delay)
            if k > best[2] * (1 + 1e-9):
                best = (Bt, float(fc), k)
    return best
