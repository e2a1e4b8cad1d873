r"""Truth models of the synthetic trials: one trial of the baseline instrument (derived chain of
:mod:`grasprom.chain.kinematics` and the FE surrogate) *plus* the withheld effects, measured with
sensor noise and encoder quantisation.

The effect models here are deliberately **richer than, and implemented independently of**, the
candidate models of the diagnosis (:mod:`grasprom.gap.model`; different code and different
physics), so that the blind benchmark does not measure a model recognising itself:

==========================  ===================================================================
truth effect                generator model (here)           vs. the diagnosis' candidate
==========================  ===================================================================
tissue_viscoelasticity      nonlinear quasi-linear viscoelasticity with a *power-law* relaxation
                            ``dG(t) = A (1 + t/tau)^-alpha`` acting on a strain-dependent
                            elastic response, by direct convolution (candidate: 3-term Prony)
mechanism_friction          LuGre (bristle state, Stribeck curve, presliding stiffness, viscous
                            term, load-dependent Coulomb level) integrated at the sample rate
                            (candidate: Coulomb + load term + viscous, no state)
backlash                    play on the *rod stroke* (mm), so the equivalent handle play varies
                            along the stroke; mapped back through the chain (candidate: play on
                            the handle angle)
jaw_compliance              nonlinear (stiffening) jaw deflection ``delta = c F^p``, p < 1
                            (candidate: linear series compliance)
thickness_error             common wall-thickness error plus a small per-specimen scatter
                            (candidate: one common offset)
tissue_stiffness_scale      gap-dependent scale, one factor in bending and another where the
                            walls meet, smooth transition (candidate: one factor)
sensor_offset_gain          offset, gain, linear drift and a small quadratic non-linearity
                            (candidate: offset + gain)
latency                     pure delay plus a first-order sensor lag (candidate: pure delay)
sensor_drift                thermal drift of zero and sensitivity from the zeroed sensor at the
                            trial's start, levelling off as a first-order approach
                            ``r tau (1 - exp(-t/tau))`` (candidate: linear in time)
motor_cogging               **outside the library**: handle-force ripple periodic in the motor
                            angle (12 cogs per motor turn, 5.41 motor turns per handle radian)
==========================  ===================================================================

Measured channels: ``theta_deg`` quantised by a 14-bit motor encoder through the 5.41:1 pulley
(0.0041 deg), ``force_handle_N`` with white noise (0.03-0.12 N), ``force_jaw_N`` (a jaw load
cell, optional, on by default) with its own noise, and ``gap_mm`` (optional, off by default): the
jaw gap where the tissue is, as a non-contact laser triangulation displacement sensor across the
jaw tips would measure it -- the kinematic gap of the linkage angle after the truth backlash
(play on the rod stroke) plus the truth jaw deflection ``c F^p`` at the true jaw force, with white
noise of 5-10 um rms (:data:`grasprom.gap.synth.GAP_NOISE_MM`) and a 1 um resolution
(:data:`GAP_RESOLUTION_MM`).  Time base :data:`SAMPLE_RATE_HZ` (1 kHz) by default, any rate in
:data:`RATE_RANGE_HZ` on request: the time grid, the angle profile, the tremor filter, the LuGre
integration, the sensor lag and the drifts follow the rate, and the sensor noise is white at
every sample (the same rms per sample at every rate).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from numbers import Real
from typing import Any

import numpy as np
import pandas as pd
from scipy.signal import fftconvolve, lfilter

from grasprom.chain import kinematics as kin
from grasprom.surrogate import Surrogate

SAMPLE_RATE_HZ = 1000.0
"""Default sample rate of the synthetic trials (Hz)."""
RATE_RANGE_HZ = (100.0, 20000.0)
"""Accepted sample rates of the synthetic trials (Hz, inclusive)."""
ENCODER_COUNTS_PER_REV = 16384  # 14-bit motor encoder
PULLEY_RADIUS_MM = 10.0
GAP_RESOLUTION_MM = 0.001
"""Resolution of the ``gap_mm`` channel (mm)."""


@dataclass
class TrialSpec:
    """Conditions of one synthetic trial (mm, s, N)."""

    thickness_mm: float
    material: str
    close_s: float
    hold_s: float
    open_s: float
    pre_s: float
    post_s: float
    target_jaw_N: float


def check_rate_hz(rate_hz: float) -> float:
    """``rate_hz`` (Hz) as a float, or a ValueError unless it is a finite number within
    :data:`RATE_RANGE_HZ`."""
    lo, hi = RATE_RANGE_HZ
    ok = isinstance(rate_hz, Real) and not isinstance(rate_hz, bool)
    if not (ok and math.isfinite(rate_hz) and lo <= rate_hz <= hi):
        raise ValueError(f"rate_hz: must be a sample rate of {lo:g} to {hi:g} Hz, got {rate_hz!r}")
    return float(rate_hz)


# ----------------------------------------------------------------------------- elements
def play(x: np.ndarray, width: float) -> np.ndarray:
    """Output of a play (backlash) element of total width ``width`` driven by ``x``."""
    out = np.empty_like(x)
    y = float(x[0])
    h = 0.5 * width
    for i, xi in enumerate(x.tolist()):
        if xi - y > h:
            y = xi - h
        elif y - xi > h:
            y = xi + h
        out[i] = y
    return out


def lugre(v_mm_s: np.ndarray, load_N: np.ndarray, p: dict[str, float], dt: float) -> np.ndarray:
    """LuGre friction force (N, resisting the finger velocity ``v`` in mm/s)."""
    s0 = p["bristle_N_per_mm"]
    s1 = p["bristle_damping_N_s_per_mm"]
    s2 = p["viscous_N_s_per_mm"]
    fc, fs, vs, mu = p["coulomb_N"], p["static_N"], p["stribeck_mm_per_s"], p["load_coefficient"]
    z = 0.0
    out = np.empty_like(v_mm_s)
    for i, (v, ld) in enumerate(zip(v_mm_s.tolist(), load_N.tolist())):
        scale = 1.0 + mu * abs(ld) / max(fc, 1e-9)
        g = scale * (fc + (fs - fc) * math.exp(-((v / vs) ** 2)))
        if v != 0.0:
            zss = g / s0 * (1.0 if v > 0 else -1.0)
            z = zss + (z - zss) * math.exp(-s0 * abs(v) * dt / g)
        zdot = v - s0 * abs(v) * z / g
        out[i] = s0 * z + s1 * zdot + s2 * v
    return out


def compliant_jaw_force(
    elastic: Callable[[np.ndarray], np.ndarray],
    g_kin: np.ndarray,
    c: float,
    p_exp: float,
    f_max: np.ndarray,
) -> np.ndarray:
    """Jaw force with a stiffening jaw deflection ``delta = c F^p``: F = elastic(g + delta)."""
    lo = np.zeros_like(g_kin)
    hi = np.maximum(f_max, 0.0)
    for _ in range(50):  # bisection: F - elastic(g + c F^p) is increasing in F
        mid = 0.5 * (lo + hi)
        r = mid - elastic(g_kin + c * np.power(mid, p_exp))
        lo = np.where(r < 0, mid, lo)
        hi = np.where(r < 0, hi, mid)
    return 0.5 * (lo + hi)


def _segment_samples(spec: TrialSpec, rate_hz: float) -> tuple[int, int, int, int, int]:
    """Samples of the open, closing, hold, opening and open segments at ``rate_hz`` (Hz)."""
    return (
        int(spec.pre_s * rate_hz),
        max(int(round(spec.close_s * rate_hz)), 1),
        int(spec.hold_s * rate_hz),
        max(int(round(spec.open_s * rate_hz)), 1),
        int(spec.post_s * rate_hz),
    )


def trial_samples(spec: TrialSpec, rate_hz: float = SAMPLE_RATE_HZ) -> int:
    """Number of samples of a trial of conditions ``spec`` at ``rate_hz`` (Hz)."""
    return sum(_segment_samples(spec, check_rate_hz(rate_hz)))


def theta_profile(
    spec: TrialSpec, theta_min: float, chain: kin.ChainParams, rate_hz: float = SAMPLE_RATE_HZ
) -> np.ndarray:
    """Handle angle (deg) sampled at ``rate_hz`` (Hz): open, cosine close to ``theta_min``,
    hold, reopen, open (:func:`trial_samples` samples)."""
    hi = chain.theta_open_deg
    pre, close, hold, open_, post = _segment_samples(spec, check_rate_hz(rate_hz))

    def ramp(a: float, b: float, m: int) -> np.ndarray:
        s = np.arange(m) / m
        return a + (b - a) * 0.5 * (1 - np.cos(np.pi * s))

    parts = [
        np.full(pre, hi),
        ramp(hi, theta_min, close),
        np.full(hold, theta_min),
        ramp(theta_min, hi, open_),
        np.full(post, hi),
    ]
    return np.concatenate(parts)


TREMOR_BAND_HZ = (6.0, 12.0)
"""Band of the synthetic hand tremor (physiological tremor, Hz)."""

HAND_STIFFNESS_N_PER_MM = 0.5
"""Stiffness of the hand at the finger loop (N/mm; pinch-grip finger stiffness is of the order
of 0.2-1 N/mm at low force): the tremor is a displacement in free motion and is held back by the
tissue where the handle is stiffer than the hand."""


def with_tremor(
    theta: np.ndarray,
    rms_deg: float,
    rng: np.random.Generator,
    chain: kin.ChainParams,
    handle_stiffness_N_per_deg: np.ndarray,
    rate_hz: float = SAMPLE_RATE_HZ,
) -> np.ndarray:
    """``theta`` (deg, sampled at ``rate_hz`` Hz) with band-limited hand tremor of ``rms_deg``
    (deg RMS in free motion, 6-12 Hz).

    Zero-phase 4th-order Butterworth band-pass of white noise from ``rng``, scaled by
    ``1 / (1 + S / k_hand)`` with the handle's static stiffness ``S`` (N per deg of handle at
    the finger, per sample) and the hand's stiffness ``k_hand``
    (:data:`HAND_STIFFNESS_N_PER_MM` at the finger loop); faded out within 2 deg of the open end
    stop (the hand rests on it) and clipped to the chain's angle range.
    """
    if rms_deg <= 0:
        return theta
    from scipy.signal import butter, sosfiltfilt

    sos = butter(4, TREMOR_BAND_HZ, "bandpass", fs=check_rate_hz(rate_hz), output="sos")
    tremor = sosfiltfilt(sos, rng.standard_normal(theta.size))
    tremor *= rms_deg / max(float(tremor.std()), 1e-12)
    k_hand = HAND_STIFFNESS_N_PER_MM * chain.L3_mm * math.pi / 180.0  # N per deg
    fade = np.clip((chain.theta_open_deg - theta) / 2.0, 0.0, 1.0)
    fade = fade / (1.0 + np.abs(handle_stiffness_N_per_deg) / k_hand)
    return np.clip(theta + fade * tremor, chain.theta_closed_deg, chain.theta_open_deg)


# ----------------------------------------------------------------------------- one trial
@dataclass
class _JawLaw:
    """The true static jaw force of one trial as a function of the kinematic gap (mm -> N)."""

    surrogate: Surrogate
    chain: kin.ChainParams
    material: str
    t_real: float  # real wall thickness (mm)
    scale: dict[str, float] | None  # tissue_stiffness_scale truth
    jaw: dict[str, float] | None  # jaw_compliance truth
    c_jaw: float = 0.0  # deflection coefficient (mm / N^p)

    def elastic(self, g: np.ndarray) -> np.ndarray:
        """Tissue force (N) at the real gap ``g`` (mm)."""
        chain, sc = self.chain, self.scale
        g_c = 2.0 * self.t_real  # where the inner walls meet (FE: ~2 t)
        f = self.surrogate.force(
            np.clip(g, chain.gap_closed_mm * 0.5, None), self.t_real, self.material
        )
        if sc is not None:
            w = 1.0 / (1.0 + np.exp((g - g_c) / 0.15))  # 1 where the walls meet, 0 in bending
            f = f * (sc["scale_bending"] * (1 - w) + sc["scale_compaction"] * w)
        return np.asarray(f, dtype=float)

    def static(self, g_kin: np.ndarray) -> np.ndarray:
        """Jaw force (N) at the kinematic gap ``g_kin`` (mm), jaw deflection included."""
        f0 = self.elastic(g_kin)
        if self.jaw is None:
            return f0
        return compliant_jaw_force(self.elastic, g_kin, self.c_jaw, self.jaw["exponent"], f0)


def _jaw_law(
    spec: TrialSpec,
    effects: dict[str, dict[str, float]],
    surrogate: Surrogate,
    chain: kin.ChainParams,
    rng: np.random.Generator,
) -> _JawLaw:
    """The trial's real wall thickness (draws its scatter from ``rng``) and jaw force law."""
    lo_t, hi_t = surrogate.thickness_range(spec.material)
    t_real = spec.thickness_mm
    if "thickness_error" in effects:
        e = effects["thickness_error"]
        t_real += e["offset_mm"] + e["scatter_mm"] * rng.standard_normal()
    t_real = min(max(t_real, lo_t), hi_t)
    jc = effects.get("jaw_compliance")
    law = _JawLaw(
        surrogate, chain, spec.material, t_real, effects.get("tissue_stiffness_scale"), jc
    )
    if jc is not None:
        law.c_jaw = jc["deflection_at_20N_mm"] / 20.0 ** jc["exponent"]
    return law


def _squeeze_angle(
    law: _JawLaw, spec: TrialSpec, surrogate: Surrogate, chain: kin.ChainParams
) -> float:
    """Handle angle (deg) at the end of the squeeze: the operator squeezes to a target force."""
    gaps = np.linspace(chain.gap_closed_mm, surrogate.diameter_mm, 4000)
    fj = law.static(gaps)
    above = np.flatnonzero(fj >= spec.target_jaw_N)
    g_min = gaps[above[-1]] if above.size else chain.gap_closed_mm
    return float(kin.theta_from_gap_deg(float(g_min), chain))


def _linkage_angle(
    theta: np.ndarray, effects: dict[str, dict[str, float]], chain: kin.ChainParams
) -> np.ndarray:
    """Angle (deg) of the linkage: backlash on the rod stroke, the jaws follow through a play."""
    if "backlash" not in effects:
        return theta
    u = np.asarray(kin.spring_dx_mm(theta, chain))
    u_eff = np.clip(play(u, effects["backlash"]["rod_play_mm"]), 0.0, chain.rod_stroke_mm)
    g_eff = chain.gap_closed_mm + (chain.gap_open_mm - chain.gap_closed_mm) * (
        1.0 - u_eff / chain.rod_stroke_mm
    )
    return np.asarray(kin.theta_from_gap_deg(g_eff, chain))


def _relaxing_jaw_force(
    f_el: np.ndarray, time: np.ndarray, effects: dict[str, dict[str, float]]
) -> np.ndarray:
    """Jaw force (N) with the power-law viscoelastic relaxation (>= 0)."""
    if "tissue_viscoelasticity" not in effects:
        return f_el
    v = effects["tissue_viscoelasticity"]
    n = f_el.size
    fref = 10.0
    h = f_el * (1.0 + v["strain_nonlinearity"] * f_el / (f_el + fref))
    kern = v["relax_amplitude"] * (1.0 + time / v["tau_s"]) ** (-v["alpha"])
    dh = np.diff(h, prepend=0.0)
    f_jaw = f_el + fftconvolve(dh, kern)[:n]
    return np.maximum(f_jaw, 0.0)


def _true_handle_force(
    theta: np.ndarray,
    theta_eff: np.ndarray,
    f_jaw: np.ndarray,
    effects: dict[str, dict[str, float]],
    chain: kin.ChainParams,
    dt: float,
) -> np.ndarray:
    """Handle force (N) of the chain with LuGre friction and motor cogging."""
    fi = np.asarray(kin.handle_force_N(f_jaw, theta_eff, chain), dtype=float)
    if "mechanism_friction" in effects:
        v_mm_s = -chain.L3_mm * np.gradient(np.radians(theta), dt)  # > 0 closing
        load = f_jaw * np.asarray(kin.dgap_dtheta_mm_per_rad(theta_eff, chain)) / chain.L3_mm
        fi = fi + lugre(v_mm_s, load, effects["mechanism_friction"], dt)
    if "motor_cogging" in effects:
        cg = effects["motor_cogging"]
        motor_rad = np.radians(theta) * chain.L3_mm / PULLEY_RADIUS_MM
        fi = fi + cg["amplitude_N"] * np.sin(cg["cogs_per_rev"] * motor_rad + cg["phase_rad"])
    return fi


def thermal_drift(time: np.ndarray, rate: float, tau_s: float) -> np.ndarray:
    """Drift of a first-order thermal approach with initial ``rate`` (per s) and time constant
    ``tau_s`` (s): ``rate tau (1 - exp(-t / tau))``, in the units of ``rate`` x s."""
    return rate * tau_s * -np.expm1(-(time - time[0]) / tau_s)


def _drifting_reading(fi: np.ndarray, time: np.ndarray, p: dict[str, float]) -> np.ndarray:
    """Reading (N) of a sensor zeroed and calibrated at the first sample whose zero and
    sensitivity then drift (:func:`thermal_drift`; ``offset_rate_N_per_s`` N/s,
    ``gain_rate_per_s`` 1/s, ``thermal_tau_s`` s)."""
    tau = p["thermal_tau_s"]
    offset = thermal_drift(time, p["offset_rate_N_per_s"], tau)
    gain = 1.0 + thermal_drift(time, p["gain_rate_per_s"], tau)
    return offset + gain * fi


def _sensor_reading(
    fi: np.ndarray, time: np.ndarray, effects: dict[str, dict[str, float]], dt: float
) -> np.ndarray:
    """Noise-free handle force sensor reading (N): lag, delay, thermal drift, offset, gain,
    drift, quadratic."""
    if "latency" in effects:
        la = effects["latency"]
        a = math.exp(-dt / la["lag_s"])
        fi = lfilter([1 - a], [1, -a], fi, zi=[a * fi[0]])[0]
        fi = np.interp(time - la["delay_s"], time, fi)
    if "sensor_drift" in effects:
        fi = _drifting_reading(fi, time, effects["sensor_drift"])
    if "sensor_offset_gain" in effects:
        so = effects["sensor_offset_gain"]
        fi = (
            so["offset_N"]
            + so["drift_N_per_s"] * time
            + (1.0 + so["gain"]) * fi
            + so["quadratic_per_N"] * fi * fi
        )
    return fi


def _add_gap_channel(
    df: pd.DataFrame,
    info: dict[str, Any],
    g_kin: np.ndarray,
    f_jaw: np.ndarray,
    law: _JawLaw,
    gap_noise: tuple[np.random.Generator, float],
) -> None:
    """Add ``gap_mm`` (mm) to the table and the largest jaw deflection (mm) to ``info``."""
    # the gap the tissue sees: kinematic gap after the play + the stiffening jaw deflection
    # at the true jaw force (rate-dependent part included)
    g_true = g_kin.copy()
    if law.jaw is not None:
        g_true = g_true + law.c_jaw * np.power(np.maximum(f_jaw, 0.0), law.jaw["exponent"])
    grng, gsig = gap_noise
    g_meas = g_true + gsig * grng.standard_normal(g_kin.size)
    df["gap_mm"] = GAP_RESOLUTION_MM * np.round(g_meas / GAP_RESOLUTION_MM)
    info["max_jaw_deflection_mm"] = float(np.max(g_true - g_kin))


def _handle_stiffness(theta: np.ndarray, law: _JawLaw, chain: kin.ChainParams) -> np.ndarray:
    """Static stiffness of the handle (N per deg at the finger) along ``theta`` (deg): the
    true tissue through the chain, central difference over 1e-3 deg."""
    d = 1e-3
    lo = np.clip(theta - d, chain.theta_closed_deg, chain.theta_open_deg)
    hi = np.clip(theta + d, chain.theta_closed_deg, chain.theta_open_deg)

    def fi(th: np.ndarray) -> np.ndarray:
        return np.asarray(
            kin.handle_force_N(law.static(np.asarray(kin.gap_mm(th, chain))), th, chain)
        )

    s = (fi(hi) - fi(lo)) / np.maximum(hi - lo, 1e-12)
    return np.nan_to_num(s, nan=0.0, posinf=0.0, neginf=0.0)


def simulate_trial(
    spec: TrialSpec,
    effects: dict[str, dict[str, float]],
    surrogate: Surrogate,
    chain: kin.ChainParams,
    rng: np.random.Generator,
    noise_N: float,
    jaw_noise_N: float,
    gap_noise: tuple[np.random.Generator, float] | None = None,
    tremor: tuple[np.random.Generator, float] | None = None,
    rate_hz: float = SAMPLE_RATE_HZ,
    noise_rng: np.random.Generator | None = None,
) -> tuple[pd.DataFrame, dict[str, Any]]:
    """One trial sampled at ``rate_hz`` (Hz, :data:`RATE_RANGE_HZ`): measured table and truth
    info.

    ``gap_noise`` = (its own generator, rms in mm) adds the ``gap_mm`` channel; ``tremor`` =
    (its own generator, rms in deg) adds hand tremor to the angle (:func:`with_tremor`);
    ``rng`` is touched by neither.  ``rng`` draws the thickness scatter, then the white noise
    of the handle and jaw force channels (``noise_N``, ``jaw_noise_N`` N rms per sample,
    :func:`trial_samples` draws each) unless ``noise_rng`` is given, which then draws that
    noise instead.
    """
    rate_hz = check_rate_hz(rate_hz)
    dt = 1.0 / rate_hz
    law = _jaw_law(spec, effects, surrogate, chain, rng)
    theta_min = _squeeze_angle(law, spec, surrogate, chain)
    theta = theta_profile(spec, theta_min, chain, rate_hz)
    if tremor is not None:
        theta = with_tremor(
            theta, tremor[1], tremor[0], chain, _handle_stiffness(theta, law, chain), rate_hz
        )
    n = theta.size
    time = dt * np.arange(n)
    theta_eff = _linkage_angle(theta, effects, chain)
    g_kin = np.asarray(kin.gap_mm(theta_eff, chain))
    f_jaw = _relaxing_jaw_force(law.static(g_kin), time, effects)
    fi = _true_handle_force(theta, theta_eff, f_jaw, effects, chain, dt)
    fi = _sensor_reading(fi, time, effects, dt)
    nrng = rng if noise_rng is None else noise_rng
    fi_meas = fi + noise_N * nrng.standard_normal(n)
    fj_meas = f_jaw + jaw_noise_N * nrng.standard_normal(n)
    q = 360.0 * PULLEY_RADIUS_MM / (ENCODER_COUNTS_PER_REV * chain.L3_mm)  # deg per count
    th_meas = np.clip(q * np.round(theta / q), chain.theta_closed_deg, chain.theta_open_deg)
    df = pd.DataFrame(
        {
            "time_s": np.round(time, 6),
            "theta_deg": th_meas,
            "force_handle_N": fi_meas,
            "force_jaw_N": fj_meas,
        }
    )
    info = {"thickness_real_mm": law.t_real, "theta_min_deg": theta_min}
    if gap_noise is not None:
        _add_gap_channel(df, info, g_kin, f_jaw, law, gap_noise)
    return df, info
