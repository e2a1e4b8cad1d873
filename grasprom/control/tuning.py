r"""Tuning of the impedance controller for passivity (python-control): :func:`tune`.

The tuner picks the virtual damping ``B`` and velocity cutoff that maximise the passive
stiffness of the device (:mod:`~grasprom.control.passivity`), then, for the coupling
rendering, the largest coupling stiffness ``k_c`` whose rendered stiffness
(:mod:`~grasprom.control.stiffness`) stays below it over theta x thickness x material, or, for
the clipped rendering (``rendering = "clipped"``), the stiffness limit ``K_lim`` itself
(:func:`clipped_limit`: the passive stiffness with the safety factor, the Prony instantaneous
factor taken off, 2 significant digits rounded down).  The clipped field bounds its node-to-node
slopes by ``K_lim`` but renders more than that: inside a node interval the chain's curvature
(~0.04 % above ``K_lim`` at the closed end), and the return spring's own slope wherever the limit
is below it (the field then renders the spring alone).  So the limit is confirmed against every
slope the fields of all cases render (:func:`~grasprom.control.stiffness.field_stiffness_extremes`
on every node interval), lowered if the chain's curvature breaks the margin, and :func:`tune`
raises when the spring alone is not passive (no limit is: a lower one renders more of the
spring alone); ``b > K T/2 + |B|`` in its delay-aware form then holds at every angle.  The
report tells the truth about the choice: closed-loop damping ratio and phase margin with the
hand at every operating point against a stated target (:mod:`~grasprom.control.margins`), the
transparency table per case with the damping / rate that would render the tissue exactly up
to 20 N (:mod:`~grasprom.control.transparency`), and an energy check released 0.5 deg above
the hold (:func:`~grasprom.control.verification.verify_by_simulation`).  It reports the choice
(:mod:`~grasprom.control.summary`, closed-loop poles from :mod:`~grasprom.control.loop`, the
time-domain check of :mod:`~grasprom.control.verification`).  The models of device and hand are in
:mod:`~grasprom.control.device`; the report text in :mod:`~grasprom.control.report`, the plots in
:mod:`~grasprom.control.plots` and the files in :mod:`~grasprom.control.outputs`.

Rendered instrument effects (``ControllerParams`` fields set from a ``grasprom diagnose``
augmented model, :func:`grasprom.gap.controller_params_from_augmented`)
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

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np

from grasprom.control.device import DeviceParams, HandParams
from grasprom.control.field import prony_factor
from grasprom.control.margins import ZETA_TARGET, damping_needed, operating_margins
from grasprom.control.params import ControllerParams
from grasprom.control.passivity import best_filter, required_damping
from grasprom.control.report import format_report, jsonable
from grasprom.control.stiffness import (
    FieldStiffness,
    OperatingPoints,
    clipped_stiffness_bound_Nm_per_rad,
    field_stiffness_extremes,
    operating_cases,
    operating_points,
    prony_stiffness_factor,
    stiffest_point,
    virtual_damping_Nms_per_rad,
)
from grasprom.control.summary import augmentation_summary, renders_instrument_effects, summarise
from grasprom.control.transparency import (
    PLOT_CASES,
    RATE_GRID_HZ,
    force_curves,
    passive_stiffness_at_rates,
    transparency_table,
)
from grasprom.control.verification import verify_by_simulation
from grasprom.fe import MATERIAL_NAMES
from grasprom.surrogate import Surrogate

__all__ = ["TuningResult", "clipped_limit", "tune"]


@dataclass
class TuningResult:
    """Result of :func:`tune` (see :meth:`to_dict` for the JSON form)."""

    params: ControllerParams
    device: DeviceParams
    hand: HandParams
    points: list[OperatingPoints]
    summary: dict[str, Any] = field(default_factory=dict)
    curves: list[dict[str, Any]] = field(default_factory=list)
    """Quasi-static force curves of a few cases for the transparency figure: ``material``,
    ``thickness_mm``, ``gap_mm``, ``force_tissue_N``, ``force_rendered_N`` (arrays)."""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready tuning report."""
        return jsonable(self.summary)

    def report(self) -> str:
        """Human-readable text report."""
        return format_report(self.summary)


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
    return best_filter(b, T, delay, safety, cutoffs, n_B, B_min)


def _round_down(x: float, digits: int = 2) -> float:
    """``x`` rounded down to ``digits`` significant digits (0 for ``x <= 0``)."""
    if x <= 0:
        return 0.0
    e = math.floor(math.log10(x)) - digits + 1
    return math.floor(x / 10**e) * 10**e


# the numpydoc docstring (the tuning procedure) is most of its length; the body is ~25 lines
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
    zeta_target: float = ZETA_TARGET,
) -> TuningResult:
    """Choose ``B``, the velocity cutoff and ``k_c`` (coupling) or ``K_lim`` (clipped).

    1. ``(B, f_c)`` maximise the passive stiffness ``K_pass`` of the device with damping
       ``b / safety`` (delay-aware Colgate-Schenkel condition).
    2. Coupling rendering (``base.rendering``): ``k_c`` is the largest (2 significant
       digits, rounded down) for which the largest rendered stiffness over theta x thickness
       x material stays ``<= K_pass``, i.e. the passivity margin ``b / b_required >= safety``
       at every operating point.  Clipped rendering: ``K_lim`` = :func:`clipped_limit` of
       ``K_pass`` (the Prony instantaneous factor taken off), confirmed against every slope
       the fields render over thickness x material (the tissue's where the field follows
       it, ``K_lim`` and the chain's curvature inside a node interval where it climbs at the
       bound, the return spring's where it renders the spring alone) and lowered (2
       significant digits) until ``b / b_required >= safety`` for all of them.

    Rendered instrument effects in ``base`` (tissue scale, jaw compliance, Prony series,
    friction; see the module docstring) are kept and accounted for: ``K`` uses the scaled tissue,
    ``k_c,eff`` and the Prony factor; the viscous friction counts as virtual damping (``B`` is
    chosen for the total, the friction's share taken off); Coulomb friction and backlash are not
    credited.
    3. Report: raw tissue (no coupling) stiffness and where it is not renderable, with the
       sample rate / damping it would need; Abbott-Okamura and Colgate closed-form figures;
       closed-loop poles and margins (python-control) at the stiffest point, with and without
       the hand, and damping ratio / phase margin with the hand at every operating point
       against ``zeta_target``; the transparency table per case
       (:mod:`~grasprom.control.transparency`).

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
        Materials (default: all of the surrogate).  The result's operating point (material,
        thickness) is ``base``'s, or :func:`covered_operating_point` when the surrogate does
        not hold ``base.material`` (a sweep of other materials).
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
    zeta_target : float
        Target closed-loop damping ratio with the hand (reported per operating point,
        :mod:`~grasprom.control.margins`).

    Returns
    -------
    TuningResult

    Raises
    ------
    ValueError
        Bad arguments, a rendered viscous friction that leaves no passive stiffness, or a
        return spring the device cannot render passively (no coupling stiffness / no
        stiffness limit is passive).
    """
    base = base or ControllerParams()
    device = device or DeviceParams()
    hand = hand or HandParams()
    cutoffs = _candidate_cutoffs(s, base, safety, materials, cutoffs_Hz)
    base = covered_operating_point(s, base, materials)
    ch = _choose_damping(base, device, safety, cutoffs)
    # B is the total virtual damping; the controller's share is what the friction leaves
    base = replace(
        base,
        damping_Nms_per_rad=ch.B - ch.B_visc if ch.B > ch.B_visc else 0.0,
        velocity_cutoff_Hz=ch.fc,
        torque_limit_Nm=min(base.torque_limit_Nm, device.torque_limit_Nm),
    )
    search = None
    if base.rendering == "clipped":
        k_lim = _passive_clipped_limit(s, base, thicknesses, materials, device, safety, ch)
        params = replace(base, stiffness_limit_Nm_per_rad=k_lim)
    else:
        search = _CouplingSearch(s, base, thicknesses, materials, n_theta, device, safety, ch)
        params = replace(base, coupling_stiffness_N_per_mm=search.largest_passive_coupling())
    pts = operating_points(s, params, thicknesses, materials, n_theta)
    summary = summarise(s, params, device, hand, pts, safety, ch.k_pass)
    if search is not None:
        summary["input_coupling"] = search.input_coupling()
    if renders_instrument_effects(params):
        summary["augmentation"] = augmentation_summary(params, ch.B_visc)
    summary.update(_truth(s, params, device, hand, pts, ch, (safety, cutoffs, zeta_target)))
    if verify:
        summary["simulation"] = verify_by_simulation(s, params, device, hand, summary, points=pts)
    return TuningResult(params=params, device=device, hand=hand, points=pts, summary=summary,
                        curves=_curves(s, params, pts))  # fmt: skip


def _curves(s: Surrogate, params: ControllerParams, pts: list[OperatingPoints]) -> list[dict]:
    """Force curves of the :data:`~grasprom.control.transparency.PLOT_CASES` present in
    ``pts`` (else the thinnest and thickest case of the first material)."""
    have = [(o.material, o.thickness_mm) for o in pts]
    cases = [c for c in PLOT_CASES if any(c[0] == m and abs(c[1] - t) < 1e-9 for m, t in have)]
    if not cases:
        first = [c for c in have if c[0] == have[0][0]]
        cases = sorted({first[0], first[-1]})
    out = []
    for m, t in cases:
        g, ft, fr = force_curves(s, replace(params, material=m, thickness_mm=t))
        out.append({"material": m, "thickness_mm": t, "gap_mm": g, "force_tissue_N": ft,
                    "force_rendered_N": fr})  # fmt: skip
    return out


def clipped_limit(params: ControllerParams, k_pass: float) -> float:
    """``K_lim`` (N m/rad) of the clipped rendering for the passive stiffness ``k_pass``.

    The field bounds its slopes by ``K_lim / (1 + sum g_i)`` and the Prony series multiplies
    the jaw part by up to :func:`~grasprom.control.stiffness.prony_stiffness_factor` ``P``, so
    ``K_lim = k_pass (1 + sum g_i) / P``, rounded down to 2 significant digits (``k_pass``
    without Prony terms).

    Parameters
    ----------
    params : ControllerParams
        Prony terms and sample time.
    k_pass : float
        Passive stiffness with the safety margin, N m/rad.

    Returns
    -------
    float
    """
    return _round_down(k_pass * prony_factor(params.prony_g) / prony_stiffness_factor(params), 2)


_LIMIT_TRIES = 12
"""Largest number of ``K_lim`` values :func:`_passive_clipped_limit` tries (each lower)."""


def _passive_clipped_limit(
    s: Surrogate,
    base: ControllerParams,
    thicknesses: Sequence[float] | None,
    materials: Sequence[str] | None,
    device: DeviceParams,
    safety: float,
    ch: _DampingChoice,
) -> float:
    """Step 2 of :func:`tune` for the clipped rendering: ``K_lim`` (N m/rad) passive everywhere.

    Starts at :func:`clipped_limit` of ``ch.k_pass`` and checks the largest and smallest slope
    of the field of every case (:func:`~grasprom.control.stiffness.field_stiffness_extremes`,
    the field at ``K_lim`` itself: with the passivity observer on the controller renders a
    stiffer field and relies on the observer) against ``b / safety``; a ``K_lim`` that fails
    through the chain's curvature is lowered by the ratio of the passive stiffness to the
    largest slope, rounded down to 2 significant digits (at least one unit of the second).

    Raises
    ------
    ValueError
        The largest slope is where the field renders the return spring alone (a lower limit
        cannot soften it), or no ``K_lim`` of :data:`_LIMIT_TRIES` passes.
    """
    T, d, b = base.sample_time_s, device.delay_samples, device.damping_Nms_per_rad
    cases = operating_cases(s, replace(base, passivity_observer=False), thicknesses, materials)
    k_next = clipped_limit(base, ch.k_pass)
    for _ in range(_LIMIT_TRIES):
        k = k_next
        worst: tuple[float, FieldStiffness, ControllerParams] | None = None
        for p in cases:
            e = field_stiffness_extremes(s, replace(p, stiffness_limit_Nm_per_rad=k))
            kk = np.array([e.K_max_Nm_per_rad, e.K_min_Nm_per_rad])
            req = max(float(required_damping(kk, ch.B, T, ch.fc, d).max()), 0.0)
            if worst is None or req > worst[0]:
                worst = (req, e, p)
        assert worst is not None
        req, e, p = worst
        if req <= b / safety:
            return k
        if e.spring_alone:
            raise ValueError(
                f"no stiffness limit is passive: the clipped field renders the return spring "
                f"alone at {p.material} {p.thickness_mm:g} mm, theta = {e.theta_max_deg:.2f} deg, "
                f"with its slope {e.K_max_Nm_per_rad:.3g} N m/rad, which needs b >= "
                f"{req * safety:.3g} N m s/rad ({req:.3g} without the safety {safety:g}; virtual "
                f"damping {ch.B:.3g} N m s/rad incl. {ch.B_visc:.3g} of viscous friction), the "
                f"device has {b:g}; a lower K_lim renders more of the spring alone, not less: "
                "raise the device damping or the rate, or leave the spring out of the rendering "
                "(render_spring = false)"
            )
        # scaled to the passive stiffness; at least one unit of the 2nd significant digit lower
        k_next = _round_down(k * min(ch.k_pass / e.K_max_Nm_per_rad, 0.999), 2)
    raise ValueError(
        f"no stiffness limit is passive: down to K_lim = {k:.3g} N m/rad the clipped field of "
        f"{p.material} {p.thickness_mm:g} mm renders slopes {e.K_min_Nm_per_rad:.3g} .. "
        f"{e.K_max_Nm_per_rad:.3g} N m/rad, which need b >= {req * safety:.3g} N m s/rad (safety "
        f"{safety:g}), the device has {b:g}"
    )


def _truth(
    s: Surrogate,
    params: ControllerParams,
    device: DeviceParams,
    hand: HandParams,
    pts: list[OperatingPoints],
    ch: _DampingChoice,
    opts: tuple[float, list[float], float],
) -> dict[str, Any]:
    """The ``rendering``, ``operating_margins`` and ``transparency`` entries of the summary.

    ``opts`` is ``(safety, candidate cutoffs Hz, target damping ratio)``.
    """
    safety, cutoffs, zeta_target = opts
    T, L3 = params.sample_time_s, params.chain_params.L3_mm
    B = virtual_damping_Nms_per_rad(params)
    om = operating_margins(pts, B, ch.fc, T, device, hand, L3, zeta_target)
    kmax = max(float(np.max(o.K_Nm_per_rad)) for o in pts)
    om["b_for_target_at_K_max_Nms_per_rad"] = damping_needed(
        kmax, B, ch.fc, T, device, hand, L3, zeta_target
    )
    rates = passive_stiffness_at_rates(device, safety, cutoffs, B_min=ch.B_visc)
    rendering = {"scheme": params.rendering}
    if params.rendering == "clipped":
        rendering.update(
            stiffness_limit_Nm_per_rad=params.stiffness_limit_Nm_per_rad,
            stiffness_bound_Nm_per_rad=clipped_stiffness_bound_Nm_per_rad(params),
            grip_stiffness_limit_N_per_rad=params.stiffness_limit_Nm_per_rad
            / (L3 * 1e-3)
            / prony_factor(params.prony_g),
        )
    else:
        rendering["coupling_stiffness_N_per_mm"] = params.coupling_stiffness_N_per_mm
    return {
        "rendering": rendering,
        "operating_margins": om,
        "transparency": transparency_table(
            s, params, pts, device, ch.k_pass, (RATE_GRID_HZ, rates)
        ),
    }


class _DampingChoice(NamedTuple):
    B: float  # total virtual damping, N m s/rad (friction's share included)
    fc: float  # velocity cutoff, Hz
    k_pass: float  # passive stiffness with the safety margin, N m/rad
    B_visc: float  # virtual damping of the rendered viscous friction, N m s/rad


def _choose_damping(
    base: ControllerParams, device: DeviceParams, safety: float, cutoffs: list[float]
) -> _DampingChoice:
    """Step 1 of :func:`tune`: ``(B, f_c)`` maximising the passive stiffness, ``B >= B_visc``."""
    T = base.sample_time_s
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
    return _DampingChoice(B, fc, k_pass, B_visc)


def covered_operating_point(
    s: Surrogate, base: ControllerParams, materials: Sequence[str] | None = None
) -> ControllerParams:
    """``base``, or, when the surrogate does not hold ``base.material``, ``base`` at the first
    tuned material (``materials[0]``, else the first of :data:`grasprom.fe.MATERIAL_NAMES` the
    surrogate holds) with its thickness (mm) clamped into that material's range.

    So that the tuned parameters (``controller.json``) are an operating point the surrogate
    and the exports of it cover (e.g. the default ``mr`` on a sweep of ``nh`` only).

    Parameters
    ----------
    s : Surrogate
    base : ControllerParams
    materials : sequence of str, optional
        The materials being tuned.

    Returns
    -------
    ControllerParams
    """
    if base.material in s.materials:
        return base
    mats = list(materials or ()) or [m for m in MATERIAL_NAMES if m in s.materials]
    m = mats[0] if mats else s.materials[0]
    lo, hi = s.thickness_range(m)
    return replace(base, material=m, thickness_mm=min(max(base.thickness_mm, lo), hi))


def _candidate_cutoffs(
    s: Surrogate,
    base: ControllerParams,
    safety: float,
    materials: Sequence[str] | None,
    cutoffs_Hz: Sequence[float],
) -> list[float]:
    """Check the arguments of :func:`tune`; the velocity cutoffs below Nyquist (Hz)."""
    if not (math.isfinite(safety) and safety >= 1.0):
        raise ValueError(f"safety must be >= 1, got {safety!r}")
    if materials:
        for m in materials:
            if m not in s.materials:
                raise ValueError(
                    f"material {m!r} not in the surrogate, which covers "
                    f"{', '.join(s.materials)} (the materials of its FE sweep)"
                )
    nyq = 0.5 / base.sample_time_s
    cutoffs = [float(c) for c in cutoffs_Hz if 0 < c < nyq]
    if not cutoffs:
        raise ValueError(f"no velocity cutoff below the Nyquist frequency {nyq:g} Hz")
    return cutoffs


@dataclass(frozen=True)
class _CouplingSearch:
    """The search for ``k_c`` (N/mm) at a chosen virtual damping and cutoff (SI units)."""

    s: Surrogate
    base: ControllerParams  # chosen damping and cutoff; its k_c is the input one
    thicknesses: Sequence[float] | None
    materials: Sequence[str] | None
    n_theta: int
    device: DeviceParams
    safety: float
    choice: _DampingChoice  # virtual damping and cutoff of step 1

    @property
    def n_coarse(self) -> int:
        """Theta samples of the search (the final check uses ``n_theta``)."""
        return max(self.n_theta // 4, 12)

    def worst(self, kc: float, n: int | None = None) -> float:
        """Largest damping (N m s/rad, >= 0) the rendering with coupling ``kc`` (N/mm) needs."""
        pts = operating_points(
            self.s,
            replace(self.base, coupling_stiffness_N_per_mm=kc),
            self.thicknesses,
            self.materials,
            self.n_coarse if n is None else n,
        )
        kmax, kmin, _op, _i = stiffest_point(pts)
        T, ch, d = self.base.sample_time_s, self.choice, self.device.delay_samples
        return max(float(required_damping(np.array([kmax, kmin]), ch.B, T, ch.fc, d).max()), 0.0)

    def largest_passive_coupling(self) -> float:
        """Largest ``k_c`` (2 significant digits, rounded down, N/mm) with ``worst <= b/safety``."""
        b, safety, ch = self.device.damping_Nms_per_rad, self.safety, self.choice
        beff = b / safety
        lo, hi = 1e-3, 1.0
        if self.worst(lo) > beff:
            raise ValueError(
                f"no coupling stiffness is passive: even k_c = {lo:g} N/mm (spring, chain and "
                f"rendered effects alone) needs b >= {self.worst(lo) * safety:.3g} N m s/rad, the "
                f"device has {b:g} (safety {safety:g}, virtual damping {ch.B:.3g} N m s/rad incl. "
                f"{ch.B_visc:.3g} of viscous friction)"
            )
        while self.worst(hi) <= beff and hi < 1e5:
            lo, hi = hi, hi * 4.0
        for _ in range(30):
            mid = math.sqrt(lo * hi)
            if self.worst(mid) <= beff:
                lo = mid
            else:
                hi = mid
            if hi / lo < 1.005:
                break
        kc = _round_down(lo, 2)
        while kc > 0 and self.worst(kc, self.n_theta) > beff:  # confirm on the full theta grid
            kc = _round_down(0.97 * kc, 2)
        return kc

    def input_coupling(self) -> dict[str, float]:
        """What the input ``k_c`` would render and need (the ``input_coupling`` summary entry)."""
        T, b, d = (
            self.base.sample_time_s,
            self.device.damping_Nms_per_rad,
            self.device.delay_samples,
        )
        ch, safety = self.choice, self.safety
        pts = operating_points(self.s, self.base, self.thicknesses, self.materials, self.n_coarse)
        k_in = stiffest_point(pts)[0]
        c = float(required_damping(1.0, 0.0, T, None, d))
        return {
            "coupling_stiffness_N_per_mm": self.base.coupling_stiffness_N_per_mm,
            "max_K_Nm_per_rad": k_in,
            "required_damping_Nms_per_rad": float(required_damping(k_in, ch.B, T, ch.fc, d))
            * safety,
            "required_rate_Hz_B0": k_in * c / T / b * safety,
        }
