"""The main job ``grasprom build`` end to end, its failure handling, and the examples.

The end-to-end run (``--fast``, into a temp dir, from a directory outside the source tree)
checks every artefact: the surrogate and controller files load, both FMUs validate (fmpy) and
simulate, the Arduino package compiles with avr-gcc (required when ``CI=true``, skipped
otherwise), and the report exists, embeds and names every figure.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
CI = os.environ.get("CI") == "true"
FIGURES = ("fe_sweep.png", "surrogate.png", "surrogate_residuals.png", "transmission.png",
           "stiffness_vs_theta.png", "zwidth.png", "bode_impedance.png", "transparency.png",
           "cosim.png")  # fmt: skip


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


def _build(out: Path, *extra: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "grasprom", "build", "--out", str(out), *extra],
        capture_output=True, text=True, env=_env(), cwd=cwd or out.parent, timeout=300,
    )  # fmt: skip


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    """One ``grasprom build --fast`` run, from a directory that is not the checkout."""
    base = tmp_path_factory.mktemp("build")
    out = base / "out"
    res = _build(out, "--fast", cwd=base)
    assert res.returncode == 0, res.stderr
    return out, res


def test_progress_names_every_stage(built):
    from grasprom.pipeline import STAGES

    _, res = built
    for i, name in enumerate(STAGES, 1):
        assert f"[{i}/{len(STAGES)}] {name} done in" in res.stderr
    assert "grasprom build:" in res.stdout and "report.html" in res.stdout


def test_surrogate_and_controller_load(built):
    from grasprom.control import ImpedanceController, load_params
    from grasprom.surrogate import Surrogate

    out, _ = built
    s = Surrogate.load(out / "surrogate.json", fe_dir=ROOT / "fe_data" / "default")
    assert set(s.materials) == {"mr", "nh", "le"}
    assert "holdout" in s.errors and "loo" in s.errors
    p = load_params(out / "controller.json")
    assert (p.material, p.thickness_mm) == ("mr", 1.4)
    assert 0 < p.coupling_stiffness_N_per_mm < 10
    tuning = json.loads((out / "controller.json").read_text())["tuning"]
    assert tuning["passive_everywhere"] and tuning["passivity_margin"] >= 1.25 - 1e-9
    ImpedanceController(p, s).step(0.1)


@pytest.mark.parametrize("name", ["GraspController.fmu", "GraspController_fmi3.fmu"])
def test_fmu_validates_and_simulates(built, name):
    from fmpy import read_model_description, simulate_fmu
    from fmpy.validation import validate_fmu

    from grasprom.control import load_params, simulate
    from grasprom.surrogate import Surrogate

    out, _ = built
    fmu = out / name
    assert validate_fmu(str(fmu)) == []
    md = read_model_description(str(fmu))
    assert md.fmiVersion.startswith("3" if "fmi3" in name else "2")
    t = np.arange(0.0, 0.5, 1e-3)
    theta_deg = 22.0 - 40.0 * t  # closing to 2 deg
    sig = np.array(list(zip(t, np.radians(theta_deg))), dtype=[("time", float), ("theta", float)])
    r = simulate_fmu(str(fmu), stop_time=0.499, step_size=1e-3, input=sig,
                     output=["torque", "force_jaw"])  # fmt: skip
    assert np.all(np.isfinite(r["torque"])) and r["force_jaw"][-1] > 0
    # same as the Python reference on the same trajectory (FMU outputs lag one step)
    import pandas as pd

    ref = simulate(
        pd.DataFrame({"time_s": t, "theta_deg": theta_deg}),
        load_params(out / "controller.json"),
        Surrogate.load(out / "surrogate.json"),
    )
    np.testing.assert_allclose(r["torque"][-1], ref["torque_Nm"].to_numpy()[-2], rtol=1e-6)


def test_arduino_package_compiles(built, tmp_path):
    out, _ = built
    sk = out / "arduino" / "grasprom_controller"
    for f in ("grasprom_controller.ino", "grasp_core.c", "grasp_core.h", "grasp_build.h",
              "grasp_fixed_config.h",
              "grasp_fixed_tables.h", "Makefile"):  # fmt: skip
        assert (sk / f).is_file(), f
    if shutil.which("avr-gcc") is None:
        (pytest.fail if CI else pytest.skip)("avr-gcc missing: apt-get install gcc-avr avr-libc")
    main = tmp_path / "main.c"
    main.write_text(
        '#include "grasp_core.h"\nstatic gf_state_t s;\nvolatile int16_t in;\n'
        "volatile int32_t o32;\nint main(void) {\n    gf_output_t o;\n    gf_init(&s, 0, 1400);\n"
        "    for (;;) { gf_step(&s, in, &o); o32 = o.torque_uNm; }\n}\n"
    )
    res = subprocess.run(
        ["avr-gcc", "-mmcu=atmega328p", "-Os", "-std=gnu99", "-Wall", "-Wextra", "-Werror",
         "-DF_CPU=16000000UL", f"-I{sk}", "-o", str(tmp_path / "fw.elf"), str(sk / "grasp_core.c"),
         str(main)],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    budget = json.loads((out / "build.json").read_text())["results"]["arduino"]
    assert budget["flash_B"] is not None and budget["flash_B"] <= 8192
    assert budget["ram_B"] <= 512


def test_report_names_and_embeds_figures(built):
    out, _ = built
    html = (out / "report.html").read_text()
    for f in FIGURES:
        assert (out / "figures" / f).is_file(), f
        assert f in html, f
    assert html.count("data:image/png;base64,") == len(FIGURES)
    for section in ("Held-out error", "passivity margin", "Z-width", "Co-simulated grasp",
                    "Arduino budget", "flash", "cycles", "Provenance", "command_line",
                    "fe_hash", "git_revision", "Transparency", "damping ratio",
                    "rate needed (Hz)"):  # fmt: skip
        assert section in html, section
    # issue 16: the results lead; stage times and artefact tables come after them
    first = html.index("Results at a glance")
    assert first < html.index("FE data and surrogate") < html.index("<h2>Stages</h2>")
    assert html.index("<h2>Artefacts</h2>") > html.index("Arduino budget")
    glance = html[first : html.index("<h2>", first + 10)]
    for needle in ("held-out haptic force error", "passivity margin", "handle-force error",
                   "co-simulation: max jaw force"):  # fmt: skip
        assert needle in glance, needle
    meta = json.loads((out / "build.json").read_text())
    prov = meta["provenance"]
    assert prov["command_line"][:2] == ["grasprom", "build"] and "--fast" in prov["command_line"]
    assert prov["failed_stage"] is None
    assert prov["versions"]["grasprom"] and prov["fe_hash"]
    assert set(prov["artefact_sha256"]) >= {
        "surrogate.json",
        "controller.json",
        "GraspController.fmu",
        "GraspController_fmi3.fmu",
    }
    cs = meta["results"]["cosim"]
    assert cs["max_torque_diff_vs_python_Nm"] < 1e-9  # FMU = Python reference
    assert cs["max_force_jaw_N"] > 0.1 and cs["min_theta_deg"] < 10  # it did grasp
    # issue 13: the grasp settles with <= 15 % overshoot, recomputed from cosim.csv
    from grasprom.pipeline.cosim import grasp_profile

    ramp, hold, _, _ = grasp_profile(True)
    data = np.genfromtxt(out / "cosim.csv", delimiter=",", names=True)
    t, f_handle, f_hand = data["time_s"], data["force_handle_N"], data["hand_N"]
    last = (t >= ramp + 0.75 * hold) & (t <= ramp + hold)
    settled = f_handle[last].mean()
    assert f_handle[t <= ramp + hold].max() / settled - 1 <= 0.15
    assert cs["settling"]["meets_target"] and cs["settling"]["overshoot"] <= 0.15
    # the operator grip reaches its 3 N hold, in equilibrium with the rendered force
    assert f_hand[last].mean() == pytest.approx(3.0, rel=0.02)
    assert settled == pytest.approx(f_hand[last].mean(), rel=0.02)
    # held-out error of the default (3D) surrogate, 0.2 mm thickness spacing: le 5.2 % of the
    # 20 N haptic scale at the t = 1.5 mm case, mr/nh 0.6 % (`grasprom surrogate check`); the
    # 3 % budget holds on the 2D data at 0.1 mm spacing (tests/surrogate)
    assert meta["results"]["surrogate"]["haptic_error"]["holdout"]["force_max_pct"] < 6


def _glance(html: str) -> str:
    first = html.index("Results at a glance")
    return html[first : html.index("<h2>", first + 10)]


def _text(fragment: str) -> str:
    """Plain text of an HTML fragment (tags dropped, entities unescaped)."""
    import html as _html
    import re

    return _html.unescape(re.sub(r"<[^>]+>", " ", fragment))


def test_headline_table_verdicts_follow_the_numbers(built):
    """Issue 16 item 6: the report leads with a table of every figure that has a stated
    target, PASS / FAIL recomputed here from build.json's results and the targets' constants."""
    import re

    from grasprom.export import CYCLE_BUDGET, ERROR_BUDGET, FLASH_BUDGET_B, RAM_BUDGET_B
    from grasprom.pipeline.cosim import OVERSHOOT_TARGET
    from grasprom.surrogate import CHECK_TOLERANCE

    out, _ = built
    meta = json.loads((out / "build.json").read_text())
    r = meta["results"]
    tuning = json.loads((out / "controller.json").read_text())["tuning"]
    ho = r["surrogate"]["haptic_error"]["holdout"]
    a, cs = r["arduino"], r["cosim"]
    want = {  # figure prefix -> (value, limit, at most?)
        "surrogate: held-out haptic force error": (ho["force_max_pct"],
                                                   CHECK_TOLERANCE["force_max_pct"], True),
        "surrogate: held-out gap error": (ho["gap_max_mm"], CHECK_TOLERANCE["gap_max_mm"], True),
        "controller: passivity margin": (tuning["passivity_margin"], tuning["safety_factor"],
                                         False),
        "closed loop with the hand": (
            tuning["operating_margins"]["worst"]["damping_ratio_min"], 0.3, False),
        "arduino: flash": (a["flash_B"], FLASH_BUDGET_B, True),
        "arduino: RAM": (a["ram_B"], RAM_BUDGET_B, True),
        "arduino: cycles": (a["cycles_max"], CYCLE_BUDGET, True),
        "arduino: handle-force error": (a["error_handle_pct_rendered"], 100 * ERROR_BUDGET,
                                        True),
        "co-simulation: FMU vs Python": (cs["max_torque_diff_vs_python_Nm"], 1e-9, True),
        "co-simulation: rendered handle-force overshoot": (
            100 * cs["settling"]["overshoot"], 100 * OVERSHOOT_TARGET, True),
    }  # fmt: skip
    rows = meta["headline"]
    assert len(rows) == len(want)
    html = (out / "report.html").read_text()
    table = _glance(html)
    cells = [re.findall(r"<td[^>]*>(.*?)</td>", tr) for tr in table.split("<tr>")[2:]]
    assert len(cells) == len(rows)
    for row, tr in zip(rows, cells):
        (key,) = [k for k in want if row["figure"].startswith(k)]
        value, limit, at_most = want[key]
        expect = "n/a" if value is None else (
            "PASS" if (value <= limit if at_most else value >= limit) else "FAIL")  # fmt: skip
        assert row["verdict"] == expect, (key, value, limit)
        assert row["limit"] == pytest.approx(limit) and row["value"] == value
        assert _text(tr[0]).strip() == row["figure"] and expect in tr[3], (key, tr)
    # --fast: the simavr cycles and the host error run are skipped, so those rows are n/a
    assert a["cycles_max"] is None and "not measured" in table
    assert "FAIL" in table  # the shipped 3D surrogate misses the 3 % target (le)
    assert html.index("Results at a glance") < html.index("FE data and surrogate")


def test_report_explains_transmission_and_open_handle_force(built):
    """Issue 16 item 6: the paper-vs-derived gap of the transmission figure and the open-handle
    force of the co-simulation are explained with numbers from the chain; the tuning text is
    wrapped."""
    import re

    from grasprom.chain import kinematics as kin
    from grasprom.control import load_params

    out, _ = built
    html = (out / "report.html").read_text()
    chain = load_params(out / "controller.json").chain_params
    chain_text = _text(html[html.index("<h2>Kinematic chain") : html.index("<h2>Controller")])
    ratio = kin.transmission_ratio(22.0, chain) / kin.seed_transmission_ratio(22.0, chain)
    assert f"{ratio:.1f}x below the derived chain" in chain_text
    assert "Not a bug" in chain_text
    # open-handle force: preload x rod travel per radian / L3, the rod travel by a difference
    h = 1e-4
    du = (kin.spring_dx_mm(chain.theta_open_deg - h, chain) - 0.0) / math.radians(h)
    f_open = chain.spring_preload_N * du / chain.L3_mm
    cosim = _text(html[html.index("<h2>Co-simulated") : html.index("<h2>Arduino")])
    m = re.search(r"the rendered handle force is ([\d.]+) N \(co-simulated: ([\d.]+) N\)", cosim)
    assert m, cosim
    assert float(m.group(1)) == pytest.approx(f_open, abs=0.006)
    data = np.genfromtxt(out / "cosim.csv", delimiter=",", names=True)
    assert data["theta_deg"][0] == pytest.approx(chain.theta_open_deg)
    assert float(m.group(2)) == pytest.approx(data["force_handle_N"][0], abs=0.006)
    assert data["force_handle_N"][0] == pytest.approx(f_open, rel=1e-3)
    assert f"F0 = {chain.spring_preload_N:g} N" in cosim
    assert "--fast only shortens the rest" in cosim
    # the tuning report wraps instead of running off the right edge
    assert "pre.wrap{white-space:pre-wrap" in html and "<pre class='wrap'>grasprom tune:" in html


def test_fast_cosim_reports_the_full_runs_figures(built):
    """Issue 16 item 8: --fast shortened the ramp and hold (max jaw force 1.04 vs 0.98 N); now it
    only shortens the rest after the release, and the co-simulation is the full run's."""
    from grasprom.control import DeviceParams, HandParams, load_params
    from grasprom.pipeline import cosimulate
    from grasprom.pipeline.cosim import grasp_profile
    from grasprom.surrogate import Surrogate

    out, _ = built
    p, s = load_params(out / "controller.json"), Surrogate.load(out / "surrogate.json")
    full = cosimulate(out / "GraspController.fmu", p, s, DeviceParams(), HandParams())
    fast = np.genfromtxt(out / "cosim.csv", delimiter=",", skip_header=1)
    assert grasp_profile(True)[:3] == grasp_profile(False)[:3]
    assert len(fast) < len(full.data)
    np.testing.assert_allclose(fast, full.data[: len(fast)], rtol=1e-8, atol=0)  # CSV: %.9g
    cs = json.loads((out / "build.json").read_text())["results"]["cosim"]
    assert cs["max_force_jaw_N"] == full.col("force_jaw_N").max()
    assert cs["min_theta_deg"] == full.col("theta_deg").min()


def test_fmu_example_agrees_with_the_build(built, tmp_path):
    """Issue 16 item 8: examples/fmu_cosim.py (tuning as the build does, FMI 2; or a build's
    controller.json, FMI 3) co-simulates the build's grasp: the same rows as cosim.csv."""
    import re

    out, _ = built
    ref = np.genfromtxt(out / "cosim.csv", delimiter=",", names=True)
    cs = json.loads((out / "build.json").read_text())["results"]["cosim"]
    for extra in (["--fast"], ["--fast", "--fmi", "3", "--controller",
                               str(out / "controller.json")]):  # fmt: skip
        ex = tmp_path / "_".join(extra[1:3]) if len(extra) > 1 else tmp_path / "fmi2"
        res = subprocess.run(
            [sys.executable, str(ROOT / "examples" / "fmu_cosim.py"), "--out", str(ex), *extra],
            capture_output=True, text=True, env=_env(), cwd=tmp_path, timeout=180,
        )  # fmt: skip
        assert res.returncode == 0, res.stdout + res.stderr
        got = np.genfromtxt(ex / "fmu_cosim.csv", delimiter=",", names=True)
        assert got.dtype.names == ref.dtype.names
        for name in ref.dtype.names:
            np.testing.assert_array_equal(got[name], ref[name], err_msg=f"{extra} {name}")
        m = re.search(r"min handle angle ([\d.]+) deg, max jaw force ([\d.]+) N", res.stdout)
        assert m, res.stdout
        assert float(m.group(1)) == pytest.approx(cs["min_theta_deg"], abs=0.006)
        assert float(m.group(2)) == pytest.approx(cs["max_force_jaw_N"], abs=0.006)


def test_bad_fe_dir_names_the_stage(tmp_path):
    """A missing --fe is a bad input (exit 2, no output folder); an FE folder without usable
    cases fails the surrogate stage (exit 1, named, with a report of the failure)."""
    out = tmp_path / "out"
    res = _build(out, "--fe", str(tmp_path / "nope"), "--fast", "--quiet")
    assert res.returncode == 2 and "--fe" in res.stderr and "nope" in res.stderr
    assert not out.exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    res = _build(out, "--fe", str(empty), "--fast", "--quiet")
    assert res.returncode == 1
    assert "stage 'surrogate' failed" in res.stderr and "empty" in res.stderr
    assert not (out / "surrogate.json").exists()
    assert "stage 'surrogate'" in (out / "report.html").read_text()


def test_failed_stage_keeps_earlier_outputs(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "arduino").write_text("a file where the arduino/ folder should go\n")
    res = _build(out, "--fast")
    assert res.returncode == 1
    assert "stage 'arduino' failed" in res.stderr
    for name in ("surrogate.json", "controller.json", "GraspController.fmu",
                 "GraspController_fmi3.fmu"):  # fmt: skip
        assert (out / name).is_file(), name
    assert "[3/6] fmu done in" in res.stderr and "cosim" not in res.stderr
    meta = json.loads((out / "build.json").read_text())
    assert meta["provenance"]["failed_stage"] == "arduino"
    assert "Build failed at stage 'arduino'" in (out / "report.html").read_text()


def test_build_renders_an_augmented_model(tmp_path):
    """grasprom build --augmented: tuned controller, FMUs and Arduino tables render the
    diagnosed effects; the co-simulation checks the FMU against the Python step with them."""
    aug = {
        "format": "grasprom-augmented-model",
        "format_version": 1,
        "chain": {},
        "effects": [
            {"name": "tissue_stiffness_scale", "params": {"scale": 1.2}},
            {"name": "mechanism_friction",
             "params": {"coulomb_N": 1.0, "load_coefficient": 0.05, "viscous_N_s_per_mm": 0.0}},
            {"name": "latency", "params": {"delay_s": 0.01}},
        ],
    }  # fmt: skip
    (tmp_path / "aug.json").write_text(json.dumps(aug))
    out = tmp_path / "out"
    res = _build(out, "--fast", "--quiet", "--augmented", str(tmp_path / "aug.json"))
    assert res.returncode == 0, res.stderr
    assert "rendered mechanism_friction, tissue_stiffness_scale" in res.stdout
    ctl = json.loads((out / "controller.json").read_text())
    assert ctl["tissue_scale"] == 1.2 and ctl["friction_coulomb_N"] == 1.0
    cfg = (out / "arduino" / "grasprom_controller" / "grasp_fixed_config.h").read_text()
    assert "#define GF_FRICTION 1" in cfg
    meta = json.loads((out / "build.json").read_text())
    prov = meta["provenance"]
    assert prov["augmentation"]["measurement_only"] == ["latency"]
    assert prov["options"]["augmented"].endswith("aug.json")
    # the FMU (with the rendering) matches the Python reference in the co-simulation
    assert meta["results"]["cosim"]["max_torque_diff_vs_python_Nm"] < 1e-9
    assert "Augmented model" in (out / "report.html").read_text()


def test_build_tune_stage_uses_the_device_file(tmp_path):
    """--device: the tune stage designs for the given device; a bad file is bad input."""
    from grasprom.control import DeviceParams, load_params, save_device
    from grasprom.pipeline import BuildOptions, run_build

    dev = save_device(DeviceParams(damping_Nms_per_rad=0.02, current_limit_A=5.0,
                                   encoder_counts_per_rev=8192), tmp_path / "dev.json")  # fmt: skip
    out = tmp_path / "out"
    opts = BuildOptions(out_dir=out, fast=True, device=dev, rendering="clipped")
    res = run_build(opts, progress=None, stages=("surrogate", "tune"))
    p = load_params(out / "controller.json")
    assert p.rendering == "clipped" and p.stiffness_limit_Nm_per_rad == pytest.approx(12.0)
    assert p.torque_limit_Nm == pytest.approx(0.5) and p.encoder_counts_per_rev == 8192
    assert res.tuning.device.damping_Nms_per_rad == 0.02
    assert "transparency" in res.figures
    (tmp_path / "bad.json").write_text('{"inertia_kg_m2": 0}')
    r = _build(tmp_path / "o2", "--device", str(tmp_path / "bad.json"))
    assert r.returncode == 2 and "'inertia_kg_m2'" in r.stderr
    assert not (tmp_path / "o2").exists()


def test_bad_material_is_bad_input(tmp_path):
    res = _build(tmp_path / "out", "--material", "steel")
    assert res.returncode == 2 and "steel" in res.stderr
    assert not (tmp_path / "out").exists()


def test_thickness_out_of_range_names_surrogate_stage(tmp_path):
    res = _build(tmp_path / "out", "--thickness", "5", "--quiet")
    assert res.returncode == 1
    assert "stage 'surrogate' failed" in res.stderr and "5 mm" in res.stderr


# ----------------------------------------------------------------------------------- examples
# examples/kinematics_fg_fi.py is run by tests/test_kinematics.py
@pytest.mark.parametrize(
    ("script", "args", "expect"),
    [
        ("fmu_cosim.py", ["--fast"], "fmu_cosim.png"),
        ("tune_controller.py", [], "controller.json"),
        ("diagnose_gap.py", [], "diagnosis"),
        ("arduino_export.py", ["--fast"], "grasprom_controller"),
        ("tube3d_vtu.py", ["--fast"], "tube_gap24.00.vtu"),
    ],
)
def test_example_runs(tmp_path, script, args, expect):
    res = subprocess.run(
        [sys.executable, str(ROOT / "examples" / script), "--out", str(tmp_path / "ex"), *args],
        capture_output=True, text=True, env=_env(), cwd=tmp_path, timeout=180,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    assert (tmp_path / "ex" / expect).exists(), list((tmp_path / "ex").iterdir())


def test_diagnose_example_replay_agrees_with_the_diagnosis(tmp_path):
    """The controller rendering the augmented model on a held-out trial (examples/
    diagnose_gap.py) shrinks the error as the diagnosis' own held-out figure says (issue 15: the
    replay ran the clipped default rendering, 10.2 -> 9.6 N against 1.09 -> 0.13 N)."""
    import re

    res = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "diagnose_gap.py"), "--out", str(tmp_path),
         "--effect", "mechanism_friction"],
        capture_output=True, text=True, env=_env(), cwd=tmp_path, timeout=180,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    diag = re.search(r"held-out RMS ([\d.]+) N -> ([\d.]+) N", res.stdout)
    replay = re.search(r"force: ([\d.]+) N without the augmentation -> ([\d.]+) N", res.stdout)
    assert diag and replay, res.stdout
    d0, d1 = map(float, diag.groups())
    r0, r1 = map(float, replay.groups())
    assert r1 < 0.3 * r0 and d1 < 0.3 * d0
    assert abs(r0 - d0) < 0.25 * d0, (diag.groups(), replay.groups())
    assert abs(r1 - d1) < 0.1 + 0.5 * d1, (diag.groups(), replay.groups())
