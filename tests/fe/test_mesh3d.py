"""The 3D tube mesh (grasprom.fe.mesh3d): walls found on coarse and default meshes."""

import numpy as np
import pytest

from grasprom.fe.mesh3d import MeshSpec3D, axial_nodes, discretise3d, tube_mesh
from grasprom.fe.model2d import graded_fractions


@pytest.mark.parametrize("n_circ, n_layers", [(3, 1), (6, 1), (12, 2)])
def test_outer_and_inner_walls_cover_the_quarter_and_their_area(n_circ, n_layers):
    """Every wall facet is found, however coarse the circumferential elements.

    References: the quarter circumference at both radii spans x = 0..R (top and side), the
    vertex nodes of the outer wall lie on r = R, and the consistent nodal areas add up to the
    faceted outer surface, (pi / 2) R L x chord / arc.
    """
    R, t, L = 15.0, 1.4, 6.0
    mesh = MeshSpec3D(n_layers=n_layers, n_circ=n_circ)
    d = discretise3d(R, t, axial_nodes(L, L, 3, 0), mesh)
    Xo, Xi = d.X[d.outer_nodes], d.X[d.inner_nodes]
    assert Xo[:, 0].min() == pytest.approx(0.0, abs=1e-12)
    assert Xo[:, 0].max() == pytest.approx(R)
    assert Xi[:, 0].min() == pytest.approx(0.0, abs=1e-12)
    n_z = 2 * 3 + 1
    assert d.outer_nodes.size == (2 * n_circ + 1) * n_z
    assert d.inner_nodes.size == 2 * n_circ * n_z  # the node on y = 0 belongs to the floor
    ro = np.hypot(Xo[:, 0], Xo[:, 1])
    assert ro.max() == pytest.approx(R)
    # faceted area: each element's chord instead of its arc
    dth = 0.5 * np.pi * np.diff(graded_fractions(n_circ, mesh.grading))
    chord = (2 * R * np.sin(0.5 * dth)).sum()
    assert d.outer_area.sum() == pytest.approx(chord * L, rel=1e-10)


@pytest.mark.parametrize(
    "kw",
    [{"grading": 0.0}, {"grading": float("nan")}, {"radial_grading": -2.0},
     {"beta": -0.1}, {"beta": 1.5}, {"beta": float("inf")}, {"n_layers": 0},
     {"n_circ": 1}, {"n_circ": 2.5}, {"n_jaw": 0}, {"n_free": -1}, {"n_layers": True},
     {"fine_margin_mm": -1.0}, {"element": "Q1/P0"}],
)  # fmt: skip
def test_mesh_spec_rejects_bad_ratios_and_shares(kw):
    with pytest.raises(ValueError, match=next(iter(kw))):
        MeshSpec3D(**kw)


def test_radial_grading_thins_the_inner_layers():
    """Layer edges in geometric progression, the outermost 3x the innermost (mm)."""
    m = tube_mesh(15.0, 1.4, np.array([0.0, 1.0]), MeshSpec3D(n_layers=3, radial_grading=3.0))
    r = np.unique(np.round(np.hypot(m.p[0], m.p[1]), 9))
    h = np.diff(r)
    assert r[0] == pytest.approx(13.6) and r[-1] == pytest.approx(15.0)
    assert h[-1] / h[0] == pytest.approx(3.0) and h[1] / h[0] == pytest.approx(np.sqrt(3.0))


@pytest.mark.parametrize(("n_free", "half"), [(1, 30.0), (2, 30.0), (3, 120.0), (2, 400.0)])
def test_axial_nodes_grade_any_free_length_with_few_elements(n_free, half):
    """Few graded elements over a long free tube (the growth factor above 10 once failed to
    bracket: n_free = 2 on a 60 mm tube): uniform over the jaw zone, then growing element
    lengths that end exactly at the tube's end."""
    z = axial_nodes(half, 7.0, 4, n_free)
    assert z.size == 4 + n_free + 1
    np.testing.assert_allclose(z[:5], np.linspace(0.0, 7.0, 5), atol=1e-12)
    assert z[-1] == pytest.approx(half, abs=1e-9)
    dz = np.diff(z[4:])
    assert np.all(dz > 0) and np.all(np.diff(dz) >= -1e-12)
    if n_free > 1:  # geometric growth from the jaw zone's element length
        assert dz[0] == pytest.approx(7.0 / 4, rel=1e-9)
        np.testing.assert_allclose(dz[1:] / dz[:-1], dz[1] / dz[0], rtol=1e-9)
