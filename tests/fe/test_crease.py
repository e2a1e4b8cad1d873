"""The smooth branch's energy between steps (grasprom.fe.crease.hermite_energy), against an
analytic energy: a cubic Hermite through (h, E, F = -dE/dh) is exact for a cubic E(h)."""

import numpy as np
import pytest

from grasprom.fe.crease import hermite_energy


def test_hermite_energy_is_exact_for_a_cubic_and_uses_dE_dh_equal_minus_F():
    def E(h):
        return 0.3 * (10 - h) ** 3 + 2.0 * (10 - h) ** 2 + 0.5 * (10 - h)

    def F(h):  # the jaw reaction, F = -dE/dh
        return 0.9 * (10 - h) ** 2 + 4.0 * (10 - h) + 0.5

    hs = [10.0, 9.0, 7.5, 7.2, 5.0]  # decreasing jaw heights (mm), uneven steps
    branch = [(h, E(h), F(h)) for h in hs]
    for h in np.linspace(5.0, 10.0, 23):
        assert hermite_energy(branch, h) == pytest.approx(E(h), rel=1e-12, abs=1e-12)
    # extrapolated past the last step from the last interval: still the cubic
    assert hermite_energy(branch, 4.5) == pytest.approx(E(4.5), rel=1e-12)
    # a wrong sign of F (dE/dh = +F) is caught
    flipped = [(h, e, -f) for h, e, f in branch]
    assert abs(hermite_energy(flipped, 8.0) - E(8.0)) > 0.1
