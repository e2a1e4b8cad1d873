"""Time-domain check of a tuning: device + controller + hand closing onto the tissue.

Simulation check: :func:`simulate_hold` runs the real :class:`ImpedanceController` step at the
sample rate against a continuous device + hand model (sub-stepped, Coulomb friction, encoder
quantisation) and measures the energy the controller injects beyond the ideal static field, and
the growth of the oscillation.
:func:`verify_by_simulation` runs it with the chosen and with rejected (stiffer) parameters.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import numpy as np

from grasprom.chain import kinematics as kin
from grasprom.control.device import DeviceParams, HandParams
from grasprom.control.impedance import ImpedanceController
from grasprom.control.loop import closed_loop
from grasprom.control.params import ControllerParams
from grasprom.control.passivity import required_damping
from grasprom.control.stiffness import (
    OperatingPoints,
    rendered_stiffness,
    static_handle_torque_Nm,
    virtual_damping_Nms_per_rad,
)
from grasprom.surrogate import Surrogate

__all__ = [
    "PERTURBATION_DEG",
    "amplitude_trend",
    "simulate_hold",
    "stiffest_hold_angle_deg",
    "verify_by_simulation",
]


PERTURBATION_DEG = 0.5
"""Perturbation of the energy check of :func:`verify_by_simulation` (deg about the hold)."""


def verify_by_simulation(
    s: Surrogate,
    params: ControllerParams,
    device: DeviceParams,
    hand: HandParams,
    summary: dict[str, Any],
    reject_factor: float = 8.0,
    perturbation_deg: float = PERTURBATION_DEG,
    points: Sequence[OperatingPoints] | None = None,
) -> dict[str, Any]:
    """Energy check: perturb the hold at the stiffest point, chosen and rejected parameters.

    Chosen: ``params`` at the material/thickness of the largest rendered stiffness.  Rejected:
    the stiffness bound x ``reject_factor`` (``k_c`` for the coupling, ``K_lim`` for the
    clipped rendering).  Each run is :func:`simulate_hold` released at rest
    ``perturbation_deg`` above the hold angle, its energies and amplitudes measured over the
    whole run (the response to the perturbation, not a settled window); returns the verdicts,
    energies (J), amplitudes (rad) and the python-control pole check at the hold angle.
    With the clipped rendering and the tuning's ``points`` the case is the one whose tissue
    is stiffest at least 0.5 deg above the closed end (every case renders the limit).
    """
    at = summary["max_at"]
    if params.rendering == "clipped" and points:
        # every clipped case renders the same largest K (the limit): hold where the tissue
        # is stiffest, so that the rejected (stiffer) limit acts there
        op = max(points, key=lambda o: float(np.max(_hold_band(o, params))))
        at = {"material": op.material, "thickness_mm": op.thickness_mm}
    p0 = replace(params, material=at["material"], thickness_mm=at["thickness_mm"])
    out = {}
    for name, p in (("chosen", p0), ("rejected", _rejected(p0, reject_factor))):
        sim = simulate_hold(
            s, p, device, hand, theta_start_offset_deg=perturbation_deg, window_start_s=0.0
        )
        op = rendered_stiffness(s, p, np.array([sim["theta_hold_deg"]]))
        K = float(op.K_Nm_per_rad[0])
        Bt = virtual_damping_Nms_per_rad(p)
        cl = closed_loop(
            K, Bt, p.velocity_cutoff_Hz, p.sample_time_s, device, hand, p.chain_params.L3_mm
        )
        out[name] = {
            "rendering": p.rendering,
            "coupling_stiffness_N_per_mm": p.coupling_stiffness_N_per_mm,
            "stiffness_limit_Nm_per_rad": p.stiffness_limit_Nm_per_rad,
            "material": p.material,
            "thickness_mm": p.thickness_mm,
            "theta_hold_deg": sim["theta_hold_deg"],
            "perturbation_deg": perturbation_deg,
            "K_Nm_per_rad": K,
            "required_damping_Nms_per_rad": float(
                required_damping(K, Bt, p.sample_time_s, p.velocity_cutoff_Hz, device.delay_samples)
            ),
            "net_generated_J": sim["net_generated_J"],
            "controller_excess_J": sim["controller_excess_J"],
            "device_dissipated_J": sim["device_dissipated_J"],
            "amp_first_rad": sim["amp_first_rad"],
            "amp_last_rad": sim["amp_last_rad"],
            "trend": sim["trend"],
            "growing": sim["growing"],
            "hit_stop": sim["hit_stop"],
            "max_pole_mag_with_hand": cl["max_pole_mag"],
            "damping_ratio_with_hand": cl["damping_ratio"],
        }
    return out


def _hold_band(op: OperatingPoints, params: ControllerParams) -> np.ndarray:
    """Tissue handle stiffness (N m/rad) of ``op`` at angles >= 0.5 deg above the closed end."""
    lo = kin.theta_range_deg(params.chain_params)[0]
    band = op.theta_deg >= lo + 0.5 - 1e-9
    return op.K_raw_Nm_per_rad[band] if np.any(band) else op.K_raw_Nm_per_rad


def _rejected(p: ControllerParams, factor: float) -> ControllerParams:
    """``p`` with its stiffness bound (``k_c`` or ``K_lim``) times ``factor``."""
    if p.rendering == "clipped":
        return replace(p, stiffness_limit_Nm_per_rad=factor * p.stiffness_limit_Nm_per_rad)
    return replace(p, coupling_stiffness_N_per_mm=factor * p.coupling_stiffness_N_per_mm)


# the numpydoc docstring (the model and the outputs) is most of its length; the body is ~25 lines
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
    window_start_s: float | None = None,
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
    window_start_s : float, optional
        Start of the measurement window, s (default ``duration_s / 2``: the settled hold; 0
        measures the whole response to the initial offset).

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
        ``trend`` (the words for the numbers: ``"growing"``, ``"decaying"``, ``"steady"``,
        ``"at rest"``, with ``", hits the end stop"`` when it does), ``saturated_fraction``.
    """
    device = device or DeviceParams()
    hand = hand or HandParams()
    chain = params.chain_params
    T = params.sample_time_s
    if not quantise:
        params = replace(params, encoder_counts_per_rev=0)
    ctl = ImpedanceController(params, s)
    th_lo, th_hi = (math.radians(v) for v in kin.theta_range_deg(chain))
    if theta_hold_deg is None:
        theta_hold_deg = stiffest_hold_angle_deg(s, params, th_lo)
    th_hold = min(max(math.radians(theta_hold_deg), th_lo), th_hi)
    plant = _HoldPlant.build(s, params, device, hand, th_hold, (th_lo, th_hi), substeps)
    th = min(th_hold + math.radians(theta_start_offset_deg), th_hi)
    n = int(round(duration_s / T))
    half = n // 2 if window_start_s is None else min(max(int(round(window_start_s / T)), 0), n - 2)
    run = _run_hold(ctl, plant, _settle(ctl, s, params, device, th), th, n, half)
    return {
        "time_s": np.arange(n + 1) * T,
        "theta_rad": run.theta_rad,
        "torque_handle_Nm": run.torque_handle_Nm,
        "theta_hold_deg": math.degrees(th_hold),
        **_hold_verdict(s, params, run, half, ctl.encoder_quantum_rad),
        "saturated_fraction": run.n_saturated / n,
    }


def stiffest_hold_angle_deg(s: Surrogate, params: ControllerParams, theta_lo_rad: float) -> float:
    """Default hold angle (deg): where the rendered stiffness peaks, >= 0.5 deg above the end.

    Clipped rendering: where the tissue's handle stiffness peaks in that band (the rendered
    stiffness is the limit all over the wall).

    Parameters
    ----------
    s : Surrogate
    params : ControllerParams
        Material and thickness of the hold.
    theta_lo_rad : float
        Closed end of the handle range (rad).

    Returns
    -------
    float
    """
    op = rendered_stiffness(s, params)
    lo = math.degrees(theta_lo_rad) + 0.5
    if params.rendering == "clipped":  # the rendered K is the limit over the whole wall
        band = op.theta_deg >= lo - 1e-9
        k = np.where(band, op.K_raw_Nm_per_rad, -np.inf)
        return max(float(op.theta_deg[int(np.argmax(k))]), lo)
    return max(float(op.theta_deg[int(np.argmax(op.K_Nm_per_rad))]), lo)


@dataclass(frozen=True)
class _HoldPlant:
    """Continuous device + hand about the handle pivot, pushed into the hold (SI units)."""

    inertia: float  # J + J_h, kg m^2
    damping: float  # b + b_h, N m s/rad
    device_damping: float  # b, N m s/rad (the device's own losses)
    coulomb: float  # device Coulomb friction f_c, N m
    coulomb_dv: float  # velocity f_c removes per sub-step, rad/s
    stiffness: float  # hand spring k_h, N m/rad, anchored at the hold angle
    theta_hold: float  # rad
    tau_push: float  # constant hand torque, N m
    theta_lo: float  # end stops, rad
    theta_hi: float
    dt: float  # sub-step, s
    substeps: int
    gain: float  # handle torque per motor torque, L3 / r

    @classmethod
    def build(
        cls,
        s: Surrogate,
        params: ControllerParams,
        device: DeviceParams,
        hand: HandParams,
        theta_hold: float,
        stops: tuple[float, float],
        substeps: int,
    ) -> _HoldPlant:
        """The plant of :func:`simulate_hold` for a hold at ``theta_hold`` (rad)."""
        L3 = params.chain_params.L3_mm
        jh, bh, kh = hand.at_pivot(L3)
        J = device.inertia_kg_m2 + jh
        dt = params.sample_time_s / substeps
        return cls(
            inertia=J,
            damping=device.damping_Nms_per_rad + bh,
            device_damping=device.damping_Nms_per_rad,
            coulomb=device.coulomb_Nm,
            coulomb_dv=device.coulomb_Nm * dt / J,
            stiffness=kh,
            theta_hold=theta_hold,
            tau_push=float(static_handle_torque_Nm(s, params, np.array([theta_hold]))[0]),
            theta_lo=stops[0],
            theta_hi=stops[1],
            dt=dt,
            substeps=substeps,
            gain=L3 / params.pulley_radius_mm,
        )

    def advance(
        self, th: float, w: float, tau: float, dissipated: float, in_window: bool
    ) -> tuple[float, float, float, bool]:
        """One sample at the held torque ``tau`` (N m): semi-implicit Euler sub-steps.

        Returns the angle (rad), velocity (rad/s), the device losses (J) accumulated onto
        ``dissipated`` while ``in_window``, and whether an end stop was hit in the window.
        """
        J, bt, kh, th_hold = self.inertia, self.damping, self.stiffness, self.theta_hold
        tau_push, dt, fc_dv = self.tau_push, self.dt, self.coulomb_dv
        th_lo, th_hi, b_dev, fc = self.theta_lo, self.theta_hi, self.device_damping, self.coulomb
        hit_stop = False
        for _ in range(self.substeps):
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
                if in_window:
                    hit_stop = True
            if in_window:
                dissipated += (b_dev * w * w + fc * abs(w)) * dt
        return th, w, dissipated, hit_stop


def _settle(
    ctl: ImpedanceController,
    s: Surrogate,
    params: ControllerParams,
    device: DeviceParams,
    th: float,
) -> list[float]:
    """Rest the controller at ``th`` (rad); the delay queue of handle torques (N m) at rest.

    20 steps converge the proxy; with Prony terms the rest lasts 8 of the longest relaxation
    times too (at most 60 s), so that the viscoelastic states start relaxed and their stored
    energy is not counted as generated by the controller.
    """
    ctl.reset(th)
    n = 20
    if params.prony_tau_s:
        n += min(int(math.ceil(8.0 * max(params.prony_tau_s) / params.sample_time_s)), 60000)
    for _ in range(n):  # at rest: no velocity, the angle does not move
        ctl.step(th)
    tau0 = float(static_handle_torque_Nm(s, params, np.array([th]))[0])
    return [tau0] * device.delay_samples  # as if resting there before t = 0


class _HoldRun(NamedTuple):
    theta_rad: np.ndarray  # angle at each sample start and the end, n + 1
    torque_handle_Nm: np.ndarray  # handle torque held over each sample, n
    n_saturated: int
    dissipated_J: float  # device losses over the hold window
    hit_stop: bool  # an end stop was hit in the hold window


def _run_hold(
    ctl: ImpedanceController, plant: _HoldPlant, queue: list[float], th: float, n: int, half: int
) -> _HoldRun:
    """``n`` samples from rest at ``th`` (rad); the window starts at sample ``half``."""
    thetas = np.empty(n + 1)
    taus = np.empty(n)
    w = 0.0
    n_sat = 0
    dissipated = 0.0
    hit_stop = False
    for k in range(n):
        out = ctl.step(th)
        n_sat += out.saturated
        queue.append(out.torque_Nm * plant.gain)
        tau = queue.pop(0)  # computed delay_samples ago, held over this period
        thetas[k] = th
        taus[k] = tau
        th, w, dissipated, hit = plant.advance(th, w, tau, dissipated, k >= half)
        hit_stop = hit_stop or hit
    thetas[n] = th
    return _HoldRun(thetas, taus, n_sat, dissipated, hit_stop)


def _hold_verdict(
    s: Surrogate, params: ControllerParams, run: _HoldRun, half: int, quantum_rad: float
) -> dict[str, Any]:
    """Energies (J), amplitudes (rad) and growth over the hold window (from sample ``half``)."""
    th_w = run.theta_rad[half:]
    excess = _controller_excess_J(s, params, th_w, run.torque_handle_Nm[half:])
    m = max(len(th_w) // 5, 2)
    a1 = float(np.std(th_w[:m]))
    a2 = float(np.std(th_w[-m:]))
    q = quantum_rad if quantum_rad > 0 else 1e-5
    return {
        "controller_excess_J": excess,
        "device_dissipated_J": run.dissipated_J,
        "net_generated_J": excess - run.dissipated_J,
        "amp_first_rad": a1,
        "amp_last_rad": a2,
        "growing": bool((a2 > 1.1 * a1 and a2 > 5 * q) or run.hit_stop),
        "hit_stop": run.hit_stop,
        "trend": amplitude_trend(a1, a2, q, run.hit_stop),
    }


def amplitude_trend(a_first: float, a_last: float, quantum_rad: float, hit_stop: bool) -> str:
    """Words for an amplitude pair (rad): growing, decaying, steady or at rest.

    ``growing`` if ``a_last > 1.1 a_first``, ``decaying`` if ``a_last < a_first / 1.1``,
    ``steady`` between; ``at rest`` when both are below one encoder count ``quantum_rad``;
    ``", hits the end stop"`` is appended when the handle reached an end stop.
    """
    if max(a_first, a_last) < quantum_rad:
        word = "at rest"
    elif a_last > 1.1 * a_first:
        word = "growing"
    elif a_last < a_first / 1.1:
        word = "decaying"
    else:
        word = "steady"
    return word + (", hits the end stop" if hit_stop else "")


def _controller_excess_J(
    s: Surrogate, params: ControllerParams, th_w: np.ndarray, taus_w: np.ndarray
) -> float:
    """Work of the device torque beyond the ideal static field over the window (J)."""
    tau_static = static_handle_torque_Nm(s, params, th_w)
    dth = np.diff(th_w)
    # U(end) - U(start) = -int tau_static dtheta (trapezoid)
    work_ideal = np.sum(0.5 * (tau_static[1:] + tau_static[:-1]) * dth)
    return float(np.sum(taus_w * dth) - work_ideal)
