r"""Hyperelastic materials for the plane-strain clamping model.

Every material is a strain energy density (MPa = mJ/mm^3) split in two parts,

.. math::

    W(\mathbf F) = W_{pt}(a, J) + U(\theta), \quad a = \mathbf F:\mathbf F,\ J = \det\mathbf F,

where ``F`` is the in-plane 2x2 deformation gradient of a plane-strain state (the out-of-plane
stretch is 1, so the 3D invariants are ``I1 = a + 1`` and ``I2 = a + J**2``).  ``W_pt`` is
evaluated at every quadrature point; the volumetric part ``U`` is evaluated on the dilatation
``theta``, the element-wise L2 projection of ``J`` on the discontinuous pressure space of the FE
model (three-field Hu-Washizu with pressure and dilatation condensed per element, Simo-Taylor-
Pister 1985), which removes volumetric locking of the nearly incompressible solids.  For a
homogeneous deformation ``theta == J`` and ``W`` is the plain strain energy.

Materials (Guachi et al. (2020) for the constants):

* ``mr`` -- Mooney-Rivlin, C10 = 0.085 MPa, C01 = 0.0565 MPa (Guachi et al. 2020, after Mayeur et
  al. 2016),
  decoupled: ``C10 (J^-2/3 I1 - 3) + C01 (J^-4/3 I2 - 3) + U(J)``.
* ``nh`` -- neo-Hookean with the same small-strain shear modulus mu = 2 (C10 + C01) = 0.283 MPa.
* ``le`` -- Guachi et al.'s "linear elastic" E = 5.18 MPa, given a large-strain form that stays
  stable in strong compression and reduces to Hooke's law at small strain: the compressible
  neo-Hookean ``mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2`` with the Lame constants of (E, nu).
  St Venant-Kirchhoff is *not* used: it softens and loses stability in compression.

Nearly incompressible: the seeds give no bulk modulus for the tissue.  We use nu = 0.49
(kappa / mu = 49.7) for all three: soft tissue is water-saturated and usually modelled with
nu = 0.45-0.499 (Idkaidek and Jasiuk (2015) use 0.48; the liver validation study (2018) uses 0.4
for liver), and 0.49 keeps the tube's
volume change below ~1 % while the per-element mean dilatation keeps the solid free of locking.
The volumetric function for mr/nh is ``U = kappa/4 (theta^2 - 1 - 2 ln theta)`` (convex, infinite
at theta -> 0, ``kappa/2 (theta-1)^2`` at small strain).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MATERIAL_NAMES = ("mr", "nh", "le")

MATERIAL_LABELS = {"mr": "Mooney-Rivlin", "nh": "neo-Hookean", "le": "linear elastic"}
"""Long name of each material key (figure legends and titles)."""


def material_label(key: str) -> str:
    """``"mr (Mooney-Rivlin)"``: the key with its long name, for figures."""
    return f"{key} ({MATERIAL_LABELS[key]})" if key in MATERIAL_LABELS else key


#: Guachi et al. (2020) constants
C10_SEED_MPA = 0.085
C01_SEED_MPA = 0.0565
E_LE_SEED_MPA = 5.18
NU_DEFAULT = 0.49


def _bulk_from_shear(mu: float, nu: float) -> float:
    """Bulk modulus (MPa) from the small-strain shear modulus (MPa) and Poisson ratio."""
    return 2.0 * mu * (1.0 + nu) / (3.0 * (1.0 - 2.0 * nu))


@dataclass(frozen=True)
class MooneyRivlin:
    """Decoupled, nearly incompressible Mooney-Rivlin solid.

    Parameters
    ----------
    C10, C01 : float
        Mooney-Rivlin constants (MPa).
    nu : float
        Small-strain Poisson ratio, sets the bulk modulus ``kappa`` (MPa).
    """

    C10: float = C10_SEED_MPA
    C01: float = C01_SEED_MPA
    nu: float = NU_DEFAULT
    name: str = "mr"

    def __post_init__(self):
        _check_positive(self.C10 + self.C01, "C10 + C01")
        _check_nu(self.nu)

    @property
    def mu(self) -> float:
        """Small-strain shear modulus mu = 2 (C10 + C01) (MPa)."""
        return 2.0 * (self.C10 + self.C01)

    @property
    def kappa(self) -> float:
        """Small-strain bulk modulus (MPa)."""
        return _bulk_from_shear(self.mu, self.nu)

    @property
    def youngs_modulus(self) -> float:
        """Small-strain Young's modulus E = 2 mu (1 + nu) (MPa)."""
        return 2.0 * self.mu * (1.0 + self.nu)

    def pointwise(self, a, J):
        """Pointwise energy and its derivatives in (a, J).

        Returns ``(W, W_a, W_J, W_aa, W_aJ, W_JJ)`` (MPa), arrays shaped like ``a``.
        """
        c10, c01 = self.C10, self.C01
        j23 = J ** (-2.0 / 3.0)
        j43 = j23 * j23
        W = c10 * (j23 * (a + 1.0) - 3.0) + c01 * (J * J * j43 + a * j43 - 3.0)
        W_a = c10 * j23 + c01 * j43
        W_J = c10 * (-2.0 / 3.0) * j23 / J * (a + 1.0) + c01 * (
            (2.0 / 3.0) * J * j43 - (4.0 / 3.0) * a * j43 / J
        )
        W_aa = np.zeros_like(a)
        W_aJ = c10 * (-2.0 / 3.0) * j23 / J + c01 * (-4.0 / 3.0) * j43 / J
        W_JJ = c10 * (10.0 / 9.0) * j23 / (J * J) * (a + 1.0) + c01 * (
            (-2.0 / 9.0) * j43 + (28.0 / 9.0) * a * j43 / (J * J)
        )
        return W, W_a, W_J, W_aa, W_aJ, W_JJ

    def volumetric(self, theta):
        """Volumetric energy ``U = kappa/4 (theta^2 - 1 - 2 ln theta)`` and U', U'' (MPa)."""
        k = self.kappa
        U = 0.25 * k * (theta * theta - 1.0 - 2.0 * np.log(theta))
        dU = 0.5 * k * (theta - 1.0 / theta)
        ddU = 0.5 * k * (1.0 + 1.0 / (theta * theta))
        return U, dU, ddU

    def constants(self) -> dict:
        """JSON-ready constants with units."""
        return {
            "model": "Mooney-Rivlin (decoupled, nearly incompressible)",
            "C10_MPa": self.C10,
            "C01_MPa": self.C01,
            "nu": self.nu,
            "mu_MPa": self.mu,
            "kappa_MPa": self.kappa,
            "E_small_strain_MPa": self.youngs_modulus,
        }


def NeoHookean(mu: float = 2.0 * (C10_SEED_MPA + C01_SEED_MPA), nu: float = NU_DEFAULT):
    """Decoupled neo-Hookean solid, ``mu/2 (J^-2/3 I1 - 3) + U(J)``.

    A Mooney-Rivlin solid with ``C10 = mu/2, C01 = 0``; the default ``mu`` (MPa) is the
    small-strain shear modulus of Guachi et al.'s Mooney-Rivlin constants.
    """
    return MooneyRivlin(C10=0.5 * mu, C01=0.0, nu=nu, name="nh")


@dataclass(frozen=True)
class CompressibleNeoHookean:
    """Large-strain form of Guachi et al.'s linear elastic material.

    ``W = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln theta)^2`` with the Lame constants of
    (E, nu): exactly Hooke's law at small strain, polyconvex-like and stable in compression.

    Parameters
    ----------
    E : float
        Young's modulus (MPa), Guachi et al. (2020): 5.18.
    nu : float
        Poisson ratio.
    """

    E: float = E_LE_SEED_MPA
    nu: float = NU_DEFAULT
    name: str = "le"

    def __post_init__(self):
        _check_positive(self.E, "E")
        _check_nu(self.nu)

    @property
    def mu(self) -> float:
        """Shear modulus (MPa)."""
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def lam(self) -> float:
        """First Lame constant (MPa)."""
        return self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))

    @property
    def kappa(self) -> float:
        """Bulk modulus (MPa)."""
        return self.lam + 2.0 * self.mu / 3.0

    @property
    def youngs_modulus(self) -> float:
        """Small-strain Young's modulus (MPa)."""
        return self.E

    def pointwise(self, a, J):
        """Pointwise energy and derivatives in (a, J); see :meth:`MooneyRivlin.pointwise`."""
        mu = self.mu
        W = 0.5 * mu * (a - 2.0) - mu * np.log(J)
        zero = np.zeros_like(a)
        return W, 0.5 * mu + zero, -mu / J, zero, zero, mu / (J * J)

    def volumetric(self, theta):
        """``U = lambda/2 (ln theta)^2`` and U', U'' (MPa)."""
        lam = self.lam
        lt = np.log(theta)
        return 0.5 * lam * lt * lt, lam * lt / theta, lam * (1.0 - lt) / (theta * theta)

    def constants(self) -> dict:
        """JSON-ready constants with units."""
        return {
            "model": "compressible neo-Hookean matched to Hooke (E, nu) at small strain",
            "E_MPa": self.E,
            "nu": self.nu,
            "mu_MPa": self.mu,
            "lambda_MPa": self.lam,
            "kappa_MPa": self.kappa,
            "E_small_strain_MPa": self.E,
        }


Material = MooneyRivlin | CompressibleNeoHookean


def get_material(name: str, **overrides) -> Material:
    """Material by short name (``mr``, ``nh``, ``le``) with the defaults of Guachi et al. (2020).

    Parameters
    ----------
    name : str
        One of :data:`MATERIAL_NAMES`.
    **overrides
        Constructor arguments, e.g. ``nu=0.3`` or ``E=1.0`` (MPa).
    """
    key = str(name).strip().lower()
    if key == "mr":
        return MooneyRivlin(**overrides)
    if key == "nh":
        return NeoHookean(**overrides)
    if key == "le":
        return CompressibleNeoHookean(**overrides)
    raise ValueError(f"unknown material {name!r}; valid: {', '.join(MATERIAL_NAMES)}")


# ----------------------------------------------------------------------------------------------
# stress and tangent from the (a, J) energy derivatives, vectorised over leading axes
# ----------------------------------------------------------------------------------------------


def cofactor(F):
    """Cofactor ``J F^-T`` of 2x2 matrices ``F[..., 2, 2]`` (linear in F)."""
    C = np.empty_like(F)
    C[..., 0, 0] = F[..., 1, 1]
    C[..., 0, 1] = -F[..., 1, 0]
    C[..., 1, 0] = -F[..., 0, 1]
    C[..., 1, 1] = F[..., 0, 0]
    return C


#: d cof(F)_ij / d F_kl, constant in 2D
H_COF = np.zeros((2, 2, 2, 2))
H_COF[0, 0, 1, 1] = 1.0
H_COF[0, 1, 1, 0] = -1.0
H_COF[1, 0, 0, 1] = -1.0
H_COF[1, 1, 0, 0] = 1.0

_I4 = np.einsum("ik,jl->ijkl", np.eye(2), np.eye(2))


def first_piola(material: Material, F, theta=None):
    """First Piola-Kirchhoff stress (MPa) of 2x2 plane-strain gradients ``F[..., 2, 2]``.

    ``theta`` is the dilatation fed to the volumetric part (defaults to ``det F``).
    """
    a = np.einsum("...ij,...ij->...", F, F)
    cof = cofactor(F)
    J = F[..., 0, 0] * F[..., 1, 1] - F[..., 0, 1] * F[..., 1, 0]
    _, W_a, W_J, *_ = material.pointwise(a, J)
    if theta is None:
        theta = J
    _, dU, _ = material.volumetric(theta)
    return 2.0 * W_a[..., None, None] * F + (W_J + dU)[..., None, None] * cof


def tangent(material: Material, F):
    """Material tangent ``dP_ij/dF_kl`` (MPa) for a homogeneous state (theta = det F)."""
    a = np.einsum("...ij,...ij->...", F, F)
    cof = cofactor(F)
    J = F[..., 0, 0] * F[..., 1, 1] - F[..., 0, 1] * F[..., 1, 0]
    _, W_a, W_J, W_aa, W_aJ, W_JJ = material.pointwise(a, J)
    _, dU, ddU = material.volumetric(J)
    return pointwise_tangent(F, cof, W_a, W_J + dU, W_aa, W_aJ, W_JJ + ddU)


def pointwise_tangent(F, cof, W_a, W_J, W_aa, W_aJ, W_JJ):
    """``dP/dF`` for ``P = 2 W_a F + W_J cof`` given the energy derivatives (MPa)."""
    e = "...ij,...kl->...ijkl"
    A = 2.0 * W_a[..., None, None, None, None] * _I4
    A = A + 4.0 * W_aa[..., None, None, None, None] * np.einsum(e, F, F)
    FC = np.einsum(e, F, cof) + np.einsum(e, cof, F)
    A = A + 2.0 * W_aJ[..., None, None, None, None] * FC
    A = A + W_JJ[..., None, None, None, None] * np.einsum(e, cof, cof)
    A = A + W_J[..., None, None, None, None] * H_COF
    return A


def cauchy_stress_plane_strain(material: Material, F):
    """In-plane Cauchy stress ``sigma = P F^T / J`` (MPa) for homogeneous plane strain."""
    P = first_piola(material, F)
    J = F[..., 0, 0] * F[..., 1, 1] - F[..., 0, 1] * F[..., 1, 0]
    return np.einsum("...ij,...kj->...ik", P, F) / J[..., None, None]


def _check_positive(value: float, name: str) -> None:
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"material constant {name} must be > 0 (MPa), got {value!r}")


def _check_nu(nu: float) -> None:
    if not (-1.0 < nu < 0.5):
        raise ValueError(f"Poisson ratio nu must be in (-1, 0.5), got {nu!r}")
