"""The headline table of a build: what was built and every figure that has a
stated target, with the target, where it is stated and PASS / FAIL computed from the numbers.

:func:`headline_rows` gives the rows (JSON-ready; ``build.json`` keeps them under
``headline``), :func:`verdict` the comparison and :func:`built_items` the one-line
inventory of the artefacts.  The targets are the project's own constants, never numbers
chosen here:

* surrogate held-out error: :data:`grasprom.surrogate.CHECK_TOLERANCE` (3 % of the
  20 N haptic scale, 0.02 mm);
* passivity margin ``b / b_required``: the tuning's safety factor (``tune(safety=1.25)``;
  passive means > 1) at the controller rate;
* closed-loop damping ratio with the hand: :data:`grasprom.control.ZETA_TARGET`;
* Arduino flash, RAM, cycles and handle-force error: the budgets of
  :mod:`grasprom.export.arduino.budget`;
* FMU vs Python reference torque over the co-simulation: :data:`PARITY_TOLERANCE_NM` (the C
  core is bit-identical to the Python reference);
* co-simulated handle-force overshoot: :data:`grasprom.pipeline.cosim.OVERSHOOT_TARGET`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from grasprom.pipeline.result import BuildResult

if TYPE_CHECKING:
    from grasprom.control import TuningResult
    from grasprom.export import ArduinoExport
    from grasprom.pipeline.result import CosimResult
    from grasprom.surrogate import Surrogate

PARITY_TOLERANCE_NM = 1e-9
"""Largest |FMU torque - Python reference torque| over the co-simulation, N m.  The C core of
the FMU is bit-identical to the Python controller (README, "C core vs Python reference");
1e-9 N m is the tolerance the pipeline tests hold it to."""

PASS, FAIL, NOT_MEASURED = "PASS", "FAIL", "n/a"
"""Verdicts of a headline row: target met, missed, or the figure was not measured."""


def verdict(value: float | None, sense: str, limit: float) -> str:
    """PASS / FAIL of ``value`` against ``limit``; ``n/a`` when ``value`` is None or NaN.

    Parameters
    ----------
    value : float or None
        Measured figure (unit of ``limit``).
    sense : str
        ``"<="`` (at most ``limit``) or ``">="`` (at least ``limit``).
    limit : float
        The target.

    Returns
    -------
    str
        :data:`PASS`, :data:`FAIL` or :data:`NOT_MEASURED`.
    """
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return NOT_MEASURED
    if sense == "<=":
        return PASS if value <= limit else FAIL
    if sense == ">=":
        return PASS if value >= limit else FAIL
    raise ValueError(f"sense must be '<=' or '>=', not {sense!r}")


def _row(
    figure: str, value: float | None, unit: str, sense: str, limit: float, source: str
) -> dict[str, Any]:
    """One headline row: figure, value (unit), target ``sense limit``, source, verdict."""
    return {"figure": figure, "value": value, "unit": unit, "sense": sense, "limit": limit,
            "source": source, "verdict": verdict(value, sense, limit)}  # fmt: skip


def headline_rows(res: BuildResult) -> list[dict[str, Any]]:
    """Rows of the headline table of a (possibly partial) build, in report order.

    Parameters
    ----------
    res : BuildResult

    Returns
    -------
    list of dict
        Each with ``figure``, ``value`` (None when not measured), ``unit``, ``sense``
        (``"<="`` or ``">="``), ``limit``, ``source`` (where the target is stated) and
        ``verdict`` (PASS, FAIL or n/a).
    """
    rows: list[dict[str, Any]] = []
    if res.surrogate is not None:
        rows += surrogate_rows(res.surrogate)
    if res.tuning is not None:
        rows += tuning_rows(res.tuning)
    if res.arduino is not None:
        rows += arduino_rows(res.arduino)
    if res.cosim is not None:
        rows += cosim_rows(res.cosim)
    return rows


def surrogate_rows(s: Surrogate) -> list[dict[str, Any]]:
    """Held-out haptic force (% of the haptic scale) and gap (mm) errors, max, all materials."""
    from grasprom.surrogate import CHECK_TOLERANCE

    fig = s.errors.get("holdout", {}).get("schemes", {}).get(s.scheme)
    h = fig["haptic"]["all"] if fig else {}
    src = "grasprom.surrogate.CHECK_TOLERANCE"
    scale = f"{s.params.force_ref_N:g} N"
    return [
        _row(f"surrogate: held-out haptic force error, max ({s.scheme}, "
             f"{', '.join(s.materials)})",
             h.get("force_max_pct"), f"% of {scale}", "<=", CHECK_TOLERANCE["force_max_pct"],
             src),
        _row("surrogate: held-out gap error where steeper, max", h.get("gap_max_mm"), "mm",
             "<=", CHECK_TOLERANCE["gap_max_mm"], src),
    ]  # fmt: skip


def tuning_rows(tuning: TuningResult) -> list[dict[str, Any]]:
    """Passivity margin at the rate against the safety factor; closed-loop damping ratio."""
    sm = tuning.summary
    rows = [
        _row(f"controller: passivity margin b / b_required at {sm['rate_Hz']:g} Hz "
             "(passive when > 1)", float(sm["passivity_margin"]), "", ">=",
             float(sm["safety_factor"]), "grasprom.control.tune safety factor"),
    ]  # fmt: skip
    om = sm.get("operating_margins")
    if om:
        rows.append(_row("closed loop with the hand: worst damping ratio",
                         float(om["worst"]["damping_ratio_min"]), "", ">=",
                         float(om["target"]["damping_ratio_min"]),
                         "grasprom.control.ZETA_TARGET"))  # fmt: skip
    return rows


def arduino_rows(a: ArduinoExport) -> list[dict[str, Any]]:
    """Flash, RAM, cycles per step and handle-force error of the Arduino core vs its budgets."""
    from grasprom.export import CYCLE_BUDGET, ERROR_BUDGET, FLASH_BUDGET_B, RAM_BUDGET_B

    src = "grasprom.export.arduino.budget"
    return [
        _row("arduino: flash, tables + core", a.flash_B, "B", "<=", FLASH_BUDGET_B, src),
        _row("arduino: RAM, static + step stack", a.ram_B, "B", "<=", RAM_BUDGET_B, src),
        _row("arduino: cycles per step, max (simavr)", a.cycles_max, "cycles", "<=",
             CYCLE_BUDGET, src),
        _row("arduino: handle-force error vs the float reference", a.error_handle_pct_rendered,
             "% of the rendered range", "<=", 100 * ERROR_BUDGET, src),
    ]  # fmt: skip


def cosim_rows(cs: CosimResult) -> list[dict[str, Any]]:
    """FMU vs Python reference torque and the handle-force overshoot of the co-simulation."""
    from grasprom.pipeline.cosim import OVERSHOOT_TARGET

    rows = [
        _row("co-simulation: FMU vs Python reference torque, max |diff|",
             float(cs.max_torque_diff_Nm), "N m", "<=", PARITY_TOLERANCE_NM,
             "grasprom.pipeline.headline.PARITY_TOLERANCE_NM (C core bit-identical)"),
    ]  # fmt: skip
    st = cs.settling
    rows.append(_row("co-simulation: rendered handle-force overshoot over the hold",
                     100 * st["overshoot"] if st else None, "%", "<=",
                     100 * OVERSHOOT_TARGET,
                     "grasprom.pipeline.cosim.OVERSHOOT_TARGET"))  # fmt: skip
    return rows


def built_items(res: BuildResult) -> list[str]:
    """What the build made, one item per artefact, with its key figures (units stated)."""
    items: list[str] = []
    s = res.surrogate
    if s is not None:
        items.append(f"surrogate: {', '.join(s.materials)}, {s.node_count()} nodes, "
                     f"{s.scheme} scheme")  # fmt: skip
    if res.tuning is not None:
        c = res.tuning.summary["chosen"]
        bound = (
            f"K_lim = {c['stiffness_limit_Nm_per_rad']:g} N m/rad (clipped rendering)"
            if c.get("rendering") == "clipped"
            else f"k_c = {c['coupling_stiffness_N_per_mm']:g} N/mm (coupling rendering)"
        )
        items.append(f"controller: {bound}, B = {c['damping_Nms_per_rad']:.4g} N m s/rad, "
                     f"velocity cutoff {c['velocity_cutoff_Hz']:g} Hz")  # fmt: skip
    fmus = [f"FMI {v} ({res.files[k].stat().st_size / 1024:.0f} KiB)"
            for k, v in (("fmu2", "2.0"), ("fmu3", "3.0")) if k in res.files]  # fmt: skip
    if fmus:
        items.append("FMUs: " + ", ".join(fmus))
    if res.arduino is not None:
        items.append("Arduino package (ATmega328P sketch, fixed-point tables)")
    if res.cosim is not None:
        cs = res.cosim
        items.append(f"co-simulation: max jaw force {cs.col('force_jaw_N').max():.2f} N, min "
                     f"handle angle {cs.col('theta_deg').min():.2f} deg, max motor torque "
                     f"{cs.col('torque_Nm').max():.3f} N m")  # fmt: skip
    return items
