"""Signal estimators of the diagnosis: white-noise sigma, encoder quantum, centred moving
average (pure numerics on sampled channels, no model)."""

from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import PchipInterpolator

from grasprom.gap.trials import FloatArray


def noise_sigma(x: FloatArray) -> float:
    """White-noise sigma from the median absolute second difference (robust to the signal)."""
    if x.size < 5:
        return float("nan")
    d2 = np.diff(x, 2)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6.0))


DEQUANTISE_MAX_GAP_S = 0.1
"""Longest time (s) between two counts of the same direction over which :func:`dequantise`
interpolates (longer: the handle is taken to rest in the level)."""


def dequantise(t: FloatArray, theta: FloatArray) -> tuple[FloatArray, np.ndarray]:
    """The angle behind a quantised (encoder) reading while it moves, at the sample times.

    The angle of :func:`reconstruct_angle` and the mask of the interpolated samples.
    """
    out, moving, _ = reconstruct_angle(t, theta)
    return out, moving


def _crossings(t: FloatArray, th: FloatArray) -> tuple[np.ndarray, FloatArray, FloatArray,
                                                        np.ndarray]:  # fmt: skip
    """First sample of each new level, crossing times and angles, and which crossing-to-crossing
    intervals are passed through in one motion (same direction, <= DEQUANTISE_MAX_GAP_S)."""
    ch = np.flatnonzero(np.diff(th) != 0.0) + 1
    kt = 0.5 * (t[ch - 1] + t[ch])
    kv = 0.5 * (th[ch - 1] + th[ch])
    step = np.sign(th[ch] - th[ch - 1])
    ok = (step[:-1] == step[1:]) & (kt[1:] - kt[:-1] <= DEQUANTISE_MAX_GAP_S)
    return ch, kt, kv, ok


def _runs(ok: np.ndarray) -> list[tuple[int, int]]:
    """``(first, last)`` crossing of every run of consecutive passed-through intervals."""
    d = np.diff(np.r_[0, ok.astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def reconstruct_angle(t: FloatArray, theta: FloatArray) -> tuple[FloatArray, np.ndarray,
                                                                 FloatArray]:  # fmt: skip
    """The angle behind a quantised (encoder) reading while it moves, and its uncertainty.

    A count changes when the true angle crosses the boundary between two levels, so at each
    change the true angle is known: the mid-level ``(theta[i-1] + theta[i]) / 2``, at about the
    middle of the sample interval. Between two crossings in the same direction less than
    :data:`DEQUANTISE_MAX_GAP_S` apart the handle moves through the level and the angle is
    interpolated between them, by a monotone cubic (PCHIP) through the crossings of the motion
    (linear where a motion has only two): it follows the acceleration out of a rest, where a
    straight line between the first two crossings is up to 0.15 of the quantum off, several N
    of handle force on the steep wall-contact rise. Elsewhere (at rest, at a reversal, at the
    ends) the reading is kept: the true angle is anywhere in the level, whose centre is the
    unbiased estimate. A reading without quantisation passes unchanged.

    Returns the angle, the mask of the interpolated samples and the interpolation's error
    estimate (deg, 0 elsewhere): the difference between the cubic and the straight line between
    the two crossings, which bounds the cubic's error in 99.6-100 % of the samples of the
    benchmark's 0.1 deg realistic acquisition (3 x the estimate).
    """
    th = np.asarray(theta, dtype=float)
    out = th.copy()
    moving = np.zeros(th.size, dtype=bool)
    err = np.zeros(th.size)
    ch, kt, kv, ok = _crossings(np.asarray(t, dtype=float), th)
    if ch.size < 2:
        return out, moving, err
    # sample i lies in the level that starts at crossing k = (crossings up to i) - 1
    k = np.searchsorted(ch, np.arange(th.size), side="right") - 1
    inside = (k >= 0) & (k < ch.size - 1)
    moving[inside] = ok[k[inside]]
    i = np.flatnonzero(moving)
    kk = k[i]
    w = (t[i] - kt[kk]) / (kt[kk + 1] - kt[kk])
    out[i] = kv[kk] + w * (kv[kk + 1] - kv[kk])
    for a, b in _runs(ok):
        if b - a < 2:  # one interval: the straight line
            continue
        sel = i[(kk >= a) & (kk < b)]
        cubic = PchipInterpolator(kt[a : b + 1], kv[a : b + 1])(t[sel])
        err[sel] = np.abs(cubic - out[sel])
        out[sel] = cubic
    return out, moving, err


def encoder_quantum(theta: FloatArray) -> float:
    """Smallest non-zero step of a quantised channel (its units; 0 when it never moves)."""
    d = np.abs(np.diff(theta))
    d = d[d > 1e-12]
    return float(d.min()) if d.size else 0.0


def smooth(x: FloatArray, t: FloatArray, window_s: float) -> tuple[FloatArray, int]:
    """Centred moving average over ``window_s`` (s) and its length in samples.

    The raw values are kept at both ends (where the window would leave the record).
    """
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1e-3
    w = max(int(round(window_s / dt)), 1)
    if w <= 1 or x.size <= 2 * w:
        return x.astype(float), 1
    out = np.convolve(x, np.ones(w) / w, mode="same")
    h = w // 2 + 1
    out[:h] = x[:h]
    out[-h:] = x[-h:]
    return out, w
