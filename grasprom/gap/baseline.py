"""The baseline gap: residuals of the baseline model (static derived chain + surrogate tissue
force at the measured angle) on the trials in contact, its systematic gap ratio, and where it
lies (by phase, direction, trial condition and block of the chain).

``chi2 = sum z_i^2`` (``z_i = r_i / s_i`` beyond the force range of the encoder level where the
angle rests in one: :mod:`~grasprom.gap.likelihood`); the *systematic gap ratio*
``rho = (chi2 - N0) / N`` is the systematic residual variance in units of the noise variance (0
for a perfect model), ``N0 = sum E[z_i^2]`` the chi2 a correct model leaves (``N`` without
resting samples).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from grasprom.chain import kinematics as kin
from grasprom.gap.blocks import block_analysis
from grasprom.gap.criteria import SIGNIFICANT_RHO
from grasprom.gap.prepare import DIRECTIONS, PHASES, PreparedTrial
from grasprom.gap.stats import residual_stats, rms, stats_by_label
from grasprom.gap.trials import FloatArray
from grasprom.surrogate import Surrogate


@dataclass
class BaselineGap:
    """The baseline residuals of the trials in contact and their summary.

    Attributes
    ----------
    residuals : list of ndarray
        Measured - baseline handle force per trial (N).
    n_samples : int
        Analysis samples of all trials.
    noise_N : float
        Median handle sensor noise (N).
    chi2, rho, systematic_chi2 : float
        Weighted chi2 (1), systematic gap ratio ``(chi2 - N0) / N`` and ``chi2 - N0``.
    labels, dlabels : list of ndarray
        Phase and direction labels per trial.
    conditions : list of dict
        Closing speed, thickness and speed class per trial (:func:`trial_conditions`).
    summary : dict
        The ``baseline`` section of the report (``by_block`` included).
    block_how : str
        How the jaw-force residual was attributed without a gap channel.
    z : list of ndarray
        The baseline's ``z`` per trial (1).
    null : list of ndarray
        The expected ``z^2`` of a correct model per sample, per trial (1).
    n_null : float
        ``N0``: their sum, the chi2 a correct model leaves (1).
    """

    residuals: list[FloatArray]
    n_samples: int
    noise_N: float
    chi2: float
    rho: float
    systematic_chi2: float
    labels: list[NDArray[np.int_]]
    dlabels: list[NDArray[np.int_]]
    conditions: list[dict[str, Any]]
    summary: dict[str, Any] = field(default_factory=dict)
    block_how: str = ""
    z: list[FloatArray] = field(default_factory=list)
    null: list[FloatArray] = field(default_factory=list)
    n_null: float = 0.0


def trial_conditions(
    preps: Sequence[PreparedTrial], chain: kin.ChainParams
) -> list[dict[str, Any]]:
    """Closing speed (deg/s), thickness (mm) and speed class (fast / slow vs median) per trial."""
    out = []
    for p in preps:
        closing = p.direction == 0
        if np.any(closing):
            i0 = int(np.argmax(closing))
            i1 = int(np.argmin(p.theta))
            span = float(p.theta[i0] - p.theta[i1])
            dur = float(p.t[i1] - p.t[i0])
            speed = span / dur if dur > 0 else float("nan")
        else:
            speed = float("nan")
        out.append({"closing_speed_deg_per_s": speed, "thickness_mm": p.thickness})
    speeds = np.array([c["closing_speed_deg_per_s"] for c in out])
    med = float(np.nanmedian(speeds)) if np.any(np.isfinite(speeds)) else float("nan")
    for c in out:
        s = c["closing_speed_deg_per_s"]
        c["speed_class"] = "fast" if (math.isfinite(s) and s > med * 1.001) else "slow"
    return out


def _by_condition(
    res0: Sequence[FloatArray], conds: Sequence[dict[str, Any]], key: str, total_ss: float
) -> dict[str, Any]:
    """:func:`residual_stats` of the trials grouped by the condition ``key``."""
    vals = sorted({str(c[key]) for c in conds})
    out = {}
    for v in vals:
        rs = [r for r, c in zip(res0, conds) if str(c[key]) == v]
        rr = np.concatenate(rs)
        out[v] = residual_stats(rr, total_ss)
    return out


def _summary(preps: Sequence[PreparedTrial], gap: BaselineGap) -> dict[str, Any]:
    """The ``baseline`` section of the report (``by_block`` left None)."""
    res0, conds, noise, rho0 = gap.residuals, gap.conditions, gap.noise_N, gap.rho
    total_ss = float(sum(r @ r for r in res0))
    return {
        "model": "static derived chain + surrogate tissue force at the measured angle",
        "rms_N": rms(res0),
        "bias_N": float(np.concatenate(res0).mean()),
        "noise_N": noise,
        "encoder_quantum_deg": float(np.median([p.quantum_deg for p in preps])),
        "model_uncertainty_rms_N": float(
            math.sqrt(np.mean(np.concatenate([p.sigma**2 for p in preps]) - noise**2).clip(0))
        ),
        "systematic_ratio": rho0,
        "systematic_rms_N": float(math.sqrt(max(rho0, 0.0))) * noise,
        "significant": bool(rho0 > SIGNIFICANT_RHO),
        "n_samples": gap.n_samples,
        "by_phase": stats_by_label(res0, gap.labels, PHASES),
        "by_direction": stats_by_label(res0, gap.dlabels, DIRECTIONS),
        "by_condition": {
            "thickness_mm": _by_condition(res0, conds, "thickness_mm", total_ss),
            "speed": _by_condition(res0, conds, "speed_class", total_ss),
        },
        "by_trial": [
            {
                "trial": p.trial.name,
                "trial_id": p.trial.trial_id,
                **c,
                **residual_stats(r, total_ss),
            }
            for p, c, r in zip(preps, conds, res0)
        ],
        "by_block": None,
    }


def baseline_z(p: PreparedTrial) -> FloatArray:
    """The baseline's ``z`` of every sample (:mod:`~grasprom.gap.likelihood`; the plain
    ``r / sigma`` of a trial prepared without the interval)."""
    return (p.F - p.F0) / p.sigma if p.z0 is None else p.z0


def null_counts(p: PreparedTrial) -> FloatArray:
    """The expected ``z^2`` of every sample under a correct model (1 without the interval)."""
    return np.ones(p.t.size) if p.null is None else p.null


def baseline_gap(
    preps: Sequence[PreparedTrial], surrogate: Surrogate, chain: kin.ChainParams
) -> BaselineGap:
    """Residuals, systematic gap ratio and summary of the baseline on prepared trials.

    Parameters
    ----------
    preps : sequence of PreparedTrial
        Trials in contact with the tissue.
    surrogate : Surrogate
    chain : kinematics.ChainParams

    Returns
    -------
    BaselineGap
    """
    n = int(sum(p.t.size for p in preps))
    res0 = [p.F - p.F0 for p in preps]
    z0 = [baseline_z(p) for p in preps]
    nulls = [null_counts(p) for p in preps]
    n0 = float(sum(np.sum(x) for x in nulls))
    chi0 = float(sum(z @ z for z in z0))
    gap = BaselineGap(
        residuals=res0,
        n_samples=n,
        noise_N=float(np.median([p.noise_N for p in preps])),
        chi2=chi0,
        rho=(chi0 - n0) / n,
        systematic_chi2=chi0 - n0,
        labels=[p.phase for p in preps],
        dlabels=[p.direction for p in preps],
        conditions=trial_conditions(preps, chain),
        z=z0,
        null=nulls,
        n_null=n0,
    )
    gap.summary = _summary(preps, gap)
    gap.summary["by_block"], gap.block_how = block_analysis(preps, surrogate, chain)
    return gap
