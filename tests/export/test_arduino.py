"""Arduino export: fixed-point core vs the Python reference, on the host and on the AVR (simavr).

CI installs gcc-avr avr-libc binutils-avr simavr libsimavr-dev arduino-mk arduino-core-avr; with
``CI=true`` a missing tool is a failure, never a skip.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
from pathlib import Path

import numpy as np
import pytest

from grasprom.control import ControllerParams, ImpedanceController
from grasprom.export import arduino as ar
from tests.tools import CI, need


def need_simavr() -> None:
    need("gcc", "gcc")
    if not Path("/usr/include/simavr/sim_avr.h").exists():
        msg = "libsimavr headers not found: apt-get install simavr libsimavr-dev"
        if CI:
            pytest.fail(msg)
        pytest.skip(msg)


@pytest.fixture(scope="module")
def tables(surrogate):
    """The default export's tables: the clipped rendering (the default since issue 13)."""
    return ar.build_tables(surrogate, ControllerParams(), 0.01)


@pytest.fixture(scope="module")
def coupling_tables(surrogate):
    """The same export with the virtual coupling (rendering="coupling")."""
    return ar.build_tables(surrogate, ControllerParams(rendering="coupling"), 0.01)


@pytest.fixture(scope="module", params=["coupling", "clipped"])
def host_dense(request, surrogate, tables, coupling_tables, tmp_path_factory):
    """``(rendering, tables, dense cases, host run)`` for either rendering."""
    need("gcc", "gcc")
    t = coupling_tables if request.param == "coupling" else tables
    assert t.params.rendering == request.param
    cases = ar.default_cases(t, surrogate, dense=True)
    return request.param, t, cases, ar.run_host(t, cases, tmp_path_factory.mktemp("host"))


def test_tools_installed_on_ci():
    """CI must provide the AVR toolchain, simavr and arduino-mk: their absence fails there."""
    for tool, pkg in (("avr-gcc", "gcc-avr"), ("avr-size", "binutils-avr"),
                      ("simavr", "simavr"), ("make", "make")):  # fmt: skip
        need(tool, pkg)
    cores = "/usr/share/arduino/hardware/arduino/avr/cores"
    for path, pkg in (("/usr/include/simavr/sim_avr.h", "libsimavr-dev"),
                      ("/usr/share/arduino/Arduino.mk", "arduino-mk"),
                      (cores, "arduino-core-avr")):  # fmt: skip
        if not Path(path).exists():
            (pytest.fail if CI else pytest.skip)(f"{path} missing: apt-get install {pkg}")


def test_tables_document_scaling_and_trade_flash_for_accuracy(surrogate, tables):
    src = tables.tables_source()
    assert "GF_PROGMEM" in src and "Q15" in src and "mN" in src and "um" in src
    cfg = tables.config_source()
    for name in ("GF_N_TOP", "GF_N_CONTACT", "GF_FI_LIMIT_MN", "GF_VEL_B", "GF_Q_RAD"):
        assert f"#define {name} " in cfg
    fine = ar.build_tables(surrogate, ControllerParams(), 0.0025)
    coarse = ar.build_tables(surrogate, ControllerParams(), 0.02)
    assert fine.table_bytes > tables.table_bytes > coarse.table_bytes
    assert tables.n_lo == 0 and tables.n_top == 1354  # 22 deg in counts of 2 pi r / (4096 L3)
    with pytest.raises(ValueError, match="encoder"):
        ar.build_tables(surrogate, ControllerParams(encoder_counts_per_rev=0))


@pytest.mark.parametrize("rendering", ["coupling", "clipped"])
def test_reference_matches_the_python_controller(surrogate, tables, rendering):
    """The vectorised reference is what ImpedanceController computes on a sweep, with either
    rendering: the converged-coupling reference to 1e-4 of full scale and at most 2 flag
    mismatches (the controller warm-starts 3 Newton iterations per step; measured 6e-14 FS,
    none); the clipped field's reference to rounding (1e-9 N), flags exact."""
    p = ControllerParams(material="nh", thickness_mm=1.3, rendering=rendering)
    counts = ar.sweep_counts(tables)
    ref = ar.reference_run(p, surrogate, "nh", 1.3, counts)
    ctl = ImpedanceController(p, surrogate)
    out = [ctl.step(n * tables.q_rad) for n in counts]
    torque = np.array([o.torque_Nm for o in out])
    fs = p.torque_limit_Nm
    assert np.max(np.abs(torque - ref.torque_Nm)) / fs < 1e-4
    if rendering == "clipped":
        fi = np.array([o.force_handle_N for o in out])
        assert np.max(np.abs(fi - ref.force_handle_N)) < 1e-9
    for name in ar.FLAG_NAMES:
        got = np.array([getattr(o, name) for o in out])
        assert np.sum(got != ref.flags[name]) <= (2 if rendering == "coupling" else 0), name


AUGMENTED = dict(
    tissue_scale=1.3,
    jaw_compliance_mm_per_N=0.01,
    backlash_deg=0.3,
    friction_coulomb_N=2.0,
    friction_load_coefficient=0.1,
    friction_viscous_N_s_per_mm=0.02,
    prony_g=(0.3, 0.2),
    prony_tau_s=(0.2, 1.0),
)
"""An augmented model's rendering (grasprom diagnose -> --augmented), every effect on."""


@pytest.mark.parametrize("rendering", ["coupling", "clipped"])
def test_augmented_reference_matches_the_python_controller(surrogate, tables, rendering):
    """With every rendered effect on, the vectorised reference is still the controller, with
    either rendering (the clipped one also to 1e-6 N: test_clipped_reference_matches_...)."""
    p = ControllerParams(material="mr", thickness_mm=1.5, rendering=rendering, **AUGMENTED)
    counts = ar.sweep_counts(tables)
    ref = ar.reference_run(p, surrogate, "mr", 1.5, counts)
    ctl = ImpedanceController(p, surrogate)
    out = [ctl.step(n * tables.q_rad) for n in counts]
    torque = np.array([o.torque_Nm for o in out])
    assert np.max(np.abs(torque - ref.torque_Nm)) / p.torque_limit_Nm < 1e-3
    base = ar.reference_run(ControllerParams(material="mr", thickness_mm=1.5, rendering=rendering),
                            surrogate, "mr", 1.5, counts)  # fmt: skip
    assert np.max(np.abs(base.torque_Nm - ref.torque_Nm)) / p.torque_limit_Nm > 0.02


def test_augmented_export_on_host_and_avr(surrogate, tmp_path):
    """The Arduino core renders an augmented model (tables: scale, compliance; state: backlash,
    friction, Prony terms) within the error budget, bit-identically on the AVR."""
    need("gcc", "gcc")
    p = ControllerParams(**AUGMENTED)
    t = ar.build_tables(surrogate, p, 0.01)
    assert t.backlash_hb > 0 and t.friction and len(t.prony_g) == 2
    cases = ar.default_cases(t, surrogate)
    host = ar.run_host(t, cases, tmp_path / "host")
    e = ar.error_figures(t, surrogate, cases, host)
    plain = ar.build_tables(surrogate, ControllerParams(), 0.01)
    e_plain = ar.error_figures(t, surrogate, cases, ar.run_host(plain, cases, tmp_path / "p"))
    print(f"\naugmented export: handle error {e.handle_pct_fs:.3f} % FS "
          f"(plain export against the augmented reference: {e_plain.handle_pct_fs:.2f} % FS); "
          f"flags {e.flag_mismatch}")  # fmt: skip
    assert e.handle_pct_fs <= 100 * ar.ERROR_BUDGET
    assert e_plain.handle_pct_fs > 4 * 100 * ar.ERROR_BUDGET  # the rendering matters
    need("avr-gcc", "gcc-avr avr-libc")
    need_simavr()
    avr = ar.run_simavr(ar.build_avr_test(t, cases, tmp_path / "avr"), cases, tmp_path / "avr")
    assert avr.run.raw == host.raw
    sz = ar.measure_size(t, tmp_path / "size")
    print(
        f"augmented export on the AVR: cycles/step max {avr.cycles.max()} mean "
        f"{avr.cycles.mean():.0f}, flash {sz.flash_B} B, RAM {sz.ram_B} B"
    )
    assert sz.flash_B <= ar.FLASH_BUDGET_B and sz.ram_B <= ar.RAM_BUDGET_B


def test_host_error_within_budget(surrogate, host_dense):
    """Every angle, every material, thickness nodes and midpoints: error budget and tol, with
    either rendering (the host build against the reference of its own rendering)."""
    rendering, tables, cases, run = host_dense
    e = ar.error_figures(tables, surrogate, cases, run)
    print(f"\n{rendering}: handle-force error {e.handle_pct_fs:.3f} % FS "
          f"({e.handle_pct_rendered:.3f} % of the "
          f"rendered {e.rendered_max_N:.2f} N), jaw {e.jaw_pct_fs:.3f} % of jaw FS, "
          f"flag mismatches {e.flag_mismatch} of {e.steps} steps")  # fmt: skip
    assert e.handle_pct_fs <= 100 * ar.ERROR_BUDGET
    assert e.jaw_pct_fs <= 100 * tables.tol * 1.5  # tol on the nodes, + thickness blending
    for name in ("contact", "saturated", "theta_clamped"):
        assert e.flag_mismatch[name] == 0, name
    # threshold flags differ only between thickness nodes (thresholds blended), and rarely
    assert e.flag_mismatch["tissue_warning"] + e.flag_mismatch["coupling_active"] < 0.005 * e.steps
    nodes = [(c, o) for c, o in zip(cases, run.outputs)
             if c.thickness_um in next(m for m in tables.materials
                                       if m.name == c.material).thickness_um]  # fmt: skip
    node_run = ar.CoreRun([0] * len(nodes), [o for _, o in nodes], b"")
    e_nodes = ar.error_figures(tables, surrogate, [c for c, _ in nodes], node_run)
    assert e_nodes.jaw_pct_fs <= 100 * tables.tol + 0.05
    assert e_nodes.flag_mismatch["tissue_warning"] == 0  # the safety flag is exact on the nodes
    if rendering == "clipped":
        # 'active' is the last clipped count of the node's field: exact on the nodes
        assert e_nodes.flag_mismatch["coupling_active"] == 0
        return
    # coupling: coupling_active is one threshold per node; at 4 of 39 nodes the reference's
    # active set has a gap near full closure (tissue stiffness dips in the extrapolated range)
    assert e_nodes.flag_mismatch["coupling_active"] < 0.001 * e_nodes.steps


def test_tables_of_a_sweep_without_a_material(surrogate, surrogate_mr_le, tmp_path):
    """Issue 16: the tables of a surrogate without nh hold mr and le only (codes kept: nh's
    entry is empty), gf_init refuses nh (-1) and the covered materials stay within the error
    budget on the host."""
    need("gcc", "gcc")
    with pytest.raises(ValueError, match="'nh' is not in the surrogate, which covers mr, le"):
        ar.build_tables(surrogate_mr_le, ControllerParams(material="nh"), 0.01)
    t = ar.build_tables(surrogate_mr_le, ControllerParams(), 0.01)
    full = ar.build_tables(surrogate, ControllerParams(), 0.01)
    assert t.material_names == ("mr", "le") and full.material_names == ("mr", "nh", "le")
    src = t.tables_source()
    assert "gf_nh_" not in src and "{0, 0, 0, 0, 0, 0, 0, 0} /* nh: not in this export */" in src
    assert "gf_mr_y" in src and "gf_le_y" in src
    assert "#define GF_N_MATERIALS 3 /* material codes: 0 mr, 1 nh, 2 le; tables of mr, le only" \
        in t.config_source()  # fmt: skip
    assert t.table_bytes < full.table_bytes
    cases = ar.default_cases(t, surrogate_mr_le, dense=True)
    assert {c.material for c in cases} == {"mr", "le"}
    probe = [ar.VectorCase(m, 1400, cases[0].counts[:1]) for m in ("nh", "mr")]
    run = ar.run_host(t, cases + probe, tmp_path)
    assert run.init_rc[-2:] == [-1, 0] and min(run.init_rc[:-2]) >= 0
    n = len(cases)
    e = ar.error_figures(t, surrogate_mr_le, cases, ar.CoreRun(run.init_rc[:n], run.outputs[:n],
                                                               b""))  # fmt: skip
    assert e.handle_pct_fs <= 100 * ar.ERROR_BUDGET


def test_thickness_is_clamped_and_flagged(surrogate, tables, tmp_path):
    need("gcc", "gcc")
    cases = ar.clamp_thickness_cases(tables, surrogate)
    m = tables.materials[0]
    ends = [ar.VectorCase(m.name, m.thickness_um[0], cases[0].counts),
            ar.VectorCase(m.name, m.thickness_um[-1], cases[1].counts)]  # fmt: skip
    run = ar.run_host(tables, cases + ends, tmp_path)
    assert run.init_rc == [1, 1, 0, 0]
    assert run.outputs[0].tobytes() == run.outputs[2].tobytes()
    assert run.outputs[1].tobytes() == run.outputs[3].tobytes()


def test_avr_size_within_budget(tables, tmp_path):
    need("avr-gcc", "gcc-avr avr-libc")
    need("avr-size", "binutils-avr")
    sz = ar.measure_size(tables, tmp_path)
    print(
        f"\nflash {sz.flash_B} B, RAM {sz.ram_B} B (static {sz.ram_static_B}, stack {sz.stack_B})"
    )
    assert 0 < sz.flash_B <= ar.FLASH_BUDGET_B
    assert 0 < sz.ram_B <= ar.RAM_BUDGET_B


def test_avr_run_is_bit_identical_to_host_and_fast_enough(surrogate, tables, tmp_path):
    """simavr runs the -Os ATmega328P build on the vectors: same bytes as gcc, <= 1,600 cycles."""
    need("avr-gcc", "gcc-avr avr-libc")
    need_simavr()
    cases = ar.default_cases(tables, surrogate)
    elf = ar.build_avr_test(tables, cases, tmp_path / "avr")
    avr = ar.run_simavr(elf, cases, tmp_path / "avr")
    host = ar.run_host(tables, cases, tmp_path / "host")
    assert len(avr.cycles) == sum(len(c.counts) for c in cases)
    assert avr.run.raw == host.raw
    e = ar.error_figures(tables, surrogate, cases, avr.run)
    print(f"\nAVR: cycles/step max {avr.cycles.max()} mean {avr.cycles.mean():.0f}; "
          f"handle error {e.handle_pct_fs:.3f} % FS")  # fmt: skip
    assert avr.cycles.max() <= ar.CYCLE_BUDGET
    assert e.handle_pct_fs <= 100 * ar.ERROR_BUDGET


def test_float_build_option_runs_on_the_avr(surrogate, tmp_path):
    """GF_FLOAT: same tables, float arithmetic; accurate, but over the cycle budget."""
    need("avr-gcc", "gcc-avr avr-libc")
    need_simavr()
    t = ar.build_tables(surrogate, ControllerParams(), 0.01, fixed_point=False)
    assert "#define GF_FLOAT" in t.config_source()
    cases = ar.default_cases(t, surrogate)[:2]
    avr = ar.run_simavr(ar.build_avr_test(t, cases, tmp_path), cases, tmp_path)
    e = ar.error_figures(t, surrogate, cases, avr.run)
    assert e.handle_pct_fs <= 100 * ar.ERROR_BUDGET
    assert avr.cycles.max() > ar.CYCLE_BUDGET  # why fixed point is the default


def test_fmu_runtime_core_runs_on_the_avr_as_float_build(surrogate, tables, tmp_path):
    """The FMU's own step (grasp_core.c without GC_TABULATED), built by avr-gcc (32-bit double,
    curves in PROGMEM; no field table on the AVR, GC_FIELD_N = 0, hence the coupling rendering),
    agrees with the Python reference to float rounding on every material -- and needs far more
    than 1,600 cycles per step: why the Arduino default is the tabulated fixed-point build of the
    same core."""
    need("avr-gcc", "gcc-avr avr-libc")
    need("avr-size", "binutils-avr")
    need_simavr()
    counts = ar.sweep_counts(tables, 9)
    cases = [ar.VectorCase(m, th, counts) for m, th in (("mr", 1400), ("nh", 2000), ("le", 850))]
    r = ar.run_runtime_avr(surrogate, ControllerParams(rendering="coupling"), cases, tmp_path)
    print(
        f"\nrun-time float core on the AVR: cycles/step max {r.cycles.max()} mean "
        f"{r.cycles.mean():.0f}, flash {r.flash_B} B, handle error {r.handle_pct_fs:.2e} % FS"
    )
    assert len(r.cycles) == sum(len(c.counts) for c in cases)
    assert r.handle_pct_fs < 1e-3  # float32 rounding, vs 0.5 % for the fixed-point build
    assert r.jaw_max_abs_N < 1e-3
    assert r.flag_mismatch == 0
    assert r.cycles.mean() > 10 * ar.CYCLE_BUDGET


def test_runtime_avr_refuses_the_clipped_rendering(surrogate, tmp_path):
    """The AVR build of the run-time core has no field table (GC_FIELD_N = 0): a clear
    ValueError up front, not the firmware's code -6 after a build and a simavr run."""
    with pytest.raises(ValueError, match="rendering='coupling'"):
        ar.run_runtime_avr(surrogate, ControllerParams(rendering="clipped"), [], tmp_path)
    assert not list(tmp_path.iterdir())


def test_export_writes_sketch_that_builds_with_arduino_mk(surrogate, tmp_path):
    p = ControllerParams(material="le", thickness_mm=1.65)
    res = ar.export_arduino(tmp_path / "exp", surrogate=surrogate, params=p, measure=False)
    sk = res.sketch_dir
    for f in ("grasprom_controller.ino", "grasp_core.c", "grasp_core.h", "grasp_build.h",
              "grasp_fixed_config.h",
              "grasp_fixed_tables.h", "Makefile"):  # fmt: skip
        assert (sk / f).is_file(), f
    ino = (sk / "grasprom_controller.ino").read_text()
    fw = (sk / "grasp_firmware.h").read_text()
    assert "#define GF_BOOT_MATERIAL 2" in fw and "#define GF_BOOT_THICKNESS_UM 1650" in fw
    assert "ISR(INT0_vect)" in ino and "ISR(TIMER2_COMPA_vect, ISR_NOBLOCK)" in ino
    mk = (sk / "Makefile").read_text()
    assert "BOARD_TAG = uno" in mk and "-DDECIMAL_DIG=__DECIMAL_DIG__" in mk
    need("make", "make")
    need("avr-gcc", "gcc-avr avr-libc")
    if not Path("/usr/share/arduino/Arduino.mk").exists():
        (pytest.fail if CI else pytest.skip)("arduino-mk missing: apt-get install arduino-mk")
    res_mk = subprocess.run(["make"], cwd=sk, capture_output=True, text=True, timeout=300)
    assert res_mk.returncode == 0, res_mk.stdout[-3000:] + res_mk.stderr[-3000:]
    assert list((sk / "build-uno").glob("*.hex")), "no .hex built"
    print("\n" + "\n".join(ln for ln in res_mk.stdout.splitlines() if "Full" in ln))


def test_export_measures_the_budget(surrogate, tmp_path):
    need("gcc", "gcc")
    need("avr-gcc", "gcc-avr avr-libc")
    need_simavr()
    res = ar.export_arduino(tmp_path, surrogate=surrogate, params=ControllerParams())
    print("\n" + res.summary())
    assert res.notes == []
    assert res.within_budget()
    assert res.error_handle_pct_fs is not None and res.cycles_max is not None
    assert math.isfinite(res.jaw_fs_N) and res.jaw_fs_N > 0


# ---------------------------------------------------------------- clipped rendering (issue 13)

CLIPPED = dict(rendering="clipped")
"""The stiffness-clipped rendering (grasprom.control.field) instead of the virtual coupling."""

CLIPPED_CASES = (("mr", 1400), ("le", 2000))
"""Operating cases the clipped export is checked on against the Python controller itself."""


def controller_run(params, surrogate, material, thickness_um, counts, q):
    """Handle force (N) and flags of ImpedanceController (double) on encoder counts."""
    p = dataclasses.replace(params, material=material, thickness_mm=thickness_um / 1000.0)
    ctl = ImpedanceController(p, surrogate)
    out = [ctl.step(int(n) * q) for n in counts]
    return np.array([o.force_handle_N for o in out]), out


@pytest.fixture(scope="module")
def clipped_tables(surrogate):
    return ar.build_tables(surrogate, ControllerParams(**CLIPPED), 0.01)


def test_clipped_tables_hold_the_field(surrogate, coupling_tables, clipped_tables):
    """y[] nodes are the controller's field at the grid counts; 'active' = last clipped count."""
    t = clipped_tables
    tables = coupling_tables
    p = t.params
    assert (t.n_lo, t.n_top, t.n_contact) == (tables.n_lo, tables.n_top, tables.n_contact)
    unit = (1 << t.fg_shift) * 1e-3
    for m in t.materials:
        for i, th_um in enumerate(m.thickness_um):
            pm = ControllerParams(**{**CLIPPED, "material": m.name, "thickness_mm": th_um / 1e3})
            field = ImpedanceController(pm, surrogate).field
            assert field is not None
            for x, y in zip(m.x, m.y[i]):
                f = field.jaw_force_N(x * t.q_rad)[0] if x < t.n_contact else 0.0
                assert abs(y * unit - f) <= 0.5 * unit + 1e-12, (m.name, th_um, x)
            cl = [n for n in range(t.n_lo, t.n_contact) if field.jaw_force_N(n * t.q_rad)[1]]
            assert m.active[i] == (max(cl) if cl else t.n_lo - 1)
    nodes = {m.name: len(m.x) for m in t.materials}
    print(f"\nclipped tables: nodes {nodes}, {t.table_bytes} B, jaw FS {t.jaw_fs_N:.3f} N "
          f"(coupling: {{{', '.join(f'{m.name}: {len(m.x)}' for m in tables.materials)}}}, "
          f"{tables.table_bytes} B, jaw FS {tables.jaw_fs_N:.3f} N)")  # fmt: skip
    assert max(nodes.values()) <= 255 and t.table_bytes < 2 * tables.table_bytes
    src, cfg = t.tables_source(), t.config_source()
    assert "stiffness-clipped field" in src and "stiffness limit active" in src
    assert f"stiffness limit {p.stiffness_limit_Nm_per_rad:g} N m/rad" in cfg
    assert "rendering clipped" not in tables.config_source()
    assert "kc (g_p - g)" in tables.tables_source() and "kc (g_p - g)" not in src


@pytest.mark.parametrize("augmented", [False, True], ids=["plain", "augmented"])
def test_clipped_reference_matches_the_python_controller(surrogate, tables, augmented):
    """With the clipped rendering the vectorised reference is the controller (to rounding)."""
    kw = {**CLIPPED, **(AUGMENTED if augmented else {})}
    p = ControllerParams(material="mr", thickness_mm=1.5, **kw)
    counts = ar.sweep_counts(tables)
    ref = ar.reference_run(p, surrogate, "mr", 1.5, counts)
    fi, out = controller_run(p, surrogate, "mr", 1500, counts, tables.q_rad)
    assert np.max(np.abs(fi - ref.force_handle_N)) < 1e-9 * (1e3 if augmented else 1.0)
    for name in ar.FLAG_NAMES:
        got = np.array([getattr(o, name) for o in out])
        assert np.sum(got != ref.flags[name]) == 0, name
    assert np.any(ref.flags["coupling_active"])  # the stiffness limit acts near closure
    coupling = ar.reference_run(ControllerParams(material="mr", thickness_mm=1.5,
                                                 rendering="coupling",
                                                 **(AUGMENTED if augmented else {})),
                                surrogate, "mr", 1.5, counts)  # fmt: skip
    assert np.max(np.abs(coupling.force_handle_N - ref.force_handle_N)) > 0.5  # N: it differs


@pytest.mark.parametrize("augmented", [False, True], ids=["plain", "augmented"])
def test_clipped_export_on_host_and_avr(surrogate, tmp_path, augmented):
    """The clipped export: host (gcc) and AVR (simavr) bit for bit, within the error budget
    against the reference and the Python controller itself, cycles, flash and RAM."""
    need("gcc", "gcc")
    kw = {**CLIPPED, **(AUGMENTED if augmented else {})}
    p = ControllerParams(**kw)
    t = ar.build_tables(surrogate, p, 0.01)
    if augmented:
        assert t.backlash_hb > 0 and t.friction and len(t.prony_g) == 2
    counts = ar.sweep_counts(t)
    own = [ar.VectorCase(m, th, counts) for m, th in CLIPPED_CASES]
    cases = own + ar.default_cases(t, surrogate)
    host = ar.run_host(t, cases, tmp_path / "host")
    e = ar.error_figures(t, surrogate, cases, host)
    fs = p.torque_limit_Nm / (p.pulley_radius_mm * 1e-3)
    e_ctl = 0.0
    for c, out in zip(own, host.outputs):  # against ImpedanceController itself
        fi, _ = controller_run(p, surrogate, c.material, c.thickness_um, c.counts, t.q_rad)
        e_ctl = max(e_ctl, float(np.max(np.abs(out["fi"] * 1e-3 - fi))) / fs * 100)
    coupled = ar.build_tables(surrogate, ControllerParams(**{**kw, "rendering": "coupling"}))
    e_cpl = ar.error_figures(t, surrogate, cases, ar.run_host(coupled, cases, tmp_path / "c"))
    label = "augmented clipped" if augmented else "clipped"
    print(f"\n{label} export: handle error {e.handle_pct_fs:.3f} % FS "
          f"({e.handle_pct_rendered:.3f} % of the rendered {e.rendered_max_N:.2f} N), vs "
          f"ImpedanceController on mr 1.4 / le 2.0 mm {e_ctl:.3f} % FS, jaw "
          f"{e.jaw_pct_fs:.3f} % of jaw FS; coupling export against the clipped reference "
          f"{e_cpl.handle_pct_fs:.2f} % FS; flags {e.flag_mismatch} of {e.steps}")  # fmt: skip
    assert e.handle_pct_fs <= 100 * ar.ERROR_BUDGET
    assert e_ctl <= 100 * ar.ERROR_BUDGET
    assert e_cpl.handle_pct_fs > 100 * ar.ERROR_BUDGET  # the export renders the clipped field
    for name in ("contact", "saturated", "theta_clamped"):
        assert e.flag_mismatch[name] == 0, name
    if not augmented:  # one threshold per node: exact but for thickness blending
        assert e.flag_mismatch["coupling_active"] < 0.001 * e.steps
    need("avr-gcc", "gcc-avr avr-libc")
    need("avr-size", "binutils-avr")
    need_simavr()
    avr = ar.run_simavr(ar.build_avr_test(t, cases, tmp_path / "avr"), cases, tmp_path / "avr")
    assert avr.run.raw == host.raw
    sz = ar.measure_size(t, tmp_path / "size")
    print(f"{label} export on the AVR: nodes {[len(m.x) for m in t.materials]}, cycles/step "
          f"max {avr.cycles.max()} mean {avr.cycles.mean():.0f}, flash {sz.flash_B} B, RAM "
          f"{sz.ram_B} B (static {sz.ram_static_B}, stack {sz.stack_B})")  # fmt: skip
    if not augmented:  # the augmented step (backlash, friction, Prony) is over 1,600 cycles
        assert avr.cycles.max() <= ar.CYCLE_BUDGET  # with either rendering (same step code)
    assert sz.flash_B <= ar.FLASH_BUDGET_B and sz.ram_B <= ar.RAM_BUDGET_B


@pytest.mark.parametrize("rendering", ["coupling", "clipped"])
def test_error_against_the_rendered_range(surrogate, tmp_path, rendering):
    """Issue 17: the handle-force error in % of the force range the device renders (the largest
    |handle force| of the reference on the vectors), next to the % of the 100 N full scale.  A
    1 % tolerance is over the 0.5 % budget on that range; the default 0.5 % meets it."""
    need("gcc", "gcc")
    p = ControllerParams(rendering=rendering)
    fs = p.torque_limit_Nm / (p.pulley_radius_mm * 1e-3)
    figs = {}
    for tol in (0.01, 0.005):
        t = ar.build_tables(surrogate, p, tol)
        cases = ar.default_cases(t, surrogate, dense=True)
        e = ar.error_figures(t, surrogate, cases, ar.run_host(t, cases, tmp_path / f"{tol}"))
        assert 0 < e.rendered_max_N < fs
        assert e.handle_pct_rendered == pytest.approx(e.handle_pct_fs * fs / e.rendered_max_N)
        figs[tol] = e
        print(f"\n{rendering}, tol {tol:g}: nodes {[len(m.x) for m in t.materials]}, handle "
              f"error {e.handle_pct_fs:.3f} % FS ({fs:g} N), {e.handle_pct_rendered:.3f} % of "
              f"the rendered range {e.rendered_max_N:.2f} N")  # fmt: skip
    assert figs[0.01].handle_pct_fs <= 100 * ar.ERROR_BUDGET
    assert figs[0.005].handle_pct_rendered <= 100 * ar.ERROR_BUDGET


def test_clipped_export_says_its_rendering_and_measures_the_budget(surrogate, tmp_path):
    need("gcc", "gcc")
    need("avr-gcc", "gcc-avr avr-libc")
    need_simavr()
    p = ControllerParams(material="le", thickness_mm=2.0, **CLIPPED)
    res = ar.export_arduino(tmp_path, surrogate=surrogate, params=p)
    print("\n" + res.summary())
    sk = res.sketch_dir
    ino = (sk / "grasprom_controller.ino").read_text()
    readme = (sk / "README.md").read_text()
    for text in (ino, readme):
        assert "stiffness-clipped field" in text and "rendering='clipped'" in text
        assert "virtual coupling (rendering='coupling'" not in text
    fw = (sk / "grasp_firmware.h").read_text()
    assert "#define GF_BOOT_MATERIAL 2" in fw and "#define GF_BOOT_THICKNESS_UM 2000" in fw
    assert "rendering clipped" in res.summary() and "rendered range" in res.summary()
    assert res.rendering == "clipped" and res.notes == [] and res.within_budget()
    assert res.error_handle_pct_rendered is not None and res.rendered_max_N is not None
    plain = ar.export_arduino(tmp_path / "c", surrogate=surrogate,
                              params=ControllerParams(rendering="coupling"),
                              measure=False)  # fmt: skip
    assert "virtual coupling (rendering='coupling'" in (plain.sketch_dir / "README.md").read_text()
