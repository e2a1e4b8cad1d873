"""The crease band of the shipped 3D sweep against one mesh refinement (issue 18: the force in
the band 2t..4t should converge within 3 % between the default mesh and one refinement).

Reference: ``fe_data/band_4x48``, the same cases on 4 x 48 (the quarter circumference a third
finer than the shipped 4 x 36; every other input the sweep's), run independently of the shipped
sweep (sidecars: ``fe_info.reference`` says how): le 1.0 and mr 1.6 mm with their own band
selection on 4 x 48, mr 1.4 mm the own run of ``python benchmarks/bench_fe3d.py band``. Reads
files only.

What holds and what does not (measured, 400 gaps over the band, force log-interpolated along
each run): above the band (gap 4t to 20 mm) the two meshes agree within 0.5 %; over the band
the mean difference is 0.9-1.1 %, but pointwise 1-10 % of the band is beyond 3 % (max 3.6 % on
mr 1.4, 5.9 % on le 1.0 mm at the walls' knee, 2t, where 6.6 um of gap is 5.9 % of the force;
5.6 % on mr 1.6 mm in the crease onset window 5.0-5.4 mm, where one mesh's lower state is
creased and the other's not yet). The bounds below are those figures with a margin, so that a
change that moves the shipped band away from the refinement fails here.
"""

from pathlib import Path

import numpy as np
import pytest

from grasprom.fe.datafiles import read_case
from tests.fe.curves import log_force_at

ROOT = Path(__file__).resolve().parents[2]
REFERENCE = ROOT / "fe_data" / "band_4x48"

#: stem: (mean over the band, share of the band beyond 3 %, max over the band), measured
MEASURED = {
    "le_t1.00": (0.0107, 0.042, 0.0589),
    "mr_t1.40": (0.0110, 0.010, 0.0362),
    "mr_t1.60": (0.0090, 0.100, 0.0562),
}


def _log_force(table, gaps: np.ndarray) -> np.ndarray:
    """Force (N) of a case table at ``gaps`` (mm) (:func:`tests.fe.curves.log_force_at`)."""
    return log_force_at(table["gap_mm"].to_numpy(), table["force_N"].to_numpy(), gaps)


@pytest.mark.parametrize("stem", sorted(MEASURED))
def test_the_shipped_band_against_a_finer_mesh(stem):
    ref = read_case(REFERENCE / f"{stem}.json")
    ship = read_case(ROOT / "fe_data" / "default" / f"{stem}.json")
    t = ship.meta["thickness_mm"]
    spec_r, spec_s = ref.meta["spec"], ship.meta["spec"]
    assert spec_r["mesh"]["n_circ"] == 48 and spec_s["mesh"]["n_circ"] == 36
    for key in ("n_layers", "grading", "n_jaw", "n_free"):  # one refinement: n_circ alone
        assert spec_r["mesh"][key] == spec_s["mesh"][key], key
    for key in ("material", "thickness_mm", "tube_length_mm", "ends", "contact"):
        assert ref.meta[key] == ship.meta[key], key
    above = np.array([4 * t, 5.0, 6.0, 8.0, 10.0, 15.0, 20.0])
    above = above[above >= 4 * t]
    d_above = np.abs(_log_force(ref.table, above) / _log_force(ship.table, above) - 1)
    assert d_above.max() < 0.006, (stem, d_above)
    band = np.linspace(max(2 * t, ref.table["gap_mm"].min()), 4 * t, 400)
    d = np.abs(_log_force(ref.table, band) / _log_force(ship.table, band) - 1)
    mean, beyond, worst = MEASURED[stem]
    assert d.mean() == pytest.approx(mean, abs=2e-4), stem
    assert (d > 0.03).mean() == pytest.approx(beyond, abs=3e-3), stem
    assert d.max() == pytest.approx(worst, abs=2e-4), stem
    assert d.mean() < 0.015 and (d > 0.03).mean() <= 0.10  # the state of the criterion


def test_the_selection_brought_the_band_closer_to_the_finer_mesh():
    """Without the band selection (the own rows, given back from ``fe_info.band_selection``)
    mr 1.4 mm is 2.2 % from 4 x 48 on average and 42 % of its band is beyond 3 %."""
    stem, t = "mr_t1.40", 1.4
    ship = read_case(ROOT / "fe_data" / "default" / f"{stem}.json")
    own = ship.table.copy()
    for c in ship.meta["fe_info"]["band_selection"]["choices"]:
        own.loc[np.abs(own["gap_mm"] - c["gap_mm"]) < 1e-9, "force_N"] = c["own_force_N"]
    ref = read_case(REFERENCE / f"{stem}.json").table
    band = np.linspace(2 * t, 4 * t, 400)
    d_own = np.abs(_log_force(ref, band) / _log_force(own, band) - 1)
    d_sel = np.abs(_log_force(ref, band) / _log_force(ship.table, band) - 1)
    assert d_own.mean() == pytest.approx(0.0223, abs=3e-4)
    assert (d_own > 0.03).mean() == pytest.approx(0.42, abs=0.01)
    assert d_sel.mean() < 0.5 * d_own.mean()
