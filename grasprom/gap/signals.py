"""Signal estimators of the diagnosis: white-noise sigma, encoder quantum, centred moving
average (pure numerics on sampled channels, no model)."""

from __future__ import annotations

import math

import numpy as np

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

    A count changes when the true angle crosses the boundary between two levels, so at each
    change the true angle is known: the mid-level ``(theta[i-1] + theta[i]) / 2``, at about the
    middle of the sample interval. Between two crossings in the same direction less than
    :data:`DEQUANTISE_MAX_GAP_S` apart the handle moves through the level and the angle is
    interpolated linearly between them (error a small fraction of the quantum instead of a
    staircase whose steps the tissue slope turns into force steps); elsewhere (at rest, at a
    reversal, at the ends) the reading is kept: the true angle is anywhere in the level, whose
    centre is the unbiased estimate. A reading without quantisation passes unchanged.

    Returns the angle and the mask of the interpolated samples.
    """
    th = np.asarray(theta, dtype=float)
    out = th.copy()
    moving = np.zeros(th.size, dtype=bool)
    ch = np.flatnonzero(np.diff(th) != 0.0) + 1  # first sample of each new level
    if ch.size < 2:
        return out, moving
    kt = 0.5 * (t[ch - 1] + t[ch])
    kv = 0.5 * (th[ch - 1] + th[ch])
    step = np.sign(th[ch] - th[ch - 1])
    ok = (step[:-1] == step[1:]) & (kt[1:] - kt[:-1] <= DEQUANTISE_MAX_GAP_S)
    # sample i lies in the level that starts at crossing k = (crossings up to i) - 1
    k = np.searchsorted(ch, np.arange(th.size), side="right") - 1
    inside = (k >= 0) & (k < ch.size - 1)
    moving[inside] = ok[k[inside]]
    i = np.flatnonzero(moving)
    kk = k[i]
    w = (t[i] - kt[kk]) / (kt[kk + 1] - kt[kk])
    out[i] = kv[kk] + w * (kv[kk + 1] - kv[kk])
    return out, moving


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
