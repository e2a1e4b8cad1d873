"""``grasprom sweep --model 3d`` (issue 18): the 3D model through the sweep machinery.

Coarse mesh, short stroke (a few seconds): the CSV contract columns, the sidecar's model keys,
resuming, the 3D tube stiffer than the 2D ring times the jaw length (the tube beyond the jaws
resists the ovalisation), and clear errors for options that do not fit the model.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pandas as pd
import pytest

from grasprom.cli import main
from grasprom.fe.datafiles import input_hash, sweep_parameters
from grasprom.fe.grid import build_grid
from grasprom.fe.grid3d import DEFAULT_MESH_PRESET, MESH_PRESETS, Model3DOptions, to_3d
from grasprom.fe.mesh3d import MeshSpec3D
from grasprom.fe.model2d import CONTRACT_COLUMNS

ROOT = Path(__file__).resolve().parents[2]
COARSE = ["--mesh", "coarse", "--n-layers", "1", "--n-circ", "8", "--tube-length", "30",
          "--closed-gap", "27"]  # fmt: skip


def _sweep(out, *extra):
    return main(["sweep", "--thickness", "1.4", "--material", "mr", "--workers", "1",
                 "--quiet", "--out", str(out), *extra])  # fmt: skip


def _sweep_3d_meta(out, *extra):
    """The sidecar of the coarse 3D case run with ``extra`` options into ``out``."""
    assert _sweep(out, "--model", "3d", *COARSE, *extra) == 0
    return json.loads((out / "mr_t1.40.json").read_text())


def test_3d_sweep_writes_the_contract_and_the_model_keys(tmp_path, capsys):
    out = tmp_path / "s3d"
    assert _sweep(out, "--model", "3d", *COARSE) == 0
    table = pd.read_csv(out / "mr_t1.40.csv")
    assert set(CONTRACT_COLUMNS) <= set(table.columns)
    assert {"contact_area_mm2", "tangential_share", "strain_energy_mJ"} <= set(table.columns)
    meta = json.loads((out / "mr_t1.40.json").read_text())
    units = meta["units"]  # every column has its unit in the sidecar
    assert set(units) == set(table.columns) and None not in units.values()
    assert units["contact_area_mm2"] == "mm^2" and units["strain_energy_mJ"] == "mJ"
    assert meta["model"] == "3d" and meta["contact"] == "stick"
    assert meta["tube_length_mm"] == 30.0 and meta["ends"] == "free"
    assert meta["status"] == "complete" and meta["max_force_N"] > 0
    # the solver's path rules beside its settings (module constants: a re-run with others may
    # take another path through the crease band)
    rules = meta["fe_info"]["solver_rules"]
    assert rules["forward_stall_rises"] == 15 and rules["stall_rises"] == 6
    assert rules["crease_back_halvings"] == 3 and rules["active_set_rtol"] == 0.01
    assert rules["relax_plain_unshifted"] is True
    # the deformed shape at the last gap, for the report's picture
    (sec,) = meta["fe_info"]["sections"]
    assert sec["gap_mm"] == pytest.approx(table["gap_mm"].iloc[-1])
    assert sec["force_N"] == pytest.approx(table["force_N"].iloc[-1])
    assert main(["report", str(out), "--out", str(tmp_path / "rep")]) == 0
    assert (tmp_path / "rep" / "sections_mr_t1.40.png").stat().st_size > 10_000
    # resumable: a second run computes nothing
    capsys.readouterr()
    assert _sweep(out, "--model", "3d", *COARSE) == 0
    assert "1 skipped" in capsys.readouterr().out

    out2 = tmp_path / "s2d"
    assert _sweep(out2, "--closed-gap", "27") == 0
    meta2 = json.loads((out2 / "mr_t1.40.json").read_text())
    assert meta2["model"] == "2d" and meta2["tube_length_mm"] is None
    assert None not in meta2["units"].values() and meta2["units"]["strain_energy_mJ"] == "mJ"
    f3 = table.set_index("gap_mm")["force_N"].iloc[-1]
    f2 = pd.read_csv(out2 / "mr_t1.40.csv").set_index("gap_mm")["force_N"].iloc[-1]
    assert f3 > 1.5 * f2 > 0
    assert meta2["contact"] == "frictionless"


def test_3d_sweep_takes_the_graded_mesh_options(tmp_path):
    """``--grading`` / ``--radial-grading`` reach the 3D mesh (the fold-resolving meshes of
    docs/fe-model.md run from the command line) and the sidecar records them."""
    out = tmp_path / "graded"
    graded = ["--grading", "3", "--radial-grading", "2", "--n-layers", "2"]
    assert _sweep(out, "--model", "3d", *COARSE, *graded) == 0
    mesh = json.loads((out / "mr_t1.40.json").read_text())["mesh"]
    assert mesh["grading"] == 3.0 and mesh["radial_grading"] == 2.0
    assert mesh["n_layers"] == 2 and mesh["n_circ"] == 8


def test_3d_sweep_takes_the_axial_mesh_and_predicted_contact_options(tmp_path):
    """``--n-jaw`` / ``--n-free`` reach the 3D mesh and ``--predict-contact-below`` (in wall
    thicknesses) the solver; the sidecars record both, and a sweep over several thicknesses
    takes it (the documented converged sweep, docs/fe-sweeps.md, stopped with "cases of one
    sweep must share their parameters" when the option was stored as a gap in mm per case)."""
    out = tmp_path / "axial"
    axial = ["--n-jaw", "2", "--n-free", "3", "--predict-contact-below", "2.5"]
    argv = ["sweep", "--thickness", "1.2,1.4", "--material", "mr", "--workers", "1", "--quiet"]
    assert main([*argv, "--out", str(out), "--model", "3d", *COARSE, *axial]) == 0
    for stem in ("mr_t1.20", "mr_t1.40"):
        meta = json.loads((out / f"{stem}.json").read_text())
        assert meta["mesh"]["n_jaw"] == 2 and meta["mesh"]["n_free"] == 3
        assert meta["solver"]["predict_contact_below_t"] == 2.5
        assert meta["solver"]["predict_contact_below_mm"] == 0.0
        assert meta["status"] == "complete"
    # one multiple serves a thickness sweep
    specs = build_grid("0.8,2.0", "mr,le")
    opts = Model3DOptions(n_free=6, predict_contact_below_t=2.5)
    cases = to_3d(specs, opts, {"n_layers": 4})
    for c in cases:
        assert c.solver.predict_contact_below_t == 2.5
        assert c.mesh.n_free == 6 and c.mesh.n_layers == 4 and c.mesh.n_jaw == 4
    # the coarse mesh: predicted contact off, MeshSpec3D's defaults
    (plain,) = to_3d(build_grid("1.4", "mr"), Model3DOptions(mesh="coarse"), {})
    assert plain.solver.predict_contact_below_t == 0.0 and plain.mesh == MeshSpec3D()


def test_3d_sweep_defaults_to_the_shipped_mesh(capsys):
    """Without mesh options ``grasprom sweep --model 3d`` computes on the mesh of the shipped
    ``fe_data/default`` (its sweep manifest records the mesh and the solver settings), so the
    documented command reproduces the shipped data; each mesh option overrides the preset."""
    manifest = json.loads((ROOT / "fe_data" / "default" / "sweep.json").read_text())
    shipped = manifest["parameters"]
    (case,) = to_3d(build_grid("1.4", "mr"), Model3DOptions(), {})
    assert sweep_parameters(case)["mesh"] == shipped["mesh"]
    hashes = {c["stem"]: c["input_hash"] for c in manifest["cases"]}
    assert input_hash(case) == hashes["mr_t1.40"]  # the shipped files stay current
    below = shipped["solver"]["predict_contact_below_t"]
    assert case.solver.predict_contact_below_t == below == 2.5
    (other,) = to_3d(build_grid("1.4", "mr"), Model3DOptions(n_free=3), {"n_circ": 24})
    assert (other.mesh.n_circ, other.mesh.n_free, other.mesh.grading) == (24, 3, 8.0)
    assert DEFAULT_MESH_PRESET == "converged"
    assert set(MESH_PRESETS) == {"converged", "coarse", "zoned"}
    with pytest.raises(SystemExit):
        main(["sweep", "--help"])
    helptext = " ".join(capsys.readouterr().out.split())
    assert all(name in helptext for name in MESH_PRESETS)


def test_3d_sweep_takes_the_far_coarsening(tmp_path):
    """``--far-coarsening 2`` reaches the mesh and the sidecar (with it, and only then, the
    sidecar's spec records the field: files written before it stay current)."""
    meta = _sweep_3d_meta(tmp_path / "zoned", "--n-layers", "2", "--far-coarsening", "2")
    assert meta["spec"]["mesh"]["far_coarsening"] == 2 and meta["status"] == "complete"
    # 2 x 8 over the jaw zone (its interface plane tied), 1 x 4 over the 9 divisions beyond
    assert meta["fe_info"]["dofs"] == 3 * (5 * 17 * 8 + 3 * 9 * 19)
    (plain,) = to_3d(build_grid("1.4", "mr"), Model3DOptions(), {})
    assert "far_coarsening" not in sweep_parameters(plain)["mesh"]


def test_3d_sweep_takes_the_band_companion(tmp_path):
    """``--band-companion 2`` reaches the solver settings and the sidecar, with the companion's
    record (this stroke ends above the crease band: no band gaps); without it the sidecar's
    spec does not name the field (files written before it stay current)."""
    meta = _sweep_3d_meta(tmp_path / "companion", "--n-layers", "2", "--band-companion", "2")
    assert meta["spec"]["solver"]["band_companion"] == 2 and meta["status"] == "complete"
    assert meta["fe_info"]["band_selection"]["status"] == "no band gaps"
    (plain,) = to_3d(build_grid("1.4", "mr"), Model3DOptions(band_companion=0), {})
    assert "band_companion" not in sweep_parameters(plain)["solver"]


@pytest.mark.parametrize(
    "opts, mesh, expected",
    [
        ({}, {}, 2),  # the converged preset's: the shipped data's selection
        ({"band_companion": 0}, {}, 0),  # off
        ({"band_companion": 4}, {}, 4),  # another companion, given
        ({"mesh": "converged"}, {}, 2),
        ({"mesh": "coarse"}, {}, 0),
        ({"mesh": "zoned"}, {}, 0),
        ({}, {"n_circ": 24}, 0),  # a mesh option leaves the preset's mesh: no companion
        ({"n_free": 3}, {}, 0),
        ({"far_coarsening": 2}, {}, 0),
        ({"contact": "frictionless"}, {}, 2),  # strain energy ranks frictionless states
        ({"contact": "coulomb", "friction": 0.3}, {}, 0),  # and not Coulomb ones
        ({}, {"n_circ": 36}, 0),  # a mesh option even at the preset's value
        ({"n_jaw": 4}, {}, 0),
        ({"predict_contact_below_t": 3.0}, {}, 2),  # a solver option keeps it
        ({"tube_length_mm": 40.0}, {}, 2),
        ({"tube_length_mm": 14.0}, {}, 0),  # jaw 10 + 2 x 2 mm margin: no far zone to coarsen
    ],
)
def test_the_converged_mesh_selects_the_crease_band_by_default(opts, mesh, expected):
    """``--mesh converged`` (the default) brings the shipped data's band companion 2 with its
    mesh (MeshPreset.band_companion); the other presets, a mesh option overriding the preset's
    mesh, or Coulomb contact leave it off; ``--band-companion K`` always wins."""
    (case,) = to_3d(build_grid("1.4", "mr"), Model3DOptions(**opts), mesh)
    assert case.solver.band_companion == expected
    assert MESH_PRESETS["converged"].band_companion == 2


def test_the_zoned_mesh_is_the_converged_one_with_a_coarsened_far_zone():
    """``--mesh zoned``: the converged preset's mesh and predicted contact with
    ``far_coarsening`` 2; ``--far-coarsening 1`` on top of it gives back the shipped mesh (the
    same input hash as the shipped case's own run, ``--band-companion 0``)."""
    specs = build_grid("1.4", "mr")
    (conv,) = to_3d(specs, Model3DOptions(band_companion=0), {})  # the own run
    (zoned,) = to_3d(specs, Model3DOptions(mesh="zoned"), {})
    assert zoned.mesh == replace(conv.mesh, far_coarsening=2)
    assert zoned.solver == conv.solver and zoned.solver.predict_contact_below_t == 2.5
    (back,) = to_3d(specs, Model3DOptions(mesh="zoned", far_coarsening=1), {})
    assert back == conv and input_hash(back) == input_hash(conv)


def test_2d_sweep_with_stick_contact_records_it(tmp_path):
    out = tmp_path / "stick2d"
    assert _sweep(out, "--contact", "stick", "--closed-gap", "20") == 0
    meta = json.loads((out / "mr_t1.40.json").read_text())
    assert meta["model"] == "2d" and meta["contact"] == "stick"
    assert pd.read_csv(out / "mr_t1.40.csv")["tangential_share"].max() > 0


def test_2d_sweep_with_coulomb_contact_records_the_coefficient(tmp_path):
    out = tmp_path / "coulomb2d"
    extra = ["--n-layers", "2", "--n-circ", "32", "--closed-gap", "20"]
    assert _sweep(out, "--contact", "coulomb", "--friction", "0.2", *extra) == 0
    meta = json.loads((out / "mr_t1.40.json").read_text())
    assert meta["model"] == "2d" and meta["contact"] == "coulomb" and meta["friction"] == 0.2
    share = pd.read_csv(out / "mr_t1.40.csv")["tangential_share"]
    assert 0 < share.max() <= 0.2 * (1 + 1e-9)


def test_3d_sweep_with_coulomb_contact_records_the_coefficient(tmp_path):
    out = tmp_path / "coulomb3d"
    extra = ["--model", "3d", *COARSE]
    assert _sweep(out, "--contact", "coulomb", "--friction", "0.2", *extra) == 0
    meta = json.loads((out / "mr_t1.40.json").read_text())
    assert meta["model"] == "3d" and meta["contact"] == "coulomb" and meta["friction"] == 0.2
    share = pd.read_csv(out / "mr_t1.40.csv")["tangential_share"]
    assert 0 < share.max() <= 0.2 * (1 + 1e-9)


@pytest.mark.parametrize(
    "extra, needle",
    [
        (["--ends", "seed"], "--ends: only with --model 3d"),
        (["--tube-length", "100"], "--tube-length: only with --model 3d"),
        (["--contact", "coulomb"], "needs --friction"),
        (["--contact", "coulomb", "--friction", "0"], "--friction: must be a coefficient"),
        (["--contact", "coulomb", "--friction", "nan"], "--friction: must be a coefficient"),
        (["--contact", "stick", "--friction", "0.3"], "only used with --contact coulomb"),
        (["--model", "3d", "--contact", "coulomb"], "needs --friction"),
        (["--model", "3d", "--friction", "0.3"], "--friction"),
        (["--model", "3d", "--tube-length", "-5"], "--tube-length"),
        (["--model", "3d", "--n-circ", "4"], "--n-circ"),
        (["--n-free", "3"], "--n-free: only with --model 3d"),
        (["--n-jaw", "2", "--predict-contact-below", "2"], "--n-jaw, --predict-contact-below"),
        (["--model", "3d", "--n-jaw", "0"], "--n-jaw: must be an integer >= 1"),
        (["--model", "3d", "--n-free", "-1"], "--n-free: must be an integer >= 0"),
        (["--model", "3d", "--predict-contact-below", "0"], "--predict-contact-below"),
        (["--model", "3d", "--predict-contact-below", "nan"], "--predict-contact-below"),
        (["--model", "3d", "--mesh", "fine"], "valid: converged, coarse, zoned"),
        (["--model", "3d", "--mesh", "zoned", "--n-layers", "3"], "--mesh zoned: far_coarsening"),
        (["--mesh", "coarse"], "--mesh: only with --model 3d"),
        (["--far-coarsening", "2"], "--far-coarsening: only with --model 3d"),
        (["--model", "3d", "--far-coarsening", "0"], "--far-coarsening: must be an integer >= 1"),
        (["--model", "3d", "--far-coarsening", "5"], "--far-coarsening: far_coarsening=5 must"),
        (["--band-companion", "2"], "--band-companion: only with --model 3d"),
        (["--model", "3d", "--band-companion", "-1"], "--band-companion: must be an integer >= 0"),
        (["--model", "3d", "--band-companion", "5"], "--band-companion: far_coarsening=5 must"),
        (["--model", "3d", "--mesh", "zoned", "--band-companion", "2"], "must be another mesh"),
        (["--model", "3d", "--tube-length", "14", "--band-companion", "2"], "no far zone"),
        (
            ["--model", "3d", "--contact", "coulomb", "--friction", "0.2", "--band-companion", "2"],
            "--band-companion: not with Coulomb contact",
        ),
    ],
)
def test_3d_options_that_do_not_fit_are_clear_errors(tmp_path, capsys, extra, needle):
    assert _sweep(tmp_path / "bad", *extra) == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err


def test_the_band_selection_of_a_stored_sweep_is_the_companion_sweeps(tmp_path):
    """``--band-companion 2 --select-from A`` writes the cases ``--band-companion 2`` writes
    (same input hash and rows; this stroke ends above the band, so the parity is of the files
    and records, the band's own parity is in tests/fe/test_bandselect.py), with the own run's
    wall time and provenance."""
    two = ["--n-layers", "2"]
    own = _sweep_3d_meta(tmp_path / "own", *two)
    direct = _sweep_3d_meta(tmp_path / "direct", *two, "--band-companion", "2")
    src = str(tmp_path / "own")
    meta = _sweep_3d_meta(tmp_path / "sel", *two, "--band-companion", "2", "--select-from", src)
    assert meta["input_hash"] == direct["input_hash"] != own["input_hash"]
    assert meta["csv_sha256"] == own["csv_sha256"] == direct["csv_sha256"]  # nothing in the band
    info = meta["fe_info"]
    assert set(info) == set(direct["fe_info"]) | {"own_run"}  # the prior time is not written
    assert info["band_selection"] == direct["fe_info"]["band_selection"] | {"wall_time_s": 0.0}
    assert info["own_run"]["source"] == str((tmp_path / "own").resolve())
    assert info["own_wall_time_s"] == own["fe_info"]["wall_time_s"]
    assert meta["wall_time_s"] >= own["wall_time_s"]


@pytest.mark.parametrize(
    "extra, needle",
    [
        (["--select-from", "{own}"], "--select-from: needs --model 3d and --band-companion"),
        (["--band-companion", "2", "--select-from", "{missing}"], "is not a directory"),
        (["--band-companion", "2", "--select-from", "{out}"], "--out must be another directory"),
        (["--band-companion", "2", "--select-from", "{empty}"], "no case mr_t1.40.json"),
        (["--band-companion", "2", "--tube-length", "40", "--select-from", "{own}"],
         "tube_length_mm"),
        (["--band-companion", "2", "--select-from", "{corrupt}"], "corrupt"),
    ],
)  # fmt: skip
def test_select_from_errors_are_clear(tmp_path, capsys, extra, needle):
    own, out = tmp_path / "own", tmp_path / "out"
    assert _sweep(own, "--model", "3d", *COARSE, "--n-layers", "2") == 0
    (tmp_path / "empty").mkdir()
    corrupt = tmp_path / "corrupt"
    corrupt.mkdir()
    (corrupt / "mr_t1.40.csv").write_bytes((own / "mr_t1.40.csv").read_bytes()[:-40])
    (corrupt / "mr_t1.40.json").write_bytes((own / "mr_t1.40.json").read_bytes())
    out.mkdir()
    paths = {"own": own, "out": out, "missing": tmp_path / "nope", "empty": tmp_path / "empty"}
    paths["corrupt"] = corrupt
    extra = [a.format(**paths) for a in extra]
    capsys.readouterr()
    assert _sweep(out, "--model", "3d", *COARSE, "--n-layers", "2", *extra) == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err
    assert not list(out.iterdir())  # nothing written
