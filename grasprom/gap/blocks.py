"""Block analysis: the baseline residual split sample by sample between the blocks of the chain
(tissue, mechanism, sensor) from the optional measured channels ``force_jaw_N`` / ``gap_mm``.

Without a gap channel the jaw-force residual is split between tissue and the gap mechanism by
fitting both (:func:`jaw_path_split`); the handle residual left by the measured jaw force is split
between the handle force sensor and the chain (:func:`sensor_split`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from grasprom.chain import kinematics as kin
from grasprom.gap.criteria import PAIR_GAIN, SIGNIFICANT_RHO
from grasprom.gap.effects import BLOCKS, EFFECT_ORDER, EFFECTS, n_params
from grasprom.gap.fit import Fit, fit_effects, predict, sub_fit
from grasprom.gap.prepare import PreparedTrial
from grasprom.gap.signals import noise_sigma, smooth
from grasprom.gap.trials import FloatArray
from grasprom.surrogate import Surrogate

GAP_MECHANISM = ("backlash", "jaw_compliance")
"""Mechanism candidates that act on the jaw gap (between the handle angle and the jaws).

Without a ``gap_mm`` channel the deviation of the measured jaw force from the surrogate at the
kinematic gap comes either from the tissue block (the force law: candidates of block ``tissue``)
or from these (the gap the tissue sees); :func:`jaw_path_split` decides by fitting both.
"""
SMOOTH_S = 0.02
"""Centred moving-average window of the jaw force channel in the block analysis (s)."""


# =============================================================================== jaw path
def jaw_path_split(
    jpreps: Sequence[PreparedTrial], surrogate: Surrogate, chain: kin.ChainParams
) -> tuple[list[dict[str, FloatArray]], str, str]:
    """Split the jaw-force residual at the kinematic gap between tissue and mechanism.

    ``jpreps`` carry ``F = handle_force_N(F_jaw_measured, theta)`` (the measured jaw force taken
    to the handle through the ideal chain), so their baseline residual is
    ``g'/L3 (F_jaw - F_s(g(theta)))`` (N at the handle).  Without a gap channel two causes show
    there: a wrong tissue force law (scale, wall thickness, rate dependence) and a wrong gap
    (the jaws are not where the handle angle puts them: play, compliance).  Both act through
    the surrogate differently -- a gap error is a shift along the force-gap curve that depends
    on the load (compliance, >= 0) or on the motion direction and persists at rest (play, >= 0);
    a force-law error scales, reshapes or relaxes the curve -- so each tissue candidate and each
    of :data:`GAP_MECHANISM` is fitted to it (weighted least squares on all trials, penalty
    ``ln N`` per parameter) and the best one names the block.  If a candidate of the other block
    then removes at least :data:`PAIR_GAIN` of the systematic residual the first leaves (and
    lowers the penalised fit), the pair's prediction is split by effect.  What the candidates
    leave (noise, model mismatch) stays in the block of the best single candidate.  A residual
    within the noise (systematic ratio <= :data:`SIGNIFICANT_RHO`) is not fitted and counts as
    tissue.

    Returns
    -------
    list of dict
        Per trial ``{"tissue": r, "mechanism": r}`` (N at the handle), summing to the residual.
    str
        The block holding the rest (``"tissue"`` or ``"mechanism"``).
    str
        What decided the split.
    """
    res0 = [p.F - p.F0 for p in jpreps]
    n = int(sum(p.t.size for p in jpreps))
    chi0 = float(sum(np.sum((r / p.sigma) ** 2) for r, p in zip(res0, jpreps)))
    if chi0 / n - 1.0 <= SIGNIFICANT_RHO:
        return (
            [{"tissue": r, "mechanism": np.zeros_like(r)} for r in res0],
            "tissue",
            "jaw force at the kinematic gap within the noise",
        )
    best, chosen = _jaw_path_fit(jpreps, n, surrogate, chain)
    home = EFFECTS[best].block
    out = []
    for p, r in zip(jpreps, res0):
        full = predict(p, chosen, surrogate, chain) - p.F0
        own = full
        if len(chosen.effects) == 2:
            own = predict(p, sub_fit(chosen, [best]), surrogate, chain) - p.F0
        parts = {"tissue": np.zeros_like(r), "mechanism": np.zeros_like(r)}
        parts[home] += own + (r - full)  # the best candidate and what no candidate explains
        parts["mechanism" if home == "tissue" else "tissue"] += full - own
        out.append(parts)
    return out, home, f"jaw force vs. kinematic gap fitted best by {' + '.join(chosen.effects)}"


def _jaw_path_fit(
    jpreps: Sequence[PreparedTrial], n: int, surrogate: Surrogate, chain: kin.ChainParams
) -> tuple[str, Fit]:
    """Best single tissue / gap-mechanism candidate and the fit kept (it, or a pair with it).

    ``n`` is the number of samples (for the ``ln N`` penalty per parameter).
    """
    lnn = math.log(max(n, 2))
    cands = [e for e in EFFECT_ORDER if EFFECTS[e].block == "tissue"] + list(GAP_MECHANISM)
    fits = {e: fit_effects(jpreps, (e,), surrogate, chain) for e in cands}

    def crit(f: Fit) -> float:
        return f.chi2 + lnn * n_params(f.effects)

    best = min(cands, key=lambda e: crit(fits[e]))
    home = EFFECTS[best].block
    chosen = fits[best]
    for e in cands:
        left = chosen.chi2 - n
        if EFFECTS[e].block == home or left <= 0:
            continue
        f2 = fit_effects(jpreps, tuple(sorted((best, e), key=EFFECT_ORDER.index)), surrogate, chain)
        if (chosen.chi2 - f2.chi2) / left >= PAIR_GAIN and crit(f2) < crit(chosen):
            chosen = f2
    return best, chosen


# =============================================================================== sensor
def sensor_split(items: Sequence[dict[str, Any]]) -> list[dict[str, FloatArray]]:
    """Split the handle residual left by the measured jaw force into sensor and mechanism (N).

    ``r = F_meas - Hc(t)``, ``Hc = handle_force_N(F_jaw_measured, theta)`` the handle force the
    ideal chain needs for the measured jaw force.  Per trial, with one delay ``d`` (s) common to
    all trials (searched on the grid of the latency candidate, refined by a bounded Brent
    search), linear least squares of::

        F_meas = (1 + b + k t) Hc(t - d) + a + c t         handle force sensor: gain, offset,
                                                           their drifts, delay (a first-order
                                                           lag of the sensor shows as extra
                                                           delay); t from the trial's start
                 + Fc s + mu s |F_jaw g'/L3| + beta v      friction of the chain (the terms of
                                                           the mechanism_friction candidate)

    The sensor part is ``(1 + b + k t) Hc(t - d) + a + c t - Hc(t)``; the mechanism part is the
    rest of ``r``: the friction terms and what neither explains (the chain between the jaw load cell
    and the handle is the mechanism).

    Parameters
    ----------
    items : sequence of dict
        Per trial: ``t`` (analysis grid, s), ``F`` (measured handle force there, N), ``hc``
        (``Hc`` there, N), ``raw_t`` / ``hc_raw`` (``Hc`` at the raw rate, from the smoothed jaw
        force) and ``fric`` (the three friction columns).

    Returns
    -------
    list of dict
        Per trial ``{"sensor": r, "mechanism": r}`` (N), summing to ``F - hc``.
    """
    spec = EFFECTS["latency"].params[0]
    grid = spec.grid

    def solve(d: float, keep: bool = False) -> Any:
        ss, out = 0.0, []
        for it in items:
            t = it["t"]
            hd = np.interp(t - d, it["raw_t"], it["hc_raw"])
            ts = t - t[0]
            a_sen = np.column_stack([np.ones_like(t), hd, ts, ts * hd])
            a = np.column_stack([a_sen, it["fric"]])
            y = it["F"] - hd
            c, *_ = np.linalg.lstsq(a, y, rcond=None)
            r = y - a @ c
            ss += float(r @ r)
            if keep:
                sen = hd - it["hc"] + a_sen @ c[: a_sen.shape[1]]
                out.append({"sensor": sen, "mechanism": it["F"] - it["hc"] - sen})
        return out if keep else ss

    vals = [solve(d) for d in grid]
    i = int(np.argmin(vals))
    lo = grid[i - 1] if i > 0 else spec.lo
    hi = grid[i + 1] if i < len(grid) - 1 else spec.hi
    d = grid[i]
    r = minimize_scalar(solve, bounds=(lo, hi), method="bounded", options={"xatol": 5e-4})
    if r.fun < vals[i]:
        d = float(r.x)
    return solve(d, keep=True)


# =============================================================================== blocks
@dataclass
class _BlockParts:
    """Per-block residual parts of the trials with a measured channel, being accumulated."""

    parts: dict[str, list[FloatArray]] = field(default_factory=lambda: {b: [] for b in BLOCKS})
    weights: list[FloatArray] = field(default_factory=list)  # 1 / s_i^2 (1/N^2)
    # expected weighted sum of squares of the noise per block
    noise_ss: dict[str, float] = field(default_factory=lambda: {b: 0.0 for b in BLOCKS})
    jaw_only: list[tuple[int, PreparedTrial]] = field(default_factory=list)
    jaw_only_noise: float = 0.0
    sens: list[tuple[int, dict[str, Any]]] = field(default_factory=list)


@dataclass
class _TrialTerms:
    """What the channels of one trial share: grid indices, ``dFi/dFg`` and the error model."""

    k: int  # index of the trial among those with a channel
    idx: np.ndarray  # raw sample of each analysis sample
    gp: FloatArray  # dFi/dFg = g'/L3 (1)
    w_i: FloatArray  # 1 / s_i^2 (1/N^2)
    sig_h: float  # handle sensor noise (N)
    s_model2: FloatArray  # model part of s_i^2: quantum, surrogate (N^2)


def _add_gap_channel(
    acc: _BlockParts, p: PreparedTrial, tt: _TrialTerms, f_kin: FloatArray, surrogate: Surrogate
) -> FloatArray:
    """Gap part of the mechanism from ``gap_mm``; the surrogate force at the measured gap (N)."""
    tr = p.trial
    # the gap sensor's noise reaches the force through the surrogate's stiffness
    # (hundreds of N/mm once the walls meet): smooth it as the jaw force, and count what
    # is left of it in the noise of both parts it enters (mechanism +, tissue -)
    g_sm, wg = smooth(tr.gap_mm, tr.time_s, SMOOTH_S)
    g_meas = g_sm[tt.idx]
    f_gm = np.asarray(surrogate.force(g_meas, p.thickness, p.material))
    acc.parts["mechanism"][tt.k] += (f_gm - f_kin) * tt.gp
    sig_g = noise_sigma(tr.gap_mm)
    if math.isfinite(sig_g) and sig_g > 0:
        k_s = np.asarray(surrogate.stiffness(g_meas, p.thickness, p.material))
        gap_noise = float(np.sum(tt.w_i * (tt.gp * k_s * sig_g) ** 2 / wg))
        acc.noise_ss["mechanism"] += gap_noise
        acc.noise_ss["tissue"] += gap_noise
    return f_gm


def _add_jaw_channel(
    acc: _BlockParts, p: PreparedTrial, tt: _TrialTerms, h_gm: FloatArray, chain: kin.ChainParams
) -> None:
    """Jaw-force part (tissue, or queued for :func:`jaw_path_split`) and the sensor item."""
    tr = p.trial
    fj_raw, w = smooth(tr.force_jaw_N, tr.time_s, SMOOTH_S)
    hc_raw = np.asarray(kin.handle_force_N(fj_raw, tr.theta_deg, chain))
    hc = hc_raw[tt.idx]
    sig_j = noise_sigma(tr.force_jaw_N)
    jaw_var = (tt.gp * sig_j) ** 2 / w if math.isfinite(sig_j) else np.zeros_like(p.theta)
    jaw_noise = float(np.sum(tt.w_i * (tt.s_model2 + jaw_var)))
    if tr.gap_mm is not None:
        acc.parts["tissue"][tt.k] += hc - h_gm
        acc.noise_ss["tissue"] += jaw_noise
    else:
        # the jaw path keeps the Gaussian quantum term (no interval likelihood)
        jp = replace(p, F=hc, sigma=np.sqrt(tt.s_model2 + jaw_var + 1e-8), sigma_fit=None,
                     rest_halfwidth_deg=None, raw_rest_halfwidth_deg=None, z0=None,
                     null=None)  # fmt: skip
        acc.jaw_only.append((tt.k, jp))
        acc.jaw_only_noise += jaw_noise
    fric = np.column_stack([p.motion_dir, p.motion_dir * np.abs(fj_raw[tt.idx] * tt.gp), p.v_mm_s])
    item = {"t": p.t, "F": p.F, "hc": hc, "raw_t": tr.time_s, "hc_raw": hc_raw, "fric": fric}
    acc.sens.append((tt.k, item))
    acc.noise_ss["mechanism"] += float(np.sum(tt.w_i * tt.sig_h**2))


def _add_trial(
    acc: _BlockParts, p: PreparedTrial, surrogate: Surrogate, chain: kin.ChainParams
) -> None:
    """Add the exactly attributable parts of one trial with a measured channel."""
    tr = p.trial
    th = p.theta
    gp = np.asarray(kin.dgap_dtheta_mm_per_rad(th, chain)) / chain.L3_mm  # dFi/dFg
    g_kin = np.asarray(kin.gap_mm(th, chain))
    f_kin = np.asarray(surrogate.force(g_kin, p.thickness, p.material))
    k = len(acc.parts["tissue"])
    for b in BLOCKS:
        acc.parts[b].append(np.zeros_like(th))
    w_i = 1.0 / p.sigma**2
    acc.weights.append(w_i)
    sig_h = p.noise_N if math.isfinite(p.noise_N) and p.noise_N > 0 else 0.0
    s_model2 = np.maximum(p.sigma**2 - max(sig_h, 0.01) ** 2, 0.0)  # quantum, surrogate
    tt = _TrialTerms(k, np.searchsorted(tr.time_s, p.t), gp, w_i, sig_h, s_model2)
    f_gm = f_kin
    if tr.gap_mm is not None:
        f_gm = _add_gap_channel(acc, p, tt, f_kin, surrogate)
    h_gm = np.asarray(kin.handle_force_N(f_gm, th, chain))
    if tr.force_jaw_N is None:
        acc.parts["tissue"][k] += p.F - h_gm
        acc.noise_ss["tissue"] += float(np.sum(w_i * (s_model2 + sig_h**2)))
        return
    _add_jaw_channel(acc, p, tt, h_gm, chain)


def _add_fitted_splits(acc: _BlockParts, surrogate: Surrogate, chain: kin.ChainParams) -> str:
    """Add the model-decided splits (jaw path, sensor); how the jaw path was attributed."""
    how = ""
    if acc.jaw_only:
        splits, home, how = jaw_path_split([jp for _, jp in acc.jaw_only], surrogate, chain)
        for (k, _), sp in zip(acc.jaw_only, splits):
            for b, r in sp.items():
                acc.parts[b][k] += r
        acc.noise_ss[home] += acc.jaw_only_noise
    if acc.sens:
        for (k, _), sp in zip(acc.sens, sensor_split([it for _, it in acc.sens])):
            for b, r in sp.items():
                acc.parts[b][k] += r
    return how


def _block_stats(acc: _BlockParts) -> dict[str, Any]:
    """``rms_N``, ``bias_N`` (N, raw parts) and systematic ``share`` per block."""
    parts, weights, noise_ss = acc.parts, acc.weights, acc.noise_ss
    ss = {
        b: float(sum(float(w_i @ (x * x)) for x, w_i in zip(v, weights))) for b, v in parts.items()
    }
    sys_ss = {b: max(ss[b] - noise_ss[b], 0.0) for b in BLOCKS}
    tot = sum(sys_ss.values())
    if tot <= 0:
        sys_ss, tot = ss, sum(ss.values())
    out = {}
    for b, v in parts.items():
        r = np.concatenate(v)
        out[b] = {
            "rms_N": float(math.sqrt(r @ r / r.size)),
            "bias_N": float(r.mean()),
            "share": sys_ss[b] / tot if tot > 0 else 0.0,
        }
    return out


def block_analysis(
    preps: Sequence[PreparedTrial], surrogate: Surrogate, chain: kin.ChainParams
) -> tuple[dict[str, Any] | None, str]:
    """Baseline residual per block of the chain from the optional ``force_jaw_N`` / ``gap_mm``.

    The handle residual ``r = F_meas - F0`` (N) of every trial with either channel is split
    exactly, sample by sample (``g'/L3 = dFi/dFg`` maps a jaw force to the handle, ``g`` the
    kinematic gap of the measured angle, ``F_s`` the surrogate, ``Hc = handle_force_N(F_jaw,
    theta)``; the jaw force is smoothed over :data:`SMOOTH_S`):

    ``mechanism`` (gap)
        ``g'/L3 (F_s(g_meas) - F_s(g))``: the tissue sees another gap than the kinematic one
        (play, compliance); only with ``gap_mm``.
    ``tissue``
        ``g'/L3 (F_jaw - F_s(g_meas))``: the measured jaw force differs from the surrogate at the
        measured gap.  Without ``gap_mm``, ``g'/L3 (F_jaw - F_s(g))`` is split between tissue and
        the gap mechanism by :func:`jaw_path_split`.
    ``sensor`` and ``mechanism`` (transmission)
        ``F_meas - Hc``: the handle force the chain does not account for given the measured jaw
        force, split by :func:`sensor_split` into the handle force sensor (offset, gain, drift,
        delay) and the chain (friction and the rest).

    With ``gap_mm`` but no jaw force, ``F_meas - handle_force_N(F_s(g_meas), theta)`` counts as
    tissue (it cannot be separated from friction or sensor errors there).  ``share`` is each
    block's sum of squares less the part the white noise of its channel puts there (handle
    sensor noise in the transmission part, the smoothed jaw load cell noise in the jaw-force
    part), clipped at 0, over the total (raw sums of squares when all are within the noise);
    ``rms_N`` and ``bias_N`` are of the raw parts.

    Returns
    -------
    dict or None
        ``{block: {"rms_N", "bias_N", "share"}}`` for the blocks of :data:`BLOCKS`; None when no
        trial has either channel.
    str
        How the jaw-force residual was attributed without a gap channel ("" when not needed).
    """
    acc = _BlockParts()
    for p in preps:
        tr = p.trial
        if tr is None or (tr.force_jaw_N is None and tr.gap_mm is None):
            continue
        _add_trial(acc, p, surrogate, chain)
    if not acc.parts["tissue"]:
        return None, ""
    how = _add_fitted_splits(acc, surrogate, chain)
    return _block_stats(acc), how
