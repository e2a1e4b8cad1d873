"""Held-out shrink per phase with a bootstrap over trials (grasprom.gap.shrink).

Reference: residuals built from a known systematic part plus noise of known sigma, where the
systematic chi2 is ``N a^2 / sigma^2`` and the shrink is ``1 - |b| / |a|`` analytically.
"""

import math

import numpy as np
import pytest

from grasprom.gap.prepare import PHASES
from grasprom.gap.shrink import shrink_by_phase


def _trials(n_trials, before, after, sigma=0.05, n=4000, seed=1, spread=0.0):
    """Trials of two phases (index 0 and 1, halves): residual = systematic level + noise."""
    rng = np.random.default_rng(seed)
    b, a, lab, sig = [], [], [], []
    for i in range(n_trials):
        lv = np.repeat([0, 1], n // 2)
        scale = 1.0 + spread * (i - (n_trials - 1) / 2)  # trial-to-trial variation of the gap
        s0 = np.where(lv == 0, before[0], before[1]) * scale
        s1 = np.where(lv == 0, after[0], after[1]) * scale
        noise = rng.normal(0.0, sigma, n)
        b.append(s0 + noise)
        a.append(s1 + noise)
        lab.append(lv)
        sig.append(np.full(n, sigma))
    return b, a, lab, sig


def test_shrink_matches_the_analytic_value_per_phase_and_flags_the_worse_phase():
    before, after = (0.5, 0.3), (0.1, 0.45)  # phase 0: shrink 0.8; phase 1: 1.5x worse
    rows = {r.phase: r for r in shrink_by_phase(*_trials(6, before, after))}
    assert set(rows) == {"all", PHASES[0], PHASES[1]}
    assert rows[PHASES[0]].shrink == pytest.approx(0.8, abs=0.01)
    assert rows[PHASES[1]].shrink == pytest.approx(-0.5, abs=0.02)
    # overall: S1 / S0 = (0.1^2 + 0.45^2) / (0.5^2 + 0.3^2)
    expect = 1 - math.sqrt((0.1**2 + 0.45**2) / (0.5**2 + 0.3**2))
    assert rows["all"].shrink == pytest.approx(expect, abs=0.01)
    assert rows[PHASES[0]].share_of_gap == pytest.approx(0.25 / 0.34, abs=0.01)
    assert rows[PHASES[1]].rms_after_N == pytest.approx(math.hypot(0.45, 0.05), rel=0.01)
    for r in rows.values():
        assert r.low <= r.shrink <= r.high


def test_interval_widens_with_trial_to_trial_spread_and_needs_three_trials():
    before, after = (0.5, 0.3), (0.1, 0.1)
    tight = shrink_by_phase(*_trials(6, before, after))[0]
    spread_b, spread_a, lab, sig = _trials(6, before, after)
    # the augmented model is good on half of the trials and poor on the others
    spread_a = [a if i % 2 else b * 0.9 for i, (a, b) in enumerate(zip(spread_a, spread_b))]
    wide = shrink_by_phase(spread_b, spread_a, lab, sig)[0]
    assert wide.high - wide.low > 5 * (tight.high - tight.low)
    assert wide.low < wide.shrink < wide.high
    two = shrink_by_phase(*_trials(2, before, after))[0]
    assert math.isnan(two.low) and math.isnan(two.high) and two.shrink > 0.5


def test_bootstrap_is_reproducible():
    data = _trials(5, (0.4, 0.2), (0.2, 0.1), spread=0.2)
    assert shrink_by_phase(*data) == shrink_by_phase(*data)


def test_trial_shrinks_against_hand_computed_chi2():
    """Per-trial held-out shrink ``1 - sqrt(max(S1, 0) / S0)`` (``S = sum z^2 - N0``) on trials
    built by hand: removed gap 1, a quarter of the chi2 left 0.5, worse than the baseline
    negative, a baseline gap below the significance level (``S0 <= N``) NaN."""
    from grasprom.gap.shrink import trial_shrinks

    n = 100
    one = np.ones(n)
    z0 = [3.0 * one, np.sqrt(5.0) * one, 1.2 * one, 2.0 * one]  # S0 = 800, 400, 44, 300
    z1 = [one, np.sqrt(2.0) * one, one, 3.0 * one]  # S1 = 0, 100, 0, 800
    got = trial_shrinks(z0, z1, [one] * 4, floor=1.0)
    assert got[0] == pytest.approx(1.0)
    assert got[1] == pytest.approx(0.5)
    assert np.isnan(got[2])
    assert got[3] == pytest.approx(1.0 - np.sqrt(800.0 / 300.0))
    # the floor is in noise units: at floor 0.4 the third trial (rho 0.44) counts
    assert trial_shrinks(z0[2:3], z1[2:3], [one], floor=0.4)[0] == pytest.approx(1.0)
