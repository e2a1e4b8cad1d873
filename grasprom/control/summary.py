"""The tuning summary: what :func:`~grasprom.control.tuning.tune` reports about its choice.

:func:`summarise` collects the passivity figures, stiffness extremes and closed-loop poles of the
tuned parameters into the dict stored in ``tuning.json``; :func:`augmentation_summary` adds the
rendered instrument effects.  The text form is :func:`grasprom.control.report.format_report`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, replace
from typing import Any

import numpy as np

from grasprom.chain import kinematics as kin
from grasprom.control.device import DeviceParams, HandParams
from grasprom.control.impedance import ImpedanceController
from grasprom.control.loop import closed_loop
from grasprom.control.params import ControllerParams
from grasprom.control.passivity import (
    abbott_okamura_bound,
    colgate_required_damping,
    required_damping,
)
from grasprom.control.stiffness import (
    OperatingPoints,
    prony_stiffness_factor,
    stiffest_point,
    virtual_damping_Nms_per_rad,
)
from grasprom.surrogate import Surrogate

__all__ = ["augmentation_summary", "renders_instrument_effects", "summarise"]


def summarise(
    s: Surrogate,
    params: ControllerParams,
    device: DeviceParams,
    hand: HandParams,
    pts: list[OperatingPoints],
    safety: float,
    k_pass: float,
) -> dict[str, Any]:
    """Tuning summary of ``params`` over the operating points ``pts`` (the JSON report).

    Parameters
    ----------
    s : Surrogate
    params : ControllerParams
        Tuned parameters.
    device : DeviceParams
    hand : HandParams
    pts : list of OperatingPoints
        Rendered stiffness of ``params`` over theta x thickness x material.
    safety : float
        Required ``b / b_required`` (1).
    k_pass : float
        Passive stiffness with the safety margin, N m/rad.

    Returns
    -------
    dict
        Rate, device, hand, chosen parameters, stiffness extremes, passivity figures (Colgate,
        Abbott-Okamura), raw tissue, coupling activity and closed-loop poles/margins.
    """
    T, B, fc = params.sample_time_s, virtual_damping_Nms_per_rad(params), params.velocity_cutoff_Hz
    b, d = device.damping_Nms_per_rad, device.delay_samples
    L3 = params.chain_params.L3_mm
    q = _encoder_quantum_rad(s, params, pts[0])
    kmax, kmin, op, i = stiffest_point(pts)
    b_req = float(required_damping(np.array([kmax, kmin]), B, T, fc, d).max())
    c_delay = float(required_damping(1.0, 0.0, T, None, d))  # b_req per unit K, B = 0
    return {
        "sample_time_s": T,
        "rate_Hz": 1.0 / T,
        "delay_samples": d,
        "safety_factor": safety,
        "device": asdict(device),
        "hand": asdict(hand),
        "hand_at_pivot": dict(zip(("J_kg_m2", "b_Nms_per_rad", "k_Nm_per_rad"), hand.at_pivot(L3))),
        "encoder_quantum_rad": q,
        "chosen": _chosen(params),
        "passive_stiffness_Nm_per_rad": k_pass * safety,
        "passive_stiffness_with_margin_Nm_per_rad": k_pass,
        "max_rendered_K_Nm_per_rad": kmax,
        "min_rendered_K_Nm_per_rad": kmin,
        "max_at": _max_at(op, i, params.chain_params),
        "required_damping_Nms_per_rad": b_req,
        "passivity_margin": b / b_req if b_req > 0 else math.inf,
        "passive_everywhere": bool(b_req < b),
        "colgate_closed_form": _colgate_closed_form(kmax, B, T, b, c_delay),
        "abbott_okamura": _abbott_okamura(kmax, b, T, device.coulomb_Nm, q),
        "raw_tissue": _raw_tissue(pts, k_pass, c_delay, b, T),
        "coupling_active": _coupling_active(pts, params.coupling_effective_N_per_mm),
        "closed_loop_with_hand": closed_loop(kmax, B, fc, T, device, hand, L3),
        "closed_loop_device_alone": closed_loop(kmax, B, fc, T, device, None, L3),
    }


def _chosen(params: ControllerParams) -> dict[str, Any]:
    """The chosen parameters: ``k_c`` (N/mm), ``B`` (N m s/rad), cutoff (Hz), torque limit
    (N m), the rendering and, when clipped, ``K_lim`` (N m/rad)."""
    out: dict[str, Any] = {
        "coupling_stiffness_N_per_mm": params.coupling_stiffness_N_per_mm,
        "damping_Nms_per_rad": params.damping_Nms_per_rad,
        "velocity_cutoff_Hz": params.velocity_cutoff_Hz,
        "torque_limit_Nm": params.torque_limit_Nm,
        "rendering": params.rendering,
    }
    if params.rendering == "clipped":
        out["stiffness_limit_Nm_per_rad"] = params.stiffness_limit_Nm_per_rad
    return out


def _encoder_quantum_rad(s: Surrogate, params: ControllerParams, op: OperatingPoints) -> float:
    """Handle angle per encoder count (rad) of ``params`` at one operating point."""
    return ImpedanceController(
        replace(params, material=op.material, thickness_mm=op.thickness_mm), s
    ).encoder_quantum_rad


def _max_at(op: OperatingPoints, i: int, chain: kin.ChainParams) -> dict[str, Any]:
    """Where the largest rendered stiffness is: material, thickness (mm), angle (deg), gap..."""
    return {
        "material": op.material,
        "thickness_mm": op.thickness_mm,
        "theta_deg": float(op.theta_deg[i]),
        "gap_mm": float(op.gap_mm[i]),
        "jaw_stiffness_N_per_mm": float(op.jaw_stiffness_N_per_mm[i]),
        "dgap_dtheta_mm_per_rad": float(kin.dgap_dtheta_mm_per_rad(op.theta_deg[i], chain)),
    }


def _colgate_closed_form(
    kmax: float, B: float, T: float, b: float, c_delay: float
) -> dict[str, float]:
    """Colgate closed forms: required ``b`` without delay (N m s/rad), ``K_max`` at B = 0."""
    return {
        "required_damping_no_delay_Nms_per_rad": colgate_required_damping(kmax, B, T),
        "max_K_no_delay_B0_Nm_per_rad": 2.0 * b / T,
        "max_K_one_sample_delay_B0_Nm_per_rad": b / c_delay if c_delay > 0 else math.inf,
    }


def _abbott_okamura(
    kmax: float, b: float, T: float, coulomb_Nm: float, q: float
) -> dict[str, float | bool]:
    """Abbott-Okamura bound (N m/rad), its viscous and Coulomb terms; whether ``kmax`` passes."""
    return {
        "max_K_Nm_per_rad": abbott_okamura_bound(b, T, coulomb_Nm, q),
        "viscous_term_Nm_per_rad": 2.0 * b / T,
        "coulomb_term_Nm_per_rad": (2.0 * coulomb_Nm / q) if q > 0 else math.inf,
        "passes": bool(kmax <= abbott_okamura_bound(b, T, coulomb_Nm, q)),
    }


def _raw_tissue(
    pts: list[OperatingPoints], k_pass: float, c_delay: float, b: float, T: float
) -> dict[str, Any]:
    """The raw tissue without coupling: largest ``K``, the damping/rate it needs, where not
    renderable (``K_raw > k_pass``)."""
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
    return {
        "max_K_Nm_per_rad": raw_max,
        "required_damping_Nms_per_rad": raw_max * c_delay,
        "required_rate_Hz": raw_max * c_delay / b / T,
        "not_renderable": not_renderable,
    }


def _coupling_active(pts: list[OperatingPoints], kc_eff: float) -> list[dict[str, Any]]:
    """Per material/thickness, the angle (deg) below which the tissue is stiffer than k_c,eff."""
    return [
        {
            "material": o.material,
            "thickness_mm": o.thickness_mm,
            "theta_deg_below": float(np.max(o.theta_deg[o.tissue_stiffness_N_per_mm > kc_eff])),
        }
        for o in pts
        if np.any(o.tissue_stiffness_N_per_mm > kc_eff)
    ]


def renders_instrument_effects(params: ControllerParams) -> bool:
    """Whether any rendered instrument effect is on."""
    return bool(
        params.tissue_scale != 1.0
        or params.jaw_compliance_mm_per_N > 0
        or params.backlash_deg > 0
        or params.friction_rendered
        or params.prony_g
    )


def augmentation_summary(params: ControllerParams, B_visc: float) -> dict[str, Any]:
    """The ``augmentation`` entry of the summary: the rendered effects and how they count.

    Parameters
    ----------
    params : ControllerParams
        Tuned parameters.
    B_visc : float
        Virtual damping of the rendered viscous friction, N m s/rad.

    Returns
    -------
    dict
    """
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
