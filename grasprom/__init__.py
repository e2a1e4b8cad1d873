"""grasprom: FE clamping sweeps of the colon wall turned into haptic-rate grasp models.

The pipeline, one subpackage per stage (units mm, N, MPa, s; degrees at the user surface):

=======================  ===================================================================
``grasprom.fe``          FE models of the tube clamped between rigid jaws, sweeps, case files
``grasprom.surrogate``   tabulated force / stiffness over gap x thickness x material
``grasprom.chain``       the grasper's kinematic chain: jaw force from handle force
``grasprom.control``     the open-loop impedance controller, simulation, passivity tuning
``grasprom.export``      the C core, the FMU (FMI 2.0 / 3.0) and the Arduino package
``grasprom.gap``         the sim-to-real gap: measured trials, diagnosis, augmented model
``grasprom.pipeline``    ``grasprom build``: the main job end to end, with its report
=======================  ===================================================================

``grasprom.paths`` says where the shipped data and the C sources are; ``grasprom.cli`` holds
every command-line parser.  The names in ``__all__`` are the entry points of each stage; they
are imported on first use, so ``import grasprom`` itself is cheap.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

_LAZY = {
    "run_case": "grasprom.fe",
    "run_sweep": "grasprom.fe",
    "CaseSpec": "grasprom.fe",
    "MeshSpec": "grasprom.fe",
    "Surrogate": "grasprom.surrogate",
    "BuildParams": "grasprom.surrogate",
    "load_surrogate": "grasprom.surrogate",
    "ChainParams": "grasprom.chain.kinematics",
    "ControllerParams": "grasprom.control",
    "ImpedanceController": "grasprom.control",
    "simulate": "grasprom.control",
    "tune": "grasprom.control",
    "export_fmu": "grasprom.export",
    "export_arduino": "grasprom.export",
    "diagnose": "grasprom.gap",
    "load_augmented": "grasprom.gap",
    "synth_case": "grasprom.gap",
    "BuildOptions": "grasprom.pipeline",
    "run_build": "grasprom.pipeline",
}
"""Public name -> the subpackage (or module) that defines it."""

__all__ = ["__version__", *sorted(_LAZY)]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'grasprom' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
