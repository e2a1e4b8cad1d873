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
