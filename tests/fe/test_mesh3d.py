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


def _zoned(n_layers=2, n_circ=6, n_jaw=2, n_free=2, k=2, half=20.0, z_fine=3.0, grading=2.0):
    mesh = MeshSpec3D(n_layers=n_layers, n_circ=n_circ, n_jaw=n_jaw, n_free=n_free,
                      grading=grading, far_coarsening=k)  # fmt: skip
    z = axial_nodes(half, z_fine, n_jaw, n_free)
    return mesh, z, discretise3d(15.0, 1.4, z, mesh, n_fine=n_jaw)


@pytest.mark.parametrize("k", [2, 3])
def test_coarsened_far_zone_passes_the_patch_test_across_its_interface(k):
    """A linear displacement field is exact on every element, across the tied interface too
    (reference: F = I + A everywhere), and the tied nodes get it from the coarse face."""
    _, _, d = _zoned(n_layers=2 * k, n_circ=6, k=k)  # two coarse layers
    A = np.array([[0.01, 0.002, -0.003], [0.004, -0.02, 0.001], [0.0, 0.003, 0.005]])
    u = (d.X @ A.T).ravel()
    from grasprom.fe.model3d import kinematics

    F = kinematics(d, u)
    np.testing.assert_allclose(F, np.broadcast_to(np.eye(3) + A, F.shape), atol=1e-13)
    X, disp, cells = d.output_mesh(u)
    np.testing.assert_allclose(disp, X @ A.T, atol=1e-13)
    assert cells.shape == (d.edofs.shape[0], 27) and X.shape[0] > d.X.shape[0]


def test_coarsened_far_zone_counts_nodes_and_faceted_area():
    """Nodes: the fine zone without its interface plane (tied) plus the coarse zone; the outer
    area adds up to each zone's faceted surface (chords of its own circumferential elements)."""
    nl, nc, nj, nf, k = 4, 12, 2, 3, 2
    mesh, z, d = _zoned(nl, nc, nj, nf, k, half=40.0, z_fine=4.0, grading=4.0)
    fine = (2 * nl + 1) * (2 * nc + 1) * (2 * nj)
    coarse = (2 * nl // k + 1) * (2 * nc // k + 1) * (2 * nf + 1)
    assert d.ndof == 3 * (fine + coarse)
    th = 0.5 * np.pi * graded_fractions(nc, mesh.grading)

    def chords(t):
        return (2 * 15.0 * np.sin(0.5 * np.diff(t))).sum()

    zf = z[nj]
    area = chords(th) * zf + chords(th[::k]) * (z[-1] - zf)
    assert d.outer_area.sum() == pytest.approx(area, rel=1e-10)
    # the walls and symmetry planes are still found in both zones
    Xo = d.X[d.outer_nodes]
    assert np.hypot(Xo[:, 0], Xo[:, 1]).max() == pytest.approx(15.0)
    assert d.on_end.sum() == (2 * nl // k + 1) * (2 * nc // k + 1)
    assert d.on_z0.sum() == (2 * nl + 1) * (2 * nc + 1)


def test_far_coarsening_must_divide_the_cross_section_and_have_a_far_zone():
    with pytest.raises(ValueError, match="far_coarsening"):
        MeshSpec3D(n_layers=3, n_circ=12, far_coarsening=2)
    with pytest.raises(ValueError, match="far_coarsening"):
        MeshSpec3D(far_coarsening=0)
    with pytest.raises(ValueError, match="fine_margin_mm > 0"):
        MeshSpec3D(far_coarsening=2, fine_margin_mm=0.0)
    mesh = MeshSpec3D(n_layers=2, n_circ=6, far_coarsening=2)
    for z, n_fine in ((axial_nodes(5.0, 7.0, 2, 2), 2), (axial_nodes(20.0, 3.0, 2, 0), 2),
                      (axial_nodes(20.0, 3.0, 2, 2), None)):  # fmt: skip
        with pytest.raises(ValueError, match="needs a far zone"):
            discretise3d(15.0, 1.4, z, mesh, n_fine=n_fine)


def test_far_coarsening_one_is_the_plain_mesh_bit_for_bit():
    """k = 1 (and a zone split given) keeps the one cross-section of before."""
    z = axial_nodes(20.0, 3.0, 2, 2)
    a = discretise3d(15.0, 1.4, z, MeshSpec3D(n_layers=2, n_circ=6))
    b = discretise3d(15.0, 1.4, z, MeshSpec3D(n_layers=2, n_circ=6), n_fine=2)
    assert b.out_X is None
    for name in ("edofs", "grads", "X", "outer_nodes", "outer_area", "inner_nodes"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
