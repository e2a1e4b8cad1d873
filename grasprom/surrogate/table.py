"""The surrogate: tabulated jaw force F(gap, thickness, material) from an FE sweep, built,
evaluated, checked, saved and loaded (see :mod:`grasprom.surrogate` for the scheme).

Units: gaps and thicknesses in mm, forces in N, stiffness in N/mm.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np

from grasprom.surrogate import fileformat
from grasprom.surrogate.build import SCHEMES, BuildParams, Curve, reduce_case
from grasprom.surrogate.fedata import FECase, fe_dir_hash, fe_hash, read_fe_cases
from grasprom.surrogate.spline import THICKNESS_TOL_MM, SplineTable
from grasprom.surrogate.validation import (
    CHECK_TOLERANCE,
    check_verdict,
    error_figures,
    leave_one_out,
)


class Surrogate:
    """Tabulated jaw force F(gap, thickness, material) from an FE sweep.

    Build with :meth:`build` (from a sweep directory) or :meth:`load` (from a file written by
    :meth:`save`). See the module docstring for the interpolation scheme and the behaviour
    outside the table.

    Parameters
    ----------
    curves : mapping of str to sequence of Curve
        Reduced curves per material, each sorted by thickness.
    diameter_mm : float
        Outer tube diameter in mm (gap of first touch).
    params : BuildParams
        Build parameters (holds the thickness scheme).
    fe_hash : str
        :func:`fe_hash` of the FE data the table came from.
    errors : dict, optional
        Error figures (see :func:`error_figures`).
    source : str, optional
        Where the FE data came from (informative).
    """

    def __init__(
        self,
        curves: Mapping[str, Sequence[Curve]],
        diameter_mm: float,
        params: BuildParams,
        fe_hash: str,
        errors: dict | None = None,
        source: str = "",
    ) -> None:
        if not curves:
            raise ValueError("a surrogate needs at least one material")
        self.params = params
        self.diameter_mm = float(diameter_mm)
        self.fe_hash = fe_hash
        self.errors: dict = dict(errors or {})
        self.source = source
        self._curves = {
            m: tuple(sorted(c, key=lambda k: k.thickness_mm)) for m, c in curves.items()
        }
        for m, cs in self._curves.items():
            if not cs:
                raise ValueError(f"material {m!r} has no curve")
            ts = [c.thickness_mm for c in cs]
            if len(set(ts)) != len(ts):
                raise ValueError(f"material {m!r}: duplicate thickness in {ts}")
        self._tables = {m: SplineTable(cs, self.diameter_mm) for m, cs in self._curves.items()}

    # ---------------------------------------------------------------- construction
    @classmethod
    def build(
        cls,
        sweep_dir: str | os.PathLike[str],
        tol: float = 0.005,
        *,
        params: BuildParams | None = None,
        holdout_dir: str | os.PathLike[str] | None = None,
    ) -> Surrogate:
        """Build the surrogate from a sweep directory.

        Partial cases are left out of the grid with a :class:`UserWarning` naming them.
        Leave-one-thickness-out figures (both schemes) are always computed; held-out
        figures too when ``holdout_dir`` is given.

        Parameters
        ----------
        sweep_dir : str or os.PathLike
            FE sweep directory (e.g. ``fe_data/default``).
        tol : float
            Node tolerance (see :class:`BuildParams`); ignored if ``params`` is given.
        params : BuildParams, optional
            All build parameters.
        holdout_dir : str or os.PathLike, optional
            Directory of extra FE cases for the held-out error figures.

        Returns
        -------
        Surrogate
        """
        params = params or BuildParams(tol=tol)
        cases, partial = read_fe_cases(sweep_dir)
        if partial:
            warnings.warn(
                f"{sweep_dir}: partial FE cases left out of the surrogate grid: "
                f"{', '.join(partial)}",
                UserWarning,
                stacklevel=2,
            )
        s = cls.from_cases(cases, params, source=str(sweep_dir))
        s.errors["loo"] = leave_one_out(s, cases)
        if holdout_dir is not None:
            s.errors["holdout"] = s.check(holdout_dir)
        return s

    @classmethod
    def from_cases(
        cls, cases: Sequence[FECase], params: BuildParams | None = None, source: str = ""
    ) -> Surrogate:
        """Build from already-read FE cases (complete ones only; see :func:`read_fe_cases`).

        Parameters
        ----------
        cases : sequence of FECase
        params : BuildParams, optional
        source : str
            Informative origin of the data.

        Returns
        -------
        Surrogate
        """
        params = params or BuildParams()
        if not cases:
            raise ValueError(f"no complete FE case to build a surrogate from ({source})")
        diam = {c.diameter_mm for c in cases}
        if len(diam) != 1:
            raise ValueError(f"FE cases of {source} have different diameters {sorted(diam)}")
        curves: dict[str, list[Curve]] = {}
        for c in cases:
            curves.setdefault(c.material, []).append(reduce_case(c, params))
        s = cls(curves, diam.pop(), params, fe_hash(cases), source=source)
        s.errors["fit"] = {
            m: {
                "nodes": [len(c.gap_mm) for c in cs],
                "fe_points": [c.n_fe_points for c in cs],
                "max_fit_error": max(c.fit_error for c in cs),
            }
            for m, cs in s._curves.items()
        }
        return s

    def with_scheme(self, scheme: str) -> Surrogate:
        """The same table with another thickness scheme (one of :data:`SCHEMES`)."""
        return Surrogate(
            self._curves,
            self.diameter_mm,
            replace(self.params, scheme=scheme),
            self.fe_hash,
            self.errors,
            self.source,
        )

    def without(self, material: str, thickness_mm: float) -> Surrogate:
        """The same table without the curve of one thickness (for leave-one-out)."""
        curves = dict(self._curves)
        curves[material] = tuple(
            c for c in curves[material] if abs(c.thickness_mm - thickness_mm) > 1e-9
        )
        return Surrogate(curves, self.diameter_mm, self.params, self.fe_hash, {}, self.source)

    # ---------------------------------------------------------------- introspection
    @property
    def materials(self) -> tuple[str, ...]:
        """Material keys in the table."""
        return tuple(self._curves)

    @property
    def scheme(self) -> str:
        """Thickness interpolation scheme (``aligned`` or ``naive``)."""
        return self.params.scheme

    def thickness_range(self, material: str) -> tuple[float, float]:
        """Swept thickness range ``(min, max)`` of a material, in mm."""
        tab = self.table(material)
        return tab.tmin, tab.tmax

    def thicknesses(self, material: str) -> tuple[float, ...]:
        """Grid thicknesses of a material, in mm."""
        return tuple(self.table(material).t)

    def curves(self, material: str) -> tuple[Curve, ...]:
        """Reduced curves of a material, sorted by thickness."""
        self.table(material)
        return self._curves[material]

    def node_count(self) -> int:
        """Total number of gap nodes over all curves."""
        return sum(len(c.gap_mm) for cs in self._curves.values() for c in cs)

    def table(self, material: str) -> SplineTable:
        """The evaluation table of one material (Hermite intervals per curve; for code generation).

        Raises
        ------
        ValueError
            If the surrogate has no such material.
        """
        try:
            return self._tables[material]
        except KeyError:
            raise ValueError(
                f"unknown material {material!r}; this surrogate has {list(self._tables)}"
            ) from None

    # ---------------------------------------------------------------- evaluation
    def force(self, gap_mm, thickness_mm, material: str, *, return_flag: bool = False):
        """Jaw force in N (numpy broadcasting over gap and thickness).

        Parameters
        ----------
        gap_mm : float or array_like
            Jaw gap in mm (finite).
        thickness_mm : float or array_like
            Wall thickness in mm, within :meth:`thickness_range`.
        material : str
            Material key.
        return_flag : bool
            Also return the out-of-range flag (gap below the FE range, extrapolated).

        Returns
        -------
        force : numpy.ndarray
            Force in N (0-d array for scalar inputs).
        flag : numpy.ndarray of bool
            Only if ``return_flag``: True where extrapolated below the FE gap range.

        Raises
        ------
        ValueError
            Unknown material, non-finite gap, or thickness outside the swept range.
        """
        f, _, flag = self.table(material).evaluate(
            gap_mm, thickness_mm, self.params.scheme, False, return_flag
        )
        return (f, flag) if return_flag else f

    def stiffness(self, gap_mm, thickness_mm, material: str, *, return_flag: bool = False):
        """Stiffness ``-dF/dgap`` in N/mm (>= 0; numpy broadcasting over gap and thickness).

        Parameters and errors as :meth:`force`.

        Returns
        -------
        stiffness : numpy.ndarray
            N/mm, positive when closing the jaws raises the force; 0 above first touch.
        flag : numpy.ndarray of bool
            Only if ``return_flag``.
        """
        _, d, flag = self.table(material).evaluate(
            gap_mm, thickness_mm, self.params.scheme, True, return_flag
        )
        k = -d
        return (k, flag) if return_flag else k

    def in_range(self, gap_mm, thickness_mm, material: str) -> np.ndarray:
        """True where the gap lies within the FE range (no extrapolation), bool array."""
        _, flag = self.force(gap_mm, thickness_mm, material, return_flag=True)
        return ~flag

    def evaluate_scalar(
        self, gap_mm: float, thickness_mm: float, material: str
    ) -> tuple[float, float, bool]:
        """Force (N), stiffness (N/mm) and out-of-range flag of one point, pure Python floats.

        No numpy and no array allocation: bisection on precomputed lists, for the controller
        loop. Gives the same numbers as :meth:`force` / :meth:`stiffness`.

        Parameters
        ----------
        gap_mm : float
            Jaw gap in mm.
        thickness_mm : float
            Wall thickness in mm, within :meth:`thickness_range`.
        material : str
            Material key.

        Returns
        -------
        tuple of (float, float, bool)
            ``(force_N, stiffness_N_per_mm, out_of_range)``.
        """
        f, d, flag = self.table(material).scalar(
            float(gap_mm), float(thickness_mm), self.params.scheme
        )
        return f, -d, flag

    def force_scalar(self, gap_mm: float, thickness_mm: float, material: str) -> float:
        """Force in N at one point, pure Python (see :meth:`evaluate_scalar`)."""
        return self.table(material).scalar(gap_mm, thickness_mm, self.params.scheme)[0]

    def stiffness_scalar(self, gap_mm: float, thickness_mm: float, material: str) -> float:
        """Stiffness ``-dF/dgap`` in N/mm at one point, pure Python (:meth:`evaluate_scalar`)."""
        return -self.table(material).scalar(gap_mm, thickness_mm, self.params.scheme)[1]

    # ---------------------------------------------------------------- accuracy
    def check(
        self,
        fe_dir: str | os.PathLike[str],
        schemes: Sequence[str] = SCHEMES,
        tolerance: Mapping[str, float] | None = None,
    ) -> dict:
        """Error figures against the FE cases of a directory, for each scheme, and a verdict.

        Parameters
        ----------
        fe_dir : str or os.PathLike
            Directory of FE cases (e.g. ``fe_data/holdout``); partial cases and cases outside
            the surrogate's materials or thickness range are skipped with a warning.
        schemes : sequence of str
            Schemes to measure.
        tolerance : mapping, optional
            ``{"force_max_pct": %, "gap_max_mm": mm}`` for the surrogate's own scheme in the
            haptic range, all materials; default :data:`CHECK_TOLERANCE` (3 %, 0.02 mm, the
            issue 3 targets).

        Returns
        -------
        dict
            ``{"source", "skipped": [stems], "schemes": {scheme: error_figures(...)},
            "tolerance": {...}, "fe_hash": {"file", "source", "source_hash", "match"},
            "passed": bool, "failures": [str]}``; see
            :func:`~grasprom.surrogate.validation.check_passed`. ``fe_hash.match`` is None
            when the FE data the surrogate was built from is not at hand.
        """
        cases, partial = read_fe_cases(fe_dir)
        if partial:
            warnings.warn(
                f"{fe_dir}: partial FE cases skipped: {', '.join(partial)}",
                UserWarning,
                stacklevel=2,
            )
        hash_record = self._hash_record(fe_dir, fe_hash(cases))
        keep, skipped = [], []
        for c in cases:
            ok = c.material in self._tables
            if ok:
                lo, hi = self.thickness_range(c.material)
                ok = lo - THICKNESS_TOL_MM <= c.thickness_mm <= hi + THICKNESS_TOL_MM
            (keep if ok else skipped).append(c)
        if skipped:
            warnings.warn(
                f"{fe_dir}: FE cases outside the surrogate's materials/thickness range "
                f"skipped: {', '.join(c.stem for c in skipped)}",
                UserWarning,
                stacklevel=2,
            )
        result: dict[str, Any] = {
            "source": str(fe_dir),
            "skipped": [c.stem for c in skipped],
            "schemes": {
                sc: error_figures(self.with_scheme(sc), keep, self.params) for sc in schemes
            },
            "tolerance": {
                "scheme": self.scheme,
                "range": "haptic",
                **{k: float(v) for k, v in (tolerance or CHECK_TOLERANCE).items()},
            },
            "fe_hash": hash_record,
        }
        result["passed"], result["failures"] = check_verdict(result)
        return result

    def _hash_record(self, fe_dir: str | os.PathLike[str], dir_hash: str) -> dict[str, Any]:
        """Compare :attr:`fe_hash` with the FE data it was built from, when at hand.

        ``dir_hash`` is the hash of ``fe_dir``'s complete cases; a match means ``fe_dir``
        is the data the surrogate was built from; otherwise the recorded source directory
        (:attr:`source`) is hashed if it exists.
        """
        rec: dict[str, Any] = {"file": self.fe_hash, "source": None, "source_hash": None}
        if dir_hash == self.fe_hash:
            rec.update(source=str(fe_dir), source_hash=dir_hash, match=True)
            return rec
        src = _source_dir(self.source)
        if src is None:
            rec["match"] = None
            return rec
        try:
            h = dir_hash if _same_dir(src, Path(fe_dir)) else fe_dir_hash(src)
        except Exception as exc:  # noqa: BLE001 - any unreadable FE data: reported
            rec.update(source=str(src), match=False, error=str(exc))
            return rec
        rec.update(source=str(src), source_hash=h, match=h == self.fe_hash)
        return rec

    # ---------------------------------------------------------------- I/O
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready representation (see :meth:`save`)."""
        mats = {m: fileformat.material_to_dict(cs) for m, cs in self._curves.items()}
        return {
            "format": fileformat.FORMAT_NAME,
            "format_version": fileformat.FORMAT_VERSION,
            "scheme": fileformat.scheme_description(self.params),
            "params": asdict(self.params),
            "diameter_mm": self.diameter_mm,
            "units": {"gap": "mm", "thickness": "mm", "force": "N", "stiffness": "N/mm"},
            "fe_source": self.source,
            "fe_hash": self.fe_hash,
            "fe_hash_method": "sha256 of sorted '<stem>:<csv_sha256>' lines, complete cases",
            "node_count": self.node_count(),
            "errors": self.errors,
            "materials": mats,
        }

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the surrogate as versioned JSON (atomically).

        Parameters
        ----------
        path : str or os.PathLike
            Output file (``.json``).

        Returns
        -------
        pathlib.Path

        Raises
        ------
        SurrogateWriteError
            (an :class:`OSError` and a :class:`SurrogateFileError`) naming ``path`` if the
            write fails, e.g. on a full disk; nothing partial is left behind.
        """
        from grasprom.fe.atomicio import AtomicWriteError, atomic_write_bytes

        p = Path(path)
        data = fileformat.encode(self.to_dict())
        try:
            atomic_write_bytes(p, data)
        except AtomicWriteError as exc:
            raise fileformat.SurrogateWriteError(exc.errno, exc.strerror, str(p)) from None
        return p

    @classmethod
    def load(
        cls,
        path: str | os.PathLike[str],
        fe_dir: str | os.PathLike[str] | None = None,
        *,
        check_source: bool = True,
    ) -> Surrogate:
        """Read a surrogate written by :meth:`save`, validating its content.

        The content is checked by :func:`~grasprom.surrogate.fileformat.check_content`
        (monotone axes, finite values, force and stiffness >= 0, positive geometry, known
        materials). The FE data hash: with ``fe_dir`` a mismatch is an error; without it,
        if the FE sweep the file names (``fe_source``) exists here, a mismatch is a
        :class:`UserWarning` (the sweep may have grown since; the file itself is complete).

        Parameters
        ----------
        path : str or os.PathLike
            Surrogate JSON file.
        fe_dir : str or os.PathLike, optional
            The FE sweep it was built from; if given, its :func:`fe_dir_hash` must match.
        check_source : bool, keyword-only
            Without ``fe_dir``, compare the hash with the recorded source sweep if present.

        Returns
        -------
        Surrogate

        Raises
        ------
        SurrogateFileError
            Missing/unparsable file, other format or version, missing keys, implausible or
            inconsistent table, or FE hash mismatch (the message names the file, material,
            curve and key).
        """
        p = Path(path)
        d = fileformat.read_json(p)
        fileformat.check_content(p, d)
        try:
            params = BuildParams(**d["params"])
            curves = fileformat.curves_from_dict(p, d["materials"])
            s = cls(
                curves,
                float(d["diameter_mm"]),
                params,
                str(d["fe_hash"]),
                d["errors"],
                str(d.get("fe_source", "")),
            )
        except fileformat.SurrogateFileError:
            raise
        except (TypeError, ValueError, KeyError, AttributeError) as exc:
            raise fileformat.SurrogateFileError(p, f"inconsistent content ({exc})") from None
        if fe_dir is not None:
            fileformat.check_fe_hash(p, s.fe_hash, fe_dir)
        elif check_source:
            _warn_source_hash(p, s)
        return s


def _source_dir(source: str) -> Path | None:
    """The FE sweep directory a surrogate records as its source, if it exists here."""
    from grasprom.paths import resolve_data_dir

    if not source:
        return None
    d = resolve_data_dir(source)
    return d if d.is_dir() else None


def _same_dir(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve()
    except OSError:
        return False


def _warn_source_hash(p: Path, s: Surrogate) -> None:
    """UserWarning if the FE sweep ``s`` was built from is at hand and hashes differently."""
    src = _source_dir(s.source)
    if src is None:
        return
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            h = fe_dir_hash(src)
    except Exception as exc:  # noqa: BLE001 - any unreadable FE data: reported
        warnings.warn(
            f"surrogate file {p}: cannot hash its FE source {src} ({exc})", UserWarning, 3
        )
        return
    if h != s.fe_hash:
        warnings.warn(
            f"surrogate file {p}: fe_hash {s.fe_hash[:12]}... differs from its FE source "
            f"{src} ({h[:12]}...); the FE data changed since the build: rebuild it",
            UserWarning,
            stacklevel=3,
        )


def clamp_thickness(surrogate: Surrogate, thickness_mm: float, material: str) -> tuple[float, bool]:
    """Clamp a thickness into the swept range, as the exported controllers do.

    Parameters
    ----------
    surrogate : Surrogate
    thickness_mm : float
        Wall thickness in mm.
    material : str
        Material key.

    Returns
    -------
    tuple of (float, bool)
        The clamped thickness in mm and True if it was clamped.
    """
    lo, hi = surrogate.thickness_range(material)
    if thickness_mm < lo:
        return lo, True
    if thickness_mm > hi:
        return hi, True
    if thickness_mm != thickness_mm:
        raise ValueError("thickness_mm is NaN")
    return float(thickness_mm), False


def load_surrogate(
    surrogate: str | os.PathLike[str] | None, fe: str | os.PathLike[str] | None
) -> Surrogate:
    """Load a surrogate file, or build one from an FE sweep (default: the shipped sweep).

    Parameters
    ----------
    surrogate : str or path-like or None
        A surrogate JSON file (``grasprom surrogate build``); wins over ``fe``.
    fe : str or path-like or None
        An FE sweep directory; None: the shipped ``fe_data/default``.

    Returns
    -------
    Surrogate
    """
    from grasprom.paths import DEFAULT_SWEEP_DIR, resolve_data_dir

    if surrogate:
        return Surrogate.load(surrogate)
    return Surrogate.build(resolve_data_dir(fe or DEFAULT_SWEEP_DIR))
