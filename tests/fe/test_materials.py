"""Material point checks: stresses against closed-form Cauchy stresses, tangent against FD."""

import numpy as np
import pytest

from grasprom.fe.materials import (
    MATERIAL_NAMES,
    CompressibleNeoHookean,
    MooneyRivlin,
    cauchy_stress_plane_strain,
    first_piola,
    get_material,
    tangent,
)

STRETCHES = [
    (1.3, 1.0 / 1.3),  # isochoric plane-strain stretch
    (1.3, 0.8),  # with volume change
    (0.6, 1.5),
    (0.5, 1.0 / 0.5),  # strong compression (clamping)
    (1.0, 0.97),
]


def _cauchy_mr_closed_form(m: MooneyRivlin, l1: float, l2: float) -> np.ndarray:
    """3D textbook form: sigma = 2/J dev[(W1 + I1b W2) Bb - W2 Bb^2] + U'(J) I (principal)."""
    lam = np.array([l1, l2, 1.0])
    J = lam.prod()
    bb = J ** (-2.0 / 3.0) * lam**2  # principal values of the isochoric left Cauchy-Green
    i1b = bb.sum()
    s = (m.C10 + i1b * m.C01) * bb - m.C01 * bb**2
    dev = s - s.mean()
    dU = 0.5 * m.kappa * (J - 1.0 / J)
    return 2.0 / J * dev[:2] + dU


def _cauchy_cnh_closed_form(m: CompressibleNeoHookean, l1: float, l2: float) -> np.ndarray:
    """sigma = mu/J (B - I) + lambda ln J / J I (principal, in-plane)."""
    lam = np.array([l1, l2])
    J = l1 * l2
    return m.mu / J * (lam**2 - 1.0) + m.lam * np.log(J) / J


@pytest.mark.parametrize("l1,l2", STRETCHES)
@pytest.mark.parametrize("name", MATERIAL_NAMES)
def test_cauchy_stress_matches_closed_form(name, l1, l2):
    m = get_material(name)
    F = np.diag([l1, l2])
    sigma = cauchy_stress_plane_strain(m, F)
    if isinstance(m, MooneyRivlin):
        ref = _cauchy_mr_closed_form(m, l1, l2)
    else:
        ref = _cauchy_cnh_closed_form(m, l1, l2)
    scale = np.abs(ref).max()
    assert np.abs(np.diag(sigma) - ref).max() <= 1e-6 * scale
    assert abs(sigma[0, 1]) <= 1e-12 * scale


@pytest.mark.parametrize("name", MATERIAL_NAMES)
def test_rotated_stretch_is_objective(name):
    """sigma(Q F) = Q sigma(F) Q^T with the closed-form principal stresses."""
    m = get_material(name)
    c, s = np.cos(0.7), np.sin(0.7)
    Q = np.array([[c, -s], [s, c]])
    F = Q @ np.diag([1.2, 0.7])
    sig = cauchy_stress_plane_strain(m, F)
    sig0 = cauchy_stress_plane_strain(m, np.diag([1.2, 0.7]))
    assert np.allclose(sig, Q @ sig0 @ Q.T, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("name", MATERIAL_NAMES)
def test_small_strain_hooke(name):
    """At small strain every material is Hooke's law in plane strain (E, nu)."""
    m = get_material(name)
    E, nu = m.youngs_modulus, m.nu
    eps = 1e-7
    sigma = cauchy_stress_plane_strain(m, np.diag([1.0 + eps, 1.0]))
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))
    assert sigma[0, 0] / eps == pytest.approx(lam + 2 * mu, rel=1e-5)
    assert sigma[1, 1] / eps == pytest.approx(lam, rel=1e-5)


def test_mooney_rivlin_equals_neo_hookean_in_incompressible_plane_strain():
    """I2 = I1 when J = 1 in plane strain: MR == NH with mu = 2 (C10 + C01) (deviatoric part)."""
    mr = get_material("mr")
    nh = get_material("nh")
    for l1 in (0.5, 0.8, 1.4):
        F = np.diag([l1, 1.0 / l1])
        d = cauchy_stress_plane_strain(mr, F) - cauchy_stress_plane_strain(nh, F)
        assert abs(d[0, 0] - d[1, 1]) <= 1e-12
    assert mr.mu == pytest.approx(2 * (0.085 + 0.0565))


@pytest.mark.parametrize("name", MATERIAL_NAMES)
def test_piola_is_energy_gradient_and_tangent_matches_fd(name):
    m = get_material(name)
    rng = np.random.default_rng(3)
    F = np.array([[0.7, 0.2], [-0.1, 1.3]]) + 0.05 * rng.standard_normal((2, 2))

    def W(G):
        a = np.array((G * G).sum())
        J = np.array(np.linalg.det(G))
        return float(m.pointwise(a, J)[0] + m.volumetric(J)[0])

    h = 1e-6
    P = first_piola(m, F)
    A = tangent(m, F)
    for k in range(2):
        for m_ in range(2):
            E = np.zeros((2, 2))
            E[k, m_] = h
            assert (W(F + E) - W(F - E)) / (2 * h) == pytest.approx(P[k, m_], rel=1e-6, abs=1e-9)
            dP = (first_piola(m, F + E) - first_piola(m, F - E)) / (2 * h)
            assert np.allclose(dP, A[:, :, k, m_], rtol=1e-6, atol=1e-8)


def test_bad_material_input():
    with pytest.raises(ValueError, match="unknown material 'xx'"):
        get_material("xx")
    with pytest.raises(ValueError, match="Poisson"):
        get_material("le", nu=0.5)
    with pytest.raises(ValueError, match="E"):
        get_material("le", E=-1.0)
