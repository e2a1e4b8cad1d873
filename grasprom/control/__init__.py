"""Stage 4, the controller: parameters, the open-loop impedance controller (Python reference),
simulation of trajectories and passivity tuning with python-control."""

from __future__ import annotations

from grasprom.control.controller import (
    MAX_PRONY_TERMS,
    ControllerParams,
    ImpedanceController,
    StepOutput,
    grasp_trajectory,
    load_params,
    save_params,
    simulate,
)
from grasprom.control.tuning import (
    DeviceParams,
    HandParams,
    TuningResult,
    plot_tuning,
    tune,
    write_outputs,
)

__all__ = [
    "ControllerParams",
    "DeviceParams",
    "HandParams",
    "ImpedanceController",
    "MAX_PRONY_TERMS",
    "StepOutput",
    "TuningResult",
    "grasp_trajectory",
    "load_params",
    "plot_tuning",
    "save_params",
    "simulate",
    "tune",
    "write_outputs",
]
