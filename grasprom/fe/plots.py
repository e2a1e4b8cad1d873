"""Figures of a sweep directory: force vs jaw gap per material and thickness (PNG).

Drawn with matplotlib's object-oriented API (no pyplot state, the caller's backend is left
alone). Units: gaps in mm, forces in N.
"""

from __future__ import annotations

import os
from pathlib import Path

from grasprom.fe import datafiles as df
from grasprom.fe.materials import material_label

GAP_TICKS_MM = (1.0, 1.5, 2.0, 3.0, 5.0, 10.0, 20.0, 30.0)
"""Labelled ticks of a logarithmic jaw-gap axis (mm)."""


def log_gap_axis(ax) -> None:
    """Make ``ax``'s x axis a logarithmic jaw-gap axis labelled at :data:`GAP_TICKS_MM` (mm).

    A bare log axis over 1.5-30 mm carries a single labelled decade tick; these ticks read as
    plain millimetres and are shared by the FE, surrogate and residual figures.
    """
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter

    ax.set_xscale("log")
    ax.xaxis.set_major_locator(FixedLocator(GAP_TICKS_MM))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:g}"))
    ax.xaxis.set_minor_formatter(NullFormatter())


def plot_sweep(
    directory: str | os.PathLike[str],
    path: str | os.PathLike[str],
    *,
    logy: bool = False,
    haptic_force_N: float = 50.0,
) -> Path:
    """Plot force (N) vs jaw gap (mm), one line per thickness, one column per material.

    Top row: the whole closing stroke; bottom row: a linear zoom on the haptic range
    (0 to ``haptic_force_N``) where the walls meet.

    Parameters
    ----------
    directory : str or os.PathLike
        Sweep directory.
    path : str or os.PathLike
        PNG file to write.
    logy : bool
        Logarithmic force axis on the top row (non-positive forces are dropped).
    haptic_force_N : float
        Upper force limit of the zoomed bottom row (N).

    Returns
    -------
    pathlib.Path
        The PNG written.
    """
    import matplotlib
    from matplotlib.figure import Figure

    data = df.load_sweep(directory)
    mats = sorted(data["material"].unique()) if len(data) else []
    n = max(len(mats), 1)
    fig = Figure(figsize=(4.8 * n, 7.6))
    axes = fig.subplots(2, n, sharey="row", squeeze=False)
    thicknesses = sorted(data["thickness_mm"].unique()) if len(data) else []
    cmap = matplotlib.colormaps["viridis"]
    tmin, tmax = (min(thicknesses), max(thicknesses)) if thicknesses else (0.0, 1.0)
    for col, mat in enumerate(mats):
        sub = data[data["material"] == mat]
        top, zoom = axes[0][col], axes[1][col]
        for t, case in sub.groupby("thickness_mm", sort=True):
            x = case["gap_mm"].to_numpy(float)
            y = case["force_N"].to_numpy(float)
            c = cmap(0.0 if tmax == tmin else (t - tmin) / (tmax - tmin))
            style = "-" if (case["status"] == "complete").all() else "--"
            keep = y > 1e-6 if logy else slice(None)  # no numerical zero at first touch
            top.plot(x[keep], y[keep], style, color=c, lw=1.2, label=f"t = {t:.2f} mm")
            zoom.plot(x, y, style, color=c, lw=1.2)
        top.set_title(f"material: {material_label(mat)}")
        if logy:
            top.set_yscale("log")
        zoom.set_ylim(0.0, haptic_force_N)
        zoom.set_xlim(1.0, 2.2 * tmax + 1.0 if thicknesses else 6.0)
        zoom.set_title(f"{mat}: haptic range, walls meeting at gap ~ 2t", fontsize=9)
        for ax in (top, zoom):
            ax.set_xlabel("jaw gap (mm)")
            ax.grid(True, alpha=0.3)
        log_gap_axis(top)  # as the surrogate figure: gap increasing to the right
    axes[0][0].set_ylabel("jaw force (N)")
    axes[1][0].set_ylabel("jaw force (N), linear")
    if mats:
        partial = len(data) and (data["status"] != "complete").any()
        axes[0][-1].legend(fontsize=7, ncol=2, title="dashed: partial" if partial else None,
                           title_fontsize=7)  # fmt: skip
    fig.suptitle(f"Force vs gap: {Path(directory)}")
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    return out
