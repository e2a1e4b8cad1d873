"""Issue 16: the main job on an FE sweep of one material.

``grasprom build --fe <sweep of mr only> --material mr --fast`` (the ``mr`` cases of the shipped
``fe_data/default``, with their manifest) runs every stage; the outputs cover mr only and say
so (stderr, ``build.json``, report); the FMUs declare ``Material`` with the one item ``mr``
(value 0) and refuse nh and le; the FMU at mr is the Python controller; the Arduino tables hold
mr only and the core refuses the others; ``--material nh`` is a bad input naming what the sweep
covers.  Tools (gcc, avr-gcc) are required under ``CI=true``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from tests.sweep_subset import copy_sweep

ROOT = Path(__file__).resolve().parents[2]
CI = os.environ.get("CI") == "true"
STATEMENT = ("outputs cover material mr 0.8-2 mm (7 FE thicknesses); not nh, le (not in the FE "
             "sweep: the FMUs and the Arduino firmware refuse them)")  # fmt: skip


def _require(tool: str, package: str) -> None:
    """Fail under CI, skip otherwise, when a tool is missing."""
    if shutil.which(tool) is None:
        (pytest.fail if CI else pytest.skip)(f"{tool} missing: apt-get install {package}")


def _build(out: Path, *extra: str) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return subprocess.run(
        [sys.executable, "-m", "grasprom", "build", "--out", str(out), *extra],
        capture_output=True, text=True, env=env, cwd=out.parent, timeout=300,
    )  # fmt: skip


@pytest.fixture(scope="module")
def one(tmp_path_factory) -> SimpleNamespace:
    """One ``grasprom build --fast`` on the sweep of mr only."""
    base = tmp_path_factory.mktemp("one")
    fe = copy_sweep("fe_data/default", base / "fe_mr", ["mr"])
    out = base / "out"
    res = _build(out, "--fe", str(fe), "--material", "mr", "--fast")
    assert res.returncode == 0, res.stderr
    return SimpleNamespace(
        fe=fe, out=out, res=res, meta=json.loads((out / "build.json").read_text())
    )


def test_every_stage_runs_and_the_coverage_is_stated(one):
    from grasprom.pipeline import STAGES

    for i, name in enumerate(STAGES, 1):
        assert f"[{i}/{len(STAGES)}] {name} done in" in one.res.stderr
    assert f"grasprom build: {STATEMENT}" in one.res.stderr
    cov = one.meta["results"]["coverage"]
    ts = [0.8, 1.0, 1.2, 1.4, 1.6, 1.8, 2.0]
    assert cov == {"materials": ["mr"], "thickness_mm": ts, "thickness_mm_by_material": {"mr": ts},
                   "thickness_range_mm": {"mr": [0.8, 2.0]}, "missing_materials": ["nh", "le"],
                   "statement": STATEMENT}  # fmt: skip
    assert f"<b>Coverage</b>: {STATEMENT}." in (one.out / "report.html").read_text()
    assert one.meta["provenance"]["failed_stage"] is None
    assert one.meta["results"]["cosim"]["max_torque_diff_vs_python_Nm"] < 1e-9


@pytest.mark.parametrize("name", ["GraspController.fmu", "GraspController_fmi3.fmu"])
def test_fmu_lists_only_mr_matches_python_and_refuses_nh(one, name):
    from fmpy import read_model_description, simulate_fmu
    from fmpy.validation import validate_fmu

    from grasprom.control import ControllerParams, ImpedanceController, load_params
    from grasprom.surrogate import Surrogate
    from tests.export.test_fmu import _Slave, opened_fmu

    _require("gcc", "gcc")
    fmu = one.out / name
    assert validate_fmu(str(fmu)) == []
    v = {x.name: x for x in read_model_description(str(fmu)).modelVariables}
    assert [(i.name, int(i.value)) for i in v["material"].declaredType.items] == [("mr", 0)]
    assert (int(v["material"].start), int(v["material"].min), int(v["material"].max)) == (0, 0, 0)
    assert (float(v["thickness"].min), float(v["thickness"].max)) == pytest.approx((8e-4, 2e-3))
    # at mr the FMU is the Python controller (outputs lag one step)
    params, sur = (
        load_params(one.out / "controller.json"),
        Surrogate.load(one.out / "surrogate.json"),
    )
    assert sur.materials == ("mr",) and params.material == "mr"
    t = np.arange(0.0, 0.5, 1e-3)
    theta = np.radians(22.0 - 40.0 * t)
    sig = np.array(list(zip(t, theta)), dtype=[("time", float), ("theta", float)])
    r = simulate_fmu(str(fmu), stop_time=0.499, step_size=1e-3, input=sig,
                     output=["torque", "force_jaw"])  # fmt: skip
    ctl = ImpedanceController(params, sur)
    ref = np.array([ctl.step(float(th)).torque_Nm for th in theta[:-1]])
    np.testing.assert_allclose(r["torque"][1:], ref, rtol=1e-9, atol=1e-12)
    assert r["force_jaw"][-1] > 0.1  # it grasped
    with pytest.raises(ValueError, match="'nh' is not in the surrogate, which covers mr"):
        ImpedanceController(ControllerParams(material="nh"), sur)
    version = 3 if "fmi3" in name else 2
    s = _Slave(opened_fmu(fmu, one.out.parent / f"x{version}", version), version)
    assert s.instantiate()
    try:
        for code in (1, 2):  # nh, le
            assert s.set("material", code) == 3
            assert (f"material = {code} is not an item of this FMU (Material items 0 mr, the "
                    "materials of the FE sweep this FMU was built from)") in s.last()  # fmt: skip
        assert s.set("material", 0) == 0 and s.enter() == 0 and s.exit() == 0
    finally:
        s.free()


def test_arduino_tables_hold_only_mr(one, tmp_path):
    from grasprom.control import load_params
    from grasprom.export import arduino as ar
    from grasprom.surrogate import Surrogate

    sk = one.out / "arduino" / "grasprom_controller"
    tables_h = (sk / "grasp_fixed_tables.h").read_text()
    assert "gf_mr_y" in tables_h and "gf_nh_" not in tables_h and "gf_le_" not in tables_h
    assert '#define GF_MATERIAL_LIST "mr"' in (sk / "grasp_firmware.h").read_text()
    assert "has no nh or le: `M nh` is refused" in (sk / "README.md").read_text()
    assert one.meta["results"]["arduino"]["flash_B"] is not None or not CI
    # the exported tables are those of the build's surrogate and controller; the core refuses
    # nh and le (gf_init -1) and runs mr
    sur, params = (
        Surrogate.load(one.out / "surrogate.json"),
        load_params(one.out / "controller.json"),
    )
    t = ar.build_tables(sur, params, 0.005)
    assert t.tables_source() == tables_h and t.material_names == ("mr",)
    _require("gcc", "gcc")
    counts = ar.sweep_counts(t)
    cases = [ar.VectorCase(m, 1400, counts) for m in ("mr", "nh", "le")]
    run = ar.run_host(t, cases, tmp_path)
    assert run.init_rc == [0, -1, -1]
    e = ar.error_figures(t, sur, cases[:1], ar.CoreRun([0], run.outputs[:1], b""))
    assert e.handle_pct_fs <= 100 * ar.ERROR_BUDGET


def test_material_not_in_the_sweep_is_a_bad_input(tmp_path):
    fe = copy_sweep("fe_data/default", tmp_path / "fe_mr", ["mr"])
    out = tmp_path / "out"
    res = _build(out, "--fe", str(fe), "--material", "nh", "--fast")
    assert res.returncode == 2
    err = res.stderr
    assert f"--material nh: the FE sweep {fe} covers only mr (thickness 0.8-2 mm)" in err
    assert "build with --material mr" in err
    assert f"grasprom sweep --material nh --thickness 0.8,1,1.2,1.4,1.6,1.8,2 --out {fe}" in err
    assert "recorded in its sweep.json" in err and "Traceback" not in err
    assert not out.exists()


def test_material_listed_in_sweep_json_but_without_cases_is_a_bad_input(tmp_path):
    """An interrupted sweep: its sweep.json lists mr, nh and le but only the mr case files
    exist. ``--material le`` was taken as covered and failed in stage surrogate (exit 1, no
    sweep command); it is a bad input before any stage, as for a sweep without le."""
    fe = copy_sweep("fe_data/default", tmp_path / "fe_interrupted", ["mr"])
    shutil.copy(ROOT / "fe_data" / "default" / "sweep.json", fe / "sweep.json")
    listed = json.loads((fe / "sweep.json").read_text())["cases"]
    assert {c["material"] for c in listed} == {"mr", "nh", "le"}
    assert {p.name.split("_t")[0] for p in fe.glob("*_t*")} == {"mr"}
    out = tmp_path / "out"
    res = _build(out, "--fe", str(fe), "--material", "le", "--fast")
    assert res.returncode == 2, res.stderr
    err = res.stderr
    assert f"--material le: the FE sweep {fe} covers only mr (thickness 0.8-2 mm)" in err
    assert f"grasprom sweep --material le --thickness 0.8,1,1.2,1.4,1.6,1.8,2 --out {fe}" in err
    assert "stage" not in err and "Traceback" not in err
    assert not out.exists()


def test_tune_on_a_sweep_without_the_default_material(tmp_path):
    """The tuned controller's operating point is a covered one: the default mr becomes nh on
    a sweep of nh only (controller.json exports as it is); a material not in it is refused."""
    from grasprom.cli import main
    from grasprom.control import ControllerParams, load_params, tune
    from grasprom.surrogate import Surrogate

    fe = copy_sweep("fe_data/2d", tmp_path / "fe_nh", ["nh"])
    sur = Surrogate.build(fe)
    res = tune(sur, ControllerParams(thickness_mm=1.4), n_theta=41, verify=False)
    assert (res.params.material, res.params.thickness_mm) == ("nh", 1.4)
    out = tmp_path / "t"
    assert main(["tune", "--fe", str(fe), "--out", str(out), "--no-plots"]) == 0
    assert load_params(out / "controller.json").material == "nh"
    assert main(["tune", "--fe", str(fe), "--out", str(tmp_path / "t2"), "--material", "le"]) == 2
