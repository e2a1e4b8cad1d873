"""The main job's modules on their own (no build): the public API, the hand profile, the
handle's integration and the result objects of an empty build."""

from __future__ import annotations

import math
from pathlib import Path

import pytest


def test_public_api_resolves():
    import grasprom.pipeline as p

    assert [n for n in p.__all__ if not hasattr(p, n)] == []
    assert p.STAGES == ("surrogate", "tune", "fmu", "arduino", "cosim", "report")
    from grasprom.pipeline.stages import STAGE_FUNCS

    assert tuple(STAGE_FUNCS) == p.STAGES


def test_hand_force_profile():
    from grasprom.pipeline import hand_force_N

    assert hand_force_N(0.0, 1.0, 2.0, 0.5, 3.0) == 0.0
    assert hand_force_N(0.5, 1.0, 2.0, 0.5, 3.0) == pytest.approx(1.5)
    assert hand_force_N(2.0, 1.0, 2.0, 0.5, 3.0) == 3.0
    assert hand_force_N(3.25, 1.0, 2.0, 0.5, 3.0) == pytest.approx(1.5)
    assert hand_force_N(4.0, 1.0, 2.0, 0.5, 3.0) == 0.0


def test_handle_stops_at_the_closed_end():
    from grasprom.pipeline.cosim import Handle

    h = Handle(0.05, math.radians(1.0), math.radians(22.0), 1e-4, 1e-3)
    theta, omega, f = h.advance(math.radians(2.0), 0.0, 0.0, lambda t, th, om: 50.0, 0.0, 1e-3, 100)
    assert theta == h.theta_closed_rad and omega == 0.0 and f == 50.0


def test_minimum_jerk_profile():
    from grasprom.control.trajectory import minimum_jerk

    assert minimum_jerk(-1.0) == (0.0, 0.0) and minimum_jerk(2.0) == (1.0, 0.0)
    assert minimum_jerk(0.5) == (0.5, 1.875)  # 10/8 - 15/16 + 6/32; slope 30/16
    h = 1e-6  # slope = derivative of the profile (central difference)
    for s in (0.1, 0.3, 0.77):
        d = (minimum_jerk(s + h)[0] - minimum_jerk(s - h)[0]) / (2 * h)
        assert minimum_jerk(s)[1] == pytest.approx(d, rel=1e-6)


def test_operator_grip_is_a_spring_damper_behind_the_intended_path():
    from grasprom.pipeline.cosim import OperatorGrip

    g = OperatorGrip(2.0, 0.1, 0.05, 0.4, 0.1, ramp_s=1.0, hold_s=1.0, release_s=0.5)
    assert g.intent(0.0) == (0.4, 0.0)
    assert g.intent(1.5) == (pytest.approx(0.1), 0.0)
    assert g.intent(3.0)[0] == pytest.approx(0.4)
    th, om = g.intent(0.5)
    assert th == pytest.approx(0.25) and om == pytest.approx(-0.3 * 1.875)
    # at the hold, 0.05 rad ahead of the intent: F L3 = k (theta - theta*) = 2 * 0.05
    assert g(1.5, 0.15, 0.0) == pytest.approx(2.0 * 0.05 / 0.05)
    assert g(1.5, 0.1, -1.0) == pytest.approx(-0.1 / 0.05)  # damping opposes the motion


def test_empty_build_result():
    from grasprom.pipeline import BuildResult, results, summary

    res = BuildResult(out_dir=Path("out"))
    assert results(res) == {}
    assert summary(res).startswith("grasprom build: 0.0 s -> out")


def test_grasp_settling_measures_the_overshoot():
    import numpy as np

    from grasprom.pipeline import CosimResult, grasp_settling
    from grasprom.pipeline.cosim import COLUMNS, grasp_profile

    ramp, hold, release, rest = grasp_profile(True)
    t = np.arange(1, int((ramp + hold + release + rest) / 1e-3) + 1) * 1e-3
    settled = 3.0
    f = np.where(t < ramp, settled * t / ramp, settled)
    f = f + np.where(t >= ramp, 0.6 * np.exp(-(t - ramp) / 0.05) * np.cos(60 * (t - ramp)), 0.0)
    data = np.zeros((t.size, len(COLUMNS)))
    data[:, COLUMNS.index("time_s")] = t
    data[:, COLUMNS.index("force_handle_N")] = f
    st = grasp_settling(CosimResult(data, COLUMNS, 0.0, 0.0), True)
    assert st["settled_N"] == pytest.approx(settled, rel=1e-3)
    assert st["overshoot"] == pytest.approx(0.2, abs=0.01)
    assert not st["meets_target"]
