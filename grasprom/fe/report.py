"""Report on a sweep directory: a summary table (text + CSV) and force-gap plots (PNG).

Units: gaps in mm, forces in N.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from grasprom.fe import datafiles as df

DEFAULT_GAPS_MM = (20.0, 10.0, 5.0, 3.0, 2.0)
"""Jaw gaps in mm at which the report tabulates the force."""


@dataclass(frozen=True)
class ReportFiles:
    """Outputs of :func:`make_report`.

    Attributes
    ----------
    table_csv : pathlib.Path
        Summary table as CSV.
    plot_png : pathlib.Path
        Force vs gap plot.
    text : str
        The summary table as plain text.
    """

    table_csv: Path
    plot_png: Path
    text: str


def force_at_gap(gap_mm: np.ndarray, force_N: np.ndarray, gap: float) -> float:
    """Force in N at jaw gap ``gap`` (mm), linearly interpolated along the load path.

    Returns NaN if the case never reached ``gap`` or started below it (no extrapolation).
    """
    g = np.asarray(gap_mm, dtype=float)
    f = np.asarray(force_N, dtype=float)
    if g.size == 0 or gap < np.nanmin(g) or gap > np.nanmax(g):
        return float("nan")
    order = np.argsort(g)
    return float(np.interp(gap, g[order], f[order]))


def _gap_col(g: float) -> str:
    return f"force_N_at_{g:g}mm"


def sweep_table(
    directory: str | os.PathLike[str], gaps_mm: Sequence[float] = DEFAULT_GAPS_MM
) -> pd.DataFrame:
    """Summary of every case a sweep directory knows of, one row per case.

    Parameters
    ----------
    directory : str or os.PathLike
        Sweep directory.
    gaps_mm : sequence of float
        Jaw gaps (mm) at which to report the force.

    Returns
    -------
    pandas.DataFrame
        Columns ``material``, ``thickness_mm``, ``status`` (``complete``, ``partial``,
        ``failed`` or ``missing``), ``steps``, ``last_gap_mm``, ``force_N_at_<g>mm`` for each
        gap (NaN where the case did not reach it), ``max_force_N``.

    Raises
    ------
    FileNotFoundError
        If ``directory`` does not exist or holds no case.
    CorruptCaseError
        If a finished case fails validation.
    """
    d = Path(directory)
    if not d.is_dir():
        raise FileNotFoundError(f"sweep directory {d} does not exist")
    rows = []
    for stem in df.known_stems(d):
        files = df.case_files(d, stem)
        parsed = df.parse_stem(stem) or (stem, float("nan"))
        row: dict[str, object] = {"material": parsed[0], "thickness_mm": parsed[1]}
        if files.json.exists():
            case = df.read_case(files.json)
            t = case.table
            row.update(
                material=case.meta["material"],
                thickness_mm=float(case.meta["thickness_mm"]),
                status=case.meta["status"],
                steps=len(t),
                last_gap_mm=float(t["gap_mm"].min()) if len(t) else float("nan"),
            )
            for g in gaps_mm:
                row[_gap_col(g)] = force_at_gap(t["gap_mm"].to_numpy(), t["force_N"].to_numpy(), g)
            row["max_force_N"] = float(t["force_N"].max()) if len(t) else float("nan")
        else:
            failed = (d / f"{stem}{df.ERROR_SUFFIX}").exists()
            row.update(status="failed" if failed else "missing", steps=0, last_gap_mm=float("nan"))
            for g in gaps_mm:
                row[_gap_col(g)] = float("nan")
            row["max_force_N"] = float("nan")
        rows.append(row)
    if not rows:
        raise FileNotFoundError(f"sweep directory {d} holds no case files")
    table = pd.DataFrame(rows)
    return table.sort_values(["material", "thickness_mm"], kind="stable").reset_index(drop=True)


def format_table(table: pd.DataFrame) -> str:
    """Plain-text rendering of :func:`sweep_table` output."""
    return table.to_string(index=False, float_format=lambda x: f"{x:.4g}", na_rep="-")


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

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    data = df.load_sweep(directory)
    mats = sorted(data["material"].unique()) if len(data) else []
    n = max(len(mats), 1)
    fig, axes = plt.subplots(2, n, figsize=(4.8 * n, 7.6), sharey="row", squeeze=False)
    thicknesses = sorted(data["thickness_mm"].unique()) if len(data) else []
    cmap = plt.get_cmap("viridis")
    tmin, tmax = (min(thicknesses), max(thicknesses)) if thicknesses else (0.0, 1.0)
    for col, mat in enumerate(mats):
        sub = data[data["material"] == mat]
        top, zoom = axes[0][col], axes[1][col]
        for t, case in sub.groupby("thickness_mm", sort=True):
            x = case["gap_mm"].to_numpy(float)
            y = case["force_N"].to_numpy(float)
            c = cmap(0.0 if tmax == tmin else (t - tmin) / (tmax - tmin))
            style = "-" if (case["status"] == "complete").all() else "--"
            keep = y > 0 if logy else slice(None)
            top.plot(x[keep], y[keep], style, color=c, lw=1.2, label=f"t = {t:.2f} mm")
            zoom.plot(x, y, style, color=c, lw=1.2)
        top.set_title(f"material: {mat}")
        if logy:
            top.set_yscale("log")
        zoom.set_ylim(0.0, haptic_force_N)
        zoom.set_xlim(2.2 * tmax + 1.0 if thicknesses else 6.0, 1.0)
        zoom.set_title(f"{mat}: haptic range, walls meeting at gap ~ 2t", fontsize=9)
        for ax in (top, zoom):
            ax.set_xlabel("jaw gap (mm)")
            ax.grid(True, alpha=0.3)
        top.invert_xaxis()
    axes[0][0].set_ylabel("jaw force (N)")
    axes[1][0].set_ylabel("jaw force (N), linear")
    if mats:
        axes[0][-1].legend(fontsize=7, ncol=2, title="dashed: partial", title_fontsize=7)
    fig.suptitle(f"Force vs gap: {Path(directory)}")
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def make_report(
    directory: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    *,
    logy: bool = False,
    gaps_mm: Sequence[float] = DEFAULT_GAPS_MM,
) -> ReportFiles:
    """Write ``sweep_table.csv`` and ``force_gap.png`` for a sweep directory.

    Parameters
    ----------
    directory : str or os.PathLike
        Sweep directory (e.g. ``fe_data/default``).
    out_dir : str or os.PathLike
        Where to write the report (created if needed).
    logy : bool
        Logarithmic force axis in the plot.
    gaps_mm : sequence of float
        Jaw gaps (mm) tabulated.

    Returns
    -------
    ReportFiles
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    table = sweep_table(directory, gaps_mm)
    csv_path = out / "sweep_table.csv"
    df.atomic_write_bytes(csv_path, table.to_csv(index=False, lineterminator="\n").encode())
    png = plot_sweep(directory, out / "force_gap.png", logy=logy)
    return ReportFiles(table_csv=csv_path, plot_png=png, text=format_table(table))
