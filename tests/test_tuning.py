"""Passivity tuning (grasprom.tuning, ``grasprom tune``)."""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from grasprom import tuning as tn
from grasprom.cli import main
from grasprom.controller import ControllerParams, ImpedanceController, load_params
from grasprom.surrogate import Surrogate

ROOT = Path(__file__).resolve().parents[1]
T = 1e-3


@pytest.fixture(scope="session")
def sur() -> Surrogate:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return Surrogate.build(ROOT / "fe_data" / "default")


@pytest.fixture(scope="session")
def tuned(sur) -> tn.TuningResult:
    return tn.tune(sur)


# ------------------------------------------------------------------ passivity conditions
@pytest.mark.parametrize("K", [0.0, 3.0, 20.0, 150.0])
@pytest.mark.parametrize("B", [0.0, 0.002, -0.004, 0.05])
def test_colgate_bound_matches_closed_form(K, B):
    # no delay, raw backward difference: b > K T / 2 + |B|
    got = tn.required_damping(K, B, T, None, 0)
    assert got == pytest.approx(tn.colgate_required_damping(K, B, T), rel=1e-5, abs=1e-9)


def test_delay_bound_closed_form_and_inverse():
    # one-sample delay, B = 0: b > 3 K T / 2
    assert tn.required_damping(10.0, 0.0, T, None, 1) == pytest.approx(15.0 * T, rel=1e-5)
    assert tn.max_passive_stiffness(0.01, 0.0, T, None, 0) == pytest.approx(20.0, rel=1e-9)
    # K_max inverts required_damping, also with B, filter and delay
    for B, fc, d in [(0.002, 100.0, 1), (0.0, 30.0, 1), (0.004, 200.0, 0)]:
        kmax = tn.max_passive_stiffness(0.01, B, T, fc, d)
        assert kmax > 0
        assert tn.required_damping(kmax, B, T, fc, d) == pytest.approx(0.01, rel=1e-6)
    # filtered virtual damping offsets the delay's negative damping at low frequency
    assert tn.max_passive_stiffness(0.01, 0.002, T, 100.0, 1) > tn.max_passive_stiffness(
        0.01, 0.0, T, 100.0, 1
    )
    # too much damping: nothing is passive
    assert tn.max_passive_stiffness(0.01, 0.05, T, None, 0) == 0.0


def test_abbott_okamura():
    assert tn.abbott_okamura_bound(0.01, T, 0.0, 1e-3) == pytest.approx(20.0)
    assert tn.abbott_okamura_bound(0.01, T, 0.01, 1e-4) == pytest.approx(200.0)
    assert tn.abbott_okamura_bound(0.01, T, 0.01, 0.0) == math.inf


# ------------------------------------------------------------------ rendered stiffness
@pytest.mark.parametrize("material,thickness", [("le", 2.0), ("mr", 1.4), ("nh", 0.8)])
def test_chain_stiffness_matches_controller_static_map(sur, material, thickness):
    p = ControllerParams(material=material, thickness_mm=thickness, encoder_counts_per_rev=0,
                         coupling_stiffness_N_per_mm=1.0)
    L3 = p.chain_params.L3_mm * 1e-3
    h = 1e-5

    def static_torque(th_rad: float) -> float:
        c = ImpedanceController(p, sur)
        c.reset(th_rad)
        for _ in range(30):  # proxy converges, velocity stays 0
            out = c.step(th_rad)
        return out.force_handle_N * L3

    ths = np.array([0.3, 1.0, 3.0, 8.0, 15.0, 21.0])
    op = tn.rendered_stiffness(sur, p, ths)
    for th, K in zip(ths, op.K_Nm_per_rad):
        t = math.radians(th)
        fd = -(static_torque(t + h) - static_torque(t - h)) / (2 * h)
        assert K == pytest.approx(fd, rel=2e-3, abs=1e-4), th
        assert tn.static_handle_torque_Nm(sur, p, np.array([t]))[0] == pytest.approx(
            static_torque(t), rel=1e-9, abs=1e-12
        )
    # the coupling bounds the jaw stiffness; raw tissue is far stiffer at the closed end
    assert np.all(op.jaw_stiffness_N_per_mm <= 1.0 + 1e-12)
    op0 = tn.rendered_stiffness(sur, p, [0.0])
    assert op0.K_raw_Nm_per_rad[0] > 50 * op0.K_Nm_per_rad[0]


# ------------------------------------------------------------------ tuning
def test_tuned_parameters_are_passive_everywhere(sur, tuned):
    sm = tuned.summary
    p = tuned.params
    assert sm["passive_everywhere"]
    assert sm["passivity_margin"] >= sm["safety_factor"] * (1 - 1e-6)
    # every operating point satisfies the delay-aware condition with margin
    allK = np.concatenate([o.K_Nm_per_rad for o in tuned.points])
    b_req = tn.required_damping(np.array([allK.max(), allK.min()]), p.damping_Nms_per_rad, T,
                                p.velocity_cutoff_Hz, 1)
    assert np.all(b_req * sm["safety_factor"] <= tuned.device.damping_Nms_per_rad * (1 + 1e-9))
    # k_c is (nearly) the largest: a 10 % stiffer coupling breaks the margin
    p2 = replace(p, coupling_stiffness_N_per_mm=1.1 * p.coupling_stiffness_N_per_mm)
    K2 = max(float(o.K_Nm_per_rad.max()) for o in tn.operating_points(sur, p2, n_theta=56))
    assert tn.required_damping(K2, p.damping_Nms_per_rad, T, p.velocity_cutoff_Hz, 1) * sm[
        "safety_factor"] > tuned.device.damping_Nms_per_rad
    assert sm["closed_loop_with_hand"]["stable"]
    assert sm["closed_loop_device_alone"]["stable"]
    # the raw tissue cannot be rendered at 1 kHz with this damping
    assert sm["raw_tissue"]["required_rate_Hz"] > 1e5
    assert {r["material"] for r in sm["raw_tissue"]["not_renderable"]} == {"le", "mr", "nh"}


def test_tuned_pass_and_rejected_oscillate_in_simulation(tuned):
    sim = tuned.summary["simulation"]
    ok, bad = sim["chosen"], sim["rejected"]
    assert ok["material"] == "le"
    assert not ok["growing"]
    assert ok["net_generated_J"] <= 1e-9
    assert ok["max_pole_mag_with_hand"] < 1.0
    assert bad["growing"]
    assert bad["net_generated_J"] > 1e-4
    assert bad["max_pole_mag_with_hand"] > 1.0


def test_zero_damping_on_low_damping_device_oscillates(sur, tuned):
    # the tuner's B on a device with 10x less physical damping and no friction: rejected
    dev = tn.DeviceParams(damping_Nms_per_rad=0.001, coulomb_Nm=0.0)
    p = replace(tuned.params, material="le", thickness_mm=2.0, damping_Nms_per_rad=0.0)
    sim = tn.simulate_hold(sur, p, dev, tuned.hand, theta_start_offset_deg=1.0)
    assert sim["growing"]
    assert sim["net_generated_J"] > 0
    K = float(tn.rendered_stiffness(sur, p, [sim["theta_hold_deg"]]).K_Nm_per_rad[0])
    assert tn.required_damping(K, 0.0, T, p.velocity_cutoff_Hz, 1) > dev.damping_Nms_per_rad
    # and the tuner, run for that device, picks a much softer coupling
    r = tn.tune(sur, device=dev, materials=["le"], thicknesses=[2.0], verify=False, n_theta=45)
    assert r.params.coupling_stiffness_N_per_mm < 0.2 * tuned.params.coupling_stiffness_N_per_mm


@pytest.mark.parametrize("factor", [1.0, 1.5, 5.0])
def test_pole_check_agrees_with_energy_simulation(sur, tuned, factor):
    # frictionless, unquantised device: the linear verdict must match the simulation
    dev = replace(tuned.device, coulomb_Nm=0.0)
    p = replace(tuned.params, material="le", thickness_mm=2.0,
                coupling_stiffness_N_per_mm=factor * tuned.params.coupling_stiffness_N_per_mm)
    sim = tn.simulate_hold(sur, p, dev, tuned.hand, theta_hold_deg=1.0,
                           theta_start_offset_deg=0.05, duration_s=1.0, quantise=False)
    K = float(tn.rendered_stiffness(sur, p, [sim["theta_hold_deg"]]).K_Nm_per_rad[0])
    cl = tn.closed_loop(K, p.damping_Nms_per_rad, p.velocity_cutoff_Hz, T, dev, tuned.hand,
                        p.chain_params.L3_mm)
    decays = sim["amp_last_rad"] < sim["amp_first_rad"] and not sim["hit_stop"]
    assert decays == cl["stable"]
    assert sim["growing"] == (not cl["stable"])
    # decay per window predicted by the dominant pole (0.4 s between window centres)
    if cl["stable"]:
        ratio = sim["amp_last_rad"] / sim["amp_first_rad"]
        assert ratio == pytest.approx(cl["max_pole_mag"] ** 400, rel=0.35)
    passive = tn.required_damping(K, p.damping_Nms_per_rad, T, p.velocity_cutoff_Hz,
                                  1) < dev.damping_Nms_per_rad
    if passive:
        assert sim["net_generated_J"] <= 1e-9
    if not cl["stable"]:
        assert sim["net_generated_J"] > 0


def test_closed_loop_margins_shape(tuned):
    cl = tuned.summary["closed_loop_with_hand"]
    assert cl["gain_margin"] > 1.0
    assert cl["phase_margin_deg"] > 0.0


# ------------------------------------------------------------------ outputs and CLI
def test_cli_tune_writes_outputs(sur, tmp_path, capsys):
    sj = sur.save(tmp_path / "sur.json")
    out = tmp_path / "tune"
    rc = main(["tune", "--surrogate", str(sj), "--material", "le,mr", "--thickness", "1.0,2.0",
               "--out", str(out)])
    assert rc == 0, capsys.readouterr().err
    text = capsys.readouterr().out
    assert "chosen: k_c =" in text and "passive everywhere" in text
    for name in ("controller.json", "tuning.json", "tuning.txt", "stiffness_vs_theta.png",
                 "zwidth.png", "bode_impedance.png"):
        assert (out / name).stat().st_size > 0, name
    p = load_params(out / "controller.json")
    tj = json.loads((out / "tuning.json").read_text())
    assert p.coupling_stiffness_N_per_mm == tj["chosen"]["coupling_stiffness_N_per_mm"]
    assert p.damping_Nms_per_rad == tj["chosen"]["damping_Nms_per_rad"]
    assert p.velocity_cutoff_Hz == tj["chosen"]["velocity_cutoff_Hz"]
    assert json.loads((out / "controller.json").read_text())["tuning"]["passive_everywhere"]
    # a slower rate needs a softer coupling
    rc = main(["tune", "--surrogate", str(sj), "--material", "le", "--thickness", "2.0",
               "--rate-hz", "500", "--no-plots", "--out", str(tmp_path / "t500")])
    assert rc == 0
    p500 = load_params(tmp_path / "t500" / "controller.json")
    assert p500.sample_time_s == pytest.approx(2e-3)
    assert p500.coupling_stiffness_N_per_mm < p.coupling_stiffness_N_per_mm


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--material", "xx"], "material 'xx'"),
        (["--thickness", "5.0"], "outside the surrogate's range"),
        (["--thickness", "1.0,abc"], "--thickness"),
        (["--rate-hz", "0"], "--rate-hz"),
        (["--rate-hz", "nan"], "--rate-hz"),
        (["--safety", "0.5"], "safety"),
        (["--surrogate", "/nonexistent/sur.json"], "sur.json"),
    ],
)
def test_cli_tune_bad_input(sur, tmp_path, capsys, args, needle):
    full = ["tune", "--out", str(tmp_path / "o"), "--no-plots"] + args
    if "--surrogate" not in args:
        sj = tmp_path / "sur.json"
        sur.save(sj)
        full += ["--surrogate", str(sj)]
    assert main(full) == 2
    assert needle in capsys.readouterr().err
    assert not (tmp_path / "o" / "controller.json").exists()


def test_bad_parameters():
    with pytest.raises(ValueError, match="damping_Nms_per_rad"):
        tn.DeviceParams(damping_Nms_per_rad=-1.0)
    with pytest.raises(ValueError, match="inertia_kg_m2"):
        tn.DeviceParams(inertia_kg_m2=0.0)
    with pytest.raises(ValueError, match="delay_samples"):
        tn.DeviceParams(delay_samples=-1)
    with pytest.raises(ValueError, match="coulomb_Nm"):
        tn.DeviceParams(coulomb_Nm=float("nan"))
    with pytest.raises(ValueError, match="stiffness_N_per_m"):
        tn.HandParams(stiffness_N_per_m=-5.0)
    h = tn.HandParams(mass_kg=0.01, damping_Ns_per_m=2.0, stiffness_N_per_m=300.0)
    jh, bh, kh = h.at_pivot(54.1)
    assert kh == pytest.approx(300.0 * 0.0541**2)
    assert bh == pytest.approx(2.0 * 0.0541**2)
    assert jh == pytest.approx(0.01 * 0.0541**2)
