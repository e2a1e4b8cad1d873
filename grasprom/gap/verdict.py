"""The verdict of the diagnosis: ``none`` (the gap is within the noise), ``explained`` (an effect
set explains at least :data:`~grasprom.gap.criteria.EXPLAINED_SHARE` of the systematic gap on
held-out trials), ``unexplained`` (an effect outside the library?) or ``not_diagnosable`` (the
data cannot support a diagnosis: :mod:`~grasprom.gap.screening`), with its confidence and the
held-out shrink of the gap."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from grasprom.gap.baseline import BaselineGap
from grasprom.gap.criteria import CONFIDENCE_PLATT, EXPLAINED_SHARE, SIGNIFICANT_RHO
from grasprom.gap.crossval import CrossValidation
from grasprom.gap.prepare import PHASES
from grasprom.gap.selection import CandidateSearch
from grasprom.gap.shrink import shrink_by_phase, trial_shrinks
from grasprom.gap.stats import rms, stats_by_label

VERDICTS = ("explained", "none", "unexplained", "not_diagnosable")

PHASE_SHARE_SIGNIFICANT = 0.15
"""Share of the baseline's systematic chi2 from which a phase counts for the verdict."""
PHASE_WORSE = 1.1
"""Held-out systematic chi2 of a phase above this multiple of the baseline's = worse."""


def worse_phases(
    gap: BaselineGap, search: CandidateSearch, sigmas: Sequence[np.ndarray]
) -> list[str]:
    """Phases carrying >= :data:`PHASE_SHARE_SIGNIFICANT` of the systematic gap (weighted chi2
    less the sample count, as the explained share) whose held-out systematic chi2 the chosen
    effect set makes worse (> :data:`PHASE_WORSE` x the baseline's), each as a sentence with
    the RMS before and after (N); the per-phase figures are :func:`~.shrink.shrink_by_phase`'s
    (without its bootstrap)."""
    cv = search.cv[search.chosen]
    rows = shrink_by_phase(
        gap.residuals,
        cv.residuals,
        gap.labels,
        sigmas,
        n_boot=0,
        **heldout_z(gap, cv),
    )
    return [
        f"{r.phase} ({100 * r.share_of_gap:.0f} % of the gap): held-out RMS "
        f"{r.rms_before_N:.3g} -> {r.rms_after_N:.3g} N"
        for r in rows
        if r.phase != "all"
        and r.share_of_gap >= PHASE_SHARE_SIGNIFICANT
        and r.systematic_after > PHASE_WORSE * r.systematic_before
    ]


def heldout_z(gap: BaselineGap, cv: CrossValidation) -> dict[str, Any]:
    """The ``z`` arguments of :func:`~.shrink.shrink_by_phase` (interval likelihood) for the
    baseline and a cross-validated set."""
    return {"z_before": gap.z, "z_after": cv.z, "null": gap.null}


@dataclass
class Verdict:
    """Outcome of :func:`judge` (RMS in N, shares and confidence in 0..1)."""

    label: str
    effects: list[str]
    confidence: float
    message: str
    explained_share: float
    rms_before_N: float
    rms_after_N: float
    shrink: float
    shrink_rms: float
    reasons: tuple[str, ...] = ()
    confidence_raw: float | None = None
    worst_trial_shrink: float | None = None


def gap_left(search: CandidateSearch, key: tuple[str, ...]) -> float:
    """Systematic gap an effect set leaves on held-out trials in noise units: the systematic
    ratio ``(chi2 - N0) / N`` (1), floored at :data:`SIGNIFICANT_RHO` (below it a gap is not
    told from the noise)."""
    rho = (search.cv[key].chi2 - search.n_null) / max(search.n_samples, 1)
    return max(rho, SIGNIFICANT_RHO)


def separation(search: CandidateSearch, e_share: float) -> float:
    """Separation (0..1) of the chosen set from the runner-up: ratio of the gaps they leave,
    1 at >= 5x.

    Measured two ways, the larger counts: as shares of the baseline's systematic gap (floored
    at 2 %) and in noise units (:func:`gap_left`).  On a baseline gap of millions of chi2 a
    single can explain 99.9 % and still leave a significant gap that the chosen pair removes:
    the shares do not tell the two apart, the gaps left in noise units do.
    """
    chosen, best = search.chosen, search.best
    if len(chosen) == 1:
        alts = [k for k in search.singles if k != best]
    else:
        alts = [best] + [k for k in search.pair_rows if k != chosen]
    alt = max((search.share(k) for k in alts), default=0.0)
    u_best = max(1.0 - e_share, 0.02)
    u_alt = max(1.0 - alt, 0.02)
    by_share = math.log(u_alt / u_best)
    by_noise = (
        math.log(min(gap_left(search, k) for k in alts) / gap_left(search, chosen)) if alts else 0
    )
    return float(np.clip(max(by_share, by_noise) / math.log(5.0), 0.0, 1.0))


def transfer(gap: BaselineGap, cv: CrossValidation) -> float | None:
    """The worst held-out shrink over the trials with a significant baseline gap
    (:func:`~.shrink.trial_shrinks`), None with fewer than two such trials.

    The pooled share can be high while one trial (a specimen of its own, another thickness) is
    predicted much worse than the others: a fresh trial may then be one of those.
    """
    if cv.z is None:
        return None
    ts = trial_shrinks(gap.z, cv.z, gap.null, SIGNIFICANT_RHO)
    ts = ts[np.isfinite(ts)]
    return float(np.min(ts)) if ts.size >= 2 else None


def classify(
    gap: BaselineGap,
    chosen: tuple[str, ...],
    e_share: float,
    sep: float,
    worst_trial: float | None = None,
) -> tuple[str, list[str], float, str]:
    """Label, effects, confidence (unclipped) and message of the verdict.

    The confidence of ``explained`` is the explained share x (0.4 + 0.6 ``sep``) x the margin of
    the gap's significance, ``rho / SIGNIFICANT_RHO - 1`` clipped to 0..1 (a gap barely above
    the noise is weak evidence: a fresh trial's gap may be noise) x the worst trial's held-out
    shrink ``worst_trial`` clipped to 0..1 (:func:`transfer`; 1 when None).
    """
    rho0, noise = gap.rho, gap.noise_N
    if not rho0 > SIGNIFICANT_RHO:
        conf = float(np.clip(1.0 - rho0 / SIGNIFICANT_RHO, 0.0, 1.0)) * 0.5 + 0.5
        msg = (
            f"the gap is within the noise: systematic ratio {rho0:.3g} <= "
            f"{SIGNIFICANT_RHO} (systematic RMS {gap.summary['systematic_rms_N']:.3g} N vs noise "
            f"{noise:.3g} N)"
        )
        return "none", [], conf, msg
    if e_share >= EXPLAINED_SHARE:
        # weak evidence where the gap is barely significant: the margin above the threshold,
        # as the confidence of ``none`` is the margin below it (full from twice the threshold)
        margin = float(np.clip(rho0 / SIGNIFICANT_RHO - 1.0, 0.0, 1.0))
        worst = 1.0 if worst_trial is None else float(np.clip(worst_trial, 0.0, 1.0))
        conf = float(np.clip(e_share, 0.0, 1.0)) * (0.4 + 0.6 * sep) * margin * worst
        msg = (
            f"{' + '.join(chosen)} explains {100 * min(e_share, 1.0):.0f} % of the systematic "
            "gap on held-out trials"
        )
        if worst < EXPLAINED_SHARE:
            msg += (
                f" (but only {100 * worst_trial:.0f} % of the gap of the worst predicted trial: "
                "the effect may carry over poorly to a new trial)"
            )
        return "explained", list(chosen), conf, msg
    conf = float(np.clip(1.0 - max(e_share, 0.0) / EXPLAINED_SHARE, 0.0, 1.0)) * min(
        1.0, rho0 / (4 * SIGNIFICANT_RHO)
    )
    msg = (
        f"significant gap (systematic ratio {rho0:.3g}); the best candidate "
        f"({' + '.join(chosen)}) explains only {100 * max(e_share, 0.0):.0f} % of it on "
        "held-out trials: an effect outside the library?"
    )
    return "unexplained", [], conf, msg


def judge(
    gap: BaselineGap,
    search: CandidateSearch,
    n_trials: int,
    sigmas: Sequence[np.ndarray] | None = None,
) -> Verdict:
    """The verdict on the selected effect set (confidence capped at 0.3 for a single trial).

    Parameters
    ----------
    gap : BaselineGap
    search : CandidateSearch
    n_trials : int
        Trials in contact.
    sigmas : sequence of ndarray, optional
        Standard deviation of every sample (N) per trial: with them an ``explained`` set that
        makes a significant phase worse held-out (:func:`worse_phases`) is ``unexplained``.

    Returns
    -------
    Verdict
    """
    chosen = search.chosen
    rms_before = rms(gap.residuals)
    e_share = search.share(chosen)
    rms_after = rms(search.cv[chosen].residuals)
    sep = separation(search, e_share)
    worst_trial = transfer(gap, search.cv[chosen]) if n_trials >= 2 else None
    label, effects_out, conf, msg = classify(gap, chosen, e_share, sep, worst_trial)
    worse = worse_phases(gap, search, sigmas) if label == "explained" and sigmas else []
    if worse:
        label, effects_out = "unexplained", []
        conf = 0.5
        msg = (
            f"{' + '.join(chosen)} explains {100 * min(e_share, 1.0):.0f} % of the systematic "
            f"gap overall but makes the held-out prediction worse in {'; '.join(worse)}: not "
            "an explanation of the gap"
        )
    if label != "explained":
        rms_after = rms_before
    if n_trials < 2:
        conf = min(conf, 0.3)
    shrink = search.sys_shrink(chosen) if label == "explained" else 0.0
    shrink_rms = (
        float(np.clip(1.0 - rms_after / rms_before, 0.0, 1.0))
        if rms_before > 0 and label == "explained"
        else 0.0
    )
    return Verdict(
        label,
        effects_out,
        conf,
        msg,
        e_share,
        rms_before,
        rms_after,
        shrink,
        shrink_rms,
        worst_trial_shrink=worst_trial,
    )


TIE_SHARE = 0.05
"""A runner-up within this explained share of the chosen set explains the data as well..."""
TIE_GAP = 2.0
"""... unless it leaves more than this multiple of the chosen set's gap in noise units
(:func:`gap_left`)."""


def runner_up(search: CandidateSearch) -> tuple[str, ...] | None:
    """The best other single effect (or pair) if it explains within :data:`TIE_SHARE` of the
    chosen set's share and leaves at most :data:`TIE_GAP` x its gap (:func:`gap_left`: a
    single leaving a significant gap that the chosen pair removes does not explain the data as
    well), else None."""
    chosen = search.chosen
    others = [k for k in (*search.singles, *search.pair_rows) if k != chosen]
    if not others:
        return None
    best = max(others, key=search.share)
    if search.share(best) < search.share(chosen) - TIE_SHARE:
        return None
    return best if gap_left(search, best) <= TIE_GAP * gap_left(search, chosen) else None


ONE_THICKNESS_LOOKALIKES = ("thickness_error", "tissue_stiffness_scale", "jaw_compliance")
"""Effects that shift one thickness's force curve alike (a thicker wall, a stiffer tissue, a
softer jaw all move the wall-contact rise); their different dependence on the thickness is what
tells them apart."""


def checked_verdict(
    v: Verdict,
    search: CandidateSearch,
    measured_block: str | None,
    chosen_blocks: frozenset[str],
    one_thickness: bool = False,
) -> Verdict:
    """An ``explained`` verdict with its confidence lowered (halved per reason) and the reasons
    added to its message: a runner-up explains the data as well (:func:`runner_up`, named); the
    block the measured channels put the gap in (None: not measured) is none of the blocks of the
    explaining effects; all trials have one nominal thickness (``one_thickness``) and the set
    holds one of :data:`ONE_THICKNESS_LOOKALIKES` (on the benchmark with two trials of one
    thickness such verdicts were right in 24 of 38 cases, and a stiffness scale named for a jaw
    compliance + thickness error predicted a trial of another thickness 2.9x worse).
    """
    if v.label != "explained":
        return v
    notes = []
    alike = [e for e in search.chosen if e in ONE_THICKNESS_LOOKALIKES]
    if one_thickness and alike:
        notes.append(f"all trials have one thickness, where {' / '.join(alike)} and the other "
                     "tissue-side effects shift the force curve alike")  # fmt: skip
    tie = runner_up(search)
    if tie is not None:
        notes.append(f"{' + '.join(tie)} explains it about as well "
                     f"({100 * search.share(tie):.0f} %)")  # fmt: skip
    if measured_block is not None and measured_block not in chosen_blocks:
        notes.append(f"the measured channels put the gap in the {measured_block} block, the "
                     f"explaining effect acts in the {'/'.join(sorted(chosen_blocks))} "
                     "block")  # fmt: skip
    if not notes:
        return v
    conf = v.confidence * 0.5 ** len(notes)
    return replace(v, confidence=conf, message=v.message + "; but " + "; and ".join(notes))


def calibrated(v: Verdict, n_trials: int) -> Verdict:
    """An ``explained`` verdict with its confidence calibrated (:data:`CONFIDENCE_PLATT`; the
    raw value kept as ``confidence_raw``), capped at 0.3 for a single trial."""
    if v.label != "explained":
        return v
    a, b = CONFIDENCE_PLATT
    conf = 1.0 / (1.0 + math.exp(-(a + b * v.confidence)))
    if n_trials < 2:
        conf = min(conf, 0.3)
    return replace(v, confidence=conf, confidence_raw=v.confidence)


def not_diagnosable(v: Verdict, reasons: Sequence[str]) -> Verdict:
    """The verdict ``not_diagnosable`` in place of ``v``: no effects, no shrink, confidence 1
    in the refusal, the reasons as the message."""
    return Verdict(
        "not_diagnosable",
        [],
        1.0,
        "not diagnosable: " + "; ".join(reasons),
        0.0,
        v.rms_before_N,
        v.rms_before_N,
        0.0,
        0.0,
        tuple(reasons),
    )


def verdict_section(v: Verdict, gap: BaselineGap, search: CandidateSearch) -> dict[str, Any]:
    """The ``verdict`` section of the report (RMS by phase before / after on held-out trials)."""
    by_phase_after = stats_by_label(search.cv[search.chosen].residuals, gap.labels, PHASES)
    by_phase_before = gap.summary["by_phase"]
    return {
        "label": v.label,
        "effects": v.effects,
        "heldout_rms_before_N": v.rms_before_N,
        "heldout_rms_after_N": v.rms_after_N,
        "shrink": v.shrink,
        "shrink_rms": v.shrink_rms,
        "confidence": float(np.clip(v.confidence, 0.0, 1.0)),
        "confidence_raw": v.confidence_raw,
        "worst_trial_shrink": v.worst_trial_shrink,
        "explained_share": v.explained_share if v.label not in ("none", "not_diagnosable") else 0.0,
        "best_candidate": list(search.chosen),
        "by_phase_before": {k: val["rms_N"] for k, val in by_phase_before.items()},
        "by_phase_after": {k: val["rms_N"] for k, val in by_phase_after.items()},
        "message": v.message,
        "reasons": list(v.reasons),
    }
