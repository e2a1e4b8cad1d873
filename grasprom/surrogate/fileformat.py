"""The versioned JSON file of a surrogate (:meth:`~grasprom.surrogate.table.Surrogate.save`):
layout, encoding of the curves, and validation of a file read back.

Units: gaps and thicknesses in mm, forces in N, dF/dgap in N/mm.
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from grasprom.fe.atomicio import AtomicWriteError
from grasprom.fe.materials import MATERIAL_NAMES
from grasprom.surrogate.build import BuildParams, Curve
from grasprom.surrogate.fedata import PLAUSIBLE_THICKNESS_MM, fe_dir_hash

FORMAT_NAME = "grasprom-surrogate"
FORMAT_VERSION = 1
"""Version of the surrogate JSON layout; bump on incompatible change."""

_REQUIRED_KEYS = (
    "format",
    "format_version",
    "scheme",
    "params",
    "diameter_mm",
    "fe_hash",
    "materials",
    "errors",
)
_REQUIRED_MAT_KEYS = ("thickness_mm", "contact_gap_mm", "curves")

FORCE_TOL_N = 1e-6
"""Most negative node force (N) a file may hold (round-off; the shipped files have 0)."""

STIFFNESS_TOL_N_PER_MM = 1e-6
"""Most positive node dF/dgap (N/mm), i.e. most negative stiffness, a file may hold
(round-off; the shipped files reach 7e-18)."""

MAX_FORCE_N = 1e5
"""Largest plausible node force in N (FE force caps are ~200 N)."""

MAX_STIFFNESS_N_PER_MM = 1e7
"""Largest plausible node stiffness ``-dF/dgap`` in N/mm (the shipped files reach 2.4e3)."""

MAX_DIAMETER_MM = 1000.0
"""Largest plausible tube diameter in mm."""

_HASH_RE = re.compile(r"^[0-9a-f]{64}$")
_REQUIRED_CURVE_KEYS = ("stem", "gap_mm", "force_N", "dforce_dgap_N_per_mm")


class SurrogateFileError(ValueError):
    """A surrogate file is unreadable, from another format version, or inconsistent.

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
        super().__init__(f"surrogate file {self.path}: {reason}")


class SurrogateWriteError(AtomicWriteError, SurrogateFileError):
    """A surrogate file could not be written (e.g. disk full); nothing partial was left.

    An :class:`OSError` (``filename`` is the target file) and a :class:`SurrogateFileError`.
    Raised as ``SurrogateWriteError(errno, strerror, path)``.
    """

    def __init__(self, *args: Any) -> None:
        OSError.__init__(self, *args)
        self.path = Path(str(self.filename))
        self.reason = f"cannot write ({self.strerror})"

    def __str__(self) -> str:
        return f"surrogate file {self.filename}: cannot write ({self.strerror}); nothing written"


# --------------------------------------------------------------------------- writing


def scheme_description(params: BuildParams) -> dict[str, str]:
    """The ``"scheme"`` entry of the file: how the table is interpolated, in words.

    Parameters
    ----------
    params : BuildParams
        Build parameters (thickness scheme and contact-gap method).

    Returns
    -------
    dict of str to str
    """
    return {
        "gap": "pchip (monotone cubic Hermite, scipy PchipInterpolator derivatives)",
        "thickness": params.scheme,
        "aligned_coordinate": "u = (gap - g_c(t)) / (D - g_c(t)), g_c linear in t",
        "contact_gap_method": params.contact_gap_method,
        "below_fe_range": "linear with the stiffness at the last node; flagged",
        "above_first_touch": "0 N for gap >= diameter_mm",
        "stiffness_sign": "stiffness = -dF/dgap (N/mm), >= 0",
    }


def material_to_dict(curves: Sequence[Curve]) -> dict[str, Any]:
    """The ``"materials"`` entry of one material: its curves sorted by thickness.

    Parameters
    ----------
    curves : sequence of Curve
        Reduced curves of the material, sorted by thickness.

    Returns
    -------
    dict
        ``thickness_mm`` and ``contact_gap_mm`` lists (mm) and one dict per curve with its
        nodes (mm, N, N/mm).
    """
    return {
        "thickness_mm": [c.thickness_mm for c in curves],
        "contact_gap_mm": [c.contact_gap_mm for c in curves],
        "curves": [
            {
                "stem": c.stem,
                "n_fe_points": c.n_fe_points,
                "fit_error": c.fit_error,
                "gap_mm": list(c.gap_mm),
                "force_N": list(c.force_N),
                "dforce_dgap_N_per_mm": list(c.dforce_dgap_N_per_mm),
            }
            for c in curves
        ],
    }


def _json_default(obj: Any) -> Any:
    if hasattr(obj, "tolist"):
        return obj.tolist()
    raise TypeError(f"object of type {type(obj).__name__} is not JSON serialisable")


def encode(d: Mapping[str, Any]) -> bytes:
    """File bytes of a surrogate dict: indented JSON (numpy values as lists), newline-terminated.

    Parameters
    ----------
    d : mapping
        Output of :meth:`~grasprom.surrogate.table.Surrogate.to_dict`.

    Returns
    -------
    bytes
    """
    text = json.dumps(d, indent=1, allow_nan=False, default=_json_default)
    return (text + "\n").encode()


# --------------------------------------------------------------------------- reading


def read_json(p: Path) -> dict[str, Any]:
    """Parse a surrogate file and check its format, version and top-level keys.

    Parameters
    ----------
    p : pathlib.Path
        Surrogate JSON file.

    Returns
    -------
    dict
        The parsed file.

    Raises
    ------
    SurrogateFileError
        Missing/unparsable file, other format or version, or missing keys.
    """
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        raise SurrogateFileError(p, "file not found") from None
    except OSError as exc:
        raise SurrogateFileError(p, f"cannot read ({exc.strerror or exc})") from None
    try:
        d = json.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise SurrogateFileError(
            p, f"not valid UTF-8 (byte 0x{data[exc.start]:02x} at offset {exc.start})"
        ) from None
    except json.JSONDecodeError as exc:
        raise SurrogateFileError(p, f"does not parse as JSON ({exc})") from None
    if not isinstance(d, dict) or d.get("format") != FORMAT_NAME:
        raise SurrogateFileError(p, f"not a {FORMAT_NAME} file")
    if d.get("format_version") != FORMAT_VERSION:
        raise SurrogateFileError(
            p,
            f"format_version {d.get('format_version')!r}, this grasprom reads "
            f"{FORMAT_VERSION}; rebuild it with 'grasprom surrogate build'",
        )
    missing = [k for k in _REQUIRED_KEYS if k not in d]
    if missing:
        raise SurrogateFileError(p, f"missing keys {missing}")
    return d


_STEM_RE = re.compile(r"^(?P<material>[A-Za-z0-9]+)_t(?P<thickness>\d+\.\d+)$")


def check_content(p: Path, d: Mapping[str, Any]) -> None:
    """Check the content of a parsed surrogate file (after :func:`read_json`).

    Checks a positive finite ``diameter_mm`` (at most :data:`MAX_DIAMETER_MM`), a SHA-256
    ``fe_hash``, known materials (:data:`grasprom.fe.materials.MATERIAL_NAMES`), a strictly
    increasing thickness axis within the plausible range, and per curve: a stem that matches
    its material and thickness, a contact gap in ``(0, diameter)``, finite node values, a
    strictly increasing gap axis within ``[0, diameter]``, forces in
    ``[-FORCE_TOL_N, MAX_FORCE_N]`` and stiffness ``-dF/dgap`` in
    ``[-STIFFNESS_TOL_N_PER_MM, MAX_STIFFNESS_N_PER_MM]`` (N, N/mm).

    Parameters
    ----------
    p : pathlib.Path
        The file (named in errors).
    d : mapping
        Its parsed content.

    Raises
    ------
    SurrogateFileError
        Naming the file, the material, the curve, the key and the value.
    """
    diam = _number(p, "diameter_mm", d["diameter_mm"])
    if not 0 < diam <= MAX_DIAMETER_MM:
        raise SurrogateFileError(
            p, f"diameter_mm {diam:g} mm must be > 0 and <= {MAX_DIAMETER_MM:g} mm"
        )
    if not isinstance(d["fe_hash"], str) or not _HASH_RE.match(d["fe_hash"]):
        raise SurrogateFileError(p, f"fe_hash {d['fe_hash']!r} is not a hex SHA-256 digest")
    if not isinstance(d["params"], Mapping):
        raise SurrogateFileError(p, "params must be an object")
    mats = d["materials"]
    if not isinstance(mats, Mapping) or not mats:
        raise SurrogateFileError(p, "materials must be a non-empty object")
    for m, md in mats.items():
        if m not in MATERIAL_NAMES:
            raise SurrogateFileError(
                p, f"unknown material {m!r} (known: {', '.join(MATERIAL_NAMES)})"
            )
        if not isinstance(md, Mapping):
            raise SurrogateFileError(p, f"material {m!r} must be an object")
        miss = [k for k in _REQUIRED_MAT_KEYS if k not in md]
        if miss:
            raise SurrogateFileError(p, f"material {m!r} lacks keys {miss}")
        _check_material(p, m, md, diam)


def _number(p: Path, where: str, v: Any) -> float:
    """``v`` as a finite float (SurrogateFileError naming ``where`` otherwise)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise SurrogateFileError(p, f"{where} = {v!r} is not a number")
    if not math.isfinite(v):
        raise SurrogateFileError(p, f"{where} = {v!r} is not finite")
    return float(v)


def _numbers(p: Path, where: str, v: Any) -> list[float]:
    """``v`` as a list of finite floats (SurrogateFileError naming ``where[i]`` otherwise)."""
    if not isinstance(v, list):
        raise SurrogateFileError(p, f"{where} must be a list of numbers, got {type(v).__name__}")
    return [_number(p, f"{where}[{i}]", x) for i, x in enumerate(v)]


def _increasing(p: Path, where: str, xs: Sequence[float]) -> None:
    for i, (a, b) in enumerate(zip(xs, xs[1:])):
        if b <= a:
            raise SurrogateFileError(
                p, f"{where} is not strictly increasing ({a:g} then {b:g} at index {i + 1})"
            )


def _check_material(p: Path, m: str, md: Mapping[str, Any], diam: float) -> None:
    """Axes and curves of one material (see :func:`check_content`)."""
    where = f"material {m!r}"
    ts = _numbers(p, f"{where} thickness_mm", md["thickness_mm"])
    gcs = _numbers(p, f"{where} contact_gap_mm", md["contact_gap_mm"])
    curves = md["curves"]
    if not isinstance(curves, list) or not (len(ts) == len(gcs) == len(curves) >= 1):
        n = len(curves) if isinstance(curves, list) else "no list"
        raise SurrogateFileError(
            p,
            f"{where}: thickness_mm, contact_gap_mm and curves must have one entry per "
            f"thickness (got {len(ts)}, {len(gcs)}, {n})",
        )
    _increasing(p, f"{where} thickness axis thickness_mm", ts)
    lo, hi = PLAUSIBLE_THICKNESS_MM
    for t in ts:
        if not lo <= t <= hi:
            raise SurrogateFileError(
                p, f"{where}: thickness_mm {t:g} mm is outside the plausible {lo:g}-{hi:g} mm"
            )
    for t, gc, cd in zip(ts, gcs, curves):
        _check_curve(p, m, t, gc, cd, diam)


def _check_curve(p: Path, m: str, t: float, gc: float, cd: Any, diam: float) -> None:
    """Nodes of one curve (see :func:`check_content`)."""
    if not isinstance(cd, Mapping):
        raise SurrogateFileError(p, f"material {m!r}: a curve must be an object")
    miss = [k for k in _REQUIRED_CURVE_KEYS if k not in cd]
    if miss:
        raise SurrogateFileError(p, f"material {m!r} curve lacks keys {miss}")
    where = f"material {m!r} curve {cd['stem']!r} (thickness {t:g} mm)"
    named = _STEM_RE.match(str(cd["stem"]))
    if named and (named["material"] != m or abs(float(named["thickness"]) - t) > 0.0051):
        raise SurrogateFileError(p, f"{where}: the stem disagrees with material/thickness")
    if not 0 < gc < diam:
        raise SurrogateFileError(
            p, f"{where}: contact_gap_mm {gc:g} must lie in (0, diameter {diam:g}) mm"
        )
    x = _numbers(p, f"{where}: gap_mm", cd["gap_mm"])
    y = _numbers(p, f"{where}: force_N", cd["force_N"])
    dd = _numbers(p, f"{where}: dforce_dgap_N_per_mm", cd["dforce_dgap_N_per_mm"])
    if not len(x) == len(y) == len(dd) >= 2:
        raise SurrogateFileError(
            p, f"{where}: node arrays of lengths {len(x)}, {len(y)}, {len(dd)} (equal, >= 2)"
        )
    _increasing(p, f"{where}: gap axis gap_mm", x)
    if x[0] < 0 or x[-1] > diam * (1 + 1e-12):
        raise SurrogateFileError(
            p, f"{where}: gap_mm {x[0]:g}..{x[-1]:g} mm lies outside [0, {diam:g}] mm"
        )
    bad = _first(y, lambda v: not -FORCE_TOL_N <= v <= MAX_FORCE_N)
    if bad is not None:
        raise SurrogateFileError(
            p, f"{where}: force_N[{bad}] = {y[bad]:g} N outside [0, {MAX_FORCE_N:g}] N"
        )
    bad = _first(dd, lambda v: not -STIFFNESS_TOL_N_PER_MM <= -v <= MAX_STIFFNESS_N_PER_MM)
    if bad is not None:
        raise SurrogateFileError(
            p,
            f"{where}: stiffness -dforce_dgap_N_per_mm[{bad}] = {-dd[bad]:g} N/mm outside "
            f"[0, {MAX_STIFFNESS_N_PER_MM:g}] N/mm",
        )


def _first(values: Sequence[float], pred) -> int | None:
    """Index of the first value for which ``pred`` holds, None if none."""
    return next((i for i, v in enumerate(values) if pred(v)), None)


def curve_from_dict(p: Path, material: str, t: Any, gc: Any, cd: Mapping[str, Any]) -> Curve:
    """One :class:`~grasprom.surrogate.build.Curve` of a surrogate file, validated.

    Parameters
    ----------
    p : pathlib.Path
        The file (named in errors).
    material : str
        Material key (named in errors).
    t, gc : float-like
        Thickness and wall-contact gap of the curve, mm.
    cd : mapping
        The curve's entry in the file.

    Returns
    -------
    Curve

    Raises
    ------
    SurrogateFileError
        Missing keys, or node arrays of unequal length, shorter than 2 or not increasing.
    """
    miss = [k for k in _REQUIRED_CURVE_KEYS if k not in cd]
    if miss:
        raise SurrogateFileError(p, f"material {material!r} curve lacks keys {miss}")
    x = tuple(float(v) for v in cd["gap_mm"])
    y = tuple(float(v) for v in cd["force_N"])
    dd = tuple(float(v) for v in cd["dforce_dgap_N_per_mm"])
    if not (len(x) == len(y) == len(dd) >= 2) or any(b <= a for a, b in zip(x, x[1:])):
        raise SurrogateFileError(p, f"curve {cd['stem']!r}: bad node arrays (length/order)")
    return Curve(
        str(cd["stem"]),
        float(t),
        float(gc),
        x,
        y,
        dd,
        int(cd.get("n_fe_points", 0)),
        float(cd.get("fit_error", 0.0)),
    )


def curves_from_dict(p: Path, materials: Mapping[str, Any]) -> dict[str, list[Curve]]:
    """The curves of every material of a surrogate file (its ``"materials"`` entry).

    Parameters
    ----------
    p : pathlib.Path
        The file (named in errors).
    materials : mapping
        The ``"materials"`` entry.

    Returns
    -------
    dict of str to list of Curve

    Raises
    ------
    SurrogateFileError
        Missing keys, bad node arrays, or a curve count that differs from the thickness count.
    """
    curves: dict[str, list[Curve]] = {}
    for m, md in materials.items():
        miss = [k for k in _REQUIRED_MAT_KEYS if k not in md]
        if miss:
            raise SurrogateFileError(p, f"material {m!r} lacks keys {miss}")
        lst = [
            curve_from_dict(p, m, t, gc, cd)
            for t, gc, cd in zip(md["thickness_mm"], md["contact_gap_mm"], md["curves"])
        ]
        if len(lst) != len(md["thickness_mm"]):
            raise SurrogateFileError(p, f"material {m!r}: curve count mismatch")
        curves[m] = lst
    return curves


def check_fe_hash(p: Path, fe_hash: str, fe_dir: str | os.PathLike[str]) -> None:
    """Check that a surrogate file was built from the FE sweep ``fe_dir``.

    Parameters
    ----------
    p : pathlib.Path
        The file (named in errors).
    fe_hash : str
        The FE hash the file records.
    fe_dir : str or os.PathLike
        The FE sweep directory.

    Raises
    ------
    SurrogateFileError
        If :func:`~grasprom.surrogate.fedata.fe_dir_hash` of ``fe_dir`` differs.
    """
    h = fe_dir_hash(fe_dir)
    if h != fe_hash:
        raise SurrogateFileError(
            p,
            f"FE data hash mismatch: the file was built from FE data "
            f"{fe_hash[:12]}..., {fe_dir} hashes to {h[:12]}...; rebuild it",
        )
