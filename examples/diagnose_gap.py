"""Synthesise a few grasp trials with a withheld effect, diagnose the sim-to-real gap, print it,
then replay a held-out trial through the controller rendering the augmented model.

Usage::

    python examples/diagnose_gap.py [--effect mechanism_friction] [--seed 3] [--out DIR]

The effect is hidden from the diagnosis (it only reads the trial CSVs and sidecars); the truth is
printed at the end for comparison.  One more trial of the same case is synthesised and *not*
given to the diagnosis: its measured handle angle drives
:func:`grasprom.control.simulate` twice, with the plain controller and with the
augmented model rendered
(:func:`grasprom.gap.controller_params_from_augmented`; stiff coupling, no damping, no
encoder, so that the controller reproduces the static chain), and the RMS of simulated -
measured handle force (N) is printed before / after (sensor effects of the model, which the
controller does not render, applied to the simulated force with
:func:`grasprom.gap.measured_handle_force_N`).  Runs in well under 30 s.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from grasprom import gap  # noqa: E402
from grasprom.chain import kinematics as kin  # noqa: E402
from grasprom.control import ControllerParams, simulate  # noqa: E402
from grasprom.gap import SYNTH_EFFECTS, synth_case, write_case  # noqa: E402
from grasprom.surrogate import Surrogate  # noqa: E402


def stiff_params(thickness_mm: float, material: str) -> ControllerParams:
    """Controller parameters that reproduce the static chain (as ``tests/test_augmented.py``).

    Coupling 1e5 N/mm (softens a tissue of stiffness ``k_t`` by ``k_t / (k_c + k_t)`` < 0.3 %),
    no damping, no encoder quantisation, no torque saturation (100 N m), the return spring
    rendered, and the friction direction threshold at the diagnosis' "still" speed
    (:data:`grasprom.gap.STILL_DEG_PER_S` of handle, in mm/s at the finger).
    """
    return ControllerParams(
        thickness_mm=thickness_mm,
        material=material,
        rendering="coupling",  # the clipped default bounds the stiffness: not the static chain
        coupling_stiffness_N_per_mm=1e5,
        damping_Nms_per_rad=0.0,
        encoder_counts_per_rev=0,
        torque_limit_Nm=100.0,
        render_spring=True,
        friction_velocity_threshold_mm_per_s=math.radians(gap.STILL_DEG_PER_S)
        * kin.ChainParams().L3_mm,
    )


def replay_heldout(trial: gap.Trial, augmented_path: Path, surrogate: Surrogate) -> dict:
    """Simulate a held-out trial with the plain and the augmented controller.

    Parameters
    ----------
    trial : grasprom.gap.Trial
        The held-out trial (its angle drives the simulation, its handle force is the reference).
    augmented_path : Path
        ``augmented_model.json`` of the diagnosis.
    surrogate : Surrogate

    Returns
    -------
    dict
        ``rms_before_N`` / ``rms_after_N`` (RMS of simulated - measured handle force, N, plain
        controller / augmented model), ``rendered`` and ``measurement_only`` (effect names).
    """
    model = gap.load_augmented(augmented_path)
    base = stiff_params(trial.thickness_mm, trial.material)
    params, info = gap.controller_params_from_augmented(base, model, surrogate)
    traj = pd.DataFrame({"time_s": trial.time_s, "theta_deg": trial.theta_deg})
    sim0 = simulate(traj, base, surrogate)
    sim1 = simulate(traj, params, surrogate)
    t = sim0["time_s"].to_numpy()
    meas = np.interp(t, trial.time_s, trial.force_handle_N)
    f1 = gap.measured_handle_force_N(t, sim1["force_handle_N"].to_numpy(), info["measurement"])
    return {
        "rms_before_N": float(np.sqrt(np.mean((sim0["force_handle_N"].to_numpy() - meas) ** 2))),
        "rms_after_N": float(np.sqrt(np.mean((f1 - meas) ** 2))),
        "rendered": info["rendered"],
        "measurement_only": info["measurement_only"],
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--effect",
        default="mechanism_friction",
        help=f"withheld effect(s), comma list from {','.join(SYNTH_EFFECTS)}; '' for noise only",
    )
    p.add_argument("--seed", type=int, default=3)
    p.add_argument("--trials", type=int, default=4, help="trials given to the diagnosis")
    p.add_argument(
        "--out",
        default=None,
        metavar="DIR",
        help="keep trials, report.json, augmented_model.json and plots here",
    )
    args = p.parse_args(argv)
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="grasprom_diag_"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        surrogate = Surrogate.build(ROOT / "fe_data" / "default")
    effects = [e for e in args.effect.split(",") if e]
    # one trial more than diagnosed: the last one is held out (the first ones are the same as
    # with --trials alone: the trials are drawn in order from the seed)
    case = synth_case(effects, seed=args.seed, n_trials=args.trials + 1, surrogate=surrogate)
    held = case.trials.pop()
    paths = write_case(case, out / "trials")
    held_path = out / "heldout" / f"{held.sidecar['trial_id']}.csv"
    held_path.parent.mkdir(parents=True, exist_ok=True)
    held.data.to_csv(held_path, index=False, float_format="%.6g")
    held_path.with_suffix(".json").write_text(json.dumps(held.sidecar, indent=2))
    chain = kin.ChainParams()
    trials = [gap.load_trial(pth, chain, surrogate) for pth in paths]  # truth.json is not read
    diag = gap.diagnose(trials, surrogate, chain)
    written = gap.write_outputs(diag, out / "diagnosis")
    print(gap.format_summary(diag.report))
    print(f"\n(withheld truth: {json.dumps(case.truth['effects'], default=float)})")

    rep = replay_heldout(
        gap.load_trial(held_path, chain, surrogate), written["augmented"], surrogate
    )
    print(
        f"\nheld-out trial {held_path.name} simulated by the controller "
        f"(rendered: {', '.join(rep['rendered']) or 'none'}; applied to the sensor reading: "
        f"{', '.join(rep['measurement_only']) or 'none'})"
    )
    print(
        f"  RMS simulated - measured handle force: {rep['rms_before_N']:.3f} N without the "
        f"augmentation -> {rep['rms_after_N']:.3f} N with it"
    )
    print(f"outputs in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
