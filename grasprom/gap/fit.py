"""Weighted least-squares fit of an effect set on prepared trials by variable projection:
linear parameters by bounded linear least squares (with the active set of the jaw-force clip),
at most two non-linear ones by grid + bounded Brent search; predictions and reported values."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import lsq_linear, minimize_scalar

from grasprom.chain import kinematics as kin
from grasprom.gap.effects import EFFECTS, ParamSpec, linear_params, nonlinear_params
from grasprom.gap.likelihood import interval_z
from grasprom.gap.model import combine, evaluate_model, visco_index
from grasprom.gap.prepare import PreparedTrial
from grasprom.gap.trials import FloatArray
from grasprom.surrogate import Surrogate


@dataclass
class Fit:
    """A fitted effect set: non-linear parameters, linear coefficients and the weighted chi2."""

    effects: tuple[str, ...]
    nl: tuple[float, ...]
    coef: FloatArray
    chi2: float


def _versions(
    p: PreparedTrial,
    effects: Sequence[str],
    nl: Sequence[float],
    surrogate: Surrogate,
    chain: kin.ChainParams,
    cache: bool,
) -> list[tuple[FloatArray, FloatArray, FloatArray]]:
    """The model (``F0``, ``Phi``, ``T``) at the level's centre and at the two ends of the encoder
    level where the angle rests in one (the centre three times without such samples)."""
    c = evaluate_model(p, effects, nl, surrogate, chain, cache)
    hw = p.rest_halfwidth_deg
    if hw is None or not np.any(hw > 0):
        return [c, c, c]
    ends = [evaluate_model(p, effects, nl, surrogate, chain, cache, side=s) for s in (-1, 1)]
    return [c, *ends]


def _bvls_clip(
    y: FloatArray, A: FloatArray, T: FloatArray, lo: FloatArray, hi: FloatArray, vi: np.ndarray
) -> FloatArray:
    """Bounded linear least squares of ``y ~ combine(0, A, T, coef, vi)`` (the active set of the
    jaw-force clip, up to 4 passes)."""
    clipped = np.zeros(y.size, dtype=bool)
    coef = np.zeros(A.shape[1])
    for _ in range(4 if vi.size else 1):
        yy = np.where(clipped, y + T, y)
        AA = A.copy()
        if vi.size:
            AA[np.ix_(clipped, vi)] = 0.0
        s = np.sqrt(np.sum(AA * AA, axis=0))
        s[s == 0] = 1.0
        coef = lsq_linear(AA / s, yy, bounds=(lo * s, hi * s), method="bvls").x / s
        if not vi.size:
            break
        new = (T + A[:, vi] @ coef[vi]) < 0
        if np.array_equal(new, clipped):
            break
        clipped = new
    return coef


def _outside(r: FloatArray) -> tuple[FloatArray, np.ndarray, np.ndarray]:
    """Residuals ``r`` (versions x samples, weighted) -> the part outside the span of the versions
    (:func:`~grasprom.gap.likelihood.deadzone`), the version nearest to the measurement and
    whether the sample lies outside the span."""
    above = np.all(r > 0, axis=0)
    below = np.all(r < 0, axis=0)
    sel = np.where(above, np.argmin(r, axis=0), np.argmax(r, axis=0))
    z = np.where(above | below, r[sel, np.arange(r.shape[1])], 0.0)
    return z, sel, above | below


DEADZONE_PASSES = 8
"""Most passes of the active set of the interval likelihood in :func:`solve_linear`."""


def solve_linear(
    preps: Sequence[PreparedTrial],
    effects: Sequence[str],
    nl: Sequence[float],
    surrogate: Surrogate,
    chain: kin.ChainParams,
    cache: bool,
) -> tuple[FloatArray, float]:
    """Linear coefficients at fixed non-linear parameters ``nl`` and the weighted chi2 (1) of the
    interval likelihood (:mod:`grasprom.gap.likelihood`).

    Where the angle rests in an encoder level the measured force costs only its distance to the
    range the model spans over the level: an active set over the samples (outside the range,
    and at which end of the level) solved by bounded least squares until it repeats.
    """
    parts: list[list[list[FloatArray]]] = [[[], [], []] for _ in range(3)]  # y, A, T by version
    for p in preps:
        w = 1.0 / p.fit_sigma()
        for k, (f0, phi, tis) in enumerate(_versions(p, effects, nl, surrogate, chain, cache)):
            parts[0][k].append((p.F - f0) * w)
            parts[1][k].append(phi * w[:, None])
            parts[2][k].append(tis * w)
    y = np.stack([np.concatenate(v) for v in parts[0]])
    A = np.stack([np.vstack(v) for v in parts[1]])
    T = np.stack([np.concatenate(v) for v in parts[2]])
    cols = linear_params(effects)
    vi = visco_index(effects)
    if A.shape[2] == 0:
        z = _outside(y)[0]
        return np.zeros(0), float(z @ z)
    lo = np.array([p.lo for _, p in cols])
    hi = np.array([p.hi for _, p in cols])
    coef = _bvls_clip(y[0], A[0], T[0], lo, hi, vi)
    best: tuple[FloatArray, float] | None = None
    state = None
    rows = np.arange(y.shape[1])
    for _ in range(DEADZONE_PASSES):
        r = np.stack([y[k] - combine(np.zeros_like(y[k]), A[k], T[k], coef, vi) for k in range(3)])
        z, sel, out = _outside(r)
        chi2 = float(z @ z)
        if best is None or chi2 < best[1]:
            best = (coef, chi2)
        if state is not None and np.array_equal(sel, state[0]) and np.array_equal(out, state[1]):
            break
        state = (sel, out)
        i = rows[out]
        coef = _bvls_clip(y[sel[i], i], A[sel[i], i], T[sel[i], i], lo, hi, vi)
    assert best is not None
    return best


def fit_effects(
    preps: Sequence[PreparedTrial],
    effects: Sequence[str],
    surrogate: Surrogate,
    chain: kin.ChainParams,
) -> Fit:
    """Weighted least-squares fit of an effect set on ``preps`` (variable projection)."""
    nlp = [p for _, p in nonlinear_params(effects)]

    def obj(x: Sequence[float], cache: bool = False) -> float:
        return solve_linear(preps, effects, x, surrogate, chain, cache)[1]

    def line_search(k: int, x: list[float], refine_only: bool = False) -> list[float]:
        return _line_search(obj, nlp[k], k, x, refine_only)

    x = [0.0 if p.lo <= 0.0 <= p.hi else p.lo for p in nlp]
    if len(nlp) == 1:
        x = line_search(0, x)
    elif len(nlp) >= 2:
        for k in range(len(nlp)):
            x = line_search(k, x)
        for k in range(len(nlp)):
            x = line_search(k, x, refine_only=True)
    coef, chi2 = solve_linear(preps, effects, x, surrogate, chain, False)
    return Fit(tuple(effects), tuple(x), coef, chi2)


def _line_search(
    obj: Callable[[Sequence[float], bool], float],
    ps: ParamSpec,
    k: int,
    x: list[float],
    refine_only: bool = False,
) -> list[float]:
    """Minimise ``obj`` over the ``k``-th non-linear parameter: grid, then bounded Brent.

    ``refine_only`` searches one grid step either side of the current value instead of the grid.
    """
    grid = list(ps.grid)

    def f1(z: float, cache: bool = False) -> float:
        xx = list(x)
        xx[k] = z
        return obj(xx, cache)

    if refine_only:  # around the current value, one grid step either side
        i = int(np.argmin(np.abs(np.array(grid) - x[k])))
        step = grid[min(i + 1, len(grid) - 1)] - grid[max(i - 1, 0)]
        a, b = max(ps.lo, x[k] - 0.5 * step), min(ps.hi, x[k] + 0.5 * step)
        best_x, best_v = x[k], f1(x[k])
    else:
        vals = [f1(gv, cache=True) for gv in grid]
        i = int(np.argmin(vals))
        a = grid[max(i - 1, 0)] if i > 0 else ps.lo
        b = grid[min(i + 1, len(grid) - 1)] if i < len(grid) - 1 else ps.hi
        best_x, best_v = grid[i], vals[i]
    if b > a:
        r = minimize_scalar(
            f1,
            bounds=(a, b),
            method="bounded",
            options={"xatol": 4e-3 * (ps.hi - ps.lo), "maxiter": 12},
        )
        if r.fun < best_v:
            best_x = float(r.x)
    out = list(x)
    out[k] = best_x
    return out


def predict(
    prep: PreparedTrial, fit: Fit, surrogate: Surrogate, chain: kin.ChainParams
) -> FloatArray:
    """Handle force (N) of a fitted effect set on one prepared trial."""
    f0, phi, tis = evaluate_model(prep, fit.effects, fit.nl, surrogate, chain)
    return combine(f0, phi, tis, fit.coef, visco_index(fit.effects))


def predict_z(
    prep: PreparedTrial, fit: Fit, surrogate: Surrogate, chain: kin.ChainParams
) -> tuple[FloatArray, FloatArray]:
    """Handle force (N) of a fitted effect set on one prepared trial and the ``z`` of its samples
    in the interval likelihood (:func:`~grasprom.gap.likelihood.interval_z`)."""
    vi = visco_index(fit.effects)
    preds = [
        combine(f0, phi, tis, fit.coef, vi)
        for f0, phi, tis in _versions(prep, fit.effects, fit.nl, surrogate, chain, False)
    ]
    return preds[0], interval_z(prep.F, preds[0], (preds[1], preds[2]), prep.fit_sigma())


def fit_params(fit: Fit) -> dict[str, dict[str, float]]:
    """Reported parameter values per effect."""
    out: dict[str, dict[str, float]] = {e: {} for e in fit.effects}
    for (e, p), x in zip(nonlinear_params(fit.effects), fit.nl):
        out[e][p.name] = float(x) + p.offset
    for (e, p), c in zip(linear_params(fit.effects), fit.coef):
        out[e][p.name] = float(c) + p.offset
    return {e: {p.name: out[e][p.name] for p in EFFECTS[e].params} for e in fit.effects}


def sub_fit(fit: Fit, keep: Sequence[str]) -> Fit:
    """The part of a fitted effect set made of the effects ``keep`` (same parameter values)."""
    nl = tuple(x for (e, _), x in zip(nonlinear_params(fit.effects), fit.nl) if e in keep)
    coef = np.array([c for (e, _), c in zip(linear_params(fit.effects), fit.coef) if e in keep])
    return Fit(tuple(e for e in fit.effects if e in keep), nl, coef, float("nan"))
