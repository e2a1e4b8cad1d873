r"""Synthetic "real" grasp trials with withheld unmodelled effects (the diagnosis' test bench).

A trial is the baseline instrument model (derived chain of :mod:`grasprom.kinematics` and the FE
surrogate) *plus* one or two effects at random parameters, sensor noise and encoder
quantisation.  The effect identities and parameters go to a separate ``truth.json`` that the
diagnosis never reads.

The effect models here are deliberately **richer than, and implemented independently of**, the
candidate models of :mod:`grasprom.diagnosis` (different code and different physics), so that the
blind benchmark does not measure a model recognising itself:

==========================  ===================================================================
truth effect                generator model (here)           vs. the diagnosis' candidate
==========================  ===================================================================
tissue_viscoelasticity      nonlinear quasi-linear viscoelasticity with a *power-law* relaxation
                            ``dG(t) = A (1 + t/tau)^-alpha`` acting on a strain-dependent
                            elastic response, by direct convolution (candidate: 3-term Prony)
mechanism_friction          LuGre (bristle state, Stribeck curve, presliding stiffness, viscous
                            term, load-dependent Coulomb level) integrated at 1 kHz
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
motor_cogging               **outside the library**: handle-force ripple periodic in the motor
                            angle (12 cogs per motor turn, 5.41 motor turns per handle radian)
==========================  ===================================================================

Measured channels: ``theta_deg`` quantised by a 14-bit motor encoder through the 5.41:1 pulley
(0.0041 deg), ``force_handle_N`` with white noise (0.03-0.12 N), ``force_jaw_N`` (a jaw load
cell, optional, on by default) with its own noise, and ``gap_mm`` (optional, off by default): the
jaw gap where the tissue is, as a non-contact laser triangulation displacement sensor across the
jaw tips would measure it -- the kinematic gap of the linkage angle after the truth backlash
(play on the rod stroke) plus the truth jaw deflection ``c F^p`` at the true jaw force, with white
noise of 5-10 um rms (:data:`GAP_NOISE_MM`) and a 1 um resolution (:data:`GAP_RESOLUTION_MM`).
The gap noise comes from its own random stream (seeded from the case seed), so switching the
channel on or off changes no other value of a case.  Time base 1 kHz.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy.signal import fftconvolve, lfilter

from grasprom.chain import kinematics as kin
from grasprom.surrogate import Surrogate

LIBRARY_EFFECTS = (
    "tissue_viscoelasticity",
    "mechanism_friction",
    "backlash",
    "jaw_compliance",
    "thickness_error",
    "tissue_stiffness_scale",
    "sensor_offset_gain",
    "latency",
)
"""Effects the diagnosis has a candidate for (names of :data:`grasprom.gap.diagnosis.EFFECTS`)."""

OUT_OF_LIBRARY_EFFECTS = ("motor_cogging",)
"""Effects the diagnosis has no candidate for."""

SYNTH_EFFECTS = LIBRARY_EFFECTS + OUT_OF_LIBRARY_EFFECTS

SAMPLE_RATE_HZ = 1000.0
ENCODER_COUNTS_PER_REV = 16384  # 14-bit motor encoder
PULLEY_RADIUS_MM = 10.0
GAP_NOISE_MM = (0.005, 0.010)
"""Range of the white noise (rms, mm) of the ``gap_mm`` channel (drawn per case)."""
GAP_RESOLUTION_MM = 0.001
"""Resolution of the ``gap_mm`` channel (mm)."""
_GAP_STREAM = 0x6A9
"""Second seed word of the ``gap_mm`` channel's own random stream."""


@dataclass
class SynthTrial:
    """One synthetic trial: the measured table and its sidecar (what the diagnosis sees)."""

    data: pd.DataFrame
    sidecar: dict[str, Any]


@dataclass
class SynthCase:
    """A set of trials of one instrument and specimen series, with the withheld truth."""

    trials: list[SynthTrial]
    truth: dict[str, Any] = field(default_factory=dict)


# ----------------------------------------------------------------------------- random truths
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
    if name == "motor_cogging":
        return {
            "amplitude_N": rng.uniform(0.3, 1.0),
            "cogs_per_rev": 12.0,
            "phase_rad": rng.uniform(0.0, 2 * math.pi),
        }
    raise ValueError(f"unknown synthetic effect {name!r}; valid: {', '.join(SYNTH_EFFECTS)}")


# ----------------------------------------------------------------------------- truth models
def _play(x: np.ndarray, width: float) -> np.ndarray:
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


def _lugre(v_mm_s: np.ndarray, load_N: np.ndarray, p: dict[str, float], dt: float) -> np.ndarray:
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


def _compliant_force(
    elastic, g_kin: np.ndarray, c: float, p_exp: float, f_max: np.ndarray
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


@dataclass
class _Spec:
    thickness_mm: float
    material: str
    close_s: float
    hold_s: float
    open_s: float
    pre_s: float
    post_s: float
    target_jaw_N: float


def _theta_profile(spec: _Spec, theta_min: float, chain: kin.ChainParams) -> np.ndarray:
    hi = chain.theta_open_deg

    def ramp(a: float, b: float, dur: float) -> np.ndarray:
        m = max(int(round(dur * SAMPLE_RATE_HZ)), 1)
        s = np.arange(m) / m
        return a + (b - a) * 0.5 * (1 - np.cos(np.pi * s))

    parts = [
        np.full(int(spec.pre_s * SAMPLE_RATE_HZ), hi),
        ramp(hi, theta_min, spec.close_s),
        np.full(int(spec.hold_s * SAMPLE_RATE_HZ), theta_min),
        ramp(theta_min, hi, spec.open_s),
        np.full(int(spec.post_s * SAMPLE_RATE_HZ), hi),
    ]
    return np.concatenate(parts)


def _simulate_truth(
    spec: _Spec,
    effects: dict[str, dict[str, float]],
    surrogate: Surrogate,
    chain: kin.ChainParams,
    rng: np.random.Generator,
    noise_N: float,
    jaw_noise_N: float,
    gap_noise: tuple[np.random.Generator, float] | None = None,
) -> tuple[pd.DataFrame, dict[str, Any]]:
    """One trial: measured table and truth info.

    ``gap_noise`` = (its own generator, rms in mm) adds the ``gap_mm`` channel; ``rng`` is not
    touched by it.
    """
    dt = 1.0 / SAMPLE_RATE_HZ
    lo_t, hi_t = surrogate.thickness_range(spec.material)
    t_real = spec.thickness_mm
    if "thickness_error" in effects:
        e = effects["thickness_error"]
        t_real += e["offset_mm"] + e["scatter_mm"] * rng.standard_normal()
    t_real = min(max(t_real, lo_t), hi_t)
    g_c = 2.0 * t_real  # where the inner walls meet (FE: ~2 t)
    sc = effects.get("tissue_stiffness_scale")

    def elastic(g: np.ndarray) -> np.ndarray:
        f = surrogate.force(np.clip(g, chain.gap_closed_mm * 0.5, None), t_real, spec.material)
        if sc is not None:
            w = 1.0 / (1.0 + np.exp((g - g_c) / 0.15))  # 1 where the walls meet, 0 in bending
            f = f * (sc["scale_bending"] * (1 - w) + sc["scale_compaction"] * w)
        return np.asarray(f, dtype=float)

    jc = effects.get("jaw_compliance")
    if jc is not None:
        c_jaw = jc["deflection_at_20N_mm"] / 20.0 ** jc["exponent"]

    def jaw_static(g_kin: np.ndarray) -> np.ndarray:
        f0 = elastic(g_kin)
        if jc is None:
            return f0
        return _compliant_force(elastic, g_kin, c_jaw, jc["exponent"], f0)

    # handle angle at the end of the squeeze: the operator squeezes to a target jaw force
    gaps = np.linspace(chain.gap_closed_mm, surrogate.diameter_mm, 4000)
    fj = jaw_static(gaps)
    above = np.flatnonzero(fj >= spec.target_jaw_N)
    g_min = gaps[above[-1]] if above.size else chain.gap_closed_mm
    theta_min = float(kin.theta_from_gap_deg(float(g_min), chain))
    theta = _theta_profile(spec, theta_min, chain)
    n = theta.size
    time = dt * np.arange(n)

    # backlash on the rod stroke: the jaws follow the rod end through a play
    theta_eff = theta
    if "backlash" in effects:
        u = np.asarray(kin.spring_dx_mm(theta, chain))
        u_eff = np.clip(_play(u, effects["backlash"]["rod_play_mm"]), 0.0, chain.rod_stroke_mm)
        g_eff = chain.gap_closed_mm + (chain.gap_open_mm - chain.gap_closed_mm) * (
            1.0 - u_eff / chain.rod_stroke_mm
        )
        theta_eff = np.asarray(kin.theta_from_gap_deg(g_eff, chain))
    g_kin = np.asarray(kin.gap_mm(theta_eff, chain))
    f_el = jaw_static(g_kin)

    if "tissue_viscoelasticity" in effects:
        v = effects["tissue_viscoelasticity"]
        fref = 10.0
        h = f_el * (1.0 + v["strain_nonlinearity"] * f_el / (f_el + fref))
        kern = v["relax_amplitude"] * (1.0 + time / v["tau_s"]) ** (-v["alpha"])
        dh = np.diff(h, prepend=0.0)
        f_jaw = f_el + fftconvolve(dh, kern)[:n]
        f_jaw = np.maximum(f_jaw, 0.0)
    else:
        f_jaw = f_el

    fi = np.asarray(kin.handle_force_N(f_jaw, theta_eff, chain), dtype=float)
    if "mechanism_friction" in effects:
        v_mm_s = -chain.L3_mm * np.gradient(np.radians(theta), dt)  # > 0 closing
        load = f_jaw * np.asarray(kin.dgap_dtheta_mm_per_rad(theta_eff, chain)) / chain.L3_mm
        fi = fi + _lugre(v_mm_s, load, effects["mechanism_friction"], dt)
    if "motor_cogging" in effects:
        cg = effects["motor_cogging"]
        motor_rad = np.radians(theta) * chain.L3_mm / PULLEY_RADIUS_MM
        fi = fi + cg["amplitude_N"] * np.sin(cg["cogs_per_rev"] * motor_rad + cg["phase_rad"])
    if "latency" in effects:
        la = effects["latency"]
        a = math.exp(-dt / la["lag_s"])
        fi = lfilter([1 - a], [1, -a], fi, zi=[a * fi[0]])[0]
        fi = np.interp(time - la["delay_s"], time, fi)
    if "sensor_offset_gain" in effects:
        so = effects["sensor_offset_gain"]
        fi = (
            so["offset_N"]
            + so["drift_N_per_s"] * time
            + (1.0 + so["gain"]) * fi
            + so["quadratic_per_N"] * fi * fi
        )
    fi_meas = fi + noise_N * rng.standard_normal(n)
    fj_meas = f_jaw + jaw_noise_N * rng.standard_normal(n)
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
    info = {"thickness_real_mm": t_real, "theta_min_deg": theta_min}
    if gap_noise is not None:
        # the gap the tissue sees: kinematic gap after the play + the stiffening jaw deflection
        # at the true jaw force (rate-dependent part included)
        g_true = g_kin.copy()
        if jc is not None:
            g_true = g_true + c_jaw * np.power(np.maximum(f_jaw, 0.0), jc["exponent"])
        grng, gsig = gap_noise
        g_meas = g_true + gsig * grng.standard_normal(n)
        df["gap_mm"] = GAP_RESOLUTION_MM * np.round(g_meas / GAP_RESOLUTION_MM)
        info["max_jaw_deflection_mm"] = float(np.max(g_true - g_kin))
    return df, info


def synth_case(
    effects: Sequence[str] | dict[str, dict[str, float]] = (),
    *,
    seed: int = 0,
    n_trials: int = 4,
    surrogate: Surrogate,
    chain: kin.ChainParams | None = None,
    material: str | None = None,
    jaw_load_cell: bool = True,
    gap_channel: bool = False,
) -> SynthCase:
    """Synthesise the trials of one blind case.

    Parameters
    ----------
    effects : sequence of str or dict
        Effect names (random parameters) or ``{name: params}`` (given parameters); empty for a
        null case (noise only).
    seed : int
        Seed of everything random (parameters, conditions, noise).
    n_trials : int
        Number of trials (>= 1): alternating two wall thicknesses and fast/slow closing.
    surrogate : Surrogate
        The baseline tissue force table.
    chain : kinematics.ChainParams, optional
        Instrument chain (default :class:`~grasprom.chain.kinematics.ChainParams`).
    material : str, optional
        Material key; random among the surrogate's by default.
    jaw_load_cell : bool
        Include the ``force_jaw_N`` channel.
    gap_channel : bool
        Include the ``gap_mm`` channel (measured jaw gap at the tissue: kinematic gap after the
        truth backlash + truth jaw deflection ``c F^p`` + 5-10 um rms noise from a separate
        random stream, so every other value of the case is the same with and without it).

    Returns
    -------
    SynthCase
        Trials (tables + sidecars) and the withheld truth.
    """
    chain = chain or kin.ChainParams()
    rng = np.random.default_rng(seed)
    if isinstance(effects, dict):
        truth_effects = {k: dict(v) for k, v in effects.items()}
    else:
        truth_effects = {name: random_effect_params(name, rng) for name in effects}
    for name in truth_effects:
        if name not in SYNTH_EFFECTS:
            raise ValueError(f"unknown effect {name!r}; valid: {', '.join(SYNTH_EFFECTS)}")
    mats = sorted(surrogate.materials)
    material = material or str(rng.choice(mats))
    lo_t, hi_t = surrogate.thickness_range(material)
    t_a = round(float(rng.uniform(max(lo_t, 1.0), min(hi_t, 1.5))), 2)
    t_b = round(float(rng.uniform(max(lo_t, 1.3), min(hi_t, 1.8))), 2)
    noise = float(rng.uniform(0.03, 0.12))
    jaw_noise = float(rng.uniform(0.03, 0.1))
    gap_noise = None
    if gap_channel:
        grng = np.random.default_rng([seed, _GAP_STREAM])
        gap_noise = (grng, float(grng.uniform(*GAP_NOISE_MM)))
    trials = []
    infos = []
    for i in range(n_trials):
        fast = i % 2 == 0
        spec = _Spec(
            thickness_mm=t_a if (i // 2) % 2 == 0 else t_b,
            material=material,
            close_s=float(rng.uniform(0.5, 0.9) if fast else rng.uniform(1.5, 2.5)),
            hold_s=float(rng.uniform(1.5, 2.5)),
            open_s=float(rng.uniform(0.5, 0.9) if not fast else rng.uniform(1.2, 2.0)),
            pre_s=float(rng.uniform(0.2, 0.4)),
            post_s=float(rng.uniform(0.2, 0.4)),
            target_jaw_N=float(rng.uniform(6.0, 20.0)),
        )
        df, info = _simulate_truth(
            spec, truth_effects, surrogate, chain, rng, noise, jaw_noise, gap_noise
        )
        if not jaw_load_cell:
            df = df.drop(columns=["force_jaw_N"])
        side = {
            "thickness_mm": spec.thickness_mm,
            "material": material,
            "trial_id": f"trial_{i + 1:02d}",
            "notes": f"close {spec.close_s:.2f} s, hold {spec.hold_s:.2f} s, "
            f"open {spec.open_s:.2f} s (synthetic)",
        }
        trials.append(SynthTrial(df, side))
        infos.append(info | {"target_jaw_N": spec.target_jaw_N})
    truth = {
        "effects": truth_effects,
        "in_library": [e for e in truth_effects if e in LIBRARY_EFFECTS],
        "out_of_library": [e for e in truth_effects if e in OUT_OF_LIBRARY_EFFECTS],
        "seed": seed,
        "material": material,
        "noise_N": noise,
        "jaw_noise_N": jaw_noise,
        "trials": infos,
    }
    if gap_noise is not None:
        truth["gap_noise_mm"] = gap_noise[1]
    return SynthCase(trials, truth)


def write_case(case: SynthCase, out_dir: str | Path) -> list[Path]:
    """Write ``trial_XX.csv`` + ``trial_XX.json`` per trial and ``truth.json`` (withheld).

    Returns
    -------
    list of Path
        The trial CSV files.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for tr in case.trials:
        stem = tr.sidecar["trial_id"]
        p = out / f"{stem}.csv"
        tr.data.to_csv(p, index=False, float_format="%.6g")
        (out / f"{stem}.json").write_text(json.dumps(tr.sidecar, indent=2))
        paths.append(p)
    (out / "truth.json").write_text(json.dumps(case.truth, indent=2, default=float))
    return paths


def main_synth(argv: Sequence[str] | None = None) -> int:
    """``grasprom synth --out DIR [--effect NAME[,NAME]] [--seed N] [--trials N] [--gap-channel]``.

    Writes synthetic trials (CSV + JSON sidecars) and the withheld ``truth.json`` into ``DIR``.

    Returns
    -------
    int
        Exit code: 0 ok, 2 bad input (message on stderr).
    """
    p = argparse.ArgumentParser(
        prog="grasprom synth",
        description="Synthesise 'real' grasp trials: baseline model + withheld effect(s) + noise.",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument(
        "--effect",
        default="",
        metavar="NAME[,NAME]",
        help=f"effect(s) to add (none = noise only); from {','.join(SYNTH_EFFECTS)}",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--trials", type=int, default=4, help="number of trials (default 4)")
    p.add_argument("--material", default=None, help="mr, nh or le (default random)")
    p.add_argument("--no-jaw-cell", action="store_true", help="omit the force_jaw_N channel")
    p.add_argument(
        "--gap-channel",
        action="store_true",
        help="add a measured jaw gap gap_mm (laser sensor at the jaw tips, 5-10 um rms)",
    )
    src = p.add_mutually_exclusive_group()
    src.add_argument("--surrogate", default=None, metavar="FILE", help="surrogate JSON")
    src.add_argument("--fe", default=None, metavar="DIR", help="FE sweep (default shipped)")
    args = p.parse_args(argv)
    names = [e.strip() for e in args.effect.split(",") if e.strip()]
    bad = [e for e in names if e not in SYNTH_EFFECTS]
    if bad:
        print(
            f"grasprom synth: unknown effect(s) {', '.join(bad)}; "
            f"valid: {', '.join(SYNTH_EFFECTS)}",
            file=sys.stderr,
        )
        return 2
    if len(set(names)) != len(names) or len(names) > 2:
        print("grasprom synth: give at most two distinct effects", file=sys.stderr)
        return 2
    if args.trials < 1:
        print("grasprom synth: --trials must be >= 1", file=sys.stderr)
        return 2
    from grasprom.surrogate import load_surrogate

    try:
        surrogate = load_surrogate(args.surrogate, args.fe)
        case = synth_case(
            names,
            seed=args.seed,
            n_trials=args.trials,
            surrogate=surrogate,
            material=args.material,
            jaw_load_cell=not args.no_jaw_cell,
            gap_channel=args.gap_channel,
        )
    except (OSError, ValueError) as exc:
        print(f"grasprom synth: {exc}", file=sys.stderr)
        return 2
    paths = write_case(case, args.out)
    print(
        f"wrote {len(paths)} trial(s) to {args.out} (effects withheld in truth.json: "
        f"{', '.join(names) or 'none'})"
    )
    return 0
