r"""Sim-to-real gap diagnosis: where the gap lies, which unmodelled effect causes it, how far
it shrinks once that effect is added (:func:`diagnose`, its result :class:`Diagnosis`).

Baseline ("the model of the real instrument")
    The measured handle angle drives the **static derived chain** with the surrogate tissue:
    ``Fi_model = handle_force_N(F_surrogate(gap(theta), t, material), theta)`` (N, return spring
    included), evaluated vectorised over the samples.  The controller's virtual coupling and
    damping are *rendering* devices of the haptic controller (they exist to keep the rendering
    passive at 1 kHz), not parts of the real instrument, so they are not in the baseline; with the
    default coupling the two differ by < 0.1 mm of gap in bending (see
    :mod:`grasprom.control`).  ``--controller FILE`` only supplies the chain (geometry and
    return spring).

Analysis grid
    Each trial is subsampled (not averaged, so the non-linear model is not biased by averaging)
    to about :data:`ANALYSIS_RATE_HZ`; the sensor noise ``sigma`` (N) is estimated from the raw
    handle force by the median absolute second difference, the encoder quantum ``q`` (deg) from the
    smallest angle step, and every sample gets the standard deviation
    ``s_i^2 = sigma^2 + (dFi/dtheta q)^2 / 12 + (0.01 Fi)^2`` (sensor noise, angle quantisation
    through the model slope, 1 % surrogate uncertainty).  ``chi2 = sum (r_i / s_i)^2``; the
    *systematic gap ratio* ``rho = chi2 / N - 1`` is the systematic residual variance in units of
    the noise variance (0 for a perfect model).

Phases (per sample, from the baseline contact state and the measured angle velocity)
    ``approach`` (no contact), ``bending`` (closing in contact, gap above the wall-contact gap),
    ``compaction`` (closing with the inner walls meeting), ``hold`` (in contact, |dtheta/dt| <
    0.5 deg/s), ``release`` (opening in contact).

Candidate effects (:data:`EFFECTS`), each added on top of the baseline, fitted by weighted
least squares (variable projection: linear parameters by bounded linear least squares, at most two
non-linear ones by grid + bounded Brent search), judged by leave-one-trial-out cross-validation,
ranked by the held-out, parameter-penalised explained share of the systematic gap, and combined in
pairs by forward selection.  See the README section "Sim-to-real gap diagnosis".

The steps live in their own modules: :mod:`~grasprom.gap.trials` (input),
:mod:`~grasprom.gap.prepare` (analysis grid, phases), :mod:`~grasprom.gap.baseline` and
:mod:`~grasprom.gap.blocks` (where the gap lies), :mod:`~grasprom.gap.effects`,
:mod:`~grasprom.gap.model`, :mod:`~grasprom.gap.fit`, :mod:`~grasprom.gap.crossval` and
:mod:`~grasprom.gap.selection` (which effect), :mod:`~grasprom.gap.verdict` (the verdict),
:mod:`~grasprom.gap.augmented` (the augmented model).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from grasprom.chain import kinematics as kin
from grasprom.gap.augmented import augmented_dict
from grasprom.gap.baseline import BaselineGap, baseline_gap
from grasprom.gap.criteria import EXPLAINED_SHARE, PAIR_GAIN, SIGNIFICANT_RHO
from grasprom.gap.crossval import uncertainty
from grasprom.gap.effects import BLOCKS, EFFECT_ORDER, EFFECTS
from grasprom.gap.fit import Fit, fit_effects, fit_params, predict
from grasprom.gap.formats import FORMAT_REPORT, FORMAT_VERSION, jsonable
from grasprom.gap.prepare import ANALYSIS_RATE_HZ, PHASES, PreparedTrial, prepare_trial
from grasprom.gap.screening import bound_reasons, screen_trials
from grasprom.gap.selection import CandidateSearch, effect_row, search_candidates
from grasprom.gap.shrink import shrink_by_phase
from grasprom.gap.trials import FloatArray, Trial
from grasprom.gap.verdict import (
    Verdict,
    calibrated,
    checked_verdict,
    heldout_z,
    judge,
    not_diagnosable,
    verdict_section,
)
from grasprom.surrogate import Surrogate


class DiagnosisError(ValueError):
    """The trials cannot support a diagnosis (too short, no tissue contact ...)."""


@dataclass
class Diagnosis:
    """Result of :func:`diagnose`: the JSON-ready report, the augmented model (None when the
    verdict is ``not_diagnosable``: nothing to render) and the data behind the plots."""

    report: dict[str, Any]
    augmented: dict[str, Any] | None
    preps: list[PreparedTrial] = field(repr=False, default_factory=list)
    baseline_pred: list[FloatArray] = field(repr=False, default_factory=list)
    augmented_pred: list[FloatArray] = field(repr=False, default_factory=list)


def _candidates(effects: Sequence[str] | None) -> tuple[str, ...]:
    """The candidate effects to try (all of :data:`EFFECTS` by default); unknown ones raise."""
    cands = tuple(effects) if effects is not None else EFFECT_ORDER
    for e in cands:
        if e not in EFFECTS:
            raise ValueError(f"unknown effect {e!r}; valid: {', '.join(EFFECTS)}")
    return cands


def _one_thickness(preps: Sequence[PreparedTrial]) -> bool:
    """Two or more trials, all of one nominal thickness and material: the held-out checks then
    do not test the model across thicknesses."""
    return len(preps) >= 2 and len({(p.thickness, p.material) for p in preps}) == 1


def _contact_trials(
    trials: Sequence[Trial],
    surrogate: Surrogate,
    chain: kin.ChainParams,
    rate_hz: float,
) -> tuple[list[PreparedTrial], list[str]]:
    """The prepared trials reaching the tissue and the warnings about the others."""
    if not trials:
        raise DiagnosisError("no trial given")
    warn_list: list[str] = []
    preps_all = [prepare_trial(tr, surrogate, chain, rate_hz) for tr in trials]
    preps = []
    for p in preps_all:
        n_contact = int(np.sum(p.phase != 0))
        if n_contact < 10:
            warn_list.append(
                f"{p.trial.name}: no tissue contact (the jaws never close below the tube "
                f"diameter {surrogate.diameter_mm:g} mm, theta never below "
                f"{chain.theta_touch_deg:.2f} deg); left out"
            )
        else:
            preps.append(p)
    if not preps:
        raise DiagnosisError(
            "no trial reaches the tissue (the jaw gap never falls below the tube diameter "
            f"{surrogate.diameter_mm:g} mm): the sim-to-real gap of the grasp cannot be "
            "diagnosed from free motion alone"
        )
    if len(preps) < 2:
        warn_list.append(
            "only one trial in contact: no cross-validation by trial is possible; effects are "
            "judged in-sample and the confidence is capped at 0.3"
        )
    elif _one_thickness(preps):
        warn_list.append(
            f"all trials in contact have one nominal thickness ({preps[0].thickness:g} mm, "
            f"{preps[0].material}): the held-out checks do not test the model across "
            "thicknesses, and its prediction at another may be worse than the baseline's"
        )
    return preps, warn_list


def _measured_block(gap: BaselineGap) -> str | None:
    """The block of the chain the measured channels put the gap in (None: not measured)."""
    bb = gap.summary["by_block"]
    return None if bb is None else max(BLOCKS, key=lambda k: bb[k]["share"])


def _where(gap: BaselineGap, label: str, chosen: tuple[str, ...]) -> dict[str, str]:
    """The ``where`` section: the phase and the block of the chain holding the gap."""
    baseline = gap.summary
    where_phase = max(PHASES, key=lambda k: baseline["by_phase"][k]["share"])
    measured = _measured_block(gap)
    if measured is not None:
        block = measured
        block_source = "measured channels (force_jaw_N / gap_mm)" + (
            f"; {gap.block_how}" if gap.block_how else ""
        )
    elif label == "explained":
        block = EFFECTS[chosen[0]].block
        block_source = "block of the explaining effect"
    else:
        block = "unknown"
        block_source = "no jaw force or gap measured and no explaining effect"
    return {"phase": where_phase, "block": block, "block_source": block_source}


def _augmented_effects(
    verdict: Verdict, search: CandidateSearch, chosen_fit: Fit
) -> list[dict[str, Any]]:
    """Effects of the augmented model: the explaining set with values, uncertainty, units."""
    if verdict.label != "explained":
        return []
    chosen = search.chosen
    return [
        {
            "name": e,
            "params": fit_params(chosen_fit)[e],
            "uncertainty": uncertainty(search.cv[chosen].fold_params)[e],
            "units": {p.name: p.unit for p in EFFECTS[e].params},
        }
        for e in chosen
    ]


def _trial_rows(preps: Sequence[PreparedTrial], gap: BaselineGap) -> list[dict[str, Any]]:
    """The ``trials`` section of the report."""
    return [
        {
            "file": p.trial.name,
            "trial_id": p.trial.trial_id,
            "thickness_mm": p.thickness,
            "material": p.material,
            "duration_s": float(p.raw_t[-1] - p.raw_t[0]),
            "n_samples": int(p.raw_t.size),
            "n_analysis": int(p.t.size),
            "noise_N": p.noise_N,
            "closing_speed_deg_per_s": c["closing_speed_deg_per_s"],
            "has_force_jaw": p.trial.force_jaw_N is not None,
            "has_gap": p.trial.gap_mm is not None,
        }
        for p, c in zip(preps, gap.conditions)
    ]


def _report(
    preps: Sequence[PreparedTrial],
    gap: BaselineGap,
    search: CandidateSearch,
    verdict: Verdict,
    chosen_fit: Fit,
    warn_list: list[str],
    rate_hz: float,
) -> dict[str, Any]:
    """The report (before :func:`~grasprom.gap.formats.jsonable`)."""
    rows = [effect_row(search, k, chosen_fit, verdict.rms_before_N) for k in search.singles]
    pair_out = [effect_row(search, k, chosen_fit, verdict.rms_before_N) for k in search.pair_rows]
    return {
        "format": FORMAT_REPORT,
        "format_version": FORMAT_VERSION,
        "trials": _trial_rows(preps, gap),
        "baseline": gap.summary,
        "where": _where(gap, verdict.label, search.chosen),
        "effects": rows,
        "pairs": pair_out,
        "verdict": {
            **verdict_section(verdict, gap, search),
            "shrink_by_phase": [
                row.as_dict()
                for row in shrink_by_phase(
                    gap.residuals,
                    search.cv[search.chosen].residuals,
                    gap.labels,
                    [p.sigma for p in preps],
                    **heldout_z(gap, search.cv[search.chosen]),
                )
            ],
        },
        "warnings": warn_list,
        "settings": {
            "analysis_rate_hz": rate_hz,
            "significant_ratio": SIGNIFICANT_RHO,
            "explained_share": EXPLAINED_SHARE,
            "pair_gain": PAIR_GAIN,
            "cross_validation": "leave-one-trial-out" if len(preps) <= 6 else "6 trial folds",
        },
    }


def diagnose(
    trials: Sequence[Trial],
    surrogate: Surrogate,
    chain: kin.ChainParams | None = None,
    *,
    rate_hz: float = ANALYSIS_RATE_HZ,
    effects: Sequence[str] | None = None,
    try_pairs: bool = True,
) -> Diagnosis:
    """Diagnose the gap between measured trials and the baseline model.

    Parameters
    ----------
    trials : sequence of Trial
        Validated trials (:func:`load_trial`).
    surrogate : Surrogate
        Tissue force table of the baseline.
    chain : kinematics.ChainParams, optional
        Instrument chain (default geometry and spring).
    rate_hz : float
        Analysis grid rate (Hz).
    effects : sequence of str, optional
        Candidate effects to try (default all of :data:`EFFECTS`).
    try_pairs : bool
        Forward selection of a second effect.

    Returns
    -------
    Diagnosis

    Raises
    ------
    DiagnosisError
        No trial, or no trial reaching the tissue.
    """
    chain = chain or kin.ChainParams()
    cands = _candidates(effects)
    preps, warn_list = _contact_trials(trials, surrogate, chain, rate_hz)
    gap = baseline_gap(preps, surrogate, chain)
    search = search_candidates(preps, cands, gap, surrogate, chain, try_pairs)
    verdict = judge(gap, search, len(preps), [p.sigma for p in preps])
    blocks = frozenset(EFFECTS[e].block for e in search.chosen)
    verdict = checked_verdict(verdict, search, _measured_block(gap), blocks, _one_thickness(preps))
    verdict = calibrated(verdict, len(preps))
    chosen_fit = fit_effects(preps, search.chosen, surrogate, chain)
    reasons = screen_trials(preps)
    if not reasons and verdict.label == "explained":
        reasons = bound_reasons(chosen_fit)
    if reasons:
        verdict = not_diagnosable(verdict, reasons)
    report = _report(preps, gap, search, verdict, chosen_fit, warn_list, rate_hz)
    augmented = (
        None
        if verdict.label == "not_diagnosable"
        else augmented_dict(
            chain,
            surrogate,
            _augmented_effects(verdict, search, chosen_fit),
            verdict.label,
            verdict.rms_before_N,
            verdict.rms_after_N,
        )
    )
    aug_pred = (
        [predict(p, chosen_fit, surrogate, chain) for p in preps]
        if verdict.label == "explained"
        else [p.F0 for p in preps]
    )
    return Diagnosis(
        jsonable(report),
        None if augmented is None else jsonable(augmented),
        list(preps),
        [p.F0 for p in preps],
        aug_pred,
    )
