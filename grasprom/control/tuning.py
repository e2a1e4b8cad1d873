r"""Tuning of the impedance controller for passivity (python-control).

The handle is modelled about its pivot (angle ``theta``, rad; closing = ``theta`` decreasing).
The device torque on the handle in the opening direction is ``tau = Fi L3`` (N m); the controller
renders, linearised at an operating point, ``tau = tau0 - K (theta - theta0) - B v_f`` with

* ``K(theta) = -L3 dFi/dtheta`` (N m/rad), the **rendered stiffness** through the chain and the
  virtual coupling: the jaw sees ``k_eff = k_c k_t / (k_c + k_t)`` (``k_t`` the surrogate
  stiffness at the proxy gap), so
  ``K = 1e-3 [g'^2 k_eff - Fg g'' + k u'^2 + F_s u'']`` (``g'`` mm/rad, ``k_eff`` N/mm) from
  :func:`grasprom.chain.kinematics.dhandle_force_dtheta_N_per_rad`;
* ``B`` the virtual damping (N m s/rad) on the velocity ``v_f``: backward difference of the
  encoder angle, first-order low-pass ``a = exp(-2 pi f_c T)``;
* the torque computed from sample ``k`` is held (zero-order hold) and applied ``delay`` samples
  later (one-sample computation delay by default).

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
operating points.  Closed-loop stability with the hand: ZOH-discretised device + hand
(``c2d``), delay and controller, ``feedback`` / ``poles`` / ``stability_margins``.

Simulation check: :func:`simulate_hold` runs the real :class:`ImpedanceController` step at the
sample rate against a continuous device + hand model (sub-stepped, Coulomb friction, encoder
quantisation) and measures the energy the controller injects beyond the ideal static field, and
the growth of the oscillation.

Rendered instrument effects (``ControllerParams`` fields set from a ``grasprom diagnose``
augmented model, :func:`grasprom.gap.diagnosis.controller_params_from_augmented`)
--------------------------------------------------------------------------------------------
* ``tissue_scale`` scales the tissue force and stiffness everywhere (static map and ``K``).
* ``jaw_compliance_mm_per_N`` ``C`` is in series with the coupling: the rendered jaw stiffness
  is bounded by ``k_c,eff = 1/(1/k_c + C)``, which replaces ``k_c`` in the proxy and in ``k_eff``.
* The Prony series raises the instantaneous jaw stiffness by
  :func:`prony_stiffness_factor` ``= 1 + sum g_i 2/(1 + a_i)`` (``a_i = exp(-T/tau_i)``; the gain of
  the discrete Prony filter at the Nyquist frequency, its largest, ``~ 1 + sum g_i`` for
  ``tau_i >> T``); ``k_eff`` is multiplied by it, so the tuner ends with
  ``k_c,eff x factor`` about where ``k_c`` alone would be.
* The viscous friction ``b_v`` (N s/mm at the finger) is a virtual damping ``b_v L3^2 1e-3``
  (N m s/rad) on the same filtered velocity as ``B``: the passivity condition uses
  ``B_total = B + b_v L3^2 1e-3`` (:func:`virtual_damping_Nms_per_rad`), and the tuner picks the
  best ``B_total >= b_v L3^2 1e-3`` (``B`` = the rest, >= 0).  Virtual damping is not free in a
  sampled-data loop (``b > K T/2 + |B|``): at the 200 Hz cutoff 0.005 N s/mm already leaves no
  passive stiffness (the tuner then lowers the cutoff), and from about 0.065 N s/mm none is left
  at 1 kHz with the default device, which :func:`tune` reports as an error.
* Coulomb and load-proportional friction, and the backlash, are not credited (they raise no
  bound, unlike the device's own friction in Abbott-Okamura): the rendered Coulomb force opposes
  the motion except while the finger speed crosses the direction threshold after a reversal.
  The simulation check runs the step with all of them.
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from grasprom.chain import kinematics as kin
from grasprom.control.controller import ControllerParams, ImpedanceController, save_params
from grasprom.surrogate import Surrogate

__all__ = [
    "DeviceParams",
    "HandParams",
    "OperatingPoints",
    "TuningResult",
    "abbott_okamura_bound",
    "closed_loop",
    "colgate_required_damping",
    "environment_tf",
    "max_passive_stiffness",
    "operating_points",
    "plot_tuning",
    "prony_stiffness_factor",
    "rendered_stiffness",
    "required_damping",
    "simulate_hold",
    "static_handle_torque_Nm",
    "tune",
    "verify_by_simulation",
    "virtual_damping_Nms_per_rad",
    "write_outputs",
    "zwidth_boundary",
]

_N_OMEGA = 2000  # frequency samples of the passivity condition on (0, pi/T]


@dataclass(frozen=True)
class DeviceParams:
    """Haptic handle (device) model about the handle pivot (SI units in the names).

    The values are representative assumptions for a cable-driven one-axis handle, not a
    datasheet of a built device; identify ``J``, ``b`` and ``f_c`` on the real handle (free decay,
    torque ramps) and rerun ``grasprom tune``: the passive coupling stiffness scales linearly
    with ``b``.

    Parameters
    ----------
    inertia_kg_m2 : float
        Handle inertia at the handle pivot, kg m^2, including the motor rotor reflected through
        the cable (motor turns ``L3 / r`` = 5.41 times the handle): default 2e-3 (a rotor of
        about 6.5e-5 kg m^2, the class of a 50-100 W flat brushless motor, x 5.41^2 = 1.9e-3,
        plus about 1e-4 for the handle lever); 0.68 kg equivalent at the finger (``J / L3^2``).
    damping_Nms_per_rad : float
        Physical viscous damping ``b`` at the handle pivot, N m s/rad: default 0.01 (3.4 N s/m
        at the finger: motor, bearings and cable; the order of desktop haptic devices, cf.
        the identified devices of Colgate & Brown 1994 and Abbott & Okamura 2005).  The
        passivity bounds scale with it.
    coulomb_Nm : float
        Coulomb friction at the handle pivot, N m: default 0.01 (0.18 N at the finger).
    torque_constant_Nm_per_A : float
        Motor torque constant, N m/A (default 0.1).
    current_limit_A : float
        Amplifier current limit, A (default 10); motor torque limit = constant x limit = 1 N m
        (the controller's default ``torque_limit_Nm``: 100 N of cable tension at r = 10 mm).
    delay_samples : int
        Computation delay in samples between the encoder read and the torque update (default 1:
        the torque computed from sample k is applied from k + 1, then held).

    Notes
    -----
    Sample time ``T`` and the encoder quantum (handle rad per count,
    ``2 pi r / (counts L3)``, :attr:`ImpedanceController.encoder_quantum_rad`) come from the
    :class:`~grasprom.control.controller.ControllerParams`.
    """

    inertia_kg_m2: float = 2.0e-3
    damping_Nms_per_rad: float = 0.01
    coulomb_Nm: float = 0.01
    torque_constant_Nm_per_A: float = 0.1
    current_limit_A: float = 10.0
    delay_samples: int = 1

    def __post_init__(self) -> None:
        for name in (
            "inertia_kg_m2",
            "damping_Nms_per_rad",
            "torque_constant_Nm_per_A",
            "current_limit_A",
        ):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ValueError(f"DeviceParams.{name} must be finite and > 0, got {v!r}")
        if not (math.isfinite(self.coulomb_Nm) and self.coulomb_Nm >= 0):
            raise ValueError(f"DeviceParams.coulomb_Nm must be >= 0, got {self.coulomb_Nm!r}")
        if int(self.delay_samples) != self.delay_samples or self.delay_samples < 0:
            raise ValueError(
                f"DeviceParams.delay_samples must be an integer >= 0, got {self.delay_samples!r}"
            )

    @property
    def torque_limit_Nm(self) -> float:
        """Motor torque limit, N m (``torque constant x current limit``)."""
        return self.torque_constant_Nm_per_A * self.current_limit_A


@dataclass(frozen=True)
class HandParams:
    """Mass-spring-damper of the fingers at the grip, along the finger travel (SI units).

    Defaults: the order of the index-fingertip impedance identified by Hajian & Howe (1997,
    "Identification of the mechanical impedance at the human finger tip", J. Biomech. Eng.
    119(1):109-114) at grip forces of a few newtons: a mass of grams, a damping of a few N s/m
    and a stiffness of a few hundred N/m, both rising with the grip force; the grip here is
    one effective finger.  Converted to the handle pivot through ``L3``:
    ``J_h = m L3^2``, ``b_h = c L3^2``, ``k_h = k L3^2``.

    Parameters
    ----------
    mass_kg : float
        Effective finger mass at the grip, kg (default 0.01).
    damping_Ns_per_m : float
        Finger damping, N s/m (default 2.0).
    stiffness_N_per_m : float
        Finger stiffness, N/m (default 300).
    """

    mass_kg: float = 0.01
    damping_Ns_per_m: float = 2.0
    stiffness_N_per_m: float = 300.0

    def __post_init__(self) -> None:
        for name in ("mass_kg", "damping_Ns_per_m", "stiffness_N_per_m"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ValueError(f"HandParams.{name} must be finite and >= 0, got {v!r}")

    def at_pivot(self, L3_mm: float) -> tuple[float, float, float]:
        """``(J_h kg m^2, b_h N m s/rad, k_h N m/rad)`` at the handle pivot for a grip at L3."""
        r2 = (L3_mm * 1e-3) ** 2
        return self.mass_kg * r2, self.damping_Ns_per_m * r2, self.stiffness_N_per_m * r2


# --------------------------------------------------------------------------- augmentation
def prony_stiffness_factor(params: ControllerParams) -> float:
    """Instantaneous over relaxed jaw stiffness of the rendered Prony series (1).

    ``1 + sum g_i 2 / (1 + a_i)`` with ``a_i = exp(-T / tau_i)``: the gain of the discrete
    filter ``Fg -> Fg + sum g_i h_i`` of :meth:`ImpedanceController.step` at the Nyquist frequency,
    its largest over frequency (``1 + sum g_i`` to ``O(T / tau_i)``); 1 without Prony terms.

    Parameters
    ----------
    params : ControllerParams
        ``prony_g`` (1), ``prony_tau_s`` (s) and ``sample_time_s`` (s).

    Returns
    -------
    float
    """
    f = 1.0
    for g, tau in zip(params.prony_g, params.prony_tau_s):
        f += g * 2.0 / (1.0 + math.exp(-params.sample_time_s / tau))
    return f


def virtual_damping_Nms_per_rad(params: ControllerParams) -> float:
    """Total virtual damping on the filtered velocity at the handle pivot, N m s/rad.

    ``B + b_v L3^2 1e-3``: the controller's damping ``B`` plus the rendered viscous friction
    ``b_v`` (N s/mm at the finger, ``L3`` in mm); ``B`` without viscous friction.

    Parameters
    ----------
    params : ControllerParams

    Returns
    -------
    float
    """
    bv = params.friction_viscous_N_s_per_mm
    if bv == 0:
        return params.damping_Nms_per_rad
    L3 = params.chain_params.L3_mm
    return params.damping_Nms_per_rad + bv * L3 * L3 * 1e-3


def _augmented(params: ControllerParams) -> bool:
    """Whether any rendered instrument effect is on."""
    return bool(
        params.tissue_scale != 1.0
        or params.jaw_compliance_mm_per_N > 0
        or params.backlash_deg > 0
        or params.friction_rendered
        or params.prony_g
    )


# --------------------------------------------------------------------------- static map
def _proxy_gap(
    s: Surrogate,
    gap: np.ndarray,
    t: float,
    material: str,
    kc: float,
    iters: int = 60,
    scale: float = 1.0,
) -> np.ndarray:
    """Converged proxy gap ``g_p >= g`` solving ``k_c (g_p - g) = scale F(g_p)`` (vectorised)."""
    f0 = scale * np.asarray(s.force(gap, t, material), dtype=float)
    lo = gap.copy()
    hi = gap + f0 / kc
    gp = hi.copy()
    for _ in range(iters):
        f = scale * np.asarray(s.force(gp, t, material), dtype=float)
        k = scale * np.asarray(s.stiffness(gp, t, material), dtype=float)
        r = kc * (gp - gap) - f  # increasing in gp
        lo = np.where(r < 0, gp, lo)
        hi = np.where(r >= 0, gp, hi)
        if np.all((np.abs(r) <= 1e-9 * np.maximum(1.0, f)) | (hi - lo <= 1e-12)):
            break
        newton = gp - r / (kc + k)
        gp = np.where((newton >= lo) & (newton <= hi), newton, 0.5 * (lo + hi))
    return np.where(f0 > 0, gp, gap)


@dataclass(frozen=True)
class OperatingPoints:
    """Operating points of one material and thickness along ``theta`` (arrays over theta).

    Attributes
    ----------
    material : str
    thickness_mm : float
    theta_deg, gap_mm, proxy_gap_mm : ndarray
        Handle angle (deg), kinematic gap (mm), converged proxy gap (mm).
    force_jaw_N : ndarray
        Rendered (relaxed) jaw force ``k_c,eff (g_p - g)``, N.
    tissue_stiffness_N_per_mm : ndarray
        Surrogate stiffness (times ``tissue_scale``) at the kinematic gap (raw tissue), N/mm.
    jaw_stiffness_N_per_mm : ndarray
        Rendered instantaneous jaw stiffness
        ``P k_c,eff k_t(g_p) / (k_c,eff + k_t(g_p))``, N/mm (``P`` the
        :func:`prony_stiffness_factor`; ``k_c,eff = k_c`` without jaw compliance).
    K_Nm_per_rad : ndarray
        Rendered stiffness at the handle pivot (chain + coupling), N m/rad.
    K_raw_Nm_per_rad : ndarray
        Stiffness the raw tissue (no coupling, no jaw compliance; scale and Prony factor
        included) would need at the handle pivot, N m/rad.
    """

    material: str
    thickness_mm: float
    theta_deg: np.ndarray
    gap_mm: np.ndarray
    proxy_gap_mm: np.ndarray
    force_jaw_N: np.ndarray
    tissue_stiffness_N_per_mm: np.ndarray
    jaw_stiffness_N_per_mm: np.ndarray
    K_Nm_per_rad: np.ndarray
    K_raw_Nm_per_rad: np.ndarray


def _handle_K(fg, kjaw, th, chain: kin.ChainParams, render_spring: bool) -> np.ndarray:
    """``-L3 dFi/dtheta`` in N m/rad (spring terms removed unless ``render_spring``)."""
    dfi = np.asarray(kin.dhandle_force_dtheta_N_per_rad(fg, kjaw, th, chain), dtype=float)
    if not render_spring:
        dfi = dfi - np.asarray(kin.dhandle_force_dtheta_N_per_rad(0.0, 0.0, th, chain))
    return -dfi * chain.L3_mm * 1e-3


def rendered_stiffness(
    s: Surrogate,
    params: ControllerParams,
    theta_deg: Sequence[float] | np.ndarray | None = None,
    *,
    n_theta: int = 221,
) -> OperatingPoints:
    """Rendered handle-pivot stiffness along ``theta`` for ``params.material``/``thickness_mm``.

    Parameters
    ----------
    s : Surrogate
        Tissue force table.
    params : ControllerParams
        Controller parameters (coupling stiffness, chain, spring, material, thickness).
    theta_deg : array_like, optional
        Handle angles, deg (default ``n_theta`` points over the chain's range).
    n_theta : int
        Number of default samples.

    Returns
    -------
    OperatingPoints
    """
    chain = params.chain_params
    if theta_deg is None:
        lo, hi = kin.theta_range_deg(chain)
        theta_deg = np.linspace(lo, hi, n_theta)
    th = np.asarray(theta_deg, dtype=float)
    t, m, kc = params.thickness_mm, params.material, params.coupling_effective_N_per_mm
    sc = params.tissue_scale
    pf = prony_stiffness_factor(params)
    g = np.asarray(kin.gap_mm(th, chain), dtype=float)
    f_raw = sc * np.asarray(s.force(g, t, m), dtype=float)
    kt_raw = sc * np.asarray(s.stiffness(g, t, m), dtype=float)
    gp = _proxy_gap(s, g, t, m, kc, scale=sc)
    kt_p = sc * np.asarray(s.stiffness(gp, t, m), dtype=float)
    contact = f_raw > 0
    fg = np.where(contact, kc * (gp - g), 0.0)
    kjaw = np.where(contact, pf * (kc * kt_p / (kc + kt_p)), 0.0)
    return OperatingPoints(
        material=m,
        thickness_mm=float(t),
        theta_deg=th,
        gap_mm=g,
        proxy_gap_mm=gp,
        force_jaw_N=fg,
        tissue_stiffness_N_per_mm=kt_raw,
        jaw_stiffness_N_per_mm=kjaw,
        K_Nm_per_rad=_handle_K(fg, kjaw, th, chain, params.render_spring),
        K_raw_Nm_per_rad=_handle_K(f_raw, pf * kt_raw, th, chain, params.render_spring),
    )


def static_handle_torque_Nm(
    s: Surrogate, params: ControllerParams, theta_rad: np.ndarray
) -> np.ndarray:
    """Static device torque at the handle pivot ``Fi L3`` (N m, opening) with converged proxy.

    The ideal (continuous, undamped) field the controller approximates; no saturation.  With
    rendered instrument effects: tissue scale and jaw compliance included, the Prony series
    relaxed, no friction, no backlash (the chain angle = the handle angle).
    """
    chain = params.chain_params
    th = np.degrees(
        np.clip(np.asarray(theta_rad, dtype=float), *np.radians(kin.theta_range_deg(chain)))
    )
    g = np.asarray(kin.gap_mm(th, chain), dtype=float)
    kc = params.coupling_effective_N_per_mm
    gp = _proxy_gap(s, g, params.thickness_mm, params.material, kc, scale=params.tissue_scale)
    fg = kc * (gp - g)
    fi = np.asarray(kin.handle_force_N(fg, th, chain), dtype=float)
    if not params.render_spring:
        fi = fi - np.asarray(kin.spring_handle_force_N(th, chain), dtype=float)
    return fi * chain.L3_mm * 1e-3


def operating_points(
    s: Surrogate,
    params: ControllerParams,
    thicknesses: Sequence[float] | None = None,
    materials: Sequence[str] | None = None,
    n_theta: int = 221,
) -> list[OperatingPoints]:
    """Operating points over theta x thickness x material (default: the surrogate's grids)."""
    mats = list(materials) if materials else list(s.materials)
    out = []
    for m in mats:
        ts = list(thicknesses) if thicknesses else list(s.thicknesses(m))
        lo, hi = s.thickness_range(m)
        for t in ts:
            if not lo - 1e-9 <= t <= hi + 1e-9:
                raise ValueError(
                    f"thickness {t} mm outside the surrogate's range [{lo:g}, {hi:g}] mm "
                    f"for material {m!r}"
                )
            p = replace(params, material=m, thickness_mm=float(t))
            out.append(rendered_stiffness(s, p, n_theta=n_theta))
    return out


# --------------------------------------------------------------------------- passivity
def colgate_required_damping(K: float, B: float, T: float) -> float:
    """Closed form ``K T / 2 + |B|`` (N m s/rad): Colgate's condition ``b > K T/2 + |B|``.

    Backward-difference velocity, no filter, no computation delay.
    """
    return 0.5 * K * T + abs(B)


def _basis(T: float, cutoff_Hz: float | None, delay: int, n: int = _N_OMEGA):
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


# --------------------------------------------------------------------------- python-control
def environment_tf(K: float, B: float, T: float, cutoff_Hz: float, delay: int):
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
        ``inf`` if none), ``phase_margin_deg``, ``gain_crossover_Hz``, ``phase_crossover_Hz``.
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

    return {
        "max_pole_mag": pmax,
        "stable": bool(pmax < 1.0),
        "gain_margin": float(gm) if gm is not None and np.isfinite(gm) else math.inf,
        "phase_margin_deg": float(pm) if pm is not None and np.isfinite(pm) else math.inf,
        "gain_crossover_Hz": _hz(wgc),
        "phase_crossover_Hz": _hz(wpc),
    }


# --------------------------------------------------------------------------- tuning
@dataclass
class TuningResult:
    """Result of :func:`tune` (see :meth:`to_dict` for the JSON form)."""

    params: ControllerParams
    device: DeviceParams
    hand: HandParams
    points: list[OperatingPoints]
    summary: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready tuning report."""
        return _jsonable(self.summary)

    def report(self) -> str:
        """Human-readable text report."""
        return format_report(self.summary)


def _jsonable(o: Any) -> Any:
    if isinstance(o, dict):
        return {k: _jsonable(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [_jsonable(v) for v in o]
    if isinstance(o, np.generic):
        o = o.item()
    if isinstance(o, float) and not math.isfinite(o):
        return None if math.isnan(o) else ("inf" if o > 0 else "-inf")
    return o


def _max_K(points: list[OperatingPoints]) -> tuple[float, float, OperatingPoints, int]:
    best = (-math.inf, math.inf, points[0], 0)
    kmin = math.inf
    for op in points:
        i = int(np.argmax(op.K_Nm_per_rad))
        kmin = min(kmin, float(np.min(op.K_Nm_per_rad)))
        if op.K_Nm_per_rad[i] > best[0]:
            best = (float(op.K_Nm_per_rad[i]), kmin, op, i)
    return best[0], kmin, best[2], best[3]


def _choose_filter(
    b: float,
    T: float,
    delay: int,
    safety: float,
    cutoffs: Sequence[float],
    n_B: int = 61,
    B_min: float = 0.0,
) -> tuple[float, float, float]:
    """(B, f_c, K_allowed) maximising the passive stiffness for ``b / safety``, ``B >= B_min``."""
    beff = b / safety
    best = (0.0, float(cutoffs[0]), -1.0)
    for fc in cutoffs:
        for B in np.linspace(0.0, 2.0 * beff, n_B):
            Bt = max(float(B), B_min)
            k = max_passive_stiffness(beff, Bt, T, fc, delay)
            if k > best[2] * (1 + 1e-9):
                best = (Bt, float(fc), k)
    return best


def _round_down(x: float, digits: int = 2) -> float:
    if x <= 0:
        return 0.0
    e = math.floor(math.log10(x)) - digits + 1
    return math.floor(x / 10**e) * 10**e


def tune(
    s: Surrogate,
    base: ControllerParams | None = None,
    device: DeviceParams | None = None,
    hand: HandParams | None = None,
    *,
    thicknesses: Sequence[float] | None = None,
    materials: Sequence[str] | None = None,
    safety: float = 1.25,
    cutoffs_Hz: Sequence[float] = (5, 10, 20, 30, 50, 75, 100, 150, 200),
    n_theta: int = 221,
    verify: bool = True,
) -> TuningResult:
    """Choose ``B``, the velocity cutoff and the coupling stiffness ``k_c`` for passivity.

    1. ``(B, f_c)`` maximise the passive stiffness ``K_pass`` of the device with damping
       ``b / safety`` (delay-aware Colgate-Schenkel condition).
    2. ``k_c`` is the largest (2 significant digits, rounded down) for which the largest
       rendered stiffness over theta x thickness x material stays ``<= K_pass``, i.e. the
       passivity margin ``b / b_required >= safety`` at every operating point.

    Rendered instrument effects in ``base`` (tissue scale, jaw compliance, Prony series,
    friction; see the module docstring) are kept and accounted for: ``K`` uses the scaled tissue,
    ``k_c,eff`` and the Prony factor; the viscous friction counts as virtual damping (``B`` is
    chosen for the total, the friction's share taken off); Coulomb friction and backlash are not
    credited.
    3. Report: raw tissue (no coupling) stiffness and where it is not renderable, with the
       sample rate / damping it would need; Abbott-Okamura and Colgate closed-form figures;
       closed-loop poles and margins (python-control) at the stiffest point, with and without
       the hand.

    Parameters
    ----------
    s : Surrogate
    base : ControllerParams, optional
        Starting parameters (sample time, encoder, chain...); default ``ControllerParams()``.
    device : DeviceParams, optional
    hand : HandParams, optional
    thicknesses : sequence of float, optional
        Wall thicknesses, mm (default: every grid thickness of each material).
    materials : sequence of str, optional
        Materials (default: all of the surrogate).
    safety : float
        Required ratio ``b / b_required`` (>= 1).
    cutoffs_Hz : sequence of float
        Candidate velocity cutoffs, Hz (those below Nyquist are used).  Capped at 200 Hz by
        default: one encoder count per sample is ``Delta / T`` = 0.28 rad/s of velocity noise
        at 1 kHz, and cutoffs above 200 Hz raise the passive stiffness by < 5 %.
    n_theta : int
        Theta samples over the range.
    verify : bool
        Run :func:`verify_by_simulation` and store it in the summary.

    Returns
    -------
    TuningResult

    Raises
    ------
    ValueError
        Bad arguments, or a rendered viscous friction that leaves no passive stiffness.
    """
    base = base or ControllerParams()
    device = device or DeviceParams()
    hand = hand or HandParams()
    if not (math.isfinite(safety) and safety >= 1.0):
        raise ValueError(f"safety must be >= 1, got {safety!r}")
    if materials:
        for m in materials:
            if m not in s.materials:
                raise ValueError(f"material {m!r} not in the surrogate {list(s.materials)}")
    T = base.sample_time_s
    nyq = 0.5 / T
    cutoffs = [float(c) for c in cutoffs_Hz if 0 < c < nyq]
    if not cutoffs:
        raise ValueError(f"no velocity cutoff below the Nyquist frequency {nyq:g} Hz")
    b, d = device.damping_Nms_per_rad, device.delay_samples
    B_visc = virtual_damping_Nms_per_rad(replace(base, damping_Nms_per_rad=0.0))
    B, fc, k_pass = _choose_filter(b, T, d, safety, cutoffs, B_min=B_visc)
    if k_pass <= 0:
        raise ValueError(
            f"the rendered viscous friction {base.friction_viscous_N_s_per_mm:g} N s/mm (virtual "
            f"damping {B_visc:.3g} N m s/rad at the handle pivot) cannot be rendered passively "
            f"by this device (b = {b:g} N m s/rad, safety {safety:g}) at {1 / T:g} Hz with any "
            f"velocity cutoff in {', '.join(f'{c:g}' for c in cutoffs)} Hz; lower "
            "friction_viscous_N_s_per_mm, raise the rate or the device damping"
        )
    # B is the total virtual damping; the controller's share is what the friction leaves
    base = replace(
        base, damping_Nms_per_rad=B - B_visc if B > B_visc else 0.0, velocity_cutoff_Hz=fc
    )

    def worst(kc: float, n: int = max(n_theta // 4, 12)) -> float:
        pts = operating_points(
            s, replace(base, coupling_stiffness_N_per_mm=kc), thicknesses, materials, n
        )
        kmax, kmin, _op, _i = _max_K(pts)
        return max(float(required_damping(np.array([kmax, kmin]), B, T, fc, d).max()), 0.0)

    beff = b / safety
    lo, hi = 1e-3, 1.0
    if worst(lo) > beff:
        raise ValueError(
            f"no coupling stiffness is passive: even k_c = {lo:g} N/mm (spring, chain and "
            f"rendered effects alone) needs b >= {worst(lo) * safety:.3g} N m s/rad, the device "
            f"has {b:g} (safety {safety:g}, virtual damping {B:.3g} N m s/rad incl. "
            f"{B_visc:.3g} of viscous friction)"
        )
    while worst(hi) <= beff and hi < 1e5:
        lo, hi = hi, hi * 4.0
    for _ in range(30):
        mid = math.sqrt(lo * hi)
        if worst(mid) <= beff:
            lo = mid
        else:
            hi = mid
        if hi / lo < 1.005:
            break
    kc = _round_down(lo, 2)
    while kc > 0 and worst(kc, n_theta) > beff:  # confirm on the full theta grid
        kc = _round_down(0.97 * kc, 2)
    params = replace(
        base,
        coupling_stiffness_N_per_mm=kc,
        torque_limit_Nm=min(base.torque_limit_Nm, device.torque_limit_Nm),
    )
    pts = operating_points(s, params, thicknesses, materials, n_theta)
    summary = _summarise(s, params, device, hand, pts, safety, k_pass)
    kc_in = base.coupling_stiffness_N_per_mm
    k_in = _max_K(operating_points(s, base, thicknesses, materials, max(n_theta // 4, 12)))[0]
    c = float(required_damping(1.0, 0.0, T, None, d))
    summary["input_coupling"] = {
        "coupling_stiffness_N_per_mm": kc_in,
        "max_K_Nm_per_rad": k_in,
        "required_damping_Nms_per_rad": float(required_damping(k_in, B, T, fc, d)) * safety,
        "required_rate_Hz_B0": k_in * c / T / b * safety,
    }
    if _augmented(params):
        summary["augmentation"] = _augmentation_summary(params, B_visc)
    if verify:
        summary["simulation"] = verify_by_simulation(s, params, device, hand, summary)
    return TuningResult(params=params, device=device, hand=hand, points=pts, summary=summary)


def _augmentation_summary(params: ControllerParams, B_visc: float) -> dict[str, Any]:
    kc = params.coupling_stiffness_N_per_mm
    return {
        "tissue_scale": params.tissue_scale,
        "jaw_compliance_mm_per_N": params.jaw_compliance_mm_per_N,
        "coupling_stiffness_N_per_mm": kc,
        "coupling_effective_N_per_mm": params.coupling_effective_N_per_mm,
        "prony_g": list(params.prony_g),
        "prony_tau_s": list(params.prony_tau_s),
        "prony_stiffness_factor": prony_stiffness_factor(params),
        "rendered_jaw_stiffness_bound_N_per_mm": params.coupling_effective_N_per_mm
        * prony_stiffness_factor(params),
        "backlash_deg": params.backlash_deg,
        "friction_coulomb_N": params.friction_coulomb_N,
        "friction_load_coefficient": params.friction_load_coefficient,
        "friction_viscous_N_s_per_mm": params.friction_viscous_N_s_per_mm,
        "friction_virtual_damping_Nms_per_rad": B_visc,
        "virtual_damping_total_Nms_per_rad": virtual_damping_Nms_per_rad(params),
        "notes": [
            "jaw stiffness bounded by k_c,eff = 1/(1/k_c + C) times the Prony factor "
            "1 + sum g_i 2/(1 + exp(-T/tau_i)) (instantaneous stiffness)",
            "viscous friction = virtual damping b_v L3^2 on the filtered velocity: counted in the "
            "passivity condition (B_total = B + b_v L3^2), B reduced by it",
            "Coulomb/load friction and backlash not credited (no higher stiffness allowed for "
            "them); the simulation check runs with them",
        ],
    }


def _summarise(
    s: Surrogate,
    params: ControllerParams,
    device: DeviceParams,
    hand: HandParams,
    pts: list[OperatingPoints],
    safety: float,
    k_pass: float,
) -> dict[str, Any]:
    T, B, fc = params.sample_time_s, virtual_damping_Nms_per_rad(params), params.velocity_cutoff_Hz
    b, d = device.damping_Nms_per_rad, device.delay_samples
    L3 = params.chain_params.L3_mm
    kc_eff = params.coupling_effective_N_per_mm
    q = ImpedanceController(
        replace(params, material=pts[0].material, thickness_mm=pts[0].thickness_mm), s
    ).encoder_quantum_rad
    kmax, kmin, op, i = _max_K(pts)
    b_req = float(required_damping(np.array([kmax, kmin]), B, T, fc, d).max())
    # raw tissue, without coupling
    c_delay = float(required_damping(1.0, 0.0, T, None, d))  # b_req per unit K, B = 0
    raw_max = max(float(np.max(o.K_raw_Nm_per_rad)) for o in pts)
    not_renderable = []
    for o in pts:
        bad = o.K_raw_Nm_per_rad > k_pass
        if np.any(bad):
            th = o.theta_deg[bad]
            not_renderable.append(
                {
                    "material": o.material,
                    "thickness_mm": o.thickness_mm,
                    "theta_deg_below": float(np.max(th)),
                    "max_K_raw_Nm_per_rad": float(np.max(o.K_raw_Nm_per_rad)),
                }
            )
    active = [
        {
            "material": o.material,
            "thickness_mm": o.thickness_mm,
            "theta_deg_below": float(np.max(o.theta_deg[o.tissue_stiffness_N_per_mm > kc_eff])),
        }
        for o in pts
        if np.any(o.tissue_stiffness_N_per_mm > kc_eff)
    ]
    with_hand = closed_loop(kmax, B, fc, T, device, hand, L3)
    free = closed_loop(kmax, B, fc, T, device, None, L3)
    gp = params.chain_params
    g1 = float(kin.dgap_dtheta_mm_per_rad(op.theta_deg[i], gp))
    return {
        "sample_time_s": T,
        "rate_Hz": 1.0 / T,
        "delay_samples": d,
        "safety_factor": safety,
        "device": asdict(device),
        "hand": asdict(hand),
        "hand_at_pivot": dict(zip(("J_kg_m2", "b_Nms_per_rad", "k_Nm_per_rad"), hand.at_pivot(L3))),
        "encoder_quantum_rad": q,
        "chosen": {
            "coupling_stiffness_N_per_mm": params.coupling_stiffness_N_per_mm,
            "damping_Nms_per_rad": params.damping_Nms_per_rad,
            "velocity_cutoff_Hz": fc,
            "torque_limit_Nm": params.torque_limit_Nm,
        },
        "passive_stiffness_Nm_per_rad": k_pass * safety,
        "passive_stiffness_with_margin_Nm_per_rad": k_pass,
        "max_rendered_K_Nm_per_rad": kmax,
        "min_rendered_K_Nm_per_rad": kmin,
        "max_at": {
            "material": op.material,
            "thickness_mm": op.thickness_mm,
            "theta_deg": float(op.theta_deg[i]),
            "gap_mm": float(op.gap_mm[i]),
            "jaw_stiffness_N_per_mm": float(op.jaw_stiffness_N_per_mm[i]),
            "dgap_dtheta_mm_per_rad": g1,
        },
        "required_damping_Nms_per_rad": b_req,
        "passivity_margin": b / b_req if b_req > 0 else math.inf,
        "passive_everywhere": bool(b_req < b),
        "colgate_closed_form": {
            "required_damping_no_delay_Nms_per_rad": colgate_required_damping(kmax, B, T),
            "max_K_no_delay_B0_Nm_per_rad": 2.0 * b / T,
            "max_K_one_sample_delay_B0_Nm_per_rad": b / c_delay if c_delay > 0 else math.inf,
        },
        "abbott_okamura": {
            "max_K_Nm_per_rad": abbott_okamura_bound(b, T, device.coulomb_Nm, q),
            "viscous_term_Nm_per_rad": 2.0 * b / T,
            "coulomb_term_Nm_per_rad": (2.0 * device.coulomb_Nm / q) if q > 0 else math.inf,
            "passes": bool(kmax <= abbott_okamura_bound(b, T, device.coulomb_Nm, q)),
        },
        "raw_tissue": {
            "max_K_Nm_per_rad": raw_max,
            "required_damping_Nms_per_rad": raw_max * c_delay,
            "required_rate_Hz": raw_max * c_delay / b / T,
            "not_renderable": not_renderable,
        },
        "coupling_active": active,
        "closed_loop_with_hand": with_hand,
        "closed_loop_device_alone": free,
    }


def verify_by_simulation(
    s: Surrogate,
    params: ControllerParams,
    device: DeviceParams,
    hand: HandParams,
    summary: dict[str, Any],
    reject_factor: float = 8.0,
) -> dict[str, Any]:
    """Simulate closing onto the stiffest point with the chosen and with rejected parameters.

    Chosen: ``params`` at the material/thickness of the largest rendered stiffness.  Rejected:
    ``k_c`` x ``reject_factor`` (``reject_factor`` x above the passive coupling).  Each run is
    :func:`simulate_hold` from 1 deg above the hold angle; returns the verdicts, energies and
    the python-control pole check at the hold angle.
    """
    at = summary["max_at"]
    p0 = replace(params, material=at["material"], thickness_mm=at["thickness_mm"])
    out = {}
    for name, p in (
        ("chosen", p0),
        (
            "rejected",
            replace(p0, coupling_stiffness_N_per_mm=reject_factor * p0.coupling_stiffness_N_per_mm),
        ),
    ):
        sim = simulate_hold(s, p, device, hand, theta_start_offset_deg=1.0)
        op = rendered_stiffness(s, p, np.array([sim["theta_hold_deg"]]))
        K = float(op.K_Nm_per_rad[0])
        Bt = virtual_damping_Nms_per_rad(p)
        cl = closed_loop(
            K, Bt, p.velocity_cutoff_Hz, p.sample_time_s, device, hand, p.chain_params.L3_mm
        )
        out[name] = {
            "coupling_stiffness_N_per_mm": p.coupling_stiffness_N_per_mm,
            "material": p.material,
            "thickness_mm": p.thickness_mm,
            "theta_hold_deg": sim["theta_hold_deg"],
            "K_Nm_per_rad": K,
            "required_damping_Nms_per_rad": float(
                required_damping(K, Bt, p.sample_time_s, p.velocity_cutoff_Hz, device.delay_samples)
            ),
            "net_generated_J": sim["net_generated_J"],
            "controller_excess_J": sim["controller_excess_J"],
            "amp_first_rad": sim["amp_first_rad"],
            "amp_last_rad": sim["amp_last_rad"],
            "growing": sim["growing"],
            "hit_stop": sim["hit_stop"],
            "max_pole_mag_with_hand": cl["max_pole_mag"],
        }
    return out


def format_report(sm: dict[str, Any]) -> str:
    """Text report of a tuning summary (:meth:`TuningResult.to_dict`)."""
    c, at, raw = sm["chosen"], sm["max_at"], sm["raw_tissue"]
    dev = sm["device"]
    lines = [
        f"grasprom tune: {sm['rate_Hz']:g} Hz, {sm['delay_samples']} sample(s) delay, "
        f"device b = {dev['damping_Nms_per_rad']:g} N m s/rad, J = {dev['inertia_kg_m2']:g} "
        f"kg m^2, Coulomb {dev['coulomb_Nm']:g} N m, encoder quantum "
        f"{sm['encoder_quantum_rad']:.3g} rad",
        f"chosen: k_c = {c['coupling_stiffness_N_per_mm']:g} N/mm, B = "
        f"{c['damping_Nms_per_rad']:.4g} N m s/rad, velocity cutoff {c['velocity_cutoff_Hz']:g} "
        f"Hz, torque limit {c['torque_limit_Nm']:g} N m",
        f"passive stiffness (delay-aware Colgate-Schenkel, this B and cutoff): "
        f"{sm['passive_stiffness_Nm_per_rad']:.4g} N m/rad "
        f"({sm['passive_stiffness_with_margin_Nm_per_rad']:.4g} with safety "
        f"{sm['safety_factor']:g})",
        f"largest rendered stiffness: {sm['max_rendered_K_Nm_per_rad']:.4g} N m/rad at "
        f"{at['material']} t = {at['thickness_mm']:g} mm, theta = {at['theta_deg']:.2f} deg "
        f"(gap {at['gap_mm']:.2f} mm, jaw {at['jaw_stiffness_N_per_mm']:.3g} N/mm, "
        f"g' = {at['dgap_dtheta_mm_per_rad']:.1f} mm/rad); smallest "
        f"{sm['min_rendered_K_Nm_per_rad']:.4g} N m/rad",
        f"required damping {sm['required_damping_Nms_per_rad']:.4g} N m s/rad -> passivity "
        f"margin b/b_req = {sm['passivity_margin']:.3g} "
        f"({'passive everywhere' if sm['passive_everywhere'] else 'NOT passive'})",
        f"Colgate closed form (no delay): b > K T/2 + |B| = "
        f"{sm['colgate_closed_form']['required_damping_no_delay_Nms_per_rad']:.4g}; "
        f"K_max(B=0) = {sm['colgate_closed_form']['max_K_no_delay_B0_Nm_per_rad']:.4g}, "
        f"with the delay {sm['colgate_closed_form']['max_K_one_sample_delay_B0_Nm_per_rad']:.4g}"
        f" N m/rad",
        f"Abbott-Okamura K <= max(2b/T, 2f_c/Delta) = "
        f"{sm['abbott_okamura']['max_K_Nm_per_rad']:.4g} N m/rad (viscous "
        f"{sm['abbott_okamura']['viscous_term_Nm_per_rad']:.4g}, Coulomb "
        f"{sm['abbott_okamura']['coulomb_term_Nm_per_rad']:.4g}; not used for k_c)",
    ]
    for name, key in (
        ("with hand", "closed_loop_with_hand"),
        ("device alone", "closed_loop_device_alone"),
    ):
        cl = sm[key]
        lines.append(
            f"closed loop {name}: max |pole| = {cl['max_pole_mag']:.5f} "
            f"({'stable' if cl['stable'] else 'UNSTABLE'}), gain margin "
            f"{cl['gain_margin']:.3g}, phase margin {cl['phase_margin_deg']:.3g} deg"
        )
    lines.append(
        f"raw tissue (no coupling): up to {raw['max_K_Nm_per_rad']:.4g} N m/rad; passive only "
        f"with b >= {raw['required_damping_Nms_per_rad']:.3g} N m s/rad at this rate, or at "
        f"{raw['required_rate_Hz']:.3g} Hz with this b (B = 0)"
    )
    if "input_coupling" in sm:
        ic = sm["input_coupling"]
        lines.append(
            f"input k_c = {ic['coupling_stiffness_N_per_mm']:g} N/mm would render up to "
            f"{ic['max_K_Nm_per_rad']:.4g} N m/rad: needs b >= "
            f"{ic['required_damping_Nms_per_rad']:.3g} N m s/rad (this B, cutoff, safety) or "
            f"{ic['required_rate_Hz_B0']:.3g} Hz (B = 0)"
        )
    if raw["not_renderable"]:
        by_mat: dict[str, list[float]] = {}
        for r in raw["not_renderable"]:
            by_mat.setdefault(r["material"], []).append(r["theta_deg_below"])
        for m, ths in by_mat.items():
            lines.append(
                f"  {m}: raw tissue not passively renderable below theta = "
                f"{min(ths):.2f}-{max(ths):.2f} deg ({len(ths)} thicknesses); the coupling "
                f"bounds it there"
            )
    au = sm.get("augmentation")
    if au and "coupling_effective_N_per_mm" in au:
        lines += [
            f"rendered instrument effects: tissue scale {au['tissue_scale']:g}, jaw compliance "
            f"{au['jaw_compliance_mm_per_N']:g} mm/N -> k_c,eff = "
            f"{au['coupling_effective_N_per_mm']:.4g} N/mm; Prony factor "
            f"{au['prony_stiffness_factor']:.4g} -> jaw stiffness bound "
            f"{au['rendered_jaw_stiffness_bound_N_per_mm']:.4g} N/mm",
            f"  viscous friction {au['friction_viscous_N_s_per_mm']:g} N s/mm = virtual damping "
            f"{au['friction_virtual_damping_Nms_per_rad']:.4g} N m s/rad, counted: total "
            f"{au['virtual_damping_total_Nms_per_rad']:.4g} N m s/rad (B "
            f"{c['damping_Nms_per_rad']:.4g} + friction)",
            f"  Coulomb {au['friction_coulomb_N']:g} N, load coefficient "
            f"{au['friction_load_coefficient']:g}, backlash {au['backlash_deg']:g} deg: not "
            "credited (only add dissipation / play; in the simulation check)",
        ]
    if au and "file" in au:
        lines.append(
            f"augmented model {au['file']} (sha256 {au['sha256'][:12]}): rendered "
            f"{', '.join(au['rendered']) or 'none'}; measurement-only (not rendered) "
            f"{', '.join(au['measurement_only']) or 'none'}"
        )
    for name, v in sm.get("simulation", {}).items():
        lines.append(
            f"simulation {name} (k_c = {v['coupling_stiffness_N_per_mm']:g} N/mm, "
            f"{v['material']} t = {v['thickness_mm']:g} mm, hold {v['theta_hold_deg']:.2f} deg): "
            f"net energy generated {v['net_generated_J']:.3g} J, amplitude "
            f"{v['amp_first_rad']:.3g} -> {v['amp_last_rad']:.3g} rad, "
            + (
                "GROWING (the oscillation reaches the end stop)"
                if v.get("hit_stop")
                else ("GROWING" if v["growing"] else "no growing oscillation")
            )
            + "; max |pole| "
            f"{v['max_pole_mag_with_hand']:.5f}"
        )
    return "\n".join(lines)


# --------------------------------------------------------------------------- simulation
def simulate_hold(
    s: Surrogate,
    params: ControllerParams,
    device: DeviceParams | None = None,
    hand: HandParams | None = None,
    *,
    theta_hold_deg: float | None = None,
    theta_start_offset_deg: float = 0.2,
    duration_s: float = 1.0,
    substeps: int = 10,
    quantise: bool = True,
) -> dict[str, Any]:
    """Discrete-time simulation of device + controller + hand closing onto the tissue and holding.

    The hand pushes with a constant torque that balances the rendered static torque at
    ``theta_hold_deg`` (default: where the rendered stiffness peaks, at least 0.5 deg above
    the closed end), plus its spring (``k_h``, anchored at the hold angle) and damper; the
    handle starts at rest ``theta_start_offset_deg`` above the hold angle and falls into it.
    The continuous dynamics ``(J + J_h) theta'' = tau - tau_push - (b + b_h) theta' -
    k_h (theta - theta_hold)`` minus Coulomb friction ``f_c`` (stick when it can hold) are
    integrated by semi-implicit Euler with ``substeps`` per sample, with inelastic end stops
    at the ends of the handle range.  The real :meth:`ImpedanceController.step` runs once per
    sample on the (quantised) angle; its torque (times ``L3 / r`` at the handle pivot) is applied
    ``device.delay_samples`` samples later and held.

    Parameters
    ----------
    s : Surrogate
    params : ControllerParams
    device : DeviceParams, optional
    hand : HandParams, optional
    theta_hold_deg : float, optional
        Hold angle, deg.
    theta_start_offset_deg : float
        Initial offset above the hold angle, deg (the excitation).
    duration_s : float
        Simulated time, s; the second half is the hold window.
    substeps : int
        Integration sub-steps per controller sample.
    quantise : bool
        Encoder quantisation on (``False``: ``encoder_counts_per_rev = 0``).

    Returns
    -------
    dict
        ``time_s``, ``theta_rad``, ``torque_handle_Nm`` (arrays per sample);
        ``theta_hold_deg``; over the hold window: ``controller_excess_J`` (work of the device
        torque beyond the ideal static field, ``sum tau dtheta + U(end) - U(start)``),
        ``device_dissipated_J`` (``b theta'^2`` and Coulomb losses of the device),
        ``net_generated_J`` = excess - dissipated (<= 0: the display behaved passively),
        ``amp_first_rad``/``amp_last_rad`` (RMS of the angle about its mean over the first and
        last fifth of the window), ``growing`` (``amp_last > 1.1 amp_first`` and above 5
        encoder counts, or the handle hit an end stop in the window), ``hit_stop``,
        ``saturated_fraction``.
    """
    device = device or DeviceParams()
    hand = hand or HandParams()
    chain = params.chain_params
    L3 = chain.L3_mm
    jh, bh, kh = hand.at_pivot(L3)
    J = device.inertia_kg_m2 + jh
    b_dev = device.damping_Nms_per_rad
    bt = b_dev + bh
    T = params.sample_time_s
    if not quantise:
        params = replace(params, encoder_counts_per_rev=0)
    ctl = ImpedanceController(params, s)
    th_lo, th_hi = (math.radians(v) for v in kin.theta_range_deg(chain))
    if theta_hold_deg is None:
        op = rendered_stiffness(s, params)
        theta_hold_deg = max(
            float(op.theta_deg[int(np.argmax(op.K_Nm_per_rad))]), math.degrees(th_lo) + 0.5
        )
    th_hold = min(max(math.radians(theta_hold_deg), th_lo), th_hi)
    tau_push = float(static_handle_torque_Nm(s, params, np.array([th_hold]))[0])
    th = min(th_hold + math.radians(theta_start_offset_deg), th_hi)
    w = 0.0
    n = int(round(duration_s / T))
    half = n // 2
    dt = T / substeps
    gain = L3 / params.pulley_radius_mm  # handle torque per motor torque
    ctl.reset(th)
    for _ in range(20):  # converge the proxy at rest (no velocity: the angle does not move)
        ctl.step(th)
    tau0 = float(static_handle_torque_Nm(s, params, np.array([th]))[0])
    queue = [tau0] * device.delay_samples  # as if resting there before t = 0
    thetas = np.empty(n + 1)
    taus = np.empty(n)
    fc_dv = device.coulomb_Nm * dt / J
    n_sat = 0
    dissipated = 0.0
    hit_stop = False
    for k in range(n):
        out = ctl.step(th)
        n_sat += out.saturated
        queue.append(out.torque_Nm * gain)
        tau = queue.pop(0)  # computed delay_samples ago, held over this period
        thetas[k] = th
        taus[k] = tau
        for _ in range(substeps):
            acc = (tau - tau_push - bt * w - kh * (th - th_hold)) / J
            w_new = w + acc * dt
            if abs(w_new) <= fc_dv:
                w_new = 0.0
            else:
                w_new -= math.copysign(fc_dv, w_new)
            w = w_new
            th += w * dt
            if th < th_lo or th > th_hi:
                th = min(max(th, th_lo), th_hi)
                w = 0.0
                if k >= half:
                    hit_stop = True
            if k >= half:
                dissipated += (b_dev * w * w + device.coulomb_Nm * abs(w)) * dt
    thetas[n] = th
    th_w = thetas[half:]
    tau_static = static_handle_torque_Nm(s, params, th_w)
    dth = np.diff(th_w)
    # U(end) - U(start) = -int tau_static dtheta (trapezoid)
    work_ideal = np.sum(0.5 * (tau_static[1:] + tau_static[:-1]) * dth)
    excess = float(np.sum(taus[half:] * dth) - work_ideal)
    m = max(len(th_w) // 5, 2)
    a1 = float(np.std(th_w[:m]))
    a2 = float(np.std(th_w[-m:]))
    q = ctl.encoder_quantum_rad if ctl.encoder_quantum_rad > 0 else 1e-5
    growing = bool((a2 > 1.1 * a1 and a2 > 5 * q) or hit_stop)
    return {
        "time_s": np.arange(n + 1) * T,
        "theta_rad": thetas,
        "torque_handle_Nm": taus,
        "theta_hold_deg": math.degrees(th_hold),
        "controller_excess_J": excess,
        "device_dissipated_J": dissipated,
        "net_generated_J": excess - dissipated,
        "amp_first_rad": a1,
        "amp_last_rad": a2,
        "growing": growing,
        "hit_stop": hit_stop,
        "saturated_fraction": n_sat / n,
    }


# --------------------------------------------------------------------------- outputs
def plot_tuning(result: TuningResult, out_dir: str | Path) -> dict[str, Path]:
    """Write ``stiffness_vs_theta.png``, ``zwidth.png`` and ``bode_impedance.png``.

    Returns
    -------
    dict of str to Path
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sm, p, dev = result.summary, result.params, result.device
    T, B, fc = p.sample_time_s, virtual_damping_Nms_per_rad(p), p.velocity_cutoff_Hz
    files: dict[str, Path] = {}
    k_pass = sm["passive_stiffness_Nm_per_rad"]

    # stiffness vs theta, per thickness (one panel per material)
    mats = sorted({o.material for o in result.points})
    fig = Figure(figsize=(5.0 * len(mats), 4.2))
    FigureCanvasAgg(fig)
    for j, m in enumerate(mats):
        ax = fig.add_subplot(1, len(mats), j + 1)
        ops = [o for o in result.points if o.material == m]
        cmap = __import__("matplotlib").colormaps["viridis"]
        for n_, o in enumerate(ops):
            col = cmap(n_ / max(len(ops) - 1, 1))
            ax.semilogy(
                o.theta_deg,
                np.maximum(o.K_Nm_per_rad, 1e-3),
                color=col,
                lw=1.2,
                label=f"t={o.thickness_mm:g}" if n_ in (0, len(ops) - 1) else None,
            )
            ax.semilogy(
                o.theta_deg, np.maximum(o.K_raw_Nm_per_rad, 1e-3), color=col, lw=0.6, ls=":"
            )
        ax.axhline(k_pass, color="C3", lw=1.5, label="passive bound")
        ax.set_title(f"{m}: rendered K (solid), raw tissue (dotted)", fontsize=9)
        ax.set_xlabel(r"handle angle $\theta$ (deg)")
        ax.set_ylabel("K at handle pivot (N m/rad)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    files["stiffness"] = out / "stiffness_vs_theta.png"
    fig.savefig(files["stiffness"], dpi=110)

    # Z-width
    bmax = max(4.0 * B, 2.0 * dev.damping_Nms_per_rad)
    Bs, Ks = zwidth_boundary(dev.damping_Nms_per_rad, T, fc, dev.delay_samples, bmax)
    _, K0 = zwidth_boundary(dev.damping_Nms_per_rad, T, None, 0, bmax)
    fig = Figure(figsize=(6.0, 4.4))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    ax.fill_between(
        Bs,
        0,
        Ks,
        color="C2",
        alpha=0.25,
        label=f"passive (delay {dev.delay_samples}, cutoff {fc:g} Hz)",
    )
    ax.plot(Bs, K0, "k--", lw=1, label="Colgate b > KT/2 + |B| (no delay)")
    allK = np.concatenate([o.K_Nm_per_rad for o in result.points])
    ax.plot(np.full_like(allK, B), allK, "C0.", ms=2, label="operating points (chosen B)")
    ax.set_xlabel("virtual damping B (N m s/rad)")
    ax.set_ylabel("rendered stiffness K (N m/rad)")
    ax.set_title("Z-width at the handle pivot", fontsize=10)
    ax.set_ylim(0, 1.2 * max(float(np.max(Ks)), float(np.max(K0[:1])), float(np.max(allK))))
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    files["zwidth"] = out / "zwidth.png"
    fig.savefig(files["zwidth"], dpi=110)

    # Bode of the rendered impedance Z = tau / omega at the stiffest point
    kmax = sm["max_rendered_K_Nm_per_rad"]
    w = np.logspace(0, math.log10(math.pi / T), 400)
    zi = np.exp(-1j * w * T)
    a = math.exp(-2 * math.pi * fc * T)
    H = zi**dev.delay_samples * (kmax + B * (1 - a) * (1 - zi) / (T * (1 - a * zi)))
    Z = H / (1j * w)
    Zc = kmax / (1j * w) + B
    fig = Figure(figsize=(6.0, 5.0))
    FigureCanvasAgg(fig)
    ax1 = fig.add_subplot(2, 1, 1)
    ax2 = fig.add_subplot(2, 1, 2, sharex=ax1)
    f = w / (2 * math.pi)
    ax1.loglog(f, np.abs(Z), label="sampled (ZOH, delay, filter)")
    ax1.loglog(f, np.abs(Zc), "--", label="ideal K/s + B")
    ax1.set_ylabel("|Z| (N m s/rad)")
    ax1.set_title(f"Rendered impedance at K = {kmax:.3g} N m/rad, B = {B:.3g}", fontsize=10)
    ax1.legend(fontsize=7)
    ax1.grid(True, which="both", alpha=0.3)
    ax2.semilogx(f, np.degrees(np.angle(Z)))
    ax2.semilogx(f, np.degrees(np.angle(Zc)), "--")
    ax2.axhline(-90, color="0.6", lw=0.8)
    ax2.axhline(90, color="0.6", lw=0.8)
    ax2.set_ylabel("phase (deg)")
    ax2.set_xlabel("frequency (Hz)")
    ax2.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    files["bode"] = out / "bode_impedance.png"
    fig.savefig(files["bode"], dpi=110)
    return files


def write_outputs(result: TuningResult, out_dir: str | Path, plots: bool = True) -> dict[str, Path]:
    """Write ``controller.json``, ``tuning.json``, ``tuning.txt`` and the plots into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    d = result.to_dict()
    files = {
        "controller": out / "controller.json",
        "tuning": out / "tuning.json",
        "report": out / "tuning.txt",
    }
    save_params(result.params, files["controller"], extra={"tuning": d})
    files["tuning"].write_text(json.dumps(d, indent=2))
    files["report"].write_text(result.report() + "\n")
    if plots:
        files.update(plot_tuning(result, out))
    return files
