r"""Device identification from free-motion trials: handle inertia, viscous damping and Coulomb
friction of the haptic device alone (no tissue, no hand), for ``grasprom tune --device``.

Model (at the handle pivot, SI units)

.. math::

    J \ddot\theta + b \dot\theta + f_c \,\mathrm{sgn}(\dot\theta) + \tau_0
        = \frac{L_3}{r} \tau_m

with the motor torque :math:`\tau_m` (N m, column ``torque_Nm``: the torque commanded to the
amplifier or measured), the cable ratio :math:`L_3 / r` (handle length over pulley radius, from
the chain and the controller parameters) and a constant torque :math:`\tau_0` (gravity of the
lever, cable preload; reported, not written).  The handle angle :math:`\theta` (``theta_deg``)
is interpolated onto a uniform grid at the trial's median rate (non-uniform time stamps), and
every term of the equation -- angle, motor torque and the friction's sign -- goes through the
same zero-phase low-pass (Butterworth, order 4, :data:`CUTOFF_HZ`) before the angle is
differentiated twice, so the filtered equation holds exactly for the linear terms (no bias from
filtering one side only) and the encoder's quantisation, white at the sampling rate, is averaged
out; samples within
:data:`END_MARGIN_DEG` of the end stops, slower than :data:`V_MIN_RAD_S` (sign of the friction
undefined) or within :data:`EDGE_S` of a trial's ends (filter transients) are left out.  The
four parameters are the least-squares solution over the remaining samples of all trials;
their standard uncertainties come from a moving-block bootstrap over the samples (blocks of
:data:`BLOCK_S`, :data:`N_BOOTSTRAP` replicates), which keeps the correlation of neighbouring
samples.  Units: s, rad, N m, kg m^2.
"""

from __future__ import annotations

import hashlib
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from grasprom.chain import kinematics as kin
from grasprom.control.device import DeviceParams, device_to_dict

__all__ = [
    "IDENTIFY_COLUMNS",
    "DeviceTrial",
    "Identification",
    "identify_device",
    "load_device_trial",
]

IDENTIFY_COLUMNS = ("time_s", "theta_deg", "torque_Nm")
"""Columns of a free-motion trial: time (s), handle angle (deg), motor torque (N m)."""
END_MARGIN_DEG = 0.5
"""Samples this close to an end stop (deg) are left out (the stop's force is not modelled)."""
V_MIN_RAD_S = 0.05
"""Samples slower than this (rad/s) are left out (the friction's sign is undefined)."""
EDGE_S = 0.05
"""Left out at both ends of a trial (s): the filter's edge transients."""
BLOCK_S = 0.2
"""Block length (s) of the moving-block bootstrap."""
N_BOOTSTRAP = 200
"""Bootstrap replicates of the uncertainty."""
REVERSAL_PERIODS = 0.5
"""Half-width of the neighbourhood of a reversal left out, in periods of the cut-off."""
CUTOFF_HZ = 30.0
"""Default low-pass cut-off (Hz): above the excitation (a hand or a test torque below ~10 Hz),
below the encoder quantisation noise that double differentiation amplifies."""
MIN_SAMPLES = 200
"""Fewest samples the fit needs after the exclusions."""


class IdentificationError(ValueError):
    """The trials cannot identify the device (too short, no motion, no reversal...)."""


@dataclass(frozen=True)
class DeviceTrial:
    """One free-motion trial (SI: s, rad, N m at the motor)."""

    name: str
    time_s: np.ndarray
    theta_rad: np.ndarray
    torque_Nm: np.ndarray
    sha256: str


@dataclass(frozen=True)
class Identification:
    """Result of :func:`identify_device`.

    Attributes
    ----------
    device : DeviceParams
        The base device with ``inertia_kg_m2``, ``damping_Nms_per_rad``, ``coulomb_Nm``
        replaced by the identified values.
    values, uncertainty : dict
        ``inertia_kg_m2``, ``damping_Nms_per_rad``, ``coulomb_Nm``, ``offset_Nm`` and their
        standard uncertainties (bootstrap, same units).
    rms_residual_Nm : float
        RMS of the equation residual at the pivot (N m).
    n_samples : int
        Samples used (after the exclusions).
    trials : list of dict
        File name and sha256 of each trial.
    """

    device: DeviceParams
    values: dict[str, float]
    uncertainty: dict[str, float]
    rms_residual_Nm: float
    n_samples: int
    trials: list[dict[str, str]]

    def to_dict(self) -> dict[str, Any]:
        """The device file (``--device``) with an ``identification`` section."""
        d = device_to_dict(self.device)
        d["identification"] = {
            "method": "least squares on the low-passed equation of motion, moving-block bootstrap",
            "values": self.values,
            "uncertainty": self.uncertainty,
            "rms_residual_Nm": self.rms_residual_Nm,
            "n_samples": self.n_samples,
            "trials": self.trials,
        }
        return d

    def format(self) -> str:
        """A readable table of the identified parameters."""
        rows = [f"{'parameter':<22}{'value':>12}{'+- 1 sigma':>12}  unit"]
        units = {"inertia_kg_m2": "kg m^2", "damping_Nms_per_rad": "N m s/rad",
                 "coulomb_Nm": "N m", "offset_Nm": "N m"}  # fmt: skip
        for k, u in units.items():
            rows.append(f"{k:<22}{self.values[k]:12.4g}{self.uncertainty[k]:12.2g}  {u}")
        rows.append(f"residual RMS {self.rms_residual_Nm:.3g} N m over {self.n_samples} samples")
        return "\n".join(rows)


def load_device_trial(path: str | Path) -> DeviceTrial:
    """Read and check a free-motion trial CSV (:data:`IDENTIFY_COLUMNS`).

    Raises
    ------
    IdentificationError
        Naming the file, the column and the row.
    """
    import pandas as pd

    p = Path(path)
    try:
        raw = p.read_bytes()  # read once: the table and its sha256
        df = pd.read_csv(io.BytesIO(raw))
    except (OSError, UnicodeDecodeError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise IdentificationError(f"{p}: cannot read the trial ({exc})") from None
    missing = [c for c in IDENTIFY_COLUMNS if c not in df.columns]
    if missing:
        raise IdentificationError(
            f"{p}: missing column(s) {', '.join(missing)} (need {', '.join(IDENTIFY_COLUMNS)})"
        )
    cols = {}
    for c in IDENTIFY_COLUMNS:
        v = np.asarray(pd.to_numeric(df[c], errors="coerce"), dtype=float)
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            i = int(bad[0])
            raise IdentificationError(f"{p}: row {i + 1}, column {c!r}: not a finite number")
        cols[c] = v
    _check_trial(p, cols)
    return DeviceTrial(p.name, cols["time_s"], np.radians(cols["theta_deg"]), cols["torque_Nm"],
                       hashlib.sha256(raw).hexdigest())  # fmt: skip


def _check_trial(p: Path, cols: dict[str, np.ndarray]) -> None:
    """Time increasing and in seconds, angle in degrees, enough rows."""
    from grasprom.control.trajectory import check_theta_degrees, check_time_seconds

    t, th = cols["time_s"], cols["theta_deg"]
    if t.size < 50:
        raise IdentificationError(f"{p}: too short ({t.size} rows; at least 50)")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        raise IdentificationError(f"{p}: row {int(bad[0]) + 2}, column 'time_s': time must "
                                  "increase strictly")  # fmt: skip
    try:
        check_time_seconds(t, str(p))
        check_theta_degrees(th, str(p))
    except ValueError as exc:
        raise IdentificationError(str(exc)) from None


def _filtered(tr: DeviceTrial, cutoff_hz: float):
    """The trial on a uniform grid at its median rate, low-passed (zero-phase Butterworth,
    order 4, ``cutoff_hz``): time, angle (rad), velocity (rad/s), acceleration (rad/s^2),
    motor torque (N m) and the filter, to be applied alike to every term of the equation."""
    from scipy.signal import butter, sosfiltfilt

    dt = float(np.median(np.diff(tr.time_s)))
    t = np.arange(tr.time_s[0], tr.time_s[-1], dt)
    fs = 1.0 / dt
    if not cutoff_hz < 0.45 * fs:
        raise IdentificationError(
            f"{tr.name}: sampled at {fs:.4g} Hz, too slow for the {cutoff_hz:g} Hz filter "
            "(needs more than 2.2 x the cut-off)"
        )
    sos = butter(4, cutoff_hz, fs=fs, output="sos")

    def filt(x: np.ndarray) -> np.ndarray:
        return sosfiltfilt(sos, x)

    th = filt(np.interp(t, tr.time_s, tr.theta_rad))
    vel = np.gradient(th, dt)
    acc = np.gradient(vel, dt)
    tau = filt(np.interp(t, tr.time_s, tr.torque_Nm))
    return t, th, vel, acc, tau, filt


def _near_reversal(vel: np.ndarray, dt: float, cutoff_hz: float) -> np.ndarray:
    """Samples slower than :data:`V_MIN_RAD_S` or within :data:`REVERSAL_PERIODS` filter
    periods (``1 / cutoff_hz``) of one: the filter smears the friction's jump (and sticking)
    over that neighbourhood, where the filtered sign is not the filtered friction."""
    slow = (np.abs(vel) < V_MIN_RAD_S) | (np.sign(vel) != np.sign(np.roll(vel, 1)))
    w = max(int(round(REVERSAL_PERIODS / (cutoff_hz * dt))), 1)
    return np.convolve(slow.astype(float), np.ones(2 * w + 1), mode="same") > 0


def _regression(trials: Sequence[DeviceTrial], ratio: float, stops_rad: tuple[float, float],
                cutoff_hz: float):  # fmt: skip
    """Regressor rows [acc, vel, sgn(vel), 1] (each filtered alike), pivot torques, blocks."""
    rows, rhs, blocks = [], [], []
    lo, hi = stops_rad
    margin = math.radians(END_MARGIN_DEG)
    for k, tr in enumerate(trials):
        t, th, vel, acc, tau, filt = _filtered(tr, cutoff_hz)
        sgn = filt(np.sign(vel))  # the friction term through the same filter
        keep = ~_near_reversal(vel, t[1] - t[0], cutoff_hz)
        keep &= (t >= t[0] + EDGE_S) & (t <= t[-1] - EDGE_S)
        keep &= (th > lo + margin) & (th < hi - margin)
        rows.append(np.column_stack([acc, vel, sgn, np.ones_like(vel)])[keep])
        rhs.append(ratio * tau[keep])
        blocks.append(k * 1_000_000 + np.floor((t[keep] - t[0]) / BLOCK_S).astype(int))
    return np.vstack(rows), np.concatenate(rhs), np.concatenate(blocks)


def _bootstrap(a: np.ndarray, y: np.ndarray, blocks: np.ndarray, seed: int) -> np.ndarray:
    """Standard deviation of the solution over block-resampled replicates."""
    rng = np.random.default_rng(seed)
    ids = np.unique(blocks)
    members = [np.flatnonzero(blocks == b) for b in ids]
    sols = []
    for _ in range(N_BOOTSTRAP):
        pick = np.concatenate([members[i] for i in rng.integers(0, len(ids), len(ids))])
        sols.append(np.linalg.lstsq(a[pick], y[pick], rcond=None)[0])
    return np.std(np.array(sols), axis=0, ddof=1)


def identify_device(
    trials: Sequence[DeviceTrial],
    chain: kin.ChainParams | None = None,
    pulley_radius_mm: float = 10.0,
    base: DeviceParams | None = None,
    seed: int = 0,
    cutoff_hz: float | None = None,
) -> Identification:
    """Identify ``J``, ``b``, ``f_c`` (and ``tau_0``) of the device from free-motion trials.

    Parameters
    ----------
    trials : sequence of DeviceTrial
        :func:`load_device_trial` results (motor torque in N m, angle in rad).
    chain : kinematics.ChainParams, optional
        Handle length ``L3_mm`` and end stops (default geometry).
    pulley_radius_mm : float
        Motor pulley radius (mm): pivot torque = ``L3 / r`` x motor torque.
    base : DeviceParams, optional
        The other device parameters of the written file (default :class:`DeviceParams`).
    seed : int
        Seed of the bootstrap.
    cutoff_hz : float, optional
        Cut-off of the low-pass applied to every term (Hz; default :data:`CUTOFF_HZ`): above
        the excitation, below the encoder's quantisation noise.

    Returns
    -------
    Identification

    Raises
    ------
    IdentificationError
        Too few usable samples, or motion that cannot separate the parameters.
    """
    if not trials:
        raise IdentificationError("no trial given")
    chain = chain or kin.ChainParams()
    base = base or DeviceParams()
    ratio = chain.L3_mm / pulley_radius_mm
    stops = tuple(math.radians(x) for x in kin.theta_range_deg(chain))
    fc = CUTOFF_HZ if cutoff_hz is None else cutoff_hz
    a, y, blocks = _regression(trials, ratio, stops, fc)  # type: ignore[arg-type]
    if a.shape[0] < MIN_SAMPLES:
        raise IdentificationError(
            f"only {a.shape[0]} usable samples (moving faster than {V_MIN_RAD_S} rad/s, away "
            f"from the end stops); at least {MIN_SAMPLES}: record longer free-motion trials"
        )
    scale = np.maximum(np.abs(a).max(axis=0), 1e-12)
    if np.linalg.cond(a / scale) > 1e6 or np.all(a[:, 2] == a[0, 2]):
        raise IdentificationError(
            "the trials cannot separate inertia, damping and friction: move the handle both "
            "ways at varying speed (e.g. a multisine torque)"
        )
    sol = np.linalg.lstsq(a, y, rcond=None)[0]
    sd = _bootstrap(a, y, blocks, seed)
    names = ("inertia_kg_m2", "damping_Nms_per_rad", "coulomb_Nm", "offset_Nm")
    values = {n: float(v) for n, v in zip(names, sol)}
    if values["inertia_kg_m2"] <= 0 or values["damping_Nms_per_rad"] <= 0:
        raise IdentificationError(
            f"non-physical fit (J = {values['inertia_kg_m2']:.3g} kg m^2, b = "
            f"{values['damping_Nms_per_rad']:.3g} N m s/rad): check the torque sign and units"
        )
    device = replace(base, inertia_kg_m2=values["inertia_kg_m2"],
                     damping_Nms_per_rad=values["damping_Nms_per_rad"],
                     coulomb_Nm=max(values["coulomb_Nm"], 0.0))  # fmt: skip
    res = y - a @ sol
    return Identification(
        device,
        values,
        {n: float(v) for n, v in zip(names, sd)},
        float(math.sqrt(res @ res / res.size)),
        int(a.shape[0]),
        [{"file": tr.name, "sha256": tr.sha256} for tr in trials],
    )
