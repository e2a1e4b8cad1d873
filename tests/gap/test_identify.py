"""Device identification (issue 15): ``grasprom identify`` recovers the inertia, damping and
Coulomb friction of a simulated device from free-motion trials.

Reference: the trials are made by integrating the device's equation of motion with a fine
semi-implicit Euler step (100 kHz, friction regularised over 1e-3 rad/s) under a multisine motor
torque, then sampled like a real acquisition (jittered time stamps, a 4096-count motor encoder
quantising the handle angle); the identification only sees the CSV.  Tolerances: 3 % on J and b,
10 % on f_c (the friction is the smallest torque), and each within 4 bootstrap sigmas.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from grasprom.chain import kinematics as kin
from grasprom.cli import main
from grasprom.control import ControllerParams, load_device
from grasprom.gap.identify import IdentificationError, identify_device, load_device_trial

TRUTH = {"inertia_kg_m2": 2.5e-3, "damping_Nms_per_rad": 0.012, "coulomb_Nm": 0.015}
CHAIN = kin.ChainParams()
RATIO = CHAIN.L3_mm / ControllerParams().pulley_radius_mm  # pivot torque / motor torque


def _simulate(seed: int, duration_s: float = 6.0, rate_hz: float = 1000.0, counts: int = 4096):
    """One free-motion trial of the TRUTH device: (time_s, theta_deg, torque_Nm) table."""
    rng = np.random.default_rng(seed)
    J, b, fc = TRUTH.values()
    freqs = np.array([1.1, 2.3, 3.7, 5.3, 8.1])
    phases = rng.uniform(0, 2 * np.pi, freqs.size)

    def torque(t):  # motor torque, N m (zero mean)
        return 0.004 * np.sum(np.sin(2 * np.pi * freqs * t + phases)) / math.sqrt(freqs.size)

    dt = 1e-5
    n = int(duration_s / dt)
    th, w = math.radians(11.0), 0.0  # mid-range, at rest
    fine_t = np.arange(n) * dt
    fine_th = np.empty(n)
    fine_tau = np.empty(n)
    for k in range(n):
        tau = torque(fine_t[k])
        acc = (RATIO * tau - b * w - fc * math.tanh(w / 1e-3)) / J
        w += acc * dt
        th += w * dt
        fine_th[k], fine_tau[k] = th, tau
    t = np.arange(0.0, duration_s - 0.01, 1.0 / rate_hz)
    t = t + rng.uniform(-0.2, 0.2, t.size) / rate_hz  # jittered time stamps
    t[0] = max(t[0], 0.0)
    theta = np.interp(t, fine_t, fine_th)
    q = 2 * math.pi * ControllerParams().pulley_radius_mm / (counts * CHAIN.L3_mm)  # rad/count
    theta = np.round(theta / q) * q
    tau = np.interp(t, fine_t, fine_tau) + rng.normal(0, 1e-4, t.size)
    lo, hi = kin.theta_range_deg(CHAIN)
    deg = np.degrees(theta)
    assert lo < deg.min() and deg.max() < hi, "the synthetic motion must stay off the stops"
    return pd.DataFrame({"time_s": t, "theta_deg": deg, "torque_Nm": tau})


@pytest.fixture(scope="module")
def trial_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("free")
    paths = []
    for seed in (1, 2):
        p = d / f"free{seed}.csv"
        _simulate(seed).to_csv(p, index=False)
        paths.append(p)
    return paths


def test_identification_recovers_the_simulated_device(trial_files):
    res = identify_device([load_device_trial(p) for p in trial_files])
    print("\n" + res.format())
    for k, tol in (("inertia_kg_m2", 0.03), ("damping_Nms_per_rad", 0.03), ("coulomb_Nm", 0.10)):
        got, sd = res.values[k], res.uncertainty[k]
        assert got == pytest.approx(TRUTH[k], rel=tol), (k, got)
        assert 0 < sd and abs(got - TRUTH[k]) < 4 * sd + 1e-3 * TRUTH[k], (k, got, sd)
    assert abs(res.values["offset_Nm"]) < 0.1 * TRUTH["coulomb_Nm"]
    assert res.device.inertia_kg_m2 == res.values["inertia_kg_m2"]


def test_cli_writes_a_device_file_tune_accepts(trial_files, tmp_path, capsys):
    out = tmp_path / "device.json"
    assert main(["identify", *map(str, trial_files), "--out", str(out)]) == 0
    assert "inertia_kg_m2" in capsys.readouterr().out
    dev = load_device(out)  # the file --device reads
    assert dev.damping_Nms_per_rad == pytest.approx(TRUTH["damping_Nms_per_rad"], rel=0.03)
    ident = json.loads(out.read_text())["identification"]
    assert [t["file"] for t in ident["trials"]] == [p.name for p in trial_files]
    assert out.stat().st_mode & 0o777 == 0o644


def test_no_motion_or_bad_units_are_clear_errors(tmp_path, capsys):
    still = tmp_path / "still.csv"
    t = np.arange(0, 2, 1e-3)
    pd.DataFrame({"time_s": t, "theta_deg": 11.0, "torque_Nm": 0.0}).to_csv(still, index=False)
    with pytest.raises(IdentificationError, match="usable samples"):
        identify_device([load_device_trial(still)])
    rad = tmp_path / "rad.csv"
    df = _simulate(3, duration_s=1.0)
    df.assign(theta_deg=np.radians(df.theta_deg) * 0.01).to_csv(rad, index=False)
    assert main(["identify", str(rad), "--out", str(tmp_path / "d.json")]) == 2
    err = capsys.readouterr().err
    assert "rad.csv" in err and "theta_deg" in err and "Traceback" not in err
    assert not (tmp_path / "d.json").exists()
