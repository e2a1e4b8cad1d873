"""Figures of a surrogate: force and stiffness vs gap, with the FE points over them (PNG).

Drawn with matplotlib's object-oriented API (no pyplot state, the caller's backend is left
alone). Units: gaps in mm, forces in N, stiffness in N/mm.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from grasprom.fe.materials import material_label
from grasprom.fe.plots import log_gap_axis
from grasprom.surrogate.fedata import FECase, read_fe_cases
from grasprom.surrogate.table import Surrogate
from grasprom.surrogate.validation import fe_point_stiffness


def plot_surrogate(
    s: Surrogate,
    path: str | os.PathLike[str],
    fe_dir: str | os.PathLike[str] | None = None,
    *,
    n_gap: int = 600,
) -> Path:
    """Force (log scale) and stiffness vs gap, one panel column per material (PNG).

    Curves are drawn at the thicknesses of the FE cases in ``fe_dir`` (else at the grid
    thicknesses), with the FE points over them; the gap axis spans first touch down to the
    closed height, zoomed on the wall contact in the lower row.

    Parameters
    ----------
    s : Surrogate
    path : str or os.PathLike
        PNG file to write.
    fe_dir : str or os.PathLike, optional
        FE cases to overlay (e.g. ``fe_data/holdout``).
    n_gap : int
        Evaluation points per curve.

    Returns
    -------
    pathlib.Path
    """
    import matplotlib
    from matplotlib.figure import Figure

    cases: list[FECase] = []
    if fe_dir is not None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            cases, _ = read_fe_cases(fe_dir)
    mats = list(s.materials)
    fig = Figure(figsize=(5.0 * len(mats), 11.0))
    axes = fig.subplots(3, len(mats), squeeze=False)
    cmap = matplotlib.colormaps["viridis"]
    for col, m in enumerate(mats):
        lo, hi = s.thickness_range(m)
        mc = [c for c in cases if c.material == m and lo <= c.thickness_mm <= hi]
        ts = [c.thickness_mm for c in mc] if mc else list(s.thicknesses(m))
        _draw_surrogate_curves(axes[:, col], s, m, ts, n_gap, cmap)
        _draw_fe_points(axes[:, col], mc, lo, hi, cmap)
        _label_column(axes[:, col], s, m)
    fig.suptitle(f"Surrogate ({s.source}) vs FE ({fe_dir})")
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    return out


def _thickness_colour(cmap: Any, t: float, lo: float, hi: float) -> Any:
    """Colour of thickness ``t`` (mm) on ``cmap`` over the swept range ``[lo, hi]`` (mm)."""
    return cmap(0.0 if hi == lo else (t - lo) / (hi - lo))


def _draw_surrogate_curves(
    column: Sequence[Any], s: Surrogate, m: str, ts: Sequence[float], n_gap: int, cmap: Any
) -> None:
    """Surrogate force, force near wall contact and stiffness of material ``m`` at ``ts`` (mm)."""
    lo, hi = s.thickness_range(m)
    x_lo = min(c.gap_mm[0] for c in s.curves(m))
    for t in ts:
        col_t = _thickness_colour(cmap, t, lo, hi)
        g = np.concatenate(
            [
                np.geomspace(x_lo, s.diameter_mm, n_gap),
                np.linspace(2 * t - 0.6, 2 * t + 0.3, n_gap),
            ]
        )
        g.sort()
        f, extrap = s.force(g, t, m, return_flag=True)
        k = s.stiffness(g, t, m)
        keep = (f > 0) & ~extrap
        column[0].plot(g[keep], f[keep], "-", color=col_t, lw=1.0, label=f"{t:.2f} mm")
        beyond = (f > 0) & extrap  # below the FE data (closed height or force cap reached)
        column[0].plot(g[beyond], f[beyond], "--", color=col_t, lw=0.6)
        column[1].plot(g - 2 * t, f, "-", color=col_t, lw=1.0)
        column[2].plot(g[k > 0], k[k > 0], "-", color=col_t, lw=1.0)


def _draw_fe_points(
    column: Sequence[Any], cases: Sequence[FECase], lo: float, hi: float, cmap: Any
) -> None:
    """FE force, force near wall contact and point stiffness of ``cases`` (open circles)."""
    for c in cases:
        col_t = _thickness_colour(cmap, c.thickness_mm, lo, hi)
        keep = c.force_N > 1e-6  # the numerical zero before first touch is not drawn
        column[0].plot(c.gap_mm[keep], c.force_N[keep], "o", ms=2.5, mfc="none", color=col_t)
        column[1].plot(
            c.gap_mm - 2 * c.thickness_mm, c.force_N, "o", ms=2.5, mfc="none", color=col_t
        )
        kf = fe_point_stiffness(c.gap_mm, c.force_N)
        column[2].plot(c.gap_mm[kf > 0], kf[kf > 0], "o", ms=2.0, mfc="none", color=col_t)


def _label_column(column: Sequence[Any], s: Surrogate, m: str) -> None:
    """Scales, limits, titles, labels, legend and grid of the three panels of material ``m``."""
    ax = column[0]
    ax.set_yscale("log")
    log_gap_axis(ax)
    ax.set_title(f"{material_label(m)}, {s.scheme} scheme", fontsize=9)
    ax.text(0.02, 0.03, "lines: surrogate (dashed: extrapolated past the FE data)\no: FE",
            transform=ax.transAxes, fontsize=6, va="bottom")  # fmt: skip
    ax.set_xlabel("jaw gap (mm)")
    ax.set_ylabel("force (N)")
    ax.legend(fontsize=6, ncol=2, title="thickness", title_fontsize=6)
    ax = column[1]
    ax.set_xlim(-0.5, 0.3)
    ax.set_ylim(0, 2 * s.params.force_ref_N)
    ax.set_title("haptic range, zoom on wall contact")
    ax.set_xlabel("gap - 2 t (mm)")
    ax.set_ylabel("force (N)")
    ax = column[2]
    ax.set_yscale("log")
    log_gap_axis(ax)
    ax.set_title("stiffness -dF/dgap (FE: larger adjacent secant)")
    ax.set_xlabel("jaw gap (mm)")
    ax.set_ylabel("stiffness (N/mm)")
    for a in column:
        a.grid(True, alpha=0.3, which="both")


def surrogate_residuals(s: Surrogate, cases: Sequence[FECase]) -> list[dict[str, Any]]:
    """Surrogate minus FE force at every FE point of ``cases`` (the data of the residual plot).

    Parameters
    ----------
    s : Surrogate
    cases : sequence of FECase
        FE cases of materials of ``s`` inside its thickness range (others are skipped).

    Returns
    -------
    list of dict
        One per case: ``stem``, ``material``, ``thickness_mm``, ``gap_mm`` (the FE gaps),
        ``residual_N`` (``s.force(gap) - F_FE``, N), ``residual_pct`` (of the haptic scale
        ``s.params.force_ref_N``), ``haptic`` (first touch to the first load step at which the
        FE force reaches ``force_ref_N``) and ``steep`` (FE point stiffness at least
        ``s.params.steep_N_per_mm``, where the error figures judge the gap, not the force).
    """
    out = []
    for c in cases:
        if c.material not in s.materials:
            continue
        lo, hi = s.thickness_range(c.material)
        if not lo <= c.thickness_mm <= hi:
            continue
        res = s.force(c.gap_mm, c.thickness_mm, c.material) - c.force_N
        reach = np.flatnonzero(c.force_N >= s.params.force_ref_N)
        haptic = np.arange(c.gap_mm.size) <= (reach[0] if reach.size else c.gap_mm.size)
        steep = fe_point_stiffness(c.gap_mm, c.force_N) >= s.params.steep_N_per_mm
        out.append({"stem": c.stem, "material": c.material, "thickness_mm": c.thickness_mm,
                    "gap_mm": c.gap_mm, "residual_N": res,
                    "residual_pct": 100.0 * res / s.params.force_ref_N, "haptic": haptic,
                    "steep": steep})  # fmt: skip
    return out


def plot_residuals(
    s: Surrogate, path: str | os.PathLike[str], fe_dir: str | os.PathLike[str]
) -> Path:
    """Residual plot surrogate - FE at the FE points of ``fe_dir`` (PNG), per material.

    Top row: ``F_surrogate - F_FE`` in N over the jaw gap (symlog force axis, log gap axis).
    Bottom row: the same in % of the haptic scale over the haptic range (first touch to the
    FE force ``force_ref_N``), with the 3 % target band; points where the FE is steeper than
    ``steep_N_per_mm`` are crosses (the error table judges them by the gap error at equal
    force).  Colours by thickness; each line's ``gid`` is ``"<stem> N"`` or ``"<stem> %"``.

    Parameters
    ----------
    s : Surrogate
    path : str or os.PathLike
        PNG file to write.
    fe_dir : str or os.PathLike
        FE cases to compare with (held-out cases when available).

    Returns
    -------
    pathlib.Path
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cases, _ = read_fe_cases(fe_dir)
    fig = residual_figure(s, surrogate_residuals(s, cases), f"Surrogate - FE ({fe_dir})")
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    return out


def residual_figure(s: Surrogate, rows: Sequence[dict[str, Any]], title: str) -> Any:
    """The figure of :func:`plot_residuals` from :func:`surrogate_residuals` rows."""
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from grasprom.surrogate.validation import CHECK_TOLERANCE

    mats = [m for m in s.materials if any(r["material"] == m for r in rows)] or list(s.materials)
    fig = Figure(figsize=(4.6 * len(mats), 7.0))
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, len(mats), squeeze=False)
    cmap = matplotlib.colormaps["viridis"]
    tol = CHECK_TOLERANCE["force_max_pct"]
    for col, m in enumerate(mats):
        lo, hi = s.thickness_range(m)
        top, bottom = axes[0, col], axes[1, col]
        for r in (r for r in rows if r["material"] == m):
            c = _thickness_colour(cmap, r["thickness_mm"], lo, hi)
            g, hap, st = r["gap_mm"], r["haptic"], r["steep"]
            top.plot(g, r["residual_N"], "o-", ms=2.5, lw=0.6, mfc="none", color=c,
                     label=f"{r['thickness_mm']:.2f} mm", gid=f"{r['stem']} N")  # fmt: skip
            keep = hap & ~st
            bottom.plot(g[keep], r["residual_pct"][keep], "o", ms=2.5, mfc="none", color=c,
                        gid=f"{r['stem']} %")  # fmt: skip
            bottom.plot(g[hap & st], r["residual_pct"][hap & st], "x", ms=3, color=c)
        _label_residual_column(top, bottom, s, m, tol)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def _label_residual_column(top: Any, bottom: Any, s: Surrogate, m: str, tol: float) -> None:
    """Scales, target band, titles and labels of the two residual panels of material ``m``."""
    top.set_yscale("symlog", linthresh=0.01)
    top.axhline(0.0, color="k", lw=0.6)
    top.set_title(f"{material_label(m)}: surrogate - FE", fontsize=9)
    top.set_xlabel("jaw gap (mm)")
    top.set_ylabel("force residual (N)")
    top.legend(fontsize=6, title="thickness", title_fontsize=6)
    bottom.axhspan(-tol, tol, color="C2", alpha=0.15, label=f"target +-{tol:g} %")
    bottom.axhline(0.0, color="k", lw=0.6)
    bottom.set_title(f"haptic range, % of {s.params.force_ref_N:g} N (x: steep, judged by gap)",
                     fontsize=8)  # fmt: skip
    bottom.set_xlabel("jaw gap (mm)")
    bottom.set_ylabel("force residual (% of the haptic scale)")
    bottom.legend(fontsize=6)
    for a in (top, bottom):
        log_gap_axis(a)
        a.grid(True, alpha=0.3, which="both")
