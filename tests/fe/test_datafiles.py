"""Case files: atomic write/read round trip, hash checks, manifest, sweep loading."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from grasprom.fe import datafiles as df
from grasprom.fe.model2d import CaseSpec
from tests.fake_runner import fake_result


@pytest.fixture
def spec():
    return CaseSpec(material="mr", thickness_mm=0.8)


def test_stem_naming():
    assert df.case_stem("mr", 0.8) == "mr_t0.80"
    assert df.case_stem("le", 2.0) == "le_t2.00"
    assert df.parse_stem("nh_t1.40") == ("nh", 1.4)
    assert df.parse_stem("sweep") is None


def test_roundtrip(tmp_path, spec):
    res = fake_result(spec)
    files = df.write_case(tmp_path, spec, res, wall_time_s=1.5)
    assert files.csv.name == "mr_t0.80.csv" and files.json.name == "mr_t0.80.json"
    case = df.read_case(files.json)
    pd.testing.assert_frame_equal(case.table, res.table, check_exact=True)
    m = case.meta
    for key in (
        "material",
        "thickness_mm",
        "diameter_mm",
        "jaw_length_mm",
        "closed_gap_mm",
        "force_cap_N",
        "status",
        "material_constants",
        "mesh",
        "solver",
        "versions",
        "git_revision",
        "input_hash",
        "csv_sha256",
        "wall_time_s",
        "units",
        "schema_version",
    ):
        assert key in m, key
    assert m["material"] == "mr" and m["thickness_mm"] == 0.8 and m["status"] == "complete"
    assert m["wall_time_s"] == 1.5
    assert m["input_hash"] == df.input_hash(spec)
    assert m["csv_sha256"] == df.sha256_file(files.csv)
    assert m["units"]["force_N"] == "N" and m["units"]["gap_mm"] == "mm"
    assert set(m["versions"]) >= {"grasprom", "numpy", "scipy", "skfem", "pandas", "python"}
    assert m["mesh"] == {"n_layers": spec.mesh.n_layers, **m["mesh"]}
    # reading via the CSV path or the bare stem works too
    assert df.read_case(files.csv).meta == m
    assert df.read_case(tmp_path / "mr_t0.80").meta == m
    # no temporary files left behind
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mr_t0.80.csv", "mr_t0.80.json"]


def test_input_hash_depends_on_every_input(spec):
    h = df.input_hash(spec)
    assert h == df.input_hash(CaseSpec(material="mr", thickness_mm=0.8))
    assert h != df.input_hash(CaseSpec(material="mr", thickness_mm=0.9))
    assert h != df.input_hash(CaseSpec(material="mr", thickness_mm=0.8, force_cap_N=100))


def test_write_rejects_bad_result(tmp_path, spec):
    res = fake_result(spec)
    bad = type(res)(table=res.table.drop(columns=["force_N"]), status="complete", info={})
    with pytest.raises(ValueError, match="force_N"):
        df.write_case(tmp_path, spec, bad)
    bad = type(res)(table=res.table, status="weird", info={})
    with pytest.raises(ValueError, match="status"):
        df.write_case(tmp_path, spec, bad)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("damage", "culprit", "reason"),
    [
        ("csv_bytes", ".csv", "sha256"),
        ("csv_missing", ".csv", "not found"),
        ("json_garbage", ".json", "does not parse"),
        ("json_keys", ".json", "missing keys"),
        ("csv_columns", ".csv", "missing required columns"),
    ],
)
def test_corruption_detected(tmp_path, spec, damage, culprit, reason):
    files = df.write_case(tmp_path, spec, fake_result(spec))
    if damage == "csv_bytes":
        files.csv.write_bytes(files.csv.read_bytes()[:-20])
    elif damage == "csv_missing":
        files.csv.unlink()
    elif damage == "json_garbage":
        files.json.write_text('{"material": "mr", ')
    elif damage == "json_keys":
        meta = json.loads(files.json.read_text())
        del meta["csv_sha256"]
        files.json.write_text(json.dumps(meta))
    elif damage == "csv_columns":
        data = pd.read_csv(files.csv).drop(columns=["gap_mm"]).to_csv(index=False).encode()
        files.csv.write_bytes(data)
        meta = json.loads(files.json.read_text())
        meta["csv_sha256"] = df.sha256_bytes(data)
        files.json.write_text(json.dumps(meta))
    with pytest.raises(df.CorruptCaseError) as exc:
        df.read_case(files.json)
    assert exc.value.path.name == f"mr_t0.80{culprit}"
    assert f"mr_t0.80{culprit}" in str(exc.value) and reason in str(exc.value)


def test_load_sweep_and_manifest(tmp_path):
    specs = [CaseSpec(material=m, thickness_mm=t) for m in ("mr", "le") for t in (0.8, 1.2)]
    for s in specs:
        df.write_case(tmp_path, s, fake_result(s))
    man = df.write_manifest(tmp_path, specs)
    assert man["grid"] == {"materials": ["le", "mr"], "thickness_mm": [0.8, 1.2]}
    assert man["parameters"]["diameter_mm"] == 30.0
    assert [c["stem"] for c in man["cases"]] == ["le_t0.80", "le_t1.20", "mr_t0.80", "mr_t1.20"]
    assert df.read_manifest(tmp_path)["created"] == man["created"]
    data = df.load_sweep(tmp_path)
    assert list(data.columns[:3]) == ["material", "thickness_mm", "status"]
    assert set(df.REQUIRED_COLUMNS) <= set(data.columns)
    assert len(data) == 4 * 12
    assert data.groupby(["material", "thickness_mm"]).size().to_dict() == {
        ("le", 0.8): 12,
        ("le", 1.2): 12,
        ("mr", 0.8): 12,
        ("mr", 1.2): 12,
    }
    # a manifest for other parameters in the same directory is refused
    other = [CaseSpec(material="mr", thickness_mm=0.8, diameter_mm=25.0)]
    with pytest.raises(ValueError, match="another --out"):
        df.write_manifest(tmp_path, other)


def test_load_sweep_missing_dir(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope"):
        df.load_sweep(tmp_path / "nope")
    assert df.load_sweep(tmp_path).empty


def test_own_wall_time_is_the_fe_runs_not_the_selections():
    """A band selection records the own run's time beside the total (bandselect); a sidecar
    without one has only the total, which is then the own run's."""
    assert df.own_wall_time_s({"wall_time_s": 900.0, "own_wall_time_s": 600.0}) == 600.0
    assert df.own_wall_time_s({"wall_time_s": 900.0}) == 900.0
    assert df.own_wall_time_s({}) != df.own_wall_time_s({})  # NaN: not recorded
