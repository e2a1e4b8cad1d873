"""The thickness x material grid of an FE sweep: parsing the ``--thickness`` / ``--material``
values, validating the case parameters and the output directory, building the case specs.

Typical use::

    specs = build_grid("0.8:2.0:0.1", "mr,nh,le", out_dir="fe_data/mine")

Units: lengths in mm, forces in N.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tempfile
from collections.abc import Iterable
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any

from grasprom.fe import datafiles as df
from grasprom.fe.materials import MATERIAL_NAMES
from grasprom.fe.model2d import CaseSpec, MeshSpec

KNOWN_MATERIALS = MATERIAL_NAMES
"""Material keys: Mooney-Rivlin, neo-Hookean, large-strain linear elastic."""

_THICKNESS_DECIMALS = 6

MAX_CASES = 1000
"""Default limit on the cases of one sweep (thicknesses x materials); the environment variable
``GRASPROM_MAX_CASES`` or the ``max_cases`` argument of :func:`build_grid` changes it."""

MAX_CASES_ENV = "GRASPROM_MAX_CASES"
"""Environment variable overriding :data:`MAX_CASES`."""

PLAUSIBLE_THICKNESS_MM = (0.1, 10.0)
"""Plausible colon wall thicknesses in mm, inclusive (outside: most likely m or um given)."""


class SweepInputError(ValueError):
    """Bad sweep input (grid, parameters, output directory); the message names the culprit."""


# --------------------------------------------------------------------------- parsing


def _unique(items: Iterable[Any]) -> list[Any]:
    seen: set[Any] = set()
    out = []
    for x in items:
        if x not in seen:
            seen.add(x)
            out.append(x)
    return out


def _dec(text: str, what: str) -> Decimal:
    try:
        d = Decimal(text.strip())
    except InvalidOperation:
        raise SweepInputError(
            f"--thickness: cannot parse {what} {text.strip()!r} as a number"
        ) from None
    if not d.is_finite():
        raise SweepInputError(f"--thickness: {what} {text.strip()!r} is not finite")
    return d


def case_limit() -> int:
    """The case limit of a sweep: ``GRASPROM_MAX_CASES`` if set, else :data:`MAX_CASES`.

    Raises
    ------
    SweepInputError
        If ``GRASPROM_MAX_CASES`` is not a positive integer.
    """
    text = os.environ.get(MAX_CASES_ENV, "").strip()
    if not text:
        return MAX_CASES
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise SweepInputError(f"{MAX_CASES_ENV}: must be a positive integer, got {text!r}")
    return n


def _too_many(what: str, n: int, limit: int) -> SweepInputError:
    return SweepInputError(
        f"{what}: {n} cases exceed the limit of {limit} cases per sweep; use a coarser "
        f"--thickness step or fewer values, or raise the limit with {MAX_CASES_ENV}=<n> "
        "(or build_grid(..., max_cases=n))"
    )


def check_plausible_thickness(t: float, what: str = "--thickness") -> None:
    """Refuse a wall thickness outside :data:`PLAUSIBLE_THICKNESS_MM` (a unit mistake).

    Parameters
    ----------
    t : float
        Wall thickness in mm.
    what : str
        Where the value came from (option or file), named in the message.

    Raises
    ------
    SweepInputError
        Naming the value, the unit and the plausible range.
    """
    lo, hi = PLAUSIBLE_THICKNESS_MM
    if lo <= t <= hi:
        return
    hint = "given in m or cm?" if t < lo else "given in um?"
    raise SweepInputError(
        f"{what}: wall thickness {t:g} mm is outside the plausible range {lo:g}-{hi:g} mm "
        f"(thicknesses are in mm; {hint})"
    )


def parse_thickness(text: str, limit: int | None = None) -> list[float]:
    """Parse a ``--thickness`` value into wall thicknesses in mm.

    Parameters
    ----------
    text : str
        ``"start:stop:step"`` (inclusive of ``stop`` when it lies on the grid),
        a comma list ``"0.8,1.0"`` or a single value ``"1.2"``; all in mm.
    limit : int, optional
        Most values allowed (default :func:`case_limit`); checked before the values are built.

    Returns
    -------
    list of float
        Thicknesses in mm, rounded to 6 decimals (no float drift: ``"0.8:2.0:0.1"`` gives
        exactly the 13 values 0.8, 0.9, ..., 2.0), duplicates removed.

    Raises
    ------
    SweepInputError
        On malformed text, a non-positive step, ``stop < start``, an empty result or more
        than ``limit`` values.
    """
    limit = case_limit() if limit is None else int(limit)
    text = str(text).strip()
    if not text:
        raise SweepInputError("--thickness: empty value (give e.g. 0.8:2.0:0.1, 0.8,1.0 or 1.2)")
    if ":" in text:
        parts = text.split(":")
        if len(parts) != 3:
            raise SweepInputError(
                f"--thickness: range {text!r} must be start:stop:step (e.g. 0.8:2.0:0.1)"
            )
        start, stop, step = (_dec(p, w) for p, w in zip(parts, ("start", "stop", "step")))
        if step <= 0:
            raise SweepInputError(f"--thickness: step must be > 0 in {text!r}")
        if stop < start:
            raise SweepInputError(
                f"--thickness: empty grid, stop {stop} < start {start} in {text!r}"
            )
        n = int((stop - start) / step)  # exact decimal arithmetic: floor
        if n + 1 > limit:
            raise _too_many(f"--thickness: range {text!r}", n + 1, limit)
        values = [float(round(start + i * step, _THICKNESS_DECIMALS)) for i in range(n + 1)]
    else:
        items = [p for p in text.split(",") if p.strip()]
        if not items:
            raise SweepInputError(f"--thickness: empty grid in {text!r}")
        if len(items) > limit:
            raise _too_many("--thickness: list", len(items), limit)
        values = [float(round(_dec(p, "value"), _THICKNESS_DECIMALS)) for p in items]
    return _unique(values)


def parse_materials(text: str | Iterable[str]) -> list[str]:
    """Parse a ``--material`` value such as ``"mr,nh,le"``.

    Parameters
    ----------
    text : str or iterable of str
        Comma-separated material keys (case-insensitive) or a list of them.

    Returns
    -------
    list of str
        Lower-case keys in given order, duplicates removed.

    Raises
    ------
    SweepInputError
        If empty or if a key is not one of :data:`KNOWN_MATERIALS` (the message lists them).
    """
    items = text.split(",") if isinstance(text, str) else list(text)
    mats = _unique(str(m).strip().lower() for m in items if str(m).strip())
    if not mats:
        raise SweepInputError(
            f"--material: empty list; valid materials: {', '.join(KNOWN_MATERIALS)}"
        )
    bad = [m for m in mats if m not in KNOWN_MATERIALS]
    if bad:
        raise SweepInputError(
            f"--material: unknown material {', '.join(map(repr, bad))}; "
            f"valid materials: {', '.join(KNOWN_MATERIALS)}"
        )
    return mats


# --------------------------------------------------------------------------- grid


def spec_defaults() -> dict[str, Any]:
    """Default values of the scalar :class:`~grasprom.fe.model2d.CaseSpec` and
    :class:`~grasprom.fe.model2d.MeshSpec` fields (the single source of CLI defaults).

    Returns
    -------
    dict
        E.g. ``{"diameter_mm": 30.0, ..., "n_layers": 2, "n_circ": 48}``.
    """
    out: dict[str, Any] = {}
    for cls in (CaseSpec, MeshSpec):
        for f in dataclasses.fields(cls):
            if f.default is not dataclasses.MISSING:
                out[f.name] = f.default
    return out


def check_out_dir(out_dir: str | os.PathLike[str]) -> Path:
    """Create ``out_dir`` if needed and check that files can be written in it.

    Returns
    -------
    pathlib.Path
        The directory.

    Raises
    ------
    SweepInputError
        Naming the directory, if it cannot be created or written.
    """
    d = Path(out_dir)
    if d.exists() and not d.is_dir():
        raise SweepInputError(f"--out: {d} exists and is not a directory")
    try:
        d.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=d, prefix=".write-probe.", suffix=".tmp")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise SweepInputError(
            f"--out: output directory {d} is not writable ({exc.strerror or exc})"
        ) from None
    return d


def _positive(name: str, value: float | None) -> None:
    if value is None:
        return
    try:
        ok = math.isfinite(float(value)) and float(value) > 0
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise SweepInputError(f"{name}: must be a positive number, got {value!r}")


def build_grid(
    thickness: str | Iterable[float],
    materials: str | Iterable[str],
    *,
    diameter_mm: float | None = None,
    jaw_length_mm: float | None = None,
    closed_gap_mm: float | None = None,
    force_cap_N: float | None = None,
    n_layers: int | None = None,
    n_circ: int | None = None,
    out_dir: str | os.PathLike[str] | None = None,
    max_cases: int | None = None,
    grading: float | None = None,
    radial_grading: float | None = None,
) -> list[CaseSpec]:
    """Build and validate the thickness x material grid of cases.

    Parameters
    ----------
    thickness : str or iterable of float
        Wall thicknesses in mm, or a ``--thickness`` string (see :func:`parse_thickness`).
    materials : str or iterable of str
        Material keys or a ``--material`` string (see :func:`parse_materials`).
    diameter_mm, jaw_length_mm, closed_gap_mm : float, optional
        Outer tube diameter, jaw length along the tube axis (out-of-plane depth) and
        closed jaw gap, in mm; None takes the :class:`~grasprom.fe.model2d.CaseSpec` default.
    force_cap_N : float, optional
        Jaw force in N at which a case stops; None takes the default.
    n_layers, n_circ : int, optional
        Mesh divisions through the wall / along the quarter circumference; None takes the
        :class:`~grasprom.fe.model2d.MeshSpec` default.
    grading, radial_grading : float, optional
        2D mesh grading toward the fold corner: largest / smallest circumferential element and
        outermost / innermost layer (>= 1, 1 = uniform); None takes the default.
    out_dir : str or os.PathLike, optional
        If given, created if needed and checked for writability.
    max_cases : int, optional
        Most cases allowed (thicknesses x materials); default ``GRASPROM_MAX_CASES`` or
        :data:`MAX_CASES` (1000).

    Returns
    -------
    list of CaseSpec
        Ordered by material, then thickness.

    Raises
    ------
    SweepInputError
        With a message naming the offending option (``--thickness``, ``--material``,
        ``--diameter``, ``--jaw-length``, ``--closed-gap``, ``--force-cap``, ``--n-layers``,
        ``--n-circ``, ``--grading``, ``--radial-grading``, ``--out``) and value; also a
        thickness outside :data:`PLAUSIBLE_THICKNESS_MM` (a unit mistake) and a grid over the
        case limit.
    """
    t_list, mats = _grid_axes(thickness, materials, _case_limit(max_cases))
    lengths = {
        "diameter_mm": diameter_mm,
        "jaw_length_mm": jaw_length_mm,
        "closed_gap_mm": closed_gap_mm,
        "force_cap_N": force_cap_N,
    }
    _check_options(lengths, n_layers, n_circ)
    _check_grading(grading, radial_grading)
    kw = {k: float(v) for k, v in lengths.items() if v is not None}
    mesh_kw = _given(
        n_layers=n_layers, n_circ=n_circ, grading=grading, radial_grading=radial_grading
    )
    _check_geometry(t_list, kw)
    mesh = MeshSpec(**mesh_kw)
    specs = [CaseSpec(material=m, thickness_mm=t, mesh=mesh, **kw) for m in mats for t in t_list]
    stems = [df.spec_stem(s) for s in specs]
    if len(set(stems)) != len(stems):
        raise SweepInputError(
            "--thickness: values closer than 0.01 mm map to the same case file name"
        )
    if out_dir is not None:
        check_out_dir(out_dir)
    return specs


def _grid_axes(
    thickness: str | Iterable[float], materials: str | Iterable[str], limit: int
) -> tuple[list[float], list[str]]:
    """The thicknesses (mm) and materials of the grid, checked against the case ``limit``."""
    t_list = (
        parse_thickness(thickness, limit)
        if isinstance(thickness, str)
        else _unique(round(float(t), _THICKNESS_DECIMALS) for t in thickness)
    )
    mats = parse_materials(materials)
    if not t_list:
        raise SweepInputError("--thickness: empty grid")
    if len(t_list) * len(mats) > limit:
        n = len(t_list) * len(mats)
        raise _too_many(f"--thickness x --material: {len(t_list)} x {len(mats)}", n, limit)
    return t_list, mats


def _case_limit(max_cases: int | None) -> int:
    """The case limit: ``max_cases`` if given (a positive integer), else :func:`case_limit`."""
    if max_cases is None:
        return case_limit()
    if isinstance(max_cases, bool) or not isinstance(max_cases, int) or max_cases < 1:
        raise SweepInputError(f"max_cases: must be a positive integer, got {max_cases!r}")
    return max_cases


MIN_CIRC_2D = 4
"""Fewest divisions along the quarter circumference a 2D case accepts (``--n-circ``)."""

_OPTION_NAMES = {
    "diameter_mm": "--diameter",
    "jaw_length_mm": "--jaw-length",
    "closed_gap_mm": "--closed-gap",
    "force_cap_N": "--force-cap",
}
"""CLI option of each scalar CaseSpec field (named in the error messages)."""


def _check_options(
    lengths: dict[str, float | None], n_layers: int | None, n_circ: int | None
) -> None:
    """Each given option on its own: positive numbers (mm, N) and positive mesh integers."""
    for key, v in lengths.items():
        _positive(_OPTION_NAMES[key], v)
    for name, v in (("--n-layers", n_layers), ("--n-circ", n_circ)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 1):
            raise SweepInputError(f"{name}: must be a positive integer, got {v!r}")
    if n_circ is not None and n_circ < MIN_CIRC_2D:
        raise SweepInputError(
            f"--n-circ: the model needs at least {MIN_CIRC_2D} divisions along the quarter "
            f"circumference (coarser meshes cannot follow the jaw contact), got {n_circ}"
        )


def _given(**kw: Any) -> dict[str, Any]:
    """The keyword arguments that are not None."""
    return {k: v for k, v in kw.items() if v is not None}


def _check_grading(grading: float | None, radial_grading: float | None) -> None:
    """Mesh gradings: finite numbers in [1, 100]."""
    for name, v in (("--grading", grading), ("--radial-grading", radial_grading)):
        if v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 1.0 <= v <= 100.0:
            raise SweepInputError(f"{name}: must be a number in [1, 100] (1 = uniform), got {v!r}")


def _check_geometry(t_list: list[float], kw: dict[str, float]) -> None:
    """Closed gap below the diameter and every thickness (mm) in ``(0, outer radius)``.

    ``kw`` holds the given scalar CaseSpec fields; the others take their defaults.
    """
    defaults = spec_defaults()
    diameter = kw.get("diameter_mm", defaults["diameter_mm"])
    radius = diameter / 2.0
    closed_gap = kw.get("closed_gap_mm", defaults["closed_gap_mm"])
    if closed_gap >= diameter:
        raise SweepInputError(
            f"--closed-gap: {closed_gap:g} mm must be smaller than the tube diameter "
            f"{diameter:g} mm"
        )
    for t in t_list:
        if not math.isfinite(t) or t <= 0:
            raise SweepInputError(f"--thickness: wall thickness must be > 0 mm, got {t:g}")
        if t >= radius:
            raise SweepInputError(
                f"--thickness: wall thickness {t:g} mm must be smaller than the outer radius "
                f"{radius:g} mm (diameter {diameter:g} mm)"
            )
        check_plausible_thickness(t)
