"""Stage 4, the controller: parameters, the open-loop impedance controller (Python reference),
simulation of trajectories and passivity tuning with python-control.

Layout (a module per concept, lower layers first; ``import control`` inside means python-control):

* :mod:`~grasprom.control.params` -- :class:`ControllerParams` and its JSON file form.
* :mod:`~grasprom.control.field` -- the stiffness-clipped field (:class:`Field`,
  :func:`build_field`).
* :mod:`~grasprom.control.impedance` -- :class:`ImpedanceController`, one step per sample
  (:class:`StepOutput`); the C core of the exports mirrors it.
* :mod:`~grasprom.control.trajectory` -- trajectories through the controller: :func:`simulate`,
  :func:`validate_trajectory`, :func:`grasp_trajectory`.
* :mod:`~grasprom.control.device` -- :class:`DeviceParams` (haptic handle) and its JSON file
  (:func:`load_device`), :class:`HandParams`.
* :mod:`~grasprom.control.stiffness` -- rendered stiffness along theta (:class:`OperatingPoints`),
  static torque, Prony factor and total virtual damping.
* :mod:`~grasprom.control.passivity` -- Colgate/Schenkel required damping, passive stiffness,
  Abbott-Okamura bound, Z-width.
* :mod:`~grasprom.control.loop` -- closed-loop poles, damping ratio and margins
  (python-control).
* :mod:`~grasprom.control.margins` -- damping ratio / phase margin with the hand at every
  operating point against the stated target (:data:`ZETA_TARGET`).
* :mod:`~grasprom.control.transparency` -- rendered / tissue force per case at 0.5, 2, 5, 20 N,
  wall stiffness vs the bound, damping / rate for an exact rendering up to 20 N.
* :mod:`~grasprom.control.verification` -- time-domain hold simulation of device + controller +
  hand, :func:`verify_by_simulation`.
* :mod:`~grasprom.control.summary` -- the tuning summary dict.
* :mod:`~grasprom.control.tuning` -- :func:`tune` and :class:`TuningResult`.
* :mod:`~grasprom.control.report` -- the report's JSON and text forms.
* :mod:`~grasprom.control.plots` -- :func:`plot_tuning`.
* :mod:`~grasprom.control.outputs` -- :func:`write_outputs` (the files of ``grasprom tune``).
"""

from __future__ import annotations

from grasprom.control.device import (
    DeviceParams,
    HandParams,
    apply_device,
    device_from_dict,
    device_to_dict,
    load_device,
    save_device,
)
from grasprom.control.field import Field, build_field, prony_factor
from grasprom.control.impedance import (
    COLD_START_ITERATIONS,
    NEWTON_ITERATIONS,
    ImpedanceController,
    StepOutput,
)
from grasprom.control.loop import closed_loop, damping_ratio, environment_tf
from grasprom.control.margins import ZETA_TARGET, damping_needed, operating_margins
from grasprom.control.outputs import write_outputs
from grasprom.control.params import (
    CONTROLLER_FILE_VERSION,
    ENCODER_COUNTS_RANGE,
    MAX_PRONY_TERMS,
    PARAMETER_RANGES,
    ControllerParams,
    load_params,
    params_from_dict,
    params_to_dict,
    save_params,
)
from grasprom.control.passivity import (
    abbott_okamura_bound,
    colgate_required_damping,
    max_passive_stiffness,
    required_damping,
    zwidth_boundary,
)
from grasprom.control.plots import plot_transparency, plot_tuning
from grasprom.control.report import format_report
from grasprom.control.stiffness import (
    FieldStiffness,
    OperatingPoints,
    StiffestPoint,
    clipped_field,
    clipped_stiffness_bound_Nm_per_rad,
    field_stiffness_extremes,
    operating_cases,
    operating_points,
    prony_stiffness_factor,
    rendered_stiffness,
    static_handle_torque_Nm,
    stiffest_point,
    virtual_damping_Nms_per_rad,
)
from grasprom.control.trajectory import (
    SIMULATION_COLUMNS,
    TRAJECTORY_COLUMNS,
    grasp_trajectory,
    simulate,
    validate_trajectory,
)
from grasprom.control.transparency import (
    FORCE_LEVELS_N,
    case_transparency,
    passive_stiffness_at_rates,
    transparency_table,
)
from grasprom.control.tuning import TuningResult, clipped_limit, tune
from grasprom.control.verification import amplitude_trend, simulate_hold, verify_by_simulation

__all__ = [
    "Field",
    "build_field",
    "prony_factor",
    "COLD_START_ITERATIONS",
    "CONTROLLER_FILE_VERSION",
    "ControllerParams",
    "DeviceParams",
    "FORCE_LEVELS_N",
    "HandParams",
    "ImpedanceController",
    "MAX_PRONY_TERMS",
    "NEWTON_ITERATIONS",
    "OperatingPoints",
    "SIMULATION_COLUMNS",
    "StepOutput",
    "StiffestPoint",
    "TRAJECTORY_COLUMNS",
    "TuningResult",
    "ZETA_TARGET",
    "abbott_okamura_bound",
    "amplitude_trend",
    "apply_device",
    "case_transparency",
    "clipped_field",
    "clipped_limit",
    "clipped_stiffness_bound_Nm_per_rad",
    "closed_loop",
    "colgate_required_damping",
    "damping_needed",
    "damping_ratio",
    "device_from_dict",
    "device_to_dict",
    "environment_tf",
    "format_report",
    "grasp_trajectory",
    "load_device",
    "load_params",
    "max_passive_stiffness",
    "operating_margins",
    "operating_points",
    "params_from_dict",
    "params_to_dict",
    "passive_stiffness_at_rates",
    "plot_transparency",
    "plot_tuning",
    "prony_stiffness_factor",
    "rendered_stiffness",
    "PARAMETER_RANGES",
    "ENCODER_COUNTS_RANGE",
    "FieldStiffness",
    "field_stiffness_extremes",
    "operating_cases",
    "required_damping",
    "save_device",
    "save_params",
    "simulate",
    "simulate_hold",
    "static_handle_torque_Nm",
    "stiffest_point",
    "transparency_table",
    "tune",
    "validate_trajectory",
    "verify_by_simulation",
    "virtual_damping_Nms_per_rad",
    "write_outputs",
    "zwidth_boundary",
]
