"""Co-simulate the exported controller FMU with the build's handle + hand model (fmpy loop).

This is the co-simulation of ``grasprom build`` written out, for FMI 2 or FMI 3: the same
operating point (mr 1.4 mm by default), the controller tuned as the build tunes it (clipped
rendering, the documented :class:`~grasprom.control.DeviceParams` and
:class:`~grasprom.control.HandParams`; or ``--controller`` a build's ``controller.json``), the
same grasp profile and the same hand.  The handle is a rotational inertia ``J`` (device plus
the finger mass reflected) about its pivot with viscous friction ``b`` and end stops, pushed
open by the FMU's rendered handle force and squeezed by the hand at the grip radius ``L3``:

    J theta'' = L3 (force_handle - F_hand) - b theta'      (theta decreases when closing)

The hand is the operator model of haptics (:class:`grasprom.pipeline.cosim.OperatorGrip`): a
minimum-jerk intended closing behind the finger's stiffness and damping, holding 3 N.  The
device is integrated with semi-implicit Euler at 10 kHz; the FMU is stepped every 1 ms (its
sample time) with the handle angle at the communication point.  The printed figures (minimum
handle angle, max jaw force, max motor torque, overshoot) are those of the build's report at
the same operating point; ``--fast`` shortens only the rest after the release, as the build's
``--fast`` does, so it prints the same figures.

    python examples/fmu_cosim.py --out /tmp/cosim [--fmi 3] [--fast] [--controller FILE]
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np

from grasprom.control import ControllerParams, DeviceParams, HandParams, load_params, tune
from grasprom.export import export_fmu
from grasprom.pipeline import CosimResult, grasp_settling, plot_cosim
from grasprom.pipeline.cosim import COLUMNS, FMU_OUTPUTS, Handle, grasp_profile, operator_grip
from grasprom.surrogate import load_surrogate

SUBSTEPS = 10
HOLD_FORCE_N = 3.0  # the build's hold force (grasprom.pipeline.cosimulate's peak_hand_N)


class _Fmu:
    """Minimal fmpy wrapper for FMI 2 / 3 co-simulation by variable name."""

    def __init__(self, path: Path, version: int):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave
        from fmpy.fmi3 import FMU3Slave

        self.v = version
        md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        cls = FMU2Slave if version == 2 else FMU3Slave
        token = md.guid if version == 2 else md.instantiationToken
        self.s = cls(
            guid=token,
            unzipDirectory=extract(str(path)),
            modelIdentifier=md.coSimulation.modelIdentifier,
            instanceName="ctl",
        )
        self.s.instantiate()
        if version == 2:
            self.s.setupExperiment(startTime=0.0)
            self.s.enterInitializationMode()
        else:
            self.s.enterInitializationMode(startTime=0.0)
        self.s.exitInitializationMode()

    def set(self, name: str, x: float) -> None:
        (self.s.setReal if self.v == 2 else self.s.setFloat64)([self.vr[name]], [x])

    def get(self, names: tuple[str, ...]) -> list[float]:
        return (self.s.getReal if self.v == 2 else self.s.getFloat64)([self.vr[n] for n in names])

    def step(self, t: float, h: float) -> None:
        self.s.doStep(t, h)

    def close(self) -> None:
        self.s.terminate()
        self.s.freeInstance()


def controller(surrogate, path: Path | None) -> tuple[ControllerParams, DeviceParams, HandParams]:
    """The build's controller: loaded from ``path``, or tuned as ``grasprom build`` does."""
    if path is not None:
        return load_params(path), DeviceParams(), HandParams()
    r = tune(surrogate, ControllerParams(rendering="clipped"), DeviceParams())
    return r.params, r.device, r.hand


def cosimulate_loop(fmu: _Fmu, params, surrogate, device, hand, fast: bool) -> np.ndarray:
    """Grasp-hold-release: one row of :data:`COLUMNS` per controller step."""
    profile = grasp_profile(fast)
    T = params.sample_time_s
    n = int(round(sum(profile) / T))
    handle = Handle.from_params(params, device, hand)
    grip = operator_grip(params, surrogate, hand, handle, HOLD_FORCE_N, profile)
    theta, omega = handle.theta_open_rad, 0.0
    rec = np.zeros((n, len(COLUMNS)))
    for k in range(n):
        t = k * T
        fmu.set("theta", theta)
        fmu.step(t, T)
        torque, f_tissue, f_jaw, f_handle = fmu.get(FMU_OUTPUTS)
        theta, omega, f_hand = handle.advance(
            theta, omega, f_handle, grip, t, T / SUBSTEPS, SUBSTEPS
        )
        rec[k] = (t + T, math.degrees(theta), torque, f_tissue, f_jaw, f_handle, f_hand)
    return rec


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("fmu_cosim"), help="output directory")
    ap.add_argument("--fmi", type=int, choices=(2, 3), default=2, help="FMI version")
    ap.add_argument("--fast", action="store_true", help="shorter rest after the release")
    ap.add_argument("--controller", type=Path, help="controller.json of a build (skip tuning)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    t_wall = time.perf_counter()

    s = load_surrogate(None, None)
    params, device, hand = controller(s, args.controller)
    fmu_path = export_fmu(args.out / "GraspController.fmu", params, s, fmi_version=args.fmi)
    fmu = _Fmu(fmu_path, args.fmi)
    try:
        rec = cosimulate_loop(fmu, params, s, device, hand, args.fast)
    finally:
        fmu.close()
    cs = CosimResult(rec, COLUMNS, math.nan, time.perf_counter() - t_wall)
    st = grasp_settling(cs, args.fast)
    png = plot_cosim(cs, params, args.out / "fmu_cosim.png")
    np.savetxt(args.out / "fmu_cosim.csv", rec, delimiter=",", comments="",
               header=",".join(COLUMNS), fmt="%.9g")  # fmt: skip
    print(f"FMI {args.fmi}.0, {params.material} {params.thickness_mm:g} mm, {len(rec)} steps; "
          f"min handle angle {cs.col('theta_deg').min():.2f} deg, max jaw force "
          f"{cs.col('force_jaw_N').max():.2f} N, max motor torque "
          f"{cs.col('torque_Nm').max():.3f} N m, handle-force overshoot "
          f"{100 * st['overshoot']:.0f} %, open-handle force {rec[0, 5]:.2f} N (return "
          f"spring); the build's co-simulation at this operating point reports the same; "
          f"{time.perf_counter() - t_wall:.1f} s -> {png}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
