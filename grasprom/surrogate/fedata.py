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
        If a CSV holds NaN/inf in ``gap_mm`` or ``force_N``, or its gaps do not decrease
        strictly (the message names the file).
    """
    from grasprom.fe import datafiles

    d = Path(directory)
    if not d.is_dir():
        raise FileNotFoundError(f"FE sweep directory {d} does not exist")
    cases: list[FECase] = []
    partial: list[str] = []
    for jp in datafiles.case_json_paths(d):
        lc = datafiles.read_case(jp)
        meta = lc.meta
        stem = str(meta.get("stem", jp.stem))
        if meta["status"] != "complete":
            partial.append(stem)
            continue
        g = lc.table["gap_mm"].to_numpy(dtype=float)
        f = lc.table["force_N"].to_numpy(dtype=float)
        if not (np.isfinite(g).all() and np.isfinite(f).all()):
            raise ValueError(f"{lc.files.csv}: NaN or inf in gap_mm/force_N")
        if g.size < 2 or not (np.diff(g) < 0).all():
            raise ValueError(f"{lc.files.csv}: gap_mm must decrease strictly (>= 2 rows)")
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
