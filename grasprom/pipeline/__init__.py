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
   (``stiffness_vs_theta.png``, ``zwidth.png``, ``bode_impedance.png``,
   ``transparency.png``).  ``--device`` gives the device model (JSON), ``--rendering`` the
   tissue rendering (coupling or clipped).
3. ``fmu`` -- :func:`grasprom.export.fmu.export_fmu`: ``GraspController.fmu`` (FMI 2.0) and
   ``GraspController_fmi3.fmu`` (FMI 3.0), native C co-simulation.
4. ``arduino`` -- :func:`grasprom.export.arduino.export_arduino` into ``arduino/`` with the budget
   (flash, RAM from avr-gcc/avr-size; cycles from simavr; error against the Python reference).
   With ``fast`` the simavr cycle count and the host error run are skipped; flash and RAM are
   still measured when avr-gcc is installed.
5. ``cosim`` -- a grasp-hold-release through the FMI 2 FMU with fmpy: the handle (inertia and
   viscous friction of :class:`~grasprom.control.DeviceParams`, end stops) is squeezed by a
   hand
   force profile and pushed back by the motor torque; the FMU's torque is compared with the
   Python reference controller replayed on the same angles.  Writes ``cosim.csv`` and
   ``figures/cosim.png``.
6. ``report`` -- ``report.html`` (self-contained: the PNGs are embedded as base64), with the
   transmission figure ``figures/transmission.png`` (Fg/Fi vs theta), and ``build.json``
   (provenance: versions, FE data hashes, git revision, command line, stage times, artefact
   hashes).

The sweep may hold any of the materials ``mr``, ``nh``, ``le`` (one is enough): every output
covers the materials and thicknesses of the sweep, no more (:class:`Coverage`, recorded in
``build.json`` under ``results.coverage`` and stated in the report); the FMUs and the Arduino
firmware refuse the others.  ``--material`` must be one of them.

A stage that fails raises :class:`StageError` naming it; what the earlier stages wrote is kept,
and a partial ``report.html`` of the finished stages is written (best effort).

Units: mm, N, N m, s, deg at the interfaces (as in the rest of the package); the FMU's
variables are SI.

Layout (one module per concept; import the names below from :mod:`grasprom.pipeline`):

- :mod:`~grasprom.pipeline.options` -- :class:`BuildOptions` (the inputs) and
  :class:`StageError`.
- :mod:`~grasprom.pipeline.result` -- :class:`BuildResult`, :class:`CosimResult`,
  :class:`Coverage` and :func:`results` (the headline figures of ``build.json``).
- :mod:`~grasprom.pipeline.stages` -- :data:`STAGES` and one function per stage.
- :mod:`~grasprom.pipeline.build` -- :func:`run_build`, the driver (progress, timing, failure).
- :mod:`~grasprom.pipeline.cosim` -- :func:`hand_force_N`, :func:`cosimulate`,
  :func:`plot_cosim`.
- :mod:`~grasprom.pipeline.buildinfo` -- :func:`provenance` and :func:`sha256_path`.
- :mod:`~grasprom.pipeline.report` -- :func:`write_report` (``report.html``, ``build.json``),
  :func:`error_rows` and :func:`summary`.
"""

from __future__ import annotations

from grasprom.pipeline.build import run_build
from grasprom.pipeline.buildinfo import provenance, sha256_path
from grasprom.pipeline.cosim import cosimulate, grasp_settling, hand_force_N, plot_cosim
from grasprom.pipeline.options import BuildOptions, StageError
from grasprom.pipeline.report import error_rows, summary, write_report
from grasprom.pipeline.result import BuildResult, CosimResult, Coverage, results
from grasprom.pipeline.stages import FMU2_NAME, FMU3_NAME, STAGES

__all__ = [
    "FMU2_NAME",
    "FMU3_NAME",
    "STAGES",
    "BuildOptions",
    "BuildResult",
    "CosimResult",
    "Coverage",
    "StageError",
    "cosimulate",
    "error_rows",
    "grasp_settling",
    "hand_force_N",
    "plot_cosim",
    "provenance",
    "results",
    "run_build",
    "sha256_path",
    "summary",
    "write_report",
]
