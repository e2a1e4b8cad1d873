"""The versioned JSON file of a surrogate (:meth:`~grasprom.surrogate.table.Surrogate.save`):
layout, encoding of the curves, and validation of a file read back.

Units: gaps and thicknesses in mm, forces in N, dF/dgap in N/mm.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from grasprom.surrogate.build import BuildParams, Curve
from grasprom.surrogate.fedata import fe_dir_hash

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
        d = json.loads(p.read_text())
    except FileNotFoundError:
        raise SurrogateFileError(p, "file not found") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
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
