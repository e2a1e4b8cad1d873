"""The smooth branch's energy between steps (grasprom.fe.crease.hermite_energy), against an
analytic energy: a cubic Hermite through (h, E, F = -dE/dh) is exact for a cubic E(h)."""

import numpy as np
import pytest

from grasprom.fe.crease import (
    crease_onset,
    hermite_energy,
    is_snap,
    released_energy,
    unload_band,
)
from grasprom.fe.model2d import SolverSettings


def test_hermite_energy_is_exact_for_a_cubic_and_uses_dE_dh_equal_minus_F():
    def E(h):
        return 0.3 * (10 - h) ** 3 + 2.0 * (10 - h) ** 2 + 0.5 * (10 - h)

    def F(h):  # the jaw reaction, F = -dE/dh
        return 0.9 * (10 - h) ** 2 + 4.0 * (10 - h) + 0.5

    hs = [10.0, 9.0, 7.5, 7.2, 5.0]  # decreasing jaw heights (mm), uneven steps
    branch = [(h, E(h), F(h)) for h in hs]
    for h in np.linspace(5.0, 10.0, 23):
        assert hermite_energy(branch, h) == pytest.approx(E(h), rel=1e-12, abs=1e-12)
    # extrapolated past the last step from the last interval: still the cubic
    assert hermite_energy(branch, 4.5) == pytest.approx(E(4.5), rel=1e-12)
    # a wrong sign of F (dE/dh = +F) is caught
    flipped = [(h, e, -f) for h, e, f in branch]
    assert abs(hermite_energy(flipped, 8.0) - E(8.0)) > 0.1


def test_crease_onset_finds_the_energy_crossing_of_two_analytic_branches():
    """Smooth branch E_s(h) = (3 - h)^2, creased branch E_c(h) = 0.6 (3 - h)^2 + 0.2 (h - 1): the
    creased state is lower below h* = 2.2192 (E_s = E_c: 0.4 (3 - h)^2 = 0.2 (h - 1)), so from a
    snap at h = 1.5 the continuation must stop at h* (bisected to the back step / 2^10)."""

    def E_s(h):
        return (3.0 - h) ** 2

    def E_c(h):
        return 0.6 * (3.0 - h) ** 2 + 0.2 * (h - 1.0)

    h_star = 3.0 - (-0.2 + np.sqrt(0.04 + 4 * 0.4 * 0.4)) / (2 * 0.4)
    assert E_s(h_star) == pytest.approx(E_c(h_star))

    def solve(state, h):  # the creased branch is followed: the state is its jaw height
        return h, 2

    def below(state, h):
        return E_c(state) < E_s(h)

    dh = 0.05
    res = crease_onset(solve, below, 1.5, 1.5, dh, h_top=2.8, landing=(2.0,), n_bisect=10)
    out = res.states
    hs = [h for h, _, _ in out]
    assert hs == sorted(hs, reverse=True) and hs[-1] > 1.5
    assert 2.0 in hs  # landed on the requested jaw height
    assert hs[0] == pytest.approx(h_star, abs=dh / 2**10)
    assert hs[0] <= h_star
    # every solve is counted (2 iterations each): the accepted back steps, the rejected probe
    # past the crossing and the 10 bisections
    n_steps = len(out) - 1  # the last state is the bisected crossing
    assert res.newton_iterations == 2 * (n_steps + 1 + 10)
    # a drop that is no jump to a lower branch: nothing to place, the probe still counted
    none = crease_onset(solve, lambda s, h: False, 1.5, 1.5, dh, 2.8)
    assert none.states == [] and none.newton_iterations == 2


def test_a_snap_shows_as_released_energy_even_when_the_force_rises():
    """Along an analytic branch E(h) = a (H - h)^2 (F = 2 a (H - h), linear: the trapezoid rule
    is exact) a step releases nothing; a step that lands on a state lower by a part of the
    step's work is a snap whether the force rises or drops; a force drop alone is one too."""
    a, H = 0.7, 10.0

    def entry(h, de=0.0, df=0.0):
        return (h, a * (H - h) ** 2 + de, 2 * a * (H - h) + df)

    prev, cur = entry(4.0), entry(3.9)
    work = 0.5 * (prev[2] + cur[2]) * 0.1
    assert released_energy(prev, cur) == pytest.approx(0.0, abs=1e-12)
    assert not is_snap(prev, cur)
    lower = entry(3.9, de=-0.3 * work, df=+0.05)  # stiffer state, less energy: a snap
    assert released_energy(prev, lower) == pytest.approx(0.3 * work + 0.5 * 0.05 * 0.1, rel=1e-9)
    assert is_snap(prev, lower)
    assert not is_snap(prev, entry(3.9, de=-0.01 * work))  # trapezoid-size noise: no snap
    assert is_snap(prev, entry(3.9, df=-0.2 * cur[2] - prev[2] + cur[2]))  # force dropped
    assert not is_snap(entry(10.0), entry(10.0))  # no travel, no work


def test_crease_onset_halves_a_failing_back_step_and_stops_where_the_branch_ends():
    """The analytic branches above, with a solver that fails on back steps longer than 0.02
    from h = 2.0 on (a stiff stretch, as a creased fold near its onset), and a creased branch
    that may end at ``h_end`` (no solution above).  Without halvings the continuation stops at
    the first long step (h = 2.0), 0.29 below the energy crossing h*; with three it reaches h*
    (bisected to the step / 2^10), and where the branch ends below h* it stops within an
    eighth of the step of that end."""
    h_star = 3.0 - (-0.2 + np.sqrt(0.04 + 4 * 0.4 * 0.4)) / (2 * 0.4)

    def below(state, h):
        return 0.6 * (3.0 - state) ** 2 + 0.2 * (state - 1.0) < (3.0 - h) ** 2

    def solver(h_end):
        def solve(state, h):
            if h > h_end or (h > 2.0 + 1e-9 and h - state > 0.02 + 1e-12):
                raise ArithmeticError("no convergence")
            return h, 1

        return solve

    dh = 0.05
    plain = crease_onset(solver(9.0), below, 1.5, 1.5, dh, h_top=2.8)
    assert plain.states[0][0] == pytest.approx(2.0)
    halved = crease_onset(solver(9.0), below, 1.5, 1.5, dh, h_top=2.8, n_halve=3)
    assert halved.states[0][0] == pytest.approx(h_star, abs=dh / 2**10)
    ended = crease_onset(solver(2.1), below, 1.5, 1.5, dh, h_top=2.8, n_halve=3)
    assert 2.1 - dh / 8 <= ended.states[0][0] <= 2.1


def test_crease_onset_places_a_crossing_within_the_first_back_step_when_asked():
    """A snap at h = 2.20, 0.019 below the energy crossing h* = 2.2192 of the analytic branches
    above: the first back step (0.05) already lands above h*.  Without ``first_step`` nothing
    is placed; with it the crossing is bisected (to the step / 2^10); a snapped state that is
    not below the smooth branch still places nothing."""
    h_star = 3.0 - (-0.2 + np.sqrt(0.04 + 4 * 0.4 * 0.4)) / (2 * 0.4)

    def below(state, h):
        return 0.6 * (3.0 - state) ** 2 + 0.2 * (state - 1.0) < (3.0 - h) ** 2

    def solve(state, h):
        return h, 1

    dh = 0.05
    assert crease_onset(solve, below, 2.20, 2.20, dh, h_top=2.8).states == []
    placed = crease_onset(solve, below, 2.20, 2.20, dh, h_top=2.8, first_step=True)
    assert placed.states[0][0] == pytest.approx(h_star, abs=dh / 2**10)
    assert placed.states[0][0] <= h_star and len(placed.states) == 1
    above = crease_onset(solve, lambda s, h: s < h - 0.01, 2.20, 2.20, dh, 2.8, first_step=True)
    assert above.states == []


def test_after_a_halved_back_step_the_next_one_doubles_back_instead_of_retrying_the_full_step():
    """A creased branch that ends at h = 1.607 (no solution above), followed back from 1.5 in
    steps of 0.05 with three halvings (down to 0.00625), every state below the smooth branch.
    From 1.60 the steps 0.05, 0.025, 0.0125 fail and 0.00625 lands at 1.60625; the next try is
    0.0125 (twice the step that worked), then 0.00625, and the branch ends: five failed tries in
    all, where retrying the full step after the halved one (the rule before: 0.05, 0.025,
    0.0125, 0.00625 again) cost seven, for the same states."""
    tried = []

    def solve(state, h):
        tried.append(round(h, 6))
        if h > 1.607:
            raise ArithmeticError("beyond the end of the branch")
        return h, 1

    out = crease_onset(solve, lambda s, h: True, 1.5, 1.5, 0.05, h_top=2.8, n_halve=3)
    assert [round(h, 6) for h, _, _ in out.states] == [1.60625, 1.6, 1.55]
    assert tried == [1.55, 1.6, 1.65, 1.625, 1.6125, 1.60625, 1.61875, 1.6125]
    assert sum(h > 1.607 for h in tried) == 5


def _two_branches():
    """The analytic branches of the tests above as ``(h, energy, force)`` entries: the smooth
    fold E_s(h) = (3 - h)^2 and the creased state E_c(h) = 0.6 (3 - h)^2 + 0.2 (h - 1), lower
    below h* = 2.2192, where they cross (F = -dE/dh)."""
    h_star = 3.0 - (-0.2 + np.sqrt(0.04 + 4 * 0.4 * 0.4)) / (2 * 0.4)

    def smooth(h):
        return (h, (3.0 - h) ** 2, 2.0 * (3.0 - h))

    def creased(h):
        return (h, 0.6 * (3.0 - h) ** 2 + 0.2 * (h - 1.0), 1.2 * (3.0 - h) - 0.2)

    return h_star, smooth, creased


def test_unloading_keeps_a_lower_branch_the_loading_missed_up_to_its_energy_crossing():
    """Loading stayed on the smooth fold through the band (rows every 0.1 from h = 2.8 to 1.2);
    unloading from the creased state at h = 1.1 must replace every row below h* by the creased
    state (energies equal to E_c exactly), bisect h* to the last interval / 2^10, and stop
    there; a state that unloads along the loaded branch itself replaces nothing and climbs to
    the top of the band; one on a higher branch stops at the first height."""
    h_star, smooth, creased = _two_branches()
    rows_h = np.round(np.arange(2.8, 1.15, -0.1), 12)
    branch = [smooth(h) for h in rows_h]

    def solve(state, h):  # the state is (branch, h): unloading follows its branch
        return (state[0], h), 3

    def energy_of(state):
        return {"c": creased, "s": smooth, "up": lambda h: (h, smooth(h)[1] + 1.0, 0)}[state[0]](
            state[1]
        )[1]

    un = unload_band(solve, energy_of, branch, ("c", 1.1), 1.1, 2.8, 0.04, n_bisect=10)
    hs = [h for h, _, _ in un.states]
    assert hs[:-1] == [h for h in sorted(rows_h) if h < h_star]
    assert hs[-1] == pytest.approx(h_star, abs=0.1 / 2**10) and hs[-1] < h_star
    assert all(energy_of(s) == pytest.approx(creased(h)[1], rel=1e-14) for h, s, _ in un.states)
    assert un.top_mm == pytest.approx(2.3)  # stopped at the first loaded height above h*
    # back steps of at most 0.04 landing on every row: 1.1 -> 2.3 is 12 rows, 3 steps each
    # of 0.1 -> 0.04, 0.04, 0.02: 36 solves, 3 iterations each, plus the 10 bisections
    assert un.newton_iterations == 3 * (36 + 10)
    same = unload_band(solve, energy_of, branch, ("s", 1.1), 1.1, 2.8, 0.04)
    assert same.states == [] and same.top_mm == pytest.approx(2.8)
    up = unload_band(solve, energy_of, branch, ("up", 1.1), 1.1, 2.8, 0.04)
    assert up.states == [] and up.top_mm == pytest.approx(1.2)


def test_unloading_stops_where_its_branch_ends_and_keeps_what_it_found():
    """The creased branch ends at h = 1.75 (no solution above, as at a fold of the branch): the
    unloading keeps the rows below it, no crossing, and reports how far it got (within an
    eighth of the 0.04 step of the end with three halvings)."""
    h_star, smooth, creased = _two_branches()
    rows_h = np.round(np.arange(2.8, 1.15, -0.1), 12)
    branch = [smooth(h) for h in rows_h]

    def solve(state, h):
        if h > 1.75:
            raise ArithmeticError("no equilibrium")
        return h, 1

    un = unload_band(
        solve, lambda h: creased(h)[1], branch, 1.1, 1.1, 2.8, 0.04, n_halve=3, n_bisect=10
    )
    assert [h for h, _, _ in un.states] == pytest.approx([1.2, 1.3, 1.4, 1.5, 1.6, 1.7])
    assert 1.75 - 0.04 / 8 <= un.top_mm <= 1.75


@pytest.mark.parametrize("bad", (-1.0, float("nan")))
def test_unloading_threshold_must_be_a_force_at_least_zero(bad):
    assert SolverSettings(unload_from_N=float("inf")).unload_from_N == float("inf")  # end only
    with pytest.raises(ValueError, match="unload_from_N"):
        SolverSettings(unload_from_N=bad)
