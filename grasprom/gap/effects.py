"""The candidate library of the diagnosis: which unmodelled effects are tried, in which block
of the chain each acts, and the parameters each is fitted with (names are a contract)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

BLOCKS = ("tissue", "mechanism", "sensor")
"""Blocks of the chain an effect (or a share of the gap) belongs to."""

PRONY_TAUS_S = (0.03, 0.2, 1.0, 5.0)
"""Fixed relaxation times of the Prony candidate (s)."""


@dataclass(frozen=True)
class ParamSpec:
    """One parameter of a candidate effect.

    Parameters
    ----------
    name : str
        Parameter name (units in the name or in ``unit``).
    unit : str
        Unit of the reported value.
    kind : {"linear", "nonlinear"}
        Linear parameters are solved by linear least squares, non-linear ones searched.
    lo, hi : float
        Bounds of the internal coefficient.
    offset : float
        Reported value = internal coefficient + offset (1 for scale and gain factors).
    grid : tuple of float
        Starting grid of a non-linear parameter.
    """

    name: str
    unit: str
    kind: str
    lo: float
    hi: float
    offset: float = 0.0
    grid: tuple[float, ...] = ()


@dataclass(frozen=True)
class EffectSpec:
    """A candidate effect: name, block of the chain, parameters and a one-line model."""

    name: str
    block: str
    params: tuple[ParamSpec, ...]
    model: str


EFFECTS: dict[str, EffectSpec] = {
    e.name: e
    for e in (
        EffectSpec(
            "tissue_viscoelasticity",
            "tissue",
            tuple(ParamSpec(f"g_{tau:g}s", "1", "linear", 0.0, 10.0) for tau in PRONY_TAUS_S),
            "quasi-linear viscoelastic Prony series on the surrogate (elastic = relaxed) force: "
            "Fg = Fe + sum_i g_i int exp(-(t-s)/tau_i) dFe(s), tau = 0.03, 0.2, 1, 5 s; the jaw "
            "force is clipped at 0 (the jaws cannot pull)",
        ),
        EffectSpec(
            "mechanism_friction",
            "mechanism",
            (
                ParamSpec("coulomb_N", "N", "linear", 0.0, 20.0),
                ParamSpec("load_coefficient", "1", "linear", 0.0, 2.0),
                ParamSpec("viscous_N_s_per_mm", "N s/mm", "linear", 0.0, 2.0),
            ),
            "Coulomb + load-proportional Coulomb + viscous friction at the finger: "
            "dFi = (Fc + mu |Fi_tissue|) s + b v, s = direction of the last finger motion, "
            "v finger speed (mm/s, > 0 closing)",
        ),
        EffectSpec(
            "backlash",
            "mechanism",
            (
                ParamSpec(
                    "play_deg",
                    "deg",
                    "nonlinear",
                    0.0,
                    1.2,
                    grid=(0.0, 0.03, 0.06, 0.1, 0.15, 0.22, 0.32, 0.5, 0.8),
                ),
            ),
            "play of total width b between the encoder and the linkage: the chain sees "
            "theta_eff = play(theta, b)",
        ),
        EffectSpec(
            "jaw_compliance",
            "mechanism",
            (
                ParamSpec(
                    "compliance_mm_per_N",
                    "mm/N",
                    "nonlinear",
                    0.0,
                    0.06,
                    grid=(0.0, 0.001, 0.002, 0.004, 0.007, 0.011, 0.017, 0.026, 0.04),
                ),
            ),
            "linear series compliance of jaw + mechanism: the real gap is g(theta) + C Fg, "
            "Fg = F_surrogate(g(theta) + C Fg)",
        ),
        EffectSpec(
            "thickness_error",
            "tissue",
            (
                ParamSpec(
                    "offset_mm",
                    "mm",
                    "nonlinear",
                    -0.4,
                    0.4,
                    grid=tuple(np.round(np.linspace(-0.35, 0.35, 11), 3)),
                ),
            ),
            "the real wall thickness is nominal + offset (clamped to the surrogate's range)",
        ),
        EffectSpec(
            "tissue_stiffness_scale",
            "tissue",
            (ParamSpec("scale", "1", "linear", -0.9, 5.0, offset=1.0),),
            "the tissue force is scale x the surrogate force",
        ),
        EffectSpec(
            "sensor_offset_gain",
            "sensor",
            (
                ParamSpec("offset_N", "N", "linear", -20.0, 20.0),
                ParamSpec("gain", "1", "linear", -0.5, 0.5, offset=1.0),
            ),
            "handle force sensor: F_meas = offset + gain x Fi",
        ),
        EffectSpec(
            "latency",
            "sensor",
            (
                ParamSpec(
                    "delay_s",
                    "s",
                    "nonlinear",
                    0.0,
                    0.15,
                    grid=(0.0, 0.004, 0.008, 0.014, 0.022, 0.032, 0.045, 0.065, 0.1),
                ),
            ),
            "time delay between the measured angle and the measured force: "
            "F_meas(t) = Fi(theta(t - d))",
        ),
        EffectSpec(
            "sensor_drift",
            "sensor",
            (
                ParamSpec("offset_rate_N_per_s", "N/s", "linear", -2.0, 2.0),
                ParamSpec("gain_rate_per_s", "1/s", "linear", -0.2, 0.2),
            ),
            "slow (thermal) drift of the handle force sensor from its zeroed, calibrated state "
            "at the first sample of the trial: F_meas = Fi + r t + k t Fi, t = time since the "
            "trial's first sample (s); r the offset drift (N/s), k the gain drift (1/s)",
        ),
    )
}
"""The candidate library (names are a contract)."""

EFFECT_ORDER = tuple(EFFECTS)
"""Canonical order of the effects (effect sets are sorted in it)."""


def linear_params(effects: Sequence[str]) -> list[tuple[str, ParamSpec]]:
    """``(effect, spec)`` of the linear parameters of an effect set, in the basis column order.

    Parameters
    ----------
    effects : sequence of str
        Effect names of :data:`EFFECTS`.

    Returns
    -------
    list of tuple
    """
    return [(e, p) for e in effects for p in EFFECTS[e].params if p.kind == "linear"]


def nonlinear_params(effects: Sequence[str]) -> list[tuple[str, ParamSpec]]:
    """``(effect, spec)`` of the non-linear (searched) parameters of an effect set, in order.

    Parameters
    ----------
    effects : sequence of str
        Effect names of :data:`EFFECTS`.

    Returns
    -------
    list of tuple
    """
    return [(e, p) for e in effects for p in EFFECTS[e].params if p.kind == "nonlinear"]


def n_params(effects: Sequence[str]) -> int:
    """Number of fitted parameters of an effect set (for the ``ln N`` penalty)."""
    return sum(len(EFFECTS[e].params) for e in effects)
