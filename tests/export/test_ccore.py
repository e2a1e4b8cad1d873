"""Parity of the C controller core (gcc, ctypes) with the Python reference: to 1e-9 for the
coupling, bit-identical (``==``) for the clipped rendering (the default) and its field table.

The general cases (:data:`CASES`) run with both renderings; :data:`CLIPPED_CASES` add limits and
effects of the clipped field, :data:`OBSERVER_CASES` the passivity observer."""

from __future__ import annotations

import dataclasses
import math
import shutil

import numpy as np
import pytest

from grasprom.control import ControllerParams, ImpedanceController, grasp_trajectory
from grasprom.control.field import FIELD_POINTS
from grasprom.export.ccore import CCore, c_params
from grasprom.export.codegen import tables_source


def _trajectories():
    slow = grasp_trajectory(close_s=2.0, hold_s=1.0, open_s=2.0)["theta_deg"].to_numpy()
    fast = grasp_trajectory(close_s=0.15, hold_s=0.3, open_s=0.1)["theta_deg"].to_numpy()
    rng = np.random.default_rng(7)
    wiggle = np.clip(11 + 11 * np.sin(np.linspace(0, 40, 3000)) + rng.normal(0, 0.3, 3000), 0, 22)
    edge = np.array([22.0, 25.0, -3.0, np.nan, 0.0, np.inf, -np.inf, 10.0, np.nan, 0.0])
    return {"slow": slow, "fast": fast, "wiggle": wiggle, "edge": edge}


CASES = [  # each with rendering "coupling" (to 1e-9) and "clipped" (bit for bit)
    ("mr", 1.4, {}),  # on a grid node
    ("nh", 0.85, {"damping_Nms_per_rad": 0.02}),  # between nodes
    ("le", 1.95, {"coupling_stiffness_N_per_mm": 80.0, "torque_limit_Nm": 0.3}),
    ("le", 0.8, {"encoder_counts_per_rev": 0, "render_spring": False}),
    ("mr", 2.0, {"velocity_cutoff_Hz": 5.0, "damping_Nms_per_rad": 0.05}),
    # every rendered effect of an augmented model (grasprom diagnose) at once
    (
        "mr",
        1.4,
        {
            "tissue_scale": 1.3,
            "jaw_compliance_mm_per_N": 0.01,
            "backlash_deg": 0.3,
            "friction_coulomb_N": 2.0,
            "friction_load_coefficient": 0.1,
            "friction_viscous_N_s_per_mm": 0.02,
            "prony_g": (0.3, 0.2),
            "prony_tau_s": (0.2, 1.0),
        },
    ),
    (
        "nh",
        1.15,
        {
            "prony_g": (0.5, 0.1, 0.05, 0.02),
            "prony_tau_s": (0.01, 0.1, 1.0, 10.0),
            "friction_coulomb_N": 1.0,
            "encoder_counts_per_rev": 0,
            "tissue_scale": 0.7,
        },
    ),
]


def test_gcc_is_available():
    """The C parity tests need gcc; CI installs it, so its absence is a failure, not a skip."""
    assert shutil.which("gcc"), "gcc not found: install it (Debian: apt-get install gcc)"


@pytest.mark.parametrize("rendering", ["coupling", "clipped"])
@pytest.mark.parametrize("material,t,extra", CASES)
def test_c_core_matches_python_reference(surrogate, core, material, t, extra, rendering):
    """Every output of every step on the parity trajectories, with either rendering: the
    virtual coupling to 1e-9, the clipped field bit for bit (``==``)."""
    p = ControllerParams(thickness_mm=t, material=material, rendering=rendering, **extra)
    assert (ImpedanceController(p, surrogate).field is None) == (rendering == "coupling")
    for name, traj in _trajectories().items():
        core.reset(p)
        assert (core.field() is None) == (rendering == "coupling")
        ref = ImpedanceController(p, surrogate)
        for k, th_deg in enumerate(traj):
            a = core.step(math.radians(th_deg))
            b = ref.step(math.radians(th_deg))
            if rendering == "clipped":
                _assert_identical(a, b, (name, k))
                continue
            for field, x, y in zip(a._fields, a, b):
                if isinstance(y, bool):
                    assert x == y, (name, k, field)
                else:
                    assert x == pytest.approx(y, rel=1e-9, abs=1e-12), (name, k, field, x, y)


def test_c_core_clamps_thickness_and_rejects_bad_params(surrogate, tmp_path):
    p = ControllerParams()
    core = CCore(p, surrogate, tmp_path)
    assert core.reset(dataclasses.replace(p, thickness_mm=2.0)) == 0
    raw = c_params(p)
    raw.thickness = 2.5  # beyond the table: clamped + flagged
    assert core.init_raw(raw) == 1
    ref = ImpedanceController(dataclasses.replace(p, thickness_mm=2.0), surrogate)
    assert core.step(0.0).force_tissue_N == ref.step(0.0).force_tissue_N
    for field, value in (("pulley_radius", -1.0), ("sample_time", float("nan")), ("material", 3)):
        raw = c_params(p)
        setattr(raw, field, value)
        with pytest.raises(ValueError, match="rejected"):
            core.init_raw(raw)


def test_c_core_refuses_a_material_the_surrogate_lacks(surrogate_mr_le, tmp_path):
    """Issue 16: the tables of a surrogate without nh keep the material codes (0 mr, 2 le) and
    give nh a row without curves, which gc_check_params refuses; le runs as in Python."""
    src = tables_source(surrogate_mr_le, ControllerParams().chain_params)
    assert "gc_nh_" not in src and "gc_le_0_x" in src and "gc_mr_0_x" in src
    assert "/* 1: nh, not in this export's surrogate */" in src
    p = ControllerParams(material="le", thickness_mm=1.2)
    core = CCore(p, surrogate_mr_le, tmp_path)
    ref = ImpedanceController(p, surrogate_mr_le)
    for th in (0.3, 0.05, 0.02):
        assert core.step(th).force_tissue_N == pytest.approx(ref.step(th).force_tissue_N, rel=1e-9)
    assert ref.step(0.02).force_tissue_N > 1.0
    for code in (1, 3):
        raw = c_params(p)
        raw.material = code
        with pytest.raises(ValueError, match="code -1.*material code not in this export"):
            core.init_raw(raw)
    with pytest.raises(ValueError, match="'nh' is not in the surrogate, which covers"):
        ImpedanceController(ControllerParams(material="nh"), surrogate_mr_le)


def test_tables_are_exact_hex_literals(surrogate):
    src = tables_source(surrogate, ControllerParams().chain_params)
    x0 = surrogate.table("mr").s_curves[0][0][1]
    assert float(x0).hex() in src
    assert "GC_MATERIALS[GC_N_MATERIALS]" in src


def test_c_core_measured_velocity_matches_python(surrogate, tmp_path):
    """gc_step_ext (damping on a measured velocity) against ImpedanceController.step(theta_dot),
    with the coupling (the clipped field: test_c_core_clipped_measured_velocity_is_bit_identical).
    """
    p = ControllerParams(material="nh", thickness_mm=1.15, damping_Nms_per_rad=0.01,
                         rendering="coupling")  # fmt: skip
    core = CCore(p, surrogate, tmp_path)
    ref = ImpedanceController(p, surrogate)
    th = _trajectories()["fast"]
    w = np.gradient(np.radians(th), 1e-3)
    w[::97] = np.nan  # non-finite velocity: both fall back to the filtered estimate
    for k, (a_deg, v) in enumerate(zip(th, w)):
        a = core.step(math.radians(a_deg), v)
        b = ref.step(math.radians(a_deg), v)
        for field, x, y in zip(a._fields, a, b):
            if isinstance(y, bool):
                assert x == y, (k, field)
            else:
                assert x == pytest.approx(y, rel=1e-9, abs=1e-12), (k, field, x, y)
    # the measured velocity changes the damping term only
    ref2 = ImpedanceController(p, surrogate)
    o1 = ref2.step(0.2)
    o2 = ImpedanceController(p, surrogate).step(0.2, -1.0)
    assert o2.force_handle_N - o1.force_handle_N == pytest.approx(
        0.01 * 1.0 / (p.chain.L3_mm * 1e-3), rel=1e-9
    )


def test_augmented_rendering_changes_the_c_output(surrogate, tmp_path):
    """The parity above is not trivial: the rendered effects move the C core's torque."""
    base = ControllerParams()
    aug = dataclasses.replace(
        base,
        tissue_scale=1.3,
        backlash_deg=0.3,
        friction_coulomb_N=2.0,
        prony_g=(0.3,),
        prony_tau_s=(0.2,),
    )
    th = _trajectories()["slow"]
    out = []
    for p in (base, aug):
        core = CCore(p, surrogate, tmp_path / str(len(out)))
        out.append(np.array([core.step(math.radians(a)).force_handle_N for a in th]))
    assert np.max(np.abs(out[1] - out[0])) > 1.0  # N


# ------------------------------------------------------------------ clipped rendering (issue 13)
AUGMENTED = {
    "tissue_scale": 1.3,
    "jaw_compliance_mm_per_N": 0.01,
    "backlash_deg": 0.3,
    "friction_coulomb_N": 2.0,
    "friction_load_coefficient": 0.1,
    "friction_viscous_N_s_per_mm": 0.02,
    "prony_g": (0.3, 0.2),
    "prony_tau_s": (0.2, 1.0),
}

CLIPPED_CASES = [  # each with rendering "coupling" (to 1e-9) and "clipped" (bit for bit)
    ("mr", 1.4, {}),  # on a grid node
    ("mr", 0.95, {"stiffness_limit_Nm_per_rad": 2.0, "damping_Nms_per_rad": 0.02}),
    ("le", 1.95, {"torque_limit_Nm": 0.3}),  # saturates
    ("le", 0.8, {"encoder_counts_per_rev": 0, "render_spring": False}),
    ("nh", 1.15, {"stiffness_limit_Nm_per_rad": 40.0, "velocity_cutoff_Hz": 5.0}),
    ("mr", 1.4, AUGMENTED),  # every rendered effect of an augmented model at once
    ("le", 1.2, {**AUGMENTED, "prony_g": (0.5, 0.1, 0.05, 0.02),
                 "prony_tau_s": (0.01, 0.1, 1.0, 10.0), "stiffness_limit_Nm_per_rad": 3.0}),
]  # fmt: skip


def _clipped(case) -> ControllerParams:
    material, t, extra = case
    return ControllerParams(thickness_mm=t, material=material, rendering="clipped", **extra)


@pytest.fixture(scope="module")
def core(surrogate, tmp_path_factory):
    """One host build of the C core (the chain is the same for every case: reset per case)."""
    return CCore(ControllerParams(), surrogate, tmp_path_factory.mktemp("ccore"))


def _assert_identical(a, b, what) -> float:
    """Every output field bit-identical (``==``, floats and flags); returns max |a - b| (0)."""
    worst = 0.0
    for field, x, y in zip(a._fields, a, b):
        assert x == y, (*what, field, x, y)
        if not isinstance(y, bool):
            worst = max(worst, abs(x - y))
    return worst


@pytest.mark.parametrize("case", CLIPPED_CASES, ids=[f"{m}-{t}" for m, t, _ in CLIPPED_CASES])
def test_c_field_table_is_the_python_table_node_for_node(surrogate, core, case):
    p = _clipped(case)
    core.reset(p)
    ref = ImpedanceController(p, surrogate).field
    got = core.field()
    assert got is not None and len(got.force_jaw_N) == FIELD_POINTS == len(ref.force_jaw_N)
    assert got.theta_lo_rad == ref.theta_lo_rad and got.dtheta_rad == ref.dtheta_rad
    assert got.stiffness_limit_N_per_rad == ref.stiffness_limit_N_per_rad
    assert got.force_jaw_N == ref.force_jaw_N  # every node, bit for bit
    assert got.clipped == ref.clipped
    assert any(ref.clipped) and not all(ref.clipped)  # the limit acts somewhere, not everywhere


@pytest.mark.parametrize("case", CLIPPED_CASES, ids=[f"{m}-{t}" for m, t, _ in CLIPPED_CASES])
def test_c_core_clipped_is_bit_identical_to_python(surrogate, core, case):
    p = _clipped(case)
    worst = 0.0
    active = 0
    for name, traj in _trajectories().items():
        core.reset(p)
        ref = ImpedanceController(p, surrogate)
        for k, th_deg in enumerate(traj):
            a = core.step(math.radians(th_deg))
            b = ref.step(math.radians(th_deg))
            worst = max(worst, _assert_identical(a, b, (name, k)))
            active += b.coupling_active
    assert worst == 0.0 and active > 0
    print(f"clipped {case[0]} {case[1]} mm: max |C - Python| = {worst}")


def test_c_core_clipped_measured_velocity_is_bit_identical(surrogate, core):
    """gc_step_ext with the clipped field (damping on a measured velocity)."""
    p = dataclasses.replace(_clipped(CLIPPED_CASES[5]), damping_Nms_per_rad=0.01)
    core.reset(p)
    ref = ImpedanceController(p, surrogate)
    th = _trajectories()["fast"]
    w = np.gradient(np.radians(th), 1e-3)
    w[::97] = np.nan
    for k, (a_deg, v) in enumerate(zip(th, w)):
        _assert_identical(core.step(math.radians(a_deg), v), ref.step(math.radians(a_deg), v), (k,))


def test_clipped_changes_the_output_and_coupling_has_no_field(surrogate, core):
    """Not trivial: the clipped field renders other forces than the coupling; with the coupling
    the C core has no table and its outputs stay the coupling's (the parity tests above:
    test_c_core_matches_python_reference runs every case with either rendering)."""
    th = _trajectories()["slow"]
    out = {}
    for rendering in ("coupling", "clipped"):
        p = ControllerParams(rendering=rendering)
        core.reset(p)
        out[rendering] = np.array([core.step(math.radians(a)).force_jaw_N for a in th])
        assert (core.field() is None) == (rendering == "coupling")
    assert np.max(np.abs(out["clipped"] - out["coupling"])) > 0.1  # N


def test_c_core_checks_the_rendering_parameters(core):
    p = ControllerParams(rendering="coupling")
    for field, value, match in (
        ("rendering", 2, "rendering must be 0 .coupling. or 1 .clipped."),
        ("rendering", -1, "rendering must be"),
        ("stiffness_limit", 0.0, "stiffness_limit must be finite and > 0"),
        ("stiffness_limit", float("nan"), "stiffness_limit"),
        ("stiffness_limit", float("inf"), "stiffness_limit"),
    ):
        raw = c_params(p)
        setattr(raw, field, value)
        with pytest.raises(ValueError, match=f"rejected.*{match}"):
            core.init_raw(raw)
    assert c_params(dataclasses.replace(p, rendering="clipped")).rendering == 1
    assert c_params(p).rendering == 0
    assert c_params(p).stiffness_limit == p.stiffness_limit_Nm_per_rad


def test_build_without_the_field_table_refuses_clipped(surrogate, tmp_path):
    """GC_FIELD_N = 0 (the AVR default: 2 KB of RAM) leaves the table out; the core then
    refuses the clipped rendering with a clear message and still runs the coupling."""
    p = ControllerParams(rendering="coupling")
    small = CCore(p, surrogate, tmp_path, defines=("GC_FIELD_N=0",))
    with pytest.raises(ValueError, match="clipped.*needs the field table"):
        small.reset(dataclasses.replace(p, rendering="clipped"))
    small.reset(p)
    ref = ImpedanceController(p, surrogate)
    for a in _trajectories()["fast"]:
        _assert_identical(small.step(math.radians(a)), ref.step(math.radians(a)), (a,))


def test_c_prony_factor_sums_left_to_right(core):
    """K_g = K_lim / (L3 1e-3) / (1 + g_1 + ... + g_n), the sum from 0 left to right, as
    Python's ``sum`` of floats up to 3.11 (3.12 compensates the rounding: 0.1 + 0.2 + 0.3 is
    then 0.6, not 0.6000000000000001; the reference must keep the plain order for parity)."""
    p = ControllerParams(rendering="clipped", prony_g=(0.1, 0.2, 0.3), prony_tau_s=(0.1, 1, 10))
    core.reset(p)
    acc = 0.0
    for g in p.prony_g:
        acc += g
    assert acc == 0.6000000000000001
    kg = p.stiffness_limit_Nm_per_rad / (p.chain.L3_mm * 1e-3) / (1.0 + acc)
    assert core.field().stiffness_limit_N_per_rad == kg


# ------------------------------------------------------------------ passivity observer (issue 13)
OBSERVER_CASES = [
    ("le", 2.0, {}),  # the energy test's wall, 5x the bound
    ("le", 1.95, {"torque_limit_Nm": 0.3, "observer_delay_samples": 0}),  # saturates
    ("mr", 1.4, {**AUGMENTED, "observer_delay_samples": 2,
                 "observer_max_damping_Nms_per_rad": 0.05}),
    ("nh", 1.15, {"observer_stiffness_factor": 8.0, "observer_delay_samples": 4,
                  "encoder_counts_per_rev": 0, "render_spring": False}),
]  # fmt: skip


def _observer(case) -> ControllerParams:
    material, t, extra = case
    return ControllerParams(thickness_mm=t, material=material, rendering="clipped",
                            passivity_observer=True, **extra)  # fmt: skip


def _observer_angles(surrogate, p) -> dict[str, np.ndarray]:
    """The parity trajectories (deg) and the closed loop of the energy test (its handle
    angles: the observer acts there), converted to deg."""
    from tests.control.test_observer import simulate_energy

    out = dict(_trajectories())
    out["loop"] = np.degrees(simulate_energy(p, surrogate, 0.15).theta_rad)
    return out


@pytest.mark.parametrize("case", OBSERVER_CASES, ids=[f"{m}-{t}" for m, t, _ in OBSERVER_CASES])
def test_c_core_observer_is_bit_identical_to_python(surrogate, core, case):
    """Every output, the observed energy and the added damping, step for step (``==``)."""
    p = _observer(case)
    acting = 0
    for name, traj in _observer_angles(surrogate, p).items():
        core.reset(p)
        ref = ImpedanceController(p, surrogate)
        for k, th_deg in enumerate(traj):
            a = core.step(math.radians(th_deg))
            b = ref.step(math.radians(th_deg))
            _assert_identical(a, b, (name, k))
            w = (ref.observer_energy_J, ref.observer_damping_Nms_per_rad)
            assert core.observer() == w, (name, k)
            acting += w[1] > 0.0
    assert acting > 0  # the controller damps somewhere
    got, want = core.field(), ImpedanceController(p, surrogate).field
    assert got.stiffness_limit_N_per_rad == want.stiffness_limit_N_per_rad
    assert got.force_jaw_N == want.force_jaw_N  # the field at K_lim x factor, node for node


def test_c_core_observer_measured_velocity_is_bit_identical(surrogate, core):
    """gc_step_ext with the observer: the damping acts on theta_dot (NaN: the estimate)."""
    p = _observer(OBSERVER_CASES[0])
    core.reset(p)
    ref = ImpedanceController(p, surrogate)
    th = _observer_angles(surrogate, p)["loop"]
    w = np.gradient(np.radians(th), 1e-3)
    w[::97] = np.nan
    w[5::89] = 0.0
    for k, (a_deg, v) in enumerate(zip(th, w)):
        _assert_identical(core.step(math.radians(a_deg), v), ref.step(math.radians(a_deg), v), (k,))
        assert core.observer() == (ref.observer_energy_J, ref.observer_damping_Nms_per_rad)


def test_observer_off_leaves_the_clipped_output_unchanged(surrogate, core):
    """The observer's parameters do nothing while it is off (C and Python)."""
    base = _clipped(CLIPPED_CASES[0])
    other = dataclasses.replace(base, observer_stiffness_factor=7.0, observer_delay_samples=3,
                                observer_max_damping_Nms_per_rad=9.0)  # fmt: skip
    th = _trajectories()["fast"]
    runs = []
    for p in (base, other):
        core.reset(p)
        ref = ImpedanceController(p, surrogate)
        runs.append([(core.step(math.radians(a)), ref.step(math.radians(a))) for a in th])
    for (a0, b0), (a1, b1) in zip(*runs):
        assert tuple(a0) == tuple(b0) == tuple(a1) == tuple(b1)


def test_c_core_checks_the_observer_parameters(core):
    p = ControllerParams(rendering="clipped", passivity_observer=True)
    for field, value, match in (
        ("passivity_observer", 2, "passivity_observer must be 0 or 1"),
        ("observer_stiffness_factor", 0.5, "observer_stiffness_factor must be finite and >= 1"),
        ("observer_stiffness_factor", float("nan"), "observer_stiffness_factor"),
        ("observer_max_damping", 0.0, "observer_max_damping must be finite and > 0"),
        ("observer_max_damping", float("inf"), "observer_max_damping"),
        ("observer_delay", 5, "observer_delay must be 0 .. 4"),
        ("observer_delay", -1, "observer_delay"),
        ("rendering", 0, "passivity_observer needs rendering 1 .clipped."),
    ):
        raw = c_params(p)
        setattr(raw, field, value)
        with pytest.raises(ValueError, match=f"rejected.*{match}"):
            core.init_raw(raw)
    raw = c_params(p)
    assert (raw.passivity_observer, raw.observer_delay) == (1, 1)
    assert raw.observer_stiffness_factor == 5.0
    assert raw.observer_max_damping == p.observer_max_damping_Nms_per_rad
    assert c_params(ControllerParams()).passivity_observer == 0
