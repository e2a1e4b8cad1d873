"""The six stages of the main job, in order (:data:`STAGES`), and what each one writes.

Every stage is a function ``(opts, res, out, figs) -> None`` (:data:`STAGE_FUNCS`): it reads
the earlier stages' results from the :class:`~grasprom.pipeline.result.BuildResult` ``res``,
writes its artefacts into the output folder ``out`` (figures into ``figs``) and records them in
``res``.  :func:`~grasprom.pipeline.build.run_build` calls them in order.
"""

from __future__ import annotations

import shutil
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from grasprom.pipeline.buildinfo import sha256_path
from grasprom.pipeline.cosim import cosimulate, grasp_settling, plot_cosim
from grasprom.pipeline.options import BuildOptions
from grasprom.pipeline.report import write_report
from grasprom.pipeline.result import BuildResult, Coverage

if TYPE_CHECKING:
    from grasprom.export import ArduinoExport

STAGES = ("surrogate", "tune", "fmu", "arduino", "cosim", "report")
"""Stage names, in order."""

FMU2_NAME = "GraspController.fmu"
FMU3_NAME = "GraspController_fmi3.fmu"


def _stage_surrogate(opts: BuildOptions, res: BuildResult, out: Path, figs: Path) -> None:
    """Build the surrogate, record its :class:`Coverage` (the materials and thicknesses every
    later output covers), check the operating point; ``surrogate.json`` and its figures."""
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
    res.coverage = Coverage.of(s)
    if opts.material not in s.materials:
        raise ValueError(f"--material {opts.material!r} is not in the FE sweep, which covers "
                         f"{', '.join(res.coverage.materials)}")  # fmt: skip
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
    from grasprom.surrogate import plot_residuals

    res.figures["residuals"] = plot_residuals(
        s, figs / "surrogate_residuals.png", res.holdout_dir if res.holdout_dir is not None else fe
    )


def _stage_tune(opts: BuildOptions, res: BuildResult, out: Path, figs: Path) -> None:
    """Tune the controller (with the ``--augmented`` effects, on the ``--device``, in the
    ``--rendering``); ``controller.json``, ``tuning.txt`` and the tuning figures."""
    from grasprom.control import (
        ControllerParams,
        DeviceParams,
        apply_device,
        load_device,
        plot_tuning,
        save_params,
        tune,
    )

    device = load_device(opts.device) if opts.device is not None else DeviceParams()
    base = ControllerParams(
        thickness_mm=opts.thickness_mm, material=opts.material, rendering=opts.rendering
    )
    if opts.device is not None:
        base = apply_device(base, device)
        res.notes.append(f"device {opts.device} (sha256 {sha256_path(opts.device)[:12]})")
    if opts.augmented is not None:
        from grasprom.gap import controller_params_from_augmented, load_augmented

        base, info = controller_params_from_augmented(
            base, load_augmented(opts.augmented), res.surrogate
        )
        res.augmentation = {"file": str(opts.augmented),
                            "sha256": sha256_path(opts.augmented), **info}  # fmt: skip
    kw: dict[str, Any] = {"n_theta": 61, "verify": False} if opts.fast else {}
    result = tune(res.surrogate, base, device, **kw)
    res.tuning = result
    res.params = result.params
    d = result.to_dict()
    save_params(result.params, out / "controller.json", extra={"tuning": d})
    res.files["controller"] = out / "controller.json"
    (out / "tuning.txt").write_text(result.report() + "\n")
    res.files["tuning_txt"] = out / "tuning.txt"
    for key, path in plot_tuning(result, figs).items():
        res.figures[key] = path


def _stage_fmu(opts: BuildOptions, res: BuildResult, out: Path, figs: Path) -> None:
    """Export the FMI 2.0 and FMI 3.0 FMUs."""
    from grasprom.export import export_fmu

    res.files["fmu2"] = export_fmu(out / FMU2_NAME, res.params, res.surrogate, fmi_version=2)
    res.files["fmu3"] = export_fmu(out / FMU3_NAME, res.params, res.surrogate, fmi_version=3)


def _stage_arduino(opts: BuildOptions, res: BuildResult, out: Path, figs: Path) -> None:
    """Export the Arduino package into ``arduino/`` with its budget (``budget.txt``)."""
    from grasprom.export import export_arduino

    ard = export_arduino(
        out / "arduino", surrogate=res.surrogate, params=res.params, measure=not opts.fast
    )
    if opts.fast:
        ard.notes.append("--fast: simavr cycle count and host error run skipped")
        _measure_flash_ram(ard, res)
    res.arduino = ard
    res.files["arduino"] = out / "arduino"
    (out / "arduino" / "budget.txt").write_text(ard.summary() + "\n")


def _measure_flash_ram(ard: ArduinoExport, res: BuildResult) -> None:
    """Flash and RAM (B) of the Arduino tables with avr-gcc/avr-size into ``ard``, or a note."""
    import tempfile

    from grasprom.export import build_tables, measure_size

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


def _stage_cosim(opts: BuildOptions, res: BuildResult, out: Path, figs: Path) -> None:
    """Co-simulate a grasp through the FMI 2 FMU; ``cosim.csv`` and ``figures/cosim.png``."""
    from grasprom.control import DeviceParams, HandParams

    dev = res.tuning.device if res.tuning is not None else DeviceParams()
    hand = res.tuning.hand if res.tuning is not None else HandParams()
    cs = cosimulate(res.files["fmu2"], res.params, res.surrogate, dev, hand, fast=opts.fast)
    cs.settling = grasp_settling(cs, opts.fast)
    res.cosim = cs
    csv = out / "cosim.csv"
    np.savetxt(csv, cs.data, delimiter=",", comments="", header=",".join(cs.columns),
               fmt="%.9g")  # fmt: skip
    res.files["cosim_csv"] = csv
    res.figures["cosim"] = plot_cosim(cs, res.params, figs / "cosim.png")


def _stage_report(opts: BuildOptions, res: BuildResult, out: Path, figs: Path) -> None:
    """Draw the transmission figure; write ``report.html`` and ``build.json``."""
    from grasprom.chain import kinematics as kin
    from grasprom.control import ControllerParams

    chain = (res.params or ControllerParams()).chain_params
    res.figures["transmission"] = kin.plot_transmission(chain, figs / "transmission.png")
    write_report(res, opts)


STAGE_FUNCS: dict[str, Callable[[BuildOptions, BuildResult, Path, Path], None]] = {
    "surrogate": _stage_surrogate,
    "tune": _stage_tune,
    "fmu": _stage_fmu,
    "arduino": _stage_arduino,
    "cosim": _stage_cosim,
    "report": _stage_report,
}
"""Stage name -> its function ``(opts, res, out, figs)``, in the order of :data:`STAGES`."""
