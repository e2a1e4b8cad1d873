r"""Sim-to-real gap diagnosis: where the gap lies, which unmodelled effect causes it, how far
it shrinks once that effect is added.

Baseline ("the model of the real instrument")
    The measured handle angle drives the **static derived chain** with the surrogate tissue:
    ``Fi_model = handle_force_N(F_surrogate(gap(theta), t, material), theta)`` (N, return spring
    included), evaluated vectorised over the samples.  The controller's virtual coupling and
    damping are *rendering* devices of the haptic controller (they exist to keep the rendering
    passive at 1 kHz), not parts of the real instrument, so they are not in the baseline; with the
    default coupling the two differ by < 0.1 mm of gap in bending (see
    :mod:`grasprom.controller`).  ``--controller FILE`` only supplies the chain (geometry and
    return spring).

Analysis grid
    Each trial is subsampled (not averaged, so the non-linear model is not biased by averaging)
    to about :data:`ANALYSIS_RATE_HZ`; the sensor noise ``sigma`` (N) is estimated from the raw
    handle force by the median absolute second difference, the encoder quantum ``q`` (deg) from the
    smallest angle step, and every sample gets the standard deviation
    ``s_i^2 = sigma^2 + (dFi/dtheta q)^2 / 12 + (0.01 Fi)^2`` (sensor noise, angle quantisation
    through the model slope, 1 % surrogate uncertainty).  ``chi2 = sum (r_i / s_i)^2``; the
    *systematic gap ratio* ``rho = chi2 / N - 1`` is the systematic residual variance in units of
    the noise variance (0 for a perfect model).

Phases (per sample, from the baseline contact state and the measured angle velocity)
    ``approach`` (no contact), ``bending`` (closing in contact, gap above the wall-contact gap),
    ``compaction`` (closing with the inner walls meeting), ``hold`` (in contact, |dtheta/dt| <
    0.5 deg/s), ``release`` (opening in contact).

Candidate effects (:data:`EFFECTS`), each added on top of the baseline, fitted by weighted
least squares (variable projection: linear parameters by bounded linear least squares, at most two
non-linear ones by grid + bounded Brent search), judged by leave-one-trial-out cross-validation,
ranked by the held-out, parameter-penalised explained share of the systematic gap, and combined in
pairs by forward selection.  See the README section "Sim-to-real gap diagnosis".
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from scipy.optimize import lsq_linear, minimize_scalar
from scipy.signal import lfilter

from grasprom.chain import kinematics as kin
from grasprom.control import MAX_PRONY_TERMS, ControllerParams
from grasprom.surrogate import Surrogate

FloatArray = NDArray[np.float64]

REQUIRED_COLUMNS = ("time_s", "theta_deg", "force_handle_N")
OPTIONAL_COLUMNS = ("force_jaw_N", "gap_mm")
SIDECAR_KEYS = ("thickness_mm", "material")
PHASES = ("approach", "bending", "compaction", "hold", "release")
DIRECTIONS = ("closing", "opening", "still")
BLOCKS = ("tissue", "mechanism", "sensor")
VERDICTS = ("explained", "none", "unexplained")

ANALYSIS_RATE_HZ = 100.0
"""Target rate of the analysis grid (Hz)."""
MIN_DURATION_S = 1.0
MIN_ROWS = 50
STILL_DEG_PER_S = 0.5
"""|dtheta/dt| below which the handle counts as still (deg/s)."""
SURROGATE_REL_UNCERTAINTY = 0.01
PRONY_TAUS_S = (0.03, 0.2, 1.0, 5.0)
"""Fixed relaxation times of the Prony candidate (s)."""

SIGNIFICANT_RHO = 1.0
"""Systematic gap ratio above which a gap is significant (systematic RMS > the noise sigma)."""
EXPLAINED_SHARE = 0.7
"""Held-out explained share of the systematic gap needed to call an effect (set) the cause."""
PAIR_GAIN = 0.5
"""A second effect is kept if it removes this share of the gap the first one leaves."""
PAIR_MIN_SHARE = 0.02
"""... and at least this share of the baseline systematic gap."""

FORMAT_REPORT = "grasprom-diagnosis"
FORMAT_AUGMENTED = "grasprom-augmented-model"
FORMAT_VERSION = 1


class TrialDataError(ValueError):
    """A trial file or its sidecar is unusable; the message names file, row and column."""


class DiagnosisError(ValueError):
    """The trials cannot support a diagnosis (too short, no tissue contact ...)."""


# =============================================================================== effect library
@dataclass(frozen=True)
class ParamSpec:
    """One parameter of a candidate effect.

    Parameters
    ----------
    name : str
        Parameter name (units in the name or in ``unit``).
    unit : str
        Unit of the reported value.
    kind : {"linear", "nonlinear"}
        Linear parameters are solved by linear least squares, non-linear ones searched.
    lo, hi : float
        Bounds of the internal coefficient.
    offset : float
        Reported value = internal coefficient + offset (1 for scale and gain factors).
    grid : tuple of float
        Starting grid of a non-linear parameter.
    """

    name: str
    unit: str
    kind: str
    lo: float
    hi: float
    offset: float = 0.0
    grid: tuple[float, ...] = ()


@dataclass(frozen=True)
class EffectSpec:
    """A candidate effect: name, block of the chain, parameters and a one-line model."""

    name: str
    block: str
    params: tuple[ParamSpec, ...]
    model: str


EFFECTS: dict[str, EffectSpec] = {
    e.name: e
    for e in (
        EffectSpec(
            "tissue_viscoelasticity",
            "tissue",
            tuple(ParamSpec(f"g_{tau:g}s", "1", "linear", 0.0, 10.0) for tau in PRONY_TAUS_S),
            "quasi-linear viscoelastic Prony series on the surrogate (elastic = relaxed) force: "
            "Fg = Fe + sum_i g_i int exp(-(t-s)/tau_i) dFe(s), tau = 0.03, 0.2, 1, 5 s; the jaw "
            "force is clipped at 0 (the jaws cannot pull)",
        ),
        EffectSpec(
            "mechanism_friction",
            "mechanism",
            (
                ParamSpec("coulomb_N", "N", "linear", 0.0, 20.0),
                ParamSpec("load_coefficient", "1", "linear", 0.0, 2.0),
                ParamSpec("viscous_N_s_per_mm", "N s/mm", "linear", 0.0, 2.0),
            ),
            "Coulomb + load-proportional Coulomb + viscous friction at the finger: "
            "dFi = (Fc + mu |Fi_tissue|) s + b v, s = direction of the last finger motion, "
            "v finger speed (mm/s, > 0 closing)",
        ),
        EffectSpec(
            "backlash",
            "mechanism",
            (
                ParamSpec(
                    "play_deg",
                    "deg",
                    "nonlinear",
                    0.0,
                    1.2,
                    grid=(0.0, 0.03, 0.06, 0.1, 0.15, 0.22, 0.32, 0.5, 0.8),
                ),
            ),
            "play of total width b between the encoder and the linkage: the chain sees "
            "theta_eff = play(theta, b)",
        ),
        EffectSpec(
            "jaw_compliance",
            "mechanism",
            (
                ParamSpec(
                    "compliance_mm_per_N",
                    "mm/N",
                    "nonlinear",
                    0.0,
                    0.06,
                    grid=(0.0, 0.001, 0.002, 0.004, 0.007, 0.011, 0.017, 0.026, 0.04),
                ),
            ),
            "linear series compliance of jaw + mechanism: the real gap is g(theta) + C Fg, "
            "Fg = F_surrogate(g(theta) + C Fg)",
        ),
        EffectSpec(
            "thickness_error",
            "tissue",
            (
                ParamSpec(
                    "offset_mm",
                    "mm",
                    "nonlinear",
                    -0.4,
                    0.4,
                    grid=tuple(np.round(np.linspace(-0.35, 0.35, 11), 3)),
                ),
            ),
            "the real wall thickness is nominal + offset (clamped to the surrogate's range)",
        ),
        EffectSpec(
            "tissue_stiffness_scale",
            "tissue",
            (ParamSpec("scale", "1", "linear", -0.9, 5.0, offset=1.0),),
            "the tissue force is scale x the surrogate force",
        ),
        EffectSpec(
            "sensor_offset_gain",
            "sensor",
            (
                ParamSpec("offset_N", "N", "linear", -20.0, 20.0),
                ParamSpec("gain", "1", "linear", -0.5, 0.5, offset=1.0),
            ),
            "handle force sensor: F_meas = offset + gain x Fi",
        ),
        EffectSpec(
            "latency",
            "sensor",
            (
                ParamSpec(
                    "delay_s",
                    "s",
                    "nonlinear",
                    0.0,
                    0.15,
                    grid=(0.0, 0.004, 0.008, 0.014, 0.022, 0.032, 0.045, 0.065, 0.1),
                ),
            ),
            "time delay between the measured angle and the measured force: "
            "F_meas(t) = Fi(theta(t - d))",
        ),
    )
}
"""The candidate library (names are a contract)."""

_ORDER = tuple(EFFECTS)


# =============================================================================== trials
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
    missing = [c for c in REQUIRED_COLUMNS if c not in df.columns]
    if missing:
        raise TrialDataError(
            f"{source}: missing column(s) {', '.join(repr(c) for c in missing)} "
            f"(need {', '.join(REQUIRED_COLUMNS)}; optional {', '.join(OPTIONAL_COLUMNS)})"
        )
    n = len(df)
    cols = {c: _num_column(df, c, source) for c in REQUIRED_COLUMNS}
    for c in OPTIONAL_COLUMNS:
        if c in df.columns:
            cols[c] = _num_column(df, c, source)
    t, th, fi = cols["time_s"], cols["theta_deg"], cols["force_handle_N"]
    if n >= 2:
        bad = np.flatnonzero(np.diff(t) <= 0)
        if bad.size:
            i = int(bad[0]) + 1
            raise TrialDataError(
                f"{source}: row {i + 1} (line {i + 2}), column 'time_s': time must increase "
                f"strictly ({float(t[i])!r} s after {float(t[i - 1])!r} s)"
            )
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
    if "gap_mm" in cols:
        g = cols["gap_mm"]
        if n >= 2 and np.max(g) < 0.1:
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
    dur = float(t[-1] - t[0]) if n else 0.0
    if n < MIN_ROWS or dur < MIN_DURATION_S:
        raise TrialDataError(
            f"{source}: trial too short ({n} rows, {dur:.3g} s): a diagnosis needs at least "
            f"{MIN_ROWS} rows and {MIN_DURATION_S:g} s (close, hold and reopen)"
        )
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
    material = str(sidecar["material"])
    if surrogate is not None:
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


# =============================================================================== preparation
def _contact_gap(surrogate: Surrogate, thickness: float, material: str) -> float:
    cs = surrogate.curves(material)
    return float(np.interp(thickness, [c.thickness_mm for c in cs], [c.contact_gap_mm for c in cs]))


def _noise_sigma(x: FloatArray) -> float:
    """White-noise sigma from the median absolute second difference (robust to the signal)."""
    if x.size < 5:
        return float("nan")
    d2 = np.diff(x, 2)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6.0))


def _quantum(theta: FloatArray) -> float:
    d = np.abs(np.diff(theta))
    d = d[d > 1e-12]
    return float(d.min()) if d.size else 0.0


@dataclass
class _Prep:
    """A trial on the analysis grid, with everything the models need (internal)."""

    trial: Trial | None
    t: FloatArray
    theta: FloatArray
    raw_t: FloatArray
    raw_theta: FloatArray
    v_mm_s: FloatArray  # finger speed, > 0 closing
    motion_dir: FloatArray  # direction of the last finger motion (+1 closing, -1 opening, 0)
    thickness: float
    material: str
    F: FloatArray | None = None
    sigma: FloatArray | None = None
    phase: NDArray[np.int_] | None = None
    direction: NDArray[np.int_] | None = None
    F0: FloatArray | None = None
    noise_N: float = float("nan")
    quantum_deg: float = 0.0
    cache: dict = field(default_factory=dict)


def _kinematic_states(
    raw_t: FloatArray, raw_theta: FloatArray, idx: NDArray[np.int_], chain: kin.ChainParams
) -> tuple[FloatArray, FloatArray]:
    """Finger speed (mm/s, > 0 closing) and direction of the last motion on ``idx``."""
    dt = float(np.median(np.diff(raw_t))) if raw_t.size > 1 else 1e-3
    w = max(int(round(0.02 / dt)), 1)  # ~20 ms moving average
    sm = np.convolve(raw_theta, np.ones(w) / w, mode="same") if w > 1 else raw_theta
    if w > 1:  # the ends of "same" convolution are biased: keep the raw values there
        h = w // 2 + 1
        sm[:h] = raw_theta[:h]
        sm[-h:] = raw_theta[-h:]
    vel = np.gradient(sm, raw_t)  # deg/s
    v = -vel[idx]
    v_mm = v * math.radians(1.0) * chain.L3_mm
    moving = np.abs(v) > STILL_DEG_PER_S
    d = np.where(moving, np.sign(v), np.nan)
    # direction of the last motion: forward fill
    s = pd.Series(d).ffill().fillna(0.0).to_numpy()
    return v_mm, s


def _prepare(
    trial: Trial,
    surrogate: Surrogate,
    chain: kin.ChainParams,
    rate_hz: float = ANALYSIS_RATE_HZ,
) -> _Prep:
    raw_t, raw_th = trial.time_s, trial.theta_deg
    dt = float(np.median(np.diff(raw_t)))
    stride = max(int(round(1.0 / (rate_hz * dt))), 1)
    idx = np.arange(0, raw_t.size, stride)
    v_mm, s = _kinematic_states(raw_t, raw_th, idx, chain)
    p = _Prep(
        trial=trial,
        t=raw_t[idx],
        theta=raw_th[idx],
        raw_t=raw_t,
        raw_theta=raw_th,
        v_mm_s=v_mm,
        motion_dir=s,
        thickness=trial.thickness_mm,
        material=trial.material,
        F=trial.force_handle_N[idx],
    )
    p.noise_N = _noise_sigma(trial.force_handle_N)
    p.quantum_deg = _quantum(raw_th)
    th = p.theta
    g = np.asarray(kin.gap_mm(th, chain))
    fe = np.asarray(surrogate.force(g, trial.thickness_mm, trial.material))
    kt = np.asarray(surrogate.stiffness(g, trial.thickness_mm, trial.material))
    f0 = np.asarray(kin.handle_force_N(fe, th, chain))
    slope = np.abs(np.asarray(kin.dhandle_force_dtheta_N_per_rad(fe, kt, th, chain))) * (
        math.pi / 180.0
    )
    p.F0 = f0
    sig = p.noise_N if math.isfinite(p.noise_N) and p.noise_N > 0 else 0.01
    p.sigma = np.sqrt(
        sig**2 + (slope * p.quantum_deg) ** 2 / 12.0 + (SURROGATE_REL_UNCERTAINTY * f0) ** 2 + 1e-8
    )
    contact = fe > 1e-9
    g_c = _contact_gap(surrogate, trial.thickness_mm, trial.material)
    vdeg = p.v_mm_s / (math.radians(1.0) * chain.L3_mm)
    still = np.abs(vdeg) <= STILL_DEG_PER_S
    direction = np.where(still, 2, np.where(vdeg > 0, 0, 1))  # closing, opening, still
    phase = np.zeros(th.size, dtype=int)  # approach
    phase[contact & (direction == 0) & (g > g_c)] = 1
    phase[contact & (direction == 0) & (g <= g_c)] = 2
    phase[contact & (direction == 2)] = 3
    phase[contact & (direction == 1)] = 4
    p.phase = phase
    p.direction = direction
    return p


def prepare_arrays(
    time_s: FloatArray,
    theta_deg: FloatArray,
    thickness_mm: float,
    material: str,
    chain: kin.ChainParams,
) -> _Prep:
    """Model-only preparation of an angle trajectory (for :meth:`AugmentedModel.handle_force_N`)."""
    t = np.asarray(time_s, dtype=float)
    th = np.asarray(theta_deg, dtype=float)
    idx = np.arange(t.size)
    v_mm, s = _kinematic_states(t, th, idx, chain)
    return _Prep(None, t, th, t, th, v_mm, s, float(thickness_mm), str(material))


# =============================================================================== model
def _play_deg(x: FloatArray, width: float) -> FloatArray:
    out = np.empty_like(x)
    h = 0.5 * width
    y = float(x[0])
    for i, xi in enumerate(x.tolist()):
        y = min(max(y, xi - h), xi + h)
        out[i] = y
    return out


def _compliant(
    surrogate: Surrogate, g: FloatArray, c: float, t: float, mat: str, f_free: FloatArray
) -> FloatArray:
    """Solve ``F = F_s(g + c F)`` (N) on the contact samples, bracketed in ``[0, F_s(g)]``.

    Newton on ``r(F) = F - F_s(g + c F)`` (increasing, ``r' = 1 + c k_s``) with a bisection
    whenever the step leaves the bracket or does not halve the step before it (``rtsafe``):
    the surrogate's stiffness jumps where the walls meet, and a plain Newton iteration there can
    creep for many steps.  Converged to ``|r| <= 1e-10 max(1, F)`` (N), in 3-16 iterations on the
    shipped surrogate, at most 60.
    """
    out = np.zeros_like(g)
    m = f_free > 0
    if not np.any(m) or c <= 0:
        return f_free.copy()
    gg = g[m]
    lo = np.zeros_like(gg)
    hi = f_free[m].copy()
    f = hi * 0.5
    dx_old = hi - lo
    dx = dx_old.copy()
    for _ in range(60):
        gp = gg + c * f
        fs = np.asarray(surrogate.force(gp, t, mat))
        ks = np.asarray(surrogate.stiffness(gp, t, mat))
        r = f - fs  # increasing in f
        dr = 1.0 + c * ks
        lo = np.where(r < 0, f, lo)
        hi = np.where(r > 0, f, hi)
        done = (np.abs(r) <= 1e-10 * np.maximum(1.0, fs)) | (hi - lo <= 1e-13 * np.maximum(1.0, hi))
        if np.all(done):
            break
        fn = f - r / dr
        newton = (fn > lo) & (fn < hi) & (np.abs(2.0 * r) <= np.abs(dx_old * dr))
        dx_old = dx
        dx = np.where(newton, r / dr, f - 0.5 * (lo + hi))
        f = np.where(done, f, f - dx)
    out[m] = f
    return out


def _columns(effects: Sequence[str]) -> list[tuple[str, ParamSpec]]:
    return [(e, p) for e in effects for p in EFFECTS[e].params if p.kind == "linear"]


def _nl_params(effects: Sequence[str]) -> list[tuple[str, ParamSpec]]:
    return [(e, p) for e in effects for p in EFFECTS[e].params if p.kind == "nonlinear"]


def _evaluate(
    prep: _Prep,
    effects: Sequence[str],
    nl: Sequence[float],
    surrogate: Surrogate,
    chain: kin.ChainParams,
    cache: bool = False,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Model handle force without linear terms ``F0`` (N), the linear basis ``Phi`` and ``T``.

    The augmented model is ``F0 + Phi @ coef`` (see :func:`_combine` for the clip of the jaw
    force) with the linear coefficients of :func:`_columns`; ``nl`` are the non-linear
    parameters of :func:`_nl_params`; ``T`` is the tissue part of ``F0`` (N at the handle).
    """
    key = (tuple(effects), tuple(round(float(x), 12) for x in nl))
    if cache and key in prep.cache:
        return prep.cache[key]
    nlv = {p.name: float(x) for (_, p), x in zip(_nl_params(effects), nl)}
    th = prep.theta
    v = prep.v_mm_s
    sdir = prep.motion_dir
    if "latency" in effects and nlv["delay_s"] > 0:
        d = nlv["delay_s"]
        th = np.interp(prep.t - d, prep.raw_t, prep.raw_theta)
        v = np.interp(prep.t - d, prep.t, v)
        sdir = np.interp(prep.t - d, prep.t, sdir)
    lo, hi = kin.theta_range_deg(chain)
    if "backlash" in effects and nlv["play_deg"] > 0:
        th = np.clip(_play_deg(th, nlv["play_deg"]), lo, hi)
    t_eff = prep.thickness
    if "thickness_error" in effects:
        tlo, thi = surrogate.thickness_range(prep.material)
        t_eff = min(max(t_eff + nlv["offset_mm"], tlo), thi)
    g = np.asarray(kin.gap_mm(th, chain))
    fe = np.asarray(surrogate.force(g, t_eff, prep.material), dtype=float)
    if "jaw_compliance" in effects and nlv["compliance_mm_per_N"] > 0:
        fe = _compliant(surrogate, g, nlv["compliance_mm_per_N"], t_eff, prep.material, fe)
    gp = np.asarray(kin.dgap_dtheta_mm_per_rad(th, chain)) / chain.L3_mm  # dFi/dFg
    f0 = np.asarray(kin.handle_force_N(fe, th, chain), dtype=float)
    cols: list[FloatArray] = []
    for e in effects:
        if e == "tissue_viscoelasticity":
            dt = float(np.median(np.diff(prep.t))) if prep.t.size > 1 else 1e-3
            dfe = np.diff(fe, prepend=0.0)
            for tau in PRONY_TAUS_S:
                a = math.exp(-dt / tau)
                cols.append(lfilter([1.0], [1.0, -a], dfe) * gp)
        elif e == "mechanism_friction":
            cols += [sdir, sdir * np.abs(fe * gp), v]
        elif e == "tissue_stiffness_scale":
            cols.append(fe * gp)
        elif e == "sensor_offset_gain":
            cols += [np.ones_like(f0), f0]
    phi = np.column_stack(cols) if cols else np.zeros((f0.size, 0))
    out = (f0, phi, fe * gp)
    if cache:
        prep.cache[key] = out
    return out


@dataclass
class _Fit:
    effects: tuple[str, ...]
    nl: tuple[float, ...]
    coef: FloatArray
    chi2: float


def _visco_index(effects: Sequence[str]) -> NDArray[np.int_]:
    return np.array(
        [i for i, (e, _) in enumerate(_columns(effects)) if e == "tissue_viscoelasticity"],
        dtype=int,
    )


def _combine(
    f0: FloatArray, phi: FloatArray, tis: FloatArray, coef: FloatArray, vi: NDArray[np.int_]
) -> FloatArray:
    """Augmented handle force (N): ``F0 + Phi coef`` with the viscoelastic jaw force >= 0."""
    if phi.shape[1] == 0:
        return f0
    out = f0 + phi @ coef
    if vi.size:
        jaw = tis + phi[:, vi] @ coef[vi]
        out = out - np.minimum(jaw, 0.0)
    return out


def _solve(
    preps: Sequence[_Prep],
    effects: Sequence[str],
    nl: Sequence[float],
    surrogate: Surrogate,
    chain: kin.ChainParams,
    cache: bool,
) -> tuple[FloatArray, float]:
    ys, As, Ts, ws = [], [], [], []
    for p in preps:
        f0, phi, tis = _evaluate(p, effects, nl, surrogate, chain, cache)
        w = 1.0 / p.sigma
        ys.append((p.F - f0) * w)
        As.append(phi * w[:, None])
        Ts.append(tis * w)
        ws.append(w)
    y = np.concatenate(ys)
    A = np.vstack(As)
    if A.shape[1] == 0:
        return np.zeros(0), float(y @ y)
    cols = _columns(effects)
    lo = np.array([p.lo for _, p in cols])
    hi = np.array([p.hi for _, p in cols])
    vi = _visco_index(effects)
    T = np.concatenate(Ts)
    clipped = np.zeros(y.size, dtype=bool)
    coef = np.zeros(A.shape[1])
    for _ in range(4 if vi.size else 1):  # active set of the jaw-force clip
        yy = np.where(clipped, y + T, y)
        AA = A.copy()
        if vi.size:
            AA[np.ix_(clipped, vi)] = 0.0
        s = np.sqrt(np.sum(AA * AA, axis=0))
        s[s == 0] = 1.0
        coef = lsq_linear(AA / s, yy, bounds=(lo * s, hi * s), method="bvls").x / s
        if not vi.size:
            break
        new = (T + A[:, vi] @ coef[vi]) < 0
        if np.array_equal(new, clipped):
            break
        clipped = new
    r = y - (_combine(np.zeros_like(y), A, T, coef, vi))
    return coef, float(r @ r)


def _fit(
    preps: Sequence[_Prep],
    effects: Sequence[str],
    surrogate: Surrogate,
    chain: kin.ChainParams,
) -> _Fit:
    """Weighted least-squares fit of an effect set on ``preps`` (variable projection)."""
    nlp = [p for _, p in _nl_params(effects)]

    def obj(x: Sequence[float], cache: bool = False) -> float:
        return _solve(preps, effects, x, surrogate, chain, cache)[1]

    def line_search(k: int, x: list[float], refine_only: bool = False) -> list[float]:
        ps = nlp[k]
        grid = list(ps.grid)

        def f1(z: float, cache: bool = False) -> float:
            xx = list(x)
            xx[k] = z
            return obj(xx, cache)

        if refine_only:  # around the current value, one grid step either side
            i = int(np.argmin(np.abs(np.array(grid) - x[k])))
            step = grid[min(i + 1, len(grid) - 1)] - grid[max(i - 1, 0)]
            a, b = max(ps.lo, x[k] - 0.5 * step), min(ps.hi, x[k] + 0.5 * step)
            best_x, best_v = x[k], f1(x[k])
        else:
            vals = [f1(gv, cache=True) for gv in grid]
            i = int(np.argmin(vals))
            a = grid[max(i - 1, 0)] if i > 0 else ps.lo
            b = grid[min(i + 1, len(grid) - 1)] if i < len(grid) - 1 else ps.hi
            best_x, best_v = grid[i], vals[i]
        if b > a:
            r = minimize_scalar(
                f1,
                bounds=(a, b),
                method="bounded",
                options={"xatol": 4e-3 * (ps.hi - ps.lo), "maxiter": 12},
            )
            if r.fun < best_v:
                best_x = float(r.x)
        out = list(x)
        out[k] = best_x
        return out

    x = [0.0 if p.lo <= 0.0 <= p.hi else p.lo for p in nlp]
    if len(nlp) == 1:
        x = line_search(0, x)
    elif len(nlp) >= 2:
        for k in range(len(nlp)):
            x = line_search(k, x)
        for k in range(len(nlp)):
            x = line_search(k, x, refine_only=True)
    coef, chi2 = _solve(preps, effects, x, surrogate, chain, False)
    return _Fit(tuple(effects), tuple(x), coef, chi2)


def _predict(prep: _Prep, fit: _Fit, surrogate: Surrogate, chain: kin.ChainParams) -> FloatArray:
    f0, phi, tis = _evaluate(prep, fit.effects, fit.nl, surrogate, chain)
    return _combine(f0, phi, tis, fit.coef, _visco_index(fit.effects))


def _fit_params(fit: _Fit) -> dict[str, dict[str, float]]:
    """Reported parameter values per effect."""
    out: dict[str, dict[str, float]] = {e: {} for e in fit.effects}
    for (e, p), x in zip(_nl_params(fit.effects), fit.nl):
        out[e][p.name] = float(x) + p.offset
    for (e, p), c in zip(_columns(fit.effects), fit.coef):
        out[e][p.name] = float(c) + p.offset
    return {e: {p.name: out[e][p.name] for p in EFFECTS[e].params} for e in fit.effects}


# =============================================================================== evaluation
@dataclass
class _CV:
    effects: tuple[str, ...]
    residuals: list[FloatArray]  # held-out residual per trial (N)
    chi2: float
    fold_params: list[dict[str, dict[str, float]]]
    predictions: list[FloatArray]


def _folds(n: int, max_folds: int = 6) -> list[list[int]]:
    if n <= max_folds:
        return [[i] for i in range(n)]
    return [list(range(k, n, max_folds)) for k in range(max_folds)]


def _cross_validate(
    preps: Sequence[_Prep],
    effects: Sequence[str],
    surrogate: Surrogate,
    chain: kin.ChainParams,
) -> _CV:
    n = len(preps)
    res: list[FloatArray | None] = [None] * n
    pred: list[FloatArray | None] = [None] * n
    fold_params = []
    folds = _folds(n) if n >= 2 else [[0]]
    for held in folds:
        train = [preps[i] for i in range(n) if i not in held] or list(preps)
        fit = _fit(train, effects, surrogate, chain)
        fold_params.append(_fit_params(fit))
        for i in held:
            pr = _predict(preps[i], fit, surrogate, chain)
            pred[i] = pr
            res[i] = preps[i].F - pr
    chi2 = float(sum(np.sum((r / p.sigma) ** 2) for r, p in zip(res, preps)))
    return _CV(tuple(effects), res, chi2, fold_params, pred)  # type: ignore[arg-type]


def _uncertainty(fold_params: list[dict[str, dict[str, float]]]) -> dict[str, dict[str, float]]:
    """Jackknife standard error of the parameters over the cross-validation folds."""
    k = len(fold_params)
    out: dict[str, dict[str, float]] = {}
    for e, ps in fold_params[0].items():
        out[e] = {}
        for name in ps:
            vals = np.array([fp[e][name] for fp in fold_params])
            out[e][name] = (
                float(math.sqrt((k - 1) / k * np.sum((vals - vals.mean()) ** 2)))
                if (k > 1)
                else float("nan")
            )
    return out


def _stats(r: FloatArray, total_ss: float) -> dict[str, float]:
    if r.size == 0:
        return {"rms_N": None, "bias_N": None, "share": 0.0, "n": 0}  # type: ignore[dict-item]
    ss = float(r @ r)
    return {
        "rms_N": float(math.sqrt(ss / r.size)),
        "bias_N": float(r.mean()),
        "share": float(ss / total_ss) if total_ss > 0 else 0.0,
        "n": int(r.size),
    }


def _by_label(
    res: Sequence[FloatArray], labels: Sequence[NDArray[np.int_]], names: Sequence[str]
) -> dict[str, dict[str, float]]:
    r = np.concatenate(res)
    lab = np.concatenate(labels)
    tot = float(r @ r)
    return {name: _stats(r[lab == k], tot) for k, name in enumerate(names)}


def _rms(res: Sequence[FloatArray]) -> float:
    r = np.concatenate(res)
    return float(math.sqrt(r @ r / r.size))


# =============================================================================== diagnosis
@dataclass
class Diagnosis:
    """Result of :func:`diagnose`: the JSON-ready report and the data behind the plots."""

    report: dict[str, Any]
    augmented: dict[str, Any]
    preps: list[_Prep] = field(repr=False, default_factory=list)
    baseline_pred: list[FloatArray] = field(repr=False, default_factory=list)
    augmented_pred: list[FloatArray] = field(repr=False, default_factory=list)


_GAP_MECHANISM = ("backlash", "jaw_compliance")
"""Mechanism candidates that act on the jaw gap (between the handle angle and the jaws).

Without a ``gap_mm`` channel the deviation of the measured jaw force from the surrogate at the
kinematic gap comes either from the tissue block (the force law: candidates of block ``tissue``)
or from these (the gap the tissue sees); :func:`_jaw_path_split` decides by fitting both.
"""
_SMOOTH_S = 0.02
"""Centred moving-average window of the jaw force channel in the block analysis (s)."""


def _smooth(x: FloatArray, t: FloatArray, window_s: float = _SMOOTH_S) -> tuple[FloatArray, int]:
    """Centred moving average over ``window_s`` (s) and its length in samples.

    The raw values are kept at both ends (where the window would leave the record).
    """
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1e-3
    w = max(int(round(window_s / dt)), 1)
    if w <= 1 or x.size <= 2 * w:
        return x.astype(float), 1
    out = np.convolve(x, np.ones(w) / w, mode="same")
    h = w // 2 + 1
    out[:h] = x[:h]
    out[-h:] = x[-h:]
    return out, w


def _sub_fit(fit: _Fit, keep: Sequence[str]) -> _Fit:
    """The part of a fitted effect set made of the effects ``keep`` (same parameter values)."""
    nl = tuple(x for (e, _), x in zip(_nl_params(fit.effects), fit.nl) if e in keep)
    coef = np.array([c for (e, _), c in zip(_columns(fit.effects), fit.coef) if e in keep])
    return _Fit(tuple(e for e in fit.effects if e in keep), nl, coef, float("nan"))


def _jaw_path_split(
    jpreps: Sequence[_Prep], surrogate: Surrogate, chain: kin.ChainParams
) -> tuple[list[dict[str, FloatArray]], str, str]:
    """Split the jaw-force residual at the kinematic gap between tissue and mechanism.

    ``jpreps`` carry ``F = handle_force_N(F_jaw_measured, theta)`` (the measured jaw force taken
    to the handle through the ideal chain), so their baseline residual is
    ``g'/L3 (F_jaw - F_s(g(theta)))`` (N at the handle).  Without a gap channel two causes show
    there: a wrong tissue force law (scale, wall thickness, rate dependence) and a wrong gap
    (the jaws are not where the handle angle puts them: play, compliance).  Both act through
    the surrogate differently -- a gap error is a shift along the force-gap curve that depends
    on the load (compliance, >= 0) or on the motion direction and persists at rest (play, >= 0);
    a force-law error scales, reshapes or relaxes the curve -- so each tissue candidate and each
    of :data:`_GAP_MECHANISM` is fitted to it (weighted least squares on all trials, penalty
    ``ln N`` per parameter) and the best one names the block.  If a candidate of the other block
    then removes at least :data:`PAIR_GAIN` of the systematic residual the first leaves (and
    lowers the penalised fit), the pair's prediction is split by effect.  What the candidates
    leave (noise, model mismatch) stays in the block of the best single candidate.  A residual
    within the noise (systematic ratio <= :data:`SIGNIFICANT_RHO`) is not fitted and counts as
    tissue.

    Returns
    -------
    list of dict
        Per trial ``{"tissue": r, "mechanism": r}`` (N at the handle), summing to the residual.
    str
        The block holding the rest (``"tissue"`` or ``"mechanism"``).
    str
        What decided the split.
    """
    res0 = [p.F - p.F0 for p in jpreps]
    n = int(sum(p.t.size for p in jpreps))
    chi0 = float(sum(np.sum((r / p.sigma) ** 2) for r, p in zip(res0, jpreps)))
    if chi0 / n - 1.0 <= SIGNIFICANT_RHO:
        return (
            [{"tissue": r, "mechanism": np.zeros_like(r)} for r in res0],
            "tissue",
            "jaw force at the kinematic gap within the noise",
        )
    lnn = math.log(max(n, 2))
    cands = [e for e in _ORDER if EFFECTS[e].block == "tissue"] + list(_GAP_MECHANISM)
    fits = {e: _fit(jpreps, (e,), surrogate, chain) for e in cands}

    def crit(f: _Fit) -> float:
        return f.chi2 + lnn * sum(len(EFFECTS[e].params) for e in f.effects)

    best = min(cands, key=lambda e: crit(fits[e]))
    home = EFFECTS[best].block
    chosen = fits[best]
    for e in cands:
        left = chosen.chi2 - n
        if EFFECTS[e].block == home or left <= 0:
            continue
        f2 = _fit(jpreps, tuple(sorted((best, e), key=_ORDER.index)), surrogate, chain)
        if (chosen.chi2 - f2.chi2) / left >= PAIR_GAIN and crit(f2) < crit(chosen):
            chosen = f2
    out = []
    for p, r in zip(jpreps, res0):
        full = _predict(p, chosen, surrogate, chain) - p.F0
        own = full
        if len(chosen.effects) == 2:
            own = _predict(p, _sub_fit(chosen, [best]), surrogate, chain) - p.F0
        parts = {"tissue": np.zeros_like(r), "mechanism": np.zeros_like(r)}
        parts[home] += own + (r - full)  # the best candidate and what no candidate explains
        parts["mechanism" if home == "tissue" else "tissue"] += full - own
        out.append(parts)
    return out, home, f"jaw force vs. kinematic gap fitted best by {' + '.join(chosen.effects)}"


def _sensor_split(items: Sequence[dict[str, Any]]) -> list[dict[str, FloatArray]]:
    """Split the handle residual left by the measured jaw force into sensor and mechanism (N).

    ``r = F_meas - Hc(t)``, ``Hc = handle_force_N(F_jaw_measured, theta)`` the handle force the
    ideal chain needs for the measured jaw force.  Per trial, with one delay ``d`` (s) common to
    all trials (searched on the grid of the latency candidate, refined by a bounded Brent
    search), linear least squares of::

        F_meas = (1 + b) Hc(t - d) + a + c t               handle force sensor: gain, offset,
                                                           drift, delay (a first-order lag of
                                                           the sensor shows as extra delay)
                 + Fc s + mu s |F_jaw g'/L3| + beta v      friction of the chain (the terms of
                                                           the mechanism_friction candidate)

    The sensor part is ``(1 + b) Hc(t - d) + a + c t - Hc(t)``; the mechanism part is the rest
    of ``r``: the friction terms and what neither explains (the chain between the jaw load cell
    and the handle is the mechanism).

    Parameters
    ----------
    items : sequence of dict
        Per trial: ``t`` (analysis grid, s), ``F`` (measured handle force there, N), ``hc``
        (``Hc`` there, N), ``raw_t`` / ``hc_raw`` (``Hc`` at the raw rate, from the smoothed jaw
        force) and ``fric`` (the three friction columns).

    Returns
    -------
    list of dict
        Per trial ``{"sensor": r, "mechanism": r}`` (N), summing to ``F - hc``.
    """
    spec = EFFECTS["latency"].params[0]
    grid = spec.grid

    def solve(d: float, keep: bool = False) -> Any:
        ss, out = 0.0, []
        for it in items:
            t = it["t"]
            hd = np.interp(t - d, it["raw_t"], it["hc_raw"])
            a_sen = np.column_stack([np.ones_like(t), hd, t - t[0]])
            a = np.column_stack([a_sen, it["fric"]])
            y = it["F"] - hd
            c, *_ = np.linalg.lstsq(a, y, rcond=None)
            r = y - a @ c
            ss += float(r @ r)
            if keep:
                sen = hd - it["hc"] + a_sen @ c[: a_sen.shape[1]]
                out.append({"sensor": sen, "mechanism": it["F"] - it["hc"] - sen})
        return out if keep else ss

    vals = [solve(d) for d in grid]
    i = int(np.argmin(vals))
    lo = grid[i - 1] if i > 0 else spec.lo
    hi = grid[i + 1] if i < len(grid) - 1 else spec.hi
    d = grid[i]
    r = minimize_scalar(solve, bounds=(lo, hi), method="bounded", options={"xatol": 5e-4})
    if r.fun < vals[i]:
        d = float(r.x)
    return solve(d, keep=True)


def _block_analysis(
    preps: Sequence[_Prep], surrogate: Surrogate, chain: kin.ChainParams
) -> tuple[dict[str, Any] | None, str]:
    """Baseline residual per block of the chain from the optional ``force_jaw_N`` / ``gap_mm``.

    The handle residual ``r = F_meas - F0`` (N) of every trial with either channel is split
    exactly, sample by sample (``g'/L3 = dFi/dFg`` maps a jaw force to the handle, ``g`` the
    kinematic gap of the measured angle, ``F_s`` the surrogate, ``Hc = handle_force_N(F_jaw,
    theta)``; the jaw force is smoothed over :data:`_SMOOTH_S`):

    ``mechanism`` (gap)
        ``g'/L3 (F_s(g_meas) - F_s(g))``: the tissue sees another gap than the kinematic one
        (play, compliance); only with ``gap_mm``.
    ``tissue``
        ``g'/L3 (F_jaw - F_s(g_meas))``: the measured jaw force differs from the surrogate at the
        measured gap.  Without ``gap_mm``, ``g'/L3 (F_jaw - F_s(g))`` is split between tissue and
        the gap mechanism by :func:`_jaw_path_split`.
    ``sensor`` and ``mechanism`` (transmission)
        ``F_meas - Hc``: the handle force the chain does not account for given the measured jaw
        force, split by :func:`_sensor_split` into the handle force sensor (offset, gain, drift,
        delay) and the chain (friction and the rest).

    With ``gap_mm`` but no jaw force, ``F_meas - handle_force_N(F_s(g_meas), theta)`` counts as
    tissue (it cannot be separated from friction or sensor errors there).  ``share`` is each
    block's sum of squares less the part the white noise of its channel puts there (handle
    sensor noise in the transmission part, the smoothed jaw load cell noise in the jaw-force
    part), clipped at 0, over the total (raw sums of squares when all are within the noise);
    ``rms_N`` and ``bias_N`` are of the raw parts.

    Returns
    -------
    dict or None
        ``{block: {"rms_N", "bias_N", "share"}}`` for the blocks of :data:`BLOCKS`; None when no
        trial has either channel.
    str
        How the jaw-force residual was attributed without a gap channel ("" when not needed).
    """
    from dataclasses import replace

    parts: dict[str, list[FloatArray]] = {b: [] for b in BLOCKS}
    weights: list[FloatArray] = []  # 1 / s_i^2 of the diagnosis' error model (1/N^2)
    noise_ss = {b: 0.0 for b in BLOCKS}  # expected weighted sum of squares of the noise
    jaw_only: list[tuple[int, _Prep]] = []
    jaw_only_noise = 0.0
    sens: list[tuple[int, dict[str, Any]]] = []
    for p in preps:
        tr = p.trial
        if tr is None or (tr.force_jaw_N is None and tr.gap_mm is None):
            continue
        k = len(parts["tissue"])
        th = p.theta
        idx = np.searchsorted(tr.time_s, p.t)
        gp = np.asarray(kin.dgap_dtheta_mm_per_rad(th, chain)) / chain.L3_mm  # dFi/dFg
        g_kin = np.asarray(kin.gap_mm(th, chain))
        f_kin = np.asarray(surrogate.force(g_kin, p.thickness, p.material))
        for b in BLOCKS:
            parts[b].append(np.zeros_like(th))
        w_i = 1.0 / p.sigma**2
        weights.append(w_i)
        sig_h = p.noise_N if math.isfinite(p.noise_N) and p.noise_N > 0 else 0.0
        s_model2 = np.maximum(p.sigma**2 - max(sig_h, 0.01) ** 2, 0.0)  # quantum, surrogate
        f_gm = f_kin
        if tr.gap_mm is not None:
            # the gap sensor's noise reaches the force through the surrogate's stiffness
            # (hundreds of N/mm once the walls meet): smooth it as the jaw force, and count what
            # is left of it in the noise of both parts it enters (mechanism +, tissue -)
            g_sm, wg = _smooth(tr.gap_mm, tr.time_s)
            g_meas = g_sm[idx]
            f_gm = np.asarray(surrogate.force(g_meas, p.thickness, p.material))
            parts["mechanism"][k] += (f_gm - f_kin) * gp
            sig_g = _noise_sigma(tr.gap_mm)
            if math.isfinite(sig_g) and sig_g > 0:
                k_s = np.asarray(surrogate.stiffness(g_meas, p.thickness, p.material))
                gap_noise = float(np.sum(w_i * (gp * k_s * sig_g) ** 2 / wg))
                noise_ss["mechanism"] += gap_noise
                noise_ss["tissue"] += gap_noise
        h_gm = np.asarray(kin.handle_force_N(f_gm, th, chain))
        if tr.force_jaw_N is None:
            parts["tissue"][k] += p.F - h_gm
            noise_ss["tissue"] += float(np.sum(w_i * (s_model2 + sig_h**2)))
            continue
        fj_raw, w = _smooth(tr.force_jaw_N, tr.time_s)
        hc_raw = np.asarray(kin.handle_force_N(fj_raw, tr.theta_deg, chain))
        hc = hc_raw[idx]
        sig_j = _noise_sigma(tr.force_jaw_N)
        jaw_var = (gp * sig_j) ** 2 / w if math.isfinite(sig_j) else np.zeros_like(th)
        jaw_noise = float(np.sum(w_i * (s_model2 + jaw_var)))
        if tr.gap_mm is not None:
            parts["tissue"][k] += hc - h_gm
            noise_ss["tissue"] += jaw_noise
        else:
            jp = replace(p, F=hc, sigma=np.sqrt(s_model2 + jaw_var + 1e-8))
            jaw_only.append((k, jp))
            jaw_only_noise += jaw_noise
        fric = np.column_stack([p.motion_dir, p.motion_dir * np.abs(fj_raw[idx] * gp), p.v_mm_s])
        item = {"t": p.t, "F": p.F, "hc": hc, "raw_t": tr.time_s, "hc_raw": hc_raw, "fric": fric}
        sens.append((k, item))
        noise_ss["mechanism"] += float(np.sum(w_i * sig_h**2))
    if not parts["tissue"]:
        return None, ""
    how = ""
    if jaw_only:
        splits, home, how = _jaw_path_split([jp for _, jp in jaw_only], surrogate, chain)
        for (k, _), sp in zip(jaw_only, splits):
            for b, r in sp.items():
                parts[b][k] += r
        noise_ss[home] += jaw_only_noise
    if sens:
        for (k, _), sp in zip(sens, _sensor_split([it for _, it in sens])):
            for b, r in sp.items():
                parts[b][k] += r
    ss = {
        b: float(sum(float(w_i @ (x * x)) for x, w_i in zip(v, weights))) for b, v in parts.items()
    }
    sys_ss = {b: max(ss[b] - noise_ss[b], 0.0) for b in BLOCKS}
    tot = sum(sys_ss.values())
    if tot <= 0:
        sys_ss, tot = ss, sum(ss.values())
    out = {}
    for b, v in parts.items():
        r = np.concatenate(v)
        out[b] = {
            "rms_N": float(math.sqrt(r @ r / r.size)),
            "bias_N": float(r.mean()),
            "share": sys_ss[b] / tot if tot > 0 else 0.0,
        }
    return out, how


def _trial_conditions(preps: Sequence[_Prep], chain: kin.ChainParams) -> list[dict[str, Any]]:
    out = []
    for p in preps:
        closing = p.direction == 0
        if np.any(closing):
            i0 = int(np.argmax(closing))
            i1 = int(np.argmin(p.theta))
            span = float(p.theta[i0] - p.theta[i1])
            dur = float(p.t[i1] - p.t[i0])
            speed = span / dur if dur > 0 else float("nan")
        else:
            speed = float("nan")
        out.append({"closing_speed_deg_per_s": speed, "thickness_mm": p.thickness})
    speeds = np.array([c["closing_speed_deg_per_s"] for c in out])
    med = float(np.nanmedian(speeds)) if np.any(np.isfinite(speeds)) else float("nan")
    for c in out:
        s = c["closing_speed_deg_per_s"]
        c["speed_class"] = "fast" if (math.isfinite(s) and s > med * 1.001) else "slow"
    return out


def diagnose(
    trials: Sequence[Trial],
    surrogate: Surrogate,
    chain: kin.ChainParams | None = None,
    *,
    rate_hz: float = ANALYSIS_RATE_HZ,
    effects: Sequence[str] | None = None,
    try_pairs: bool = True,
) -> Diagnosis:
    """Diagnose the gap between measured trials and the baseline model.

    Parameters
    ----------
    trials : sequence of Trial
        Validated trials (:func:`load_trial`).
    surrogate : Surrogate
        Tissue force table of the baseline.
    chain : kinematics.ChainParams, optional
        Instrument chain (default geometry and spring).
    rate_hz : float
        Analysis grid rate (Hz).
    effects : sequence of str, optional
        Candidate effects to try (default all of :data:`EFFECTS`).
    try_pairs : bool
        Forward selection of a second effect.

    Returns
    -------
    Diagnosis

    Raises
    ------
    DiagnosisError
        No trial, or no trial reaching the tissue.
    """
    chain = chain or kin.ChainParams()
    cands = tuple(effects) if effects is not None else _ORDER
    for e in cands:
        if e not in EFFECTS:
            raise ValueError(f"unknown effect {e!r}; valid: {', '.join(EFFECTS)}")
    if not trials:
        raise DiagnosisError("no trial given")
    warn_list: list[str] = []
    preps_all = [_prepare(tr, surrogate, chain, rate_hz) for tr in trials]
    preps = []
    for p in preps_all:
        n_contact = int(np.sum(p.phase != 0))
        if n_contact < 10:
            warn_list.append(
                f"{p.trial.name}: no tissue contact (the jaws never close below the tube "
                f"diameter {surrogate.diameter_mm:g} mm, theta never below "
                f"{chain.theta_touch_deg:.2f} deg); left out"
            )
        else:
            preps.append(p)
    if not preps:
        raise DiagnosisError(
            "no trial reaches the tissue (the jaw gap never falls below the tube diameter "
            f"{surrogate.diameter_mm:g} mm): the sim-to-real gap of the grasp cannot be "
            "diagnosed from free motion alone"
        )
    if len(preps) < 2:
        warn_list.append(
            "only one trial in contact: no cross-validation by trial is possible; effects are "
            "judged in-sample and the confidence is capped at 0.3"
        )
    N = int(sum(p.t.size for p in preps))
    noise = float(np.median([p.noise_N for p in preps]))
    labels = [p.phase for p in preps]
    dlabels = [p.direction for p in preps]
    res0 = [p.F - p.F0 for p in preps]
    chi0 = float(sum(np.sum((r / p.sigma) ** 2) for r, p in zip(res0, preps)))
    rho0 = chi0 / N - 1.0
    sys0 = chi0 - N
    total_ss = float(sum(r @ r for r in res0))
    conds = _trial_conditions(preps, chain)

    def group(key: str) -> dict[str, Any]:
        vals = sorted({str(c[key]) for c in conds})
        out = {}
        for v in vals:
            rs = [r for r, c in zip(res0, conds) if str(c[key]) == v]
            rr = np.concatenate(rs)
            out[v] = _stats(rr, total_ss)
        return out

    baseline = {
        "model": "static derived chain + surrogate tissue force at the measured angle",
        "rms_N": _rms(res0),
        "bias_N": float(np.concatenate(res0).mean()),
        "noise_N": noise,
        "encoder_quantum_deg": float(np.median([p.quantum_deg for p in preps])),
        "model_uncertainty_rms_N": float(
            math.sqrt(np.mean(np.concatenate([p.sigma**2 for p in preps]) - noise**2).clip(0))
        ),
        "systematic_ratio": rho0,
        "systematic_rms_N": float(math.sqrt(max(rho0, 0.0))) * noise,
        "significant": bool(rho0 > SIGNIFICANT_RHO),
        "n_samples": N,
        "by_phase": _by_label(res0, labels, PHASES),
        "by_direction": _by_label(res0, dlabels, DIRECTIONS),
        "by_condition": {"thickness_mm": group("thickness_mm"), "speed": group("speed_class")},
        "by_trial": [
            {"trial": p.trial.name, "trial_id": p.trial.trial_id, **c, **_stats(r, total_ss)}
            for p, c, r in zip(preps, conds, res0)
        ],
        "by_block": None,
    }
    baseline["by_block"], block_how = _block_analysis(preps, surrogate, chain)
    where_phase = max(PHASES, key=lambda k: baseline["by_phase"][k]["share"])

    # ---- candidates
    cv: dict[tuple[str, ...], _CV] = {}
    lnN = math.log(max(N, 2))

    def n_par(es: Sequence[str]) -> int:
        return sum(len(EFFECTS[e].params) for e in es)

    def share(key: tuple[str, ...]) -> float:
        if sys0 <= 0:
            return 0.0
        return (chi0 - cv[key].chi2) / sys0

    def score(key: tuple[str, ...]) -> float:
        if sys0 <= 0:
            return 0.0
        return (chi0 - cv[key].chi2 - n_par(key) * lnN) / sys0

    for e in cands:
        cv[(e,)] = _cross_validate(preps, (e,), surrogate, chain)
    singles = sorted(((e,) for e in cands), key=score, reverse=True)
    best = singles[0]
    chosen = best
    pair_rows = []
    rho_best = cv[best].chi2 / N - 1.0
    if try_pairs and len(cands) > 1 and rho_best > SIGNIFICANT_RHO and rho0 > SIGNIFICANT_RHO:
        for e in cands:
            if e == best[0]:
                continue
            key = tuple(sorted(best + (e,), key=_ORDER.index))
            cv[key] = _cross_validate(preps, key, surrogate, chain)
        pairs = sorted((k for k in cv if len(k) == 2), key=score, reverse=True)
        for k in pairs:
            pair_rows.append(k)
        top = pairs[0]
        left = cv[best].chi2 - N
        gain = (cv[best].chi2 - cv[top].chi2) / left if left > 0 else 0.0
        if gain >= PAIR_GAIN and score(top) - score(best) >= PAIR_MIN_SHARE:
            chosen = top

    # ---- verdict
    rms_before = _rms(res0)
    e_share = share(chosen)
    rms_after = _rms(cv[chosen].residuals)
    runner = [k for k in singles if k != best]
    if len(chosen) == 1:
        alt = max((share(k) for k in runner), default=0.0)
    else:
        alt = max([share(best)] + [share(k) for k in pair_rows if k != chosen])
    # separation from the runner-up: ratio of the systematic gaps they leave
    u_best = max(1.0 - e_share, 0.02)
    u_alt = max(1.0 - alt, 0.02)
    sep = float(np.clip(math.log(u_alt / u_best) / math.log(5.0), 0.0, 1.0))
    if not rho0 > SIGNIFICANT_RHO:
        label = "none"
        effects_out: list[str] = []
        conf = float(np.clip(1.0 - rho0 / SIGNIFICANT_RHO, 0.0, 1.0)) * 0.5 + 0.5
        rms_after = rms_before
        msg = (
            f"the gap is within the noise: systematic ratio {rho0:.3g} <= "
            f"{SIGNIFICANT_RHO} (systematic RMS {baseline['systematic_rms_N']:.3g} N vs noise "
            f"{noise:.3g} N)"
        )
    elif e_share >= EXPLAINED_SHARE:
        label = "explained"
        effects_out = list(chosen)
        conf = float(np.clip(e_share, 0.0, 1.0)) * (0.4 + 0.6 * sep)
        msg = (
            f"{' + '.join(chosen)} explains {100 * min(e_share, 1.0):.0f} % of the systematic "
            "gap on held-out trials"
        )
    else:
        label = "unexplained"
        effects_out = []
        rms_after = rms_before
        conf = float(np.clip(1.0 - max(e_share, 0.0) / EXPLAINED_SHARE, 0.0, 1.0)) * min(
            1.0, rho0 / (4 * SIGNIFICANT_RHO)
        )
        msg = (
            f"significant gap (systematic ratio {rho0:.3g}); the best candidate "
            f"({' + '.join(chosen)}) explains only {100 * max(e_share, 0.0):.0f} % of it on "
            "held-out trials: an effect outside the library?"
        )
    if len(preps) < 2:
        conf = min(conf, 0.3)

    def sys_shrink(key: tuple[str, ...]) -> float:
        """Share of the systematic gap RMS removed on held-out trials, 0..1."""
        if sys0 <= 0:
            return 0.0
        left = max(cv[key].chi2 - N, 0.0) / sys0
        return float(np.clip(1.0 - math.sqrt(left), 0.0, 1.0))

    shrink = sys_shrink(chosen) if label == "explained" else 0.0
    shrink_rms = (
        float(np.clip(1.0 - rms_after / rms_before, 0.0, 1.0))
        if rms_before > 0 and label == "explained"
        else 0.0
    )

    def fold_mean(key: tuple[str, ...]) -> dict[str, dict[str, float]]:
        fps = cv[key].fold_params
        return {e: {k: float(np.mean([fp[e][k] for fp in fps])) for k in fps[0][e]} for e in key}

    chosen_fit = _fit(preps, chosen, surrogate, chain)

    def effect_row(key: tuple[str, ...]) -> dict[str, Any]:
        params = _fit_params(chosen_fit) if key == chosen else fold_mean(key)
        unc = _uncertainty(cv[key].fold_params)
        rms = _rms(cv[key].residuals)
        return {
            "name": " + ".join(key),
            "effects": list(key),
            "params": params if len(key) > 1 else params[key[0]],
            "uncertainty": unc if len(key) > 1 else unc[key[0]],
            "units": (
                {e: {p.name: p.unit for p in EFFECTS[e].params} for e in key}
                if len(key) > 1
                else {p.name: p.unit for p in EFFECTS[key[0]].params}
            ),
            "block": [EFFECTS[e].block for e in key] if len(key) > 1 else EFFECTS[key[0]].block,
            "params_from": "fit on all trials" if key == chosen else "mean of the CV folds",
            "heldout_rms_N": rms,
            "shrink": sys_shrink(key),
            "shrink_rms": float(np.clip(1 - rms / rms_before, 0, 1)) if rms_before > 0 else 0.0,
            "explained_share": share(key),
            "score": score(key),
        }

    rows = [effect_row(k) for k in singles]
    pair_out = [effect_row(k) for k in pair_rows]
    by_phase_after = _by_label(cv[chosen].residuals, labels, PHASES)
    by_phase_before = baseline["by_phase"]

    if baseline["by_block"] is not None:
        bb = baseline["by_block"]
        block = max(BLOCKS, key=lambda k: bb[k]["share"])
        block_source = "measured channels (force_jaw_N / gap_mm)" + (
            f"; {block_how}" if block_how else ""
        )
    elif label == "explained":
        block = EFFECTS[chosen[0]].block
        block_source = "block of the explaining effect"
    else:
        block = "unknown"
        block_source = "no jaw force or gap measured and no explaining effect"

    verdict = {
        "label": label,
        "effects": effects_out,
        "heldout_rms_before_N": rms_before,
        "heldout_rms_after_N": rms_after,
        "shrink": shrink,
        "shrink_rms": shrink_rms,
        "confidence": float(np.clip(conf, 0.0, 1.0)),
        "explained_share": e_share if label != "none" else 0.0,
        "best_candidate": list(chosen),
        "by_phase_before": {k: v["rms_N"] for k, v in by_phase_before.items()},
        "by_phase_after": {k: v["rms_N"] for k, v in by_phase_after.items()},
        "message": msg,
    }
    if label == "explained":
        aug_effects = [
            {
                "name": e,
                "params": _fit_params(chosen_fit)[e],
                "uncertainty": _uncertainty(cv[chosen].fold_params)[e],
                "units": {p.name: p.unit for p in EFFECTS[e].params},
            }
            for e in chosen
        ]
    else:
        aug_effects = []
    augmented = {
        "format": FORMAT_AUGMENTED,
        "format_version": FORMAT_VERSION,
        "baseline": "static derived chain + surrogate (grasprom.diagnosis)",
        "chain": {f: getattr(chain, f) for f in chain.__dataclass_fields__ if f != "_c"},
        "surrogate": {"source": surrogate.source, "fe_hash": surrogate.fe_hash},
        "effects": aug_effects,
        "verdict": label,
        "heldout_rms_before_N": rms_before,
        "heldout_rms_after_N": rms_after if label == "explained" else rms_before,
    }
    report = {
        "format": FORMAT_REPORT,
        "format_version": FORMAT_VERSION,
        "trials": [
            {
                "file": p.trial.name,
                "trial_id": p.trial.trial_id,
                "thickness_mm": p.thickness,
                "material": p.material,
                "duration_s": float(p.raw_t[-1] - p.raw_t[0]),
                "n_samples": int(p.raw_t.size),
                "n_analysis": int(p.t.size),
                "noise_N": p.noise_N,
                "closing_speed_deg_per_s": c["closing_speed_deg_per_s"],
                "has_force_jaw": p.trial.force_jaw_N is not None,
                "has_gap": p.trial.gap_mm is not None,
            }
            for p, c in zip(preps, conds)
        ],
        "baseline": baseline,
        "where": {"phase": where_phase, "block": block, "block_source": block_source},
        "effects": rows,
        "pairs": pair_out,
        "verdict": verdict,
        "warnings": warn_list,
        "settings": {
            "analysis_rate_hz": rate_hz,
            "significant_ratio": SIGNIFICANT_RHO,
            "explained_share": EXPLAINED_SHARE,
            "pair_gain": PAIR_GAIN,
            "cross_validation": "leave-one-trial-out" if len(preps) <= 6 else "6 trial folds",
        },
    }
    report = _jsonable(report)
    aug_pred = (
        [_predict(p, chosen_fit, surrogate, chain) for p in preps]
        if label == "explained"
        else [p.F0 for p in preps]
    )
    return Diagnosis(report, _jsonable(augmented), list(preps), [p.F0 for p in preps], aug_pred)


def _jsonable(o: Any) -> Any:
    if isinstance(o, dict):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [_jsonable(v) for v in o]
    if isinstance(o, np.generic):
        o = o.item()
    if isinstance(o, float) and not math.isfinite(o):
        return None
    return o


# =============================================================================== augmented model
@dataclass
class AugmentedModel:
    """The baseline chain plus fitted effects (loaded from the augmented-model JSON).

    Parameters
    ----------
    effects : dict
        Effect name (:data:`EFFECTS`) -> parameter name -> reported value (units of
        :attr:`ParamSpec.unit`).
    chain : kinematics.ChainParams
        Instrument chain the effects were fitted with.
    meta : dict
        The other keys of the file (verdict, surrogate, held-out RMS...).
    """

    effects: dict[str, dict[str, float]]
    chain: kin.ChainParams
    meta: dict[str, Any] = field(default_factory=dict)

    def handle_force_N(
        self,
        time_s: FloatArray,
        theta_deg: FloatArray,
        thickness_mm: float,
        material: str,
        surrogate: Surrogate,
    ) -> FloatArray:
        """Augmented-model handle force along an angle trajectory (static chain, vectorised).

        The diagnosis' own model (:func:`_evaluate` / :func:`_combine`), measurement effects
        included; independent of the controller step.

        Parameters
        ----------
        time_s : ndarray
            Sample times, s (strictly increasing).
        theta_deg : ndarray
            Measured handle angle, deg.
        thickness_mm : float
            Nominal wall thickness, mm.
        material : str
        surrogate : Surrogate

        Returns
        -------
        ndarray
            Handle force, N (return spring included).
        """
        prep = prepare_arrays(time_s, theta_deg, thickness_mm, material, self.chain)
        names = [e for e in _ORDER if e in self.effects]
        nl = [self.effects[e][p.name] - p.offset for e, p in _nl_params(names)]
        coef = np.array([self.effects[e][p.name] - p.offset for e, p in _columns(names)])
        f0, phi, tis = _evaluate(prep, names, nl, surrogate, self.chain)
        return _combine(f0, phi, tis, coef, _visco_index(names))


def save_augmented(augmented: dict[str, Any], path: str | Path) -> Path:
    """Write the augmented-model dict (from :class:`Diagnosis`) as JSON."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(augmented, indent=2))
    return p


def load_augmented(path: str | Path) -> AugmentedModel:
    """Load an augmented-model JSON written by ``grasprom diagnose``.

    Raises
    ------
    ValueError
        Wrong format or version, unknown effect or parameter (naming the file).
    """
    p = Path(path)
    try:
        d = json.loads(p.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ValueError(f"{p}: cannot read augmented model ({e})") from None
    if not isinstance(d, dict):
        raise ValueError(f"{p}: not a {FORMAT_AUGMENTED} file (expected a JSON object)")
    if d.get("format") != FORMAT_AUGMENTED or d.get("format_version") != FORMAT_VERSION:
        raise ValueError(
            f"{p}: not a {FORMAT_AUGMENTED} v{FORMAT_VERSION} file "
            f"(format={d.get('format')!r}, format_version={d.get('format_version')!r})"
        )
    effects: dict[str, dict[str, float]] = {}
    for e in d.get("effects", []):
        name = e.get("name")
        if name not in EFFECTS:
            raise ValueError(f"{p}: unknown effect {name!r}")
        want = {q.name for q in EFFECTS[name].params}
        got = set(e.get("params", {}))
        if want != got:
            raise ValueError(
                f"{p}: effect {name!r} needs parameters {sorted(want)}, got {sorted(got)}"
            )
        effects[name] = {k: float(v) for k, v in e["params"].items()}
    try:
        chain = kin.ChainParams(**d.get("chain", {}))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{p}: chain: {exc}") from None
    return AugmentedModel(effects, chain, {k: v for k, v in d.items() if k != "effects"})


RENDERED_EFFECTS = (
    "tissue_viscoelasticity",
    "mechanism_friction",
    "backlash",
    "jaw_compliance",
    "thickness_error",
    "tissue_stiffness_scale",
)
"""Effects of the instrument the controller renders (:func:`controller_params_from_augmented`)."""

MEASUREMENT_EFFECTS = ("sensor_offset_gain", "latency")
"""Effects of the measurement (force sensor, time base): never rendered by the controller."""


def controller_params_from_augmented(
    params: ControllerParams,
    model: AugmentedModel,
    surrogate: Surrogate | None = None,
) -> tuple[ControllerParams, dict[str, Any]]:
    """Controller parameters that render the instrument effects of an augmented model.

    The augmented model of ``grasprom diagnose`` describes the real instrument; the controller
    renders its instrument effects, so the diagnosis improves the controller (``grasprom
    simulate --augmented``, ``grasprom tune --augmented`` and the exports of the tuned
    parameters):

    ==========================  ===============================================================
    effect                      controller parameter (see :class:`ControllerParams`)
    ==========================  ===============================================================
    thickness_error             ``thickness_mm`` += ``offset_mm`` (clamped into the surrogate's
                                range when ``surrogate`` is given, as the diagnosis does)
    tissue_stiffness_scale      ``tissue_scale`` = ``scale``
    jaw_compliance              ``jaw_compliance_mm_per_N`` = ``compliance_mm_per_N``
    backlash                    ``backlash_deg`` = ``play_deg``
    mechanism_friction          ``friction_coulomb_N``, ``friction_load_coefficient``,
                                ``friction_viscous_N_s_per_mm``
    tissue_viscoelasticity      ``prony_g`` / ``prony_tau_s``: the non-zero ``g_i`` at
                                :data:`PRONY_TAUS_S`
    sensor_offset_gain          not rendered (a property of the force sensor): returned in
                                ``measurement`` (``offset_N``, ``gain``)
    latency                     not rendered (a delay of the measurement): ``measurement``
                                (``delay_s``)
    ==========================  ===============================================================

    The model's chain replaces ``params.chain`` (``params.spring_k_N_per_mm`` is kept).  Fields of
    effects absent from the model are left as they are.  Values outside the controller's bounds
    (a negative friction or Prony coefficient, a non-positive scale) are clipped to the bound
    (a non-positive scale: left at 1) with a warning.

    Parameters
    ----------
    params : ControllerParams
        Parameters without the augmentation (``thickness_mm`` the nominal wall thickness, mm).
    model : AugmentedModel
    surrogate : Surrogate, optional
        For the thickness range of ``params.material``.

    Returns
    -------
    ControllerParams
        With the rendered effects.
    dict
        ``rendered`` and ``measurement_only`` (effect names), ``measurement`` (``offset_N`` N,
        ``gain`` 1, ``delay_s`` s; 0, 1, 0 when absent: apply them with
        :func:`measured_handle_force_N`), ``warnings`` (list of str).
    """
    from dataclasses import replace

    eff = model.effects
    warn: list[str] = []
    if (
        params.tissue_scale != 1.0
        or params.jaw_compliance_mm_per_N > 0
        or params.backlash_deg > 0
        or params.friction_rendered
        or params.prony_g
    ):
        warn.append(
            "the controller parameters already render instrument effects (an earlier "
            "--augmented?): the model's replace them, and a thickness offset is added again; "
            "start from the un-augmented parameters"
        )

    def nonneg(effect: str, key: str) -> float:
        v = float(eff[effect][key])
        if not (math.isfinite(v) and v >= 0):
            warn.append(f"{effect}.{key} = {v!r} is outside the controller's bound >= 0: set to 0")
            return 0.0
        return v

    new: dict[str, Any] = {"chain": model.chain}
    if model.chain.spring_k_N_per_mm != params.spring_k_N_per_mm:
        warn.append(
            f"the model was fitted with a return spring of {model.chain.spring_k_N_per_mm:g} "
            f"N/mm; the controller's {params.spring_k_N_per_mm:g} N/mm is kept"
        )
    if "thickness_error" in eff:
        t = params.thickness_mm + float(eff["thickness_error"]["offset_mm"])
        if surrogate is not None:
            lo, hi = surrogate.thickness_range(params.material)
            tc = min(max(t, lo), hi)
            if tc != t:
                warn.append(
                    f"thickness {params.thickness_mm:g} + offset = {t:.4g} mm clamped into the "
                    f"surrogate's range [{lo:g}, {hi:g}] mm"
                )
            t = tc
        new["thickness_mm"] = t
    if "tissue_stiffness_scale" in eff:
        sc = float(eff["tissue_stiffness_scale"]["scale"])
        if not (math.isfinite(sc) and sc > 0):
            warn.append(f"tissue_stiffness_scale.scale = {sc!r} is not > 0: left at 1")
            sc = 1.0
        new["tissue_scale"] = sc
    if "jaw_compliance" in eff:
        new["jaw_compliance_mm_per_N"] = nonneg("jaw_compliance", "compliance_mm_per_N")
    if "backlash" in eff:
        new["backlash_deg"] = nonneg("backlash", "play_deg")
    if "mechanism_friction" in eff:
        new["friction_coulomb_N"] = nonneg("mechanism_friction", "coulomb_N")
        new["friction_load_coefficient"] = nonneg("mechanism_friction", "load_coefficient")
        new["friction_viscous_N_s_per_mm"] = nonneg("mechanism_friction", "viscous_N_s_per_mm")
    if "tissue_viscoelasticity" in eff:
        gs, taus = [], []
        for spec, tau in zip(EFFECTS["tissue_viscoelasticity"].params, PRONY_TAUS_S):
            g = nonneg("tissue_viscoelasticity", spec.name)
            if g > 0:
                gs.append(g)
                taus.append(float(tau))
        assert len(gs) <= MAX_PRONY_TERMS
        new["prony_g"] = tuple(gs)
        new["prony_tau_s"] = tuple(taus)
    measurement = {"offset_N": 0.0, "gain": 1.0, "delay_s": 0.0}
    if "sensor_offset_gain" in eff:
        measurement["offset_N"] = float(eff["sensor_offset_gain"]["offset_N"])
        measurement["gain"] = float(eff["sensor_offset_gain"]["gain"])
    if "latency" in eff:
        measurement["delay_s"] = nonneg("latency", "delay_s")
    info = {
        "rendered": [e for e in _ORDER if e in eff and e in RENDERED_EFFECTS],
        "measurement_only": [e for e in _ORDER if e in eff and e in MEASUREMENT_EFFECTS],
        "measurement": measurement,
        "warnings": warn,
    }
    return replace(params, **new), info


def measured_handle_force_N(
    time_s: FloatArray, force_handle_N: FloatArray, measurement: dict[str, float]
) -> FloatArray:
    """What the force sensor of the augmented model would read: offset, gain and latency.

    ``offset_N + gain F(t - delay_s)``, ``F`` interpolated linearly in time and held at its first
    value before the first sample.

    Parameters
    ----------
    time_s : ndarray
        Sample times, s (increasing).
    force_handle_N : ndarray
        Handle force, N.
    measurement : dict
        ``offset_N`` (N), ``gain`` (1), ``delay_s`` (s), as returned by
        :func:`controller_params_from_augmented`.

    Returns
    -------
    ndarray
        Measured handle force, N.
    """
    t = np.asarray(time_s, dtype=float)
    f = np.asarray(force_handle_N, dtype=float)
    d = float(measurement.get("delay_s", 0.0))
    if d > 0:
        f = np.interp(t - d, t, f)
    return float(measurement.get("offset_N", 0.0)) + float(measurement.get("gain", 1.0)) * f


# =============================================================================== output
def format_summary(report: dict[str, Any]) -> str:
    """Readable summary of a diagnosis report."""
    b = report["baseline"]
    v = report["verdict"]
    w = report["where"]
    lines = [
        f"trials: {len(report['trials'])}, analysis samples: {b['n_samples']}",
        f"baseline RMS {b['rms_N']:.3f} N (bias {b['bias_N']:+.3f} N), noise {b['noise_N']:.3f} N, "
        f"systematic ratio {b['systematic_ratio']:.3g} -> "
        f"{'significant' if b['significant'] else 'within noise'}",
        "",
        f"{'phase':<12}{'rms N':>9}{'bias N':>9}{'share':>8}{'n':>7}",
    ]
    for k in PHASES:
        s = b["by_phase"][k]
        if s["n"]:
            lines.append(f"{k:<12}{s['rms_N']:9.3f}{s['bias_N']:+9.3f}{s['share']:8.2f}{s['n']:7d}")
    if b.get("by_block"):
        lines.append("")
        for k, s in b["by_block"].items():
            lines.append(f"block {k:<10} rms {s['rms_N']:.3f} N  share {s['share']:.2f}")
    lines += ["", f"where: phase {w['phase']}, block {w['block']} ({w['block_source']})", ""]
    lines.append(f"{'candidate':<42}{'held-out rms N':>15}{'shrink':>8}{'score':>8}")
    for r in report["effects"] + report["pairs"]:
        lines.append(
            f"{r['name']:<42}{r['heldout_rms_N']:15.3f}{r['shrink']:8.2f}{r['score']:8.2f}"
        )
    lines += [
        "",
        f"VERDICT: {v['label']}"
        + (f" ({', '.join(v['effects'])})" if v["effects"] else "")
        + f", confidence {v['confidence']:.2f}",
        f"  held-out RMS {v['heldout_rms_before_N']:.3f} N -> {v['heldout_rms_after_N']:.3f} N "
        f"(shrink {100 * v['shrink']:.0f} %)",
        f"  {v['message']}",
    ]
    if v["label"] == "explained":
        for r in report["effects"] + report["pairs"]:
            if r["effects"] == v["effects"]:
                ps = r["params"] if len(v["effects"]) > 1 else {v["effects"][0]: r["params"]}
                us = (
                    r["uncertainty"]
                    if len(v["effects"]) > 1
                    else {v["effects"][0]: r["uncertainty"]}
                )
                un = r["units"] if len(v["effects"]) > 1 else {v["effects"][0]: r["units"]}
                for e in ps:
                    for k, val in ps[e].items():
                        u = us[e].get(k)
                        lines.append(
                            f"  {e}.{k} = {val:.4g} +- {u if u is None else format(u, '.2g')} "
                            f"{un[e][k]}"
                        )
    for wmsg in report["warnings"]:
        lines.append(f"warning: {wmsg}")
    return "\n".join(lines)


def write_plots(diag: Diagnosis, out_dir: str | Path) -> list[Path]:
    """Measured vs baseline vs augmented per trial, and residual RMS by phase (PNG)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, (p, fb, fa) in enumerate(zip(diag.preps, diag.baseline_pred, diag.augmented_pred)):
        fig = Figure(figsize=(8, 4.5))
        FigureCanvasAgg(fig)
        ax = fig.add_subplot(2, 1, 1)
        ax.plot(p.t, p.F, "k.", ms=1.5, label="measured")
        ax.plot(p.t, fb, "C0-", lw=1, label="baseline")
        ax.plot(p.t, fa, "C3-", lw=1, label="augmented")
        ax.set_ylabel("handle force (N)")
        ax.set_title(f"{Path(p.trial.name).name}: t = {p.thickness:g} mm, {p.material}")
        ax.legend(fontsize=7)
        ax2 = fig.add_subplot(2, 1, 2, sharex=ax)
        ax2.plot(p.t, p.F - fb, "C0-", lw=0.8, label="measured - baseline")
        ax2.plot(p.t, p.F - fa, "C3-", lw=0.8, label="measured - augmented")
        for k in range(1, len(PHASES)):
            m = p.phase == k
            if np.any(m):
                ax2.fill_between(
                    p.t,
                    0,
                    1,
                    where=m,
                    color=f"C{k + 3}",
                    alpha=0.15,
                    transform=ax2.get_xaxis_transform(),
                    label=PHASES[k],
                )
        ax2.set_xlabel("time (s)")
        ax2.set_ylabel("residual (N)")
        ax2.legend(fontsize=6, ncol=3)
        fig.tight_layout()
        path = out / f"trial_{i + 1:02d}.png"
        fig.savefig(path, dpi=100)
        paths.append(path)
    v = diag.report["verdict"]
    fig = Figure(figsize=(6, 3.5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    x = np.arange(len(PHASES))
    before = [v["by_phase_before"][k] or 0.0 for k in PHASES]
    after = [v["by_phase_after"][k] or 0.0 for k in PHASES]
    ax.bar(x - 0.2, before, 0.4, label="baseline")
    ax.bar(x + 0.2, after, 0.4, label="augmented (held-out)")
    ax.axhline(diag.report["baseline"]["noise_N"], color="k", ls=":", lw=1, label="noise")
    ax.set_xticks(x, PHASES)
    ax.set_ylabel("residual RMS (N)")
    ax.set_title(f"verdict: {v['label']} {', '.join(v['effects'])}")
    ax.legend(fontsize=7)
    fig.tight_layout()
    path = out / "residual_by_phase.png"
    fig.savefig(path, dpi=100)
    paths.append(path)
    return paths


def write_outputs(diag: Diagnosis, out_dir: str | Path, plots: bool = True) -> dict[str, Path]:
    """Write ``report.json``, ``augmented_model.json`` and (optionally) the plots."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rep = dict(diag.report)
    rep["augmented_model"] = "augmented_model.json"
    (out / "report.json").write_text(json.dumps(rep, indent=2))
    paths = {"report": out / "report.json"}
    paths["augmented"] = save_augmented(diag.augmented, out / "augmented_model.json")
    if plots:
        for p in write_plots(diag, out):
            paths[p.stem] = p
    return paths


def main_diagnose(argv: Sequence[str] | None = None) -> int:
    """``grasprom diagnose TRIAL.csv... --out DIR [--surrogate F | --fe DIR] [--controller F]``.

    Returns
    -------
    int
        Exit code: 0 ok, 2 bad input (message naming file/row/column on stderr).
    """
    p = argparse.ArgumentParser(
        prog="grasprom diagnose",
        description="Diagnose the sim-to-real gap of measured grasp trials: where it lies, "
        "which unmodelled effect causes it, how far it shrinks once added.",
    )
    p.add_argument("trials", nargs="+", metavar="TRIAL.csv", help="trial CSVs (sidecar .json)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--surrogate", default=None, metavar="FILE", help="surrogate JSON")
    src.add_argument("--fe", default=None, metavar="DIR", help="FE sweep (default shipped)")
    p.add_argument("--controller", default=None, metavar="FILE", help="controller JSON (chain)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    args = p.parse_args(argv)
    from grasprom.surrogate import load_surrogate

    try:
        if args.controller:
            from grasprom.control import load_params

            chain = load_params(args.controller).chain_params
        else:
            chain = kin.ChainParams()
        surrogate = load_surrogate(args.surrogate, args.fe)
        trials = [load_trial(t, chain, surrogate) for t in args.trials]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            diag = diagnose(trials, surrogate, chain)
    except (OSError, ValueError) as exc:
        print(f"grasprom diagnose: {exc}", file=sys.stderr)
        return 2
    write_outputs(diag, args.out, plots=not args.no_plots)
    print(format_summary(diag.report))
    print(f"\nwrote {Path(args.out) / 'report.json'} and {Path(args.out) / 'augmented_model.json'}")
    return 0
