"""Stage 5, the co-simulated grasp: a hand squeezes the handle, whose motor is driven by the
FMI 2 FMU (fmpy), with the Python reference controller replayed on the same angles.

:func:`hand_force_N` is the hand's force profile, :func:`cosimulate` the run and
:func:`plot_cosim` its figure.
"""

from __future__ import annotations

import math
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from grasprom.control.trajectory import minimum_jerk
from grasprom.pipeline.result import CosimResult

if TYPE_CHECKING:
    from grasprom.control import ControllerParams, DeviceParams, HandParams, ImpedanceController
    from grasprom.surrogate import Surrogate

COLUMNS = ("time_s", "theta_deg", "torque_Nm", "force_tissue_N", "force_jaw_N",
           "force_handle_N", "hand_N")  # fmt: skip
"""Columns of :attr:`CosimResult.data` written by :func:`cosimulate`."""

FMU_OUTPUTS = ("torque", "force_tissue", "force_jaw", "force_handle")
"""FMU output variables read at every communication point (N m, N, N, N)."""


def hand_force_N(t: float, ramp: float, hold: float, release: float, peak: float) -> float:
    """Hand force at the grip, N: cosine ramp up, hold, cosine release, then zero.

    Parameters
    ----------
    t : float
        Time, s.
    ramp, hold, release : float
        Durations of the three phases, s.
    peak : float
        Hold force, N.

    Returns
    -------
    float
    """
    if t < ramp:
        return peak * 0.5 * (1 - math.cos(math.pi * t / ramp))
    if t < ramp + hold:
        return peak
    if t < ramp + hold + release:
        return peak * 0.5 * (1 + math.cos(math.pi * (t - ramp - hold) / release))
    return 0.0


@dataclass(frozen=True)
class Handle:
    """Rigid handle about its pivot, with the hand's mass and damping reflected to it.

    Attributes
    ----------
    grip_radius_m : float
        Grip radius ``L3`` of the chain, m.
    theta_closed_rad, theta_open_rad : float
        End stops, rad.
    inertia_kg_m2 : float
        Handle plus hand inertia about the pivot, kg m^2.
    damping_Nms_per_rad : float
        Handle plus hand viscous damping about the pivot, N m s/rad.
    """

    grip_radius_m: float
    theta_closed_rad: float
    theta_open_rad: float
    inertia_kg_m2: float
    damping_Nms_per_rad: float

    @classmethod
    def from_params(
        cls, params: ControllerParams, device: DeviceParams, hand: HandParams | None
    ) -> Handle:
        """Handle of the chain of ``params`` with ``device`` and, if given, the finger mass.

        Parameters
        ----------
        params : ControllerParams
            Its chain gives the grip radius (mm) and the end stops (deg).
        device : DeviceParams
            Handle inertia (kg m^2) and damping (N m s/rad).
        hand : HandParams or None
            The finger mass (kg) at the grip is reflected to the pivot (``J_h = m L3^2``); the
            finger's stiffness and damping act through :class:`OperatorGrip`.

        Returns
        -------
        Handle
        """
        chain = params.chain_params
        J, b = device.inertia_kg_m2, device.damping_Nms_per_rad
        if hand is not None:
            J = J + hand.at_pivot(chain.L3_mm)[0]
        return cls(
            grip_radius_m=chain.L3_mm * 1e-3,
            theta_closed_rad=math.radians(chain.theta_closed_deg),
            theta_open_rad=math.radians(chain.theta_open_deg),
            inertia_kg_m2=J,
            damping_Nms_per_rad=b,
        )

    def advance(
        self,
        theta: float,
        omega: float,
        f_handle: float,
        hand: Callable[[float, float, float], float],
        t: float,
        dt: float,
        substeps: int,
    ) -> tuple[float, float, float]:
        """``substeps`` semi-implicit Euler steps of ``dt`` s with the rendered force held.

        Parameters
        ----------
        theta, omega : float
            Handle angle (rad) and angular velocity (rad/s) at the start.
        f_handle : float
            Rendered handle force pushing the handle open, N (held: zero-order hold).
        hand : callable
            ``hand(t, theta, omega)``: the hand's force squeezing the grip, N.
        t : float
            Time at the start, s.
        dt : float
            Integration step, s.
        substeps : int
            Number of steps.

        Returns
        -------
        theta, omega, f_hand : float
            At the end: rad, rad/s (stopped at an end stop) and the last hand force (N).
        """
        L3, J, b = self.grip_radius_m, self.inertia_kg_m2, self.damping_Nms_per_rad
        th_lo, th_hi = self.theta_closed_rad, self.theta_open_rad
        f_hand = 0.0
        for i in range(substeps):
            f_hand = hand(t + i * dt, theta, omega)
            omega += (L3 * (f_handle - f_hand) - b * omega) / J * dt
            theta += omega * dt
            if theta < th_lo or theta > th_hi:  # end stops
                theta = min(max(theta, th_lo), th_hi)
                omega = 0.0
        return theta, omega, f_hand


@dataclass(frozen=True)
class OperatorGrip:
    """The surgeon's hand as a position source behind the finger impedance (Thevenin model).

    The hand intends a path ``theta*(t)`` of the handle (minimum jerk from the open stop to
    ``theta_intent_rad`` over the ramp, held, minimum jerk back to the open stop over the
    release) and pushes the grip through the finger stiffness and damping
    (:class:`~grasprom.control.HandParams`, reflected to the pivot):
    ``F_hand L3 = k_h (theta - theta*) + b_h (omega - omega*)``.  This is the classic
    operator model of haptics (Hogan's position-controlled arm impedance): unlike a force source,
    the handle cannot run away through the soft part of the stroke and slam into the tissue.
    The intended end angle is chosen so that the hold force is ``peak_hand_N``
    (:func:`operator_grip`).

    Attributes
    ----------
    stiffness_Nm_per_rad, damping_Nms_per_rad : float
        Finger stiffness and damping at the pivot, N m/rad and N m s/rad.
    grip_radius_m : float
        ``L3``, m.
    theta_open_rad, theta_intent_rad : float
        Start (open stop) and intended hold angle of the path, rad.
    ramp_s, hold_s, release_s : float
        Durations, s.
    """

    stiffness_Nm_per_rad: float
    damping_Nms_per_rad: float
    grip_radius_m: float
    theta_open_rad: float
    theta_intent_rad: float
    ramp_s: float
    hold_s: float
    release_s: float

    def intent(self, t: float) -> tuple[float, float]:
        """Intended angle (rad) and angular velocity (rad/s) at time ``t`` (s)."""
        span = self.theta_intent_rad - self.theta_open_rad
        if t < self.ramp_s + self.hold_s:
            s, ds = minimum_jerk(t / self.ramp_s)
            return self.theta_open_rad + span * s, span * ds / self.ramp_s
        s, ds = minimum_jerk((t - self.ramp_s - self.hold_s) / self.release_s)
        return self.theta_intent_rad - span * s, -span * ds / self.release_s

    def __call__(self, t: float, theta: float, omega: float) -> float:
        """Force of the hand squeezing the grip (N) at ``t`` (s), ``theta`` (rad), rad/s."""
        th_i, om_i = self.intent(t)
        tau = self.stiffness_Nm_per_rad * (theta - th_i) + self.damping_Nms_per_rad * (omega - om_i)
        return tau / self.grip_radius_m


def static_handle_force_N(ctl: ImpedanceController, theta: float) -> float:
    """Rendered handle force at rest at the angle ``theta`` (rad), N.

    ``ctl`` is reset to rest at ``theta`` (its tables, e.g. the clipped field, are kept).
    """
    ctl.reset(theta)
    return ctl.step(theta).force_handle_N


def hold_angle_rad(
    params: ControllerParams, surrogate: Surrogate, force_N: float, lo: float, hi: float
) -> float:
    """Handle angle (rad) in ``[lo, hi]`` where the rendered force at rest is ``force_N`` (N).

    Bisection (the rendered force grows as the handle closes); ``lo`` if it never gets there.
    One controller serves every evaluation.
    """
    from grasprom.control import ImpedanceController

    ctl = ImpedanceController(params, surrogate)
    if static_handle_force_N(ctl, lo) < force_N:
        return lo
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if static_handle_force_N(ctl, mid) > force_N:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def operator_grip(
    params: ControllerParams,
    surrogate: Surrogate,
    hand: HandParams,
    handle: Handle,
    peak_hand_N: float,
    profile: tuple[float, float, float, float],
) -> OperatorGrip:
    """The :class:`OperatorGrip` whose hold force is ``peak_hand_N`` (N).

    The hold angle ``theta_h`` is where the rendered force at rest equals ``peak_hand_N``;
    the intent lies beyond it by the finger compression ``peak_hand_N L3 / k_h``.
    """
    _J, b_h, k_h = hand.at_pivot(params.chain_params.L3_mm)
    if k_h <= 0.0:
        raise ValueError("the operator grip needs a finger stiffness > 0 (HandParams)")
    L3 = handle.grip_radius_m
    th_h = hold_angle_rad(
        params, surrogate, peak_hand_N, handle.theta_closed_rad, handle.theta_open_rad
    )
    ramp, hold, release, _rest = profile
    return OperatorGrip(k_h, b_h, L3, handle.theta_open_rad, th_h - peak_hand_N * L3 / k_h,
                        ramp, hold, release)  # fmt: skip


GRASP_PROFILE_S = (1.0, 2.0, 0.5, 1.0)
"""Durations (ramp, hold, release, rest) of the co-simulated grasp, s."""

FAST_REST_S = 0.2
"""Rest after the release with ``--fast``, s: the only phase ``--fast`` shortens (a shorter
ramp and hold had changed the max jaw force from 0.98 to 1.04 N and the min handle angle from
3.69 to 3.54 deg; the handle is back at its open stop 0.1 s before the end of the release, so
the rest changes none of the reported figures)."""


def grasp_profile(fast: bool) -> tuple[float, float, float, float]:
    """Durations (ramp, hold, release, rest) of the grasp, s.

    ``fast`` shortens only the rest after the release (:data:`FAST_REST_S`): the ramp, hold
    and release, hence every figure the build reports, are those of the full run.
    """
    ramp, hold, release, rest = GRASP_PROFILE_S
    return (ramp, hold, release, FAST_REST_S if fast else rest)


OVERSHOOT_TARGET = 0.15
"""Largest overshoot of the co-simulated grasp the report calls settled, 1."""


def grasp_settling(cs: CosimResult, fast: bool) -> dict[str, Any]:
    """Overshoot of the rendered handle force of a co-simulated grasp over its settled hold.

    ``settled`` is the mean handle force over the last quarter of the hold, ``peak`` the
    largest from the start to the end of the hold; ``overshoot = peak / settled - 1``.  The
    ringing amplitude is the standard deviation of the handle force over the last quarter.

    Parameters
    ----------
    cs : CosimResult
    fast : bool
        The profile of :func:`grasp_profile` the run used.

    Returns
    -------
    dict
        ``peak_N``, ``settled_N``, ``overshoot`` (1), ``ringing_rms_N``, ``target``,
        ``meets_target``.
    """
    ramp, hold, _release, _rest = grasp_profile(fast)
    t, f = cs.col("time_s"), cs.col("force_handle_N")
    end = ramp + hold
    last = (t >= end - 0.25 * hold) & (t <= end)
    settled = float(np.mean(f[last])) if np.any(last) else math.nan
    peak = float(np.max(f[t <= end]))
    over = peak / settled - 1.0 if settled > 0 else math.inf
    return {"peak_N": peak, "settled_N": settled, "overshoot": over,
            "ringing_rms_N": float(np.std(f[last])) if np.any(last) else math.nan,
            "target": OVERSHOOT_TARGET, "meets_target": bool(over <= OVERSHOOT_TARGET)}  # fmt: skip


def cosimulate(
    fmu_path: str | Path,
    params: ControllerParams,
    surrogate: Surrogate,
    device: DeviceParams,
    hand: HandParams | None = None,
    *,
    fast: bool = False,
    peak_hand_N: float = 3.0,
    substeps: int = 10,
) -> CosimResult:
    """Grasp-hold-release through an FMI 2 co-simulation FMU with fmpy.

    The handle is a rotational inertia ``J`` about its pivot with viscous friction ``b``
    (``device``) and end stops at the chain's range, pushed open by the FMU's rendered handle
    force and squeezed by the hand at the grip radius ``L3``:
    ``(J + J_h) theta'' = L3 (force_handle - F_hand) - b theta'``, integrated with
    semi-implicit Euler at ``substeps`` per controller step; the FMU is stepped at its sample
    time with the angle at the communication point.  With ``hand`` the hand is the operator of
    :class:`OperatorGrip` (a minimum-jerk intended path behind the finger stiffness and
    damping, whose hold force is ``peak_hand_N``; ``J_h = m L3^2``); without it a pure force
    source (:func:`hand_force_N`, cosine ramp), which lets the handle run through the soft
    stroke and slam into the tissue.  The Python
    :class:`~grasprom.control.ImpedanceController` is stepped on the same angles for comparison.

    Parameters
    ----------
    fmu_path : str or Path
        FMI 2.0 FMU of :func:`grasprom.export.fmu.export_fmu`.
    params : ControllerParams
        Parameters the FMU was exported with (sample time, chain, operating point).
    surrogate : Surrogate
        Tissue table of the Python reference.
    device : DeviceParams
        Handle inertia (kg m^2) and damping (N m s/rad).
    hand : HandParams, optional
        Finger mass (kg), damping (N s/m) and stiffness (N/m) at the grip; default none (a
        pure force source).
    fast : bool
        Shorter rest after the release (:func:`grasp_profile`: 0.2 s instead of 1 s; ramp
        1 s, hold 2 s and release 0.5 s either way, so the reported figures are the same).
    peak_hand_N : float
        Hold force of the hand at the grip, N.
    substeps : int
        Device integration steps per controller step.

    Returns
    -------
    CosimResult
    """
    from grasprom.control import ImpedanceController

    t_wall = time.perf_counter()
    ramp, hold, release, rest = grasp_profile(fast)
    T = params.sample_time_s
    n = int(round((ramp + hold + release + rest) / T))
    handle = Handle.from_params(params, device, hand)
    grip = _grip(params, surrogate, hand, handle, peak_hand_N, (ramp, hold, release, rest))
    fmu, vr, unzip = _open_fmu2(fmu_path)
    ref = ImpedanceController(params, surrogate)
    out_vr = [vr[k] for k in FMU_OUTPUTS]
    rec = np.zeros((n, 7))
    diff = 0.0
    try:
        _start(fmu)
        theta, omega = handle.theta_open_rad, 0.0
        dt = T / substeps
        for k in range(n):
            t = k * T
            fmu.setReal([vr["theta"]], [theta])
            fmu.doStep(t, T)
            torque, f_tissue, f_jaw, f_handle = fmu.getReal(out_vr)
            diff = max(diff, abs(torque - ref.step(theta).torque_Nm))
            theta, omega, f_hand = handle.advance(theta, omega, f_handle, grip, t, dt, substeps)
            rec[k] = (t + T, math.degrees(theta), torque, f_tissue, f_jaw, f_handle, f_hand)
        fmu.terminate()
    finally:
        fmu.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)
    return CosimResult(rec, COLUMNS, diff, time.perf_counter() - t_wall)


def _grip(
    params: ControllerParams,
    surrogate: Surrogate,
    hand: HandParams | None,
    handle: Handle,
    peak_hand_N: float,
    profile: tuple[float, float, float, float],
) -> Callable[[float, float, float], float]:
    """The hand's force at the grip, ``grip(t, theta, omega)`` (N): operator or force source."""
    if hand is not None:
        return operator_grip(params, surrogate, hand, handle, peak_hand_N, profile)
    ramp, hold, release, _rest = profile

    def force_source(t: float, _theta: float, _omega: float) -> float:
        return hand_force_N(t, ramp, hold, release, peak_hand_N)

    return force_source


def _open_fmu2(fmu_path: str | Path) -> tuple[Any, dict[str, int], str]:
    """Unzip an FMI 2 FMU: its slave (not instantiated), value references by name, the folder."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(str(fmu_path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzip = extract(str(fmu_path))
    fmu = FMU2Slave(
        guid=md.guid,
        unzipDirectory=unzip,
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName="build",
    )
    return fmu, vr, unzip


def _start(fmu: Any) -> None:
    """Instantiate and initialise an FMI 2 slave at t = 0."""
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()


def plot_cosim(cs: CosimResult, params: ControllerParams, path: str | Path) -> Path:
    """Handle angle, forces and motor torque of a co-simulation (PNG).

    Parameters
    ----------
    cs : CosimResult
    params : ControllerParams
        For the title (material, thickness).
    path : str or Path
        PNG to write.

    Returns
    -------
    Path
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    t = cs.col("time_s")
    fig = Figure(figsize=(7.0, 7.0))
    FigureCanvasAgg(fig)
    ax = fig.subplots(3, 1, sharex=True)
    ax[0].plot(t, cs.col("theta_deg"))
    ax[0].set_ylabel("handle angle (deg)")
    ax[1].plot(t, cs.col("force_handle_N"), label="rendered handle force")
    ax[1].plot(t, cs.col("hand_N"), "k--", lw=0.8, label="hand force")
    ax[1].set_ylabel("force at the grip (N)")
    ax[1].legend(fontsize=7)
    tw = ax[1].twinx()
    tw.plot(t, cs.col("torque_Nm"), "C3", lw=0.6, alpha=0.6)
    tw.set_ylabel("motor torque (N m)", color="C3")
    ax[2].semilogy(t, np.maximum(cs.col("force_jaw_N"), 1e-3), label="rendered jaw force")
    ax[2].semilogy(
        t,
        np.maximum(cs.col("force_tissue_N"), 1e-3),
        ":",
        label="tissue at the handle's gap (surrogate, without the coupling)",
    )
    ax[2].set_ylim(bottom=1e-2)
    ax[2].set_ylabel("jaw force (N)")
    ax[2].set_xlabel("time (s)")
    ax[2].legend(fontsize=7)
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle(f"FMU co-simulation (FMI 2.0, fmpy): grasp - hold - release, "
                 f"{params.material} {params.thickness_mm:g} mm")  # fmt: skip
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    return out
