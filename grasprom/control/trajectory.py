"""Handle-angle trajectories through the controller (``grasprom simulate``).

:func:`validate_trajectory` checks a ``time_s, theta_deg`` table, :func:`simulate` runs the
:class:`~grasprom.control.impedance.ImpedanceController` on it at the controller rate (the
reference for every export) and :func:`grasp_trajectory` makes a grasp-hold-release test input.
"""

from __future__ import annotations

import math
import os
from typing import TYPE_CHECKING

import numpy as np

from grasprom.chain import kinematics as kin
from grasprom.control.field import jaw_stiffness_limit_N_per_mm
from grasprom.control.impedance import ImpedanceController, StepOutput
from grasprom.control.params import ControllerParams
from grasprom.surrogate import Surrogate

if TYPE_CHECKING:  # pandas is imported when used: ``import grasprom.control`` stays light
    import pandas as pd

__all__ = [
    "SIMULATION_COLUMNS",
    "MAX_SIMULATION_STEPS",
    "check_theta_degrees",
    "check_time_seconds",
    "TRAJECTORY_COLUMNS",
    "grasp_trajectory",
    "max_simulation_steps",
    "minimum_jerk",
    "simulate",
    "validate_trajectory",
]

TRAJECTORY_COLUMNS = ("time_s", "theta_deg")
"""Columns of a handle-angle trajectory: time (s), handle angle (deg)."""

MAX_SIMULATION_STEPS = 2_000_000
"""Default bound on the controller steps of one :func:`simulate` (``GRASPROM_MAX_STEPS``)."""

SIMULATION_COLUMNS = (
    "time_s",
    "theta_deg",
    "gap_mm",
    "force_jaw_N",
    "force_handle_N",
    "force_handle_spring_N",
    "torque_Nm",
    "contact",
    "tissue_warning",
    "force_tissue_N",
    "proxy_gap_mm",
    "velocity_rad_per_s",
    "coupling_active",
    "saturated",
    "theta_clamped",
    "theta_chain_deg",
    "force_handle_friction_N",
    "tissue_stiffness_N_per_mm",
    "stiffness_limit_N_per_mm",
)
"""Columns of :func:`simulate`: ``time_s``, the :class:`StepOutput` fields (units in names), the
tissue stiffness ``-dF/dgap`` at the kinematic gap (N/mm, scaled like the force) and the
rendering's bound on the jaw stiffness at the chain angle
(:func:`~grasprom.control.field.jaw_stiffness_limit_N_per_mm`, N/mm)."""


def minimum_jerk(s):
    """Minimum-jerk profile (Flash & Hogan 1985) and its slope at the phase ``s`` (1, 1/1).

    ``10 s^3 - 15 s^4 + 6 s^5`` on ``0 <= s <= 1``; 0 before, 1 after, slope 0 outside.
    ``s`` is a float (floats returned: the co-simulation's per-step path) or an array.
    """
    s = min(max(float(s), 0.0), 1.0) if np.ndim(s) == 0 else np.clip(s, 0.0, 1.0)
    return s**3 * (10.0 - 15.0 * s + 6.0 * s**2), 30.0 * s * s * (1.0 - s) ** 2


MS_SUSPECT_STEP_S = 0.5
"""Median time step (s) from which a long record's ``time_s`` is taken for milliseconds."""
MS_SUSPECT_SPAN_S = 100.0
"""Span (s) from which a record with :data:`MS_SUSPECT_STEP_S` steps is taken for ms."""


def check_theta_degrees(th: np.ndarray, source: str) -> None:
    """Refuse a moving handle-angle column that stays within 0.4 deg: radians, not degrees.

    Raises
    ------
    ValueError
        Naming ``source`` and the column ``theta_deg``.
    """
    if np.ptp(th) > 0 and np.abs(th).max() <= 0.4:
        raise ValueError(
            f"{source}: column 'theta_deg' stays within 0.4 deg -- is it in radians? "
            "(the column must be in degrees: multiply by 180/pi)"
        )


def check_time_seconds(t: np.ndarray, source: str, column: str = "time_s") -> None:
    """Refuse a time column that looks like milliseconds.

    A sampled record whose median step is at least :data:`MS_SUSPECT_STEP_S` (2 Hz or slower)
    and which spans at least :data:`MS_SUSPECT_SPAN_S` is a grasp written in ms (a 1 kHz
    record in ms has a step of 1 and spans thousands); a few waypoints (< 20 rows) pass.

    Raises
    ------
    ValueError
        Naming ``source`` and ``column``.
    """
    if t.size < 20:
        return
    step = float(np.median(np.diff(t)))
    span = float(t[-1] - t[0])
    if step >= MS_SUSPECT_STEP_S and span >= MS_SUSPECT_SPAN_S:
        raise ValueError(
            f"{source}: column {column!r} spans {span:.6g} s with a median step of {step:.3g} s "
            "-- is it in milliseconds? (the column must be in seconds: divide by 1000)"
        )


def validate_trajectory(
    df: pd.DataFrame, params: ControllerParams, source: str = "trajectory"
) -> tuple[np.ndarray, np.ndarray]:
    """Check a trajectory table (``time_s``, ``theta_deg``); errors name the row and column.

    Returns float arrays ``(time_s, theta_deg)``.
    """
    import pandas as pd

    missing = [c for c in TRAJECTORY_COLUMNS if c not in df.columns]
    if missing:
        raise ValueError(
            f"{source}: missing column(s) {', '.join(missing)} (need time_s, theta_deg)"
        )
    if len(df) < 2:
        raise ValueError(f"{source}: needs at least 2 rows, got {len(df)}")
    out = []
    for col in TRAJECTORY_COLUMNS:
        vals = np.asarray(pd.to_numeric(df[col], errors="coerce"), dtype=float)
        bad = np.flatnonzero(~np.isfinite(vals))
        if bad.size:
            raise ValueError(
                f"{source}: column {col!r}, row {int(bad[0]) + 1}: not a finite number "
                f"({df[col].iloc[bad[0]]!r})"
            )
        out.append(vals)
    t, th = out
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        raise ValueError(
            f"{source}: column 'time_s' must increase strictly; row {int(bad[0]) + 2} "
            f"({t[bad[0] + 1]!r} s) does not follow row {int(bad[0]) + 1} ({t[bad[0]]!r} s)"
        )
    lo, hi = kin.theta_range_deg(params.chain_params)
    bad = np.flatnonzero((th < lo - 1e-9) | (th > hi + 1e-9))
    if bad.size:
        raise ValueError(
            f"{source}: column 'theta_deg', row {int(bad[0]) + 1}: {th[bad[0]]!r} deg outside "
            f"the chain's range [{lo:g}, {hi:g}] deg"
        )
    check_theta_degrees(th, source)
    check_time_seconds(t, source)
    _check_steps(t, params, source)
    return t, th


def max_simulation_steps() -> int:
    """The most controller steps :func:`simulate` runs: ``GRASPROM_MAX_STEPS`` or 2,000,000.

    Two million steps are 33 minutes at 1 kHz (about 300 MB of output columns).
    """
    raw = os.environ.get("GRASPROM_MAX_STEPS", "")
    try:
        n = int(raw) if raw.strip() else MAX_SIMULATION_STEPS
    except ValueError:
        raise ValueError(f"GRASPROM_MAX_STEPS must be a positive integer, got {raw!r}") from None
    if n < 1:
        raise ValueError(f"GRASPROM_MAX_STEPS must be a positive integer, got {raw!r}")
    return n


def _check_steps(t: np.ndarray, params: ControllerParams, source: str) -> None:
    """The trajectory's duration at the controller rate stays within the step limit."""
    n = (t[-1] - t[0]) / params.sample_time_s
    limit = max_simulation_steps()
    if n + 1 > limit:
        raise ValueError(
            f"{source}: column 'time_s' spans {t[-1] - t[0]:.6g} s, {n:.3g} steps at "
            f"{1.0 / params.sample_time_s:g} Hz, over the limit of {limit} steps (is the time "
            "in ms? it must be in s); raise the limit with GRASPROM_MAX_STEPS"
        )


def simulate(
    trajectory: pd.DataFrame,
    params: ControllerParams,
    surrogate: Surrogate,
    source: str = "trajectory",
) -> pd.DataFrame:
    """Run the controller on a handle-angle trajectory (the reference for all exports).

    The controller runs at its own rate ``1 / sample_time_s`` from the first to the last
    trajectory time; the angle is interpolated linearly between trajectory rows (a trajectory
    sampled at the controller rate is used as is).

    Parameters
    ----------
    trajectory : pandas.DataFrame
        Columns ``time_s`` (s, strictly increasing) and ``theta_deg`` (deg, in the chain range).
    params : ControllerParams
    surrogate : Surrogate

    Returns
    -------
    pandas.DataFrame
        One row per controller step, columns :data:`SIMULATION_COLUMNS`.
    """
    import pandas as pd

    t, th = validate_trajectory(trajectory, params, source)
    T = params.sample_time_s
    n = int(math.floor((t[-1] - t[0]) / T + 1e-9)) + 1
    ticks = t[0] + T * np.arange(n)
    theta = np.interp(ticks, t, th)
    ctl = ImpedanceController(params, surrogate)
    rows = [ctl.step(math.radians(x)) for x in theta]
    out = pd.DataFrame(rows, columns=StepOutput._fields)
    out.insert(0, "time_s", ticks)
    gap = out["gap_mm"].to_numpy()
    k_t = surrogate.stiffness(gap, params.thickness_mm, params.material)
    out["tissue_stiffness_N_per_mm"] = np.asarray(k_t, dtype=float) * params.tissue_scale
    out["stiffness_limit_N_per_mm"] = jaw_stiffness_limit_N_per_mm(
        params, out["theta_chain_deg"].to_numpy()
    )
    return out[list(SIMULATION_COLUMNS)]


def grasp_trajectory(
    *,
    close_s: float = 1.0,
    hold_s: float = 2.0,
    open_s: float = 1.0,
    theta_open_deg: float = 22.0,
    theta_closed_deg: float = 0.0,
    sample_time_s: float = 1e-3,
) -> pd.DataFrame:
    """A grasp-hold-release handle trajectory (cosine ramps), columns ``time_s, theta_deg``."""
    import pandas as pd

    def ramp(a: float, b: float, dur: float) -> np.ndarray:
        m = max(int(round(dur / sample_time_s)), 1)
        s = np.arange(m) / m
        return a + (b - a) * 0.5 * (1 - np.cos(np.pi * s))

    th = np.concatenate(
        [
            ramp(theta_open_deg, theta_closed_deg, close_s),
            np.full(max(int(round(hold_s / sample_time_s)), 1), theta_closed_deg),
            ramp(theta_closed_deg, theta_open_deg, open_s),
            [theta_open_deg],
        ]
    )
    return pd.DataFrame({"time_s": sample_time_s * np.arange(th.size), "theta_deg": th})
