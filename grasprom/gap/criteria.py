"""Decision thresholds of the diagnosis: when a gap is significant, when an effect (set)
explains it, when a second effect is worth keeping."""

from __future__ import annotations

SIGNIFICANT_RHO = 1.0
"""Systematic gap ratio above which a gap is significant (systematic RMS > the noise sigma)."""
EXPLAINED_SHARE = 0.7
"""Held-out explained share of the systematic gap needed to call an effect (set) the cause."""
PAIR_GAIN = 0.5
"""A second effect is kept if it removes this share of the gap the first one leaves."""
PAIR_MIN_SHARE = 0.02
"""... and at least this share of the baseline systematic gap."""
CONFIDENCE_PLATT = (-0.3926, 3.2402)
"""Calibration of the confidence of an ``explained`` verdict: ``1 / (1 + exp(-(a + b c)))`` of
the raw confidence ``c`` (Platt scaling), ``(a, b)`` fitted by maximum likelihood
(``benchmarks/fit_confidence.py``) on the exact truth-set accuracy of the 350 ``explained``
verdicts of ``benchmarks/bench_diagnosis.py --seed 2024`` in four conditions (ideal, realistic,
``--tremor 0.1``, realistic + tremor 0.1 + 2 trials; 116 cases each, the raw confidence with
the separation in noise units and the significance margin) and checked on ``--seed 2025`` (see
docs/diagnosis.md for the figures).  Before: ``(-0.0572, 2.889)``, fitted on seed 2024 ideal
for the earlier raw confidence, which stated at least 0.49 for any ``explained`` verdict."""
