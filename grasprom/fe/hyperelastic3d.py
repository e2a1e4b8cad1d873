r"""3D strain energies of the clamping materials (``mr``, ``nh``, ``le``), vectorised.

The material objects of :mod:`grasprom.fe.materials` carry the constants and the volumetric
function ``U(theta)``; their ``pointwise`` methods are written for a 2x2 plane-strain gradient.
This module evaluates the same energies for a full 3x3 deformation gradient ``F``:

.. math::

    W(\mathbf F) = W_{pt}(I_1, I_2, J) + U(\theta), \quad I_1 = \mathbf F:\mathbf F,
    \quad I_2 = \tfrac12 (I_1^2 - \mathbf C:\mathbf C), \quad J = \det \mathbf F

* Mooney-Rivlin / neo-Hookean: ``W_pt = C10 (J^-2/3 I1 - 3) + C01 (J^-4/3 I2 - 3)``;
* ``le`` (compressible neo-Hookean): ``W_pt = mu/2 (I1 - 3) - mu ln J``, ``U = lambda/2 ln^2``.

For a plane-strain ``F`` (``F33 = 1``) these reduce exactly to the 2D energies (``I1 = a + 1``,
``I2 = a + J^2``), which the tests check.  ``theta`` is the element-wise projection of ``J``
(three-field mean dilatation, see :mod:`grasprom.fe.model3d`).  Stresses in MPa.
"""

from __future__ import annotations

import numpy as np

from grasprom.fe.materials import CompressibleNeoHookean, Material, MooneyRivlin


def cofactor3(F: np.ndarray) -> np.ndarray:
    """Cofactor ``J F^-T`` of 3x3 matrices ``F[..., 3, 3]``."""
    H = np.empty_like(F)
    H[..., 0, 0] = F[..., 1, 1] * F[..., 2, 2] - F[..., 1, 2] * F[..., 2, 1]
    H[..., 0, 1] = F[..., 1, 2] * F[..., 2, 0] - F[..., 1, 0] * F[..., 2, 2]
    H[..., 0, 2] = F[..., 1, 0] * F[..., 2, 1] - F[..., 1, 1] * F[..., 2, 0]
    H[..., 1, 0] = F[..., 0, 2] * F[..., 2, 1] - F[..., 0, 1] * F[..., 2, 2]
    H[..., 1, 1] = F[..., 0, 0] * F[..., 2, 2] - F[..., 0, 2] * F[..., 2, 0]
    H[..., 1, 2] = F[..., 0, 1] * F[..., 2, 0] - F[..., 0, 0] * F[..., 2, 1]
    H[..., 2, 0] = F[..., 0, 1] * F[..., 1, 2] - F[..., 0, 2] * F[..., 1, 1]
    H[..., 2, 1] = F[..., 0, 2] * F[..., 1, 0] - F[..., 0, 0] * F[..., 1, 2]
    H[..., 2, 2] = F[..., 0, 0] * F[..., 1, 1] - F[..., 0, 1] * F[..., 1, 0]
    return H


def invariants(F: np.ndarray):
    """``(I1, I2, J, H, C)`` of 3x3 gradients ``F[..., 3, 3]``; ``H`` is the cofactor."""
    C = np.einsum("...ki,...kj->...ij", F, F)
    I1 = np.einsum("...ii->...", C)
    I2 = 0.5 * (I1 * I1 - np.einsum("...ij,...ij->...", C, C))
    H = cofactor3(F)
    J = np.einsum("...ij,...ij->...", F, H) / 3.0
    return I1, I2, J, H, C


def pointwise3d(material: Material, I1, I2, J):
    """Pointwise energy (MPa) and its derivatives in ``(I1, I2, J)``.

    Returns
    -------
    tuple
        ``(W, (W_1, W_2, W_J), (W_11, W_12, W_1J, W_22, W_2J, W_JJ))``, arrays like ``I1``.
    """
    zero = np.zeros_like(I1)
    if isinstance(material, MooneyRivlin):
        c10, c01 = material.C10, material.C01
        j23 = J ** (-2.0 / 3.0)
        j43 = j23 * j23
        W = c10 * (j23 * I1 - 3.0) + c01 * (j43 * I2 - 3.0)
        W_1 = c10 * j23
        W_2 = c01 * j43
        W_J = (-2.0 / 3.0) * c10 * j23 * I1 / J + (-4.0 / 3.0) * c01 * j43 * I2 / J
        W_1J = (-2.0 / 3.0) * c10 * j23 / J
        W_2J = (-4.0 / 3.0) * c01 * j43 / J
        W_JJ = ((10.0 / 9.0) * c10 * j23 * I1 + (28.0 / 9.0) * c01 * j43 * I2) / (J * J)
        return W, (W_1, W_2, W_J), (zero, zero, W_1J, zero, W_2J, W_JJ)
    if isinstance(material, CompressibleNeoHookean):
        mu = material.mu
        W = 0.5 * mu * (I1 - 3.0) - mu * np.log(J)
        return W, (0.5 * mu + zero, zero, -mu / J), (zero, zero, zero, zero, zero, mu / (J * J))
    raise TypeError(f"no 3D energy for material {type(material).__name__}")


def stress_and_tangent(
    material: Material, F: np.ndarray, p: np.ndarray, tangent: bool = True, k_pt=None
):
    """First Piola stress ``P`` and ``dP/dF`` (MPa) of the pointwise part plus ``p cof F``.

    Parameters
    ----------
    material : Material
        ``mr``, ``nh`` or ``le`` material object.
    F : ndarray (..., 3, 3)
        Deformation gradient.
    p : ndarray (...)
        Pressure (MPa) of the volumetric part, ``U'(theta)`` projected; it enters as
        ``p d(det F)/dF`` in ``P`` and ``p d^2(det F)/dF^2`` in the tangent.
    tangent : bool
        Also return ``A[..., i, j, k, l] = dP_ij/dF_kl``; else ``None``.
    k_pt : ndarray (...), optional
        Extra pointwise volumetric stiffness (MPa): adds ``k_pt cof F (x) cof F`` to ``A``
        (the second derivative of a pointwise volumetric energy whose first is in ``p``).

    Returns
    -------
    P, A, J, H
        Stress, tangent, ``det F`` and the cofactor of ``F``.
    """
    I1, I2, J, H, C = invariants(F)
    _, (W_1, W_2, W_J), second = pointwise3d(material, I1, I2, J)
    FC = np.einsum("...ik,...kj->...ij", F, C)
    G1 = 2.0 * F
    G2 = 2.0 * (I1[..., None, None] * F - FC)
    WJt = W_J + p
    P = W_1[..., None, None] * G1 + W_2[..., None, None] * G2 + WJt[..., None, None] * H
    if not tangent:
        return P, None, J, H
    if k_pt is not None:
        second = (*second[:5], second[5] + k_pt)
    W_11, W_12, W_1J, W_22, W_2J, W_JJ = second
    # A as a 9 x 9 matrix A[(i j), (k l)]: the isotropic part, the Kronecker and "swap"
    # parts of d G2 / dF and d H / dF, and the rank-one parts sum_mn c_mn M_m (x) M_n over
    # M = (G1, G2, H) (d G1 / dF = 2 I4 is in the isotropic part; 4 W_2 F (x) F = W_2 G1 (x) G1)
    B = np.matmul(F, F.swapaxes(-1, -2))
    shape = F.shape[:-2]
    A = np.zeros((*shape, 9, 9))
    A[..., np.arange(9), np.arange(9)] = (2.0 * W_1 + 2.0 * W_2 * I1)[..., None]
    w2 = (-2.0 * W_2)[..., None, None]
    wh = (-WJt / J)[..., None, None]
    A4 = A.reshape(*shape, 3, 3, 3, 3)
    wC, wB = w2 * C, w2 * B
    for i in range(3):  # slice adds: 2x faster than broadcasting against the identity
        A4[..., i, :, i, :] += wC  # delta_ik C_jl
        A4[..., :, i, :, i] += wB  # B_ik delta_jl
    X = (w2 * F)[..., :, :, None, None] * F[..., None, None, :, :]  # X[i, l, k, j] = F_il F_kj
    X += (wh * H)[..., :, :, None, None] * H[..., None, None, :, :]  # + H_il H_kj
    A4 += np.moveaxis(X, (-3, -1), (-1, -3))  # as [i, j, k, l]
    M = np.stack([G1, G2, H], axis=-3).reshape(*shape, 3, 9)
    c = np.empty((*shape, 3, 3))
    c[..., 0, 0] = W_11 + W_2
    c[..., 1, 1] = W_22
    c[..., 2, 2] = W_JJ + WJt / J
    c[..., 0, 1] = c[..., 1, 0] = W_12
    c[..., 0, 2] = c[..., 2, 0] = W_1J
    c[..., 1, 2] = c[..., 2, 1] = W_2J
    A += np.matmul(M.swapaxes(-1, -2), np.matmul(c, M))
    return P, A4, J, H


def strain_energy3d(material: Material, F: np.ndarray, theta: np.ndarray | None = None):
    """Energy density ``W_pt(F) + U(theta)`` (MPa); ``theta`` defaults to ``det F``."""
    I1, I2, J, _, _ = invariants(F)
    W = pointwise3d(material, I1, I2, J)[0]
    return W + material.volumetric(J if theta is None else theta)[0]
