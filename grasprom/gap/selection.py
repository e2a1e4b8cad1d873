"""Candidate selection: every candidate effect cross-validated by trial, ranked by the held-out,
parameter-penalised explained share of the systematic gap, and combined in pairs by forward
selection; the report rows of the candidates."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from grasprom.chain import kinematics as kin
from grasprom.gap.baseline import BaselineGap
from grasprom.gap.criteria import PAIR_GAIN, PAIR_MIN_SHARE, SIGNIFICANT_RHO
from grasprom.gap.crossval import CrossValidation, cross_validate, uncertainty
from grasprom.gap.effects import EFFECT_ORDER, EFFECTS, n_params
from grasprom.gap.fit import Fit, fit_params
from grasprom.gap.prepare import PreparedTrial
from grasprom.gap.stats import rms
from grasprom.surrogate import Surrogate

EffectSet = tuple[str, ...]


@dataclass
class CandidateSearch:
    """Cross-validated candidates and the selected effect set.

    Attributes
    ----------
    chi2_baseline : float
        Weighted chi2 of the baseline (1).
    systematic_chi2 : float
        Its systematic part ``chi2 - N``.
    n_samples : int
        Analysis samples ``N``.
    n_null : float
        The chi2 a correct model leaves, ``N0`` (:class:`~grasprom.gap.baseline.BaselineGap`).
    cv : dict
        Effect set -> :class:`~grasprom.gap.crossval.CrossValidation`.
    singles : list of tuple
        Single effects, best score first.
    best : tuple
        The best single effect.
    chosen : tuple
        The selected set (``best`` or a pair with it).
    pair_rows : list of tuple
        The pairs tried, best score first.
    """

    chi2_baseline: float
    systematic_chi2: float
    n_samples: int
    n_null: float
    cv: dict[EffectSet, CrossValidation] = field(default_factory=dict)
    singles: list[EffectSet] = field(default_factory=list)
    best: EffectSet = ()
    chosen: EffectSet = ()
    pair_rows: list[EffectSet] = field(default_factory=list)

    def share(self, key: EffectSet) -> float:
        """Held-out explained share of the systematic gap (1)."""
        if self.systematic_chi2 <= 0:
            return 0.0
        return (self.chi2_baseline - self.cv[key].chi2) / self.systematic_chi2

    def score(self, key: EffectSet) -> float:
        """:meth:`share` less the ``ln N`` penalty per parameter (1)."""
        if self.systematic_chi2 <= 0:
            return 0.0
        lnN = math.log(max(self.n_samples, 2))
        return (self.chi2_baseline - self.cv[key].chi2 - n_params(key) * lnN) / self.systematic_chi2

    def sys_shrink(self, key: EffectSet) -> float:
        """Share of the systematic gap RMS removed on held-out trials, 0..1."""
        if self.systematic_chi2 <= 0:
            return 0.0
        left = max(self.cv[key].chi2 - self.n_null, 0.0) / self.systematic_chi2
        return float(np.clip(1.0 - math.sqrt(left), 0.0, 1.0))

    def fold_mean(self, key: EffectSet) -> dict[str, dict[str, float]]:
        """Parameter values averaged over the cross-validation folds."""
        fps = self.cv[key].fold_params
        return {e: {k: float(np.mean([fp[e][k] for fp in fps])) for k in fps[0][e]} for e in key}


def search_candidates(
    preps: Sequence[PreparedTrial],
    cands: Sequence[str],
    gap: BaselineGap,
    surrogate: Surrogate,
    chain: kin.ChainParams,
    try_pairs: bool = True,
) -> CandidateSearch:
    """Cross-validate the single candidates, then (if needed) the pairs with the best one.

    A pair is chosen if it removes :data:`~grasprom.gap.criteria.PAIR_GAIN` of the gap the
    best single leaves and scores :data:`~grasprom.gap.criteria.PAIR_MIN_SHARE` higher, or
    scores higher at all and leaves no significant gap (systematic ratio <=
    :data:`~grasprom.gap.criteria.SIGNIFICANT_RHO`); pairs are tried only while both the
    baseline and the best single leave a significant gap.
    """
    n = gap.n_samples
    search = CandidateSearch(gap.chi2, gap.systematic_chi2, n, gap.n_null)
    cv = search.cv
    for e in cands:
        cv[(e,)] = cross_validate(preps, (e,), surrogate, chain)
    search.singles = sorted(((e,) for e in cands), key=search.score, reverse=True)
    best = search.singles[0]
    search.best = search.chosen = best
    rho_best = (cv[best].chi2 - gap.n_null) / n
    if try_pairs and len(cands) > 1 and rho_best > SIGNIFICANT_RHO and gap.rho > SIGNIFICANT_RHO:
        for e in cands:
            if e == best[0]:
                continue
            key = tuple(sorted(best + (e,), key=EFFECT_ORDER.index))
            cv[key] = cross_validate(preps, key, surrogate, chain)
        pairs = sorted((k for k in cv if len(k) == 2), key=search.score, reverse=True)
        search.pair_rows = list(pairs)
        top = pairs[0]
        left = cv[best].chi2 - gap.n_null
        gain = (cv[best].chi2 - cv[top].chi2) / left if left > 0 else 0.0
        # the pair leaves no significant gap where the best single leaves one: kept even when
        # the share it adds is small next to a large baseline gap (on a gap of millions of
        # chi2 a single can explain 99.9 % and still miss the second effect that decides the
        # prediction at forces outside the trials' range)
        resolves = (cv[top].chi2 - gap.n_null) / n <= SIGNIFICANT_RHO
        extra = search.score(top) - search.score(best)
        if gain >= PAIR_GAIN and (extra >= PAIR_MIN_SHARE or (resolves and extra > 0)):
            search.chosen = top
    return search


def effect_row(
    search: CandidateSearch, key: EffectSet, chosen_fit: Fit, rms_before: float
) -> dict[str, Any]:
    """Report row of one candidate set (parameters of the chosen set from the fit on all trials).

    ``rms_before`` is the baseline RMS (N).
    """
    params = fit_params(chosen_fit) if key == search.chosen else search.fold_mean(key)
    unc = uncertainty(search.cv[key].fold_params)
    rms_k = rms(search.cv[key].residuals)
    return {
        "name": " + ".join(key),
        "effects": list(key),
        "params": params if len(key) > 1 else params[key[0]],
        "uncertainty": unc if len(key) > 1 else unc[key[0]],
        "units": (
            {e: {p.name: p.unit for p in EFFECTS[e].params} for e in key}
            if len(key) > 1
            else {p.name: p.unit for p in EFFECTS[key[0]].params}
        ),
        "block": [EFFECTS[e].block for e in key] if len(key) > 1 else EFFECTS[key[0]].block,
        "params_from": "fit on all trials" if key == search.chosen else "mean of the CV folds",
        "heldout_rms_N": rms_k,
        "shrink": search.sys_shrink(key),
        "shrink_rms": float(np.clip(1 - rms_k / rms_before, 0, 1)) if rms_before > 0 else 0.0,
        "explained_share": search.share(key),
        "score": search.score(key),
    }
