"""Stage 1, FE sweeps: materials, the clamped-tube models, sweeps over thickness x material,
case files and the sweep report (mm, N, MPa).

Modules: ``materials`` (constitutive laws), ``model2d`` (the plane-strain clamped-tube model,
:func:`run_case`), ``grid`` (the thickness x material grid, :func:`build_grid`), ``sweep``
(running a grid resumably, :func:`run_sweep`), ``datafiles`` (the on-disk case and manifest
format) with ``atomicio`` (atomic writes, JSON encoding) and ``provenance`` (versions, git
revision, time stamps), ``report`` (summary table) and ``plots`` (force-gap figure); ``model3d``
(the 3D tube, :func:`run_case_3d`; :func:`equilibrium_from` solves one gap from a given
state, :class:`EquilibriumSolver` many on one set-up), ``transfer3d`` (a 3D field moved to
another mesh, :func:`transfer_displacement`),
``bandselect`` (the crease band's lower-energy state across the case's run and a companion
run's, :func:`run_case_3d_selected`) and ``ccx`` (the same case in CalculiX, :func:`run_ccx`).

The names below are imported on first use (PEP 562), so ``import grasprom.fe.materials`` or
``from grasprom.fe import MATERIAL_NAMES`` does not pull in scikit-fem and pandas.
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "CaseSpec3D": "model3d",
    "MeshSpec3D": "mesh3d",
    "run_case_3d": "model3d",
    "equilibrium_from": "model3d",
    "Equilibrium3D": "model3d",
    "EquilibriumSolver": "model3d",
    "transfer_displacement": "transfer3d",
    "FieldProbe": "transfer3d",
    "run_case_3d_selected": "bandselect",
    "BandSelection": "bandselect",
    "run_ccx": "ccx",
    "CaseResult": "model2d",
    "CaseSpec": "model2d",
    "CorruptCaseError": "datafiles",
    "KNOWN_MATERIALS": "grid",
    "MATERIAL_LABELS": "materials",
    "MATERIAL_NAMES": "materials",
    "material_label": "materials",
    "MeshSpec": "model2d",
    "SolverSettings": "model2d",
    "SweepConflictError": "sweep",
    "SweepInputError": "grid",
    "atomic_write_bytes": "atomicio",
    "build_grid": "grid",
    "default_runner": "sweep",
    "get_material": "materials",
    "git_revision": "provenance",
    "load_sweep": "datafiles",
    "make_report": "report",
    "package_versions": "provenance",
    "plot_sweep": "plots",
    "read_case": "datafiles",
    "run_case": "model2d",
    "run_sweep": "sweep",
    "spec_defaults": "grid",
}
"""Public name -> module of this subpackage that defines it."""

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
