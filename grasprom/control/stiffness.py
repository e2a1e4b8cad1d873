r"""The controller linearised along the handle angle: rendered stiffness and static torque.

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

With the clipped rendering (:mod:`grasprom.control.field`) ``K`` is the slope of the field the
controller renders, ``Fi = Fr(theta) a(theta) + S(theta)`` with ``Fr`` linear between the
field's nodes: on the node interval holding ``theta``,
``K = -L3 1e-3 [P Fr' a + Fr a' + S']`` (``Fr'`` the interval's slope, ``P`` the Prony factor).
It is the tissue's where the field follows the tissue, ``K_lim`` (to the chain's curvature
inside an interval, ~0.04 %) where the field climbs at the bound -- also where the tissue is
already softer again but the field has not yet rejoined it -- and the spring's own where the
field renders the spring alone.

:func:`rendered_stiffness` gives ``K`` along ``theta`` for one material and thickness
(:class:`OperatingPoints`), :func:`operating_points` over the whole grid and
:func:`stiffest_point` the largest of them; :func:`field_stiffness_extremes` the extremes of
the clipped field over every node interval; :func:`static_handle_torque_Nm` is the ideal
static field.  Rendered instrument effects enter through :func:`prony_stiffness_factor` (on
``k_eff``) and :func:`virtual_damping_Nms_per_rad` (on ``B``); see
:mod:`grasprom.control.tuning`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from grasprom.chain import kinematics as kin
from grasprom.control.field import Field, prony_factor
from grasprom.control.impedance import ImpedanceController
from grasprom.control.params import ControllerParams
from grasprom.surrogate import Surrogate

__all__ = [
    "FieldStiffness",
    "OperatingPoints",
    "StiffestPoint",
    "clipped_field",
    "clipped_stiffness_bound_Nm_per_rad",
    "field_stiffness_extremes",
    "operating_cases",
    "operating_points",
    "prony_stiffness_factor",
    "rendered_stiffness",
    "static_handle_torque_Nm",
    "stiffest_point",
    "virtual_damping_Nms_per_rad",
]


@functools.lru_cache(maxsize=128)
def clipped_field(s: Surrogate, params: ControllerParams) -> Field:
    """The field of the clipped rendering of ``params`` (as the controller builds it, cached).

    Parameters
    ----------
    s : Surrogate
    params : ControllerParams
        With ``rendering = "clipped"`` (the field uses ``stiffness_limit_Nm_per_rad``).

    Returns
    -------
    Field
    """
    field = ImpedanceController(replace(params, rendering="clipped"), s).field
    assert field is not None
    return field


def clipped_stiffness_bound_Nm_per_rad(params: ControllerParams) -> float:
    """Bound on the clipped field's handle slope from its limit, N m/rad at the pivot.

    The field's node-to-node slopes are bounded by ``K_lim / (1 + sum g_i)`` (relaxed); the
    rendered Prony series multiplies the jaw part by at most :func:`prony_stiffness_factor`,
    so the bound is ``K_lim P / (1 + sum g_i)`` (``K_lim`` without Prony terms).  It is not
    the largest slope rendered: inside a node interval the slope differs from the chord by the
    chain's curvature (``Fr a'``, ~0.04 % at the closed end), and where the limit is below the
    return spring's own stiffness the field renders the spring alone, at the spring's slope
    (:func:`field_stiffness_extremes` has the slopes the field renders).

    Parameters
    ----------
    params : ControllerParams

    Returns
    -------
    float
    """
    return (
        params.stiffness_limit_Nm_per_rad
        * prony_stiffness_factor(params)
        / prony_factor(params.prony_g)
    )


def _field_jaw_force_N(s: Surrogate, params: ControllerParams, th_deg: np.ndarray) -> np.ndarray:
    """Rendered (relaxed) jaw force of the clipped field at chain angles ``th_deg`` (N)."""
    return clipped_field(s, params).jaw_force_array(np.radians(th_deg))[0]


def prony_stiffness_factor(params: ControllerParams) -> float:
    """Instantaneous over relaxed jaw stiffness of the rendered Prony series (1).

    ``1 + sum g_i 2 / (1 + a_i)`` with ``a_i = exp(-T / tau_i)``: the gain of the discrete
    filter ``Fg -> Fg + sum g_i h_i`` of
    :meth:`~grasprom.control.impedance.ImpedanceController.step` at the Nyquist frequency,
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
        Rendered (relaxed) jaw force ``k_c,eff (g_p - g)``, N (clipped: the field's ``Fr``;
        the proxy gap is then the gap).
    tissue_stiffness_N_per_mm : ndarray
        Surrogate stiffness (times ``tissue_scale``) at the kinematic gap (raw tissue), N/mm.
    jaw_stiffness_N_per_mm : ndarray
        Rendered instantaneous jaw stiffness
        ``P k_c,eff k_t(g_p) / (k_c,eff + k_t(g_p))``, N/mm (``P`` the
        :func:`prony_stiffness_factor`; ``k_c,eff = k_c`` without jaw compliance; clipped:
        ``-P dFr/dgap`` of the field's node interval).
    K_Nm_per_rad : ndarray
        Rendered stiffness at the handle pivot (chain + coupling, or the clipped field's
        slope on its node interval), N m/rad.
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


def _handle_K(
    fg: np.ndarray,
    kjaw: np.ndarray,
    th: np.ndarray,
    chain: kin.ChainParams,
    render_spring: bool,
) -> np.ndarray:
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
    K_raw = _handle_K(f_raw, pf * kt_raw, th, chain, params.render_spring)
    if params.rendering == "clipped":
        return _clipped_points(s, params, th, g, kt_raw, K_raw)
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
        K_raw_Nm_per_rad=K_raw,
    )


def _clipped_points(
    s: Surrogate,
    params: ControllerParams,
    th: np.ndarray,
    g: np.ndarray,
    kt_raw: np.ndarray,
    K_raw: np.ndarray,
) -> OperatingPoints:
    """Operating points of the clipped rendering: the field's force and its actual slope.

    ``th`` chain angles (deg), ``g`` gaps (mm), ``kt_raw`` tissue stiffness (N/mm), ``K_raw``
    the tissue's handle stiffness (N m/rad).  The rendered stiffness is the slope of the
    field's handle force on the node interval holding each angle (:func:`_field_slopes`):
    the tissue's where the field follows it, the limit where it climbs at the bound (also
    while it rejoins a tissue that is already softer), the spring's where it renders the
    spring alone; the jaw stiffness is the interval's ``-P dFr/dgap``.
    """
    f = clipped_field(s, params)
    th_rad = np.radians(th)
    fr, _clip = f.jaw_force_array(th_rad)
    u = (th_rad - f.theta_lo_rad) / f.dtheta_rad
    j = np.clip(np.floor(u).astype(np.int64), 0, len(f.force_jaw_N) - 2)
    kjaw, K = _field_slopes(f, params, j, u - j, th)
    return OperatingPoints(
        material=params.material,
        thickness_mm=float(params.thickness_mm),
        theta_deg=th,
        gap_mm=g,
        proxy_gap_mm=g.copy(),
        force_jaw_N=fr,
        tissue_stiffness_N_per_mm=kt_raw,
        jaw_stiffness_N_per_mm=kjaw,
        K_Nm_per_rad=K,
        K_raw_Nm_per_rad=K_raw,
    )


def _field_slopes(
    f: Field, params: ControllerParams, j: np.ndarray, w: np.ndarray, th_deg: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Instantaneous jaw stiffness (N/mm) and handle stiffness (N m/rad) of the field ``f``.

    On node interval ``j`` (int array) at the weight ``w`` in ``[0, 1]`` (chain angle
    ``th_deg``, deg): the jaw force ``Fr = Fr_j + w (Fr_j+1 - Fr_j)`` is linear in the angle
    with slope ``Fr' = (Fr_j+1 - Fr_j) / dtheta``, so the jaw stiffness is ``-P Fr' / g'`` and
    the handle stiffness ``-L3 1e-3 d(Fr a + S)/dtheta`` the chain's
    :func:`~grasprom.chain.kinematics.dhandle_force_dtheta_N_per_rad` of them (``P`` the
    :func:`prony_stiffness_factor`; spring terms without ``render_spring``).
    """
    fr = np.asarray(f.force_jaw_N, dtype=float)
    f0 = fr[j]
    force = f0 + w * (fr[j + 1] - f0)
    dfr = (fr[j + 1] - f0) / f.dtheta_rad  # N/rad
    chain = params.chain_params
    g1 = np.asarray(kin.dgap_dtheta_mm_per_rad(th_deg, chain), dtype=float)
    kjaw = -prony_stiffness_factor(params) * dfr / g1
    return kjaw, _handle_K(force, kjaw, th_deg, chain, params.render_spring)


class FieldStiffness(NamedTuple):
    """Extremes of the clipped field's handle stiffness (:func:`field_stiffness_extremes`).

    Attributes
    ----------
    K_max_Nm_per_rad, K_min_Nm_per_rad : float
        Largest and smallest slope over every node interval, N m/rad at the pivot.
    theta_max_deg : float
        Where the largest is (an end of its interval), deg.
    spring_alone : bool
        Whether the field renders the return spring alone there (zero jaw force at both nodes
        of the interval): a lower limit does not soften it.
    """

    K_max_Nm_per_rad: float
    K_min_Nm_per_rad: float
    theta_max_deg: float
    spring_alone: bool


def field_stiffness_extremes(s: Surrogate, params: ControllerParams) -> FieldStiffness:
    """Largest and smallest handle stiffness the clipped field of ``params`` renders.

    The slope of :func:`rendered_stiffness` at both ends of each of the field's node intervals:
    inside an interval it is smooth and nearly linear in the angle (it changes by at most
    ~0.08 % across one, through the chain's ``a'``, ``a''`` and the spring's ``S''``; its
    curvature is a further factor ``dtheta`` smaller), so the ends hold its extremes.  Every
    slope the field renders, the return spring's where it renders the spring alone included,
    not only at sampled angles.

    Parameters
    ----------
    s : Surrogate
    params : ControllerParams
        Any rendering: the field is built as the clipped controller builds it (its limit is
        ``field_stiffness_limit_Nm_per_rad``).

    Returns
    -------
    FieldStiffness
    """
    p = replace(params, rendering="clipped")
    f = clipped_field(s, p)
    n = len(f.force_jaw_N)
    deg = np.degrees(f.theta_lo_rad + f.dtheta_rad * np.arange(n))
    deg[-1] = kin.theta_range_deg(p.chain_params)[1]  # the last node as the field builds it
    j = np.arange(n - 1)
    k_lo = _field_slopes(f, p, j, np.zeros(n - 1), deg[:-1])[1]
    k_hi = _field_slopes(f, p, j, np.ones(n - 1), deg[1:])[1]
    i_lo, i_hi = int(np.argmax(k_lo)), int(np.argmax(k_hi))
    i, th = (i_lo, deg[i_lo]) if k_lo[i_lo] >= k_hi[i_hi] else (i_hi, deg[i_hi + 1])
    fr = f.force_jaw_N
    return FieldStiffness(
        K_max_Nm_per_rad=float(max(k_lo[i_lo], k_hi[i_hi])),
        K_min_Nm_per_rad=float(min(np.min(k_lo), np.min(k_hi))),
        theta_max_deg=float(th),
        spring_alone=bool(p.render_spring and fr[i] == 0.0 and fr[i + 1] == 0.0),
    )


def static_handle_torque_Nm(
    s: Surrogate, params: ControllerParams, theta_rad: np.ndarray
) -> np.ndarray:
    """Static device torque at the handle pivot ``Fi L3`` (N m, opening) with converged proxy.

    With the clipped rendering the jaw force is the field's (:func:`clipped_field`).

    The ideal (continuous, undamped) field the controller approximates; no saturation.  With
    rendered instrument effects: tissue scale and jaw compliance included, the Prony series
    relaxed, no friction, no backlash (the chain angle = the handle angle).
    """
    chain = params.chain_params
    th = np.degrees(
        np.clip(np.asarray(theta_rad, dtype=float), *np.radians(kin.theta_range_deg(chain)))
    )
    g = np.asarray(kin.gap_mm(th, chain), dtype=float)
    if params.rendering == "clipped":
        fg = _field_jaw_force_N(s, params, th)
    else:
        kc = params.coupling_effective_N_per_mm
        gp = _proxy_gap(s, g, params.thickness_mm, params.material, kc, scale=params.tissue_scale)
        fg = kc * (gp - g)
    fi = np.asarray(kin.handle_force_N(fg, th, chain), dtype=float)
    if not params.render_spring:
        fi = fi - np.asarray(kin.spring_handle_force_N(th, chain), dtype=float)
    return fi * chain.L3_mm * 1e-3


def operating_cases(
    s: Surrogate,
    params: ControllerParams,
    thicknesses: Sequence[float] | None = None,
    materials: Sequence[str] | None = None,
) -> list[ControllerParams]:
    """``params`` at every material x thickness (default: the surrogate's grids), checked.

    Raises
    ------
    ValueError
        A thickness outside the surrogate's range of its material.
    """
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
            out.append(replace(params, material=m, thickness_mm=float(t)))
    return out


def operating_points(
    s: Surrogate,
    params: ControllerParams,
    thicknesses: Sequence[float] | None = None,
    materials: Sequence[str] | None = None,
    n_theta: int = 221,
) -> list[OperatingPoints]:
    """Operating points over theta x thickness x material (default: the surrogate's grids)."""
    return [
        rendered_stiffness(s, p, n_theta=n_theta)
        for p in operating_cases(s, params, thicknesses, materials)
    ]


class StiffestPoint(NamedTuple):
    """Largest rendered stiffness over a set of :class:`OperatingPoints` (:func:`stiffest_point`).

    Attributes
    ----------
    K_max_Nm_per_rad : float
        Largest rendered stiffness at the handle pivot, N m/rad.
    K_min_Nm_per_rad : float
        Smallest rendered stiffness, N m/rad (the other end of the passivity check).
    point : OperatingPoints
        The material/thickness holding the largest.
    index : int
        Its index along ``point.theta_deg``.
    """

    K_max_Nm_per_rad: float
    K_min_Nm_per_rad: float
    point: OperatingPoints
    index: int


def stiffest_point(points: list[OperatingPoints]) -> StiffestPoint:
    """Largest (and smallest) rendered stiffness over ``points`` and where the largest is.

    Parameters
    ----------
    points : list of OperatingPoints

    Returns
    -------
    StiffestPoint
        Unpacks as ``(K_max, K_min, point, index)``; the first point of the largest wins a tie.
    """
    best = (-math.inf, math.inf, points[0], 0)
    kmin = math.inf
    for op in points:
        i = int(np.argmax(op.K_Nm_per_rad))
        kmin = min(kmin, float(np.min(op.K_Nm_per_rad)))
        if op.K_Nm_per_rad[i] > best[0]:
            best = (float(op.K_Nm_per_rad[i]), kmin, op, i)
    return StiffestPoint(best[0], kmin, best[2], best[3])
