"""Stage 1, FE sweeps: materials, the clamped-tube models, sweeps over thickness x material,
case files and the sweep report (mm, N, MPa).

The names below are imported on first use (PEP 562), so ``import grasprom.fe.materials`` or
``from grasprom.fe import MATERIAL_NAMES`` does not pull in scikit-fem and pandas.
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "CaseResult": "model2d",
    "CaseSpec": "model2d",
    "CorruptCaseError": "datafiles",
    "KNOWN_MATERIALS": "sweep",
    "MATERIAL_NAMES": "materials",
    "MeshSpec": "model2d",
    "SolverSettings": "model2d",
    "SweepConflictError": "sweep",
    "SweepInputError": "sweep",
    "atomic_write_bytes": "datafiles",
    "build_grid": "sweep",
    "default_runner": "sweep",
    "get_material": "materials",
    "git_revision": "datafiles",
    "load_sweep": "datafiles",
    "make_report": "report",
    "package_versions": "datafiles",
    "plot_sweep": "report",
    "read_case": "datafiles",
    "run_case": "model2d",
    "run_sweep": "sweep",
    "spec_defaults": "sweep",
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
