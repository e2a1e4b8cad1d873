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
CONFIDENCE_PLATT = (-0.0572, 2.889)
"""Calibration of the confidence of an ``explained`` verdict: ``1 / (1 + exp(-(a + b c)))`` of
the raw confidence ``c`` (Platt scaling), ``(a, b)`` fitted by maximum likelihood on the exact
truth-set accuracy of the 72 ``explained`` verdicts of ``benchmarks/bench_diagnosis.py --seed
2024`` (expected calibration error 24 points raw, 1.6 after, when fitted) and checked on
``--seed 2025`` (see the README for the figures at this version)."""
