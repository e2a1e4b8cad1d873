"""Result objects of the main job: :class:`BuildResult` (also the state of a partial build),
:class:`CosimResult` (the co-simulated grasp) and :func:`results`, their headline figures."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from grasprom.control import ControllerParams, TuningResult
    from grasprom.export import ArduinoExport
    from grasprom.surrogate import Surrogate


@dataclass(frozen=True)
class Coverage:
    """Which materials and wall thicknesses the outputs of a build cover: those of its FE sweep
    (the surrogate, the tuned controller, the FMUs' ``Material`` enumeration and tables, the
    Arduino tables).

    Parameters
    ----------
    materials : tuple of str
        Covered materials in :data:`grasprom.fe.MATERIAL_NAMES` order.
    thickness_mm : tuple of tuple of float
        Per covered material (same order), its swept thickness nodes, mm ascending; thickness
        is interpolated between them and clamped outside.
    """

    materials: tuple[str, ...]
    thickness_mm: tuple[tuple[float, ...], ...]

    @classmethod
    def of(cls, surrogate: Surrogate) -> Coverage:
        """The coverage of a surrogate (its materials and thickness nodes)."""
        from grasprom.export.variables import covered_materials

        mats = covered_materials(surrogate)
        return cls(mats, tuple(tuple(float(t) for t in surrogate.thicknesses(m)) for m in mats))

    @property
    def missing(self) -> tuple[str, ...]:
        """Materials of :data:`grasprom.fe.MATERIAL_NAMES` the outputs do not cover."""
        from grasprom.fe import MATERIAL_NAMES

        return tuple(m for m in MATERIAL_NAMES if m not in self.materials)

    def statement(self) -> str:
        """One sentence (for stderr and the report): the materials and thickness ranges (mm)
        covered, and what is left out."""
        parts = [f"{m} {ts[0]:g}-{ts[-1]:g} mm ({len(ts)} FE thicknesses)"
                 for m, ts in zip(self.materials, self.thickness_mm)]  # fmt: skip
        text = "outputs cover material " if len(parts) == 1 else "outputs cover materials "
        text += ", ".join(parts)
        if self.missing:
            text += (f"; not {', '.join(self.missing)} (not in the FE sweep: the FMUs and the "
                     "Arduino firmware refuse them)")  # fmt: skip
        return text

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``materials``, ``thickness_mm`` (the union of the thickness nodes, mm),
        ``thickness_mm_by_material``, ``thickness_range_mm`` (per material, [min, max] mm),
        ``missing_materials`` and ``statement``."""
        by = dict(zip(self.materials, (list(ts) for ts in self.thickness_mm)))
        return {
            "materials": list(self.materials),
            "thickness_mm": sorted({t for ts in self.thickness_mm for t in ts}),
            "thickness_mm_by_material": by,
            "thickness_range_mm": {m: [ts[0], ts[-1]] for m, ts in by.items()},
            "missing_materials": list(self.missing),
            "statement": self.statement(),
        }


@dataclass
class CosimResult:
    """Grasp-hold-release co-simulation through the FMU (see
    :func:`~grasprom.pipeline.cosimulate`).

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
    settling : dict or None
        Overshoot of the rendered handle force over the settled hold
        (:func:`~grasprom.pipeline.cosim.grasp_settling`), set by the build.
    """

    data: np.ndarray
    columns: tuple[str, ...]
    max_torque_diff_Nm: float
    wall_s: float
    settling: dict[str, Any] | None = None

    def col(self, name: str) -> np.ndarray:
        """Column ``name`` of :attr:`data`."""
        return self.data[:, self.columns.index(name)]


@dataclass
class BuildResult:
    """What :func:`~grasprom.pipeline.run_build` produced (also the state of a partial build).

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
    coverage : Coverage or None
        Materials and thicknesses the outputs cover (set by the surrogate stage).
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
    coverage: Coverage | None = None


def results(res: BuildResult) -> dict[str, Any]:
    """Headline figures of a (possibly partial) build, JSON-ready (units in the key names).

    Parameters
    ----------
    res : BuildResult

    Returns
    -------
    dict
        ``coverage`` (:meth:`Coverage.to_dict`: the materials and thicknesses the outputs
        cover), ``surrogate`` (held-out / leave-one-out haptic errors, aligned scheme), ``tuning``
        (chosen parameters, passivity margin), ``fmu`` (file sizes), ``arduino`` (budget
        figures), ``cosim`` (peaks, FMU vs Python torque difference).
    """
    out: dict[str, Any] = {}
    if res.coverage is not None:
        out["coverage"] = res.coverage.to_dict()
    if res.surrogate is not None:
        out["surrogate"] = _surrogate_figures(res.surrogate)
    if res.tuning is not None:
        out["tuning"] = _tuning_figures(res.tuning)
    fm = {k: res.files[k].stat().st_size for k in ("fmu2", "fmu3") if k in res.files}
    if fm:
        out["fmu"] = {f"{k}_bytes": v for k, v in fm.items()}
    if res.arduino is not None:
        out["arduino"] = _arduino_figures(res.arduino)
    if res.cosim is not None:
        out["cosim"] = _cosim_figures(res.cosim)
    return out


def _surrogate_figures(s: Surrogate) -> dict[str, Any]:
    """Node count, scheme, FE hash and haptic errors (held-out, leave-one-out, %FS / mm)."""
    err = {}
    for key in ("holdout", "loo"):
        fig = s.errors.get(key, {}).get("schemes", {}).get(s.scheme)
        if fig:
            err[key] = fig["haptic"]["all"]
    return {"nodes": s.node_count(), "scheme": s.scheme, "fe_hash": s.fe_hash,
            "haptic_error": err}  # fmt: skip


def _tuning_figures(tuning: TuningResult) -> dict[str, Any]:
    """Chosen controller parameters, the passivity figures of a tuning, the closed-loop
    target with the hand and the transparency ratios per case."""
    sm = tuning.summary
    out = {**sm["chosen"], "passivity_margin": sm["passivity_margin"],
           "passive_everywhere": sm["passive_everywhere"],
           "max_rendered_K_Nm_per_rad": sm["max_rendered_K_Nm_per_rad"],
           "passive_stiffness_Nm_per_rad": sm["passive_stiffness_Nm_per_rad"]}  # fmt: skip
    om = sm.get("operating_margins")
    if om:
        out["closed_loop_target"] = {"statement": om["target"]["statement"],
                                     "met": om["meets_target"],
                                     "worst_damping_ratio": om["worst"]["damping_ratio_min"],
                                     "worst_phase_margin_deg":
                                         om["worst"]["phase_margin_min_deg"]}  # fmt: skip
    tr = sm.get("transparency")
    if tr:
        out["transparency"] = {f"{c['material']} {c['thickness_mm']:g}": c["ratios"]
                               for c in tr["cases"]}  # fmt: skip
    return out


def _arduino_figures(a: ArduinoExport) -> dict[str, Any]:
    """Flash and RAM (B), cycles per step, errors (% FS, % of the rendered range) and notes of an
    Arduino export."""
    return {"flash_B": a.flash_B, "ram_B": a.ram_B, "cycles_max": a.cycles_max,
            "cycles_mean": a.cycles_mean, "error_handle_pct_fs": a.error_handle_pct_fs,
            "error_handle_pct_rendered": a.error_handle_pct_rendered,
            "rendered_max_N": a.rendered_max_N,
            "error_jaw_pct_fs": a.error_jaw_pct_fs, "table_bytes": a.table_bytes,
            "within_budget": a.within_budget(), "notes": list(a.notes)}  # fmt: skip


def _cosim_figures(cs: CosimResult) -> dict[str, Any]:
    """Steps, min handle angle (deg), max jaw force (N), max torque and FMU-Python diff (N m)."""
    return {"steps": len(cs.data), "min_theta_deg": float(cs.col("theta_deg").min()),
            "max_force_jaw_N": float(cs.col("force_jaw_N").max()),
            "max_torque_Nm": float(cs.col("torque_Nm").max()),
            "max_torque_diff_vs_python_Nm": cs.max_torque_diff_Nm,
            "settling": cs.settling}  # fmt: skip
