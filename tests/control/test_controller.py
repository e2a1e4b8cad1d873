"""Impedance controller (Python reference): coupling, chain, damping, flags, simulate CLI."""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from scipy.optimize import brentq

from grasprom.chain import kinematics as kin
from grasprom.control import (
    ControllerParams,
    ImpedanceController,
    grasp_trajectory,
    load_params,
    save_params,
    simulate,
)


def _hold(ctl: ImpedanceController, theta_deg: float, n: int = 30):
    out = None
    for _ in range(n):
        out = ctl.step(math.radians(theta_deg))
    return out


@pytest.mark.parametrize("material,t", [("mr", 1.4), ("le", 2.0), ("nh", 0.85)])
def test_coupling_proxy_solves_the_series_spring_equation(surrogate, material, t):
    """At rest the proxy gap satisfies k_c (g_p - g) = F(g_p) (checked with brentq)."""
    p = ControllerParams(
        thickness_mm=t, material=material, encoder_counts_per_rev=0, rendering="coupling"
    )
    kc = p.coupling_stiffness_N_per_mm
    for theta in (15.0, 5.0, 2.0, 1.0, 0.5, 0.0):
        ctl = ImpedanceController(p, surrogate)
        out = _hold(ctl, theta)
        g = kin.gap_mm(theta, p.chain_params)

        def r(gp, g=g):
            return kc * (gp - g) - surrogate.force_scalar(gp, t, material)

        f0 = surrogate.force_scalar(g, t, material)
        if f0 == 0.0:
            assert out.force_jaw_N == 0.0 and not out.contact
            continue
        gp_ref = brentq(r, g, g + f0 / kc, xtol=1e-13)
        assert out.proxy_gap_mm == pytest.approx(gp_ref, abs=1e-9)
        assert out.force_jaw_N == pytest.approx(kc * (gp_ref - g), rel=1e-9)
        assert out.force_jaw_N <= f0 + 1e-12  # the coupling only softens


def test_static_handle_force_is_the_chain_of_the_jaw_force(surrogate):
    p = ControllerParams(encoder_counts_per_rev=0)
    ctl = ImpedanceController(p, surrogate)
    for theta in (20.0, 10.0, 3.0, 0.7):
        out = _hold(ctl, theta, 50)
        fi = kin.handle_force_N(out.force_jaw_N, theta, p.chain_params)
        assert out.force_handle_N == pytest.approx(fi, rel=1e-12)
        assert out.torque_Nm == pytest.approx(fi * p.pulley_radius_mm * 1e-3, rel=1e-12)
        assert out.force_handle_spring_N == pytest.approx(
            kin.spring_handle_force_N(theta, p.chain_params), rel=1e-12
        )
    no_spring = ImpedanceController(dataclasses.replace(p, render_spring=False), surrogate)
    out = _hold(no_spring, 20.5, 5)  # before first touch: nothing to render
    assert out.force_handle_N == pytest.approx(0.0, abs=1e-12)


def test_velocity_filter_and_damping(surrogate):
    """Constant closing speed: filtered velocity -> speed (first-order lag), damping resists."""
    T, fc, B = 1e-3, 20.0, 0.02
    p = ControllerParams(
        encoder_counts_per_rev=0, damping_Nms_per_rad=B, velocity_cutoff_Hz=fc, sample_time_s=T
    )
    ctl = ImpedanceController(p, surrogate)
    w = -math.radians(10.0)  # rad/s, closing
    th0 = math.radians(21.0)
    a = math.exp(-2 * math.pi * fc * T)
    ref_static = ImpedanceController(dataclasses.replace(p, damping_Nms_per_rad=0.0), surrogate)
    for k in range(200):
        out = ctl.step(th0 + w * T * k)
        st = ref_static.step(th0 + w * T * k)
        v_ref = w * (1 - a**k)  # exact response of the discrete filter to a ramp
        assert out.velocity_rad_per_s == pytest.approx(v_ref, rel=1e-9, abs=1e-12)
    # damping adds -B v / L3 (N) at the grip: resists closing
    extra = out.force_handle_N - st.force_handle_N
    assert extra == pytest.approx(-B * out.velocity_rad_per_s / (p.chain.L3_mm * 1e-3), rel=1e-9)
    assert extra > 0


def test_saturation_warning_and_clamp_flags(surrogate):
    p = ControllerParams(
        material="le",
        thickness_mm=2.0,
        coupling_stiffness_N_per_mm=200.0,
        torque_limit_Nm=0.2,
        rendering="coupling",
    )
    ctl = ImpedanceController(p, surrogate)
    out = _hold(ctl, 0.0, 40)
    assert out.saturated and out.torque_Nm == pytest.approx(0.2)
    assert out.force_handle_N == pytest.approx(0.2 / (p.pulley_radius_mm * 1e-3))
    assert out.tissue_warning and out.force_tissue_N >= p.force_warning_N
    assert out.coupling_active
    out = ctl.step(math.radians(25.0))
    assert out.theta_clamped and out.theta_deg == pytest.approx(22.0)
    out = ctl.step(float("nan"))
    assert out.theta_clamped and math.isfinite(out.torque_Nm)
    # pressure threshold alone
    low = dataclasses.replace(p, force_warning_N=1e5, pressure_warning_MPa=1e-3)
    c2 = ImpedanceController(low, surrogate)
    o2 = _hold(c2, 3.0, 5)
    area = p.jaw_length_mm * 0.5 * math.pi * (p.diameter_mm - p.thickness_mm)
    assert o2.tissue_warning == (o2.force_tissue_N / area >= 1e-3)


def test_encoder_quantisation(surrogate):
    p = ControllerParams(encoder_counts_per_rev=4096)
    ctl = ImpedanceController(p, surrogate)
    q = 2 * math.pi * p.pulley_radius_mm / (4096 * p.chain.L3_mm)
    assert ctl.encoder_quantum_rad == pytest.approx(q)
    out = ctl.step(math.radians(10.0))
    k = math.radians(out.theta_deg) / q
    assert k == pytest.approx(round(k), abs=1e-9)
    assert abs(math.radians(out.theta_deg) - math.radians(10.0)) <= q / 2 + 1e-15


def test_bad_parameters_name_the_parameter(surrogate):
    with pytest.raises(ValueError, match="material"):
        ControllerParams(material="xx")
    with pytest.raises(ValueError, match="pulley_radius_mm"):
        ControllerParams(pulley_radius_mm=0.0)
    with pytest.raises(ValueError, match="velocity_cutoff_Hz"):
        ControllerParams(velocity_cutoff_Hz=600.0)
    with pytest.raises(ValueError, match="thickness_mm=3.0"):
        ImpedanceController(ControllerParams(thickness_mm=3.0), surrogate)


@pytest.mark.parametrize(
    "kw,match",
    [
        ({"friction_coulomb_N": -0.1}, "friction_coulomb_N must be finite and >= 0"),
        ({"friction_load_coefficient": float("nan")}, "friction_load_coefficient"),
        ({"friction_viscous_N_s_per_mm": -1e-3}, "friction_viscous_N_s_per_mm"),
        ({"friction_velocity_threshold_mm_per_s": 0.0}, "friction_velocity_threshold"),
        ({"tissue_scale": 0.0}, "tissue_scale must be finite and > 0"),
        ({"jaw_compliance_mm_per_N": -0.01}, "jaw_compliance_mm_per_N"),
        ({"backlash_deg": float("inf")}, "backlash_deg"),
        ({"prony_g": (0.3, 0.2), "prony_tau_s": (0.2,)}, "same length"),
        ({"prony_g": (0.1,) * 5, "prony_tau_s": (1.0,) * 5}, "at most 4 Prony terms, got 5"),
        ({"prony_g": (0.1, -0.2), "prony_tau_s": (1.0, 2.0)}, r"prony_g\[1\] must be"),
        ({"prony_g": (0.1,), "prony_tau_s": (0.0,)}, r"prony_tau_s\[0\] must be finite and > 0"),
        ({"prony_g": "0.3", "prony_tau_s": "1"}, "list of numbers"),
    ],
)
def test_bad_augmentation_parameters(kw, match):
    with pytest.raises(ValueError, match=match):
        ControllerParams(**kw)


def test_params_round_trip(tmp_path):
    p = ControllerParams(damping_Nms_per_rad=0.003, material="le")
    save_params(p, tmp_path / "c.json", extra={"tuning": {"x": 1}})
    assert load_params(tmp_path / "c.json") == p
    aug = ControllerParams(tissue_scale=1.3, jaw_compliance_mm_per_N=0.01, backlash_deg=0.2,
                           friction_coulomb_N=0.5, friction_load_coefficient=0.05,
                           friction_viscous_N_s_per_mm=0.002, prony_g=[0.3, 0.2],
                           prony_tau_s=[0.2, 1.0])  # fmt: skip
    assert aug.prony_g == (0.3, 0.2) and aug.prony_tau_s == (0.2, 1.0)  # lists -> tuples
    save_params(aug, tmp_path / "a.json")
    d = json.loads((tmp_path / "a.json").read_text())
    assert d["prony_g"] == [0.3, 0.2] and d["tissue_scale"] == 1.3
    back = load_params(tmp_path / "a.json")
    assert back == aug and hash(back) == hash(aug)
    d["prony_tau_s"] = [0.2]
    (tmp_path / "b.json").write_text(json.dumps(d))
    with pytest.raises(ValueError, match="b.json: .*same length"):
        load_params(tmp_path / "b.json")
    (tmp_path / "bad.json").write_text('{"foo": 1}')
    with pytest.raises(ValueError, match="bad.json: unknown key"):
        load_params(tmp_path / "bad.json")


def test_simulate_grasp_hold_release(surrogate):
    p = ControllerParams()
    traj = grasp_trajectory(close_s=0.5, hold_s=0.5, open_s=0.5)
    out = simulate(traj, p, surrogate)
    assert len(out) == len(traj)
    assert np.allclose(out["time_s"], traj["time_s"])
    closed = out["theta_deg"] < 0.01
    assert out.loc[closed, "contact"].all()
    assert out["force_jaw_N"].max() > 1.0
    # reopening releases the tissue
    assert out["force_jaw_N"].iloc[-1] == 0.0 and not out["contact"].iloc[-1]


@pytest.mark.parametrize(
    "frame,match",
    [
        (pd.DataFrame({"time_s": [0, 1]}), "missing column"),
        (pd.DataFrame({"time_s": [0, 1, 1], "theta_deg": [1, 2, 3]}), "row 3"),
        (pd.DataFrame({"time_s": [0, 1, 2], "theta_deg": [1, float("nan"), 3]}), "row 2"),
        (pd.DataFrame({"time_s": [0, 1, 2], "theta_deg": [1, 2, 30]}), "theta_deg', row 3"),
    ],
)
def test_simulate_input_errors(surrogate, frame, match):
    with pytest.raises(ValueError, match=match):
        simulate(frame, ControllerParams(), surrogate)


def test_simulate_cli_writes_nothing_on_error(tmp_path):
    traj = tmp_path / "traj.csv"
    pd.DataFrame({"time_s": [0.0, 0.001, 0.001], "theta_deg": [20, 19, 18]}).to_csv(traj)
    out = tmp_path / "sim.csv"
    cmd = [sys.executable, "-m", "grasprom", "simulate", "--trajectory", str(traj)]
    r = subprocess.run(
        [*cmd, "--out", str(out)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2
    assert "row 3" in r.stderr and "time_s" in r.stderr
    assert not out.exists() and not list(tmp_path.glob("*.tmp"))
