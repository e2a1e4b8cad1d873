"""Tabulated force surrogate F(gap, thickness, material) built from an FE sweep.

The surrogate stores, per material, one reduced force-gap curve per swept wall thickness and
interpolates between them.

Along the gap
    Monotone piecewise cubic Hermite interpolation (PCHIP, the derivatives of
    :class:`scipy.interpolate.PchipInterpolator`) through a subset of the FE load steps chosen
    adaptively (:func:`select_nodes`). Force never wiggles or turns negative, the stiffness is
    continuous. Evaluation uses precomputed Hermite coefficients, vectorised with numpy
    (:meth:`Surrogate.force`) or in pure Python floats (:meth:`Surrogate.force_scalar`).
Along the thickness (scheme ``"aligned"``, the default)
    The steep rise where the inner walls meet sits at the wall-contact gap ``g_c(t)``
    (about 2 t). Both neighbouring thickness curves are evaluated at the same *aligned*
    coordinate ``u = (gap - g_c(t)) / (D - g_c(t))`` (0 at wall contact, 1 at first touch
    ``gap = D``) and blended linearly in t; ``g_c(t)`` is interpolated linearly in t.
    Scheme ``"naive"`` blends the two curves at equal gap (the baseline of the error figures).
Outside the table
    * ``gap >= D`` (the outer diameter, first touch): 0 N, stiffness 0.
    * ``gap`` below the last FE gap of a curve (closed height or force cap reached): linear
      continuation with the curve's stiffness at its last node (force and stiffness stay
      continuous, force keeps rising, never negative); such points are flagged out of range
      (``return_flag=True`` or :meth:`Surrogate.in_range`).
    * thickness outside the swept range: :class:`ValueError` (see :func:`clamp_thickness` for
      the clamp + flag used by exported controllers).

Sign convention: ``stiffness = -dF/dgap`` in N/mm, positive when closing the jaws (gap
decreasing) raises the force.

Units: gaps and thicknesses in mm, forces in N, stiffness in N/mm.

Layout
    :mod:`~grasprom.surrogate.fedata` reads the FE sweep (:func:`read_fe_cases`, :func:`fe_hash`);
    :mod:`~grasprom.surrogate.build` reduces each FE curve to PCHIP nodes (:class:`BuildParams`,
    :func:`reduce_case`); :mod:`~grasprom.surrogate.spline` evaluates the tables
    (:class:`SplineTable`); :mod:`~grasprom.surrogate.table` is the :class:`Surrogate` itself
    (build, evaluate, check, save/load) with :func:`load_surrogate`;
    :mod:`~grasprom.surrogate.fileformat` is its JSON file; :mod:`~grasprom.surrogate.validation`
    the error figures; :mod:`~grasprom.surrogate.plots` the figures.
"""

from __future__ import annotations

from grasprom.surrogate.build import (
    CONTACT_GAP_METHODS,
    SCHEMES,
    BuildParams,
    Curve,
    contact_gap,
    pchip_derivatives,
    reduce_case,
    select_nodes,
)
from grasprom.surrogate.fedata import FECase, FEDataError, fe_dir_hash, fe_hash, read_fe_cases
from grasprom.surrogate.fileformat import (
    FORMAT_NAME,
    FORMAT_VERSION,
    SurrogateFileError,
    SurrogateWriteError,
    check_content,
)
from grasprom.surrogate.plots import plot_residuals, plot_surrogate, surrogate_residuals
from grasprom.surrogate.spline import SplineTable
from grasprom.surrogate.table import Surrogate, clamp_thickness, load_surrogate
from grasprom.surrogate.validation import (
    CHECK_TOLERANCE,
    case_errors,
    check_passed,
    check_verdict,
    error_figures,
    fe_point_stiffness,
    format_check,
    format_errors,
    invert_gap,
    leave_one_out,
)

__all__ = [
    "CHECK_TOLERANCE",
    "CONTACT_GAP_METHODS",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "SCHEMES",
    "BuildParams",
    "Curve",
    "FECase",
    "FEDataError",
    "SplineTable",
    "Surrogate",
    "SurrogateFileError",
    "SurrogateWriteError",
    "case_errors",
    "check_content",
    "check_passed",
    "check_verdict",
    "clamp_thickness",
    "contact_gap",
    "error_figures",
    "fe_dir_hash",
    "fe_hash",
    "fe_point_stiffness",
    "format_check",
    "format_errors",
    "invert_gap",
    "leave_one_out",
    "load_surrogate",
    "pchip_derivatives",
    "plot_residuals",
    "plot_surrogate",
    "read_fe_cases",
    "reduce_case",
    "select_nodes",
    "surrogate_residuals",
]
