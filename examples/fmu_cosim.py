"""Co-simulate the exported controller FMU with a device + hand model (fmpy, Python loop).

The FMU (exported here with :func:`grasprom.export.fmu.export_fmu`) renders the tissue through the
motor torque; the device is the handle, a rotational inertia ``J`` about its pivot with viscous
friction ``b`` and end stops, pushed closed by the hand (force ``F_hand(t)`` at the grip radius
``L3``: ramp up, hold, release) and pushed open by the cable force ``torque / r`` of the motor:

    J theta'' = L3 (force_handle - F_hand(t)) - b theta'      (theta decreases when closing)

The device is integrated with semi-implicit Euler at 10 kHz; the FMU is stepped every 1 ms
(its sample time) with the handle angle at the communication point.  The plot shows the handle
angle, motor torque and tissue force over grasp-hold-release (PNG in ``--out``).

    python examples/fmu_cosim.py --out /tmp/cosim [--fmi 3] [--fast]
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from grasprom.control import ControllerParams  # noqa: E402
from grasprom.export import export_fmu  # noqa: E402
from grasprom.pipeline import hand_force_N  # noqa: E402
from grasprom.surrogate import load_surrogate  # noqa: E402

J = 2e-4  # kg m^2, handle + reflected motor inertia at the pivot
B = 5e-3  # N m s / rad, pivot friction
SUBSTEPS = 10


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

    def get(self, names: list[str]) -> list[float]:
        return (self.s.getReal if self.v == 2 else self.s.getFloat64)([self.vr[n] for n in names])

    def step(self, t: float, h: float) -> None:
        self.s.doStep(t, h)

    def close(self) -> None:
        self.s.terminate()
        self.s.freeInstance()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("fmu_cosim"), help="output directory")
    ap.add_argument("--fmi", type=int, choices=(2, 3), default=2, help="FMI version")
    ap.add_argument("--fast", action="store_true", help="shorter grasp (CI smoke run)")
    ap.add_argument("--peak", type=float, default=3.5, help="peak hand force, N")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    t_wall = time.perf_counter()

    params = ControllerParams(damping_Nms_per_rad=0.01)
    fmu_path = export_fmu(args.out / "GraspController.fmu", params, load_surrogate(None, None),
                          fmi_version=args.fmi)  # fmt: skip
    ramp, hold, release, rest = (0.4, 0.6, 0.3, 0.5) if args.fast else (1.0, 2.0, 0.5, 1.0)
    T = params.sample_time_s
    n = int(round((ramp + hold + release + rest) / T))
    L3 = params.chain.L3_mm * 1e-3
    th_lo = math.radians(params.chain.theta_closed_deg)
    th_hi = math.radians(params.chain.theta_open_deg)

    fmu = _Fmu(fmu_path, args.fmi)
    theta, omega = th_hi, 0.0
    rec = np.zeros((n, 6))  # t, theta_deg, torque, force_tissue, force_handle, hand
    outputs = ["torque", "force_tissue", "force_handle"]
    f_handle = 0.0
    for k in range(n):
        t = k * T
        fmu.set("theta", theta)
        fmu.step(t, T)
        torque, f_tissue, f_handle = fmu.get(outputs)
        hand = hand_force_N(t, ramp, hold, release, args.peak)
        dt = T / SUBSTEPS
        for _ in range(SUBSTEPS):
            acc = (L3 * (f_handle - hand) - B * omega) / J
            omega += acc * dt
            theta += omega * dt
            if theta < th_lo or theta > th_hi:  # end stops
                theta = min(max(theta, th_lo), th_hi)
                omega = 0.0
        rec[k] = (t + T, math.degrees(theta), torque, f_tissue, f_handle, hand)
    fmu.close()

    fig, ax = plt.subplots(3, 1, sharex=True, figsize=(7, 7))
    ax[0].plot(rec[:, 0], rec[:, 1])
    ax[0].set_ylabel("handle angle (deg)")
    ax[1].plot(rec[:, 0], rec[:, 2], label="motor torque")
    ax[1].set_ylabel("torque (N m)")
    ax2 = ax[1].twinx()
    ax2.plot(rec[:, 0], rec[:, 5], "k--", lw=0.8, label="hand force")
    ax2.set_ylabel("hand force (N)")
    ax[2].plot(rec[:, 0], rec[:, 3])
    ax[2].set_ylabel("tissue force (N)")
    ax[2].set_xlabel("time (s)")
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle(f"FMU co-simulation (FMI {args.fmi}.0): grasp - hold - release, "
                 f"{params.material} {params.thickness_mm:g} mm")  # fmt: skip
    fig.tight_layout()
    png = args.out / "fmu_cosim.png"
    fig.savefig(png, dpi=120)
    header = "time_s,theta_deg,torque_Nm,force_tissue_N,force_handle_N,hand_N"
    np.savetxt(args.out / "fmu_cosim.csv", rec, delimiter=",", comments="", header=header)
    print(f"{n} steps; min handle angle {rec[:, 1].min():.2f} deg, max torque "
          f"{rec[:, 2].max():.3f} N m, max tissue force {rec[:, 3].max():.1f} N; "
          f"{time.perf_counter() - t_wall:.1f} s -> {png}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
