r"""The encoder quantum as a bounded error: the interval ("dead-zone") likelihood of the diagnosis.

Where the handle rests (or reverses) inside one level of the angle encoder the true angle is
anywhere in that level: nothing in the record says where.  On the steep wall-contact rise a level
of a 0.1 deg encoder spans tens of N of handle force (a 0.0041 deg one up to 3 N), far more than
the tangent slope at the level's centre suggests, so a Gaussian term ``(dF/dtheta q)^2 / 12``
both under- and mis-states the error (the force curve is strongly convex there).  Instead, a
model is evaluated at both ends of the level, ``theta -+ q/2`` (:func:`~.model.evaluate_model`
``side=-1/+1``), and a measured force inside the range the model spans over the level costs
nothing; outside it costs its distance to the range, in units of the sensor noise (and 1 % of
surrogate uncertainty) ``s_i``:

    ``z_i = d_i / s_i``, ``d_i = r_i - clip(r_i, lo_i, hi_i)``

(``r_i`` measured - model at the level's centre, ``lo_i <= 0 <= hi_i`` the model's range over the
level relative to it; ``lo = hi = 0`` where the angle is known between the counts).  Under a
correct model with the true angle uniform in the level, ``E[z_i^2]`` is :func:`null_chi2` of the
width ``W = hi - lo`` in noise units -- 1 for ``W = 0``, ``0.53 s / W`` for ``W >> s`` -- and the
systematic gap is ``sum z_i^2 - sum E[z_i^2]`` in place of ``chi2 - N``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ndtr

from grasprom.gap.trials import FloatArray

_PHI0 = 1.0 / math.sqrt(2.0 * math.pi)


def deadzone(r: FloatArray, lo: FloatArray, hi: FloatArray) -> FloatArray:
    """The part of the residual ``r`` outside ``[lo, hi]`` (same units; 0 inside)."""
    return r - np.clip(r, lo, hi)


def _upper_third_moment(c: FloatArray) -> FloatArray:
    """``E[(z - c)_+^3]`` of a standard normal ``z``."""
    phi = _PHI0 * np.exp(-0.5 * c * c)
    return (c * c + 2.0) * phi - c * (c * c + 3.0) * ndtr(-c)


def null_chi2(width: FloatArray, sigma: FloatArray) -> FloatArray:
    """Expected ``z^2`` of a sample under a correct model: the true value uniform over an interval
    of ``width`` (N) plus Gaussian noise ``sigma`` (N), the residual counted beyond the interval.

    ``E = 2 / (3 u) (h(0) - h(u))``, ``u = width / sigma``, ``h(c) = E[(z - c)_+^3]``: 1 at
    ``u = 0``, ``0.532 / u`` for large ``u``.
    """
    u = np.abs(np.asarray(width, dtype=float)) / np.asarray(sigma, dtype=float)
    out = np.ones_like(u)
    m = u > 1e-6
    um = u[m]
    out[m] = 2.0 / (3.0 * um) * (2.0 * _PHI0 - _upper_third_moment(um))
    return out


def interval_z(
    F: FloatArray, centre: FloatArray, ends: tuple[FloatArray, FloatArray], sigma: FloatArray
) -> FloatArray:
    """``z`` of every sample: the measured force ``F`` against the model's range over the level.

    ``centre`` is the model at the level's centre and ``ends`` at its two ends (N); the range is
    the span of the three.
    """
    lo = np.minimum(np.minimum(ends[0], ends[1]), centre) - centre
    hi = np.maximum(np.maximum(ends[0], ends[1]), centre) - centre
    return deadzone(F - centre, lo, hi) / sigma
