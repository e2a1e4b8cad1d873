"""Physics sanity of the shipped 2D sweep in fe_data/2d (no FE is re-run here)."""

from pathlib import Path

import numpy as np
import pytest

from grasprom.fe.datafiles import load_sweep, read_case
from grasprom.fe.grid import parse_thickness
from tests.fe.curves import curve, force_at

SWEEP = Path(__file__).resolve().parents[2] / "fe_data" / "2d"
THICKNESSES = parse_thickness("0.8:2.0:0.1")
MATERIALS = ("mr", "nh", "le")


@pytest.fixture(scope="module")
def sweep():
    return load_sweep(SWEEP)


def test_grid_is_complete_and_every_case_covers_the_haptic_range(sweep):
    for m in MATERIALS:
        for t in THICKNESSES:
            meta = read_case(SWEEP / f"{m}_t{t:.2f}.json").meta
            assert meta["status"] == "complete", (m, t)
            g, f = curve(sweep, m, t)
            # reaches the closed height or the force cap, and passes 50 N (haptic range)
            assert g.min() <= 1.5 + 1e-9 or f.max() >= 200.0
            assert f.max() >= 50.0 or g.min() <= 1.5 + 1e-9


def test_force_is_monotone_in_closing(sweep):
    for m in MATERIALS:
        for t in THICKNESSES:
            g, f = curve(sweep, m, t)
            assert np.all(np.diff(g) < 0)
            assert np.all(np.diff(f) >= -1e-9 * max(1.0, f.max())), (m, t)


def test_force_increases_with_thickness_at_every_gap(sweep):
    for m in MATERIALS:
        for t0, t1 in zip(THICKNESSES[:-1], THICKNESSES[1:]):
            g0, _ = curve(sweep, m, t0)
            g1, _ = curve(sweep, m, t1)
            lo = max(g0.min(), g1.min())
            for gap in np.linspace(lo, 25.0, 60):
                assert force_at(sweep, m, t1, gap) > force_at(sweep, m, t0, gap), (m, t0, gap)


def test_linear_elastic_is_stiffer_than_mooney_rivlin(sweep):
    """Guachi et al. (2020): LE (E = 5.18 MPa) is stiffer than MR (small-strain E = 0.84 MPa)."""
    for t in THICKNESSES:
        g, _ = curve(sweep, "le", t)
        for gap in np.linspace(g.min(), 25.0, 30):
            assert force_at(sweep, "le", t, gap) > 2.0 * force_at(sweep, "mr", t, gap)


def test_bending_plateau_then_steep_rise_at_walls_meeting(sweep):
    """Low force while the wall bends (gap > 2 t), steep rise once the walls meet (gap < 2 t)."""
    for m in ("mr", "nh"):
        for t in THICKNESSES:
            bend = force_at(sweep, m, t, 2 * t + 1.0)
            assert bend < 2.5  # N, bending regime with the default 10 mm jaw length
            g, _ = curve(sweep, m, t)
            gap_c = max(2 * t - 0.1, g.min())
            # stiffness (N/mm) after the walls meet vs. in the bending regime
            k_bend = (bend - force_at(sweep, m, t, 2 * t + 2.0)) / 1.0
            k_comp = (force_at(sweep, m, t, gap_c) - force_at(sweep, m, t, 2 * t)) / (2 * t - gap_c)
            assert k_comp > 50 * k_bend, (m, t, k_bend, k_comp)


def test_mooney_rivlin_equals_neo_hookean_in_plane_strain(sweep):
    """I2 = I1 for incompressible plane strain: MR and NH (same mu) give the same curves up
    to the compressibility effect (nu = 0.49): within 5 % wherever the force exceeds 0.05 N."""
    for t in THICKNESSES:
        g, _ = curve(sweep, "mr", t)
        gn, _ = curve(sweep, "nh", t)
        for gap in np.linspace(max(g.min(), gn.min()), 25.0, 40):
            fm = force_at(sweep, "mr", t, gap)
            fn = force_at(sweep, "nh", t, gap)
            if max(fm, fn) > 0.05:
                assert fm == pytest.approx(fn, rel=0.05), (t, gap)


def test_sidecars_record_provenance(sweep):
    meta = read_case(SWEEP / "mr_t1.40.json").meta
    for key in (
        "material",
        "thickness_mm",
        "diameter_mm",
        "jaw_length_mm",
        "closed_gap_mm",
        "status",
        "material_constants",
        "input_hash",
        "wall_time_s",
    ):
        assert key in meta, key
    assert meta["material_constants"]["C10_MPa"] == 0.085
