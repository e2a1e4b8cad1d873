"""FE data as the surrogate reads it: the complete force-gap curves of a sweep directory and
the hash that ties a surrogate to them.

Units: gaps and thicknesses in mm, forces in N.
"""

from __future__ import annotations

import hashlib
import os
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

PLAUSIBLE_THICKNESS_MM = (0.1, 10.0)
"""Wall thicknesses (mm) a case may have; outside, most likely a unit mistake (m, um)."""


class FEDataError(ValueError):
    """An FE case file the surrogate reads is implausible or does not belong to its sweep.

    Parameters
    ----------
    path : str or os.PathLike
        The offending file.
    reason : str
        What is wrong with it.
    """

    def __init__(self, path: str | os.PathLike[str], reason: str) -> None:
        self.path = Path(path)
        self.reason = reason
        super().__init__(f"FE case file {self.path}: {reason}")

    def __reduce__(self):  # keep picklable despite the custom signature
        return (type(self), (str(self.path), self.reason))


@dataclass(frozen=True)
class FECase:
    """One FE force-gap curve as read from a sweep directory.

    Attributes
    ----------
    stem : str
        Case stem, e.g. ``mr_t0.80``.
    material : str
        Material key.
    thickness_mm : float
        Wall thickness in mm.
    gap_mm : numpy.ndarray
        Jaw gaps in mm, in load-step order (decreasing from the diameter).
    force_N : numpy.ndarray
        Jaw force in N at each gap.
    diameter_mm : float
        Outer tube diameter in mm (gap of first touch).
    force_cap_N : float
        Force cap of the FE run in N (full scale of the full-range error figures).
    csv_sha256 : str
        SHA-256 of the case CSV.
    status : str
        ``complete`` or ``partial``.
    """

    stem: str
    material: str
    thickness_mm: float
    gap_mm: np.ndarray = field(repr=False)
    force_N: np.ndarray = field(repr=False)
    diameter_mm: float
    force_cap_N: float
    csv_sha256: str
    status: str


def read_fe_cases(directory: str | os.PathLike[str]) -> tuple[list[FECase], list[str]]:
    """Read and validate the FE cases of a sweep directory.

    Parameters
    ----------
    directory : str or os.PathLike
        Sweep directory (e.g. ``fe_data/default``).

    Returns
    -------
    complete : list of FECase
        Complete cases, sorted by material and thickness.
    partial : list of str
        Stems of partial cases (not returned in ``complete``).

    Raises
    ------
    FileNotFoundError
        If the directory does not exist or holds no case.
    grasprom.fe.datafiles.CorruptCaseError
        If a case file fails validation (hash, columns).
    ValueError
        If a CSV holds NaN/inf in ``gap_mm`` or ``force_N``, fewer than 2 rows, or its gaps
        do not decrease strictly (the message names the file).
    FEDataError
        (a ValueError) naming the file and the key: a sidecar whose sweep parameters differ
        from the manifest's ``sweep.json`` (or, without a manifest, from the first case's),
        a case missing from the manifest or with another ``input_hash``, a material or
        thickness that disagrees with the file name, an unknown material or a thickness
        outside :data:`PLAUSIBLE_THICKNESS_MM`.
    """
    from grasprom.fe import datafiles

    d = Path(directory)
    if not d.is_dir():
        raise FileNotFoundError(f"FE sweep directory {d} does not exist")
    reference = _reference_parameters(d)
    cases: list[FECase] = []
    partial: list[str] = []
    for jp in datafiles.case_json_paths(d):
        lc = datafiles.read_case(jp)
        reference = _check_case_meta(jp, lc.meta, reference)
        meta = lc.meta
        stem = str(meta.get("stem", jp.stem))
        if meta["status"] != "complete":
            partial.append(stem)
            continue
        g, f = _curve(lc)
        cases.append(
            FECase(
                stem=stem,
                material=str(meta["material"]),
                thickness_mm=float(meta["thickness_mm"]),
                gap_mm=g,
                force_N=f,
                diameter_mm=float(meta.get("diameter_mm", g[0])),
                force_cap_N=float(meta.get("force_cap_N") or 200.0),
                csv_sha256=str(meta["csv_sha256"]),
                status="complete",
            )
        )
    if not cases and not partial:
        raise FileNotFoundError(f"FE sweep directory {d} holds no case files")
    cases.sort(key=lambda c: (c.material, c.thickness_mm))
    return cases, partial


def _reference_parameters(d: Path) -> dict | None:
    """The manifest of ``d`` as ``{"parameters", "cases", "path"}``, or None without one."""
    from grasprom.fe import datafiles

    man = datafiles.read_manifest(d)
    if man is None:
        return None
    cases = {c.get("stem"): c for c in man["cases"] if isinstance(c, dict)}
    return {"parameters": man["parameters"], "cases": cases, "path": d / "sweep.json"}


def _check_case_meta(jp: Path, meta: dict, reference: dict | None) -> dict:
    """Check one sidecar against its file name, the materials and the sweep's parameters.

    ``reference`` is the manifest (see :func:`_reference_parameters`) or, without one, the
    first case's parameters (None for the first case); returns the reference to use next.
    """
    from grasprom.fe import datafiles
    from grasprom.fe.materials import MATERIAL_NAMES

    material, t = str(meta["material"]), meta["thickness_mm"]
    if material not in MATERIAL_NAMES:
        raise FEDataError(jp, f"unknown material {material!r} (known: {', '.join(MATERIAL_NAMES)})")
    if not isinstance(t, (int, float)) or isinstance(t, bool) or not np.isfinite(t):
        raise FEDataError(jp, f"thickness_mm {t!r} is not a finite number")
    lo, hi = PLAUSIBLE_THICKNESS_MM
    if not lo <= t <= hi:
        raise FEDataError(
            jp,
            f"thickness_mm {t:g} mm is outside the plausible range {lo:g}-{hi:g} mm "
            "(thicknesses are in mm: a unit mistake?)",
        )
    named = datafiles.parse_stem(jp.stem)
    if named is not None and (named[0] != material or abs(named[1] - t) > 0.0051):
        raise FEDataError(
            jp, f"material {material!r} / thickness_mm {t:g} disagree with the file name"
        )
    params = datafiles.case_parameters(meta)
    if params is None:
        return reference or {}
    _check_geometry(jp, meta, params)
    if reference is None:
        return {"parameters": params, "cases": None, "path": jp}
    if not reference:
        return reference
    diffs = datafiles.parameter_differences(reference["parameters"], params)
    if diffs:
        raise FEDataError(
            jp,
            f"sweep parameters differ from {reference['path']} "
            f"({datafiles.format_differences(diffs)}; {reference['path'].name} != this file); "
            "cases of different sweeps are mixed in one directory",
        )
    _check_listed(jp, meta, reference)
    return reference


_GEOMETRY_KEYS = ("diameter_mm", "jaw_length_mm", "closed_gap_mm", "force_cap_N")


def _check_geometry(jp: Path, meta: dict, params: dict) -> None:
    """Positive finite geometry (mm, N), the sidecar's copies equal to its ``spec``."""
    for key in _GEOMETRY_KEYS:
        v = params.get(key)
        if v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v < np.inf:
            raise FEDataError(jp, f"spec {key} = {v!r} must be a positive finite number")
        if key in meta and meta[key] != v:
            raise FEDataError(jp, f"{key} = {meta[key]!r} disagrees with its spec ({v!r})")


def _check_listed(jp: Path, meta: dict, reference: dict) -> None:
    """A case must be listed in the manifest with the same input hash (if there is one)."""
    listed = reference["cases"]
    if listed is None:
        return
    entry = listed.get(jp.stem)
    if entry is None:
        raise FEDataError(jp, f"case {jp.stem!r} is not listed in {reference['path']}")
    if entry.get("input_hash") != meta.get("input_hash"):
        raise FEDataError(
            jp, f"input_hash differs from the one {reference['path']} records for {jp.stem!r}"
        )


def _curve(lc) -> tuple[np.ndarray, np.ndarray]:
    """Gap and force columns of a complete case (mm, N), checked (ValueError naming the CSV)."""
    g = lc.table["gap_mm"].to_numpy(dtype=float)
    f = lc.table["force_N"].to_numpy(dtype=float)
    if not (np.isfinite(g).all() and np.isfinite(f).all()):
        raise ValueError(f"{lc.files.csv}: NaN or inf in gap_mm/force_N")
    if g.size < 2:
        raise FEDataError(lc.files.csv, f"{g.size} row(s); a force-gap curve needs >= 2")
    if not (np.diff(g) < 0).all():
        raise ValueError(f"{lc.files.csv}: gap_mm must decrease strictly (>= 2 rows)")
    return g, f


def fe_hash(cases: Iterable[FECase]) -> str:
    """Combined SHA-256 of the FE data: hash of the sorted ``stem:csv_sha256`` lines.

    Parameters
    ----------
    cases : iterable of FECase

    Returns
    -------
    str
        Hex digest.
    """
    lines = sorted(f"{c.stem}:{c.csv_sha256}" for c in cases)
    return hashlib.sha256("\n".join(lines).encode()).hexdigest()


def fe_dir_hash(directory: str | os.PathLike[str]) -> str:
    """:func:`fe_hash` of the complete cases of a sweep directory (partial ones excluded)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cases, _ = read_fe_cases(directory)
    return fe_hash(cases)
