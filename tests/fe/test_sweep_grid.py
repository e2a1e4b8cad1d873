"""Grid parsing and input validation of sweeps."""

from __future__ import annotations

import pytest

from grasprom.fe.grid import (
    KNOWN_MATERIALS,
    SweepInputError,
    build_grid,
    check_out_dir,
    parse_materials,
    parse_thickness,
    spec_defaults,
)
from grasprom.fe.model2d import CaseSpec, MeshSpec


def test_parse_thickness_range_inclusive_without_drift():
    values = parse_thickness("0.8:2.0:0.1")
    assert len(values) == 13
    assert values[0] == 0.8 and values[-1] == 2.0
    assert values[3] == 1.1  # exact, not 1.1000000000000003
    assert parse_thickness("0.8:2.0:0.2") == [0.8, 1.0, 1.2, 1.4, 1.6, 1.8, 2.0]
    assert parse_thickness("0.8:2.05:0.1")[-1] == 2.0  # stop off-grid: last value <= stop


def test_parse_thickness_list_and_single():
    assert parse_thickness("0.8,1.0") == [0.8, 1.0]
    assert parse_thickness(" 1.2 ") == [1.2]
    assert parse_thickness("1.0,1.0,0.8") == [1.0, 0.8]


@pytest.mark.parametrize(
    "text", ["", "abc", "0.8:2.0", "0.8:2.0:0", "0.8:2.0:-0.1", "2.0:0.8:0.1", ",", "1:x:0.1"]
)
def test_parse_thickness_bad(text):
    with pytest.raises(SweepInputError, match="--thickness"):
        parse_thickness(text)


def test_parse_materials():
    assert parse_materials("mr,nh,le") == ["mr", "nh", "le"]
    assert parse_materials("MR, le,mr") == ["mr", "le"]
    with pytest.raises(SweepInputError) as exc:
        parse_materials("mr,steel")
    msg = str(exc.value)
    assert "--material" in msg and "'steel'" in msg
    assert all(m in msg for m in KNOWN_MATERIALS)
    with pytest.raises(SweepInputError, match="--material"):
        parse_materials(" , ")


def test_build_grid_defaults_come_from_casespec():
    specs = build_grid("0.8:1.0:0.1", "mr,le")
    assert [(s.material, s.thickness_mm) for s in specs] == [
        ("mr", 0.8),
        ("mr", 0.9),
        ("mr", 1.0),
        ("le", 0.8),
        ("le", 0.9),
        ("le", 1.0),
    ]
    ref = CaseSpec(material="mr", thickness_mm=0.8)
    assert specs[0] == ref
    d = spec_defaults()
    assert d["diameter_mm"] == ref.diameter_mm and d["n_circ"] == MeshSpec().n_circ


def test_build_grid_overrides():
    (s,) = build_grid(
        [1.2],
        ["nh"],
        diameter_mm=25,
        jaw_length_mm=12,
        closed_gap_mm=2,
        force_cap_N=50,
        n_layers=3,
        n_circ=32,
    )
    assert (s.diameter_mm, s.jaw_length_mm, s.closed_gap_mm, s.force_cap_N) == (25, 12, 2, 50)
    assert (s.mesh.n_layers, s.mesh.n_circ) == (3, 32)


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"thickness": "0"}, "--thickness"),
        ({"thickness": "-0.5"}, "--thickness"),
        ({"thickness": "15"}, "outer radius 15"),
        ({"thickness": "1.0,20"}, "--thickness: wall thickness 20"),
        ({"thickness": "6", "diameter_mm": 12}, "outer radius 6"),
        ({"materials": "rubber"}, "--material"),
        ({"diameter_mm": 0}, "--diameter"),
        ({"diameter_mm": float("nan")}, "--diameter"),
        ({"jaw_length_mm": -1}, "--jaw-length"),
        ({"closed_gap_mm": 0}, "--closed-gap"),
        ({"closed_gap_mm": 40}, "--closed-gap"),
        ({"force_cap_N": -5}, "--force-cap"),
        ({"n_layers": 0}, "--n-layers"),
        ({"n_circ": 2.5}, "--n-circ"),
        ({"thickness": "1.0,1.001"}, "--thickness"),
    ],
)
def test_build_grid_bad_input_names_parameter(kwargs, needle):
    args = {"thickness": "1.0", "materials": "mr", **kwargs}
    with pytest.raises(SweepInputError) as exc:
        build_grid(args.pop("thickness"), args.pop("materials"), **args)
    assert needle in str(exc.value)


def test_build_grid_empty():
    with pytest.raises(SweepInputError, match="empty"):
        build_grid([], "mr")


def test_out_dir_not_writable_names_dir(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    bad = blocker / "sub"
    with pytest.raises(SweepInputError) as exc:
        build_grid("1.0", "mr", out_dir=bad)
    assert "--out" in str(exc.value) and str(bad) in str(exc.value)
    with pytest.raises(SweepInputError, match="not a directory"):
        check_out_dir(blocker)
    assert blocker.read_text() == "x"


def test_out_dir_created(tmp_path):
    d = tmp_path / "x" / "y"
    build_grid("1.0", "mr", out_dir=d)
    assert d.is_dir() and list(d.iterdir()) == []
