"""The Arduino export's budget: flash, RAM, cycles and the handle-force error.

The error budget: the rendered handle force (= torque / pulley radius) of the fixed-point core
against the Python reference on the float surrogate (:mod:`.reference`), in percent of the
device's full-scale handle force ``torque_limit / pulley_radius`` (the force that saturates the
motor), over every encoder position of the handle's range, every material and thicknesses on
and between the nodes.  The jaw-force error in percent of the jaw-force full scale (the
quantity ``tol`` bounds on the thickness nodes) is reported too, and (issue 17) the
handle-force error in percent of the force range the device actually renders: the largest
|rendered handle force| of the reference over the test vectors (usually well below the full
scale, so this figure is the stricter one).

The reference is :func:`.reference.reference_run` with the tables' parameters: the Python
controller's step in double, with either rendering (``params.rendering``: virtual coupling or
stiffness-clipped field).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from grasprom.export.arduino.reference import reference_run
from grasprom.export.arduino.tables import FixedTables
from grasprom.export.arduino.vectors import CoreRun, VectorCase
from grasprom.export.variables import FLAG_NAMES
from grasprom.surrogate import Surrogate

FLASH_BUDGET_B = 8192
"""Flash budget for tables + core (bytes)."""
RAM_BUDGET_B = 512
"""RAM budget of the core: static state + stack of the step (bytes)."""
CYCLE_BUDGET = 1600
"""Cycles per controller step: 100 us at 16 MHz."""
ERROR_BUDGET = 0.005
"""Handle-force error budget, fraction of the rendered range (the largest |handle force| the
reference renders on the test vectors; issue 17: not of the motor's 100 N full scale)."""


@dataclass
class ErrorFigures:
    """Fixed-point core vs the float reference."""

    handle_pct_fs: float  # max |dFi| / (torque_limit / r), percent
    jaw_pct_fs: float  # max |dFg| / jaw-force full scale of the tables, percent
    flag_mismatch: dict[str, int]  # steps where a flag differs
    steps: int
    handle_pct_rendered: float = float("nan")  # max |dFi| / rendered_max_N, percent
    rendered_max_N: float = float("nan")  # max |reference handle force| over the vectors (N)


def error_figures(
    tables: FixedTables, surrogate: Surrogate, cases: Sequence[VectorCase], run: CoreRun
) -> ErrorFigures:
    """Compare a core run with :func:`reference_run` on the same cases.

    Parameters
    ----------
    tables : FixedTables
        The tables of the run (their ``params`` are the reference's).
    surrogate : Surrogate
    cases : sequence of VectorCase
    run : CoreRun
        The core's outputs on ``cases``.

    Returns
    -------
    ErrorFigures
    """
    p = tables.params
    fs = p.torque_limit_Nm / (p.pulley_radius_mm * 1e-3)
    e_h = e_j = f_max = 0.0
    mism = dict.fromkeys(FLAG_NAMES, 0)
    steps = 0
    for c, out in zip(cases, run.outputs):
        ref = reference_run(p, surrogate, c.material, c.thickness_um / 1000.0, c.counts)
        e_h = max(e_h, float(np.max(np.abs(out["fi"] * 1e-3 - ref.force_handle_N))))
        f_max = max(f_max, float(np.max(np.abs(ref.force_handle_N))))
        e_j = max(e_j, float(np.max(np.abs(out["fg"] * 1e-3 - ref.force_jaw_N))))
        for bit, name in enumerate(FLAG_NAMES):
            mism[name] += int(np.sum(((out["flags"] >> bit) & 1).astype(bool) != ref.flags[name]))
        steps += len(c.counts)
    rendered = 100.0 * e_h / f_max if f_max > 0.0 else float("nan")
    return ErrorFigures(
        100.0 * e_h / fs, 100.0 * e_j / tables.jaw_fs_N, mism, steps, rendered, f_max
    )
