"""Cross-validation by trial of a candidate effect set (held-out residuals and chi2) and the
jackknife uncertainty of its parameters over the folds."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from grasprom.chain import kinematics as kin
from grasprom.gap.fit import fit_effects, fit_params, predict_z
from grasprom.gap.prepare import PreparedTrial
from grasprom.gap.trials import FloatArray
from grasprom.surrogate import Surrogate

MAX_FOLDS = 6
"""More trials than this are grouped into this many folds (else leave-one-trial-out)."""


@dataclass
class CrossValidation:
    """Held-out result of one effect set."""

    effects: tuple[str, ...]
    residuals: list[FloatArray]  # held-out residual per trial (N)
    chi2: float  # sum of z^2 (interval likelihood, :mod:`grasprom.gap.likelihood`)
    fold_params: list[dict[str, dict[str, float]]]
    predictions: list[FloatArray]
    z: list[FloatArray] | None = None  # held-out z per trial (1)


def folds(n: int, max_folds: int = MAX_FOLDS) -> list[list[int]]:
    """Trial indices held out per fold: one trial each, or ``max_folds`` interleaved groups."""
    if n <= max_folds:
        return [[i] for i in range(n)]
    return [list(range(k, n, max_folds)) for k in range(max_folds)]


def cross_validate(
    preps: Sequence[PreparedTrial],
    effects: Sequence[str],
    surrogate: Surrogate,
    chain: kin.ChainParams,
) -> CrossValidation:
    """Fit on the other trials, predict each held-out fold (in-sample with a single trial)."""
    n = len(preps)
    res: list[FloatArray | None] = [None] * n
    pred: list[FloatArray | None] = [None] * n
    zs: list[FloatArray | None] = [None] * n
    fold_params = []
    held_out = folds(n) if n >= 2 else [[0]]
    for held in held_out:
        train = [preps[i] for i in range(n) if i not in held] or list(preps)
        fit = fit_effects(train, effects, surrogate, chain)
        fold_params.append(fit_params(fit))
        for i in held:
            pr, zs[i] = predict_z(preps[i], fit, surrogate, chain)
            pred[i] = pr
            res[i] = preps[i].F - pr
    chi2 = float(sum(z @ z for z in zs))  # type: ignore[union-attr]
    return CrossValidation(tuple(effects), res, chi2, fold_params, pred, zs)  # type: ignore[arg-type]


def uncertainty(fold_params: list[dict[str, dict[str, float]]]) -> dict[str, dict[str, float]]:
    """Jackknife standard error of the parameters over the cross-validation folds."""
    k = len(fold_params)
    out: dict[str, dict[str, float]] = {}
    for e, ps in fold_params[0].items():
        out[e] = {}
        for name in ps:
            vals = np.array([fp[e][name] for fp in fold_params])
            out[e][name] = (
                float(math.sqrt((k - 1) / k * np.sum((vals - vals.mean()) ** 2)))
                if (k > 1)
                else float("nan")
            )
    return out
