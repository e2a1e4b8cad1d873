"""The main job: one command from FE data to an FMU, Arduino code and a report.

``grasprom build`` (:func:`run_build`) runs six stages on an FE sweep (default: the shipped
``fe_data/default``) and writes everything into one output folder:

1. ``surrogate`` -- :meth:`Surrogate.build` with its leave-one-thickness-out error and, when the
   held-out FE directory exists (default ``fe_data/holdout``), its held-out error; writes
   ``surrogate.json``, ``figures/fe_sweep.png`` (FE curves) and ``figures/surrogate.png``
   (surrogate over the FE points).
2. ``tune`` -- :func:`~grasprom.control.tuning.tune` over every thickness x material of the
   surrogate;
   writes ``controller.json`` (tuned :class:`ControllerParams` at ``--thickness`` /
   ``--material``, report under ``"tuning"``), ``tuning.txt`` and the tuning figures
   (``stiffness_vs_theta.png``, ``zwidth.png``, ``bode_impedance.png``).
3. ``fmu`` -- :func:`grasprom.export.fmu.export_fmu`: ``GraspController.fmu`` (FMI 2.0) and
   ``GraspController_fmi3.fmu`` (FMI 3.0), native C co-simulation.
4. ``arduino`` -- :func:`grasprom.export.arduino.export_arduino` into ``arduino/`` with the budget
   (flash, RAM from avr-gcc/avr-size; cycles from simavr; error against the Python reference).
   With ``fast`` the simavr cycle count and the host error run are skipped; flash and RAM are
   still measured when avr-gcc is installed.
5. ``cosim`` -- a grasp-hold-release through the FMI 2 FMU with fmpy: the handle (inertia and
   viscous friction of :class:`~grasprom.control.tuning.DeviceParams`, end stops) is squeezed by a
   hand
   force profile and pushed back by the motor torque; the FMU's torque is compared with the
   Python reference controller replayed on the same angles.  Writes ``cosim.csv`` and
   ``figures/cosim.png``.
6. ``report`` -- ``report.html`` (self-contained: the PNGs are embedded as base64), with the
   transmission figure ``figures/transmission.png`` (Fg/Fi vs theta), and ``build.json``
   (provenance: versions, FE data hashes, git revision, command line, stage times, artefact
   hashes).

A stage that fails raises :class:`StageError` naming it; what the earlier stages wrote is kept,
and a partial ``report.html`` of the finished stages is written (best effort).

Units: mm, N, N m, s, deg at the interfaces (as in the rest of the package); the FMU's
variables are SI.
"""

from __future__ import annotations

import base64
import datetime as _dt
import hashlib
import html
import json
import math
import platform
import shutil
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np

if TYPE_CHECKING:
    from grasprom.control import ControllerParams, DeviceParams, HandParams, TuningResult
    from grasprom.export import ArduinoExport
    from grasprom.surrogate import Surrogate

from grasprom.paths import DEFAULT_HOLDOUT_DIR, resolve_data_dir

STAGES = ("surrogate", "tune", "fmu", "arduino", "cosim", "report")
"""Stage names, in order."""

FMU2_NAME = "GraspController.fmu"
FMU3_NAME = "GraspController_fmi3.fmu"


class StageError(RuntimeError):
    """A stage of :func:`run_build` failed.

    Parameters
    ----------
    stage : str
        Name of the failed stage (one of :data:`STAGES`).
    message : str
        What went wrong.
    """

    def __init__(self, stage: str, message: str) -> None:
        super().__init__(f"stage '{stage}' failed: {message}")
        self.stage = stage


@dataclass
class BuildOptions:
    """Inputs of :func:`run_build`.

    Parameters
    ----------
    fe_dir : str or Path
        FE sweep directory (default the shipped ``fe_data/default``, found from any directory).
    holdout_dir : str or Path or None
        Held-out FE cases; ignored when the directory does not exist (default the shipped
        ``fe_data/holdout``).
    thickness_mm : float
        Wall thickness of the exported operating point, mm (FMU start value, Arduino sketch
        default, co-simulation).
    material : str
        Material of the operating point: ``mr``, ``nh`` or ``le``.
    out_dir : str or Path
        Output folder (created).
    fast : bool
        Shorter run for tests: coarser tuning grid without the simulation check, no simavr
        cycle measurement nor host error run, shorter co-simulation.
    command_line : sequence of str, optional
        Command line recorded in the provenance block (default ``sys.argv``).
    augmented : str or Path, optional
        Augmented model of ``grasprom diagnose`` (``augmented_model.json``): its instrument
        effects are rendered by the tuned controller, the FMUs and the Arduino package.
    """

    fe_dir: str | Path = "fe_data/default"
    holdout_dir: str | Path | None = DEFAULT_HOLDOUT_DIR
    thickness_mm: float = 1.4
    material: str = "mr"
    out_dir: str | Path = "build"
    fast: bool = False
    command_line: Sequence[str] | None = None
    augmented: str | Path | None = None


@dataclass
class CosimResult:
    """Grasp-hold-release co-simulation through the FMU (see :func:`cosimulate`).

    Attributes
    ----------
    data : numpy.ndarray
        One row per controller step: time (s), handle angle (deg), motor torque (N m), tissue
        force (N), jaw force (N), handle force (N), hand force (N).
    columns : tuple of str
        Column names of ``data``.
    max_torque_diff_Nm : float
        Largest |FMU torque - Python reference torque| over the run, N m.
    wall_s : float
        Wall time of the co-simulation, s.
    """

    data: np.ndarray
    columns: tuple[str, ...]
    max_torque_diff_Nm: float
    wall_s: float

    def col(self, name: str) -> np.ndarray:
        """Column ``name`` of :attr:`data`."""
        return self.data[:, self.columns.index(name)]


@dataclass
class BuildResult:
    """What :func:`run_build` produced (also the state of a partial build).

    Attributes
    ----------
    out_dir : Path
    files : dict of str to Path
        Artefacts written, by key (``surrogate``, ``controller``, ``fmu2``, ``fmu3``,
        ``arduino``, ``cosim_csv``, ``report``, ``build_json``).
    figures : dict of str to Path
        PNG figures, by key.
    stage_times_s : dict of str to float
        Wall time per finished stage, s.
    failed_stage : str or None
        Name of the stage that failed, if any.
    error : str or None
        Its message.
    """

    out_dir: Path
    files: dict[str, Path] = field(default_factory=dict)
    figures: dict[str, Path] = field(default_factory=dict)
    stage_times_s: dict[str, float] = field(default_factory=dict)
    failed_stage: str | None = None
    error: str | None = None
    surrogate: Surrogate | None = None
    tuning: TuningResult | None = None
    params: ControllerParams | None = None
    augmentation: dict[str, Any] | None = None  # mapping info of --augmented
    arduino: ArduinoExport | None = None
    cosim: CosimResult | None = None
    notes: list[str] = field(default_factory=list)
    fe_dir: Path | None = None
    holdout_dir: Path | None = None
    started: str = ""
    total_s: float = 0.0


# ----------------------------------------------------------------------------------- helpers
def sha256_path(path: str | Path) -> str:
    """SHA-256 (hex) of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _versions() -> dict[str, str | None]:
    import importlib

    from grasprom.fe import package_versions

    out = dict(package_versions())
    for mod, name in (("matplotlib", "matplotlib"), ("control", "control"), ("fmpy", "fmpy")):
        try:
            out[name] = str(importlib.import_module(mod).__version__)
        except Exception:  # noqa: BLE001 - best effort provenance
            out[name] = None
    out["platform"] = platform.platform()
    return out


def _tool_version(tool: str) -> str | None:
    import subprocess

    if shutil.which(tool) is None:
        return None
    try:
        res = subprocess.run([tool, "--version"], capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    first = (res.stdout or res.stderr).strip().splitlines()
    return first[0] if first else None


# ----------------------------------------------------------------------------------- stages
def _stage_surrogate(opts: BuildOptions, res: BuildResult, out: Path, figs: Path) -> None:
    from grasprom.fe import plot_sweep
    from grasprom.surrogate import BuildParams, Surrogate, plot_surrogate

    fe = res.fe_dir
    assert fe is not None
    if not fe.is_dir():
        raise FileNotFoundError(f"FE sweep directory {fe} does not exist")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = Surrogate.build(fe, params=BuildParams(), holdout_dir=res.holdout_dir)
    res.notes += [f"surrogate: {w.message}" for w in caught]
    if opts.material not in s.materials:
        raise ValueError(f"--material {opts.material!r} not in the surrogate {list(s.materials)}")
    lo, hi = s.thickness_range(opts.material)
    if not lo <= opts.thickness_mm <= hi:
        raise ValueError(
            f"--thickness {opts.thickness_mm:g} mm outside the swept range [{lo:g}, {hi:g}] mm "
            f"of {opts.material}"
        )
    res.surrogate = s
    res.files["surrogate"] = s.save(out / "surrogate.json")
    res.figures["fe_sweep"] = plot_sweep(fe, figs / "fe_sweep.png", logy=True)
    res.figures["surrogate"] = plot_surrogate(
        s, figs / "surrogate.png", res.holdout_dir if res.holdout_dir is not None else fe
    )


def _stage_tune(opts: BuildOptions, res: BuildResult, out: Path, figs: Path) -> None:
    from grasprom.control import ControllerParams, plot_tuning, save_params, tune

    base = ControllerParams(thickness_mm=opts.thickness_mm, material=opts.material)
    if opts.augmented is not None:
        from grasprom.gap import controller_params_from_augmented, load_augmented

        base, info = controller_params_from_augmented(
            base, load_augmented(opts.augmented), res.surrogate
        )
        res.augmentation = {"file": str(opts.augmented),
                            "sha256": sha256_path(opts.augmented), **info}  # fmt: skip
    kw: dict[str, Any] = {"n_theta": 61, "verify": False} if opts.fast else {}
    result = tune(res.surrogate, base, **kw)
    res.tuning = result
    res.params = result.params
    d = result.to_dict()
    save_params(result.params, out / "controller.json", extra={"tuning": d})
    res.files["controller"] = out / "controller.json"
    res.files["controller"].chmod(0o644)  # save_params writes through mkstemp (0600)
    (out / "tuning.txt").write_text(result.report() + "\n")
    res.files["tuning_txt"] = out / "tuning.txt"
    for key, path in plot_tuning(result, figs).items():
        res.figures[key] = path


def _stage_fmu(opts: BuildOptions, res: BuildResult, out: Path, figs: Path) -> None:
    from grasprom.export import export_fmu

    res.files["fmu2"] = export_fmu(out / FMU2_NAME, res.params, res.surrogate, fmi_version=2)
    res.files["fmu3"] = export_fmu(out / FMU3_NAME, res.params, res.surrogate, fmi_version=3)


def _stage_arduino(opts: BuildOptions, res: BuildResult, out: Path, figs: Path) -> None:
    import tempfile

    from grasprom.export import build_tables, export_arduino, measure_size

    ard = export_arduino(
        out / "arduino", surrogate=res.surrogate, params=res.params, measure=not opts.fast
    )
    if opts.fast:
        ard.notes.append("--fast: simavr cycle count and host error run skipped")
        if shutil.which("avr-gcc") and shutil.which("avr-size"):
            tables = build_tables(res.surrogate, res.params, ard.tol, fixed_point=ard.fixed_point)
            with tempfile.TemporaryDirectory(prefix="grasprom_build_") as tmp:
                sz = measure_size(tables, Path(tmp))
            ard.flash_B, ard.ram_B = sz.flash_B, sz.ram_B
        else:
            ard.notes.append(
                "flash/RAM not measured: avr-gcc/avr-size not found "
                "(Debian: apt-get install gcc-avr avr-libc binutils-avr)"
            )
    res.arduino = ard
    res.files["arduino"] = out / "arduino"
    (out / "arduino" / "budget.txt").write_text(ard.summary() + "\n")


def _stage_cosim(opts: BuildOptions, res: BuildResult, out: Path, figs: Path) -> None:
    from grasprom.control import DeviceParams, HandParams

    dev = res.tuning.device if res.tuning is not None else DeviceParams()
    hand = res.tuning.hand if res.tuning is not None else HandParams()
    cs = cosimulate(res.files["fmu2"], res.params, res.surrogate, dev, hand, fast=opts.fast)
    res.cosim = cs
    csv = out / "cosim.csv"
    np.savetxt(csv, cs.data, delimiter=",", comments="", header=",".join(cs.columns),
               fmt="%.9g")  # fmt: skip
    res.files["cosim_csv"] = csv
    res.figures["cosim"] = plot_cosim(cs, res.params, figs / "cosim.png")


def _stage_report(opts: BuildOptions, res: BuildResult, out: Path, figs: Path) -> None:
    from grasprom.chain import kinematics as kin
    from grasprom.control import ControllerParams

    chain = (res.params or ControllerParams()).chain_params
    res.figures["transmission"] = kin.plot_transmission(chain, figs / "transmission.png")
    write_report(res, opts)


_STAGE_FUNCS: dict[str, Callable[[BuildOptions, BuildResult, Path, Path], None]] = {
    "surrogate": _stage_surrogate,
    "tune": _stage_tune,
    "fmu": _stage_fmu,
    "arduino": _stage_arduino,
    "cosim": _stage_cosim,
    "report": _stage_report,
}


# ----------------------------------------------------------------------------------- co-simulation
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
    (``device``) and end stops at the chain's range, squeezed by the hand (force ``F_hand(t)``
    at the grip radius ``L3``, plus the finger's mass and damping from ``hand``, reflected to the
    pivot: ``J_h = m L3^2``, ``b_h = c L3^2``) and pushed open by the FMU's rendered handle force:
    ``(J + J_h) theta'' = L3 (force_handle - F_hand) - (b + b_h) theta'``, integrated with
    semi-implicit Euler at
    ``substeps`` per controller step; the FMU is stepped at its sample time with the angle at
    the communication point.  The Python
    :class:`~grasprom.control.controller.ImpedanceController` is
    stepped on the same angles for comparison.

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
        Finger mass (kg) and damping (N s/m) at the grip; default none (a pure force source).
    fast : bool
        Shorter profile (ramp 0.4 s, hold 0.6 s, release 0.3 s, rest 0.5 s instead of
        1 / 2 / 0.5 / 1 s).
    peak_hand_N : float
        Hold force of the hand at the grip, N.
    substeps : int
        Device integration steps per controller step.

    Returns
    -------
    CosimResult
    """
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    from grasprom.control import ImpedanceController

    t_wall = time.perf_counter()
    ramp, hold, release, rest = (0.4, 0.6, 0.3, 0.5) if fast else (1.0, 2.0, 0.5, 1.0)
    T = params.sample_time_s
    n = int(round((ramp + hold + release + rest) / T))
    chain = params.chain_params
    L3 = chain.L3_mm * 1e-3
    th_lo = math.radians(chain.theta_closed_deg)
    th_hi = math.radians(chain.theta_open_deg)
    J, b = device.inertia_kg_m2, device.damping_Nms_per_rad
    if hand is not None:
        J_h, b_h, _k_h = hand.at_pivot(chain.L3_mm)
        J, b = J + J_h, b + b_h

    md = read_model_description(str(fmu_path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzip = extract(str(fmu_path))
    fmu = FMU2Slave(
        guid=md.guid,
        unzipDirectory=unzip,
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName="build",
    )
    ref = ImpedanceController(params, surrogate)
    names = ["torque", "force_tissue", "force_jaw", "force_handle"]
    out_vr = [vr[k] for k in names]
    rec = np.zeros((n, 7))
    diff = 0.0
    try:
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        theta, omega = th_hi, 0.0
        dt = T / substeps
        for k in range(n):
            t = k * T
            fmu.setReal([vr["theta"]], [theta])
            fmu.doStep(t, T)
            torque, f_tissue, f_jaw, f_handle = fmu.getReal(out_vr)
            diff = max(diff, abs(torque - ref.step(theta).torque_Nm))
            hand = hand_force_N(t, ramp, hold, release, peak_hand_N)
            for _ in range(substeps):
                omega += (L3 * (f_handle - hand) - b * omega) / J * dt
                theta += omega * dt
                if theta < th_lo or theta > th_hi:  # end stops
                    theta = min(max(theta, th_lo), th_hi)
                    omega = 0.0
            rec[k] = (t + T, math.degrees(theta), torque, f_tissue, f_jaw, f_handle, hand)
        fmu.terminate()
    finally:
        fmu.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)
    cols = ("time_s", "theta_deg", "torque_Nm", "force_tissue_N", "force_jaw_N",
            "force_handle_N", "hand_N")  # fmt: skip
    return CosimResult(rec, cols, diff, time.perf_counter() - t_wall)


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


# ----------------------------------------------------------------------------------- report
_FIGURES = (
    ("fe_sweep", "FE sweep: force vs jaw gap (full stroke, log axis; zoom on the walls meeting)"),
    (
        "surrogate",
        "Surrogate (lines) over FE points (held-out cases when available): force, "
        "zoom on wall contact, stiffness",
    ),
    ("transmission", "Fg/Fi vs handle angle theta: derived chain and seed formula"),
    (
        "stiffness",
        "Rendered and raw-tissue stiffness at the handle pivot vs theta, with the passive bound",
    ),
    ("zwidth", "Z-width: passive (K, B) set and the operating points"),
    ("bode", "Rendered impedance at the stiffest point vs the ideal K/s + B"),
    ("cosim", "Grasp-hold-release co-simulated through the FMU (fmpy)"),
)


def _img(path: Path, alt: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return (
        f'<figure><img alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'
        f"<figcaption>{html.escape(path.name)}: {html.escape(alt)}</figcaption></figure>"
    )


def _table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    th = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows
    )
    return f"<table><tr>{th}</tr>{body}</table>"


def _fmt(v: Any, spec: str = ".3g") -> str:
    if v is None:
        return "n/a"
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)
    return format(v, spec)


def error_rows(fig: dict[str, Any]) -> list[list[str]]:
    """Rows (scheme, range, material, F rms %, F max %, gap rms mm, gap max mm) of error figures.

    Parameters
    ----------
    fig : dict
        Output of :meth:`Surrogate.check` or :func:`grasprom.surrogate.leave_one_out`.

    Returns
    -------
    list of list of str
    """
    rows = []
    for sc, fg in fig.get("schemes", {}).items():
        for rng in ("haptic", "full"):
            for mat in sorted(fg.get(rng, {}), key=lambda k: (k == "all", k)):
                r = fg[rng][mat]
                rows.append([sc, rng, mat, _fmt(r["force_rms_pct"], ".3f"),
                             _fmt(r["force_max_pct"], ".3f"), _fmt(r["gap_rms_mm"], ".4f"),
                             _fmt(r["gap_max_mm"], ".4f")])  # fmt: skip
    return rows


def provenance(res: BuildResult, opts: BuildOptions) -> dict[str, Any]:
    """Provenance block of a build: versions, hashes, git revision, command line, timings.

    Parameters
    ----------
    res : BuildResult
    opts : BuildOptions

    Returns
    -------
    dict
    """
    from grasprom.fe import git_revision
    from grasprom.surrogate import fe_dir_hash

    def dir_hash(d: Path | None) -> str | None:
        if d is None or not d.is_dir():
            return None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return fe_dir_hash(d)
        except Exception:  # noqa: BLE001 - provenance must not fail the report
            return None

    artefacts = {}
    for key, p in res.files.items():
        if p.is_file() and key not in ("report", "build_json"):
            artefacts[p.name] = sha256_path(p)
    return {
        "command_line": list(opts.command_line if opts.command_line is not None else sys.argv),
        "started": res.started,
        "options": {
            "fe_dir": str(res.fe_dir),
            "holdout_dir": None if res.holdout_dir is None else str(res.holdout_dir),
            "thickness_mm": opts.thickness_mm,
            "material": opts.material,
            "out_dir": str(res.out_dir),
            "fast": opts.fast,
            "augmented": None if opts.augmented is None else str(opts.augmented),
        },
        "augmentation": res.augmentation,
        "fe_hash": getattr(res.surrogate, "fe_hash", None) or dir_hash(res.fe_dir),
        "holdout_fe_hash": dir_hash(res.holdout_dir),
        "versions": _versions(),
        "tools": {t: _tool_version(t) for t in ("gcc", "avr-gcc")}
        | {"simavr": shutil.which("simavr")},
        **git_revision(),
        "stage_times_s": dict(res.stage_times_s),
        "total_s": res.total_s,
        "failed_stage": res.failed_stage,
        "error": res.error,
        "artefact_sha256": artefacts,
    }


def write_report(res: BuildResult, opts: BuildOptions) -> Path:
    """Write ``report.html`` (figures embedded as base64 PNG) and ``build.json``.

    Works on a partial build: sections of the stages that did not run are left out and the
    failed stage is named at the top.

    Parameters
    ----------
    res : BuildResult
    opts : BuildOptions

    Returns
    -------
    Path
        The HTML report.
    """
    from grasprom import __version__

    out = res.out_dir
    prov = provenance(res, opts)
    parts = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'>",
        "<title>grasprom build report</title><style>body{font-family:sans-serif;"
        "max-width:1100px;margin:auto}table{border-collapse:collapse;margin:0.5em 0}"
        "td,th{border:1px solid #bbb;padding:2px 6px;text-align:right}"
        "img{max-width:100%}pre{background:#f4f4f4;padding:6px;overflow-x:auto}"
        ".fail{color:#b00}</style></head><body>",
        f"<h1>grasprom build report</h1><p>grasprom {html.escape(__version__)}, "
        f"{html.escape(res.started)}; operating point {html.escape(opts.material)} "
        f"{opts.thickness_mm:g} mm{' (--fast)' if opts.fast else ''}.</p>",
    ]
    if res.failed_stage:
        parts.append(f"<p class='fail'><b>Build failed at stage '{res.failed_stage}'</b>: "
                     f"{html.escape(str(res.error))}. Sections of later stages are missing."
                     "</p>")  # fmt: skip
    parts.append(
        "<h2>Stages</h2>"
        + _table(
            ["stage", "wall time (s)"],
            [[k, f"{v:.1f}"] for k, v in res.stage_times_s.items()]
            + ([[res.failed_stage, "FAILED"]] if res.failed_stage else []),
        )
    )
    files = [[k, str(p.relative_to(out)) if p.is_relative_to(out) else str(p)]
             for k, p in res.files.items()]  # fmt: skip
    parts.append("<h2>Artefacts</h2>" + _table(["artefact", "path"], files))
    figs = res.figures
    s = res.surrogate
    if s is not None:
        parts.append("<h2>FE data and surrogate</h2>")
        parts.append(f"<p>FE sweep {html.escape(str(res.fe_dir))}: materials "
                     f"{', '.join(s.materials)}, {s.node_count()} surrogate nodes, scheme "
                     f"{s.scheme}.</p>")  # fmt: skip
        for key in ("fe_sweep", "surrogate"):
            if key in figs:
                parts.append(_img(figs[key], dict(_FIGURES)[key]))
        hdr = ["scheme", "range", "material", "F rms %FS", "F max %FS", "gap rms mm",
               "gap max mm"]  # fmt: skip
        if "holdout" in s.errors:
            parts.append(f"<h3>Held-out error ({html.escape(str(res.holdout_dir))})</h3>")
            parts.append(_table(hdr, error_rows(s.errors["holdout"])))
        else:
            parts.append("<p>No held-out FE directory: only the leave-one-out error.</p>")
        parts.append("<h3>Leave-one-thickness-out error</h3>")
        parts.append(_table(hdr, error_rows(s.errors.get("loo", {}))))
        parts.append("<p>F: force error at equal gap, % of full scale (haptic: 20 N, full: the "
                     "force cap) where the FE stiffness is below the steep limit; gap: gap error "
                     "at equal force where steeper.</p>")  # fmt: skip
    if "transmission" in figs:
        parts.append(
            "<h2>Kinematic chain</h2>" + _img(figs["transmission"], dict(_FIGURES)["transmission"])
        )
    if res.tuning is not None:
        sm = res.tuning.summary
        c = sm["chosen"]
        parts.append("<h2>Controller tuning</h2>")
        if res.augmentation is not None:
            a = res.augmentation
            parts.append(
                f"<p>Augmented model {html.escape(a['file'])} (sha256 {a['sha256'][:12]}): "
                f"rendered {html.escape(', '.join(a['rendered']) or 'none')}; measurement-only "
                f"(not rendered) {html.escape(', '.join(a['measurement_only']) or 'none')}.</p>"
            )
        parts.append(
            _table(
                ["quantity", "value"],
                [
                    ["coupling stiffness k_c (N/mm)", _fmt(c["coupling_stiffness_N_per_mm"])],
                    ["virtual damping B (N m s/rad)", _fmt(c["damping_Nms_per_rad"], ".4g")],
                    ["velocity cutoff (Hz)", _fmt(c["velocity_cutoff_Hz"])],
                    ["largest rendered stiffness (N m/rad)", _fmt(sm["max_rendered_K_Nm_per_rad"])],
                    ["passive stiffness bound (N m/rad)", _fmt(sm["passive_stiffness_Nm_per_rad"])],
                    ["passivity margin b / b_required", _fmt(sm["passivity_margin"])],
                    ["passive everywhere", str(sm["passive_everywhere"])],
                    [
                        "closed loop with hand: max |pole|",
                        _fmt(sm["closed_loop_with_hand"]["max_pole_mag"], ".5f"),
                    ],
                ],
            )
        )
        parts.append(f"<pre>{html.escape(res.tuning.report())}</pre>")
        for key in ("zwidth", "stiffness", "bode"):
            if key in figs:
                parts.append(_img(figs[key], dict(_FIGURES)[key]))
    if "fmu2" in res.files:
        parts.append(
            "<h2>FMU</h2>"
            + _table(
                ["file", "FMI", "size (KiB)"],
                [
                    [res.files[k].name, v, f"{res.files[k].stat().st_size / 1024:.0f}"]
                    for k, v in (("fmu2", "2.0"), ("fmu3", "3.0"))
                    if k in res.files
                ],
            )
        )
    if res.cosim is not None:
        cs = res.cosim
        parts.append("<h2>Co-simulated grasp</h2>")
        parts.append(
            f"<p>{len(cs.data)} steps at {1 / res.params.sample_time_s:g} Hz; min handle "
            f"angle {cs.col('theta_deg').min():.2f} deg, max jaw force "
            f"{cs.col('force_jaw_N').max():.2f} N, max motor torque "
            f"{cs.col('torque_Nm').max():.3f} N m; FMU vs Python reference torque: "
            f"max |diff| {cs.max_torque_diff_Nm:.2e} N m; {cs.wall_s:.1f} s.</p>"
        )
        if "cosim" in figs:
            parts.append(_img(figs["cosim"], dict(_FIGURES)["cosim"]))
    if res.arduino is not None:
        from grasprom.export import CYCLE_BUDGET, ERROR_BUDGET, FLASH_BUDGET_B, RAM_BUDGET_B

        a = res.arduino
        parts.append(
            "<h2>Arduino budget (ATmega328P)</h2>"
            + _table(
                ["figure", "measured", "budget"],
                [
                    ["flash tables + core (B)", _fmt(a.flash_B, "d"), FLASH_BUDGET_B],
                    ["RAM static + step stack (B)", _fmt(a.ram_B, "d"), RAM_BUDGET_B],
                    ["cycles per step, max", _fmt(a.cycles_max, "d"), CYCLE_BUDGET],
                    [
                        "handle-force error (% FS)",
                        _fmt(a.error_handle_pct_fs, ".3f"),
                        f"{100 * ERROR_BUDGET:g}",
                    ],
                    ["jaw-force error (% of jaw FS)", _fmt(a.error_jaw_pct_fs, ".3f"), ""],
                    ["tables (B)", a.table_bytes, ""],
                    ["grid nodes", ", ".join(f"{k} {v}" for k, v in a.grid_nodes.items()), ""],
                ],
            )
        )
        if a.notes:
            parts.append("<ul>" + "".join(f"<li>{html.escape(n)}</li>" for n in a.notes) + "</ul>")
    if res.notes:
        parts.append(
            "<h2>Notes</h2><ul>"
            + "".join(f"<li>{html.escape(n)}</li>" for n in res.notes)
            + "</ul>"
        )
    parts.append("<h2>Provenance</h2><pre>" + html.escape(json.dumps(prov, indent=2)) + "</pre>")
    parts.append("</body></html>")
    path = out / "report.html"
    path.write_text("\n".join(parts))
    res.files["report"] = path
    (out / "build.json").write_text(json.dumps(
        {"format": "grasprom-build", "format_version": 1, "provenance": prov,
         "results": results(res),
         "figures": {k: str(p.relative_to(out)) for k, p in figs.items()},
         "files": {k: str(p.relative_to(out)) for k, p in res.files.items()}},
        indent=2, default=str))  # fmt: skip
    res.files["build_json"] = out / "build.json"
    return path


def results(res: BuildResult) -> dict[str, Any]:
    """Headline figures of a (possibly partial) build, JSON-ready (units in the key names).

    Parameters
    ----------
    res : BuildResult

    Returns
    -------
    dict
        ``surrogate`` (held-out / leave-one-out haptic errors, aligned scheme), ``tuning``
        (chosen parameters, passivity margin), ``fmu`` (file sizes), ``arduino`` (budget
        figures), ``cosim`` (peaks, FMU vs Python torque difference).
    """
    out: dict[str, Any] = {}
    s = res.surrogate
    if s is not None:
        err = {}
        for key in ("holdout", "loo"):
            fig = s.errors.get(key, {}).get("schemes", {}).get(s.scheme)
            if fig:
                err[key] = fig["haptic"]["all"]
        out["surrogate"] = {"nodes": s.node_count(), "scheme": s.scheme, "fe_hash": s.fe_hash,
                            "haptic_error": err}  # fmt: skip
    if res.tuning is not None:
        sm = res.tuning.summary
        out["tuning"] = {**sm["chosen"], "passivity_margin": sm["passivity_margin"],
                         "passive_everywhere": sm["passive_everywhere"],
                         "max_rendered_K_Nm_per_rad": sm["max_rendered_K_Nm_per_rad"],
                         "passive_stiffness_Nm_per_rad":
                             sm["passive_stiffness_Nm_per_rad"]}  # fmt: skip
    fm = {k: res.files[k].stat().st_size for k in ("fmu2", "fmu3") if k in res.files}
    if fm:
        out["fmu"] = {f"{k}_bytes": v for k, v in fm.items()}
    if res.arduino is not None:
        a = res.arduino
        out["arduino"] = {"flash_B": a.flash_B, "ram_B": a.ram_B, "cycles_max": a.cycles_max,
                          "cycles_mean": a.cycles_mean,
                          "error_handle_pct_fs": a.error_handle_pct_fs,
                          "error_jaw_pct_fs": a.error_jaw_pct_fs, "table_bytes": a.table_bytes,
                          "within_budget": a.within_budget(), "notes": list(a.notes)}  # fmt: skip
    if res.cosim is not None:
        cs = res.cosim
        out["cosim"] = {"steps": len(cs.data), "min_theta_deg": float(cs.col("theta_deg").min()),
                        "max_force_jaw_N": float(cs.col("force_jaw_N").max()),
                        "max_torque_Nm": float(cs.col("torque_Nm").max()),
                        "max_torque_diff_vs_python_Nm": cs.max_torque_diff_Nm}  # fmt: skip
    return out


# ----------------------------------------------------------------------------------- driver
def run_build(
    opts: BuildOptions,
    *,
    progress: TextIO | None = sys.stderr,
    stages: Sequence[str] = STAGES,
) -> BuildResult:
    """Run the main job; see the module docstring.

    Parameters
    ----------
    opts : BuildOptions
    progress : text stream or None
        Where the per-stage progress lines go (stage name, wall time); None for quiet.
    stages : sequence of str
        Stages to run (default all, in order; a later stage needs the earlier ones).

    Returns
    -------
    BuildResult

    Raises
    ------
    StageError
        A stage failed; its ``stage`` attribute names it.  Files of earlier stages are kept
        and a partial report is written (best effort).
    """
    out = Path(opts.out_dir)
    res = BuildResult(out_dir=out)
    res.started = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    res.fe_dir = resolve_data_dir(opts.fe_dir)
    if opts.holdout_dir is not None:
        hd = resolve_data_dir(opts.holdout_dir)
        res.holdout_dir = hd if hd.is_dir() else None
        if res.holdout_dir is None:
            res.notes.append(f"held-out FE directory {opts.holdout_dir} not found: "
                             "held-out error not computed")  # fmt: skip
    t_all = time.perf_counter()
    figs = out / "figures"

    def say(msg: str) -> None:
        if progress is not None:
            print(msg, file=progress, flush=True)

    todo = [s for s in STAGES if s in stages]
    for i, name in enumerate(todo, 1):
        say(f"[{i}/{len(todo)}] {name} ...")
        t0 = time.perf_counter()
        try:
            out.mkdir(parents=True, exist_ok=True)
            figs.mkdir(exist_ok=True)
            _STAGE_FUNCS[name](opts, res, out, figs)
        except KeyboardInterrupt:
            raise
        except Exception as exc:  # noqa: BLE001 - every failure is reported with its stage
            res.failed_stage = name
            res.error = f"{type(exc).__name__}: {exc}".strip()
            res.total_s = time.perf_counter() - t_all
            if name != "report":
                try:
                    write_report(res, opts)
                except Exception:  # noqa: BLE001 - the partial report is best effort
                    pass
            raise StageError(name, res.error) from exc
        res.stage_times_s[name] = time.perf_counter() - t0
        say(f"[{i}/{len(todo)}] {name} done in {res.stage_times_s[name]:.1f} s")
    res.total_s = time.perf_counter() - t_all
    if "report" in todo:  # rewrite build.json with the report stage's time included
        write_report(res, opts)
    return res


def summary(res: BuildResult) -> str:
    """One paragraph on a finished build: artefacts and headline figures."""
    lines = [f"grasprom build: {res.total_s:.1f} s -> {res.out_dir}"]
    if res.tuning is not None:
        sm = res.tuning.summary
        lines.append(f"  controller: k_c = {sm['chosen']['coupling_stiffness_N_per_mm']:g} N/mm, "
                     f"passivity margin {sm['passivity_margin']:.3g}")  # fmt: skip
    if res.augmentation is not None:
        lines.append(f"  augmented model {res.augmentation['file']}: rendered "
                     f"{', '.join(res.augmentation['rendered']) or 'none'}")  # fmt: skip
    if res.arduino is not None:
        a = res.arduino
        lines.append(f"  arduino: flash {_fmt(a.flash_B, 'd')} B, RAM {_fmt(a.ram_B, 'd')} B, "
                     f"cycles {_fmt(a.cycles_max, 'd')}, handle-force error "
                     f"{_fmt(a.error_handle_pct_fs, '.3f')} % FS")  # fmt: skip
    if res.cosim is not None:
        lines.append(
            f"  co-simulation: max jaw force {res.cosim.col('force_jaw_N').max():.2f} N,"
            f" FMU vs Python torque {res.cosim.max_torque_diff_Nm:.1e} N m"
        )
    for key in ("surrogate", "controller", "fmu2", "fmu3", "arduino", "report"):
        if key in res.files:
            lines.append(f"  {key:10s} {res.files[key]}")
    return "\n".join(lines)
