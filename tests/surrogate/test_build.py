"""The reduction of FE force-gap curves to PCHIP node tables: snaps."""

import numpy as np

from grasprom.surrogate.build import BuildParams, reduce_case, snap_interior
from grasprom.surrogate.fedata import FECase


def test_snap_interior_flags_only_the_inside_of_multi_step_drops():
    gap = np.arange(8.0)
    # closing (gap falling) the force rises, drops over two steps (gaps 3 -> 1), rises again
    force = np.array([9.0, 4.0, 5.0, 6.0, 3.0, 2.0, 1.5, 1.0])
    np.testing.assert_array_equal(
        snap_interior(gap, force), [False, False, True, False, False, False, False, False]
    )
    one_step = np.array([9.0, 4.0, 5.0, 3.0, 2.5, 2.0, 1.5, 1.0])
    assert not snap_interior(gap, one_step).any()


def test_table_of_a_two_step_snap_has_no_negative_stiffness_at_its_nodes():
    """A smooth rising curve with a 15 % force drop spread over two FE steps (as the 3D le
    0.8 mm case at gap 1.84 mm): every node derivative dF/dgap <= 0 (stiffness >= 0), the snap's
    ends are nodes with zero slope, and away from the snap the table reproduces the curve."""
    gap = np.round(np.linspace(3.0, 1.5, 61), 6)  # steps of 0.025 mm
    force = 2.0 / (gap - 1.2)
    force = np.where(gap <= 1.80 + 1e-9, 0.85 * force, force)  # the creased branch
    mid = np.isclose(gap, 1.825)
    force[mid] = 2.95  # between 3.08 N (gap 1.85) and 2.83 N (gap 1.80): a two-step drop
    assert snap_interior(gap[::-1], force[::-1]).sum() == 1
    case = FECase("le_t0.80", "le", 0.8, gap, force, 30.0, 200.0, "", "complete")
    curve = reduce_case(case, BuildParams())
    d = np.array(curve.dforce_dgap_N_per_mm)
    assert (d <= 1e-12).all()
    g = np.array(curve.gap_mm)
    far = np.abs(gap - 1.83) > 0.1
    fit = np.interp(gap[far], g, np.array(curve.force_N))
    np.testing.assert_allclose(fit, force[far], rtol=0.05)
