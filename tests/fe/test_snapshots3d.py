"""Deformed shapes of the 3D model (issue 18): the recorded cross-sections obey the contact
geometry, and the VTU file has valid triquadratic hexahedra (VTK's node order, checked on the
reference geometry) that meshio reads back with the displacements."""

from __future__ import annotations

import numpy as np
import pytest

from grasprom.fe.mesh3d import MeshSpec3D
from grasprom.fe.model3d import CaseSpec3D, build_disc, run_case_3d
from grasprom.fe.snapshots3d import SectionRecorder, plot_sections, write_vtu

SPEC = CaseSpec3D("mr", 1.4, tube_length_mm=30.0, closed_gap_mm=24.0,
                  mesh=MeshSpec3D(n_layers=1, n_circ=8, n_jaw=2, n_free=2))  # fmt: skip


@pytest.fixture(scope="module")
def run():
    rec = SectionRecorder(gaps_mm=(27.0, 25.0))
    states = []
    res = run_case_3d(SPEC, on_step=lambda d, u, g, f: (rec(d, u, g, f), states.append(u.copy())))
    return res, rec.result(), states[-1]


def test_sections_follow_the_jaw_and_the_tube_ovalises(run):
    res, sections, _ = run
    gaps = [s["gap_mm"] for s in sections]
    # the first converged state at or below each requested gap (steps of <= 2 mm of gap)
    assert gaps[0] <= 27.0 < gaps[0] + 2.0 and gaps[1] <= 25.0 < gaps[1] + 2.0
    assert np.all(np.diff(gaps) < 0)
    last = sections[-1]
    assert last["gap_mm"] == pytest.approx(res.table["gap_mm"].iloc[-1])
    outer = np.asarray(last["outer_xy_mm"])
    R = 0.5 * SPEC.diameter_mm
    # the top node (x = 0) never enters the jaw (y <= gap / 2) and stays on it or just below
    # (in 3D the contact moves to the jaw edges; on this coarse mesh the centre lifts off by
    # ~2 um); the side (y = 0) bulges out
    assert outer[0, 0] == pytest.approx(0.0, abs=1e-9)
    assert 0.5 * last["gap_mm"] - 0.01 < outer[0, 1] <= 0.5 * last["gap_mm"] + 1e-9
    assert outer[-1, 1] == pytest.approx(0.0, abs=1e-9) and outer[-1, 0] > R
    inner = np.asarray(last["inner_xy_mm"])
    assert len(inner) == len(outer)  # the whole quarter of the inner wall, x = 0 to y = 0
    assert inner[0, 0] == pytest.approx(0.0, abs=1e-9) and inner[-1, 1] == pytest.approx(0.0)
    wall = np.hypot(*(outer - inner).T)  # the wall keeps about its thickness
    assert np.all(np.abs(wall / SPEC.thickness_mm - 1) < 0.25)
    # along the axis the top line rises back towards the undeformed radius away from the jaw
    top = np.asarray(last["top_zy_mm"])
    assert top[0, 1] == outer[0, 1]  # the same node: x = 0, z = 0
    assert top[-1, 1] > top[0, 1]


def test_plot_sections(run, tmp_path):
    png = plot_sections(run[1], "mr_t1.40", tmp_path / "s.png")
    assert png.stat().st_size > 10_000


def test_vtu_has_valid_hexahedra_and_the_displacements(run, tmp_path):
    import meshio

    disc = build_disc(SPEC)
    cells = disc.edofs[:, ::3] // 3
    u = run[2]
    path = write_vtu(tmp_path / "tube.vtu", disc, u, cells)
    m = meshio.read(path)
    (block,) = m.cells
    assert block.type == "hexahedron27" and block.data.shape == (cells.shape[0], 27)
    np.testing.assert_allclose(m.point_data["displacement_mm"], u.reshape(-1, 3))
    X = m.point_data["reference_position_mm"][block.data]  # (ne, 27, 3), VTK order
    # VTK order: corners 0-7 right-handed, edge node 8 between corners 0 and 1, face node 24
    # (z = 0 face) amid corners 0-3, centre 26 amid all corners (curved cells: to h / 20)
    e1, e3, e4 = X[:, 1] - X[:, 0], X[:, 3] - X[:, 0], X[:, 4] - X[:, 0]
    vol = np.einsum("ei,ei->e", np.cross(e1, e3), e4)
    assert np.all(vol > 0)
    h = np.linalg.norm(e1, axis=1)[:, None]
    for node, corners in ((8, [0, 1]), (24, [0, 1, 2, 3]), (26, list(range(8)))):
        dev = np.linalg.norm(X[:, node] - X[:, corners].mean(axis=1), axis=1)[:, None]
        assert np.all(dev < 0.05 * np.maximum(h, np.linalg.norm(e3, axis=1)[:, None])), node


def test_vtu_of_a_coarsened_far_zone_writes_every_node(tmp_path):
    """With far_coarsening = 2 the fine zone's interface nodes are not solver nodes: the VTU
    holds them too, each at the coarse face's interpolation (reference: a linear displacement
    field, exact there), and its cells are the mesh's valid hexahedra."""
    from dataclasses import replace

    import meshio

    spec = replace(SPEC, mesh=MeshSpec3D(n_layers=2, n_circ=8, n_jaw=2, n_free=2, far_coarsening=2))
    disc = build_disc(spec)
    A = np.array([[0.01, 0.0, 0.002], [0.003, -0.02, 0.0], [0.0, 0.001, 0.004]])
    u = (disc.X @ A.T).ravel()
    path = write_vtu(tmp_path / "zoned.vtu", disc, u)
    m = meshio.read(path)
    (block,) = m.cells
    X = m.point_data["reference_position_mm"]
    assert X.shape[0] > disc.X.shape[0] and block.data.shape == (disc.edofs.shape[0], 27)
    np.testing.assert_allclose(m.point_data["displacement_mm"], X @ A.T, atol=1e-12)
    Xc = X[block.data]
    e1, e3, e4 = Xc[:, 1] - Xc[:, 0], Xc[:, 3] - Xc[:, 0], Xc[:, 4] - Xc[:, 0]
    vol = np.einsum("ei,ei->e", np.cross(e1, e3), e4)
    assert np.all(vol > 0)
    with pytest.raises(ValueError, match="omit cells"):
        write_vtu(tmp_path / "bad.vtu", disc, u, disc.edofs[:, ::3] // 3)
