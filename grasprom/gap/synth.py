r"""Synthetic "real" grasp trials with withheld unmodelled effects (the diagnosis' test bench).

A trial is the baseline instrument model (derived chain of :mod:`grasprom.chain.kinematics` and
the FE surrogate) *plus* one or two effects at random parameters, sensor noise and encoder
quantisation (the truth models: :mod:`grasprom.gap.synth_truth`).  The effect identities and
parameters go to a separate ``truth.json`` that the diagnosis never reads.

A case alternates two wall thicknesses and fast / slow closing over its trials.  The gap noise
comes from its own random stream (seeded from the case seed), so switching the ``gap_mm``
channel on or off changes no other value of a case.
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
from grasprom.gap.synth_truth import TrialSpec, simulate_trial
from grasprom.surrogate import Surrogate

GAP_NOISE_MM = (0.005, 0.010)
"""Range of the white noise (rms, mm) of the ``gap_mm`` channel (drawn per case)."""
_GAP_STREAM = 0x6A9
"""Second seed word of the ``gap_mm`` channel's own random stream."""
_TREMOR_STREAM = 0x7E3
"""Second seed word of the hand tremor's own random stream."""


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

    Returns
    -------
    SynthCase
        Trials (tables + sidecars) and the withheld truth.
    """
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
    trials = []
    infos = []
    for i in range(n_trials):
        spec = _trial_spec(i, rng, t_a, t_b, material)
        df, info = simulate_trial(
            spec, truth_effects, surrogate, chain, rng, noise, jaw_noise, gap_noise, tremor
        )
        if not jaw_load_cell:
            df = df.drop(columns=["force_jaw_N"])
        trials.append(SynthTrial(df, _sidecar(spec, i)))
        infos.append(info | {"target_jaw_N": spec.target_jaw_N})
    truth = _truth(truth_effects, seed, material, noise, jaw_noise, infos)
    if gap_noise is not None:
        truth["gap_noise_mm"] = gap_noise[1]
    if tremor is not None:
        truth["tremor_deg"] = tremor_deg
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
