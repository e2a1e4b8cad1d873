r"""Synthetic "real" grasp trials with withheld unmodelled effects (the diagnosis' test bench).

A trial is the baseline instrument model (derived chain of :mod:`grasprom.chain.kinematics` and
the FE surrogate) *plus* one or two effects at random parameters, sensor noise and encoder
quantisation (the truth models: :mod:`grasprom.gap.synth_truth`).  The effect identities and
parameters go to a separate ``truth.json`` that the diagnosis never reads.

A case alternates two wall thicknesses and fast / slow closing over its trials.  The gap noise
comes from its own random stream (seeded from the case seed), so switching the ``gap_mm``
channel on or off changes no other value of a case.

The sample rate is 1 kHz by default (``rate_hz``).  Whatever the rate, the case's random stream
is drawn from as at 1 kHz, so one seed gives the same truth and the same trial conditions
(durations, target forces, real thicknesses) at every rate; at a rate other than 1 kHz the
white sensor noise of each trial comes from a stream of its own (seeded from the case seed and
the trial number), independent at every sample.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from grasprom.chain import kinematics as kin
from grasprom.gap.synth_effects import (
    LIBRARY_EFFECTS,
    OUT_OF_LIBRARY_EFFECTS,
    SYNTH_EFFECTS,
    random_effect_params,
)
from grasprom.gap.synth_truth import (
    SAMPLE_RATE_HZ,
    TrialSpec,
    check_rate_hz,
    simulate_trial,
    trial_samples,
)
from grasprom.surrogate import Surrogate

GAP_NOISE_MM = (0.005, 0.010)
"""Range of the white noise (rms, mm) of the ``gap_mm`` channel (drawn per case)."""
_GAP_STREAM = 0x6A9
"""Second seed word of the ``gap_mm`` channel's own random stream."""
_TREMOR_STREAM = 0x7E3
"""Second seed word of the hand tremor's own random stream."""
_NOISE_STREAM = 0x5A4
"""Second seed word of the force noise's own random streams at rates other than 1 kHz (the
third word is the trial number)."""


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


def _truth_effects(
    effects: Sequence[str] | dict[str, dict[str, float]], rng: np.random.Generator
) -> dict[str, dict[str, float]]:
    """Given parameters, or random ones drawn from ``rng``; unknown effects raise."""
    if isinstance(effects, dict):
        truth_effects = {k: dict(v) for k, v in effects.items()}
    else:
        truth_effects = {name: random_effect_params(name, rng) for name in effects}
    for name in truth_effects:
        if name not in SYNTH_EFFECTS:
            raise ValueError(f"unknown effect {name!r}; valid: {', '.join(SYNTH_EFFECTS)}")
    return truth_effects


def _trial_spec(
    i: int, rng: np.random.Generator, t_a: float, t_b: float, material: str
) -> TrialSpec:
    """Conditions of trial ``i``: thickness ``t_a`` / ``t_b`` (mm) by pairs, fast / slow closing."""
    fast = i % 2 == 0
    return TrialSpec(
        thickness_mm=t_a if (i // 2) % 2 == 0 else t_b,
        material=material,
        close_s=float(rng.uniform(0.5, 0.9) if fast else rng.uniform(1.5, 2.5)),
        hold_s=float(rng.uniform(1.5, 2.5)),
        open_s=float(rng.uniform(0.5, 0.9) if not fast else rng.uniform(1.2, 2.0)),
        pre_s=float(rng.uniform(0.2, 0.4)),
        post_s=float(rng.uniform(0.2, 0.4)),
        target_jaw_N=float(rng.uniform(6.0, 20.0)),
    )


def _sidecar(spec: TrialSpec, i: int) -> dict[str, Any]:
    return {
        "thickness_mm": spec.thickness_mm,
        "material": spec.material,
        "trial_id": f"trial_{i + 1:02d}",
        "notes": f"close {spec.close_s:.2f} s, hold {spec.hold_s:.2f} s, "
        f"open {spec.open_s:.2f} s (synthetic)",
    }


def _gap_stream(seed: int) -> tuple[np.random.Generator, float]:
    """The gap channel's own random stream and noise level (mm RMS)."""
    grng = np.random.default_rng([seed, _GAP_STREAM])
    return grng, float(grng.uniform(*GAP_NOISE_MM))


def _truth(
    effects: dict[str, dict[str, float]],
    seed: int,
    material: str,
    noise: float,
    jaw_noise: float,
    infos: list[dict[str, Any]],
) -> dict[str, Any]:
    """The withheld truth of a case (``truth.json``)."""
    return {
        "effects": effects,
        "in_library": [e for e in effects if e in LIBRARY_EFFECTS],
        "out_of_library": [e for e in effects if e in OUT_OF_LIBRARY_EFFECTS],
        "seed": seed,
        "material": material,
        "noise_N": noise,
        "jaw_noise_N": jaw_noise,
        "trials": infos,
    }


def _tremor_stream(seed: int, tremor_deg: float) -> tuple[np.random.Generator, float] | None:
    """The tremor's own random stream and level (deg RMS), or None without tremor."""
    if not (math.isfinite(tremor_deg) and tremor_deg >= 0):
        raise ValueError(f"tremor_deg: must be >= 0 deg RMS, got {tremor_deg!r}")
    return (np.random.default_rng([seed, _TREMOR_STREAM]), tremor_deg) if tremor_deg else None


def _noise_stream(seed: int, i: int, rate_hz: float) -> np.random.Generator | None:
    """Own noise stream of trial ``i`` at a rate other than 1 kHz (None at 1 kHz: the case
    stream draws the noise, as before ``rate_hz`` existed)."""
    if rate_hz == SAMPLE_RATE_HZ:
        return None
    return np.random.default_rng([seed, _NOISE_STREAM, i])


@dataclass(frozen=True)
class _CaseSetup:
    """What the trials of one case share (see :func:`synth_case`; mm, N, Hz)."""

    effects: dict[str, dict[str, float]]
    surrogate: Surrogate
    chain: kin.ChainParams
    material: str
    thicknesses_mm: tuple[float, float]
    noise_N: float
    jaw_noise_N: float
    gap_noise: tuple[np.random.Generator, float] | None
    tremor: tuple[np.random.Generator, float] | None
    rate_hz: float
    seed: int
    jaw_load_cell: bool


def _case_trial(
    c: _CaseSetup, i: int, rng: np.random.Generator
) -> tuple[SynthTrial, dict[str, Any]]:
    """Trial ``i`` of the case ``c`` and its truth info; its conditions, thickness scatter and
    (at 1 kHz) noise drawn from the case stream ``rng``, which off 1 kHz is drawn from as at
    1 kHz (the noise then comes from the trial's own stream), so that the next trials'
    conditions do not depend on the rate."""
    spec = _trial_spec(i, rng, *c.thicknesses_mm, c.material)
    own_noise = _noise_stream(c.seed, i, c.rate_hz)
    df, info = simulate_trial(
        spec, c.effects, c.surrogate, c.chain, rng, c.noise_N, c.jaw_noise_N, c.gap_noise,
        c.tremor, c.rate_hz, own_noise,
    )  # fmt: skip
    if own_noise is not None:
        rng.standard_normal(2 * trial_samples(spec, SAMPLE_RATE_HZ))  # handle + jaw noise
    if not c.jaw_load_cell:
        df = df.drop(columns=["force_jaw_N"])
    return SynthTrial(df, _sidecar(spec, i)), info | {"target_jaw_N": spec.target_jaw_N}


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
    tremor_deg: float = 0.0,
    rate_hz: float = SAMPLE_RATE_HZ,
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
    tremor_deg : float
        Hand tremor on the handle angle, deg RMS, 6-12 Hz (0: none; from its own random
        stream, like the gap channel).  Physiological tremor at the finger is of the order of
        0.1 mm, i.e. about 0.1 deg of handle.
    rate_hz : float
        Sample rate of every channel, Hz (100 to 20000; default 1000).  The white noise of the
        force channels has the same rms at every sample and rate (``truth["noise_N"]``), and
        is independent from sample to sample.  The same seed gives the same truth and trial
        conditions at every rate (module docstring); at 1000 Hz the trials are those of the
        versions without ``rate_hz``, bit for bit.

    Returns
    -------
    SynthCase
        Trials (tables + sidecars) and the withheld truth.
    """
    rate_hz = check_rate_hz(rate_hz)
    chain = chain or kin.ChainParams()
    rng = np.random.default_rng(seed)
    truth_effects = _truth_effects(effects, rng)
    mats = sorted(surrogate.materials)
    material = material or str(rng.choice(mats))
    lo_t, hi_t = surrogate.thickness_range(material)
    t_a = round(float(rng.uniform(max(lo_t, 1.0), min(hi_t, 1.5))), 2)
    t_b = round(float(rng.uniform(max(lo_t, 1.3), min(hi_t, 1.8))), 2)
    noise = float(rng.uniform(0.03, 0.12))
    jaw_noise = float(rng.uniform(0.03, 0.1))
    gap_noise = _gap_stream(seed) if gap_channel else None
    tremor = _tremor_stream(seed, tremor_deg)
    setup = _CaseSetup(
        truth_effects, surrogate, chain, material, (t_a, t_b), noise, jaw_noise, gap_noise,
        tremor, rate_hz, seed, jaw_load_cell,
    )  # fmt: skip
    made = [_case_trial(setup, i, rng) for i in range(n_trials)]
    truth = _truth(truth_effects, seed, material, noise, jaw_noise, [m[1] for m in made])
    if gap_noise is not None:
        truth["gap_noise_mm"] = gap_noise[1]
    if tremor is not None:
        truth["tremor_deg"] = tremor_deg
    if rate_hz != SAMPLE_RATE_HZ:
        truth["rate_hz"] = rate_hz
    return SynthCase([m[0] for m in made], truth)


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
