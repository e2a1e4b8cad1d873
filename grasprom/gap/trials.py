"""Measured trials: the table columns and sidecar keys, the validated :class:`Trial`, and reading
and validating ``TRIAL.csv`` + ``TRIAL.json`` (every error names file, row and column)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from grasprom.chain import kinematics as kin
from grasprom.surrogate import Surrogate

FloatArray = NDArray[np.float64]

REQUIRED_COLUMNS = ("time_s", "theta_deg", "force_handle_N")
OPTIONAL_COLUMNS = ("force_jaw_N", "gap_mm")
SIDECAR_KEYS = ("thickness_mm", "material")
MIN_DURATION_S = 1.0
MIN_ROWS = 50


class TrialDataError(ValueError):
    """A trial file or its sidecar is unusable; the message names file, row and column."""


@dataclass
class Trial:
    """A validated measured trial (SI-ish units as in the column names)."""

    name: str
    time_s: FloatArray
    theta_deg: FloatArray
    force_handle_N: FloatArray
    thickness_mm: float
    material: str
    trial_id: str = ""
    force_jaw_N: FloatArray | None = None
    gap_mm: FloatArray | None = None
    notes: Any = None


def _num_column(df: pd.DataFrame, col: str, source: str) -> FloatArray:
    vals = np.asarray(pd.to_numeric(df[col], errors="coerce"), dtype=float)
    bad = np.flatnonzero(~np.isfinite(vals))
    if bad.size:
        i = int(bad[0])
        raise TrialDataError(
            f"{source}: row {i + 1} (line {i + 2}), column {col!r}: not a finite number "
            f"({df[col].iloc[i]!r})"
        )
    return vals


def _numeric_columns(df: pd.DataFrame, source: str) -> dict[str, FloatArray]:
    """The required and present optional columns as finite floats (missing ones raise)."""
    missing = [c for c in REQUIRED_COLUMNS if c not in df.columns]
    if missing:
        raise TrialDataError(
            f"{source}: missing column(s) {', '.join(repr(c) for c in missing)} "
            f"(need {', '.join(REQUIRED_COLUMNS)}; optional {', '.join(OPTIONAL_COLUMNS)})"
        )
    cols = {c: _num_column(df, c, source) for c in REQUIRED_COLUMNS}
    for c in OPTIONAL_COLUMNS:
        if c in df.columns:
            cols[c] = _num_column(df, c, source)
    return cols


def _check_time(t: FloatArray, source: str) -> None:
    """Time (s) must increase strictly and be in seconds (not ms)."""
    from grasprom.control.trajectory import check_time_seconds

    if t.size >= 2:
        bad = np.flatnonzero(np.diff(t) <= 0)
        if bad.size:
            i = int(bad[0]) + 1
            raise TrialDataError(
                f"{source}: row {i + 1} (line {i + 2}), column 'time_s': time must increase "
                f"strictly ({float(t[i])!r} s after {float(t[i - 1])!r} s)"
            )
    try:
        check_time_seconds(t, source)
    except ValueError as exc:
        raise TrialDataError(str(exc)) from None


def _check_theta(th: FloatArray, source: str, chain: kin.ChainParams) -> None:
    """Angle (deg) in degrees and within the chain's range."""
    n = th.size
    lo, hi = kin.theta_range_deg(chain)
    if n >= 2 and np.ptp(th) > 0 and np.max(np.abs(th)) <= math.radians(hi) * 1.05 and hi > 2:
        i = int(np.argmax(np.abs(th)))
        raise TrialDataError(
            f"{source}: column 'theta_deg' spans only [{th.min():.4g}, {th.max():.4g}] (max at "
            f"row {i + 1}, line {i + 2}): radians? the column must be in degrees "
            f"(chain range [{lo:g}, {hi:g}] deg)"
        )
    bad = np.flatnonzero((th < lo - 1e-6) | (th > hi + 1e-6))
    if bad.size:
        i = int(bad[0])
        raise TrialDataError(
            f"{source}: row {i + 1} (line {i + 2}), column 'theta_deg': {float(th[i])!r} deg "
            "outside "
            f"the chain's range [{lo:g}, {hi:g}] deg"
        )


def _check_forces(cols: dict[str, FloatArray], source: str) -> None:
    """Handle (N) and jaw (N) forces of a hand-held grasper (not mN)."""
    fi = cols["force_handle_N"]
    bad = np.flatnonzero(np.abs(fi) > 1000.0)
    if bad.size:
        i = int(bad[0])
        raise TrialDataError(
            f"{source}: row {i + 1} (line {i + 2}), column 'force_handle_N': {float(fi[i])!r} N is "
            "implausible for a hand-held grasper (|F| > 1000 N): mN instead of N?"
        )
    if "force_jaw_N" in cols:
        fj = cols["force_jaw_N"]
        bad = np.flatnonzero(np.abs(fj) > 2000.0)
        if bad.size:
            i = int(bad[0])
            raise TrialDataError(
                f"{source}: row {i + 1} (line {i + 2}), column 'force_jaw_N': {float(fj[i])!r} "
                "N is "
                "implausible (|F| > 2000 N): mN instead of N?"
            )


def _check_gap(cols: dict[str, FloatArray], source: str, chain: kin.ChainParams) -> None:
    """Jaw gap (mm) in mm and within ``[0, 2 x open gap]``."""
    if "gap_mm" not in cols:
        return
    g = cols["gap_mm"]
    if g.size >= 2 and np.max(g) < 0.1:
        i = int(np.argmax(g))
        raise TrialDataError(
            f"{source}: column 'gap_mm' stays below 0.1 (max {float(g[i])!r} at row {i + 1}, "
            "line "
            f"{i + 2}): metres instead of mm?"
        )
    bad = np.flatnonzero((g < 0) | (g > 2 * chain.gap_open_mm))
    if bad.size:
        i = int(bad[0])
        raise TrialDataError(
            f"{source}: row {i + 1} (line {i + 2}), column 'gap_mm': {float(g[i])!r} mm "
            "outside "
            f"[0, {2 * chain.gap_open_mm:g}] mm"
        )


def _check_length(t: FloatArray, source: str) -> None:
    """At least :data:`MIN_ROWS` rows and :data:`MIN_DURATION_S` (s)."""
    n = t.size
    dur = float(t[-1] - t[0]) if n else 0.0
    if n < MIN_ROWS or dur < MIN_DURATION_S:
        raise TrialDataError(
            f"{source}: trial too short ({n} rows, {dur:.3g} s): a diagnosis needs at least "
            f"{MIN_ROWS} rows and {MIN_DURATION_S:g} s (close, hold and reopen)"
        )


def _sidecar_thickness(sidecar: Any, side_src: str) -> float:
    """The sidecar is an object with the keys of :data:`SIDECAR_KEYS`; its thickness (mm)."""
    if not isinstance(sidecar, dict):
        raise TrialDataError(f"{side_src}: must hold a JSON object")
    for key in SIDECAR_KEYS:
        if key not in sidecar:
            raise TrialDataError(
                f"{side_src}: missing key {key!r} (need {', '.join(SIDECAR_KEYS)})"
            )
    try:
        thick = float(sidecar["thickness_mm"])
    except (TypeError, ValueError):
        raise TrialDataError(
            f"{side_src}: key 'thickness_mm' must be a number, got {sidecar['thickness_mm']!r}"
        ) from None
    if not math.isfinite(thick) or thick <= 0:
        raise TrialDataError(f"{side_src}: key 'thickness_mm' must be > 0, got {thick!r}")
    if thick < 0.05:
        raise TrialDataError(f"{side_src}: key 'thickness_mm' = {thick!r}: metres instead of mm?")
    return thick


def _check_against_surrogate(
    material: str, thick: float, surrogate: Surrogate | None, side_src: str
) -> None:
    """Material known to the surrogate and thickness (mm) within its range."""
    if surrogate is None:
        return
    if material not in surrogate.materials:
        raise TrialDataError(
            f"{side_src}: key 'material' = {material!r} unknown; the surrogate has "
            f"{', '.join(surrogate.materials)}"
        )
    tlo, thi = surrogate.thickness_range(material)
    if not tlo - 1e-9 <= thick <= thi + 1e-9:
        raise TrialDataError(
            f"{side_src}: key 'thickness_mm' = {thick!r} mm outside the surrogate's range "
            f"[{tlo:g}, {thi:g}] mm for {material!r}"
        )


def validate_trial(
    df: pd.DataFrame,
    sidecar: dict[str, Any],
    source: str,
    chain: kin.ChainParams,
    surrogate: Surrogate | None = None,
    sidecar_source: str | None = None,
) -> Trial:
    """Validate one trial table and its sidecar; every error names file, row and column.

    Parameters
    ----------
    df : pandas.DataFrame
        Columns ``time_s`` (s), ``theta_deg`` (deg), ``force_handle_N`` (N), optionally
        ``force_jaw_N`` (N) and ``gap_mm`` (mm).
    sidecar : dict
        At least ``thickness_mm`` (mm, nominal) and ``material``.
    source : str
        Name of the CSV (for the messages).
    chain : kinematics.ChainParams
        Instrument chain (angle range).
    surrogate : Surrogate, optional
        Checks material and thickness range when given.
    sidecar_source : str, optional
        Name of the sidecar file (for the messages).

    Returns
    -------
    Trial

    Raises
    ------
    TrialDataError
    """
    side_src = sidecar_source or f"sidecar of {source}"
    cols = _numeric_columns(df, source)
    t, th, fi = cols["time_s"], cols["theta_deg"], cols["force_handle_N"]
    _check_time(t, source)
    _check_theta(th, source, chain)
    _check_forces(cols, source)
    _check_gap(cols, source, chain)
    _check_length(t, source)
    thick = _sidecar_thickness(sidecar, side_src)
    material = str(sidecar["material"])
    _check_against_surrogate(material, thick, surrogate, side_src)
    lo, hi = kin.theta_range_deg(chain)
    return Trial(
        name=source,
        time_s=t,
        theta_deg=np.clip(th, lo, hi),
        force_handle_N=fi,
        thickness_mm=thick,
        material=material,
        trial_id=str(sidecar.get("trial_id", Path(source).stem)),
        force_jaw_N=cols.get("force_jaw_N"),
        gap_mm=cols.get("gap_mm"),
        notes=sidecar.get("notes"),
    )


def load_trial(
    path: str | Path, chain: kin.ChainParams, surrogate: Surrogate | None = None
) -> Trial:
    """Read ``TRIAL.csv`` and its sidecar ``TRIAL.json`` (same stem) and validate them.

    Raises
    ------
    TrialDataError
        Naming the file, row and column of the first problem.
    """
    p = Path(path)
    try:
        df = pd.read_csv(p)
    except FileNotFoundError:
        raise TrialDataError(f"{p}: no such file") from None
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as e:
        raise TrialDataError(f"{p}: cannot read CSV ({e})") from None
    sp = p.with_suffix(".json")
    try:
        sidecar = json.loads(sp.read_text())
    except FileNotFoundError:
        raise TrialDataError(
            f"{sp}: sidecar missing (a JSON object with thickness_mm and material beside {p.name})"
        ) from None
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as e:
        raise TrialDataError(f"{sp}: cannot read sidecar JSON ({e})") from None
    return validate_trial(df, sidecar, str(p), chain, surrogate, str(sp))
