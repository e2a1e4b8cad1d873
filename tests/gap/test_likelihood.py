"""The interval ("dead-zone") likelihood of the encoder quantum (grasprom.gap.likelihood).

Reference: ``E[z^2]`` of a correct model, the true value uniform over an interval of width ``W``
plus Gaussian noise ``sigma``, the residual counted beyond the interval, by brute-force
numerical integration over the uniform position and the noise (scipy ``dblquad``) and by Monte
Carlo; the closed form's limits 1 (``W = 0``) and ``0.532 sigma / W`` (``W >> sigma``).
"""

import math

import numpy as np
import pytest
from scipy.integrate import dblquad

from grasprom.gap.likelihood import deadzone, interval_z, null_chi2


def _brute_null(width: float, sigma: float) -> float:
    """E[d^2] / sigma^2 by direct integration: u ~ U(0, W) the true value's place in the
    interval [0, W], n ~ N(0, sigma), measured x = u + n, d = x - clip(x, 0, W)."""

    def f(n, u):
        x = u + n
        d = x - min(max(x, 0.0), width)
        pdf = math.exp(-0.5 * (n / sigma) ** 2) / (sigma * math.sqrt(2.0 * math.pi))
        return (d / sigma) ** 2 * pdf / width

    val, err = dblquad(f, 0.0, width, -12.0 * sigma, 12.0 * sigma, epsabs=1e-11, epsrel=1e-9)
    assert err < 1e-6
    return val


@pytest.mark.parametrize("u", [0.05, 0.3, 1.0, 2.5, 7.0, 40.0])
def test_null_chi2_matches_numeric_integral(u):
    sigma = 0.2
    got = float(null_chi2(np.array([u * sigma]), np.array([sigma]))[0])
    assert got == pytest.approx(_brute_null(u * sigma, sigma), rel=1e-6)


def test_null_chi2_limits_and_monte_carlo():
    sigma = np.array([0.1, 0.1, 0.1])
    out = null_chi2(np.array([0.0, 1e-9, 100.0]), sigma)
    assert out[0] == 1.0 and out[1] == pytest.approx(1.0, abs=1e-6)
    # W >> sigma (u = W / sigma = 1000): only the two ends leak, E = 4 / (3 sqrt(2 pi) u)
    assert out[2] == pytest.approx(4.0 / (3.0 * math.sqrt(2 * math.pi)) / 1000.0, rel=1e-6)
    rng = np.random.default_rng(7)
    w, s, n = 0.35, 0.1, 400_000
    x = rng.uniform(0.0, w, n) + rng.normal(0.0, s, n)
    mc = float(np.mean((deadzone(x, 0.0, w) / s) ** 2))
    assert float(null_chi2(np.array([w]), np.array([s]))[0]) == pytest.approx(mc, rel=0.02)


def test_interval_z_costs_only_the_distance_to_the_range():
    centre = np.array([10.0, 10.0, 10.0, 10.0])
    ends = (np.array([8.0, 8.0, 8.0, 10.0]), np.array([13.0, 13.0, 13.0, 10.0]))
    F = np.array([12.0, 14.0, 7.5, 10.3])
    z = interval_z(F, centre, ends, np.array([0.5, 0.5, 0.5, 0.1]))
    # inside [8, 13]: 0; 1 N above: 2 sigma; 0.5 N below: -1 sigma; no interval: r / sigma
    np.testing.assert_allclose(z, [0.0, 2.0, -1.0, 3.0], atol=1e-12)
