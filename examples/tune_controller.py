"""Passivity tuning of the impedance controller over the shipped FE sweep.

Builds the surrogate from ``fe_data/default``, runs :func:`grasprom.control.tuning.tune` (Colgate /
Abbott-Okamura bounds, Z-width, python-control poles and margins with the hand at every
operating point, the transparency table, simulation check), prints the report and writes
``controller.json``, ``tuning.json``, ``tuning.txt`` and the plots (``transparency.png``
among them) into ``--out``.  Takes about 10 s.  The defaults are ``grasprom tune``'s (the
stiffness-clipped rendering), so both print the same design.

    python examples/tune_controller.py --out /tmp/tune
    python examples/tune_controller.py --out /tmp/tune --rendering coupling --device dev.json
"""

from __future__ import annotations

import argparse
import warnings
from dataclasses import replace
from pathlib import Path

from grasprom.control import (
    ControllerParams,
    DeviceParams,
    apply_device,
    load_device,
    tune,
    write_outputs,
)
from grasprom.surrogate import Surrogate

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("tuning"), help="output directory")
    ap.add_argument("--rate-hz", type=float, default=1000.0, help="controller rate, Hz")
    ap.add_argument(
        "--damping",
        type=float,
        default=DeviceParams().damping_Nms_per_rad,
        help="physical damping b at the handle pivot, N m s/rad",
    )
    ap.add_argument(
        "--rendering",
        choices=("coupling", "clipped"),
        default="clipped",
        help="tissue rendering (default: clipped, as grasprom tune)",
    )
    ap.add_argument("--device", type=Path, default=None, help="device JSON (replaces --damping)")
    args = ap.parse_args(argv)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        sur = Surrogate.build(ROOT / "fe_data" / "default")
    base = replace(ControllerParams(rendering=args.rendering), sample_time_s=1.0 / args.rate_hz)
    if args.device is not None:
        device = load_device(args.device)
        base = apply_device(base, device)
    else:
        device = DeviceParams(damping_Nms_per_rad=args.damping)
    result = tune(sur, base, device)
    files = write_outputs(result, args.out)
    print(result.report())
    print("wrote " + ", ".join(str(f) for f in files.values()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
