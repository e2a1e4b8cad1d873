"""The slow (thermal) drift of the handle force sensor: its synthetic truth, the library candidate
``sensor_drift`` and the sensor reading of an augmented model with it."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from grasprom import gap
from grasprom.chain import kinematics as kin
from grasprom.control import ControllerParams
from grasprom.gap.synth import synth_case
from grasprom.gap.synth_truth import thermal_drift

CHAIN = kin.ChainParams()
DRIFT = {"offset_rate_N_per_s": 0.1, "gain_rate_per_s": -0.012, "thermal_tau_s": 40.0}
"""A drift truth: initial zero drift 0.1 N/s, sensitivity drift -1.2 %/s, levelling off with a
40 s thermal time constant."""


def _diagnose(effects, seed, surrogate):
    case = synth_case(effects, seed=seed, surrogate=surrogate, n_trials=4)
    trials = [
        gap.validate_trial(t.data, t.sidecar, f"t{i}.csv", CHAIN, surrogate)
        for i, t in enumerate(case.trials)
    ]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return case, gap.diagnose(trials, surrogate, CHAIN)


def test_thermal_drift_first_order():
    t = np.array([0.0, 1.0, 40.0, 1e4])
    d = thermal_drift(t, 0.1, 40.0)
    assert d[0] == 0.0
    assert d[1] == pytest.approx(0.1 * 40.0 * (1.0 - math.exp(-1.0 / 40.0)), rel=1e-12)
    assert d[2] == pytest.approx(4.0 * (1.0 - math.exp(-1.0)), rel=1e-12)
    assert d[3] == pytest.approx(4.0, rel=1e-12)  # levels off at rate x tau


def test_drift_named_and_rates_recovered(surrogate):
    """A drifting sensor (zero and sensitivity, from a zeroed, calibrated start) is named
    ``sensor_drift``, not a constant offset/gain, in the sensor block; the fitted rates are the
    truth's mean slope over a trial, ``r tau (1 - exp(-T/tau)) / T`` (T the mean duration, the
    candidate being linear in time): offset rate within 10 %, gain rate within 25 % (measured
    3 % and 18 %: the gain rate rests on the few seconds of large force)."""
    case, d = _diagnose({"sensor_drift": DRIFT}, 12, surrogate)
    v = d.report["verdict"]
    assert v["label"] == "explained" and v["effects"] == ["sensor_drift"]
    assert v["confidence"] >= 0.8
    assert d.report["where"]["block"] == "sensor"
    dur = np.mean([t.data["time_s"].iloc[-1] for t in case.trials])
    tau = DRIFT["thermal_tau_s"]
    mean_slope = tau * -math.expm1(-dur / tau) / dur  # x the initial rate
    row = d.report["effects"][0]
    assert row["name"] == "sensor_drift" and row["units"]["offset_rate_N_per_s"] == "N/s"
    fit = row["params"]
    assert fit["offset_rate_N_per_s"] == pytest.approx(
        DRIFT["offset_rate_N_per_s"] * mean_slope, rel=0.10
    )
    assert fit["gain_rate_per_s"] == pytest.approx(DRIFT["gain_rate_per_s"] * mean_slope, rel=0.25)


def test_constant_offset_gain_not_named_drift(surrogate):
    """A constant offset and gain (no drift in the truth) is ``sensor_offset_gain``, with its
    truth values (0.5 N to 0.05 N, gain 1.08 to 0.01), never ``sensor_drift``."""
    truth = {"offset_N": 0.5, "gain": 0.08, "drift_N_per_s": 0.0, "quadratic_per_N": 0.0}
    _, d = _diagnose({"sensor_offset_gain": truth}, 13, surrogate)
    v = d.report["verdict"]
    assert v["label"] == "explained" and v["effects"] == ["sensor_offset_gain"]
    p = d.report["effects"][0]["params"]
    assert p["offset_N"] == pytest.approx(0.5, abs=0.05)
    assert p["gain"] == pytest.approx(1.08, abs=0.01)
    drift = next(r for r in d.report["effects"] if r["name"] == "sensor_drift")
    assert drift["score"] < d.report["effects"][0]["score"] - 0.1


def test_measured_reading_with_drift(surrogate):
    """The sensor reading of an augmented model with a drift: ``offset + r t + (gain + k t) F``
    (t from the first sample), analytic values; the controller does not render it."""
    t = np.linspace(2.0, 7.0, 11)
    f = np.linspace(0.0, 30.0, 11)
    meas = {"offset_N": 0.2, "gain": 1.05, "delay_s": 0.0}
    drift = {"offset_rate_N_per_s": 0.1, "gain_rate_per_s": -0.01}
    got = gap.measured_handle_force_N(t, f, meas | drift)
    ts = t - 2.0
    assert np.allclose(got, 0.2 + 0.1 * ts + (1.05 - 0.01 * ts) * f, rtol=0, atol=1e-12)
    model = gap.AugmentedModel({"sensor_drift": drift}, CHAIN)
    _, info = gap.controller_params_from_augmented(ControllerParams(), model)
    assert info["rendered"] == [] and info["measurement_only"] == ["sensor_drift"]
    assert info["measurement"] == {"offset_N": 0.0, "gain": 1.0, "delay_s": 0.0} | drift
