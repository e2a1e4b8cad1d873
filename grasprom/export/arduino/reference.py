"""The Python reference of the Arduino export: the controller step on encoder counts, in double.

What the tabulated fixed-point core (``GC_TABULATED``) must reproduce: the step of
:class:`grasprom.control.ImpedanceController` with ``theta = count * q`` and, by
``ControllerParams.rendering``, either the virtual coupling solved to convergence
(:func:`coupled_jaw_force`, ``"coupling"``) or the stiffness-clipped field of
:mod:`grasprom.control.field` interpolated at the chain angle (:func:`clipped_field`,
:meth:`~grasprom.control.field.Field.jaw_force_array`, ``"clipped"``);
:func:`rendered_jaw_force` dispatches.  The tables
(:mod:`grasprom.export.arduino.tables`) and the error figures
(:mod:`grasprom.export.arduino.budget`) are computed from it.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from grasprom.chain import kinematics as kin
from grasprom.control import ControllerParams, Field, ImpedanceController
from grasprom.surrogate import Surrogate


def coupled_jaw_force(
    surrogate: Surrogate,
    gap_mm: NDArray,
    thickness_mm: float,
    material: str,
    kc: float,
    scale: float = 1.0,
) -> tuple[NDArray, NDArray]:
    """Jaw force through the virtual coupling, proxy solved to convergence (vectorised).

    Solves ``kc (g_p - g) = F(g_p)`` in ``[g, g + F(g)/kc]`` by bisection (the residual
    increases with ``g_p``), to machine precision: the fixed point the controller's three
    warm-started Newton iterations track.

    Parameters
    ----------
    surrogate : Surrogate
    gap_mm : ndarray
        Kinematic jaw gaps (mm).
    thickness_mm : float
    material : str
    kc : float
        Coupling stiffness (N/mm; in series with a jaw compliance: the effective one).
    scale : float
        Factor on the tissue force (``ControllerParams.tissue_scale``).

    Returns
    -------
    (ndarray, ndarray)
        Rendered jaw force ``kc (g_p - g)`` (N) and the proxy gap ``g_p`` (mm).
    """
    g = np.asarray(gap_mm, dtype=float)
    f = scale * surrogate.force(g, thickness_mm, material)
    lo, hi = g.copy(), g + f / kc
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        r = kc * (mid - g) - scale * surrogate.force(mid, thickness_mm, material)
        neg = r < 0.0
        lo = np.where(neg, mid, lo)
        hi = np.where(neg, hi, mid)
    gp = np.where(f > 0.0, 0.5 * (lo + hi), g)
    return kc * (gp - g), gp


def chain_terms(theta_rad: NDArray, chain: kin.ChainParams) -> tuple[NDArray, NDArray, NDArray]:
    """Gap (mm), ``a = g'/L3`` (1/rad... N per N) and spring handle force (N), no range check."""
    c = chain.constants
    xc, d1, _d2, _s, _cb = kin.linkage_state(np.asarray(theta_rad, dtype=float), chain)
    gap = chain.gap_closed_mm + c.gap_per_xc * (xc - c.xc_closed)
    u = (c.xc_open - xc) * c.stroke_sign
    fs = chain.spring_preload_N + chain.spring_k_N_per_mm * u
    du = -d1 * c.stroke_sign
    return gap, c.gap_per_xc * d1 / chain.L3_mm, -fs * du / chain.L3_mm


def clipped_field(
    params: ControllerParams, surrogate: Surrogate, material: str, thickness_mm: float
) -> Field:
    """The stiffness-clipped field of one operating case, as the Python controller builds it.

    ``ImpedanceController(params', surrogate).field`` with ``params'`` = ``params`` at this
    material and thickness (clamped into the surrogate's range, as ``gf_init`` clamps it) and
    ``rendering = "clipped"``.

    Parameters
    ----------
    params : ControllerParams
    surrogate : Surrogate
    material : str
    thickness_mm : float

    Returns
    -------
    Field
    """
    lo, hi = surrogate.thickness_range(material)
    t = min(max(float(thickness_mm), lo), hi)
    return _cached_field(replace(params, material=material, thickness_mm=t), surrogate)


@functools.lru_cache(maxsize=256)
def _cached_field(params: ControllerParams, surrogate: Surrogate) -> Field:
    """``ImpedanceController(params, surrogate).field``, memoised (tables and error figures
    build the field of a case several times; with a jaw compliance each costs a bisection per
    node)."""
    f = ImpedanceController(replace(params, rendering="clipped"), surrogate).field
    if f is None:  # pragma: no cover - rendering "clipped" always builds the field
        raise RuntimeError("the clipped controller built no field")
    return f


def rendered_jaw_force(
    params: ControllerParams,
    surrogate: Surrogate,
    material: str,
    thickness_mm: float,
    theta_rad: NDArray,
) -> tuple[NDArray, NDArray, NDArray]:
    """Static rendered jaw force at chain angles, by ``params.rendering`` (vectorised).

    ``"coupling"``: :func:`coupled_jaw_force` (proxy to convergence); ``"clipped"``: the
    field of :func:`clipped_field` at the angles
    (:meth:`~grasprom.control.field.Field.jaw_force_array`).  Before the
    Prony series, friction, spring and damping.

    Parameters
    ----------
    params : ControllerParams
    surrogate : Surrogate
    material : str
    thickness_mm : float
    theta_rad : ndarray
        Chain angles (rad, in the chain's range).

    Returns
    -------
    (ndarray, ndarray, ndarray)
        Jaw force (N); the flag ``coupling_active`` (coupling: tissue stiffer than the
        coupling at the proxy, in contact; clipped: the stiffness limit acts); the proxy gap
        (mm; the kinematic gap with the clipped rendering).
    """
    th = np.asarray(theta_rad, dtype=float)
    gap, _, _ = chain_terms(th, params.chain_params)
    if params.rendering == "clipped":
        fg, active = clipped_field(params, surrogate, material, thickness_mm).jaw_force_array(th)
        return fg, active, gap
    sc = params.tissue_scale
    kc = params.coupling_effective_N_per_mm
    fg, gp = coupled_jaw_force(surrogate, gap, thickness_mm, material, kc, sc)
    f_t = sc * surrogate.force(gap, thickness_mm, material)
    active = (f_t > 0.0) & (sc * surrogate.stiffness(gp, thickness_mm, material) > kc)
    return fg, active, gp


def encoder_quantum_rad(params: ControllerParams) -> float:
    """Handle angle per encoder count (rad), as :class:`ImpedanceController`."""
    n = int(params.encoder_counts_per_rev)
    if n <= 0:
        raise ValueError("the Arduino export needs an encoder: encoder_counts_per_rev > 0")
    return 2.0 * math.pi * params.pulley_radius_mm / (n * params.chain_params.L3_mm)


@dataclass
class ReferenceRun:
    """Float reference outputs of one test case (arrays over the steps, SI-like units)."""

    torque_Nm: NDArray
    force_handle_N: NDArray
    force_jaw_N: NDArray
    velocity_rad_per_s: NDArray
    count: NDArray
    flags: dict[str, NDArray]


def filtered_velocity(theta_rad: NDArray, params: ControllerParams) -> NDArray:
    """First-order low-pass of the backward-difference velocity, as the controller (rad/s).

    Parameters
    ----------
    theta_rad : ndarray
        Handle angles of the steps (rad, clamped).
    params : ControllerParams
        Cut-off and sample time.

    Returns
    -------
    ndarray
    """
    a = math.exp(-2.0 * math.pi * params.velocity_cutoff_Hz * params.sample_time_s)
    v = np.empty(len(theta_rad))
    vs, prev = 0.0, None
    for i, t in enumerate(theta_rad):
        if prev is None:
            prev = t
        vs = a * vs + (1.0 - a) * (t - prev) / params.sample_time_s
        prev = t
        v[i] = vs
    return v


def backlash_angles(theta_rad: NDArray, backlash_deg: float, lo: float, hi: float) -> NDArray:
    """Linkage angle behind a play of total width ``backlash_deg`` (rad, clipped to [lo, hi]).

    Parameters
    ----------
    theta_rad : ndarray
        Encoder-side handle angles (rad).
    backlash_deg : float
        Total play (deg); 0: the angles themselves.
    lo, hi : float
        Handle range (rad).

    Returns
    -------
    ndarray
    """
    if not backlash_deg > 0:
        return theta_rad
    hb = 0.5 * math.radians(backlash_deg)
    thc = np.empty_like(theta_rad)
    y = float(theta_rad[0]) if len(theta_rad) else 0.0
    for i, t in enumerate(theta_rad.tolist()):
        y = min(max(min(max(y, t - hb), t + hb), lo), hi)
        thc[i] = y
    return thc


def prony_rendered(fg: NDArray, params: ControllerParams) -> NDArray:
    """Quasi-linear viscoelastic rendering of the jaw force (N; unchanged without terms).

    Parameters
    ----------
    fg : ndarray
        Coupled jaw force of the steps (N).
    params : ControllerParams
        Prony coefficients, time constants (s) and sample time (s).

    Returns
    -------
    ndarray
    """
    if not params.prony_g:
        return fg
    from scipy.signal import lfilter

    dfg = np.diff(fg, prepend=0.0)
    acc = np.zeros_like(fg)
    for g_i, tau in zip(params.prony_g, params.prony_tau_s):
        acc += g_i * lfilter([1.0], [1.0, -math.exp(-params.sample_time_s / tau)], dfg)
    return np.maximum(fg + acc, 0.0)


def friction_force(v: NDArray, fg_handle: NDArray, params: ControllerParams) -> NDArray:
    """Rendered friction at the handle (N): Coulomb + load-proportional + viscous.

    Parameters
    ----------
    v : ndarray
        Filtered handle velocity (rad/s).
    fg_handle : ndarray
        Tissue handle force ``Fg g'/L3`` (N), the load of the load-proportional term.
    params : ControllerParams

    Returns
    -------
    ndarray
    """
    vf = -v * params.chain_params.L3_mm  # finger speed, mm/s, > 0 closing
    thr = params.friction_velocity_threshold_mm_per_s
    sdir = np.empty_like(vf)
    sd = 0.0
    for i, x in enumerate(vf.tolist()):
        sd = 1.0 if x > thr else (-1.0 if x < -thr else sd)
        sdir[i] = sd
    return (
        params.friction_coulomb_N + params.friction_load_coefficient * np.abs(fg_handle)
    ) * sdir + params.friction_viscous_N_s_per_mm * vf


def reference_run(
    params: ControllerParams,
    surrogate: Surrogate,
    material: str,
    thickness_mm: float,
    counts: Sequence[int] | NDArray,
) -> ReferenceRun:
    """The Python reference (double, float surrogate) on encoder counts.

    Same step as :meth:`grasprom.control.ImpedanceController.step` with ``theta = count *
    q``; with the coupling rendering the proxy is solved to convergence (the controller's
    warm-started Newton iterations converge to it on any realistic trajectory; see the tests),
    with the clipped rendering the jaw force is the controller's own field at the chain angle
    (:func:`rendered_jaw_force`).

    Parameters
    ----------
    params : ControllerParams
    surrogate : Surrogate
    material : str
    thickness_mm : float
        Inside the surrogate's range.
    counts : sequence of int
        Handle angles in encoder counts, one per step.

    Returns
    -------
    ReferenceRun
    """
    chain = params.chain_params
    q = encoder_quantum_rad(params)
    th_lo, th_hi = (math.radians(v) for v in kin.theta_range_deg(chain))
    raw = np.asarray(counts, dtype=np.int64)
    th_raw = raw * q
    clamped = (th_raw < th_lo) | (th_raw > th_hi)
    th = np.clip(th_raw, th_lo, th_hi)
    v = filtered_velocity(th, params)
    thc = backlash_angles(th, params.backlash_deg, th_lo, th_hi)  # play before the linkage
    gap, ca, cb = chain_terms(thc, chain)
    sc = params.tissue_scale
    f_t = sc * surrogate.force(gap, thickness_mm, material)
    fg, active, _gp = rendered_jaw_force(params, surrogate, material, thickness_mm, thc)
    contact = f_t > 0.0
    fg = prony_rendered(fg, params)
    fi = fg * ca + (cb if params.render_spring else 0.0)
    if params.friction_rendered:
        fi = fi + friction_force(v, fg * ca, params)
    fi = fi - params.damping_Nms_per_rad * v / (chain.L3_mm * 1e-3)
    r_m = params.pulley_radius_mm * 1e-3
    torque = fi * r_m
    sat = np.abs(torque) > params.torque_limit_Nm
    torque = np.where(sat, np.copysign(params.torque_limit_Nm, torque), torque)
    area = params.jaw_length_mm * 0.5 * math.pi * (params.diameter_mm - thickness_mm)
    warn = (f_t >= params.force_warning_N) | (f_t / area >= params.pressure_warning_MPa)
    return ReferenceRun(
        torque_Nm=torque,
        force_handle_N=torque / r_m,
        force_jaw_N=fg,
        velocity_rad_per_s=v,
        count=np.round(th / q).astype(int),
        flags={
            "contact": contact,
            "tissue_warning": warn,
            "coupling_active": active,
            "saturated": sat,
            "theta_clamped": clamped,
        },
    )
