"""The 3D variant of a sweep grid: ``grasprom sweep --model 3d`` (issue 18).

:func:`to_3d` turns the validated 2D grid of :func:`grasprom.fe.grid.build_grid` (thickness x
material, tube and jaw options) into :class:`~grasprom.fe.model3d.CaseSpec3D` cases with the 3D
options: contact law, tube length and end condition.  The keys every case sidecar records about
the model are :func:`grasprom.fe.datafiles.model_keys`.  Lengths in mm.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any

from grasprom.fe.grid import SweepInputError

__all__ = [
    "CONTACT_LAWS",
    "DEFAULT_MESH_PRESET",
    "ENDS",
    "MESH_PRESETS",
    "MIN_CIRC_3D",
    "MODELS",
    "MeshPreset",
    "Model3DOptions",
    "check_options",
    "to_2d",
    "to_3d",
]

MODELS = ("2d", "3d")
"""FE models of a sweep (``--model``)."""

CONTACT_LAWS = ("stick", "frictionless", "coulomb")
"""Contact laws of ``--contact`` (``coulomb`` needs ``--friction``)."""

ENDS = ("seed", "free")
"""End conditions of the 3D tube (``--ends``)."""

MIN_CIRC_3D = 6
"""Fewest divisions along the quarter circumference a 3D case accepts (a guard: coarser meshes
are not tested against the contact, and one graded element would span over 20 degrees)."""


@dataclasses.dataclass(frozen=True)
class MeshPreset:
    """A named 3D mesh of ``grasprom sweep --model 3d --mesh NAME``.

    Parameters
    ----------
    mesh : mapping
        :class:`~grasprom.fe.mesh3d.MeshSpec3D` fields that differ from its defaults (the
        mesh options given on the command line override them one by one).
    predict_contact_below_t : float or None
        ``SolverSettings.predict_contact_below_t`` (jaw gap in wall thicknesses) unless
        ``--predict-contact-below`` is given; None: off.
    band_companion : int
        ``SolverSettings.band_companion`` unless ``--band-companion`` is given (0: off). It
        belongs to the preset's mesh: a mesh option that overrides the preset (even at the
        preset's value), Coulomb contact (whose states strain energy does not rank) or a case
        that cannot have it (a tube too short for a far zone) turns it off; the other options
        (``--predict-contact-below``, tube, jaw, contact law otherwise) keep it.
    """

    mesh: Mapping[str, float]
    predict_contact_below_t: float | None
    band_companion: int = 0


MESH_PRESETS: Mapping[str, MeshPreset] = MappingProxyType(
    {
        "converged": MeshPreset(
            MappingProxyType({"n_layers": 4, "n_circ": 36, "grading": 8.0, "n_free": 6}),
            2.5,
            band_companion=2,
        ),
        "coarse": MeshPreset(
            MappingProxyType({}),
            None,
        ),
        "zoned": MeshPreset(
            MappingProxyType(
                {"n_layers": 4, "n_circ": 36, "grading": 8.0, "n_free": 6, "far_coarsening": 2}
            ),
            2.5,
        ),
    }
)
"""The named 3D meshes of ``--mesh``: ``converged`` (4 x 36 graded 8:1, 6 axial divisions beyond
the jaw, contact predicted below gap 2.5 t, the crease band selected with a companion on the
2 x 18 far zone: the mesh and settings of the shipped ``fe_data/default``),
``coarse`` (the :class:`~grasprom.fe.mesh3d.MeshSpec3D` defaults, 2 x 12: ``fe_data/3d_2x12``,
converged in bending only) and ``zoned`` (``converged`` over the jaw and its 2 mm margin, 2 x 18
beyond: ``far_coarsening`` 2, 56 % of the unknowns and 30 % of the sweep's worker time);
docs/fe-sweeps.md, docs/fe-model.md."""

DEFAULT_MESH_PRESET = "converged"
"""The ``--mesh`` of ``grasprom sweep --model 3d`` when none is given: the shipped data's."""


@dataclasses.dataclass(frozen=True)
class Model3DOptions:
    """The 3D options of a sweep; None takes the :class:`CaseSpec3D` default.

    Parameters
    ----------
    contact : str or None
        ``stick`` (no sliding once in contact, Guachi et al.'s assumption), ``frictionless`` or
        ``coulomb`` (with ``friction``).
    friction : float or None
        Coulomb coefficient (-), required with ``coulomb`` and only used there.
    tube_length_mm : float or None
        Length of the modelled tube (mm).
    ends : str or None
        ``seed`` (in-plane translations held at the free edges) or ``free``.
    n_jaw, n_free : int or None
        Axial mesh divisions over the jaw (and its fine margin) and beyond it
        (:class:`~grasprom.fe.mesh3d.MeshSpec3D`).
    predict_contact_below_t : float or None
        Predicted contact (experimental) below this jaw gap, in wall thicknesses
        (``SolverSettings.predict_contact_below_t``: the gap is this times each case's
        thickness, and the cases share one setting), so one value fits a thickness sweep (the
        converged 4 x 36 mesh needs it where the inner walls close onto each other: 2.5 = gap
        3.5 mm at t = 1.4 mm).
    mesh : str or None
        A name of :data:`MESH_PRESETS` (None: :data:`DEFAULT_MESH_PRESET`); the mesh options
        given override it one by one.
    far_coarsening : int or None
        Cross-section coarsening beyond the fine zone over the jaw
        (:class:`~grasprom.fe.mesh3d.MeshSpec3D` ``far_coarsening``; 1 = one cross-section).
    band_companion : int or None
        ``SolverSettings.band_companion``: the ``far_coarsening`` of a companion run whose
        crease-band states replace the case's where they hold less strain energy
        (:mod:`grasprom.fe.bandselect`); 0: off; None: the preset's
        (:attr:`MeshPreset.band_companion`: 2 with ``converged`` unless a mesh option
        overrides it or the contact is Coulomb).
    """

    contact: str | None = None
    friction: float | None = None
    tube_length_mm: float | None = None
    ends: str | None = None
    n_jaw: int | None = None
    n_free: int | None = None
    predict_contact_below_t: float | None = None
    mesh: str | None = None
    far_coarsening: int | None = None
    band_companion: int | None = None

    def given_3d_only(self) -> list[str]:
        """The CLI names of the options given that only the 3D model takes."""
        flags = (
            ("--tube-length", self.tube_length_mm),
            ("--ends", self.ends),
            ("--n-jaw", self.n_jaw),
            ("--n-free", self.n_free),
            ("--predict-contact-below", self.predict_contact_below_t),
            ("--mesh", self.mesh),
            ("--far-coarsening", self.far_coarsening),
            ("--band-companion", self.band_companion),
        )
        return [name for name, v in flags if v is not None]


def check_options(model: str, opts: Model3DOptions) -> None:
    """Validate ``--model`` and the 3D options; errors name the option and the value
    (the 3D-only ones are refused with ``--model 2d``).

    Raises
    ------
    SweepInputError
    """
    if model not in MODELS:
        raise SweepInputError(f"--model: {model!r} unknown; valid: {', '.join(MODELS)}")
    if opts.contact is not None and opts.contact not in CONTACT_LAWS:
        raise SweepInputError(
            f"--contact: {opts.contact!r} unknown; valid: {', '.join(CONTACT_LAWS)}"
        )
    _check_friction(opts)
    if opts.ends is not None and opts.ends not in ENDS:
        raise SweepInputError(f"--ends: {opts.ends!r} unknown; valid: {', '.join(ENDS)}")
    if opts.mesh is not None and opts.mesh not in MESH_PRESETS:
        valid = ", ".join(MESH_PRESETS)
        raise SweepInputError(f"--mesh: {opts.mesh!r} unknown; valid: {valid}")
    tl = opts.tube_length_mm
    if tl is not None and not (isinstance(tl, int | float) and math.isfinite(tl) and tl > 0):
        raise SweepInputError(f"--tube-length: must be a length > 0 in mm, got {tl!r}")
    _check_axial(opts)
    if model == "2d":
        given = opts.given_3d_only()
        if given:
            raise SweepInputError(f"{', '.join(given)}: only with --model 3d")


def _check_axial(opts: Model3DOptions) -> None:
    """``--n-jaw`` >= 1, ``--n-free`` >= 0, ``--far-coarsening`` >= 1 and
    ``--band-companion`` >= 0 (integers); ``--predict-contact-below`` a multiple of the wall
    thickness in (0, 100]."""
    ints = (
        ("--n-jaw", opts.n_jaw, 1),
        ("--n-free", opts.n_free, 0),
        ("--far-coarsening", opts.far_coarsening, 1),
        ("--band-companion", opts.band_companion, 0),
    )
    for name, v, least in ints:
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < least):
            raise SweepInputError(f"{name}: must be an integer >= {least}, got {v!r}")
    m = opts.predict_contact_below_t
    if m is not None and not (isinstance(m, int | float) and math.isfinite(m) and 0 < m <= 100):
        what = "a jaw gap in wall thicknesses in (0, 100]"
        raise SweepInputError(f"--predict-contact-below: must be {what}, got {m!r}")


def _check_friction(opts: Model3DOptions) -> None:
    """``--contact coulomb`` needs ``--friction MU`` > 0 (both models); MU needs coulomb."""
    mu = opts.friction
    if opts.contact == "coulomb":
        if mu is None:
            raise SweepInputError("--contact coulomb: needs --friction MU (a coefficient > 0)")
    if mu is not None:
        if opts.contact != "coulomb":
            raise SweepInputError("--friction: only used with --contact coulomb")
        if not (isinstance(mu, int | float) and math.isfinite(mu) and 0 < mu <= 10):
            raise SweepInputError(f"--friction: must be a coefficient in (0, 10], got {mu!r}")


def to_2d(specs: Sequence[Any], opts: Model3DOptions) -> list[Any]:
    """The 2D cases of a validated grid with the contact law of ``opts`` (if given).

    Parameters
    ----------
    specs : sequence of CaseSpec
        The 2D grid of :func:`grasprom.fe.grid.build_grid`.
    opts : Model3DOptions
        Validated by :func:`check_options` for ``--model 2d`` (only ``contact`` may be set).

    Returns
    -------
    list of CaseSpec
    """
    if opts.contact is None:
        return list(specs)
    mu = float(opts.friction) if opts.contact == "coulomb" else 0.0
    return [dataclasses.replace(s, contact=opts.contact, friction=mu) for s in specs]


def to_3d(specs: Sequence[Any], opts: Model3DOptions, mesh: Mapping[str, float]) -> list[Any]:
    """The 3D cases of a validated 2D grid.

    Parameters
    ----------
    specs : sequence of CaseSpec
        The 2D grid (material, thickness, tube and jaw options).
    opts : Model3DOptions
    mesh : mapping
        ``n_layers``, ``n_circ``, ``grading``, ``radial_grading`` given on the command line
        (validated by the 2D grid); they override the preset ``opts.mesh`` (default
        :data:`DEFAULT_MESH_PRESET`), and the preset the :class:`MeshSpec3D` defaults.

    Returns
    -------
    list of CaseSpec3D
    """
    from grasprom.fe.mesh3d import MeshSpec3D
    from grasprom.fe.model3d import CaseSpec3D

    preset = MESH_PRESETS[opts.mesh or DEFAULT_MESH_PRESET]
    default_companion = _preset_companion(preset, opts, mesh_given=bool(mesh))
    mesh = {**preset.mesh, **mesh}
    if mesh.get("n_circ", MIN_CIRC_3D) < MIN_CIRC_3D:
        raise SweepInputError(
            f"--n-circ: the 3D model needs at least {MIN_CIRC_3D} divisions along the quarter "
            f"circumference (coarser meshes are not tested against the contact), "
            f"got {mesh['n_circ']}"
        )
    extra = {k: v for k, v in dataclasses.asdict(opts).items() if v is not None}
    extra["friction"] = float(opts.friction) if opts.contact == "coulomb" else 0.0
    axial = {k: extra.pop(k) for k in ("n_jaw", "n_free", "far_coarsening") if k in extra}
    below_t = extra.pop("predict_contact_below_t", preset.predict_contact_below_t)
    companion = int(extra.pop("band_companion", default_companion))
    extra.pop("mesh", None)
    try:
        mesh3d = MeshSpec3D(**{**mesh, **axial})
    except ValueError as exc:
        if "far_coarsening" in axial:
            raise SweepInputError(f"--far-coarsening: {exc}") from exc
        if "far_coarsening" in mesh and "far_coarsening" in str(exc):  # the preset's
            raise SweepInputError(f"--mesh {opts.mesh}: {exc}") from exc
        raise
    out = []
    for s in specs:
        spec = CaseSpec3D(
            material=s.material,
            thickness_mm=s.thickness_mm,
            diameter_mm=s.diameter_mm,
            jaw_length_mm=s.jaw_length_mm,
            closed_gap_mm=s.closed_gap_mm,
            force_cap_N=s.force_cap_N,
            mesh=mesh3d,
            **extra,
        )
        solver = spec.solver
        if below_t is not None:  # in thicknesses, so that the cases share their settings
            solver = dataclasses.replace(solver, predict_contact_below_t=float(below_t))
        out.append(dataclasses.replace(spec, solver=solver))
    if companion and out:
        if opts.band_companion is not None:
            _check_companion(out[0], companion)
        elif not _companion_fits(out[0], companion):
            companion = 0  # the preset's, where the cases cannot have it
    return [
        dataclasses.replace(s, solver=dataclasses.replace(s.solver, band_companion=companion))
        for s in out
    ]


def _preset_companion(preset: MeshPreset, opts: Model3DOptions, mesh_given: bool) -> int:
    """The preset's band companion, or 0 where a mesh option overrides the preset's mesh (even
    at the preset's value; :attr:`MeshPreset.band_companion`; a case that cannot have it, e.g.
    with Coulomb contact, is left to :func:`_companion_fits`)."""
    axial = (opts.n_jaw, opts.n_free, opts.far_coarsening)
    if mesh_given or any(v is not None for v in axial):
        return 0
    return preset.band_companion


def _companion_fits(spec, companion: int) -> bool:
    """Whether the cases (they share mesh, tube and contact) can have the preset's companion
    (:func:`grasprom.fe.bandselect.check_companion`: not with Coulomb contact, nor on a tube
    too short for a far zone): where not, the preset's companion is off rather than an
    error."""
    from grasprom.fe.bandselect import check_companion

    try:
        check_companion(spec, companion)
    except ValueError:
        return False
    return True


def _check_companion(spec, companion: int) -> None:
    """``--band-companion``: :func:`grasprom.fe.bandselect.check_companion` of a case (the
    cases share mesh and contact), as a SweepInputError."""
    from grasprom.fe.bandselect import check_companion

    try:
        check_companion(spec, companion)
    except ValueError as exc:
        raise SweepInputError(f"--band-companion: {exc}") from exc
