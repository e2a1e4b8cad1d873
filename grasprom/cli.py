"""Command-line interface: ``grasprom <subcommand>`` (also ``python -m grasprom``).

Subcommands
-----------
build
    The main job: FE sweep -> surrogate -> tuning -> FMU (FMI 2 and 3) -> Arduino package ->
    FMU co-simulation -> report.html, into one output folder.
sweep
    Run an FE clamping sweep over wall thickness x material (resumable).
report
    Summary table (text + CSV) and force-gap plot of a sweep directory.
surrogate {build,check,plot}
    Tabulated force surrogate: build from a sweep, error table against FE cases, plot.
simulate
    Run the impedance controller (Python reference) on a handle-angle trajectory.
tune
    Passivity tuning of the controller with python-control.
export {fmu,arduino}
    FMU (FMI 2/3 co-simulation) or Arduino package of the controller.
diagnose, synth
    Sim-to-real gap diagnosis of measured trials; synthetic trials with withheld effects.
export fmu
    Co-simulation FMU (FMI 2.0 / 3.0) of the controller, native C.

Exit codes: 0 success, 1 some case failed, 2 bad input (message on stderr), 130 interrupted.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from grasprom import __version__
from grasprom.paths import DEFAULT_HOLDOUT_DIR, DEFAULT_SWEEP_DIR, resolve_data_dir


def _build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="grasprom",
        description="From FE clamping sweeps of the colon wall to haptic grasp controllers: "
        "surrogate, passivity tuning, FMU and Arduino exports, sim-to-real gap diagnosis. "
        "Start with 'grasprom build'.",
    )
    p.add_argument("--version", action="version", version=f"grasprom {__version__}")
    sub = p.add_subparsers(
        dest="command", required=True, metavar="{build,sweep,report,surrogate,simulate,...}"
    )
    _add_build_parser(sub)

    _add_sweep_parser(sub)
    _add_report_parser(sub)
    _add_surrogate_parser(sub)
    _add_simulate_parser(sub)
    _add_tune_parser(sub)
    _add_export_parser(sub)
    _add_identify_parser(sub)
    # subcommands with their own parsers (main() hands them the rest of the command line)
    sub.add_parser(
        "diagnose",
        add_help=False,
        help="sim-to-real gap diagnosis of measured trials (grasprom diagnose -h)",
    )
    sub.add_parser(
        "synth",
        add_help=False,
        help="synthetic 'real' trials with withheld effects (grasprom synth -h)",
    )
    return p


def _add_identify_parser(sub) -> None:
    i = sub.add_parser(
        "identify",
        help="identify the haptic device (inertia, damping, friction) from free-motion trials",
        description="Identify handle inertia, viscous damping and Coulomb friction of the "
        "device alone (no tissue, no hand) from free-motion trials: CSV columns time_s (s), "
        "theta_deg (deg), torque_Nm (motor torque, N m). Writes the device JSON of "
        "'grasprom tune --device' with the uncertainties.",
    )
    i.add_argument("trials", nargs="+", metavar="TRIAL.csv", help="free-motion trials")
    i.add_argument("--out", required=True, metavar="JSON", help="device JSON to write")
    i.add_argument("--controller", default=None, metavar="JSON",
                   help="controller parameters: chain (L3, end stops) and pulley radius "
                   "(default: the defaults)")  # fmt: skip
    i.add_argument("--device", default=None, metavar="JSON",
                   help="base device whose other values (torque constant, current limit, "
                   "delay, encoder) the written file keeps (default: the defaults)")  # fmt: skip


def _cmd_identify(args: argparse.Namespace) -> int:
    from grasprom.control import ControllerParams, load_params
    from grasprom.fe.atomicio import atomic_write_json
    from grasprom.gap.identify import identify_device, load_device_trial

    try:
        params = load_params(args.controller) if args.controller else ControllerParams()
        base = _load_device_option(args.device)
        trials = [load_device_trial(t) for t in args.trials]
        res = identify_device(trials, params.chain_params, params.pulley_radius_mm, base)
    except (OSError, ValueError) as exc:
        return _error("identify", exc)
    try:
        atomic_write_json(args.out, res.to_dict())
    except OSError as exc:
        return _error("identify", f"--out {args.out}: cannot write ({exc.strerror or exc})")
    print(res.format())
    print(f"wrote {args.out} (use: grasprom tune --device {args.out})")
    return 0


def _add_sweep_parser(sub) -> None:
    from grasprom.fe import KNOWN_MATERIALS, spec_defaults

    d = spec_defaults()
    s = sub.add_parser(
        "sweep",
        help="run an FE sweep over thickness x material (resumable)",
        description="Run the FE clamping grid. Finished cases are written atomically; "
        "rerunning the same command skips them.",
    )
    s.add_argument(
        "--thickness",
        required=True,
        help="wall thickness in mm: start:stop:step (inclusive), a comma list, "
        "or one value; e.g. 0.8:2.0:0.1",
    )
    s.add_argument(
        "--material",
        required=True,
        help=f"comma list of materials from {','.join(KNOWN_MATERIALS)}",
    )
    _add_case_geometry(s, d)
    _add_model_options(s)
    g = s.add_mutually_exclusive_group()
    g.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="local worker processes (default: CPU count; 1 = in-process)",
    )
    g.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDR",
        help="address of an existing Dask scheduler, e.g. tcp://127.0.0.1:8786",
    )
    s.add_argument(
        "--out", required=True, metavar="DIR", help="sweep directory, e.g. fe_data/<name>"
    )
    s.add_argument("--quiet", action="store_true", help="no progress bar")


def _add_case_geometry(s: argparse.ArgumentParser, d: dict) -> None:
    """Tube, jaw and mesh options of ``grasprom sweep`` (defaults ``d`` from the FE model)."""
    s.add_argument(
        "--diameter",
        type=float,
        default=None,
        metavar="MM",
        help=f"outer tube diameter in mm (default {d['diameter_mm']:g})",
    )
    s.add_argument(
        "--jaw-length",
        type=float,
        default=None,
        metavar="MM",
        help="jaw length along the tube axis in mm, the out-of-plane depth "
        f"(default {d['jaw_length_mm']:g})",
    )
    s.add_argument(
        "--closed-gap",
        type=float,
        default=None,
        metavar="MM",
        help=f"final jaw gap in mm (default {d['closed_gap_mm']:g})",
    )
    s.add_argument(
        "--force-cap",
        type=float,
        default=None,
        metavar="N",
        help=f"stop a case once the jaw force exceeds this, in N (default {d['force_cap_N']:g})",
    )
    s.add_argument(
        "--n-layers",
        type=int,
        default=None,
        metavar="N",
        help=f"mesh layers through the wall (2d default {d['n_layers']}; 3d: of --mesh)",
    )
    s.add_argument(
        "--n-circ",
        type=int,
        default=None,
        metavar="N",
        help=f"mesh divisions along the quarter circumference (2d default {d['n_circ']}; 3d: of "
        "--mesh)",
    )
    s.add_argument(
        "--grading",
        type=float,
        default=None,
        metavar="RATIO",
        help="mesh: largest / smallest element along the circumference, refining toward the "
        f"side fold (1 = uniform; 2d default {d['grading']:g}, lowered for thick walls so the "
        f"fold corner element is at least {d['corner_aspect']:g} times as long as thick; 3d: "
        "of --mesh)",
    )
    s.add_argument(
        "--radial-grading",
        type=float,
        default=None,
        metavar="RATIO",
        help="mesh: outermost / innermost layer thickness, refining toward the inner wall "
        f"(1 = uniform; 2d default {d['radial_grading']:g}; 3d: of --mesh)",
    )


def _add_model_options(s: argparse.ArgumentParser) -> None:
    """``--model`` and the 3D options of ``grasprom sweep`` (issue 18)."""
    s.add_argument(
        "--model",
        choices=("2d", "3d"),
        default="2d",
        help="FE model: 2d (plane-strain ring, fast) or 3d (1/8 tube with finite jaws; default 2d)",
    )
    s.add_argument(
        "--contact",
        choices=("stick", "frictionless", "coulomb"),
        default=None,
        help="jaw contact: stick (no sliding, Guachi et al. 2020; 3d default), frictionless (2d "
        "default) or coulomb (needs --friction: stuck until the tangential force passes "
        "MU x the normal force, then sliding against MU x the normal force)",
    )
    s.add_argument(
        "--friction",
        type=float,
        default=None,
        metavar="MU",
        help="Coulomb friction coefficient (-), with --contact coulomb (no default)",
    )
    s.add_argument(
        "--tube-length",
        type=float,
        default=None,
        metavar="MM",
        help="3d: length of the modelled tube in mm (default of grasprom.fe.model3d)",
    )
    s.add_argument(
        "--ends",
        choices=("seed", "free"),
        default=None,
        help=(
            "3d: end condition at the tube's free edges: seed = as in Guachi et al. (2020), "
            "in-plane translations held, axial translation and rotation free; free = no "
            "constraint (default of grasprom.fe.model3d)"
        ),
    )
    _add_mesh3d_options(s)


def _add_mesh3d_options(s: argparse.ArgumentParser) -> None:
    """The 3D mesh options of ``grasprom sweep``: axial divisions, the far zone, predicted
    contact and the named mesh."""
    s.add_argument(
        "--n-jaw",
        type=int,
        default=None,
        metavar="N",
        help="3d: axial mesh divisions over the jaw and its fine margin (default of --mesh)",
    )
    s.add_argument(
        "--n-free",
        type=int,
        default=None,
        metavar="N",
        help="3d: axial mesh divisions beyond the jaw, growing toward the tube end (default of "
        "--mesh)",
    )
    s.add_argument(
        "--far-coarsening",
        type=int,
        default=None,
        metavar="K",
        help="3d: beyond the fine zone over the jaw, 1/K of the layers and circumferential "
        "divisions (K divides both; the zones are tied at their interface plane): with "
        "--mesh converged and K = 2, 22,983 unknowns instead of 41,391 and about half the wall "
        "time (default 1: one cross-section along the tube, the shipped data's)",
    )
    s.add_argument(
        "--band-companion",
        type=int,
        default=None,
        metavar="K",
        help="3d: after each case a companion run on its mesh with --far-coarsening K lands on "
        "the case's crease-band gaps (2t-4t); where its state, moved to the case's mesh, holds "
        "less strain energy it replaces the case's row (two runs can reach different crease "
        "patterns; this keeps the lower one; the selection costs 0.4-1.5x the own run; default "
        "of --mesh: 2 with converged, the shipped data's, unless a mesh option overrides it or "
        "the contact is coulomb; otherwise 0, off; grasprom.fe.bandselect)",
    )
    s.add_argument(
        "--select-from",
        default=None,
        metavar="DIR",
        help="3d with a band companion: take each case's own run from DIR (a sweep of the same "
        "cases with --band-companion 0) instead of running it again, "
        "and run only the companion and the selection; writes to --out (another directory) "
        "what the sweep with --band-companion would (grasprom.fe.reselect)",
    )
    s.add_argument(
        "--predict-contact-below",
        type=float,
        default=None,
        metavar="T",
        help="3d: below this jaw gap, in wall thicknesses (2.5 = gap 3.5 mm at t = 1.4 mm), a "
        "Newton step cut at a first touch adds every node its full step would push into "
        "contact, so fine meshes do not crawl where the inner walls meet (default of --mesh: "
        "2.5 converged, off coarse)",
    )
    s.add_argument(
        "--mesh",
        default=None,
        metavar="NAME",
        help="3d: named mesh, converged (default; the shipped fe_data/default's: 4 x 36 graded "
        "8:1, 6 axial divisions beyond the jaw, contact predicted below 2.5 t, the crease band "
        "selected with --band-companion 2; 6-34 min a case and 0.4-1.5x that for the "
        "selection), coarse (2 x 12 graded 2:1, 9 beyond: fe_data/3d_2x12, converged in bending "
        "only; 2-5 min a case) or zoned (converged over the jaw, 2 x 18 beyond its 2 mm margin: "
        "--far-coarsening 2; 2-10 min a case); the mesh options above override it one by one "
        "(grasprom.fe.grid3d.MESH_PRESETS)",
    )


def _add_report_parser(sub) -> None:
    r = sub.add_parser("report", help="table and plot of a sweep directory")
    r.add_argument(
        "directory",
        nargs="?",
        default=DEFAULT_SWEEP_DIR,
        help=f"sweep directory (default {DEFAULT_SWEEP_DIR})",
    )
    r.add_argument(
        "--out",
        default="report",
        metavar="DIR",
        help="output directory for sweep_table.csv and force_gap.png (default ./report)",
    )
    r.add_argument(
        "--linear",
        dest="logy",
        action="store_false",
        help="linear force axis on the full-stroke plot (default: logarithmic)",
    )
    r.add_argument("--logy", dest="logy", action="store_true", help=argparse.SUPPRESS)


def _add_surrogate_parser(sub) -> None:
    sg = sub.add_parser("surrogate", help="tabulated force surrogate (build, check, plot)")
    ssub = sg.add_subparsers(dest="surrogate_command", required=True, metavar="{build,check,plot}")
    b = ssub.add_parser("build", help="build a surrogate JSON from an FE sweep")
    b.add_argument("--fe", required=True, metavar="DIR", help="FE sweep, e.g. fe_data/default")
    b.add_argument("--out", required=True, metavar="FILE", help="surrogate JSON to write")
    b.add_argument(
        "--tol",
        type=_tolerance,
        default=0.005,
        help=f"gap-node tolerance relative to max(20 N, F), in (0, {TOL_MAX:g}] (default 0.005)",
    )
    b.add_argument(
        "--scheme",
        choices=("aligned", "naive"),
        default="aligned",
        help="thickness interpolation (default aligned)",
    )
    b.add_argument(
        "--holdout",
        metavar="DIR",
        default=None,
        help="extra FE cases whose error figures are stored in the file too",
    )
    c = ssub.add_parser("check", help="error table of a surrogate against FE cases")
    c.add_argument("surrogate", metavar="FILE", help="surrogate JSON")
    c.add_argument(
        "--fe", required=True, metavar="DIR", help="directory of FE cases (e.g. fe_data/holdout)"
    )
    pl = ssub.add_parser("plot", help="force and stiffness vs gap, surrogate over FE points")
    pl.add_argument("surrogate", metavar="FILE", help="surrogate JSON")
    pl.add_argument("--fe", default=None, metavar="DIR", help="FE cases to overlay")
    pl.add_argument("--out", required=True, metavar="PNG", help="PNG to write")


def _delegated(name: str):
    """Entry point of a subcommand that parses its own arguments."""
    return _main_diagnose if name == "diagnose" else _main_synth


def _add_simulate_parser(sub) -> None:
    m = sub.add_parser(
        "simulate",
        help="run the impedance controller on a handle-angle trajectory (reference output)",
        description="Run the Python reference controller on a trajectory CSV (time_s, "
        "theta_deg) at the controller rate and write the rendered forces and torque.",
    )
    m.add_argument("--trajectory", required=True, metavar="CSV", help="columns time_s, theta_deg")
    m.add_argument("--thickness", type=float, default=None, metavar="MM",
                   help="wall thickness in mm (default: the controller's, 1.4)")  # fmt: skip
    m.add_argument("--material", default=None,
                   help="mr, nh or le (default: the controller's, mr)")  # fmt: skip
    m.add_argument("--controller", default=None, metavar="JSON",
                   help="controller parameters (default: the documented defaults)")  # fmt: skip
    m.add_argument(
        "--augmented",
        default=None,
        metavar="JSON",
        help="augmented model of 'grasprom diagnose': render its instrument effects; sensor "
        "offset/gain and latency go to a column force_handle_measured_N",
    )
    _add_rendering_option(m)
    _add_surrogate_source(m)
    m.add_argument("--out", required=True, metavar="CSV", help="simulation output CSV")


def _add_surrogate_source(parser) -> None:
    """``--surrogate FILE | --fe DIR``: where a command gets its tissue surrogate."""
    src = parser.add_mutually_exclusive_group()
    src.add_argument("--surrogate", default=None, metavar="JSON", help="surrogate file")
    src.add_argument(
        "--fe",
        default=None,
        metavar="DIR",
        help=f"FE sweep to build the surrogate from (default {DEFAULT_SWEEP_DIR})",
    )


def _augment_params(cmd: str, path: str, params, sur) -> tuple[object, dict]:
    """Load ``--augmented`` and map it onto ``params``; prints what is rendered (stdout) and
    the mapping's warnings (stderr).  Returns the new parameters and the mapping info with the
    file and its sha256."""
    import hashlib

    from grasprom.gap import controller_params_from_augmented, load_augmented

    model = load_augmented(path)
    params, info = controller_params_from_augmented(params, model, sur)
    info = {"file": str(path), "sha256": hashlib.sha256(Path(path).read_bytes()).hexdigest(),
            **info}  # fmt: skip
    fe_hash = (model.meta.get("surrogate") or {}).get("fe_hash")
    if fe_hash and getattr(sur, "fe_hash", None) and fe_hash != sur.fe_hash:
        info["warnings"].append(
            f"the model was fitted with another surrogate (fe_hash {fe_hash[:12]}, this one "
            f"{sur.fe_hash[:12]})"
        )
    for w in info["warnings"]:
        print(f"grasprom {cmd}: warning: {w}", file=sys.stderr)
    m = info["measurement"]
    drift = (
        f", drift {m['offset_rate_N_per_s']:.4g} N/s and {m['gain_rate_per_s']:.4g} 1/s"
        if "offset_rate_N_per_s" in m
        else ""
    )
    print(
        f"grasprom {cmd}: augmented model {path} (sha256 {info['sha256'][:12]}): rendered "
        f"{', '.join(info['rendered']) or 'none'}; measurement-only, not rendered "
        f"{', '.join(info['measurement_only']) or 'none'}"
        + (
            f" (offset {m['offset_N']:.4g} N, gain {m['gain']:.4g}, delay {m['delay_s']:.4g} s"
            f"{drift})"
            if info["measurement_only"]
            else ""
        )
    )
    return params, info


def _cmd_simulate(args: argparse.Namespace) -> int:
    import dataclasses
    import math

    import pandas as pd

    from grasprom.control import ControllerParams, load_params, simulate
    from grasprom.fe.atomicio import atomic_write_bytes

    if args.thickness is not None and not (math.isfinite(args.thickness) and args.thickness > 0):
        return _error("simulate", f"--thickness must be > 0 mm, got {args.thickness}")
    try:
        params = load_params(args.controller) if args.controller else ControllerParams()
        over = {}
        if args.thickness is not None:
            over["thickness_mm"] = args.thickness
        if args.material is not None:
            over["material"] = args.material
        if args.rendering is not None:
            over["rendering"] = args.rendering
        params = dataclasses.replace(params, **over)
        try:
            traj = pd.read_csv(args.trajectory)
        except (OSError, UnicodeDecodeError, pd.errors.ParserError,
                pd.errors.EmptyDataError) as exc:  # fmt: skip
            raise ValueError(f"{args.trajectory}: cannot read trajectory ({exc})") from None
        from grasprom.surrogate import load_surrogate

        sur = load_surrogate(args.surrogate, args.fe)
        aug = None
        if args.augmented:
            params, aug = _augment_params("simulate", args.augmented, params, sur)
        out = simulate(traj, params, sur, source=args.trajectory)
        if aug and aug["measurement_only"]:
            from grasprom.gap import measured_handle_force_N

            out["force_handle_measured_N"] = measured_handle_force_N(
                out["time_s"].to_numpy(), out["force_handle_N"].to_numpy(), aug["measurement"]
            )
        try:
            atomic_write_bytes(args.out, out.to_csv(index=False).encode())
        except OSError as exc:
            raise OSError(f"--out {args.out}: cannot write ({exc.strerror or exc})") from None
    except (OSError, ValueError) as exc:
        return _error("simulate", exc)
    n_warn = int(out["tissue_warning"].sum())
    print(
        f"grasprom simulate: {len(out)} steps at {1 / params.sample_time_s:g} Hz, "
        f"max jaw force {out['force_jaw_N'].max():.3g} N, max handle force "
        f"{out['force_handle_N'].max():.3g} N, tissue warning in {n_warn} steps -> {args.out}"
    )
    return 0


TOL_MAX = 0.1
"""Largest ``--tol`` (a fraction: 10 % of the force scale; beyond that the tables are not a
model of the FE data any more)."""


def _tolerance(text: str) -> float:
    """``--tol``: a fraction in (0, :data:`TOL_MAX`] (argparse type)."""
    import math

    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (math.isfinite(x) and 0.0 < x <= TOL_MAX):
        raise argparse.ArgumentTypeError(
            f"must be a fraction in (0, {TOL_MAX:g}] (0.005 = 0.5 %), got {text}"
        )
    return x


def _error(cmd: str, msg: object) -> int:
    print(f"grasprom {cmd}: error: {msg}", file=sys.stderr)
    return 2


def _cmd_sweep(args: argparse.Namespace, runner=None) -> int:
    from grasprom.fe import CorruptCaseError, SweepInputError, build_grid, default_runner, run_sweep
    from grasprom.fe.grid import check_out_dir
    from grasprom.fe.grid3d import Model3DOptions, check_options, to_2d, to_3d

    opts3d = Model3DOptions(
        args.contact,
        args.friction,
        args.tube_length,
        args.ends,
        args.n_jaw,
        args.n_free,
        args.predict_contact_below,
        args.mesh,
        far_coarsening=args.far_coarsening,
        band_companion=args.band_companion,
    )
    try:
        check_options(args.model, opts3d)
        specs = build_grid(
            args.thickness,
            args.material,
            diameter_mm=args.diameter,
            jaw_length_mm=args.jaw_length,
            closed_gap_mm=args.closed_gap,
            force_cap_N=args.force_cap,
            n_layers=args.n_layers,
            n_circ=args.n_circ,
            grading=args.grading,
            radial_grading=args.radial_grading,
        )
        if args.model == "3d":
            given = {"n_layers": args.n_layers, "n_circ": args.n_circ, "grading": args.grading}
            given["radial_grading"] = args.radial_grading
            mesh = {k: v for k, v in given.items() if v is not None}
            specs = to_3d(specs, opts3d, mesh)
        else:
            specs = to_2d(specs, opts3d)
        if args.workers is not None and args.workers < 1:
            raise SweepInputError(f"--workers: must be a positive integer, got {args.workers}")
        if args.select_from is not None:
            runner = _stored_runner(args, specs)
        check_out_dir(args.out)  # created only once every option is valid
        if not args.quiet:
            print(
                f"grasprom sweep: {len(specs)} cases ({args.model}) -> {args.out}",
                file=sys.stderr,
            )
        summary = run_sweep(
            specs,
            args.out,
            workers=args.workers,
            scheduler=args.scheduler,
            progress=not args.quiet,
            runner=runner or default_runner,
        )
    except (SweepInputError, CorruptCaseError, OSError) as exc:
        return _error("sweep", exc)
    except KeyboardInterrupt:
        print(
            "grasprom sweep: interrupted; finished cases are kept, rerun the same command "
            "to resume",
            file=sys.stderr,
        )
        return 130
    print(summary.format())
    return 0 if summary.ok else 1


def _stored_runner(args: argparse.Namespace, specs):
    """``--select-from``: the runner taking the own runs from that directory, after checking
    every case is there (SweepInputError otherwise)."""
    from grasprom.fe.grid import SweepInputError
    from grasprom.fe.reselect import StoredOwnRuns, check_own_runs

    src = Path(args.select_from)
    if not src.is_dir():
        raise SweepInputError(f"--select-from: {src} is not a directory")
    if src.resolve() == Path(args.out).resolve():
        raise SweepInputError(
            "--select-from: --out must be another directory (its cases will have the "
            "companion's inputs, the source's do not)"
        )
    check_own_runs(specs, src)
    return StoredOwnRuns(str(src.resolve()))  # absolute: workers may run elsewhere


def _cmd_report(args: argparse.Namespace) -> int:
    from grasprom.fe import CorruptCaseError, make_report

    directory = resolve_data_dir(args.directory)
    try:
        files = make_report(directory, args.out, logy=args.logy)
    except (FileNotFoundError, CorruptCaseError) as exc:
        return _error("report", exc)
    print(files.text)
    print(f"\nwrote {files.table_csv} and {files.plot_png}")
    if files.section_pngs:
        print(f"wrote {len(files.section_pngs)} deformed-section figures (sections_*.png)")
    if files.band_png is not None:
        print(f"wrote {files.band_png} (the crease band's companion selection)")
    return 0


def _cmd_surrogate(args: argparse.Namespace) -> int:
    import warnings

    from grasprom.fe import CorruptCaseError
    from grasprom.surrogate import (
        BuildParams,
        Surrogate,
        SurrogateFileError,
        check_passed,
        format_check,
        format_errors,
        plot_surrogate,
    )

    cmd = f"surrogate {args.surrogate_command}"
    code = 0
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            if args.surrogate_command == "build":
                params = BuildParams(tol=args.tol, scheme=args.scheme)
                s = Surrogate.build(args.fe, params=params, holdout_dir=args.holdout)
                out = s.save(args.out)
                print(
                    f"grasprom {cmd}: {s.node_count()} nodes over "
                    f"{sum(len(s.thicknesses(m)) for m in s.materials)} curves, "
                    f"{out.stat().st_size} bytes -> {out}"
                )
                print(format_errors(s.errors["loo"], "leave-one-thickness-out:"))
                if "holdout" in s.errors:
                    print(format_errors(s.errors["holdout"], f"held-out FE ({args.holdout}):"))
            elif args.surrogate_command == "check":
                s = Surrogate.load(args.surrogate)
                print(
                    f"surrogate {args.surrogate}: scheme {s.scheme}, "
                    f"{s.node_count()} nodes, built from {s.source}"
                )
                res = s.check(args.fe)
                print(format_errors(res, f"against FE cases in {args.fe}:"))
                print(format_check(res))
                if not check_passed(res):
                    code = 1
            else:
                s = Surrogate.load(args.surrogate)
                png = plot_surrogate(s, args.out, args.fe)
                print(f"wrote {png}")
        for w in caught:
            print(f"grasprom {cmd}: warning: {w.message}", file=sys.stderr)
    except (FileNotFoundError, CorruptCaseError, SurrogateFileError, ValueError, OSError) as exc:
        return _error(cmd, exc)
    return code


def _add_tune_parser(sub) -> None:
    t = sub.add_parser(
        "tune",
        help="choose the stiffness bound, damping and velocity filter for passivity",
        description="Passivity tuning of the impedance controller over theta x thickness x "
        "material (Colgate, Abbott-Okamura, Z-width, python-control poles/margins, "
        "simulation check). Writes controller.json, tuning.json, tuning.txt and plots.",
    )
    _add_surrogate_source(t)
    t.add_argument(
        "--thickness",
        default=None,
        metavar="MM",
        help="comma list of wall thicknesses in mm (default: every grid thickness)",
    )
    t.add_argument(
        "--material", default=None, help="comma list of materials (default: all in the surrogate)"
    )
    t.add_argument(
        "--rate-hz", type=float, default=1000.0, metavar="HZ", help="controller rate (default 1000)"
    )
    t.add_argument(
        "--controller", default=None, metavar="JSON", help="starting controller parameters"
    )
    t.add_argument(
        "--augmented",
        default=None,
        metavar="JSON",
        help="augmented model of 'grasprom diagnose': tune with its instrument effects rendered "
        "(kept in controller.json)",
    )
    t.add_argument(
        "--safety", type=float, default=1.25, help="required b / b_required (default 1.25)"
    )
    _add_rendering_option(t)
    _add_device_option(t)
    t.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    t.add_argument("--out", default="tuning", metavar="DIR",
                   help="output directory (default tuning)")  # fmt: skip


def _add_rendering_option(p: argparse.ArgumentParser) -> None:
    """``--rendering {coupling,clipped}`` (default: the controller's, else clipped)."""
    p.add_argument(
        "--rendering",
        choices=("coupling", "clipped"),
        default=None,
        help="tissue rendering: coupling (virtual coupling k_c in series) or clipped (the "
        "tissue's own force wherever it is softer than the passive bound K_lim, the stiffest "
        "passive wall beyond); default: that of --controller, else clipped",
    )


def _add_device_option(p: argparse.ArgumentParser) -> None:
    """``--device FILE``: the haptic device (JSON, :func:`grasprom.control.load_device`)."""
    p.add_argument(
        "--device",
        default=None,
        metavar="JSON",
        help="haptic device: JSON with inertia_kg_m2, damping_Nms_per_rad, coulomb_Nm, "
        "torque_constant_Nm_per_A, current_limit_A, delay_samples, encoder_counts_per_rev, "
        "pulley_radius_mm (each optional; default: the documented assumptions of DeviceParams)",
    )


def _load_device_option(path: str | None):
    """The :class:`DeviceParams` of ``--device`` (the defaults without it)."""
    from grasprom.control import DeviceParams, load_device

    return load_device(path) if path else DeviceParams()


def _cmd_tune(args: argparse.Namespace) -> int:
    import dataclasses
    import math
    import warnings

    from grasprom.control import (
        PARAMETER_RANGES,
        ControllerParams,
        apply_device,
        load_params,
        tune,
        write_outputs,
    )
    from grasprom.surrogate import SurrogateFileError

    t_lo, t_hi = PARAMETER_RANGES["sample_time_s"]
    if not (math.isfinite(args.rate_hz) and 1.0 / t_hi <= args.rate_hz <= 1.0 / t_lo):
        return _error("tune", f"--rate-hz must be in [{1 / t_hi:g}, {1 / t_lo:g}] Hz (the "
                      f"controller's sample-time range), got {args.rate_hz}")  # fmt: skip
    if not (math.isfinite(args.safety) and args.safety >= 1.0):
        return _error("tune", f"--safety must be a factor >= 1, got {args.safety}")
    try:
        thick = None
        if args.thickness:
            try:
                thick = [float(v) for v in args.thickness.split(",") if v.strip()]
            except ValueError:
                raise ValueError(
                    f"--thickness: not a comma list of numbers: {args.thickness!r}"
                ) from None
        mats = [m.strip() for m in args.material.split(",") if m.strip()] if args.material else None
        base = load_params(args.controller) if args.controller else ControllerParams()
        base = dataclasses.replace(base, sample_time_s=1.0 / args.rate_hz)
        if args.rendering:
            base = dataclasses.replace(base, rendering=args.rendering)
        device = _load_device_option(args.device)
        if args.device:
            base = apply_device(base, device)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            from grasprom.surrogate import load_surrogate

            sur = load_surrogate(args.surrogate, args.fe)
        aug = None
        if args.augmented:
            base, aug = _augment_params("tune", args.augmented, base, sur)
        result = tune(sur, base, device, thicknesses=thick, materials=mats, safety=args.safety)
        if aug:
            result.summary.setdefault("augmentation", {}).update(aug)
        files = write_outputs(result, args.out, plots=not args.no_plots)
    except (OSError, ValueError, SurrogateFileError) as exc:
        return _error("tune", exc)
    print(result.report())
    print("wrote " + ", ".join(str(f) for f in files.values()))
    return 0


# ---------------------------------------------------------------- export (FMU; Arduino later)
def _add_export_parser(sub) -> None:
    e = sub.add_parser("export", help="export the controller (FMU, Arduino)")
    esub = e.add_subparsers(dest="export_command", required=True, metavar="{fmu,arduino}")
    f = esub.add_parser(
        "fmu",
        help="co-simulation FMU (FMI 2.0 or 3.0), native C",
        description="Write a co-simulation FMU of the impedance controller: native C binary "
        "for this platform (gcc), sources to rebuild elsewhere, documentation.",
    )
    f.add_argument("--out", required=True, metavar="FMU", help="FMU file to write")
    f.add_argument("--fmi", type=int, choices=(2, 3), default=2, help="FMI version (default 2)")
    _add_surrogate_source(f)
    f.add_argument("--params", default=None, metavar="JSON",
                   help="controller parameters, e.g. controller.json of 'grasprom tune' "
                   "(default: the documented defaults, untuned)")  # fmt: skip
    _add_augmented_export(f)
    a = esub.add_parser(
        "arduino",
        help="ATmega328P (Arduino Uno) package: PROGMEM tables, core, sketch, Makefile",
        description="Write the Arduino export: fixed-point tables in PROGMEM generated from the "
        "surrogate for a tolerance, the controller core, an example sketch and an arduino-mk "
        "Makefile; prints the flash/RAM/cycle/error budget (measured with avr-gcc + simavr).",
    )
    a.add_argument("--out", required=True, metavar="DIR", help="output directory")
    _add_surrogate_source(a)
    a.add_argument("--params", default=None, metavar="JSON",
                   help="controller parameters, e.g. controller.json of 'grasprom tune' "
                   "(default: the documented defaults, untuned)")  # fmt: skip
    a.add_argument(
        "--tol",
        type=_tolerance,
        default=0.005,
        help=f"table tolerance, fraction of the largest rendered jaw force, in (0, {TOL_MAX:g}] "
        "(default 0.005: handle-force error within 0.5 %% of the rendered range)",
    )
    a.add_argument(
        "--driver",
        choices=("pwm_dir", "in1_in2", "lap"),
        default=None,
        help="motor bridge inputs: PWM + DIR (default), IN1/IN2 (DRV8871), locked anti-phase "
        "(L298N)",
    )
    a.add_argument(
        "--homing",
        choices=("endstop", "index"),
        default=None,
        help="home on an end-stop switch (default, handle open) or the encoder's index pulse",
    )
    a.add_argument(
        "--pwm-hz",
        type=float,
        default=None,
        metavar="HZ",
        help="motor PWM frequency, 16000 .. 31250 Hz (default 20000)",
    )
    a.add_argument(
        "--firmware",
        default=None,
        metavar="JSON",
        help="firmware configuration: JSON with the fields of FirmwareConfig (pins, "
        "home_count, timeouts, watchdog_ms, baud, ...); --driver/--homing/--pwm-hz win",
    )
    a.add_argument(
        "--float",
        dest="fixed_point",
        action="store_false",
        help="float build instead of Q-format (default: Q-format fixed point)",
    )
    _add_augmented_export(a)


def _add_augmented_export(p) -> None:
    _add_device_option(p)
    p.add_argument(
        "--augmented",
        default=None,
        metavar="JSON",
        help="augmented model of 'grasprom diagnose': render its instrument effects (tissue "
        "scale, thickness, jaw compliance, backlash, friction, viscoelasticity) on top of "
        "--params",
    )


def _firmware_option(args: argparse.Namespace):
    """The :class:`FirmwareConfig` of ``export arduino`` (``--firmware`` JSON + flags)."""
    import dataclasses
    import json

    from grasprom.export.arduino import FirmwareConfig, FirmwareError

    fields: dict = {}
    if args.firmware:
        try:
            with open(args.firmware, encoding="utf-8") as f:
                fields = json.load(f)
        except json.JSONDecodeError as exc:
            raise ValueError(f"--firmware {args.firmware}: not JSON ({exc})") from None
        if not isinstance(fields, dict):
            raise ValueError(f"--firmware {args.firmware}: expected a JSON object")
        known = {f.name for f in dataclasses.fields(FirmwareConfig)}
        unknown = sorted(set(fields) - known)
        if unknown:
            raise ValueError(
                f"--firmware {args.firmware}: unknown field(s) {', '.join(unknown)} "
                f"(known: {', '.join(sorted(known))})"
            )
    for key, val in (("driver", args.driver), ("homing", args.homing), ("pwm_hz", args.pwm_hz)):
        if val is not None:
            fields[key] = val
    try:
        return FirmwareConfig(**fields)
    except FirmwareError as exc:
        where = f"--firmware {args.firmware}" if args.firmware else "firmware"
        raise ValueError(f"{where}: {exc}") from None


def _cmd_export(args: argparse.Namespace) -> int:
    from grasprom.control import ControllerParams, apply_device, load_params

    try:
        params = load_params(args.params) if args.params else ControllerParams()
        if args.device:
            params = apply_device(params, _load_device_option(args.device))
        from grasprom.surrogate import load_surrogate

        sur = load_surrogate(args.surrogate, args.fe)
        if args.augmented:
            params, _ = _augment_params(f"export {args.export_command}", args.augmented, params,
                                        sur)  # fmt: skip
        if args.export_command == "arduino":
            from grasprom.export import export_main

            return export_main(
                args.out,
                surrogate=sur,
                params=params,
                tol=args.tol,
                fixed_point=args.fixed_point,
                firmware=_firmware_option(args),
            )
        from grasprom.export import export_fmu
        from grasprom.export.fmu import write_demo_input

        out = export_fmu(args.out, params, sur, fmi_version=args.fmi)
        demo = write_demo_input(out.with_name(out.stem + "_input.csv"), params, sur)
    except (OSError, ValueError, RuntimeError) as exc:
        return _error(f"export {args.export_command}", exc)
    from grasprom.export.variables import covered_materials

    print(
        f"grasprom export fmu: {out} (FMI {args.fmi}.0 co-simulation, "
        f"{out.stat().st_size / 1024:.0f} KiB, {params.material} {params.thickness_mm:g} mm; "
        f"materials {', '.join(covered_materials(sur))})"
    )
    print(f"  quick look: fmpy simulate {out} --input-file {demo} --show-plot")
    print("  (--show-plot needs plotly: pip install 'grasprom[plot]')")
    return 0


# ---------------------------------------------------------------- build (the main job)
def _add_build_parser(sub) -> None:
    from grasprom.pipeline import STAGES

    b = sub.add_parser(
        "build",
        help="the main job: FE data -> surrogate, tuned controller, FMU, Arduino code, report",
        description="Run the whole pipeline on an FE sweep and write one output folder: "
        "surrogate.json, controller.json, GraspController.fmu (FMI 2.0), "
        "GraspController_fmi3.fmu (FMI 3.0), arduino/, cosim.csv, figures/, report.html "
        f"(self-contained), build.json (provenance). Stages: {', '.join(STAGES)}. A failed "
        "stage is named on stderr (exit 1); what earlier stages wrote is kept.",
    )
    b.add_argument(
        "--fe",
        default=DEFAULT_SWEEP_DIR,
        metavar="DIR",
        help=f"FE sweep (default {DEFAULT_SWEEP_DIR}, the shipped sweep)",
    )
    b.add_argument(
        "--holdout",
        default=DEFAULT_HOLDOUT_DIR,
        metavar="DIR",
        help=f"held-out FE cases for the surrogate error, used if present "
        f"(default {DEFAULT_HOLDOUT_DIR})",
    )
    b.add_argument(
        "--thickness",
        type=float,
        default=1.4,
        metavar="MM",
        help="wall thickness of the exported operating point in mm (default 1.4)",
    )
    b.add_argument("--material", default="mr",
                   help="material of the operating point: mr, nh or le, one the FE sweep has "
                   "(default mr); the outputs cover every material of the sweep")  # fmt: skip
    b.add_argument("--out", default="build", metavar="DIR", help="output folder (default build)")
    b.add_argument(
        "--fast",
        action="store_true",
        help="quick run (tests): coarse tuning grid, no simavr cycle count, short co-simulation",
    )
    b.add_argument("--quiet", action="store_true", help="no per-stage progress on stderr")
    b.add_argument(
        "--augmented",
        default=None,
        metavar="JSON",
        help="augmented model of 'grasprom diagnose': tune, export and co-simulate the "
        "controller with its instrument effects rendered",
    )
    _add_device_option(b)
    b.add_argument(
        "--rendering",
        choices=("coupling", "clipped"),
        default="clipped",
        help="tissue rendering of the tuned controller: clipped (default: the tissue's own "
        "force wherever it is softer than the passive bound, the stiffest passive wall beyond) "
        "or coupling (virtual coupling k_c in series, the earlier scheme)",
    )


def _build_material_error(args: argparse.Namespace, fe_dir: Path) -> str | None:
    """``--material`` not in the sweep ``fe_dir``: what the sweep covers and the command that
    adds the material (None: covered, or a sweep without readable cases, which the surrogate
    stage reports).

    Coverage is that of the case sidecars present (what the surrogate reads), not the cases
    ``sweep.json`` lists: an interrupted or cut-down sweep may list cases it does not hold.
    """
    from grasprom.fe import MATERIAL_NAMES
    from grasprom.fe.datafiles import case_json_paths, parse_stem

    stems = (p.stem for p in case_json_paths(fe_dir))
    cases = [ps for ps in map(parse_stem, stems) if ps is not None]
    found = [m for m in MATERIAL_NAMES if any(c[0] == m for c in cases)]
    if not found or args.material in found:
        return None
    ts = sorted({t for m, t in cases if m in found})
    recorded = ", recorded in its sweep.json" if (fe_dir / "sweep.json").is_file() else ""
    return (
        f"--material {args.material}: the FE sweep {args.fe} covers only "
        f"{', '.join(found)} (thickness {ts[0]:g}-{ts[-1]:g} mm); build with --material "
        f"{found[0]}, or add {args.material} to the sweep: grasprom sweep --material "
        f"{args.material} --thickness {','.join(f'{t:g}' for t in ts)} --out {args.fe} "
        f"(with the model and mesh options the sweep was run with{recorded})"
    )


def _build_inputs_error(args: argparse.Namespace, fe_dir: Path) -> str | None:
    """What is wrong with the inputs of ``build`` before any stage runs (None: nothing); then
    creates ``--out`` (so that a bad input leaves no output folder behind)."""
    if not fe_dir.is_dir():
        return f"--fe {args.fe}: FE sweep directory {fe_dir} does not exist"
    err = _build_material_error(args, fe_dir)
    if err is not None:
        return err
    if args.augmented:
        from grasprom.gap import load_augmented

        try:
            load_augmented(args.augmented)
        except (OSError, ValueError) as exc:
            return f"--augmented {args.augmented}: {exc}"
    try:
        Path(args.out).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        return f"--out {args.out}: cannot create the output folder ({exc.strerror or exc})"
    return None


def _cmd_build(args: argparse.Namespace, argv: Sequence[str]) -> int:
    import math

    from grasprom.fe import MATERIAL_NAMES
    from grasprom.pipeline import BuildOptions, StageError, run_build, summary

    if args.material not in MATERIAL_NAMES:
        return _error("build", f"--material {args.material!r} unknown; valid: "
                      f"{', '.join(MATERIAL_NAMES)}")  # fmt: skip
    if not (math.isfinite(args.thickness) and args.thickness > 0):
        return _error("build", f"--thickness must be > 0 mm, got {args.thickness}")
    if args.device:
        try:
            _load_device_option(args.device)
        except ValueError as exc:
            return _error("build", exc)
    fe_dir = resolve_data_dir(args.fe)
    err = _build_inputs_error(args, fe_dir)
    if err is not None:
        return _error("build", err)
    opts = BuildOptions(
        fe_dir=fe_dir,
        holdout_dir=args.holdout,
        thickness_mm=args.thickness,
        material=args.material,
        out_dir=args.out,
        fast=args.fast,
        command_line=["grasprom", *argv],
        augmented=args.augmented,
        device=args.device,
        rendering=args.rendering,
    )
    try:
        res = run_build(opts, progress=None if args.quiet else sys.stderr)
    except StageError as exc:
        print(f"grasprom build: error: {exc}", file=sys.stderr)
        print(f"grasprom build: outputs of the earlier stages kept in {args.out}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("grasprom build: interrupted; outputs of finished stages kept", file=sys.stderr)
        return 130
    if res.coverage is not None:
        print(f"grasprom build: {res.coverage.statement()}", file=sys.stderr)
    print(summary(res))
    return 0


# ---------------------------------------------------------------- diagnose, synth (own parsers)
def _diagnose_parser() -> argparse.ArgumentParser:
    """Argument parser of ``grasprom diagnose``."""
    p = argparse.ArgumentParser(
        prog="grasprom diagnose",
        description="Diagnose the sim-to-real gap of measured grasp trials: where it lies, "
        "which unmodelled effect causes it, how far it shrinks once added.",
    )
    p.add_argument("trials", nargs="+", metavar="TRIAL.csv",
                   help="trial CSVs: time_s (s), theta_deg (deg), force_handle_N (N), optional "
                   "force_jaw_N (N) and gap_mm (mm); each with a sidecar TRIAL.json giving "
                   "thickness_mm and material")  # fmt: skip
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--surrogate", default=None, metavar="FILE", help="surrogate JSON")
    src.add_argument("--fe", default=None, metavar="DIR", help="FE sweep (default shipped)")
    p.add_argument("--controller", default=None, metavar="FILE", help="controller JSON (chain)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    return p


def _cmd_diagnose(args: argparse.Namespace) -> int:
    """Run ``grasprom diagnose`` on parsed arguments (see :func:`_main_diagnose`)."""
    import warnings

    from grasprom.chain import kinematics as kin
    from grasprom.gap import diagnose, format_summary, load_trial, write_outputs
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
    try:
        paths = write_outputs(diag, args.out, plots=not args.no_plots)
    except OSError as exc:
        print(f"grasprom diagnose: --out {args.out}: cannot write the outputs ({exc})",
              file=sys.stderr)  # fmt: skip
        return 2
    print(format_summary(diag.report))
    wrote = [str(paths["report"])] + ([str(paths["augmented"])] if "augmented" in paths else [])
    print(f"\nwrote {' and '.join(wrote)}")
    return 0


def _main_diagnose(argv: Sequence[str] | None = None) -> int:
    """``grasprom diagnose TRIAL.csv... --out DIR [--surrogate F | --fe DIR] [--controller F]``.

    Returns
    -------
    int
        Exit code: 0 ok, 2 bad input (message naming file/row/column on stderr).
    """
    return _cmd_diagnose(_diagnose_parser().parse_args(argv))


def _synth_parser() -> argparse.ArgumentParser:
    """Argument parser of ``grasprom synth``."""
    from grasprom.gap import SYNTH_EFFECTS

    p = argparse.ArgumentParser(
        prog="grasprom synth",
        description="Synthesise 'real' grasp trials: baseline model + withheld effect(s) + noise.",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument(
        "--effect",
        default="",
        metavar="NAME[,NAME]",
        help=f"effect(s) to add (none = noise only); from {', '.join(SYNTH_EFFECTS)}",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--trials", type=int, default=4, help="number of trials (default 4)")
    p.add_argument("--material", default=None, help="mr, nh or le (default random)")
    p.add_argument("--no-jaw-cell", action="store_true", help="omit the force_jaw_N channel")
    p.add_argument(
        "--gap-channel",
        action="store_true",
        help="add a measured jaw gap gap_mm (laser sensor at the jaw tips, 5-10 um rms)",
    )
    p.add_argument(
        "--tremor",
        type=float,
        default=0.0,
        metavar="DEG",
        help="hand tremor on the handle angle, deg RMS in 6-12 Hz (default 0: none)",
    )
    p.add_argument(
        "--rate-hz",
        type=float,
        default=1000.0,
        metavar="HZ",
        help="sample rate of every channel, Hz, 100 to 20000 (default 1000); the force noise is "
        "white at every sample, and one seed gives the same truth and trial conditions at every "
        "rate",
    )
    src = p.add_mutually_exclusive_group()
    src.add_argument("--surrogate", default=None, metavar="FILE", help="surrogate JSON")
    src.add_argument("--fe", default=None, metavar="DIR", help="FE sweep (default shipped)")
    return p


def _synth_args_error(names: list[str], n_trials: int) -> str | None:
    """What is wrong with the effect names / trial count of ``grasprom synth`` (None: fine)."""
    from grasprom.gap import SYNTH_EFFECTS

    bad = [e for e in names if e not in SYNTH_EFFECTS]
    if bad:
        return f"unknown effect(s) {', '.join(bad)}; valid: {', '.join(SYNTH_EFFECTS)}"
    if len(set(names)) != len(names) or len(names) > 2:
        return "give at most two distinct effects"
    if n_trials < 1:
        return "--trials must be >= 1"
    return None


def _cmd_synth(args: argparse.Namespace) -> int:
    """Run ``grasprom synth`` on parsed arguments (see :func:`_main_synth`)."""
    names = [e.strip() for e in args.effect.split(",") if e.strip()]
    err = _synth_args_error(names, args.trials)
    if err is not None:
        print(f"grasprom synth: {err}", file=sys.stderr)
        return 2
    from grasprom.gap import synth_case, write_case
    from grasprom.surrogate import load_surrogate

    try:
        surrogate = load_surrogate(args.surrogate, args.fe)
        case = synth_case(
            names,
            seed=args.seed,
            n_trials=args.trials,
            surrogate=surrogate,
            material=args.material,
            jaw_load_cell=not args.no_jaw_cell,
            gap_channel=args.gap_channel,
            tremor_deg=args.tremor,
            rate_hz=args.rate_hz,
        )
    except (OSError, ValueError) as exc:
        print(f"grasprom synth: {exc}", file=sys.stderr)
        return 2
    try:
        paths = write_case(case, args.out)
    except OSError as exc:
        print(f"grasprom synth: --out {args.out}: cannot write the trials ({exc})",
              file=sys.stderr)  # fmt: skip
        return 2
    print(
        f"wrote {len(paths)} trial(s) to {args.out} (effects withheld in truth.json: "
        f"{', '.join(names) or 'none'})"
    )
    return 0


def _main_synth(argv: Sequence[str] | None = None) -> int:
    """``grasprom synth --out DIR [--effect NAME[,NAME]] [--seed N] [--trials N] [--gap-channel]``.

    Writes synthetic trials (CSV + JSON sidecars) and the withheld ``truth.json`` into ``DIR``.

    Returns
    -------
    int
        Exit code: 0 ok, 2 bad input (message on stderr).
    """
    return _cmd_synth(_synth_parser().parse_args(argv))


def cli_help_pages(width: int = 100) -> list[tuple[str, str]]:
    """The full ``--help`` text of every command, generated from the live parsers.

    Used by the docs site's CLI reference (``docs/hooks.py``), so that page cannot drift.

    Parameters
    ----------
    width : int
        Terminal width for argparse, columns.

    Returns
    -------
    list of (str, str)
        ``(command, help text)`` pairs: ``"grasprom"`` first, then every subcommand in the
        order of ``grasprom --help`` (nested ones as ``"grasprom export fmu"``).
    """
    import contextlib
    import io
    import os

    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(width)
    try:
        parser = _build_parser()
        pages = [("grasprom", parser.format_help().rstrip())]
        subs = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        for name, sp in subs.choices.items():
            nested = [a for a in sp._actions if isinstance(a, argparse._SubParsersAction)]
            if nested:
                for name2, sp2 in nested[0].choices.items():
                    pages.append((f"grasprom {name} {name2}", sp2.format_help().rstrip()))
            elif name in ("diagnose", "synth"):
                buf = io.StringIO()
                with contextlib.redirect_stdout(buf), contextlib.suppress(SystemExit):
                    _delegated(name)(["--help"])
                pages.append((f"grasprom {name}", buf.getvalue().rstrip()))
            else:
                pages.append((f"grasprom {name}", sp.format_help().rstrip()))
        return pages
    finally:
        if old is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = old


def _chosen_parser(
    parser: argparse.ArgumentParser, args: argparse.Namespace
) -> argparse.ArgumentParser:
    """The innermost (sub)parser ``args`` was parsed with, e.g. that of ``export fmu``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The top-level parser (:func:`_build_parser`).
    args : argparse.Namespace
        What ``parser`` parsed (each subparsers action stores its choice in its ``dest``).

    Returns
    -------
    argparse.ArgumentParser
        The parser of the chosen (nested) subcommand, ``parser`` itself if none was chosen.
    """
    while True:
        subs = (a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        action = next(subs, None)
        chosen = None if action is None else action.choices.get(getattr(args, action.dest, None))
        if chosen is None:
            return parser
        parser = chosen


def main(argv: Sequence[str] | None = None, *, runner=None) -> int:
    """Entry point of the ``grasprom`` command.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments (default ``sys.argv[1:]``).
    runner : callable, optional
        Case runner for ``sweep`` (tests substitute a fake; default the real FE model).

    Returns
    -------
    int
        Exit code: 0 ok, 1 some case failed, 2 bad input, 130 interrupted.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in ("diagnose", "synth"):
        return _delegated(argv[0])(argv[1:])
    parser = _build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:  # the chosen subcommand's usage, not the top-level one (exits 2)
        _chosen_parser(parser, args).error(f"unrecognized arguments: {' '.join(extra)}")
    if args.command == "build":
        return _cmd_build(args, argv)
    if args.command == "sweep":
        return _cmd_sweep(args, runner)
    if args.command == "surrogate":
        return _cmd_surrogate(args)
    if args.command == "simulate":
        return _cmd_simulate(args)
    if args.command == "tune":
        return _cmd_tune(args)
    if args.command == "export":
        return _cmd_export(args)
    if args.command == "identify":
        return _cmd_identify(args)
    return _cmd_report(args)


if __name__ == "__main__":
    sys.exit(main())
