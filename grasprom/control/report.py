"""The tuning report: its JSON form (:func:`jsonable`) and its text (:func:`format_report`).

Both work on the summary dict of :func:`grasprom.control.summary.summarise` (as stored in
``tuning.json``), so a report can be re-rendered from the file alone.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["format_report", "jsonable", "margins_lines", "transparency_lines"]


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
    lines += _rendering_lines(sm)
    lines += _closed_loop_lines(sm)
    lines += margins_lines(sm)
    lines += _raw_tissue_lines(sm)
    lines += _augmentation_lines(sm)
    lines += transparency_lines(sm)
    lines += _simulation_lines(sm)
    return "\n".join(lines)


def _rendering_lines(sm: dict[str, Any]) -> list[str]:
    """The rendering scheme and its stiffness bound."""
    r = sm.get("rendering")
    if not r:
        return []
    if r["scheme"] == "clipped":
        return [
            f"rendering: clipped (the tissue's own force wherever its handle stiffness is below "
            f"K_lim, the stiffest passive wall beyond): K_lim = "
            f"{r['stiffness_limit_Nm_per_rad']:g} N m/rad at the pivot "
            f"({r['grip_stiffness_limit_N_per_rad']:.4g} N/rad at the grip after the Prony "
            f"factor; instantaneous bound {r['stiffness_bound_Nm_per_rad']:.4g} N m/rad)"
        ]
    return [
        f"rendering: coupling (virtual coupling k_c = {r['coupling_stiffness_N_per_mm']:g} N/mm "
        "in series with the tissue)"
    ]


def margins_lines(sm: dict[str, Any]) -> list[str]:
    """Damping ratio and phase margin with the hand at every operating point, against the
    stated target; the device damping that would meet it."""
    om = sm.get("operating_margins")
    if not om:
        return []
    w = om["worst"]
    lines = [
        f"target: {om['target']['statement']}: " + ("MET" if om["meets_target"] else "NOT MET"),
        f"  worst case {w['material']} t = {w['thickness_mm']:g} mm (K from "
        f"{w['K_min_Nm_per_rad']:.4g} to {w['K_max_Nm_per_rad']:.4g} N m/rad; negative where "
        f"the tissue softens): damping ratio {w['damping_ratio_min']:.3g}, smallest phase margin "
        f"{w['phase_margin_min_deg']:.3g} deg with the hand over that range; "
        f"{sum(c['meets_target'] for c in om['cases'])}/{len(om['cases'])} cases meet it",
    ]
    g = om["grid"]
    cells = [
        f"K {k:.3g}: zeta {z:.3g}, PM {pm:.3g} deg"
        for k, z, pm in zip(g["K_Nm_per_rad"], g["damping_ratio"], g["phase_margin_deg"])
    ]
    lines.append("  with the hand, by rendered stiffness (N m/rad): " + "; ".join(cells[-4:]))
    kt = om["K_max_meeting_target_Nm_per_rad"]
    lines.append(
        f"  the target holds up to K = {kt:.3g} N m/rad"
        if kt > 0
        else "  no rendered stiffness of the grid meets the target with this device and hand"
    )
    lines.append(
        f"  device damping b for the target at the largest K: "
        f"{om['b_for_target_at_K_max_Nms_per_rad']:.3g} N m s/rad (B and cutoff unchanged)"
    )
    return lines


def transparency_lines(sm: dict[str, Any]) -> list[str]:
    """The transparency table: rendered/tissue force per case and level, wall vs bound, and
    the damping / rate that would render the tissue exactly up to 20 N."""
    tr = sm.get("transparency")
    if not tr:
        return []
    levels = [f"{L:g}" for L in tr["levels_N"]]
    head = " ".join(f"{L + ' N':>6s}" for L in levels)
    lines = [
        f"transparency ({tr['rendering']} rendering, quasi-static): rendered / tissue jaw force "
        "at the gap where the tissue force reaches",
        f"  {'case':10s} {head} {'max N':>7s} {'wall/bound':>10s} {'K20':>8s} "
        f"{'b_needed':>9s} {'rate_needed':>11s}",
    ]
    for c in tr["cases"]:
        cells = " ".join(
            f"{c['ratios'][L]:6.3f}" if c["ratios"][L] is not None else f"{'-':>6s}" for L in levels
        )
        wb = c["wall_over_bound"]
        lines.append(
            f"  {c['material']} {c['thickness_mm']:<7g} {cells} {c['max_rendered_N']:7.3g} "
            f"{(f'{wb:.3f}' if wb is not None else '-'):>10s} {c['K20_Nm_per_rad']:8.3g} "
            f"{c['b_needed_Nms_per_rad']:9.3g} {c['rate_needed_Hz']:11.3g}"
        )
    lines.append(
        f"  (wall/bound: median rendered handle stiffness where the tissue is stiffer than the "
        f"passive bound, over the bound; K20: largest tissue handle stiffness below "
        f"{tr['exact_up_to_N']:g} N, N m/rad; b_needed (N m s/rad) or rate_needed (Hz): what "
        "renders it passively, i.e. the tissue exactly up to 20 N)"
    )
    return lines


def _choice_lines(sm: dict[str, Any]) -> list[str]:
    """Rate and device, the chosen parameters, stiffness extremes and the passivity figures."""
    c, at = sm["chosen"], sm["max_at"]
    dev = sm["device"]
    return [
        f"grasprom tune: {sm['rate_Hz']:g} Hz, {sm['delay_samples']} sample(s) delay, "
        f"device b = {dev['damping_Nms_per_rad']:g} N m s/rad, J = {dev['inertia_kg_m2']:g} "
        f"kg m^2, Coulomb {dev['coulomb_Nm']:g} N m, encoder quantum "
        f"{sm['encoder_quantum_rad']:.3g} rad",
        f"chosen: {_bound_text(c)}, B = "
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
        f"{sm['abbott_okamura']['coulomb_term_Nm_per_rad']:.4g}; not used for the bound)",
    ]


def _bound_text(c: dict[str, Any]) -> str:
    """``K_lim = ... N m/rad`` (clipped) or ``k_c = ... N/mm`` (coupling) of a chosen dict."""
    if c.get("rendering") == "clipped":
        return f"K_lim = {c['stiffness_limit_Nm_per_rad']:g} N m/rad (clipped rendering)"
    return f"k_c = {c['coupling_stiffness_N_per_mm']:g} N/mm"


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
    clipped = sm.get("rendering", {}).get("scheme") == "clipped"
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
                f"{min(ths):.2f}-{max(ths):.2f} deg ({len(ths)} thicknesses); the "
                + ("stiffness limit clips it" if clipped else "coupling bounds it")
                + " there"
            )
    return lines


def _augmentation_lines(sm: dict[str, Any]) -> list[str]:
    """Rendered instrument effects and the augmented model file, when present."""
    c = sm["chosen"]
    lines: list[str] = []
    au = sm.get("augmentation")
    if au and "coupling_effective_N_per_mm" in au:
        if sm.get("rendering", {}).get("scheme") == "clipped":
            lines.append(
                f"rendered instrument effects (clipped rendering): tissue scale "
                f"{au['tissue_scale']:g}, jaw compliance {au['jaw_compliance_mm_per_N']:g} mm/N "
                f"(inside the field: the tissue force behind it), Prony factor "
                f"{au['prony_stiffness_factor']:.4g} (K_lim = bound x (1 + sum g) / factor)"
            )
        else:
            lines.append(
                f"rendered instrument effects: tissue scale {au['tissue_scale']:g}, jaw "
                f"compliance {au['jaw_compliance_mm_per_N']:g} mm/N -> k_c,eff = "
                f"{au['coupling_effective_N_per_mm']:.4g} N/mm; Prony factor "
                f"{au['prony_stiffness_factor']:.4g} -> jaw stiffness bound "
                f"{au['rendered_jaw_stiffness_bound_N_per_mm']:.4g} N/mm"
            )
        lines += [
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
    """Verdicts of the simulation check (chosen and rejected parameters), in words that match
    the numbers: the amplitude trend, the end stop and the sign of the net energy."""
    lines = []
    for name, v in sm.get("simulation", {}).items():
        if v.get("rendering") == "clipped":
            what = f"K_lim = {v['stiffness_limit_Nm_per_rad']:g} N m/rad"
        else:
            what = f"k_c = {v['coupling_stiffness_N_per_mm']:g} N/mm"
        trend = v.get("trend") or (
            "GROWING (the oscillation reaches the end stop)"
            if v.get("hit_stop")
            else ("GROWING" if v["growing"] else "no growing oscillation")
        )
        energy = "ACTIVE" if v["net_generated_J"] > 1e-9 else "passive"
        pert = v.get("perturbation_deg")
        lines.append(
            f"simulation {name} ({what}, {v['material']} t = {v['thickness_mm']:g} mm, hold "
            f"{v['theta_hold_deg']:.2f} deg"
            + (f", released {pert:g} deg above it" if pert is not None else "")
            + f"): net energy generated {v['net_generated_J']:.3g} J ({energy}), amplitude "
            f"{v['amp_first_rad']:.3g} -> {v['amp_last_rad']:.3g} rad, {trend}; max |pole| "
            f"{v['max_pole_mag_with_hand']:.5f}"
        )
    return lines
