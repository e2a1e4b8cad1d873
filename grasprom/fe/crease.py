"""Placing a crease by energy (Maxwell's rule), shared by the 2D and 3D models.

In the crease band the inner wall of the flattened tube can fold smoothly or crease; the
creased state has less strain energy below some jaw height.  A model follows the smooth fold
until it loses stability and snaps; the crease is placed instead where the creased state first
has less energy than the smooth fold at the same jaw height.  The smooth fold's energy between
steps comes from :func:`hermite_energy` (jaw and floor are rigid and do no work, so
``dE/dh = -F``).
"""

from __future__ import annotations

import numpy as np


def hermite_energy(branch: list[tuple[float, float, float]], h: float) -> float:
    """Strain energy (N mm/mm) of the followed branch at jaw height ``h`` (mm), cubic Hermite
    through the recorded steps ``(h, energy, force_q)`` (``dE/dh = -force_q``); extrapolated
    from the last interval below the last step."""
    hs = np.array([b[0] for b in branch])
    i = int(np.clip(np.searchsorted(-hs, -h) - 1, 0, len(branch) - 2))
    (h0, e0, f0), (h1, e1, f1) = branch[i], branch[i + 1]
    d = h1 - h0
    s = (h - h0) / d
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * e0 + h10 * d * (-f0) + h01 * e1 + h11 * d * (-f1)
