"""Force-gap curves of a loaded sweep (``grasprom.fe.load_sweep``) for the shipped-data tests."""

from __future__ import annotations

import numpy as np


def curve(df, material: str, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Gaps (mm) and forces (N) of one case, in load-step order."""
    c = df[(df["material"] == material) & np.isclose(df["thickness_mm"], t)]
    return c["gap_mm"].to_numpy(), c["force_N"].to_numpy()


def force_at(df, material: str, t: float, gap: float) -> float:
    """Force (N) at ``gap`` (mm), interpolated along the load path; the case must reach it."""
    g, f = curve(df, material, t)
    assert g.min() <= gap + 1e-9 <= g.max() + 1e-9, f"{material} t={t} does not reach gap {gap}"
    return float(np.interp(-gap, -g, f))
