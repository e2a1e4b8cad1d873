"""Synthesise a few grasp trials with a withheld effect, diagnose the sim-to-real gap, print it.

Usage::

    python examples/diagnose_gap.py [--effect mechanism_friction] [--seed 3] [--out DIR]

The effect is hidden from the diagnosis (it only reads the trial CSVs and sidecars); the truth is
printed at the end for comparison.  Runs in well under 30 s.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from grasprom import diagnosis as dg  # noqa: E402
from grasprom import kinematics as kin  # noqa: E402
from grasprom.surrogate import Surrogate  # noqa: E402
from grasprom.synth import SYNTH_EFFECTS, synth_case, write_case  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--effect", default="mechanism_friction",
                   help=f"withheld effect(s), comma list from {','.join(SYNTH_EFFECTS)}; "
                   "'' for noise only")
    p.add_argument("--seed", type=int, default=3)
    p.add_argument("--trials", type=int, default=4)
    p.add_argument("--out", default=None, metavar="DIR",
                   help="keep trials, report.json, augmented_model.json and plots here")
    args = p.parse_args(argv)
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="grasprom_diag_"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        surrogate = Surrogate.build(ROOT / "fe_data" / "default")
    effects = [e for e in args.effect.split(",") if e]
    case = synth_case(effects, seed=args.seed, n_trials=args.trials, surrogate=surrogate)
    paths = write_case(case, out / "trials")
    chain = kin.ChainParams()
    trials = [dg.load_trial(pth, chain, surrogate) for pth in paths]  # truth.json is not read
    diag = dg.diagnose(trials, surrogate, chain)
    dg.write_outputs(diag, out / "diagnosis")
    print(dg.format_summary(diag.report))
    print(f"\n(withheld truth: {json.dumps(case.truth['effects'], default=float)})")
    print(f"outputs in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
