r"""Kinematic chain of the grasper: handle angle -> jaw gap, and handle force <-> jaw force.

Guachi et al. (2020, section 3, eqs (1)-(4), Table 1, Fig. 2) describes the instrument as a
handle lever, a crank-and-link (slider-crank) driving the push rod, a return spring on the rod and
a cam that turns the rod stroke into the jaw rotation:

.. math::

    F_g = F_t' \frac{m}{n}, \qquad
    F_t' = \frac{F_i L_3}{L_1}\cos\varphi\cos\beta - k\,\Delta x, \qquad
    \sin\beta = \frac{d\cos\theta + \sin\theta\sqrt{L_1^2 - d^2} - d}{L_2}, \qquad
    \varphi = \theta/2 .

This module builds that chain from its geometry (positions of the linkage points as functions of
the handle angle) and gets the forces from virtual work, so that the chain is exactly
energy-conserving; the paper's closed-form eq (2) is kept as :func:`seed_jaw_force_N` for
comparison.

Geometry (all lengths mm, angles in degrees at the public API, radians inside)
------------------------------------------------------------------------------
* ``O`` = (0, 0): the handle pivot.  The moving handle is rigid with the crank ``OB`` (length
  ``L1``); the finger force ``Fi`` acts on the handle at ``L3`` from ``O``, perpendicular to the
  handle, so the handle moment is ``Fi * L3`` and the finger travels ``L3 * dtheta``.
* ``B(theta) = R(theta) (h, d)`` with ``h = sqrt(L1^2 - d^2)``: at ``theta = 0`` the crank tip is
  at height ``d`` (the offset), so ``y_B - d = d cos(theta) + h sin(theta) - d``.
* ``C`` is the rod end (slider), constrained to the line ``y = d`` (the rod axis) and joined to
  ``B`` by the link ``BC`` (length ``L2``).  The link angle to the rod axis is then exactly
  eq (3): ``sin(beta) = (y_B - d) / L2``; ``x_C = x_B + side * L2 cos(beta)`` with ``side = -1``
  when the slider lies on the pivot side of ``B`` ("behind", the default) and ``+1`` beyond it.
* Sign convention: ``theta`` is the handle angle of Guachi et al. (2020), ``theta_open_deg``
  (22 deg, Table 1's theta_initial) with the handle released and the jaws open, decreasing to
  ``theta_closed_deg`` (0 deg) with the handle squeezed and the jaws at the closed height.
  Closing = ``theta`` decreasing.  ``Fi > 0`` squeezes the handle (closes), ``Fg > 0`` is the
  clamping force on one jaw (the force the tissue pushes back with, as in the FE data).
* Rod stroke ``u(theta) = |x_C(theta) - x_C(theta_open)|`` (mm, 0 open, ``u_max`` closed): this
  is Guachi et al.'s ``Delta x`` (displacement of ``C(theta)`` from ``C0 = C(22 deg)``).
* Jaw: a single-acting jaw turned by a straight-slot cam (Scotch yoke): a pin at ``m`` from the
  jaw pivot runs in a slot of the rod end normal to the rod, so ``u = m (sin a_open - sin a)``,
  and the tissue reference point at ``n`` from the jaw pivot sits at ``gap = gap_closed +
  n sin a``.  The gap is therefore linear in the rod stroke, ``d gap = -(n/m) du``, and seed
  eq (1) ``Fg = F_rod m/n`` is exact.  The endpoints fix ``n/m = (gap_open - gap_closed)/u_max``;
  ``n`` is a choice (it sets the jaw opening angle), ``m`` follows.  A symmetric double-acting
  pair gives the same gap law with ``n`` replaced by ``2n``.
* Return spring on the rod: force ``F_s = F0 + k u`` resisting closing (eq (2)'s
  ``k Delta x`` plus a preload ``F0``), energy ``E = F0 u + k u^2 / 2`` (N mm = mJ).

Virtual work (frictionless rigid chain)
---------------------------------------
With ``g(theta)`` the gap, ``g' = dg/dtheta > 0`` (mm/rad), ``u' = du/dtheta < 0``:

.. math::

    F_i\, L_3\,(-d\theta) = F_g\,(-dg) + dE
    \;\Rightarrow\;
    F_i = \frac{F_g g' - F_s u'}{L_3}, \qquad F_g = \frac{F_i L_3 + F_s u'}{g'} .

The transmission ratio is ``Fg/Fi = L3 / g'`` (spring excluded, as in Guachi et al. (2020) Fig. 6).

Seed formula vs derived chain
-----------------------------
Eq (2) projects the crank-tip force ``Fi L3 / L1`` with ``cos(phi) cos(beta)``; the exact
rod force is ``Fi L3 cos(beta) / (L1 sin(mu))`` with ``mu`` the crank-link transmission angle,
i.e. ``Fi L3 / |dx_C/dtheta|``.  With Table 1's lengths and eq (3)'s layout the crank stays
nearly parallel to the link (``mu`` = 7.6 deg open to 11.0 deg closed), so the rod moves only
2.9-4.0 mm per radian of handle, not ``L1`` = 21 mm, and the paper formula understates the jaw
force several times.  With the default parameters (same ``m/n`` in both) the paper's ``Fg/Fi``
is 81.0-87.0 % below the derived one: the largest deviation, -87.0 %, is at ``theta = 22 deg``
(open), the smallest, -81.0 % (exactly ``|d|/L1 - 1``), at ``theta = 0`` (closed).  The derived
ratio falls from 79.3 % (open) to 58.1 % (closed); the paper's rises from 10.3 % to 11.1 %.  The
spring terms agree exactly (the spring acts along the rod, so eq (2)'s ``k Delta x`` is the
exact rod-side spring force, less the preload).  Only the derived chain satisfies virtual work,
so the controller uses it: a passive haptic rendering needs the handle force to be the exact
work-conjugate of the handle motion, otherwise the rendered chain creates or destroys energy
over a closing/opening cycle (and with the paper formula the handle force for a given tissue
force would be 5-8x too large).  Whatever the linkage details, the mean of ``Fg/Fi`` over
the stroke is fixed by energy: ``L3 * 22 deg / (gap_open - gap_closed)`` = 68.1 % with the
defaults (22 deg of handle at 54.1 mm is 20.8 mm of finger travel for 30.5 mm of gap travel).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "ChainParams",
    "LinkagePoints",
    "beta_deg",
    "dgap_dtheta_mm_per_rad",
    "d2gap_dtheta2_mm_per_rad2",
    "dxc_dtheta",
    "dhandle_force_dtheta_N_per_rad",
    "gap_mm",
    "handle_force_N",
    "jaw_force_N",
    "linkage_points_mm",
    "linkage_state",
    "plot_transmission",
    "seed_comparison",
    "seed_jaw_force_N",
    "seed_transmission_ratio",
    "slider_x_mm",
    "spring_dx_mm",
    "spring_energy_Nmm",
    "spring_force_N",
    "spring_handle_force_N",
    "theta_from_gap_deg",
    "theta_range_deg",
    "transmission_ratio",
    "xc_mm",
]

#: Table 1 of Guachi et al. (2020) (mm, deg).  ``beta_initial = 19 deg`` is not reachable with
#: eq (3) and these lengths for any offset ``d``: see :attr:`ChainParams.beta_open_deg`.
SEED_TABLE1 = {
    "L1_mm": 21.0,
    "L2_mm": 25.1,
    "L3_mm": 54.1,
    "theta_initial_deg": 22.0,
    "beta_initial_deg": 19.0,
}

_THETA_TOL_DEG = 1e-9  # float slack accepted at the ends of the theta range (then clipped)
_N_CHECK = 1025  # samples used to check assembly and monotonicity of a parameter set

FloatOrArray = float | NDArray[np.float64]


class LinkageConstants(NamedTuple):
    """Derived constants of a :class:`ChainParams` (mm, rad), for the C core's code generation."""

    h: float  # sqrt(L1^2 - d^2), mm
    side: float  # -1 slider behind B (pivot side), +1 beyond
    xc_closed: float  # x_C(theta_closed), mm
    xc_open: float  # x_C(theta_open), mm
    stroke_sign: float  # sign(x_C(open) - x_C(closed))
    u_max: float  # rod stroke open -> closed, mm
    gap_per_xc: float  # (gap_open - gap_closed) / (x_C(open) - x_C(closed)), 1
    th_lo: float  # rad
    th_hi: float  # rad


@dataclass(frozen=True)
class ChainParams:
    """Geometry and mechanics of the grasper chain (mm, N, N/mm, deg).

    Guachi et al. (2020) Table 1 gives ``L1``, ``L2``, ``L3``, theta_initial = 22 deg and
    beta_initial =
    19 deg; everything else is a documented choice.  All fields can be overridden
    (``dataclasses.replace(p, offset_d_mm=-3.0)``); the set is validated on construction
    (``ValueError`` naming the parameter).

    Parameters
    ----------
    L1_mm : float
        Crank ``OB`` on the handle, mm.  Guachi et al. (2020) Table 1: 21 mm.
    L2_mm : float
        Link ``BC`` from the crank tip to the rod end, mm.  Table 1: 25.1 mm.
    L3_mm : float
        Distance from the handle pivot to the finger force ``Fi``, mm.  Table 1: 54.1 mm.  The
        handle work is ``Fi * L3 * dtheta``.
    theta_open_deg : float
        Handle angle with the handle released and the jaws fully open, deg.  Table 1's
        theta_initial = 22 deg.  ``C0 = C(theta_open)`` is the spring's reference.
    theta_closed_deg : float
        Handle angle at full closure (the closed height), deg.  0 deg: Guachi et al.'s eq (3) has
        the link parallel to the rod (beta = 0) at theta = 0, and phi = theta/2 "spans
        [0, theta_i/2]" (section 3).
    offset_d_mm : float
        Offset ``d`` of the crank tip from the rod axis at ``theta = 0`` (eq (3)), mm; the paper
        does not give it.  Default -4.0 mm: eq (3) at 22 deg is largest at
        ``d = -L1 sin(theta_initial/2) = -4.007 mm`` (the crank then swings symmetrically,
        -11 to +11 deg about the rod direction); -4.0 mm gives beta_open = 18.62 deg, the
        closest eq (3) gets to Table 1's 19 deg (0.38 deg short, an inconsistency of the paper).
    slider_side : {"behind", "beyond"}
        Assembly branch of the slider-crank: the rod end ``C`` on the pivot side of ``B``
        ("behind", default; ``x_C = x_B - L2 cos(beta)``) or beyond it.  With ``d = -4 mm`` the
        "beyond" branch passes a dead centre at theta = 6.0 deg (the jaws would reopen during
        the last 6 deg of squeeze), so it is rejected by the validation; "behind" is monotone,
        the rod end ``C`` moving 1.31 mm (towards -x, away from the crank tip) with
        ``|dx_C/dtheta|`` from 2.93 mm/rad (open) to 4.00 mm/rad (closed).
    n_mm : float
        Jaw lever arm from the jaw pivot to the tissue reference point (where the tube sits and
        where the gap is measured), mm.  Eq (1)'s ``n``; the paper does not give it.
        Default 35 mm: a bowel-grasper jaw long enough for a 30 mm tube; with the single-acting
        slot cam the jaw then opens ``asin((gap_open - gap_closed)/n)`` = 60.6 deg.  Must exceed
        ``gap_open - gap_closed``.
    gap_open_mm : float
        Jaw gap at ``theta_open``, mm.  Default 32 mm: the FE tube (outer diameter 30 mm, see
        ``grasprom.fe.model2d.CaseSpec``) fits with 1 mm clearance on each side, so the handle has
        a free stroke before first touch (at :attr:`theta_touch_deg`, 20.3 deg).
    gap_closed_mm : float
        Jaw gap at ``theta_closed``, mm.  1.5 mm: Guachi et al.'s blue staple cartridge closed
        height, the FE model's ``closed_gap_mm``.
    tube_diameter_mm : float
        Outer diameter of the clamped tube, mm (30, the FE model's ``diameter_mm``); only used
        to check that the open jaws clear it and to locate the first touch.
    spring_k_N_per_mm : float
        Return-spring rate on the rod, N/mm (eq (2)'s ``k``; not given).  Default 10 N/mm.
    spring_preload_N : float
        Return-spring force at the open position, N (holds the handle open).  Default 10 N.
        With the defaults the empty instrument needs 0.54 N at the finger to start closing and
        1.71 N at full closure: a light return force next to the 65-88 N finger force that a
        50 N grasp (the colon-damage threshold) needs (design choice, not from the paper).

    Notes
    -----
    Derived quantities (read-only properties): :attr:`m_mm` (cam arm, from ``n`` and the
    endpoints), :attr:`rod_stroke_mm`, :attr:`beta_open_deg`, :attr:`jaw_open_angle_deg`,
    :attr:`theta_touch_deg`.
    """

    L1_mm: float = 21.0
    L2_mm: float = 25.1
    L3_mm: float = 54.1
    theta_open_deg: float = 22.0
    theta_closed_deg: float = 0.0
    offset_d_mm: float = -4.0
    slider_side: str = "behind"
    n_mm: float = 35.0
    gap_open_mm: float = 32.0
    gap_closed_mm: float = 1.5
    tube_diameter_mm: float = 30.0
    spring_k_N_per_mm: float = 10.0
    spring_preload_N: float = 10.0
    _c: LinkageConstants = field(init=False, repr=False, compare=False)

    @property
    def constants(self) -> LinkageConstants:
        """Derived linkage constants (mm, rad): what the C core's tables are generated from."""
        return self._c

    def __post_init__(self) -> None:
        self._check_fields()
        self._check_ranges()
        object.__setattr__(self, "_c", _linkage_constants(self))

    def _check_fields(self) -> None:
        """Each field on its own: finite numbers, signs, the slider branch (``ValueError``)."""
        for name in (
            "L1_mm",
            "L2_mm",
            "L3_mm",
            "theta_open_deg",
            "theta_closed_deg",
            "offset_d_mm",
            "n_mm",
            "gap_open_mm",
            "gap_closed_mm",
            "tube_diameter_mm",
            "spring_k_N_per_mm",
            "spring_preload_N",
        ):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"ChainParams.{name} must be a finite number, got {v!r}")
        for name in ("L1_mm", "L2_mm", "L3_mm", "n_mm", "gap_closed_mm", "tube_diameter_mm"):
            if getattr(self, name) <= 0:
                raise ValueError(f"ChainParams.{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("spring_k_N_per_mm", "spring_preload_N"):
            if getattr(self, name) < 0:
                raise ValueError(f"ChainParams.{name} must be >= 0, got {getattr(self, name)!r}")
        if self.slider_side not in ("behind", "beyond"):
            raise ValueError(
                f"ChainParams.slider_side must be 'behind' or 'beyond', got {self.slider_side!r}"
            )

    def _check_ranges(self) -> None:
        """Fields against each other: offset, handle range, gaps and jaw arm (``ValueError``)."""
        if not abs(self.offset_d_mm) < self.L1_mm:
            raise ValueError(
                f"ChainParams.offset_d_mm must satisfy |d| < L1_mm = {self.L1_mm}, "
                f"got {self.offset_d_mm!r}"
            )
        if not self.theta_closed_deg < self.theta_open_deg:
            raise ValueError(
                f"ChainParams.theta_closed_deg ({self.theta_closed_deg}) must be < "
                f"theta_open_deg ({self.theta_open_deg})"
            )
        if self.theta_open_deg - self.theta_closed_deg >= 90.0:
            raise ValueError(
                "ChainParams: the handle range theta_open_deg - theta_closed_deg must be "
                f"< 90 deg, got {self.theta_open_deg - self.theta_closed_deg}"
            )
        if not self.gap_closed_mm < self.gap_open_mm:
            raise ValueError(
                f"ChainParams.gap_closed_mm ({self.gap_closed_mm}) must be < gap_open_mm "
                f"({self.gap_open_mm})"
            )
        if self.gap_open_mm < self.tube_diameter_mm:
            raise ValueError(
                f"ChainParams.gap_open_mm ({self.gap_open_mm}) must be >= tube_diameter_mm "
                f"({self.tube_diameter_mm}): the open jaws must clear the tube"
            )
        if not self.n_mm > self.gap_open_mm - self.gap_closed_mm:
            raise ValueError(
                f"ChainParams.n_mm ({self.n_mm}) must exceed gap_open_mm - gap_closed_mm "
                f"({self.gap_open_mm - self.gap_closed_mm}): the jaw cannot open that far"
            )

    # -- derived quantities -------------------------------------------------------------------
    @property
    def rod_stroke_mm(self) -> float:
        """Rod (slider ``C``) stroke from open to closed, mm."""
        return self._c.u_max

    @property
    def m_mm(self) -> float:
        """Cam arm ``m`` of eq (1), mm: ``n * rod_stroke / (gap_open - gap_closed)``.

        Not an independent input: with the slot cam, ``gap`` is linear in the rod stroke with
        slope ``n/m``, and the two endpoints (open gap, closed height) fix that slope.
        """
        return self.n_mm * self._c.u_max / (self.gap_open_mm - self.gap_closed_mm)

    @property
    def jaw_open_angle_deg(self) -> float:
        """Jaw rotation from closed to open, deg: ``asin((gap_open - gap_closed)/n)``."""
        return math.degrees(math.asin((self.gap_open_mm - self.gap_closed_mm) / self.n_mm))

    @property
    def beta_open_deg(self) -> float:
        """Link angle beta at ``theta_open`` from eq (3), deg (Table 1 says 19; 18.62 here)."""
        return float(beta_deg(self.theta_open_deg, self))

    @property
    def theta_touch_deg(self) -> float:
        """Handle angle at which the gap equals ``tube_diameter_mm`` (first touch), deg."""
        return float(theta_from_gap_deg(self.tube_diameter_mm, self))


# -- construction of the derived constants ---------------------------------------------------
def _linkage_constants(p: ChainParams) -> LinkageConstants:
    """Derived constants of a field-checked parameter set, after checking that the linkage
    assembles and moves monotonically over the whole handle range (``ValueError`` otherwise)."""
    d = float(p.offset_d_mm)
    h = math.sqrt(p.L1_mm**2 - d**2)
    side = -1.0 if p.slider_side == "behind" else 1.0
    th_lo = math.radians(p.theta_closed_deg)
    th_hi = math.radians(p.theta_open_deg)
    # assembly and monotonicity over the whole range (dense sampling)
    th = np.linspace(th_lo, th_hi, _N_CHECK)
    _check_assembly(p, th, d, h)
    sgn = _check_monotone(p, th, d, h, side)
    xc_closed = float(xc_mm(th_lo, p.L2_mm, d, h, side))
    xc_open = float(xc_mm(th_hi, p.L2_mm, d, h, side))
    return LinkageConstants(
        h=h,
        side=side,
        xc_closed=xc_closed,
        xc_open=xc_open,
        stroke_sign=sgn,
        u_max=abs(xc_open - xc_closed),
        gap_per_xc=(p.gap_open_mm - p.gap_closed_mm) / (xc_open - xc_closed),
        th_lo=th_lo,
        th_hi=th_hi,
    )


def _check_assembly(p: ChainParams, th: NDArray[np.float64], d: float, h: float) -> None:
    """``ValueError`` if the link cannot reach the rod axis at some sampled angle ``th`` (rad)."""
    yb = h * np.sin(th) + d * np.cos(th)
    sb = (yb - d) / p.L2_mm
    if np.max(np.abs(sb)) >= 1.0 - 1e-9:
        i = int(np.argmax(np.abs(sb)))
        raise ValueError(
            f"ChainParams: the link L2_mm = {p.L2_mm} cannot reach the rod axis at "
            f"theta = {math.degrees(th[i]):.3f} deg (|sin beta| >= 1); increase L2_mm or "
            "change offset_d_mm / L1_mm"
        )


def _check_monotone(
    p: ChainParams, th: NDArray[np.float64], d: float, h: float, side: float
) -> float:
    """Stroke sign of x_C over the sampled angles ``th`` (rad); ``ValueError`` at a dead centre."""
    xc = xc_mm(th, p.L2_mm, d, h, side)
    dxc = dxc_dtheta(th, p.L2_mm, d, h, side)[0]
    sgn = 1.0 if xc[-1] > xc[0] else -1.0
    bad = np.nonzero(dxc * sgn <= 1e-9 * p.L1_mm)[0]
    if bad.size:
        flips = np.nonzero(np.sign(dxc[:-1]) != np.sign(dxc[1:]))[0]
        i = int(flips[0]) if flips.size else int(bad[0])
        if flips.size:  # linear interpolation of the zero of dx_C/dtheta
            th_dead = th[i] - dxc[i] * (th[i + 1] - th[i]) / (dxc[i + 1] - dxc[i])
        else:
            th_dead = th[i]
        raise ValueError(
            f"ChainParams: with offset_d_mm = {d} and slider_side = {p.slider_side!r} "
            f"the linkage passes a dead centre near theta = {math.degrees(th_dead):.2f} "
            f"deg (dx_C/dtheta changes sign in [{p.theta_closed_deg}, "
            f"{p.theta_open_deg}] deg); the jaw gap would not be monotone. Choose another "
            "offset_d_mm or slider_side"
        )
    return sgn


# -- geometry kernels (radians, no validation; numpy-generic so complex step works) -----------
def xc_mm(th: Any, L2: float, d: float, h: float, side: float) -> Any:
    """x coordinate of the rod end C, mm.

    Parameters
    ----------
    th : float, ndarray or complex
        Handle angle, rad (no range check).
    L2, d, h : float
        Link length ``L2_mm``, offset ``offset_d_mm`` and ``sqrt(L1^2 - d^2)``, mm
        (:attr:`ChainParams.constants` holds ``h``).
    side : float
        -1 slider behind B (pivot side), +1 beyond.

    Returns
    -------
    float, ndarray or complex
        ``x_C``, mm.
    """
    yb = h * np.sin(th) + d * np.cos(th)
    xb = h * np.cos(th) - d * np.sin(th)
    s = (yb - d) / L2
    return xb + side * L2 * np.sqrt(1.0 - s * s)


def dxc_dtheta(th: Any, L2: float, d: float, h: float, side: float) -> tuple[Any, Any]:
    """First and second derivatives of x_C with respect to theta (rad), mm/rad, mm/rad^2.

    Parameters as :func:`xc_mm`.

    Returns
    -------
    tuple
        ``(dx_C/dtheta, d2x_C/dtheta2)`` in mm/rad and mm/rad^2.
    """
    sn, cs = np.sin(th), np.cos(th)
    yb = h * sn + d * cs
    xb = h * cs - d * sn
    s = (yb - d) / L2
    c = np.sqrt(1.0 - s * s)
    t = s / c
    d1 = -yb - side * xb * t
    d2 = -xb + side * yb * t - side * xb * xb / (L2 * c**3)
    return d1, d2


def slider_x_mm(theta_rad: Any, p: ChainParams) -> Any:
    """x_C(theta) in mm, radians in, no range check (accepts complex for complex-step tests)."""
    c = p._c
    return xc_mm(theta_rad, p.L2_mm, p.offset_d_mm, c.h, c.side)


def _linkage_state(th: Any, p: ChainParams, sin: Any, cos: Any, sqrt: Any) -> tuple[Any, ...]:
    """(x_C, dx_C, d2x_C, sin beta, cos beta) at theta (rad), with the given sin/cos/sqrt."""
    c = p._c
    L2, d, h, side = p.L2_mm, p.offset_d_mm, c.h, c.side
    sn, cs = sin(th), cos(th)
    yb = h * sn + d * cs
    xb = h * cs - d * sn
    s = (yb - d) / L2
    cb = sqrt(1.0 - s * s)
    tb = s / cb
    xc = xb + side * L2 * cb
    d1 = -yb - side * xb * tb
    d2 = -xb + side * yb * tb - side * xb * xb / (L2 * cb**3)
    return xc, d1, d2, s, cb


def _scalar_state(t: float, p: ChainParams) -> tuple[float, float, float, float, float]:
    """Scalar fast path (``math``): (x_C, dx_C, d2x_C, sin beta, cos beta) at theta t (rad)."""
    return _linkage_state(t, p, math.sin, math.cos, math.sqrt)


def linkage_state(th: NDArray[np.float64], p: ChainParams) -> tuple[Any, ...]:
    """Linkage state at handle angles ``th`` (rad, no range check), vectorised.

    Returns
    -------
    tuple of ndarray
        ``(x_C, dx_C/dtheta, d2x_C/dtheta2, sin beta, cos beta)``: slider position (mm) and
        its derivatives (mm/rad, mm/rad^2), and the rod angle.
    """
    return _linkage_state(th, p, np.sin, np.cos, np.sqrt)


def _is_scalar(x: object) -> bool:
    return isinstance(x, (float, int)) and not isinstance(x, bool)


def _theta_rad(theta_deg: ArrayLike, p: ChainParams) -> float | NDArray[np.float64]:
    """Validate theta (deg) against the range and return radians (clipped to the exact ends)."""
    lo, hi = p.theta_closed_deg, p.theta_open_deg
    if _is_scalar(theta_deg):
        t = float(theta_deg)  # type: ignore[arg-type]
        if not (lo - _THETA_TOL_DEG <= t <= hi + _THETA_TOL_DEG):
            raise ValueError(
                f"theta_deg = {t!r} is outside the chain's range [{lo}, {hi}] deg "
                f"({hi} open, {lo} closed)"
            )
        return math.radians(min(max(t, lo), hi))
    a = np.asarray(theta_deg, dtype=float)
    ok = (a >= lo - _THETA_TOL_DEG) & (a <= hi + _THETA_TOL_DEG)
    if not np.all(ok):
        idx = np.unravel_index(int(np.argmin(ok)), a.shape) if a.ndim else ()
        bad = a[idx]
        where = f" at index {tuple(int(i) for i in idx)}" if a.ndim else ""
        raise ValueError(
            f"theta_deg = {float(bad)!r}{where} is outside the chain's range [{lo}, {hi}] deg "
            f"({hi} open, {lo} closed)"
        )
    return np.radians(np.clip(a, lo, hi))


def _state(theta_deg: ArrayLike, p: ChainParams) -> tuple[tuple[Any, ...], Any]:
    t = _theta_rad(theta_deg, p)
    if isinstance(t, float):
        return _scalar_state(t, p), t
    return linkage_state(t, p), t


def _out(x: FloatOrArray) -> FloatOrArray:
    return float(x) if np.ndim(x) == 0 else x


# -- public API ---------------------------------------------------------------------------------
def theta_range_deg(p: ChainParams) -> tuple[float, float]:
    """Handle-angle range ``(theta_closed, theta_open)`` in deg (default ``(0.0, 22.0)``).

    Parameters
    ----------
    p : ChainParams
        Chain parameters.

    Returns
    -------
    tuple of float
        ``(closed, open)``, deg.  Closing is ``theta`` decreasing from ``open`` to ``closed``.
    """
    return (float(p.theta_closed_deg), float(p.theta_open_deg))


def gap_mm(theta_deg: ArrayLike, p: ChainParams) -> FloatOrArray:
    """Jaw gap at the tissue reference point, mm, for handle angle ``theta_deg`` (deg).

    ``gap_open_mm`` at ``theta_open``, exactly ``gap_closed_mm`` at ``theta_closed``, strictly
    increasing in between.  Raises ``ValueError`` if ``theta_deg`` is outside
    :func:`theta_range_deg`.
    """
    (xc, *_), _ = _state(theta_deg, p)
    return _out(p.gap_closed_mm + p._c.gap_per_xc * (xc - p._c.xc_closed))


def dgap_dtheta_mm_per_rad(theta_deg: ArrayLike, p: ChainParams) -> FloatOrArray:
    """Derivative of the gap with respect to the handle angle, mm/rad (> 0).

    ``theta_deg`` in deg, the derivative per radian.  Analytic (checked against the complex-step
    derivative of the linkage positions in the tests).
    """
    (_, d1, *_), _ = _state(theta_deg, p)
    return _out(p._c.gap_per_xc * d1)


def d2gap_dtheta2_mm_per_rad2(theta_deg: ArrayLike, p: ChainParams) -> FloatOrArray:
    """Second derivative of the gap with respect to the handle angle, mm/rad^2."""
    (_, _, d2, *_), _ = _state(theta_deg, p)
    return _out(p._c.gap_per_xc * d2)


def theta_from_gap_deg(gap_mm: ArrayLike, p: ChainParams) -> FloatOrArray:
    """Inverse of :func:`gap_mm`: handle angle (deg) at which the jaw gap is ``gap_mm`` (mm).

    Safeguarded Newton iteration (bracketed, falls back to bisection), converged to 1e-12 mm;
    about 6 us for a Python float.  Raises ``ValueError`` naming ``gap_mm`` if the gap is
    outside ``[gap_closed_mm, gap_open_mm]`` (or NaN).
    """
    g_lo, g_hi = p.gap_closed_mm, p.gap_open_mm
    tol = 1e-9 * g_hi
    if _is_scalar(gap_mm):
        gs = float(gap_mm)  # type: ignore[arg-type]
        if not (g_lo - tol <= gs <= g_hi + tol):
            raise ValueError(f"gap_mm = {gs!r} is outside the chain's range [{g_lo}, {g_hi}] mm")
        return _theta_from_gap_scalar(min(max(gs, g_lo), g_hi), p)
    g = np.atleast_1d(np.asarray(gap_mm, dtype=float))
    ok = (g >= g_lo - tol) & (g <= g_hi + tol)
    if not np.all(ok):
        bad = float(g.ravel()[int(np.argmin(ok.ravel()))])
        raise ValueError(f"gap_mm = {bad!r} is outside the chain's range [{g_lo}, {g_hi}] mm")
    g = np.clip(g, g_lo, g_hi)
    c = p._c
    target = c.xc_closed + (g - g_lo) / c.gap_per_xc  # solve x_C(theta) = target
    lo = np.full_like(g, c.th_lo)
    hi = np.full_like(g, c.th_hi)
    t = c.th_lo + (g - g_lo) / (g_hi - g_lo) * (c.th_hi - c.th_lo)
    xtol = 1e-12 / abs(c.gap_per_xc)
    for _ in range(100):
        xc = xc_mm(t, p.L2_mm, p.offset_d_mm, c.h, c.side)
        d1 = dxc_dtheta(t, p.L2_mm, p.offset_d_mm, c.h, c.side)[0]
        r = (xc - target) * c.stroke_sign  # increasing in t
        if np.all(np.abs(r) <= xtol):
            break
        lo = np.where(r < 0, t, lo)
        hi = np.where(r > 0, t, hi)
        tn = t - (xc - target) / d1
        inside = (tn > lo) & (tn < hi)
        t = np.where(np.abs(r) <= xtol, t, np.where(inside, tn, 0.5 * (lo + hi)))
    res = np.degrees(t)
    if np.ndim(gap_mm) == 0:
        return float(res[0])
    return res.reshape(np.shape(gap_mm))


def _theta_from_gap_scalar(g: float, p: ChainParams) -> float:
    """Scalar fast path of :func:`theta_from_gap_deg` (g already inside the range)."""
    c = p._c
    target = c.xc_closed + (g - p.gap_closed_mm) / c.gap_per_xc
    lo, hi = c.th_lo, c.th_hi
    t = lo + (g - p.gap_closed_mm) / (p.gap_open_mm - p.gap_closed_mm) * (hi - lo)
    xtol = 1e-12 / abs(c.gap_per_xc)
    for _ in range(100):
        xc, d1, _d2, _s, _cb = _scalar_state(t, p)
        r = (xc - target) * c.stroke_sign
        if abs(r) <= xtol:
            break
        if r < 0:
            lo = t
        else:
            hi = t
        tn = t - (xc - target) / d1
        t = tn if lo < tn < hi else 0.5 * (lo + hi)
    return math.degrees(t)


def beta_deg(theta_deg: ArrayLike, p: ChainParams) -> FloatOrArray:
    """Link angle beta to the rod axis, deg, from Guachi et al. (2020) eq (3) (also the geometry's
    angle)."""
    t = _theta_rad(theta_deg, p)
    d, L1, L2 = p.offset_d_mm, p.L1_mm, p.L2_mm
    if isinstance(t, float):
        return math.degrees(
            math.asin((d * math.cos(t) + math.sin(t) * math.sqrt(L1 * L1 - d * d) - d) / L2)
        )
    return np.degrees(np.arcsin((d * np.cos(t) + np.sin(t) * np.sqrt(L1 * L1 - d * d) - d) / L2))


class LinkagePoints(NamedTuple):
    """Positions of the linkage points, mm (pivot ``O`` at the origin, rod axis ``y = d``)."""

    bx: FloatOrArray
    by: FloatOrArray
    cx: FloatOrArray
    cy: FloatOrArray


def linkage_points_mm(theta_deg: ArrayLike, p: ChainParams) -> LinkagePoints:
    """Crank tip ``B`` and rod end ``C`` positions, mm, at handle angle ``theta_deg`` (deg)."""
    t = np.asarray(_theta_rad(theta_deg, p))
    h, d = p._c.h, p.offset_d_mm
    bx = h * np.cos(t) - d * np.sin(t)
    by = h * np.sin(t) + d * np.cos(t)
    cx = xc_mm(t, p.L2_mm, d, h, p._c.side)
    cy = np.full_like(cx, d)
    return LinkagePoints(_out(bx), _out(by), _out(cx), _out(cy))


def spring_dx_mm(theta_deg: ArrayLike, p: ChainParams) -> FloatOrArray:
    """Rod stroke ``u = |x_C(theta) - x_C(theta_open)|``, mm: Guachi et al.'s Delta x (0 when
    open)."""
    (xc, *_), _ = _state(theta_deg, p)
    return _out((p._c.xc_open - xc) * p._c.stroke_sign)


def spring_force_N(theta_deg: ArrayLike, p: ChainParams) -> FloatOrArray:
    """Return-spring force on the rod, N: ``preload + k * u`` (resists closing)."""
    return _out(p.spring_preload_N + p.spring_k_N_per_mm * spring_dx_mm(theta_deg, p))


def spring_energy_Nmm(theta_deg: ArrayLike, p: ChainParams) -> FloatOrArray:
    """Energy stored in the return spring since the open position, N mm (= mJ)."""
    u = spring_dx_mm(theta_deg, p)
    return _out(p.spring_preload_N * u + 0.5 * p.spring_k_N_per_mm * u * u)


def _spring_terms(theta_deg: ArrayLike, p: ChainParams) -> tuple[Any, ...]:
    """(g', F_s, u', u'', x_C) with g' mm/rad, F_s N, u' mm/rad, u'' mm/rad^2."""
    (xc, d1, d2, _s, _c), _ = _state(theta_deg, p)
    c = p._c
    u = (c.xc_open - xc) * c.stroke_sign
    fs = p.spring_preload_N + p.spring_k_N_per_mm * u
    du = -d1 * c.stroke_sign
    ddu = -d2 * c.stroke_sign
    return c.gap_per_xc * d1, fs, du, ddu, c.gap_per_xc * d2


def spring_handle_force_N(theta_deg: ArrayLike, p: ChainParams) -> FloatOrArray:
    """Finger force that balances the return spring alone (no tissue), N (> 0 with preload)."""
    _g1, fs, du, _ddu, _g2 = _spring_terms(theta_deg, p)
    return _out(-fs * du / p.L3_mm)


def handle_force_N(jaw_force_N: ArrayLike, theta_deg: ArrayLike, p: ChainParams) -> FloatOrArray:
    """Finger force ``Fi`` (N) needed to hold jaw force ``Fg`` (N) at ``theta_deg`` (deg).

    Virtual work of the frictionless chain: ``Fi = (Fg g' - F_s u') / L3`` with ``g'`` the gap
    slope (mm/rad), ``F_s`` the spring force (N) and ``u' < 0`` the rod-stroke slope (mm/rad);
    includes the return spring (``Fi = spring_handle_force_N`` at ``Fg = 0``).
    """
    g1, fs, du, _ddu, _g2 = _spring_terms(theta_deg, p)
    return _out((np.asarray(jaw_force_N, dtype=float) * g1 - fs * du) / p.L3_mm)


def jaw_force_N(handle_force_N: ArrayLike, theta_deg: ArrayLike, p: ChainParams) -> FloatOrArray:
    """Jaw force ``Fg`` (N, on one jaw) produced by finger force ``Fi`` (N) at ``theta_deg``.

    Inverse of :func:`handle_force_N`: ``Fg = (Fi L3 + F_s u') / g'``.  Negative when ``Fi`` does
    not overcome the return spring (the jaws would not press on anything).
    """
    g1, fs, du, _ddu, _g2 = _spring_terms(theta_deg, p)
    return _out((np.asarray(handle_force_N, dtype=float) * p.L3_mm + fs * du) / g1)


def transmission_ratio(theta_deg: ArrayLike, p: ChainParams) -> FloatOrArray:
    """Incremental force ratio ``dFg/dFi = L3 / g'`` of the derived chain (spring excluded), 1."""
    return _out(p.L3_mm / dgap_dtheta_mm_per_rad(theta_deg, p))


def dhandle_force_dtheta_N_per_rad(
    jaw_force_N: ArrayLike,
    jaw_stiffness_N_per_mm: ArrayLike,
    theta_deg: ArrayLike,
    p: ChainParams,
) -> FloatOrArray:
    """Slope of the finger force along the handle angle, N/rad, for the linearised tissue.

    Parameters
    ----------
    jaw_force_N : array_like
        Tissue force on one jaw at the current gap, N.
    jaw_stiffness_N_per_mm : array_like
        ``-dFg/dgap`` of the tissue at the current gap, N/mm (>= 0 for a tissue that pushes
        harder as the jaws close).
    theta_deg : array_like
        Handle angle, deg.
    p : ChainParams
        Chain parameters.

    Returns
    -------
    float or ndarray
        ``dFi/dtheta`` in N/rad: ``(-K g'^2 + Fg g'' - k u'^2 - F_s u'') / L3``; negative (the
        finger force grows as ``theta`` decreases).  The handle stiffness felt when closing is
        ``-dFi/dtheta / L3`` in N/mm of finger travel.
    """
    g1, fs, du, ddu, g2 = _spring_terms(theta_deg, p)
    fg = np.asarray(jaw_force_N, dtype=float)
    kt = np.asarray(jaw_stiffness_N_per_mm, dtype=float)
    return _out((-kt * g1 * g1 + fg * g2 - p.spring_k_N_per_mm * du * du - fs * ddu) / p.L3_mm)


def seed_transmission_ratio(theta_deg: ArrayLike, p: ChainParams) -> FloatOrArray:
    """Guachi et al.'s ``Fg/Fi`` from eqs (1)-(4), spring excluded: ``L3/L1 cos(theta/2) cos(beta)
    m/n``.

    For comparison only: it does not conserve energy (see the module docstring).
    """
    (_xc_, _d1, _d2, _s, cb), t = _state(theta_deg, p)
    cos_phi = math.cos(t / 2) if isinstance(t, float) else np.cos(t / 2)
    return _out(p.L3_mm / p.L1_mm * cos_phi * cb * p.m_mm / p.n_mm)


def seed_jaw_force_N(
    handle_force_N: ArrayLike, theta_deg: ArrayLike, p: ChainParams
) -> FloatOrArray:
    """Jaw force from Guachi et al. (2020) eqs (1)-(4) as printed, N.

    ``Fg = (Fi L3/L1 cos(phi) cos(beta) - k Delta x) m/n`` with ``phi = theta/2``, beta from
    eq (3), ``Delta x`` = :func:`spring_dx_mm`, and this chain's ``m``, ``n`` and ``k`` (the
    printed formula has no spring preload).  Not energy-consistent; use :func:`jaw_force_N`.
    """
    ratio = seed_transmission_ratio(theta_deg, p)
    spring = p.spring_k_N_per_mm * spring_dx_mm(theta_deg, p) * p.m_mm / p.n_mm
    return _out(np.asarray(handle_force_N, dtype=float) * ratio - spring)


def seed_comparison(p: ChainParams) -> dict[str, dict[str, float]]:
    """Why Guachi et al.'s ``Fg/Fi`` sits several times below the derived chain, at both end stops.

    Eq (2) takes the rod force as the crank-tip force ``Fi L3 / L1`` projected with
    ``cos(phi) cos(beta)``.  Virtual work gives the rod force ``Fi L3 / |u'|`` with ``|u'|`` the
    rod travel per radian of handle, ``|u'| = L1 sin(mu) / cos(beta)`` (``mu`` the angle between
    crank and link).  The crank and the link stay nearly in line, so the rod moves only a few
    mm per radian instead of ``L1``, and ``derived / seed = 1 / (sin(mu) cos(phi))``.  Not a
    bug of either curve: the printed formula does not conserve energy (module docstring).

    Parameters
    ----------
    p : ChainParams

    Returns
    -------
    dict
        ``{"open": {...}, "closed": {...}}`` at ``theta_open_deg`` and ``theta_closed_deg``,
        each with ``theta_deg``, ``derived_pct`` and ``seed_pct`` (``Fg/Fi`` in %, spring
        excluded), ``derived_over_seed`` (1), ``rod_mm_per_rad`` (``|u'|``, mm/rad),
        ``crank_mm`` (``L1``, mm) and ``mu_deg`` (crank-link angle, deg).
    """
    out = {}
    for key, th in (("open", p.theta_open_deg), ("closed", p.theta_closed_deg)):
        _g1, _fs, du, _ddu, _g2 = _spring_terms(float(th), p)
        derived = float(transmission_ratio(th, p))
        seed = float(seed_transmission_ratio(th, p))
        rod = abs(float(du))
        cos_b = math.cos(math.radians(float(beta_deg(th, p))))
        out[key] = {"theta_deg": float(th), "derived_pct": 100.0 * derived,
                    "seed_pct": 100.0 * seed, "derived_over_seed": derived / seed,
                    "rod_mm_per_rad": rod, "crank_mm": p.L1_mm,
                    "mu_deg": math.degrees(math.asin(rod * cos_b / p.L1_mm))}  # fmt: skip
    return out


def _seed_note(p: ChainParams) -> str:
    """Two-line note of the transmission figure: why the paper curve sits below (numbers)."""
    c = seed_comparison(p)
    o, k = c["open"], c["closed"]
    return (
        f"eq (2) moves the rod by L1 = {o['crank_mm']:g} mm per rad; the linkage moves it "
        f"{o['rod_mm_per_rad']:.2f}-{k['rod_mm_per_rad']:.2f} mm/rad\n"
        f"(crank-link angle {o['mu_deg']:.1f}-{k['mu_deg']:.1f} deg): printed formula "
        f"{o['derived_over_seed']:.1f}x (open) to {k['derived_over_seed']:.1f}x (closed) below"
    )


def plot_transmission(p: ChainParams, path: str | Path, n: int = 221) -> Path:
    """Plot ``Fg/Fi`` (percent) vs ``theta`` (deg), derived chain and paper's formula (Fig. 6).

    Parameters
    ----------
    p : ChainParams
        Chain parameters.
    path : str or Path
        Output PNG file (parent directories are created).
    n : int
        Number of theta samples.

    Returns
    -------
    Path
        The written file.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    lo, hi = theta_range_deg(p)
    th = np.linspace(lo, hi, n)
    derived = 100.0 * np.asarray(transmission_ratio(th, p))
    seed = 100.0 * np.asarray(seed_transmission_ratio(th, p))
    fig = Figure(figsize=(6.4, 4.2))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(th, derived, "C0-", lw=2, label="derived chain (virtual work), $L_3/g'(\\theta)$")
    ax.plot(th, seed, "C3--", lw=2, label="Guachi et al. (2020) eqs (1)-(4) as printed, same m/n")
    ax.axvline(p.theta_touch_deg, color="0.6", lw=1, ls=":")
    ax.text(
        p.theta_touch_deg - 0.2,
        0.5 * float(np.max(derived)),
        "first touch\n(gap = tube diameter)",
        color="0.4",
        fontsize=8,
        ha="right",
    )
    ax.text(0.98, 0.17, _seed_note(p), transform=ax.transAxes, fontsize=7, ha="right",
            va="bottom", color="C3")  # fmt: skip
    ax.set_xlabel(r"handle angle $\theta$ (deg)  (closed 0 $\rightarrow$ open)")
    ax.set_ylabel(r"$F_g / F_i$ (%)")
    ax.set_title("Force transmission handle -> jaw (spring excluded)")
    ax.set_xlim(lo, hi)
    ax.set_ylim(0, None)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="center left")
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    return out
