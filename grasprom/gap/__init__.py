"""Stage 6, the sim-to-real gap: measured trials, candidate effects, the diagnosis, the
augmented model and synthetic "real" trials with withheld effects."""

from __future__ import annotations

from grasprom.gap.diagnosis import (
    BLOCKS,
    EFFECTS,
    AugmentedModel,
    Diagnosis,
    controller_params_from_augmented,
    diagnose,
    load_augmented,
    load_trial,
    main_diagnose,
    measured_handle_force_N,
)
from grasprom.gap.synth import (
    LIBRARY_EFFECTS,
    OUT_OF_LIBRARY_EFFECTS,
    SYNTH_EFFECTS,
    main_synth,
    synth_case,
    write_case,
)

__all__ = [
    "AugmentedModel",
    "BLOCKS",
    "Diagnosis",
    "EFFECTS",
    "LIBRARY_EFFECTS",
    "OUT_OF_LIBRARY_EFFECTS",
    "SYNTH_EFFECTS",
    "controller_params_from_augmented",
    "diagnose",
    "load_augmented",
    "load_trial",
    "main_diagnose",
    "main_synth",
    "measured_handle_force_N",
    "synth_case",
    "write_case",
]
