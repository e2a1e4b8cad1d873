"""The diagnosis' forward model: the baseline chain plus candidate effects, evaluated on a
prepared trial as ``F0 + Phi @ coef`` (non-linear parameters inside ``F0``, linear ones as basis
columns), with the play operator and the compliant-jaw solve it needs."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

from grasprom.chain import kinematics as kin
from grasprom.gap.effects import PRONY_TAUS_S, linear_params, nonlinear_params
from grasprom.gap.prepare import PreparedTrial
from grasprom.gap.trials import FloatArray
from grasprom.surrogate import Surrogate


def play_deg(x: FloatArray, width: float) -> FloatArray:
    """Output of a play (backlash) element of total width ``width`` (deg) driven by ``x`` (deg)."""
    out = np.empty_like(x)
    h = 0.5 * width
    y = float(x[0])
    for i, xi in enumerate(x.tolist()):
        y = min(max(y, xi - h), xi + h)
        out[i] = y
    return out


def compliant_force(
    surrogate: Surrogate, g: FloatArray, c: float, t: float, mat: str, f_free: FloatArray
) -> FloatArray:
    """Solve ``F = F_s(g + c F)`` (N) on the contact samples, bracketed in ``[0, F_s(g)]``.

    Newton on ``r(F) = F - F_s(g + c F)`` (increasing, ``r' = 1 + c k_s``) with a bisection
    whenever the step leaves the bracket or does not halve the step before it (``rtsafe``):
    the surrogate's stiffness jumps where the walls meet, and a plain Newton iteration there can
    creep for many steps.  Converged to ``|r| <= 1e-10 max(1, F)`` (N), in 3-16 iterations on the
    shipped surrogate, at most 60.
    """
    out = np.zeros_like(g)
    m = f_free > 0
    if not np.any(m) or c <= 0:
        return f_free.copy()
    gg = g[m]
    lo = np.zeros_like(gg)
    hi = f_free[m].copy()
    f = hi * 0.5
    dx_old = hi - lo
    dx = dx_old.copy()
    for _ in range(60):
        gp = gg + c * f
        fs = np.asarray(surrogate.force(gp, t, mat))
        ks = np.asarray(surrogate.stiffness(gp, t, mat))
        r = f - fs  # increasing in f
        dr = 1.0 + c * ks
        lo = np.where(r < 0, f, lo)
        hi = np.where(r > 0, f, hi)
        done = (np.abs(r) <= 1e-10 * np.maximum(1.0, fs)) | (hi - lo <= 1e-13 * np.maximum(1.0, hi))
        if np.all(done):
            break
        fn = f - r / dr
        newton = (fn > lo) & (fn < hi) & (np.abs(2.0 * r) <= np.abs(dx_old * dr))
        dx_old = dx
        dx = np.where(newton, r / dr, f - 0.5 * (lo + hi))
        f = np.where(done, f, f - dx)
    out[m] = f
    return out


def _effective_motion(
    prep: PreparedTrial,
    effects: Sequence[str],
    nlv: dict[str, float],
    chain: kin.ChainParams,
    side: int = 0,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Angle the chain sees (deg), finger speed (mm/s) and motion direction after latency/play.

    ``side`` -1 / +1 puts the angle at the lower / upper end of the encoder level where it rests
    in one (:attr:`PreparedTrial.rest_halfwidth_deg`), 0 at the level's centre.
    """
    th = prep.theta
    raw_th = prep.raw_theta
    if side and prep.rest_halfwidth_deg is not None:
        th = th + side * prep.rest_halfwidth_deg
        raw_th = raw_th + side * prep.raw_rest_halfwidth_deg
    v = prep.v_mm_s
    sdir = prep.motion_dir
    if "latency" in effects and nlv["delay_s"] > 0:
        d = nlv["delay_s"]
        th = np.interp(prep.t - d, prep.raw_t, raw_th)
        v = np.interp(prep.t - d, prep.t, v)
        sdir = np.interp(prep.t - d, prep.t, sdir)
    lo, hi = kin.theta_range_deg(chain)
    if "backlash" in effects and nlv["play_deg"] > 0:
        th = np.clip(play_deg(th, nlv["play_deg"]), lo, hi)
    elif side:
        th = np.clip(th, lo, hi)
    return th, v, sdir


def _tissue_force(
    prep: PreparedTrial,
    effects: Sequence[str],
    nlv: dict[str, float],
    th: FloatArray,
    surrogate: Surrogate,
    chain: kin.ChainParams,
) -> FloatArray:
    """Jaw force of the tissue (N) at the angle ``th`` (deg): thickness error, compliance."""
    t_eff = prep.thickness
    if "thickness_error" in effects:
        tlo, thi = surrogate.thickness_range(prep.material)
        t_eff = min(max(t_eff + nlv["offset_mm"], tlo), thi)
    g = np.asarray(kin.gap_mm(th, chain))
    fe = np.asarray(surrogate.force(g, t_eff, prep.material), dtype=float)
    if "jaw_compliance" in effects and nlv["compliance_mm_per_N"] > 0:
        fe = compliant_force(surrogate, g, nlv["compliance_mm_per_N"], t_eff, prep.material, fe)
    return fe


def _linear_basis(
    prep: PreparedTrial,
    effects: Sequence[str],
    fe: FloatArray,
    gp: FloatArray,
    f0: FloatArray,
    v: FloatArray,
    sdir: FloatArray,
) -> FloatArray:
    """Basis columns ``Phi`` (N per unit coefficient) of the linear parameters, in order."""
    cols: list[FloatArray] = []
    for e in effects:
        if e == "tissue_viscoelasticity":
            dt = float(np.median(np.diff(prep.t))) if prep.t.size > 1 else 1e-3
            dfe = np.diff(fe, prepend=0.0)
            for tau in PRONY_TAUS_S:
                a = math.exp(-dt / tau)
                cols.append(lfilter([1.0], [1.0, -a], dfe) * gp)
        elif e == "mechanism_friction":
            cols += [sdir, sdir * np.abs(fe * gp), v]
        elif e == "tissue_stiffness_scale":
            cols.append(fe * gp)
        elif e == "sensor_offset_gain":
            cols += [np.ones_like(f0), f0]
        elif e == "sensor_drift":
            ts = prep.t - prep.raw_t[0]  # time since the trial's first sample (s)
            cols += [ts, ts * f0]
    return np.column_stack(cols) if cols else np.zeros((f0.size, 0))


def evaluate_model(
    prep: PreparedTrial,
    effects: Sequence[str],
    nl: Sequence[float],
    surrogate: Surrogate,
    chain: kin.ChainParams,
    cache: bool = False,
    side: int = 0,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Model handle force without linear terms ``F0`` (N), the linear basis ``Phi`` and ``T``.

    ``side`` -1 / +1: with the angle at an end of the encoder level where it rests in one (see
    :mod:`grasprom.gap.likelihood`), 0 at the level's centre.

    The augmented model is ``F0 + Phi @ coef`` (see :func:`combine` for the clip of the jaw
    force) with the linear coefficients of :func:`~grasprom.gap.effects.linear_params`; ``nl``
    are the non-linear parameters of :func:`~grasprom.gap.effects.nonlinear_params`; ``T`` is
    the tissue part of ``F0`` (N at the handle).
    """
    key = (tuple(effects), tuple(round(float(x), 12) for x in nl), side)
    if cache and key in prep.cache:
        return prep.cache[key]
    nlv = {p.name: float(x) for (_, p), x in zip(nonlinear_params(effects), nl)}
    th, v, sdir = _effective_motion(prep, effects, nlv, chain, side)
    fe = _tissue_force(prep, effects, nlv, th, surrogate, chain)
    gp = np.asarray(kin.dgap_dtheta_mm_per_rad(th, chain)) / chain.L3_mm  # dFi/dFg
    f0 = np.asarray(kin.handle_force_N(fe, th, chain), dtype=float)
    phi = _linear_basis(prep, effects, fe, gp, f0, v, sdir)
    out = (f0, phi, fe * gp)
    if cache:
        prep.cache[key] = out
    return out


def visco_index(effects: Sequence[str]) -> NDArray[np.int_]:
    """Indices of the viscoelastic (Prony) coefficients among the linear parameters."""
    return np.array(
        [i for i, (e, _) in enumerate(linear_params(effects)) if e == "tissue_viscoelasticity"],
        dtype=int,
    )


def combine(
    f0: FloatArray, phi: FloatArray, tis: FloatArray, coef: FloatArray, vi: NDArray[np.int_]
) -> FloatArray:
    """Augmented handle force (N): ``F0 + Phi coef`` with the viscoelastic jaw force >= 0."""
    if phi.shape[1] == 0:
        return f0
    out = f0 + phi @ coef
    if vi.size:
        jaw = tis + phi[:, vi] @ coef[vi]
        out = out - np.minimum(jaw, 0.0)
    return out
