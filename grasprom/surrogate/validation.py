"""Accuracy of a surrogate against FE cases: force error at equal gap where the tissue is soft,
gap error at equal force where it is steep; per case, per material, leave-one-thickness-out,
and as a plain-text table.

Units: gaps in mm, forces in N, stiffness in N/mm, force errors in % of full scale.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from grasprom.surrogate.build import SCHEMES, BuildParams
from grasprom.surrogate.fedata import FECase

if TYPE_CHECKING:  # annotations only: the surrogate module imports this one
    from grasprom.surrogate.table import Surrogate


def fe_point_stiffness(gap_mm: np.ndarray, force_N: np.ndarray) -> np.ndarray:
    """FE stiffness ``-dF/dgap`` at each load step, N/mm: the larger adjacent secant.

    Parameters
    ----------
    gap_mm, force_N : numpy.ndarray
        The FE curve in load-step order (mm, N).

    Returns
    -------
    numpy.ndarray
        N/mm per point (the steeper side counts, so a point at the slope jump of the walls
        meeting is classed as steep).
    """
    sec = -np.diff(force_N) / np.diff(gap_mm)
    k = np.empty(len(gap_mm))
    k[0] = sec[0]
    k[-1] = sec[-1]
    k[1:-1] = np.maximum(sec[:-1], sec[1:])
    return k


def invert_gap(
    s: Surrogate,
    force_N: np.ndarray,
    thickness_mm: float,
    material: str,
    lo_mm: float,
    iters: int = 60,
) -> np.ndarray:
    """Gap (mm) where the surrogate force reaches ``force_N`` (vectorised bisection).

    Parameters
    ----------
    s : Surrogate
    force_N : numpy.ndarray
        Target forces in N (> 0).
    thickness_mm : float
        Thickness in mm.
    material : str
        Material key.
    lo_mm : float
        Lower bracket in mm (the surrogate force there must exceed the targets).
    iters : int
        Bisection steps.

    Returns
    -------
    numpy.ndarray
        Gaps in mm (largest gap with ``F >= force_N`` up to bisection accuracy).
    """
    target = np.asarray(force_N, dtype=float)
    lo = np.full(target.shape, float(lo_mm))
    hi = np.full(target.shape, s.diameter_mm)
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        above = s.force(mid, thickness_mm, material) >= target
        lo = np.where(above, mid, lo)
        hi = np.where(above, hi, mid)
    return 0.5 * (lo + hi)


def _summ(force_pct: list[np.ndarray], gap_mm: list[np.ndarray]) -> dict[str, Any]:
    fp = np.concatenate(force_pct) if force_pct else np.zeros(0)
    gp = np.concatenate(gap_mm) if gap_mm else np.zeros(0)
    return {
        "force_rms_pct": float(np.sqrt(np.mean(fp**2))) if fp.size else None,
        "force_max_pct": float(np.max(np.abs(fp))) if fp.size else None,
        "n_force": int(fp.size),
        "gap_rms_mm": float(np.sqrt(np.mean(gp**2))) if gp.size else None,
        "gap_max_mm": float(np.max(np.abs(gp))) if gp.size else None,
        "n_gap": int(gp.size),
    }


def case_errors(s: Surrogate, case: FECase, params: BuildParams) -> dict[str, dict]:
    """Errors of the surrogate on one FE case, haptic and full range.

    Points with FE stiffness (:func:`fe_point_stiffness`) below ``params.steep_N_per_mm``
    get the force error at equal gap in % of full scale (``force_ref_N`` in the haptic range,
    the case's ``force_cap_N`` in the full range); steeper points get the gap error at equal
    force in mm. The haptic range is first touch to the first load step where the FE force
    reaches ``force_ref_N``.

    Parameters
    ----------
    s : Surrogate
    case : FECase
    params : BuildParams

    Returns
    -------
    dict
        ``{"haptic": {...}, "full": {...}}`` each with the raw arrays
        ``force_pct``, ``gap_mm`` and ``n_extrapolated``.
    """
    g, f = case.gap_mm, case.force_N
    k = fe_point_stiffness(g, f)
    fs, flag = s.force(g, case.thickness_mm, case.material, return_flag=True)
    steep = k >= params.steep_N_per_mm
    reach = np.flatnonzero(f >= params.force_ref_N)
    n_hap = (reach[0] + 1) if reach.size else g.size
    hap = np.zeros(g.size, bool)
    hap[:n_hap] = True
    gap_err = np.zeros(g.size)
    if steep.any():
        lo = min(float(g.min()), s.curves(case.material)[0].gap_mm[0]) - 2.0
        gi = invert_gap(s, f[steep], case.thickness_mm, case.material, lo)
        gap_err[steep] = gi - g[steep]
    out = {}
    for name, sel, fsc in (
        ("haptic", hap, params.force_ref_N),
        ("full", np.ones_like(hap), case.force_cap_N),
    ):
        out[name] = {
            "force_pct": 100.0 * (fs - f)[sel & ~steep] / fsc,
            "gap_mm": gap_err[sel & steep],
            "n_extrapolated": int((flag & sel).sum()),
        }
    return out


def error_figures(
    s: Surrogate, cases: Sequence[FECase], params: BuildParams | None = None
) -> dict[str, Any]:
    """Error figures of a surrogate on FE cases, per material and overall.

    Parameters
    ----------
    s : Surrogate
        The surrogate (its scheme is used).
    cases : sequence of FECase
        Reference FE cases (not necessarily grid thicknesses).
    params : BuildParams, optional
        Thresholds (default ``s.params``).

    Returns
    -------
    dict
        ``{"haptic": {"all": summary, "<material>": summary, ...}, "full": {...},
        "cases": [per-case summaries]}``, a summary holding ``force_rms_pct``,
        ``force_max_pct``, ``n_force``, ``gap_rms_mm``, ``gap_max_mm``, ``n_gap`` and
        ``n_extrapolated``.
    """
    params = params or s.params
    return _aggregate(s.scheme, ((s, c) for c in cases), params)


def _aggregate(scheme: str, pairs, params: BuildParams) -> dict[str, Any]:
    """Error figures over ``(surrogate, case)`` pairs: per material, all, and per case."""
    acc: dict[str, dict[str, tuple[list, list, list]]] = {"haptic": {}, "full": {}}
    per_case = []
    for sur, c in pairs:
        e = case_errors(sur, c, params)
        row: dict[str, Any] = {
            "stem": c.stem,
            "material": c.material,
            "thickness_mm": c.thickness_mm,
        }
        for rng in ("haptic", "full"):
            r = e[rng]
            for key in (c.material, "all"):
                a = acc[rng].setdefault(key, ([], [], []))
                a[0].append(r["force_pct"])
                a[1].append(r["gap_mm"])
                a[2].append(r["n_extrapolated"])
            row[rng] = {
                **_summ([r["force_pct"]], [r["gap_mm"]]),
                "n_extrapolated": r["n_extrapolated"],
            }
        per_case.append(row)
    out: dict[str, Any] = {"scheme": scheme}
    for rng, d in acc.items():
        out[rng] = {
            key: {**_summ(a[0], a[1]), "n_extrapolated": int(sum(a[2]))} for key, a in d.items()
        }
    out["cases"] = per_case
    return out


def leave_one_out(
    s: Surrogate, cases: Sequence[FECase], schemes: Sequence[str] = SCHEMES
) -> dict[str, Any]:
    """Leave-one-thickness-out error figures over the interior grid thicknesses.

    Each interior curve is dropped in turn (its neighbours are then 2 grid steps apart) and
    the reduced surrogate is compared with that FE case (:func:`error_figures`).

    Parameters
    ----------
    s : Surrogate
        Surrogate built from ``cases``.
    cases : sequence of FECase
        The FE cases of the grid.
    schemes : sequence of str
        Schemes to measure.

    Returns
    -------
    dict
        ``{"schemes": {scheme: error_figures-like dict}}``.
    """
    res = {}
    for sc in schemes:
        base = s.with_scheme(sc)

        def pairs(base=base):
            for c in cases:
                ts = base.thicknesses(c.material)
                if ts[0] < c.thickness_mm < ts[-1]:
                    yield base.without(c.material, c.thickness_mm), c

        res[sc] = _aggregate(sc, pairs(), base.params)
    return {"schemes": res}


CHECK_TOLERANCE = {"force_max_pct": 3.0, "gap_max_mm": 0.02}
"""Default pass limits of :meth:`Surrogate.check`: the issue 3 targets, largest haptic-range
force error 3 % of full scale and largest gap error 0.02 mm (own scheme, all materials)."""


def check_verdict(result: Mapping[str, Any]) -> tuple[bool, list[str]]:
    """Whether a :meth:`Surrogate.check` result is within its tolerance, and why not.

    Parameters
    ----------
    result : mapping
        Output of :meth:`Surrogate.check` (``tolerance`` defaults to :data:`CHECK_TOLERANCE`
        on the first scheme for results without one).

    Returns
    -------
    passed : bool
        True if the haptic-range error figures of the tolerance's scheme (all materials) are
        within the limits, at least one FE point was compared, and the FE hash does not
        mismatch.
    failures : list of str
        One line per failed criterion (empty if passed).
    """
    tol = dict(result.get("tolerance") or {})
    schemes = result.get("schemes") or {}
    scheme = tol.get("scheme") or next(iter(schemes), None)
    fig = (schemes.get(scheme) or {}).get(tol.get("range", "haptic"), {}).get("all")
    failures = []
    if not fig or not (fig.get("n_force", 0) or fig.get("n_gap", 0)):
        failures.append("no FE point within the surrogate's materials and thickness range")
    else:
        for key, unit in (("force_max_pct", "%"), ("gap_max_mm", "mm")):
            limit = float(tol.get(key, CHECK_TOLERANCE[key]))
            v = fig.get(key)
            if v is not None and not v <= limit:
                failures.append(
                    f"{scheme} haptic {key} {v:.4g} {unit} > tolerance {limit:g} {unit}"
                )
    h = result.get("fe_hash") or {}
    if h.get("match") is False:
        failures.append(
            f"fe_hash {str(h.get('file'))[:12]}... of the file != {str(h.get('source_hash'))[:12]}"
            f"... of its FE source {h.get('source')}: rebuild the surrogate"
        )
    return not failures, failures


def check_passed(result: Mapping[str, Any]) -> bool:
    """True if a :meth:`Surrogate.check` result is within its tolerance (see
    :func:`check_verdict`); the CLI exit code of ``grasprom surrogate check``.

    Parameters
    ----------
    result : mapping
        Output of :meth:`Surrogate.check`.

    Returns
    -------
    bool
    """
    return check_verdict(result)[0]


def format_check(result: Mapping[str, Any]) -> str:
    """One verdict line (and one line per failure) of a :meth:`Surrogate.check` result.

    Parameters
    ----------
    result : mapping
        Output of :meth:`Surrogate.check`.

    Returns
    -------
    str
        ``"check PASSED (...)"`` or ``"check FAILED: ..."`` lines.
    """
    passed, failures = check_verdict(result)
    tol = {**CHECK_TOLERANCE, **dict(result.get("tolerance") or {})}
    limits = (
        f"tolerance: {tol.get('scheme', '?')} haptic force max {tol['force_max_pct']:g} %, "
        f"gap max {tol['gap_max_mm']:g} mm"
    )
    match = (result.get("fe_hash") or {}).get("match")
    hash_txt = {True: "fe_hash matches", False: "fe_hash MISMATCH", None: "fe_hash not checked"}
    if passed:
        return f"check PASSED ({limits}; {hash_txt[match]})"
    return "\n".join([f"check FAILED ({limits}; {hash_txt[match]}):", *failures])


def format_errors(fig: Mapping[str, Any], title: str = "") -> str:
    """Plain-text table of error figures (output of :func:`error_figures`, or of
    :meth:`Surrogate.check` / :func:`leave_one_out` with several schemes).

    Parameters
    ----------
    fig : mapping
        Error figures.
    title : str
        Heading line.

    Returns
    -------
    str
    """
    figs = fig["schemes"] if "schemes" in fig else {fig.get("scheme", "?"): fig}
    lines = [title] if title else []
    hdr = (
        f"{'scheme':8s} {'range':7s} {'material':8s} {'F rms %':>8s} {'F max %':>8s} "
        f"{'nF':>5s} {'gap rms':>8s} {'gap max':>8s} {'nG':>5s} {'extrap':>6s}"
    )
    lines.append(hdr)
    lines.append("-" * len(hdr))

    def f(v, fmt):
        return "-" if v is None else format(v, fmt)

    for sc, fg in figs.items():
        for rng in ("haptic", "full"):
            rows = fg.get(rng, {})
            for mat in sorted(rows, key=lambda k: (k == "all", k)):
                r = rows[mat]
                lines.append(
                    f"{sc:8s} {rng:7s} {mat:8s} {f(r['force_rms_pct'], '8.3f')} "
                    f"{f(r['force_max_pct'], '8.3f')} {r['n_force']:5d} "
                    f"{f(r['gap_rms_mm'], '8.4f')} {f(r['gap_max_mm'], '8.4f')} "
                    f"{r['n_gap']:5d} {r.get('n_extrapolated', 0):6d}"
                )
    lines.append(
        "F: force error at equal gap, % of full scale (haptic: force_ref_N, full: "
        "force cap), where FE stiffness < steep_N_per_mm; gap: gap error at equal "
        "force (mm) where steeper; extrap: points below the FE gap range (flagged)"
    )
    return "\n".join(lines)
