"""Report on a sweep directory: a summary table (text + CSV) and force-gap plots (PNG, drawn
by :func:`grasprom.fe.plots.plot_sweep`).

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
from grasprom.fe.atomicio import atomic_write_bytes
from grasprom.fe.materials import material_label
from grasprom.fe.plots import plot_sweep

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
    section_pngs : tuple of pathlib.Path
        The deformed sections of the 3D cases (:func:`plot_case_sections`).
    band_png : pathlib.Path or None
        The crease band's selection (:func:`plot_band_selection`), None if no case has one.
    """

    table_csv: Path
    plot_png: Path
    text: str
    section_pngs: tuple[Path, ...] = ()
    band_png: Path | None = None


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
        gap (NaN where the case did not reach it), ``max_force_N``, ``band_rows_taken`` (rows
        the crease band's companion selection replaced, ``fe_info.band_selection``; NaN for a
        case without one).

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
            sel = (case.meta.get("fe_info") or {}).get("band_selection")
            row["band_rows_taken"] = len(sel["taken_gaps_mm"]) if sel else float("nan")
        else:
            failed = (d / f"{stem}{df.ERROR_SUFFIX}").exists()
            row.update(status="failed" if failed else "missing", steps=0, last_gap_mm=float("nan"))
            for g in gaps_mm:
                row[_gap_col(g)] = float("nan")
            row["max_force_N"] = float("nan")
            row["band_rows_taken"] = float("nan")
        rows.append(row)
    if not rows:
        raise FileNotFoundError(f"sweep directory {d} holds no case files")
    table = pd.DataFrame(rows)
    return table.sort_values(["material", "thickness_mm"], kind="stable").reset_index(drop=True)


def format_table(table: pd.DataFrame) -> str:
    """Plain-text rendering of :func:`sweep_table` output."""
    return table.to_string(index=False, float_format=lambda x: f"{x:.4g}", na_rep="-")


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
    table = sweep_table(directory, gaps_mm)  # reads (and checks) the sweep before any output
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    csv_path = out / "sweep_table.csv"
    atomic_write_bytes(csv_path, table.to_csv(index=False, lineterminator="\n").encode())
    png = plot_sweep(directory, out / "force_gap.png", logy=logy)
    sections = plot_case_sections(directory, out)
    band = plot_band_selection(directory, out / "band_selection.png")
    return ReportFiles(table_csv=csv_path, plot_png=png, text=format_table(table),
                       section_pngs=sections, band_png=band)  # fmt: skip


def _selected_cases(directory: str | os.PathLike[str]) -> list[tuple[dict, pd.DataFrame]]:
    """``(sidecar, table)`` of every case of ``directory`` with a band selection."""
    out = []
    for meta_path in df.case_json_paths(directory):
        case = df.read_case(meta_path)
        if (case.meta.get("fe_info") or {}).get("band_selection"):
            out.append((case.meta, case.table))
    return out


def plot_band_selection(
    directory: str | os.PathLike[str], path: str | os.PathLike[str]
) -> Path | None:
    """The crease band of every case with a companion selection (``--band-companion``):
    force (N) against the gap over the wall thickness, the selected rows as a line, the case's
    own force where a companion state was taken (open circles) and where a companion state
    was not (dots, the companion's own force on its mesh), one column per material.

    Returns
    -------
    pathlib.Path or None
        The PNG written; None (nothing written) if no case has a selection.
    """
    from matplotlib.figure import Figure

    cases = _selected_cases(directory)
    if not cases:
        return None
    mats = sorted({m["material"] for m, _ in cases})
    fig = Figure(figsize=(max(4.8 * len(mats), 6.0), 4.6))
    axes = fig.subplots(1, len(mats), squeeze=False)[0]
    for ax, mat in zip(axes, mats):
        for meta, table in (c for c in cases if c[0]["material"] == mat):
            t = float(meta["thickness_mm"])
            sel = meta["fe_info"]["band_selection"]
            band = table[(table["gap_mm"] >= 2 * t - 1e-9) & (table["gap_mm"] <= 4 * t)]
            (line,) = ax.plot(band["gap_mm"] / t, band["force_N"], lw=1.0, label=f"{t:.2f} mm")
            ch = [c for c in sel["choices"] if c["companion_force_N"] is not None]
            taken = [c for c in ch if c["taken"]]
            ax.plot([c["gap_mm"] / t for c in taken], [c["own_force_N"] for c in taken], "o",
                    mfc="none", color=line.get_color(), ms=4)  # fmt: skip
            kept = [c for c in ch if not c["taken"]]
            ax.plot([c["gap_mm"] / t for c in kept], [c["companion_force_N"] for c in kept], ".",
                    color=line.get_color(), ms=2)  # fmt: skip
        ax.set_yscale("log")
        ax.set_xlabel("jaw gap / wall thickness")
        ax.set_title(f"{material_label(mat)}: band 2t-4t", fontsize=9)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=6, ncol=2, title="t", title_fontsize=6)
    axes[0].set_ylabel("jaw force (N)")
    title = "Crease band: selected rows (lines), own rows replaced (o),\n"
    title += "companion states not taken (., the companion's own force)"
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    return out


def plot_case_sections(
    directory: str | os.PathLike[str], out_dir: str | os.PathLike[str]
) -> tuple[Path, ...]:
    """``sections_<stem>.png`` for every 3D case whose sidecar records deformed sections.

    The 3D sweep stores the mid-plane cross-section and the top line at a few gaps
    (:mod:`grasprom.fe.snapshots3d`); 2D cases have none and get no picture.
    """
    from grasprom.fe.snapshots3d import plot_sections

    pngs = []
    for meta_path in df.case_json_paths(directory):
        meta = df.read_case(meta_path).meta
        sections = (meta.get("fe_info") or {}).get("sections")
        if sections:
            title = f"{meta['stem']}: 3D tube, {meta.get('contact', '')} contact"
            pngs.append(
                plot_sections(sections, title, Path(out_dir) / f"sections_{meta['stem']}.png")
            )
    return tuple(pngs)
