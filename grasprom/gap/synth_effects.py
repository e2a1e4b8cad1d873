"""The effects a synthetic trial can withhold (in and outside the diagnosis' library) and their
random truth parameters."""

from __future__ import annotations

import math

import numpy as np

LIBRARY_EFFECTS = (
    "tissue_viscoelasticity",
    "mechanism_friction",
    "backlash",
    "jaw_compliance",
    "thickness_error",
    "tissue_stiffness_scale",
    "sensor_offset_gain",
    "latency",
    "sensor_drift",
)
"""Effects the diagnosis has a candidate for (names of :data:`grasprom.gap.EFFECTS`)."""

OUT_OF_LIBRARY_EFFECTS = ("motor_cogging",)
"""Effects the diagnosis has no candidate for."""

SYNTH_EFFECTS = LIBRARY_EFFECTS + OUT_OF_LIBRARY_EFFECTS


def _loguniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _signed(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.choice([-1.0, 1.0]) * rng.uniform(lo, hi))


def random_effect_params(name: str, rng: np.random.Generator) -> dict[str, float]:
    """Random truth parameters of one effect (units in the key names).

    Ranges are chosen so that the effect is clearly above the sensor noise in typical trials.

    Parameters
    ----------
    name : str
        One of :data:`SYNTH_EFFECTS`.
    rng : numpy.random.Generator

    Returns
    -------
    dict
        Parameter name -> value.
    """
    if name == "tissue_viscoelasticity":
        return {
            "relax_amplitude": rng.uniform(0.3, 0.9),  # instantaneous excess / elastic, 1
            "tau_s": _loguniform(rng, 0.05, 0.6),
            "alpha": rng.uniform(0.4, 1.0),
            "strain_nonlinearity": rng.uniform(0.0, 0.5),  # extra relaxing share at high load
        }
    if name == "mechanism_friction":
        fc = rng.uniform(0.3, 1.2)
        return {
            "coulomb_N": fc,
            "static_N": fc * rng.uniform(1.1, 1.5),
            "stribeck_mm_per_s": rng.uniform(1.0, 5.0),
            "bristle_N_per_mm": _loguniform(rng, 30.0, 300.0),
            "bristle_damping_N_s_per_mm": rng.uniform(0.05, 0.3),
            "viscous_N_s_per_mm": rng.uniform(0.0, 0.02),
            "load_coefficient": rng.uniform(0.0, 0.06),
        }
    if name == "backlash":
        return {"rod_play_mm": rng.uniform(0.006, 0.02)}  # ~0.1-0.35 deg of handle
    if name == "jaw_compliance":
        return {
            "deflection_at_20N_mm": rng.uniform(0.06, 0.25),
            "exponent": rng.uniform(0.6, 0.95),
        }
    if name == "thickness_error":
        return {"offset_mm": _signed(rng, 0.05, 0.15), "scatter_mm": rng.uniform(0.0, 0.01)}
    if name == "tissue_stiffness_scale":
        s = math.exp(_signed(rng, math.log(1.25), math.log(1.8)))
        return {"scale_bending": s, "scale_compaction": s * rng.uniform(0.85, 1.15)}
    if name == "sensor_offset_gain":
        return {
            "offset_N": _signed(rng, 0.15, 0.6),
            "gain": _signed(rng, 0.04, 0.15),
            "drift_N_per_s": rng.uniform(-0.01, 0.01),
            "quadratic_per_N": rng.uniform(-2e-4, 2e-4),
        }
    if name == "latency":
        return {"delay_s": rng.uniform(0.008, 0.04), "lag_s": rng.uniform(0.001, 0.006)}
    if name == "sensor_drift":
        return {
            "offset_rate_N_per_s": _signed(rng, 0.04, 0.15),  # initial zero drift
            "gain_rate_per_s": _signed(rng, 0.004, 0.02),  # initial sensitivity drift
            "thermal_tau_s": rng.uniform(15.0, 60.0),  # the drifts level off with this time
        }
    if name == "motor_cogging":
        return {
            "amplitude_N": rng.uniform(0.3, 1.0),
            "cogs_per_rev": 12.0,
            "phase_rad": rng.uniform(0.0, 2 * math.pi),
        }
    raise ValueError(f"unknown synthetic effect {name!r}; valid: {', '.join(SYNTH_EFFECTS)}")
