"""The tuning report: its JSON form (:func:`jsonable`) and its text (:func:`format_report`).

Both work on the summary dict of :func:`grasprom.control.summary.summarise` (as stored in
``tuning.json``), so a report can be re-rendered from the file alone.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["format_report", "jsonable"]


def jsonable(o: Any) -> Any:
    """``o`` with dicts/lists/tuples recursed, numpy scalars as Python, non-finite floats as
    ``None``, ``"inf"`` or ``"-inf"`` (strict JSON)."""
    if isinstance(o, dict):
        return {k: jsonable(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [jsonable(v) for v in o]
    if isinstance(o, np.generic):
        o = o.item()
    if isinstance(o, float) and not math.isfinite(o):
        return None if math.isnan(o) else ("inf" if o > 0 else "-inf")
    return o


def format_report(sm: dict[str, Any]) -> str:
    """Text report of a tuning summary (:meth:`~grasprom.control.tuning.TuningResult.to_dict`)."""
    lines = _choice_lines(sm)
    lines += _closed_loop_lines(sm)
    lines += _raw_tissue_lines(sm)
    lines += _augmentation_lines(sm)
    lines += _simulation_lines(sm)
    return "\n".join(lines)


def _choice_lines(sm: dict[str, Any]) -> list[str]:
    """Rate and device, the chosen parameters, stiffness extremes and the passivity figures."""
    c, at = sm["chosen"], sm["max_at"]
    dev = sm["device"]
    return [
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


def _closed_loop_lines(sm: dict[str, Any]) -> list[str]:
    """Closed-loop poles and margins, with the hand and for the device alone."""
    lines = []
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
    return lines


def _raw_tissue_lines(sm: dict[str, Any]) -> list[str]:
    """The raw tissue and the input coupling: what they would need, where not renderable."""
    raw = sm["raw_tissue"]
    lines = []
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
    return lines


def _augmentation_lines(sm: dict[str, Any]) -> list[str]:
    """Rendered instrument effects and the augmented model file, when present."""
    c = sm["chosen"]
    lines: list[str] = []
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
    return lines


def _simulation_lines(sm: dict[str, Any]) -> list[str]:
    """Verdicts of the simulation check (chosen and rejected parameters)."""
    lines = []
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
    return lines
