"""Jaw stepping shared by the 2D and 3D models: landing on requested jaw heights."""

from __future__ import annotations

from collections.abc import Sequence


def land_on(h: float, dh: float, landing: Sequence[float], dh_min: float) -> float:
    """Shorten or stretch a jaw step so that it lands on a requested jaw height.

    A step from ``h`` to ``h - dh`` that passes a requested height ends on it.  A step that
    would stop just above one, closer than ``max(2 dh_min, dh / 100)``, is stretched onto it:
    otherwise the next step, shorter than ``dh_min``, would end the run (a case stopped
    `partial` 4 um above gap 2.7 mm this way).

    Parameters
    ----------
    h : float
        Jaw height (mm) at the start of the step.
    dh : float
        Proposed step (mm), > 0.
    landing : sequence of float
        Requested jaw heights (mm), in any order.
    dh_min : float
        The smallest step (mm) the model takes.

    Returns
    -------
    float
        The step (mm): ``dh``, or ``h - hc`` for the highest requested height ``hc`` below
        ``h`` that the step passes or stops just above.
    """
    reach = h - dh - max(2.0 * dh_min, 0.01 * dh)
    passed = [hc for hc in landing if reach < hc < h - 1e-12]
    return h - max(passed) if passed else dh
