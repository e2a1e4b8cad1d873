"""A trial on the analysis grid: subsampling, kinematic states (finger speed, direction of the
last motion), the baseline model force, the per-sample error model and the phase labels.

Analysis grid
    Each trial is subsampled (not averaged, so the non-linear model is not biased by averaging)
    to about :data:`ANALYSIS_RATE_HZ`; the sensor noise ``sigma`` (N) is estimated from the raw
    handle force by the median absolute second difference, the encoder quantum ``q`` (deg) from the
    smallest angle step, and every sample gets the standard deviation
    ``s_i^2 = sigma^2 + (dFi/dtheta q)^2 / 12 + (0.01 Fi)^2`` (sensor noise, angle quantisation
    through the model slope, 1 % surrogate uncertainty).

Phases (per sample, from the baseline contact state and the measured angle velocity)
    ``approach`` (no contact), ``bending`` (closing in contact, gap above the wall-contact gap),
    ``compaction`` (closing with the inner walls meeting), ``hold`` (in contact, |dtheta/dt| <
    0.5 deg/s), ``release`` (opening in contact).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from grasprom.chain import kinematics as kin
from grasprom.gap.likelihood import interval_z, null_chi2
from grasprom.gap.signals import encoder_quantum, noise_sigma, reconstruct_angle
from grasprom.gap.trials import FloatArray, Trial
from grasprom.surrogate import Surrogate

PHASES = ("approach", "bending", "compaction", "hold", "release")
DIRECTIONS = ("closing", "opening", "still")

ANALYSIS_RATE_HZ = 100.0
"""Target rate of the analysis grid (Hz)."""
STILL_DEG_PER_S = 0.5
"""|dtheta/dt| below which the handle counts as still (deg/s)."""
SURROGATE_REL_UNCERTAINTY = 0.01


@dataclass
class PreparedTrial:
    """A trial on the analysis grid, with everything the models need."""

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
    quantum_eff_deg: FloatArray | float = 0.0  # per-sample angle uncertainty (deg), see below
    cache: dict = field(default_factory=dict)
    # the interval likelihood (:mod:`grasprom.gap.likelihood`): half the level (deg) where the
    # angle rests inside an encoder level (0 where it is known between the counts), on the grid
    # and at the raw samples; the sigma without the quantum at those samples (N); the baseline's
    # z and the expected z^2 of a correct model per sample (1)
    rest_halfwidth_deg: FloatArray | None = None
    raw_rest_halfwidth_deg: FloatArray | None = None
    sigma_fit: FloatArray | None = None
    z0: FloatArray | None = None
    null: FloatArray | None = None

    def fit_sigma(self) -> FloatArray:
        """The sigma of the fit (N): :attr:`sigma_fit`, or :attr:`sigma` without an interval."""
        return self.sigma if self.sigma_fit is None else self.sigma_fit


def _contact_gap(surrogate: Surrogate, thickness: float, material: str) -> float:
    cs = surrogate.curves(material)
    return float(np.interp(thickness, [c.thickness_mm for c in cs], [c.contact_gap_mm for c in cs]))


def kinematic_states(
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


def _add_baseline(
    p: PreparedTrial, surrogate: Surrogate, chain: kin.ChainParams
) -> tuple[FloatArray, FloatArray]:
    """Set the baseline force ``F0`` (N) and the per-sample sigma (N).

    Returns the kinematic gap (mm) and the surrogate force there (N).
    """
    th = p.theta
    g = np.asarray(kin.gap_mm(th, chain))
    fe = np.asarray(surrogate.force(g, p.thickness, p.material))
    kt = np.asarray(surrogate.stiffness(g, p.thickness, p.material))
    f0 = np.asarray(kin.handle_force_N(fe, th, chain))
    slope = np.abs(np.asarray(kin.dhandle_force_dtheta_N_per_rad(fe, kt, th, chain))) * (
        math.pi / 180.0
    )
    p.F0 = f0
    sig = p.noise_N if math.isfinite(p.noise_N) and p.noise_N > 0 else 0.01
    base2 = sig**2 + (SURROGATE_REL_UNCERTAINTY * f0) ** 2 + 1e-8
    p.sigma = np.sqrt(base2 + (slope * p.quantum_eff_deg) ** 2 / 12.0)
    if p.rest_halfwidth_deg is not None:
        _add_interval(p, surrogate, chain, base2, slope)
    return g, fe


def _add_interval(
    p: PreparedTrial, surrogate: Surrogate, chain: kin.ChainParams, base2: FloatArray,
    slope: FloatArray,
) -> None:  # fmt: skip
    """The interval likelihood's sigma, the baseline's ``z`` and the expected null ``z^2``.

    At the samples resting in a level the quantum is the interval (the baseline evaluated at
    both ends of the level), elsewhere the Gaussian angle term of :attr:`sigma` stays.
    """
    hw = p.rest_halfwidth_deg
    rest = hw > 0
    q_moving = np.where(rest, 0.0, p.quantum_eff_deg)
    p.sigma_fit = np.sqrt(base2 + (slope * q_moving) ** 2 / 12.0)
    ends = []
    lo, hi = kin.theta_range_deg(chain)
    for side in (-1.0, 1.0):
        th = np.clip(p.theta + side * hw, lo, hi)
        fe = np.asarray(surrogate.force(np.asarray(kin.gap_mm(th, chain)), p.thickness, p.material))
        ends.append(np.asarray(kin.handle_force_N(fe, th, chain), dtype=float))
    p.z0 = interval_z(p.F, p.F0, (ends[0], ends[1]), p.sigma_fit)
    p.null = null_chi2(np.abs(ends[1] - ends[0]), p.sigma_fit)


def _add_labels(
    p: PreparedTrial, g: FloatArray, fe: FloatArray, surrogate: Surrogate, chain: kin.ChainParams
) -> None:
    """Set the phase (index of :data:`PHASES`) and direction (of :data:`DIRECTIONS`) labels.

    ``g`` is the kinematic gap (mm), ``fe`` the surrogate force there (N).
    """
    th = p.theta
    contact = fe > 1e-9
    g_c = _contact_gap(surrogate, p.thickness, p.material)
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


def prepare_trial(
    trial: Trial,
    surrogate: Surrogate,
    chain: kin.ChainParams,
    rate_hz: float = ANALYSIS_RATE_HZ,
) -> PreparedTrial:
    """A measured trial on the analysis grid (about ``rate_hz``, Hz) with baseline and labels.

    Parameters
    ----------
    trial : Trial
    surrogate : Surrogate
    chain : kinematics.ChainParams
    rate_hz : float
        Target rate of the analysis grid (Hz).

    Returns
    -------
    PreparedTrial
    """
    raw_t = trial.time_s
    quantum = encoder_quantum(trial.theta_deg)
    # the angle between the counts and the error of its interpolation (deg)
    raw_th, moving, interp_err = reconstruct_angle(raw_t, trial.theta_deg)
    dt = float(np.median(np.diff(raw_t)))
    stride = max(int(round(1.0 / (rate_hz * dt))), 1)
    idx = np.arange(0, raw_t.size, stride)
    v_mm, s = kinematic_states(raw_t, raw_th, idx, chain)
    p = PreparedTrial(
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
    p.noise_N = noise_sigma(trial.force_handle_N)
    p.quantum_deg = quantum
    # angle uncertainty per sample (the width of a uniform error, deg): the quantum at rest;
    # where the angle was interpolated, the crossing-time uncertainty (one sample of motion, at
    # most the quantum) and the interpolation error (a standard deviation: x sqrt(12))
    vdeg = np.abs(v_mm) / (math.radians(1.0) * chain.L3_mm)
    crossing = np.minimum(quantum, vdeg * dt)
    p.quantum_eff_deg = np.where(
        moving[idx], np.sqrt(crossing**2 + 12.0 * interp_err[idx] ** 2), quantum
    )
    p.raw_rest_halfwidth_deg = np.where(moving, 0.0, 0.5 * quantum)
    p.rest_halfwidth_deg = p.raw_rest_halfwidth_deg[idx]
    g, fe = _add_baseline(p, surrogate, chain)
    _add_labels(p, g, fe, surrogate, chain)
    return p


def prepare_arrays(
    time_s: FloatArray,
    theta_deg: FloatArray,
    thickness_mm: float,
    material: str,
    chain: kin.ChainParams,
) -> PreparedTrial:
    """Model-only preparation of an angle trajectory (for :meth:`AugmentedModel.handle_force_N`)."""
    t = np.asarray(time_s, dtype=float)
    th = np.asarray(theta_deg, dtype=float)
    idx = np.arange(t.size)
    v_mm, s = kinematic_states(t, th, idx, chain)
    return PreparedTrial(None, t, th, t, th, v_mm, s, float(thickness_mm), str(material))
