"""FE model verification against independent references (thin-ring theory, FD, mesh refinement)."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from grasprom.fe.datafiles import input_mismatch, read_case
from grasprom.fe.materials import get_material
from grasprom.fe.model2d import (
    CaseSpec,
    MeshSpec,
    SolverSettings,
    assemble,
    discretise,
    energy,
    ring_mesh,
    run_case,
    touch_x,
)
from tests.fe.curves import trapezoid_work

#: The 2x refined run of the 2D mesh-convergence case (``benchmarks/bench_fe.py
#: --refined-reference``).
REFINED_2D = Path(__file__).resolve().parents[2] / "fe_data" / "2d_refined"


@pytest.mark.parametrize("nu", [0.3, 0.49])
def test_thin_ring_diametral_compression(nu):
    """Small diametral compression of a thin ring: delta = (pi/4 - 2/pi) F R^3 / (E' I).

    R is the mean radius (D - t)/2, E' = E/(1-nu^2) (plane strain), I = t^3/12 per unit length,
    F the force per unit length, delta the change of the outer diameter along the load line.
    t/R = 0.034; the linear regime is ensured by delta/D = 7e-4.
    """
    t, D = 0.5, 30.0
    spec = CaseSpec(
        "le",
        t,
        diameter_mm=D,
        nu=nu,
        closed_gap_mm=D - 0.02,
        solver=SolverSettings(dh_initial_mm=0.01),
    )
    res = run_case(spec)
    assert res.status == "complete"
    last = res.table.iloc[-1]
    m = spec.make_material()
    Ep = m.E / (1.0 - nu**2)
    R = 0.5 * (D - t)
    F = last["force_per_length_N_per_mm"]
    delta_theory = (np.pi / 4 - 2 / np.pi) * F * R**3 / (Ep * t**3 / 12.0)
    delta_fe = D - last["gap_mm"]
    assert delta_fe == pytest.approx(0.02, rel=1e-9)
    assert delta_fe == pytest.approx(delta_theory, rel=0.03)
    # measured agreement is 0.27 % (thick-ring correction ~ (t/R)^2); guard against drift
    assert abs(delta_fe / delta_theory - 1) < 0.01


def test_internal_force_is_energy_gradient_and_tangent_is_consistent():
    """f = dPi/du and K = df/du by central finite differences on a deformed state."""
    disc = discretise(15.0, 1.0, MeshSpec(n_layers=1, n_circ=8))
    mat = get_material("mr")
    rng = np.random.default_rng(0)
    u = 0.02 * rng.standard_normal(disc.ndof)
    f, K, minJ = assemble(disc, mat, u)
    assert minJ > 0
    h = 1e-6
    idx = rng.choice(disc.ndof, size=8, replace=False)
    for i in idx:
        e = np.zeros(disc.ndof)
        e[i] = h
        dE = (energy(disc, mat, u + e) - energy(disc, mat, u - e)) / (2 * h)
        assert dE == pytest.approx(f[i], rel=1e-5, abs=1e-9)
        fp = assemble(disc, mat, u + e, tangent=False)[0]
        fm = assemble(disc, mat, u - e, tangent=False)[0]
        df = (fp - fm) / (2 * h)
        col = K[:, i].toarray().ravel()
        assert np.abs(df - col).max() <= 1e-5 * np.abs(col).max()


def test_rigid_translation_is_stress_free():
    disc = discretise(15.0, 1.0, MeshSpec(n_layers=1, n_circ=8))
    u = np.zeros(disc.ndof)
    u[0::2] = 0.3
    u[1::2] = -0.2
    u[2 * disc.bubble_nodes] = u[2 * disc.bubble_nodes + 1] = 0.0  # bubble amplitudes
    f, _, _ = assemble(disc, get_material("le"), u)
    assert np.abs(f).max() < 1e-12


def test_mesh_convergence_default_vs_refined():
    """Default mesh (4 x 64, graded toward the fold corner) against its 2x refinement: <= 1 %
    in bending, <= 3 % in the crease band (gap 2 t .. 4 t) and after the walls meet.

    In the band the fold's inner surface creases; the crease is placed by energy (Maxwell's
    rule) and the graded mesh resolves the fold corner, so the crease lands within ~0.1 mm on
    the two meshes and its force step is small (``benchmarks/bench_fe.py --crease``, dense:
    t = 0.8 mm max 2.4 %).  t = 0.8 mm is the thinnest wall, where the band deviates most.
    The steps land exactly on the gaps: no interpolation error.

    The refined run (8 x 128, 110 s against 21 s for the default mesh) is read from
    ``fe_data/2d_refined``, written by ``python benchmarks/bench_fe.py --refined-reference``.
    Its sidecar's input hash and material constants show it is the refinement of the case run
    here; the inputs, not the code: the sidecar also holds the default mesh's forces of the
    same benchmark run, and this run must reproduce them where they do not depend on the
    crease path (bending, walls met, compaction: to 1e-6), so a change to the 2D model fails
    here until the reference is re-run.  Measured: bending +0.04 %, band -0.4..+1.4 %, walls
    met -0.3 %, compaction -0.2 %.
    """
    t = 0.8
    gaps = {"bending": 10.0}
    gaps |= {f"crease_{g}": float(g) for g in np.round(np.linspace(2 * t + 0.05, 4 * t, 6), 3)}
    gaps |= {"walls_met": 2 * t - 0.05, "compaction": max(2 * t - 0.2, 1.5)}
    solver = SolverSettings(land_on_gaps_mm=tuple(gaps.values()))
    wall = MeshSpec().for_wall(15.0 - t, t)
    spec = CaseSpec("mr", t, mesh=wall, closed_gap_mm=gaps["compaction"], solver=solver)
    ref = read_case(REFINED_2D / "mr_t0.80.json")
    assert input_mismatch(ref.meta, replace(spec, mesh=wall.refined(2))) is None
    assert ref.meta["material_constants"] == get_material("mr").constants()
    assert ref.meta["status"] == "complete"
    tables = {"default": run_case(spec).table, "refined": ref.table}
    forces = {}
    for name, tb in tables.items():
        forces[name] = {}
        for k, g in gaps.items():
            row = tb[np.isclose(tb["gap_mm"], g, rtol=0, atol=1e-9)]
            assert len(row) == 1, (name, k, g)
            forces[name][k] = float(row["force_N"].iloc[0])
    coarse, fine = forces.values()
    same_code = ref.meta["fe_info"]["default_mesh_force_N"]  # the benchmark's default-mesh run
    for k in ("bending", "walls_met", "compaction"):
        assert coarse[k] == pytest.approx(same_code[k], rel=1e-6), (k, "re-run the reference")
    rel = {k: abs(coarse[k] / fine[k] - 1) for k in gaps}
    assert rel["bending"] <= 0.01, rel
    assert rel["walls_met"] <= 0.03 and rel["compaction"] <= 0.03, rel
    assert max(v for k, v in rel.items() if k.startswith("crease")) <= 0.03, rel
    assert max(rel.values()) > 1e-3  # two meshes, not one run read twice


@pytest.mark.parametrize("t", [0.8, 1.0, 1.2, 1.4, 1.6, 1.8, 2.0])
def test_thick_walls_get_a_corner_element_no_flatter_than_the_aspect(t):
    """The thick-wall rule measured on the mesh itself: the element at the fold's inner corner
    (nodes (0, 0), (0, 1) along the inner wall and (1, 0) through it) is at least
    ``corner_aspect`` = 0.6 times as long as thick, the grading is lowered only where 8:1
    would make it flatter (t >= 1.5 mm: 8:1 gave 0.43 at t = 2.0 mm and missed the 3 % crease
    band criterion, 5.1 %; with the rule 1.8 %, ``benchmarks/bench_fe.py --crease``), and
    walls up to 1.4 mm keep the 8:1 mesh (their measured 2.4 / 1.4 %)."""
    R = 15.0
    spec = MeshSpec()
    pts = ring_mesh(R, t, spec).p  # node (i, j) at column i * (n_circ + 1) + j
    n = spec.n_circ + 1
    circ = np.linalg.norm(pts[:, 1] - pts[:, 0])
    radial = np.linalg.norm(pts[:, n] - pts[:, 0])
    g = spec.for_wall(R - t, t).grading
    assert circ / radial >= spec.corner_aspect * (1 - 2e-3)  # chord vs arc: 1e-5
    if t <= 1.4:
        assert g == spec.grading
    else:
        assert g < spec.grading and circ / radial == pytest.approx(0.6, rel=2e-3)
    uniform_circ = 0.5 * np.pi * (R - t) / spec.n_circ  # never coarser than uniform
    assert circ <= uniform_circ


def test_a_uniform_mesh_holds_the_smooth_fold_too_long():
    """The reason for the graded default: a uniform 4 x 64 mesh (0.35 mm at the fold corner)
    holds the smooth fold past the crease onset of the graded default (gap 4.85 mm), then
    creases late (4.54 mm) and hard, below the graded default and its refinement by > 3 % just
    after (t = 1.4 mm, gap 4.4 mm: 1.05 vs 1.11 N)."""
    t, gap = 1.4, 4.4
    solver = SolverSettings(land_on_gaps_mm=(gap,))
    f = []
    for mesh in (MeshSpec(grading=1.0, radial_grading=1.0), MeshSpec()):
        tb = run_case(CaseSpec("mr", t, mesh=mesh, closed_gap_mm=4.4, solver=solver)).table
        f.append(float(tb.loc[np.isclose(tb["gap_mm"], gap), "force_N"].iloc[0]))
    assert f[0] / f[1] - 1 < -0.03, f


def test_maxwell_crease_is_the_lower_energy_state():
    """With the crease placed by energy the band's force is never above the path that holds the
    smooth fold to its stability limit (the smooth fold is metastable there), and both paths
    agree before the crease band and after the walls meet (t = 1.4 mm, uniform 4 x 64: the
    creased state has less energy from gap 4.52-4.54 mm, the smooth fold snaps at 4.50 mm)."""
    t = 1.4
    gaps = (6.0, 4.52, 4.5, 3.2)
    mesh = MeshSpec(grading=1.0, radial_grading=1.0)
    f = {}
    for mx in (True, False):
        solver = SolverSettings(land_on_gaps_mm=gaps, maxwell_crease=mx)
        tb = run_case(CaseSpec("mr", t, mesh=mesh, closed_gap_mm=3.1, solver=solver)).table
        f[mx] = np.array(
            [float(tb.loc[np.isclose(tb["gap_mm"], g), "force_N"].iloc[0]) for g in gaps]
        )
    assert f[True][0] == pytest.approx(f[False][0], rel=1e-6)  # before the band: same path
    assert np.all(f[True][1:3] <= f[False][1:3] * (1 + 1e-6)), f  # never above
    assert f[True][2] < 0.98 * f[False][2], f  # 4.5 mm: creased by energy, smooth fold held
    assert f[True][3] == pytest.approx(f[False][3], rel=0.01)  # both creased


@pytest.mark.slow(seconds=7)
def test_one_layer_through_the_wall_is_too_coarse():
    """The default's 2 layers are needed: 1 layer misses the bending criterion (~6 % at t = 2)."""
    solver = SolverSettings(land_on_gaps_mm=(10.0,))
    f = []
    for mesh in (MeshSpec(n_layers=1), MeshSpec(n_layers=1).refined(2)):
        tb = run_case(CaseSpec("mr", 2.0, mesh=mesh, closed_gap_mm=10.0, solver=solver)).table
        f.append(float(tb["force_N"].iloc[-1]))
    assert abs(f[0] / f[1] - 1) > 0.01


def test_partial_case_is_kept_not_extrapolated():
    spec = CaseSpec("mr", 1.0, solver=SolverSettings(max_newton=1, dh_min_mm=0.01))
    res = run_case(spec)
    assert res.status == "partial"
    assert res.info["failures"] > 0
    assert res.info["last_gap_mm"] == pytest.approx(res.table["gap_mm"].iloc[-1])
    assert res.table["gap_mm"].iloc[-1] > spec.closed_gap_mm


@pytest.mark.parametrize(
    "kw,name",
    [
        ({"thickness_mm": 0.0}, "thickness_mm"),
        ({"thickness_mm": 15.0}, "thickness_mm"),
        ({"thickness_mm": 1.0, "force_cap_N": -1.0}, "force_cap_N"),
        ({"thickness_mm": 1.0, "closed_gap_mm": 40.0}, "closed_gap_mm"),
    ],
)
def test_bad_case_input_names_the_parameter(kw, name):
    with pytest.raises(ValueError, match=name):
        run_case(CaseSpec(material="mr", **kw))


def _force_at(table, gaps):
    out = []
    for g in gaps:
        row = table[np.isclose(table["gap_mm"], g, rtol=0, atol=1e-9)]
        assert len(row) == 1, g
        out.append(float(row["force_N"].iloc[0]))
    return np.array(out)


@pytest.fixture(scope="module")
def stick_vs_frictionless():
    """mr, t = 1.4 mm, both contact laws to the 200 N cap, landing on bending and wall gaps."""
    gaps = (20.0, 10.0, 5.0, 2.7, 2.65)
    out = {}
    for contact in ("frictionless", "stick"):
        spec = CaseSpec("mr", 1.4, contact=contact, solver=SolverSettings(land_on_gaps_mm=gaps))
        out[contact] = run_case(spec)
    return gaps, out


def test_touch_x_is_where_the_path_meets_the_moving_jaw():
    """Hand-solved: a node from (1, 9.5) to (2, 10.5) mm while the jaw face y = h moves from
    10 to 9.8 mm meets it where 9.5 + s = 10 - 0.2 s, s = 0.5 / 1.2, x = 1 + s.  A node on the
    jaw at the start (released there and back) keeps its end x; so does every node when the
    start height is unknown (the projection rule)."""

    class Disc:
        X = np.array([[1.0, 9.5], [3.0, 10.0]])

    u0 = np.zeros(4)
    u1 = np.array([1.0, 1.0, 0.5, 0.3])  # node 0 to (2, 10.5), node 1 to (3.5, 10.3)
    nodes = np.array([0, 1])
    x = touch_x(Disc, u0, u1, nodes, 10.0, 9.8)
    assert x[0] == pytest.approx(1.0 + 0.5 / 1.2, rel=1e-14)
    assert x[1] == 3.5
    assert np.array_equal(touch_x(Disc, u0, u1, nodes, np.nan, 9.8), [2.0, 3.5])


def test_stick_anchors_at_the_touch_point_make_the_2d_force_independent_of_the_step(monkeypatch):
    """A node entering stick contact is anchored where its path meets the jaw
    (:func:`touch_x`), not at its end position (the projection rule, the second formulation).
    Both converge as the jaw step shrinks (within 0.1 % at 0.01 mm steps); at 1 mm steps the
    touch rule stays within 0.15 % of that, the projection rule does not (coarse 2 x 32 mesh,
    mr t = 1.4 mm, bending to gap 6 mm: -0.6 to -1.1 %)."""
    from grasprom.fe import model2d

    gaps = (20.0, 10.0, 6.0)

    def force(dh):
        spec = CaseSpec("mr", 1.4, contact="stick", closed_gap_mm=6.0,
                        mesh=MeshSpec(n_layers=2, n_circ=32),
                        solver=SolverSettings(land_on_gaps_mm=gaps, dh_max_mm=dh))  # fmt: skip
        return _force_at(run_case(spec).table, gaps)

    touch_fine, touch_coarse = force(0.01), force(1.0)
    monkeypatch.setattr(
        model2d, "touch_x", lambda d, u0, u1, n, h0, h1: touch_x(d, u0, u1, n, np.nan, h1)
    )
    proj_fine, proj_coarse = force(0.01), force(1.0)
    assert proj_fine == pytest.approx(touch_fine, rel=1e-3)
    assert touch_coarse == pytest.approx(touch_fine, rel=1.5e-3)
    assert np.max(np.abs(proj_coarse / touch_fine - 1)) > 4e-3


@pytest.mark.slow(seconds=53)
@pytest.mark.xdist_group("stick_vs_frictionless_2d")  # one fixture run
def test_stick_contact_2d_against_the_independent_model(stick_vs_frictionless):
    """Stick (Guachi et al.'s no sliding) vs frictionless in 2D.

    References: in bending, a contact law hardly matters (no wall squeezes out yet), stick at
    most a few percent stiffer; once the walls meet the frictionless double wall squeezes out
    sideways and issue 18's independent 2D model measured the force 5-7x higher with the jaw
    nodes stuck and the 20 N point 0.05-0.09 mm earlier; in bending stick adds 1-6 %.
    Compared at gaps 2.7 and 2.65 mm, past the knee (at 2.75 mm, on it, the ratio is about 2
    and moves with the landing gaps: 0.01 mm there is a factor 5 in force).
    """
    gaps, res = stick_vs_frictionless
    fs = _force_at(res["stick"].table, gaps)
    ff = _force_at(res["frictionless"].table, gaps)
    rel = fs / ff - 1
    assert np.all(rel[:3] >= -1e-4) and np.all(rel[:3] < 0.06), rel  # bending: 1-6 % at most
    ratio = fs[3:] / ff[3:]  # walls met (gaps 2.7, 2.65 mm < 2 t)
    assert np.all((4.5 < ratio) & (ratio < 8.0)), ratio  # the reference's 5-7x

    def gap_at_20N(tb):
        return float(np.interp(20.0, tb["force_N"], tb["gap_mm"]))

    shift = gap_at_20N(res["stick"].table) - gap_at_20N(res["frictionless"].table)
    assert 0.03 < shift < 0.12, shift  # earlier = at a larger gap
    assert res["frictionless"].table["tangential_share"].max() == 0.0
    share = res["stick"].table["tangential_share"]
    assert 0.05 < share.iloc[-1] < 3.0 and share.max() > 0.1


def test_contact_law_is_validated():
    with pytest.raises(ValueError, match="contact"):
        run_case(CaseSpec("mr", 1.4, contact="glue"))


@pytest.mark.slow(seconds=53)
@pytest.mark.xdist_group("stick_vs_frictionless_2d")  # one fixture run
def test_both_contact_laws_complete(stick_vs_frictionless):
    _, res = stick_vs_frictionless
    assert res["stick"].status == res["frictionless"].status == "complete"


@pytest.fixture(scope="module")
def coulomb_runs():
    """mr, t = 1.4 mm, coarse 2 x 32 mesh, to gap 8 mm: frictionless, stick and Coulomb with a
    vanishing, a moderate and a large coefficient."""
    gaps = (20.0, 10.0, 8.0)
    mesh = MeshSpec(n_layers=2, n_circ=32)
    out = {}
    for contact, mu in (
        ("frictionless", 0.0),
        ("stick", 0.0),
        ("coulomb", 1e-6),
        ("coulomb", 0.2),
        ("coulomb", 5.0),
    ):
        spec = CaseSpec(
            "mr",
            1.4,
            contact=contact,
            friction=mu,
            closed_gap_mm=8.0,
            mesh=mesh,
            solver=SolverSettings(land_on_gaps_mm=gaps),
        )
        out[(contact, mu)] = run_case(spec)
    return gaps[1:], out


def test_coulomb_spans_frictionless_to_stick(coulomb_runs):
    """Coulomb friction between its limits: mu -> 0 is the frictionless solution (1e-4), a
    coefficient above the stick solution's largest tangential share (2.0 near first touch)
    sticks (within 1 %: the stick regularisation FRICTION_EPS_MM = 1 um lets the first
    contacts creep while their normal force is still tiny), and mu = 0.2 lies between the two
    at every gap."""
    gaps, res = coulomb_runs
    f = {k: _force_at(r.table, gaps) for k, r in res.items()}
    assert all(r.status == "complete" for r in res.values())
    np.testing.assert_allclose(f[("coulomb", 1e-6)], f[("frictionless", 0.0)], rtol=1e-4)
    np.testing.assert_allclose(f[("coulomb", 5.0)], f[("stick", 0.0)], rtol=0.01)
    lo, hi = f[("frictionless", 0.0)], f[("stick", 0.0)]
    assert np.all(lo * (1 - 1e-6) <= f[("coulomb", 0.2)]), (lo, f[("coulomb", 0.2)])
    assert np.all(f[("coulomb", 0.2)] <= hi * (1 + 1e-6)), (hi, f[("coulomb", 0.2)])
    assert np.all(hi > lo * 1.002)  # the limits differ, so "between" says something


def test_coulomb_friction_never_exceeds_mu_times_the_normal_force(coulomb_runs):
    """The jaw's tangential reaction is at most mu times its normal reaction (the Coulomb
    cone, summed over the contact), and with mu = 0.2 the contact slides: the share comes
    close to mu where the contact widens; stick needs up to 10x that share."""
    _, res = coulomb_runs
    share = res[("coulomb", 0.2)].table["tangential_share"]
    assert share.max() <= 0.2 * (1 + 1e-9)
    assert share.max() > 0.15
    assert res[("stick", 0.0)].table["tangential_share"].max() > 1.0
    assert res[("coulomb", 0.2)].info["mesh"]["n_circ"] == 32


@pytest.mark.parametrize(
    "kw,match",
    [
        ({"contact": "coulomb"}, "friction"),
        ({"contact": "coulomb", "friction": float("nan")}, "friction"),
        ({"contact": "stick", "friction": 0.3}, "only used with"),
    ],
)
def test_coulomb_needs_a_coefficient_and_only_coulomb_takes_one(kw, match):
    with pytest.raises(ValueError, match=match):
        run_case(CaseSpec("mr", 1.4, **kw))


def test_the_2d_model_refuses_predicted_contact():
    """``SolverSettings.predict_contact_below_mm`` is a 3D option: 2D names it, not ignores it."""
    spec = CaseSpec("mr", 1.4, solver=SolverSettings(predict_contact_below_mm=3.5))
    with pytest.raises(ValueError, match="predict_contact_below_mm=3.5: predicted contact is 3D"):
        run_case(spec)
    spec = CaseSpec("mr", 1.4, solver=SolverSettings(predict_contact_below_t=2.5))
    with pytest.raises(ValueError, match="predict_contact_below_t=2.5: predicted contact is 3D"):
        run_case(spec)


def test_strain_energy_column_equals_the_jaws_work_2d():
    """Work-energy balance in 2D (frictionless: nothing dissipates): strain_energy_mJ (the whole
    ring x jaw length) equals the integral of force_N over the gap closed.  The trapezoid rule
    over the steps is within 0.2 % of it (measured -0.20..+0.17 % to gap 6 mm; to gap 3 mm, the
    crease placed by energy, within 0.35 %); a wrong symmetry factor is off by 100 %."""
    r = run_case(CaseSpec("mr", 1.4, contact="frictionless", closed_gap_mm=6.0))
    work = trapezoid_work(r.table)
    e = r.table["strain_energy_mJ"].to_numpy()
    assert r.status == "complete" and e[0] == 0.0 and np.all(np.diff(e) > 0)
    np.testing.assert_allclose(e[1:], work[1:], rtol=3e-3)
