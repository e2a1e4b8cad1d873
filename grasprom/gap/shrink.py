"""Held-out shrink of the systematic gap, overall and per phase, with a bootstrap over trials.

The shrink of a phase is ``1 - sqrt(S1 / S0)``: ``S0`` is the baseline's systematic chi2 in that
phase (weighted chi2 less the sample count, the part of the gap that is not noise) and ``S1``
the chosen effect set's on held-out trials (cross-validation by trial, :mod:`~.crossval`).  1
removes the whole systematic gap, 0 none, **negative: the augmented model predicts that phase
worse than the baseline**.  The interval comes from resampling the trials with replacement
(each trial's residuals keep their time correlation), so it says how much the figure would move
with other trials of the same kind.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from grasprom.gap.prepare import PHASES

N_BOOTSTRAP = 400
"""Bootstrap resamples of the trials."""

INTERVAL = 0.9
"""Central coverage of the reported interval (5th to 95th percentile)."""

MIN_TRIALS_INTERVAL = 3
"""Fewest trials for an interval: with two, a resample is one of three sets."""


@dataclass(frozen=True)
class PhaseShrink:
    """Held-out shrink of one phase (or ``"all"``); shares and shrinks in 1, RMS in N.

    Attributes
    ----------
    phase : str
        A name of :data:`~grasprom.gap.prepare.PHASES`, or ``"all"``.
    share_of_gap : float
        The phase's share of the baseline's systematic gap (0..1; 1 for ``"all"``).
    shrink : float
        ``1 - sqrt(S1 / S0)``, <= 1; negative when the phase got worse.
    low, high : float
        Bootstrap interval over trials (:data:`INTERVAL`); NaN with fewer than
        :data:`MIN_TRIALS_INTERVAL` trials.
    rms_before_N, rms_after_N : float
        Held-out RMS of the residual before / after (N).
    n : int
        Samples in the phase.
    systematic_before, systematic_after : float
        ``S0`` and ``S1``: the weighted chi2 less the sample count (1) before / after.
    """

    phase: str
    share_of_gap: float
    shrink: float
    low: float
    high: float
    rms_before_N: float
    rms_after_N: float
    n: int
    systematic_before: float
    systematic_after: float

    def as_dict(self) -> dict[str, float | str | int]:
        """The JSON form (report key ``verdict.shrink_by_phase``)."""
        return dict(self.__dict__)


def _per_trial(
    residuals: Sequence[np.ndarray],
    labels: Sequence[np.ndarray],
    sigmas: Sequence[np.ndarray],
    z: Sequence[np.ndarray] | None = None,
    null: Sequence[np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per trial and phase: weighted sum of squares (of ``z`` if given, else ``r / sigma``), sum
    of squares (N^2), sample count and the chi2 a correct model leaves (``null``'s sum, else the
    count)."""
    k = len(PHASES)
    wss = np.zeros((len(residuals), k))
    ss = np.zeros_like(wss)
    cnt = np.zeros_like(wss)
    n0 = np.zeros_like(wss)
    for i, (r, lab, sig) in enumerate(zip(residuals, labels, sigmas)):
        w = r / sig if z is None else z[i]
        for j in range(k):
            m = lab == j
            wss[i, j] = np.sum(w[m] ** 2)
            ss[i, j] = np.sum(r[m] ** 2)
            cnt[i, j] = np.sum(m)
            n0[i, j] = cnt[i, j] if null is None else np.sum(null[i][m])
    return wss, ss, cnt, n0


def _shrink(s0: np.ndarray, s1: np.ndarray) -> np.ndarray:
    """``1 - sqrt(max(S1, 0) / S0)``, NaN where ``S0 <= 0`` (no systematic gap to shrink)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        out = 1.0 - np.sqrt(np.maximum(s1, 0.0) / s0)
    return np.where(s0 > 0, out, np.nan)


def _bootstrap_interval(
    d0: np.ndarray, d1: np.ndarray, n_boot: int, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Bootstrap interval (:data:`INTERVAL`) of the shrink over trials: ``d0``, ``d1`` are the
    per-trial (rows) systematic chi2 before / after per column; NaN with too few trials."""
    n_tr = d0.shape[0]
    lo = np.full(d0.shape[1], math.nan)
    hi = np.full(d0.shape[1], math.nan)
    if n_tr < MIN_TRIALS_INTERVAL or n_boot <= 0:
        return lo, hi
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, n_tr, size=(n_boot, n_tr))
    counts = np.stack([np.bincount(row, minlength=n_tr) for row in idx])  # (n_boot, n_tr)
    boot = _shrink(counts @ d0, counts @ d1)
    q = (1.0 - INTERVAL) / 2.0
    for j in range(boot.shape[1]):
        col = boot[:, j][np.isfinite(boot[:, j])]
        if col.size:
            lo[j], hi[j] = np.quantile(col, [q, 1.0 - q])
    return lo, hi


def shrink_by_phase(
    before: Sequence[np.ndarray],
    after: Sequence[np.ndarray],
    labels: Sequence[np.ndarray],
    sigmas: Sequence[np.ndarray],
    n_boot: int = N_BOOTSTRAP,
    seed: int = 0,
    *,
    z_before: Sequence[np.ndarray] | None = None,
    z_after: Sequence[np.ndarray] | None = None,
    null: Sequence[np.ndarray] | None = None,
) -> list[PhaseShrink]:
    """Held-out shrink overall and per phase, with a bootstrap interval over trials.

    Parameters
    ----------
    before, after : sequence of ndarray
        Per trial: the baseline's residual and the chosen set's held-out residual (N).
    labels : sequence of ndarray
        Per trial: the phase index of every sample (into :data:`PHASES`).
    sigmas : sequence of ndarray
        Per trial: the noise standard deviation of every sample (N).
    n_boot : int
        Bootstrap resamples (0: no interval, ``low`` and ``high`` NaN).
    seed : int
        Seed of the resampling (the result is reproducible).
    z_before, z_after, null : sequence of ndarray, optional
        Per trial: the ``z`` of the interval likelihood before / after and the expected ``z^2``
        of a correct model (:mod:`~grasprom.gap.likelihood`), in place of ``r / sigma`` and 1.

    Returns
    -------
    list of PhaseShrink
        ``"all"`` first, then the phases with samples, in :data:`PHASES` order.
    """
    w0, ss0, cnt_n, cnt = _per_trial(before, labels, sigmas, z_before, null)
    w1, ss1, _, _ = _per_trial(after, labels, sigmas, z_after, null)
    # columns: the phases, then "all"
    w0 = np.column_stack([w0, w0.sum(axis=1)])
    w1 = np.column_stack([w1, w1.sum(axis=1)])
    ss0 = np.column_stack([ss0, ss0.sum(axis=1)])
    ss1 = np.column_stack([ss1, ss1.sum(axis=1)])
    cnt = np.column_stack([cnt, cnt.sum(axis=1)])
    cnt_n = np.column_stack([cnt_n, cnt_n.sum(axis=1)])
    s0 = w0.sum(axis=0) - cnt.sum(axis=0)
    s1 = w1.sum(axis=0) - cnt.sum(axis=0)
    point = _shrink(s0, s1)
    lo, hi = _bootstrap_interval(w0 - cnt, w1 - cnt, n_boot, seed)
    total = float(np.sum(np.maximum(s0[:-1], 0.0)))
    n_all = cnt_n.sum(axis=0)
    out = []
    for j, name in [(len(PHASES), "all"), *enumerate(PHASES)]:
        if n_all[j] == 0:
            continue
        share = 1.0 if name == "all" else (max(s0[j], 0.0) / total if total > 0 else 0.0)
        out.append(
            PhaseShrink(
                phase=name,
                share_of_gap=float(share),
                shrink=float(point[j]),
                low=float(lo[j]),
                high=float(hi[j]),
                rms_before_N=float(math.sqrt(ss0[:, j].sum() / n_all[j])),
                rms_after_N=float(math.sqrt(ss1[:, j].sum() / n_all[j])),
                n=int(n_all[j]),
                systematic_before=float(s0[j]),
                systematic_after=float(s1[j]),
            )
        )
    return out


def trial_shrinks(
    z_before: Sequence[np.ndarray],
    z_after: Sequence[np.ndarray],
    null: Sequence[np.ndarray],
    floor: float,
) -> np.ndarray:
    """Held-out shrink of every trial whose baseline gap is significant.

    ``1 - sqrt(max(S1, 0) / S0)`` per trial with ``S0 > f N`` (``S = sum z^2 - N0``, ``N0`` the
    trial's chi2 of a correct model, ``N`` its samples, ``f`` = ``floor``, the systematic ratio
    below which a gap is not told from the noise): negative when the effect set predicts the
    trial worse than the baseline.  The spread over the trials shows how well the fitted effect
    carries over from one trial (specimen, thickness, speed) to another.

    Parameters
    ----------
    z_before, z_after : sequence of ndarray
        Per trial: the baseline's and the effect set's held-out ``z`` (1).
    null : sequence of ndarray
        Per trial: the expected ``z^2`` of a correct model per sample (1).
    floor : float
        Systematic ratio of the significance level (1).

    Returns
    -------
    ndarray
        One shrink per trial (1), NaN where the baseline's gap on the trial is not significant
        (there is nothing to shrink: the trial says nothing of the transfer).
    """
    n0 = np.array([float(np.sum(n)) for n in null])
    s0 = np.array([float(z @ z) for z in z_before]) - n0
    s1 = np.array([float(z @ z) for z in z_after]) - n0
    significant = s0 > floor * np.array([z.size for z in z_before])
    return np.where(significant, _shrink(s0, s1), np.nan)
