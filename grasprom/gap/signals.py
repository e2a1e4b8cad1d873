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
