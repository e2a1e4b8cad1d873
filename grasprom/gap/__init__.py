"""Stage 6, the sim-to-real gap: measured trials, candidate effects, the diagnosis, the
augmented model and synthetic "real" trials with withheld effects.

Where things are:

=====================  ==========================================================================
module                 concept
=====================  ==========================================================================
``trials``             measured trial tables + sidecars: :class:`Trial`, validation, loading
``signals``            noise sigma, encoder quantum, moving average of sampled channels
``prepare``            a trial on the analysis grid: kinematic states, baseline, sigma, phases
``effects``            the candidate library: :data:`EFFECTS`, parameter specs, :data:`BLOCKS`
``model``              forward model: baseline + candidate effects on a prepared trial
``fit``                variable-projection weighted least-squares fit of an effect set
``crossval``           cross-validation by trial, jackknife uncertainty
``stats``              residual RMS / bias / share, by label
``criteria``           decision thresholds (significance, explained share, pair gain)
``blocks``             block analysis from ``force_jaw_N`` / ``gap_mm`` (tissue/mechanism/sensor)
``baseline``           the baseline gap: residuals, systematic ratio, where it lies
``selection``          candidate ranking and forward selection of pairs, report rows
``verdict``            verdict label, confidence, shrink
``diagnosis``          :func:`diagnose` and its result :class:`Diagnosis`
``formats``            output format names / version, JSON conversion
``augmented``          :class:`AugmentedModel`, building / saving / loading its JSON
``rendering``          augmented model -> controller parameters; the sensor reading
``report``             readable summary, ``report.json`` / ``augmented_model.json``
``plots``              PNG plots of a diagnosis
``synth_effects``      withheld effects of synthetic trials and their random truths
``synth_truth``        truth models: one synthetic trial of instrument + effects + sensors
``synth``              synthetic cases (trials + withheld truth) and writing them
``cli``                ``grasprom diagnose`` / ``grasprom synth`` argument parsing and running
=====================  ==========================================================================
"""

from __future__ import annotations

from grasprom.gap.augmented import AugmentedModel, load_augmented, save_augmented
from grasprom.gap.diagnosis import Diagnosis, DiagnosisError, diagnose
from grasprom.gap.effects import BLOCKS, EFFECTS, PRONY_TAUS_S
from grasprom.gap.formats import FORMAT_AUGMENTED, FORMAT_REPORT, FORMAT_VERSION
from grasprom.gap.prepare import PHASES, STILL_DEG_PER_S
from grasprom.gap.rendering import (
    MEASUREMENT_EFFECTS,
    RENDERED_EFFECTS,
    controller_params_from_augmented,
    measured_handle_force_N,
)
from grasprom.gap.report import format_summary, write_outputs
from grasprom.gap.synth import SynthCase, SynthTrial, synth_case, write_case
from grasprom.gap.synth_effects import LIBRARY_EFFECTS, OUT_OF_LIBRARY_EFFECTS, SYNTH_EFFECTS
from grasprom.gap.trials import Trial, TrialDataError, load_trial, validate_trial

__all__ = [
    "AugmentedModel",
    "BLOCKS",
    "Diagnosis",
    "DiagnosisError",
    "EFFECTS",
    "FORMAT_AUGMENTED",
    "FORMAT_REPORT",
    "FORMAT_VERSION",
    "LIBRARY_EFFECTS",
    "MEASUREMENT_EFFECTS",
    "OUT_OF_LIBRARY_EFFECTS",
    "PHASES",
    "PRONY_TAUS_S",
    "RENDERED_EFFECTS",
    "STILL_DEG_PER_S",
    "SYNTH_EFFECTS",
    "SynthCase",
    "SynthTrial",
    "Trial",
    "TrialDataError",
    "controller_params_from_augmented",
    "diagnose",
    "format_summary",
    "load_augmented",
    "load_trial",
    "measured_handle_force_N",
    "save_augmented",
    "synth_case",
    "validate_trial",
    "write_case",
    "write_outputs",
]
