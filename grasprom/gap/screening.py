"""Data the diagnosis cannot diagnose: the screens behind the ``not_diagnosable`` verdict.

Before any effect is believed, the measured trials must carry a signal the model can be
compared with, and the best fit must stay inside the physically plausible ranges of the effect
library.  :func:`screen_trials` looks at the data alone (after the baseline is evaluated);
:func:`bound_reasons` at the fitted explaining effect set.  Each returns the reasons (one
sentence each, naming the trial file or the parameter); no reason means the data passes.

Screens (forces in N, on the analysis grid unless stated):

* **no signal** -- the measured handle force spans (5th to 95th percentile) less than
  :data:`MIN_SIGNAL_SHARE` of what the baseline model spans on the same angles (an all-zero or
  constant column, a disconnected sensor);
* **noise far above the model scale** -- the sensor noise sigma (median absolute second
  difference of the raw force) exceeds :data:`MAX_NOISE_TO_MODEL` of the model's span;
* **not a signal of time** -- the sample-to-sample scatter (the same sigma) exceeds
  :data:`MAX_NOISE_TO_SPREAD` of the measured force's own standard deviation (a shuffled or
  misaligned column: white noise has a ratio of about 1, a real grasp 0.01-0.1);
* **duplicates** -- two trials with the same samples (the same file twice, or a copy):
  cross-validation by trial would test a trial on itself;
* **fit at a bound** -- a parameter of the explaining fit sits at a bound of its range that is
  not its neutral value (e.g. ``tissue_stiffness_scale`` 6.0 or 0.1, ``thickness_error``
  +-0.4 mm): the data lie outside what the library can represent (wrong thickness or material
  in the sidecar, another instrument?).
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence

import numpy as np

from grasprom.gap.effects import EFFECTS
from grasprom.gap.fit import Fit, fit_params
from grasprom.gap.prepare import PreparedTrial

MIN_SIGNAL_SHARE = 0.05
"""Smallest measured/model force span (1) of a trial with a signal."""
MAX_NOISE_TO_MODEL = 0.5
"""Largest sensor noise sigma / model force span (1)."""
MAX_NOISE_TO_SPREAD = 0.5
"""Largest sensor noise sigma / standard deviation of the measured force (1)."""
BOUND_TOLERANCE = 1e-3
"""A fitted coefficient within this share of its range from a bound is at the bound."""


def _span(x: np.ndarray) -> float:
    """5th-95th percentile span (robust range) of a force series, N."""
    lo, hi = np.percentile(x, [5.0, 95.0])
    return float(hi - lo)


def _trial_reasons(p: PreparedTrial) -> list[str]:
    """The reasons of one trial (see the module docstring)."""
    name = p.trial.name if p.trial is not None else "trial"
    measured, model = np.asarray(p.F, float), np.asarray(p.F0, float)
    span_meas, span_model = _span(measured), _span(model)
    sigma = p.noise_N
    if not span_meas >= MIN_SIGNAL_SHARE * span_model:
        return [
            f"{name}: no signal: the measured handle force spans {span_meas:.3g} N (5-95 %) "
            f"where the model spans {span_model:.3g} N on the same angles (a constant or "
            "disconnected force channel?)"
        ]
    out = []
    if np.isfinite(sigma) and sigma > MAX_NOISE_TO_MODEL * span_model:
        out.append(
            f"{name}: the force noise (sigma {sigma:.3g} N) is far above the model's force "
            f"scale ({span_model:.3g} N span): nothing systematic can be told from it"
        )
    spread = float(np.std(measured))
    if np.isfinite(sigma) and sigma > MAX_NOISE_TO_SPREAD * spread:
        out.append(
            f"{name}: the force is not a smooth signal of time (sample-to-sample scatter "
            f"{sigma:.3g} N of a {spread:.3g} N spread): a shuffled or misaligned column?"
        )
    return out


def _fingerprint(p: PreparedTrial) -> str:
    """Hash of a trial's raw samples (time, angle and force)."""
    h = hashlib.sha256()
    for a in (p.raw_t, p.raw_theta):
        h.update(np.ascontiguousarray(a, dtype=float).tobytes())
    if p.trial is not None:
        h.update(np.ascontiguousarray(p.trial.force_handle_N, dtype=float).tobytes())
    return h.hexdigest()


def screen_trials(preps: Sequence[PreparedTrial]) -> list[str]:
    """Reasons why the prepared trials cannot be diagnosed (empty list: they can).

    Parameters
    ----------
    preps : sequence of PreparedTrial
        Trials in contact, with the measured (``F``) and baseline (``F0``) handle force, N.

    Returns
    -------
    list of str
    """
    reasons: list[str] = []
    for p in preps:
        reasons += _trial_reasons(p)
    seen: dict[str, str] = {}
    for p in preps:
        key = _fingerprint(p)
        name = p.trial.name if p.trial is not None else "trial"
        if key in seen:
            reasons.append(
                f"{name} and {seen[key]} hold the same samples: a trial given twice cannot "
                "cross-validate the other"
            )
        else:
            seen[key] = name
    return reasons


def bound_reasons(fit: Fit) -> list[str]:
    """Parameters of a fitted effect set at a non-neutral bound of their range.

    Parameters
    ----------
    fit : Fit
        The fitted explaining effect set.

    Returns
    -------
    list of str
        One sentence per parameter at a bound (reported value, bound, unit).
    """
    values = fit_params(fit)
    out = []
    for e in fit.effects:
        for ps in EFFECTS[e].params:
            x = values[e][ps.name] - ps.offset  # the internal coefficient
            tol = BOUND_TOLERANCE * (ps.hi - ps.lo)
            unit = "" if ps.unit == "1" else f" {ps.unit}"
            for bound in (ps.lo, ps.hi):
                if bound != 0.0 and abs(x - bound) <= tol:
                    out.append(
                        f"the best fit puts {e}.{ps.name} at the bound of its range "
                        f"({bound + ps.offset:g}{unit}): the data lie outside what the "
                        "effect library represents (wrong thickness or material in the "
                        "sidecar, another instrument?)"
                    )
    return out
