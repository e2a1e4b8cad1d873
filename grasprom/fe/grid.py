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


def parse_thickness(text: str) -> list[float]:
    """Parse a ``--thickness`` value into wall thicknesses in mm.

    Parameters
    ----------
    text : str
        ``"start:stop:step"`` (inclusive of ``stop`` when it lies on the grid),
        a comma list ``"0.8,1.0"`` or a single value ``"1.2"``; all in mm.

    Returns
    -------
    list of float
        Thicknesses in mm, rounded to 6 decimals (no float drift: ``"0.8:2.0:0.1"`` gives
        exactly the 13 values 0.8, 0.9, ..., 2.0), duplicates removed.

    Raises
    ------
    SweepInputError
        On malformed text, a non-positive step, ``stop < start`` or an empty result.
    """
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
        values = [float(round(start + i * step, _THICKNESS_DECIMALS)) for i in range(n + 1)]
    else:
        items = [p for p in text.split(",") if p.strip()]
        if not items:
            raise SweepInputError(f"--thickness: empty grid in {text!r}")
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
    out_dir : str or os.PathLike, optional
        If given, created if needed and checked for writability.

    Returns
    -------
    list of CaseSpec
        Ordered by material, then thickness.

    Raises
    ------
    SweepInputError
        With a message naming the offending option (``--thickness``, ``--material``,
        ``--diameter``, ``--jaw-length``, ``--closed-gap``, ``--force-cap``, ``--n-layers``,
        ``--n-circ``, ``--out``) and value.
    """
    t_list = (
        parse_thickness(thickness)
        if isinstance(thickness, str)
        else _unique(round(float(t), _THICKNESS_DECIMALS) for t in thickness)
    )
    mats = parse_materials(materials)
    if not t_list:
        raise SweepInputError("--thickness: empty grid")
    lengths = {
        "diameter_mm": diameter_mm,
        "jaw_length_mm": jaw_length_mm,
        "closed_gap_mm": closed_gap_mm,
        "force_cap_N": force_cap_N,
    }
    _check_options(lengths, n_layers, n_circ)
    kw = {k: float(v) for k, v in lengths.items() if v is not None}
    mesh_kw = {k: v for k, v in (("n_layers", n_layers), ("n_circ", n_circ)) if v is not None}
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
