"""The clipped tuner checks every slope its field renders, the return spring's included.

Independent references: the return spring's handle stiffness from central differences of
:func:`grasprom.chain.kinematics.spring_handle_force_N` (not the chain's analytic derivative
the controller code uses), the closed form ``b > 3 K T / 2`` of the sampled-data condition with
one sample of delay and no virtual damping, and finite differences of the controller's static
map (:meth:`ImpedanceController.step` at rest).
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from grasprom.chain import kinematics as kin
from grasprom.control import ControllerParams, ImpedanceController, stiffness
from grasprom.control.device import DeviceParams
from grasprom.control.passivity import required_damping
from grasprom.control.tuning import tune
from grasprom.surrogate import Surrogate

ROOT = Path(__file__).resolve().parents[2]
T = 1e-3
LOW_B = 1e-5  # N m s/rad: a device far too lightly damped for the return spring
KW = dict(materials=["le"], thicknesses=[2.0], verify=False, n_theta=45)


@pytest.fixture(scope="module")
def sur() -> Surrogate:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return Surrogate.build(ROOT / "fe_data" / "2d")


def _spring_slope_fd(chain: kin.ChainParams) -> tuple[float, float]:
    """Largest handle stiffness of the return spring alone (N m/rad at the pivot) and where
    (deg), from central differences of the spring's handle force (h = 1e-4 deg)."""
    lo, hi = kin.theta_range_deg(chain)
    h = 1e-4
    th = np.linspace(lo + h, hi - h, 2201)
    f = lambda x: np.asarray(kin.spring_handle_force_N(x, chain), dtype=float)  # noqa: E731
    K = -(f(th + h) - f(th - h)) / (2 * math.radians(h)) * chain.L3_mm * 1e-3
    i = int(np.argmax(K))
    return float(K[i]), float(th[i])


def test_spring_reference_numbers():
    """The spring alone: 0.245 N m/rad at the closed end, which needs b = 3 K T/2 = 3.7e-4."""
    k_s, th = _spring_slope_fd(ControllerParams().chain_params)
    assert k_s == pytest.approx(0.245, abs=1e-3)
    assert th < 0.01  # at the closed end
    assert 1.5 * k_s * T == pytest.approx(3.7e-4, rel=0.01)
    assert required_damping(k_s, 0.0, T, None, 1) == pytest.approx(1.5 * k_s * T, rel=1e-4)
    assert 1.5 * k_s * T > 30 * LOW_B


def test_low_damping_device_is_refused_for_the_clipped_rendering(sur):
    """Before: K_lim = 0.0062, 'passive everywhere', margin 1.26, although the field renders the
    spring alone at 0.245 N m/rad.  Now an error, as the coupling tuner gives."""
    dev = DeviceParams(damping_Nms_per_rad=LOW_B)
    with pytest.raises(ValueError, match="no stiffness limit is passive") as exc:
        tune(sur, ControllerParams(), dev, **KW)
    msg = str(exc.value)
    assert "return spring alone" in msg and "render_spring" in msg
    k_s, _th = _spring_slope_fd(ControllerParams().chain_params)
    got = float(msg.split("with its slope ")[1].split(" N m/rad")[0])
    assert got == pytest.approx(k_s, rel=2e-3)  # 3 significant digits in the message
    need = float(msg.split("needs b >= ")[1].split(" N m s/rad")[0])
    assert need == pytest.approx(1.25 * 1.5 * k_s * T, rel=0.05)  # B is tiny on this device
    assert ControllerParams().rendering == "clipped"  # the default path is the one checked
    with pytest.raises(ValueError, match="no coupling stiffness is passive"):
        tune(sur, ControllerParams(rendering="coupling"), dev, **KW)


def test_the_field_at_that_limit_renders_the_spring_and_is_flagged(sur):
    """At the limit the old tuner chose (0.0062 N m/rad, below the spring's own stiffness) the
    field renders the spring alone; its stiffness report and extremes say so."""
    p = ControllerParams(material="le", thickness_mm=2.0, stiffness_limit_Nm_per_rad=0.0062,
                         encoder_counts_per_rev=0)  # fmt: skip
    k_s, _th = _spring_slope_fd(p.chain_params)
    e = stiffness.field_stiffness_extremes(sur, p)
    assert e.spring_alone
    assert e.K_max_Nm_per_rad == pytest.approx(k_s, rel=1e-3)
    assert e.theta_max_deg < 0.05
    op = stiffness.rendered_stiffness(sur, p, [0.3, 10.0, 21.0])
    # the static map of the controller: the spring, 40x the limit
    L3 = p.chain_params.L3_mm * 1e-3
    h = 1e-5

    def torque(t: float) -> float:
        c = ImpedanceController(p, sur)
        c.reset(t)
        return c.step(t).force_handle_N * L3

    for th, K in zip((0.3, 10.0, 21.0), op.K_Nm_per_rad):
        t = math.radians(th)
        assert K == pytest.approx(-(torque(t + h) - torque(t - h)) / (2 * h), rel=1e-6)
        assert K > 15 * p.stiffness_limit_Nm_per_rad
    # a passivity check on these slopes fails for the low-damping device
    assert required_damping(e.K_max_Nm_per_rad, 0.0, T, 200.0, 1) > 10 * LOW_B


def test_enough_damping_for_the_spring_passes_and_every_slope_meets_the_margin(sur):
    """b = 3e-4: the limit (0.18) is below the spring's closed-end stiffness, but the tissue
    lifts the field above the spring there; every slope the field renders meets the margin."""
    dev = DeviceParams(damping_Nms_per_rad=3e-4)
    r = tune(sur, ControllerParams(), dev, **KW)
    p, sm = r.params, r.summary
    assert p.stiffness_limit_Nm_per_rad < _spring_slope_fd(p.chain_params)[0]
    e = stiffness.field_stiffness_extremes(sur, p)
    assert not e.spring_alone
    req = required_damping(np.array([e.K_max_Nm_per_rad, e.K_min_Nm_per_rad]),
                           p.damping_Nms_per_rad, T, p.velocity_cutoff_Hz, 1)  # fmt: skip
    assert np.max(req) * sm["safety_factor"] <= dev.damping_Nms_per_rad
    assert sm["passive_everywhere"] and sm["passivity_margin"] >= sm["safety_factor"]


def test_the_chain_curvature_lowers_a_limit_at_the_margin(sur):
    """Inside a node interval the field's slope exceeds K_lim by the chain's curvature
    (6.2021 for K_lim = 6.2 at the closed end).  A device whose passive stiffness with the
    margin is 6.201 N m/rad: 6.2 would break the margin, the tuner lowers it to 6.1."""
    e = stiffness.field_stiffness_extremes(sur, ControllerParams(material="le", thickness_mm=2.0))
    assert 6.2 < e.K_max_Nm_per_rad < 6.2 * (1 + 1e-3)
    r0 = tune(sur, ControllerParams(), **KW)
    k_pass0 = r0.summary["passive_stiffness_with_margin_Nm_per_rad"]
    assert r0.params.stiffness_limit_Nm_per_rad == pytest.approx(6.2)
    # the passive stiffness is proportional to b (B scales along): aim at 6.201
    dev = DeviceParams(damping_Nms_per_rad=0.01 * 6.201 / k_pass0)
    r = tune(sur, ControllerParams(), dev, **KW)
    assert r.summary["passive_stiffness_with_margin_Nm_per_rad"] == pytest.approx(6.201, rel=1e-4)
    assert r.params.stiffness_limit_Nm_per_rad == pytest.approx(6.1)
    assert r.summary["passivity_margin"] >= r.summary["safety_factor"]
