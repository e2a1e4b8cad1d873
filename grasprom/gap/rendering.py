"""From the augmented model to the haptic controller: the controller parameters rendering its
instrument effects, and the sensor reading of its measurement effects (which the controller does
not render)."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from grasprom.control import MAX_PRONY_TERMS, ControllerParams
from grasprom.gap.augmented import AugmentedModel
from grasprom.gap.effects import EFFECT_ORDER, EFFECTS, PRONY_TAUS_S
from grasprom.gap.trials import FloatArray
from grasprom.surrogate import Surrogate

RENDERED_EFFECTS = (
    "tissue_viscoelasticity",
    "mechanism_friction",
    "backlash",
    "jaw_compliance",
    "thickness_error",
    "tissue_stiffness_scale",
)
"""Effects of the instrument the controller renders (:func:`controller_params_from_augmented`)."""

MEASUREMENT_EFFECTS = ("sensor_offset_gain", "latency", "sensor_drift")
"""Effects of the measurement (force sensor, time base): never rendered by the controller."""


class _Effects:
    """Values of the model's effects, clipped into the controller's bounds with a warning."""

    def __init__(self, effects: dict[str, dict[str, float]], warn: list[str]) -> None:
        self.eff = effects
        self.warn = warn

    def nonneg(self, effect: str, key: str) -> float:
        """``effect.key`` if finite and >= 0, else 0 (warned)."""
        v = float(self.eff[effect][key])
        if not (math.isfinite(v) and v >= 0):
            self.warn.append(
                f"{effect}.{key} = {v!r} is outside the controller's bound >= 0: set to 0"
            )
            return 0.0
        return v


def _check_start(params: ControllerParams, model: AugmentedModel, warn: list[str]) -> None:
    """Warn when ``params`` are already augmented or the model's return spring differs."""
    if (
        params.tissue_scale != 1.0
        or params.jaw_compliance_mm_per_N > 0
        or params.backlash_deg > 0
        or params.friction_rendered
        or params.prony_g
    ):
        warn.append(
            "the controller parameters already render instrument effects (an earlier "
            "--augmented?): the model's replace them, and a thickness offset is added again; "
            "start from the un-augmented parameters"
        )
    if model.chain.spring_k_N_per_mm != params.spring_k_N_per_mm:
        warn.append(
            f"the model was fitted with a return spring of {model.chain.spring_k_N_per_mm:g} "
            f"N/mm; the controller's {params.spring_k_N_per_mm:g} N/mm is kept"
        )


def _tissue_fields(
    params: ControllerParams, ev: _Effects, surrogate: Surrogate | None
) -> dict[str, Any]:
    """``thickness_mm`` (mm, offset clamped into the surrogate's range) and ``tissue_scale``."""
    eff, new = ev.eff, {}
    if "thickness_error" in eff:
        t = params.thickness_mm + float(eff["thickness_error"]["offset_mm"])
        if surrogate is not None:
            lo, hi = surrogate.thickness_range(params.material)
            tc = min(max(t, lo), hi)
            if tc != t:
                ev.warn.append(
                    f"thickness {params.thickness_mm:g} + offset = {t:.4g} mm clamped into the "
                    f"surrogate's range [{lo:g}, {hi:g}] mm"
                )
            t = tc
        new["thickness_mm"] = t
    if "tissue_stiffness_scale" in eff:
        sc = float(eff["tissue_stiffness_scale"]["scale"])
        if not (math.isfinite(sc) and sc > 0):
            ev.warn.append(f"tissue_stiffness_scale.scale = {sc!r} is not > 0: left at 1")
            sc = 1.0
        new["tissue_scale"] = sc
    return new


def _mechanism_fields(ev: _Effects) -> dict[str, Any]:
    """Jaw compliance (mm/N), backlash (deg), friction (N, 1, N s/mm) and Prony terms."""
    eff, new = ev.eff, {}
    if "jaw_compliance" in eff:
        new["jaw_compliance_mm_per_N"] = ev.nonneg("jaw_compliance", "compliance_mm_per_N")
    if "backlash" in eff:
        new["backlash_deg"] = ev.nonneg("backlash", "play_deg")
    if "mechanism_friction" in eff:
        new["friction_coulomb_N"] = ev.nonneg("mechanism_friction", "coulomb_N")
        new["friction_load_coefficient"] = ev.nonneg("mechanism_friction", "load_coefficient")
        new["friction_viscous_N_s_per_mm"] = ev.nonneg("mechanism_friction", "viscous_N_s_per_mm")
    if "tissue_viscoelasticity" in eff:
        gs, taus = [], []
        for spec, tau in zip(EFFECTS["tissue_viscoelasticity"].params, PRONY_TAUS_S):
            g = ev.nonneg("tissue_viscoelasticity", spec.name)
            if g > 0:
                gs.append(g)
                taus.append(float(tau))
        assert len(gs) <= MAX_PRONY_TERMS
        new["prony_g"] = tuple(gs)
        new["prony_tau_s"] = tuple(taus)
    return new


def _measurement(ev: _Effects) -> dict[str, float]:
    """``offset_N`` (N), ``gain`` (1), ``delay_s`` (s) of the measurement effects, and with a
    ``sensor_drift`` its ``offset_rate_N_per_s`` (N/s) and ``gain_rate_per_s`` (1/s)."""
    eff = ev.eff
    measurement = {"offset_N": 0.0, "gain": 1.0, "delay_s": 0.0}
    if "sensor_offset_gain" in eff:
        measurement["offset_N"] = float(eff["sensor_offset_gain"]["offset_N"])
        measurement["gain"] = float(eff["sensor_offset_gain"]["gain"])
    if "latency" in eff:
        measurement["delay_s"] = ev.nonneg("latency", "delay_s")
    if "sensor_drift" in eff:
        for k in ("offset_rate_N_per_s", "gain_rate_per_s"):
            measurement[k] = float(eff["sensor_drift"][k])
    return measurement


def controller_params_from_augmented(
    params: ControllerParams,
    model: AugmentedModel,
    surrogate: Surrogate | None = None,
) -> tuple[ControllerParams, dict[str, Any]]:
    """Controller parameters that render the instrument effects of an augmented model.

    The augmented model of ``grasprom diagnose`` describes the real instrument; the controller
    renders its instrument effects, so the diagnosis improves the controller (``grasprom
    simulate --augmented``, ``grasprom tune --augmented`` and the exports of the tuned
    parameters):

    ==========================  ===============================================================
    effect                      controller parameter (see :class:`ControllerParams`)
    ==========================  ===============================================================
    thickness_error             ``thickness_mm`` += ``offset_mm`` (clamped into the surrogate's
                                range when ``surrogate`` is given, as the diagnosis does)
    tissue_stiffness_scale      ``tissue_scale`` = ``scale``
    jaw_compliance              ``jaw_compliance_mm_per_N`` = ``compliance_mm_per_N``
    backlash                    ``backlash_deg`` = ``play_deg``
    mechanism_friction          ``friction_coulomb_N``, ``friction_load_coefficient``,
                                ``friction_viscous_N_s_per_mm``
    tissue_viscoelasticity      ``prony_g`` / ``prony_tau_s``: the non-zero ``g_i`` at
                                :data:`PRONY_TAUS_S`
    sensor_offset_gain          not rendered (a property of the force sensor): returned in
                                ``measurement`` (``offset_N``, ``gain``)
    sensor_drift                not rendered (a drift of the force sensor): ``measurement``
                                (``offset_rate_N_per_s``, ``gain_rate_per_s``)
    latency                     not rendered (a delay of the measurement): ``measurement``
                                (``delay_s``)
    ==========================  ===============================================================

    The model's chain replaces ``params.chain`` (``params.spring_k_N_per_mm`` is kept).  Fields of
    effects absent from the model are left as they are.  Values outside the controller's bounds
    (a negative friction or Prony coefficient, a non-positive scale) are clipped to the bound
    (a non-positive scale: left at 1) with a warning.

    Parameters
    ----------
    params : ControllerParams
        Parameters without the augmentation (``thickness_mm`` the nominal wall thickness, mm).
    model : AugmentedModel
    surrogate : Surrogate, optional
        For the thickness range of ``params.material``.

    Returns
    -------
    ControllerParams
        With the rendered effects.
    dict
        ``rendered`` and ``measurement_only`` (effect names), ``measurement`` (``offset_N`` N,
        ``gain`` 1, ``delay_s`` s; 0, 1, 0 when absent; with a ``sensor_drift`` also
        ``offset_rate_N_per_s`` N/s and ``gain_rate_per_s`` 1/s: apply them with
        :func:`measured_handle_force_N`), ``warnings`` (list of str).
    """
    eff = model.effects
    warn: list[str] = []
    _check_start(params, model, warn)
    ev = _Effects(eff, warn)
    new: dict[str, Any] = {"chain": model.chain}
    new.update(_tissue_fields(params, ev, surrogate))
    new.update(_mechanism_fields(ev))
    measurement = _measurement(ev)
    info = {
        "rendered": [e for e in EFFECT_ORDER if e in eff and e in RENDERED_EFFECTS],
        "measurement_only": [e for e in EFFECT_ORDER if e in eff and e in MEASUREMENT_EFFECTS],
        "measurement": measurement,
        "warnings": warn,
    }
    return replace(params, **new), info


def measured_handle_force_N(
    time_s: FloatArray, force_handle_N: FloatArray, measurement: dict[str, float]
) -> FloatArray:
    """What the force sensor of the augmented model would read: offset, gain, drift, latency.

    ``offset_N + r t + (gain + k t) F(t - delay_s)``, ``F`` interpolated linearly in time and
    held at its first value before the first sample; ``t`` the time since the first sample (s),
    ``r`` = ``offset_rate_N_per_s`` and ``k`` = ``gain_rate_per_s`` (0 when absent).

    Parameters
    ----------
    time_s : ndarray
        Sample times, s (increasing).
    force_handle_N : ndarray
        Handle force, N.
    measurement : dict
        ``offset_N`` (N), ``gain`` (1), ``delay_s`` (s), optionally ``offset_rate_N_per_s``
        (N/s) and ``gain_rate_per_s`` (1/s), as returned by
        :func:`controller_params_from_augmented`.

    Returns
    -------
    ndarray
        Measured handle force, N.
    """
    t = np.asarray(time_s, dtype=float)
    f = np.asarray(force_handle_N, dtype=float)
    d = float(measurement.get("delay_s", 0.0))
    if d > 0:
        f = np.interp(t - d, t, f)
    ts = t - t[0]
    offset = (
        float(measurement.get("offset_N", 0.0))
        + float(measurement.get("offset_rate_N_per_s", 0.0)) * ts
    )
    gain = float(measurement.get("gain", 1.0)) + float(measurement.get("gain_rate_per_s", 0.0)) * ts
    return offset + gain * f
