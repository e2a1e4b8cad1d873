"""Export the tuned controller for an Arduino Uno (ATmega328P) and print its budget.

The default ``ControllerParams`` are the tuned ones (``grasprom tune`` on the default device);
``--controller`` takes a ``controller.json`` of ``grasprom tune`` or ``grasprom build``.
Builds the surrogate from the shipped sweep, writes ``--out/grasprom_controller/`` (sketch,
fixed-point core, PROGMEM tables, arduino-mk Makefile) and prints flash, RAM, cycles per step and
the force error (measured with avr-gcc/avr-size, simavr and gcc when installed; a missing tool
leaves its figure ``n/a``).  ``--fast`` skips the measurement (about 1 s instead of 4 s).
``--rendering clipped`` exports the stiffness-clipped rendering (``grasprom.control.field``)
instead of the virtual coupling.

    python examples/arduino_export.py --out /tmp/arduino [--thickness 1.4] [--material mr] \
        [--controller build/controller.json] [--rendering clipped] [--fast]
    cd /tmp/arduino/grasprom_controller && make          # needs arduino-mk
"""

from __future__ import annotations

import argparse
import dataclasses
import warnings
from pathlib import Path

from grasprom.control import ControllerParams, load_params
from grasprom.export import export_arduino
from grasprom.surrogate import Surrogate

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("arduino_out"), help="output directory")
    ap.add_argument("--thickness", type=float, default=1.4, help="wall thickness, mm")
    ap.add_argument("--material", default="mr", help="mr, nh or le")
    ap.add_argument("--controller", type=Path, default=None, help="controller parameters JSON")
    ap.add_argument(
        "--rendering", choices=("coupling", "clipped"), default=None,
        help="rendering scheme (default: that of the parameters)",
    )  # fmt: skip
    ap.add_argument("--fast", action="store_true", help="write the package, do not measure")
    args = ap.parse_args(argv)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        sur = Surrogate.build(ROOT / "fe_data" / "default")
    base = load_params(args.controller) if args.controller else ControllerParams()
    params = dataclasses.replace(base, thickness_mm=args.thickness, material=args.material)
    if args.rendering:
        params = dataclasses.replace(params, rendering=args.rendering)
    res = export_arduino(args.out, surrogate=sur, params=params, measure=not args.fast)
    print(res.summary())
    return 0 if res.within_budget() else 1


if __name__ == "__main__":
    raise SystemExit(main())
