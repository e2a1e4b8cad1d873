"""Inputs of the main job (:class:`BuildOptions`) and its failure (:class:`StageError`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from grasprom.paths import DEFAULT_HOLDOUT_DIR


class StageError(RuntimeError):
    """A stage of :func:`~grasprom.pipeline.run_build` failed.

    Parameters
    ----------
    stage : str
        Name of the failed stage (one of :data:`~grasprom.pipeline.STAGES`).
    message : str
        What went wrong.
    """

    def __init__(self, stage: str, message: str) -> None:
        super().__init__(f"stage '{stage}' failed: {message}")
        self.stage = stage


@dataclass
class BuildOptions:
    """Inputs of :func:`~grasprom.pipeline.run_build`.

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
        cycle measurement nor host error run, a shorter rest after the co-simulated grasp (its
        figures are those of the full run).
    command_line : sequence of str, optional
        Command line recorded in the provenance block (default ``sys.argv``).
    augmented : str or Path, optional
        Augmented model of ``grasprom diagnose`` (``augmented_model.json``): its instrument
        effects are rendered by the tuned controller, the FMUs and the Arduino package.
    device : str or Path, optional
        Device file (:func:`grasprom.control.load_device`): the tuning, exports and
        co-simulation use it (default the documented :class:`~grasprom.control.DeviceParams`).
    rendering : str
        Tissue rendering of the tuned controller, ``"clipped"`` (default) or ``"coupling"``.
    """

    fe_dir: str | Path = "fe_data/default"
    holdout_dir: str | Path | None = DEFAULT_HOLDOUT_DIR
    thickness_mm: float = 1.4
    material: str = "mr"
    out_dir: str | Path = "build"
    fast: bool = False
    command_line: Sequence[str] | None = None
    augmented: str | Path | None = None
    device: str | Path | None = None
    rendering: str = "clipped"
