"""Forward selection of the candidate search (grasprom.gap.selection.search_candidates).

Reference: cross-validation replaced by prescribed held-out chi2 values, so the choice follows
from the rule alone: N = 4000 samples, a correct model leaves N0 = 3000 (the interval
likelihood's null chi2), the baseline leaves 4e6 more.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from grasprom.gap import selection
from grasprom.gap.criteria import PAIR_MIN_SHARE
from grasprom.gap.crossval import CrossValidation

N, N0, SYS0 = 4000, 3000.0, 4.0e6


def _search(monkeypatch, left):
    """search_candidates with the held-out systematic chi2 ``left[key]`` (chi2 - N0)."""

    def fake_cv(preps, key, surrogate, chain):
        return CrossValidation(tuple(key), [], N0 + left[tuple(key)], [{}], [])

    monkeypatch.setattr(selection, "cross_validate", fake_cv)
    gap = SimpleNamespace(
        n_samples=N, chi2=N0 + SYS0, systematic_chi2=SYS0, n_null=N0, rho=SYS0 / N
    )
    cands = ("thickness_error", "tissue_stiffness_scale", "latency")
    return selection.search_candidates([], cands, gap, None, None)


def _left(pair_left):
    return {
        ("thickness_error",): 12000.0,  # rho 3: a significant gap left, 99.7 % explained
        ("tissue_stiffness_scale",): 2.0e5,
        ("latency",): 3.0e6,
        ("thickness_error", "tissue_stiffness_scale"): pair_left,
        ("thickness_error", "latency"): 11990.0,
    }


def test_pair_kept_when_it_resolves_a_significant_gap(monkeypatch):
    s = _search(monkeypatch, _left(20.0))  # rho 0.005
    top = ("thickness_error", "tissue_stiffness_scale")
    assert s.best == ("thickness_error",)
    # the added share is far below PAIR_MIN_SHARE: the earlier rule kept the single
    assert 0 < s.score(top) - s.score(s.best) < PAIR_MIN_SHARE
    assert s.chosen == top
    assert s.share(top) == pytest.approx(1.0 - 20.0 / SYS0)


@pytest.mark.parametrize("pair_left", [5000.0, 7000.0])
def test_pair_not_kept_while_it_leaves_a_significant_gap(monkeypatch, pair_left):
    # 5000: removes 58 % of what the single leaves but rho 1.25 > 1; 7000: 42 % < PAIR_GAIN
    s = _search(monkeypatch, _left(pair_left))
    assert (s.cv[s.pair_rows[0]].chi2 - N0) / N > 1.0
    assert s.chosen == ("thickness_error",)
    assert np.isclose(s.share(s.chosen), 1.0 - 12000.0 / SYS0)
