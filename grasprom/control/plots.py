"""Plots of a tuning (:func:`plot_tuning`): rendered stiffness, Z-width, rendered impedance.

Uses the object-oriented matplotlib API (:class:`matplotlib.figure.Figure` on an Agg canvas):
the caller's backend and pyplot state are untouched.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from grasprom.control.passivity import zwidth_boundary
from grasprom.control.stiffness import virtual_damping_Nms_per_rad
from grasprom.control.tuning import TuningResult
from grasprom.fe.materials import material_label

if TYPE_CHECKING:  # matplotlib is imported when plotting
    from matplotlib.figure import Figure

__all__ = ["plot_transparency", "plot_tuning", "zwidth_figure"]


def plot_tuning(result: TuningResult, out_dir: str | Path) -> dict[str, Path]:
    """Write ``stiffness_vs_theta.png``, ``zwidth.png``, ``bode_impedance.png`` and
    ``transparency.png`` (the last when the result has force curves).

    Returns
    -------
    dict of str to Path
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = {
        "stiffness": _plot_stiffness(result, out / "stiffness_vs_theta.png"),
        "zwidth": _plot_zwidth(result, out / "zwidth.png"),
        "bode": _plot_bode(result, out / "bode_impedance.png"),
    }
    if result.curves:
        files["transparency"] = plot_transparency(result, out / "transparency.png")
    return files


def plot_transparency(result: TuningResult, path: str | Path) -> Path:
    """Rendered vs tissue jaw force over the gap (N vs mm) and their ratio vs the tissue force.

    Left: tissue (dotted) and rendered (solid) force of each case of ``result.curves`` over
    the jaw gap, log force axis.  Right: rendered / tissue over the tissue force, with the
    levels of the transparency table marked.

    Parameters
    ----------
    result : TuningResult
    path : str or Path
        PNG to write.

    Returns
    -------
    Path
    """
    path = Path(path)
    fig = _figure((11.0, 4.4))
    ax1 = fig.add_subplot(1, 2, 1)
    ax2 = fig.add_subplot(1, 2, 2)
    scheme = result.params.rendering
    for n_, c in enumerate(result.curves):
        col = f"C{n_}"
        lab = f"{c['material']} {c['thickness_mm']:g} mm"
        ft, fr = np.asarray(c["force_tissue_N"]), np.asarray(c["force_rendered_N"])
        on = ft > 1e-3
        ax1.semilogy(c["gap_mm"][on], ft[on], color=col, ls=":", lw=1.2)
        ax1.semilogy(c["gap_mm"][on], np.maximum(fr[on], 1e-3), color=col, lw=1.5, label=lab)
        ax2.semilogx(ft[on], fr[on] / ft[on], color=col, lw=1.5, label=lab)
    levels = result.summary.get("transparency", {}).get("levels_N", [])
    for L in levels:
        ax2.axvline(L, color="0.7", lw=0.8)
    ax1.set_xlabel("jaw gap (mm)")
    ax1.set_ylabel("jaw force (N)")
    ax1.set_ylim(1e-2, 200.0)
    ax1.set_title(f"{scheme} rendering: rendered (solid), tissue (dotted)", fontsize=9)
    ax2.set_xlabel("tissue jaw force (N)")
    ax2.set_ylabel("rendered / tissue")
    ax2.set_ylim(0.0, 1.1)
    ax2.set_xlim(0.05, 200.0)
    ax2.set_title("transparency (quasi-static)", fontsize=9)
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def _figure(figsize: tuple[float, float]) -> Figure:
    """A figure on its own Agg canvas (no pyplot, no backend switch)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig


def _plot_stiffness(result: TuningResult, path: Path) -> Path:
    """Rendered and raw-tissue stiffness (N m/rad) vs theta (deg), one panel per material."""
    import matplotlib

    k_pass = result.summary["passive_stiffness_Nm_per_rad"]
    mats = sorted({o.material for o in result.points})
    fig = _figure((5.0 * len(mats), 4.2))
    for j, m in enumerate(mats):
        ax = fig.add_subplot(1, len(mats), j + 1)
        ops = [o for o in result.points if o.material == m]
        cmap = matplotlib.colormaps["viridis"]
        for n_, o in enumerate(ops):
            col = cmap(n_ / max(len(ops) - 1, 1))
            ax.semilogy(
                o.theta_deg,
                np.maximum(o.K_Nm_per_rad, 1e-3),
                color=col,
                lw=1.2,
                label=f"t = {o.thickness_mm:g} mm" if n_ in (0, len(ops) - 1) else None,
            )
            ax.semilogy(
                o.theta_deg, np.maximum(o.K_raw_Nm_per_rad, 1e-3), color=col, lw=0.6, ls=":"
            )
        ax.axhline(k_pass, color="C3", lw=1.5, label="passive bound")
        ax.set_title(f"{material_label(m)}: rendered K (solid), raw tissue (dotted)",
                     fontsize=9)  # fmt: skip
        ax.set_xlabel(r"handle angle $\theta$ (deg)")
        ax.set_ylabel("K at handle pivot (N m/rad)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def _plot_zwidth(result: TuningResult, path: Path) -> Path:
    """Write :func:`zwidth_figure` of ``result`` to ``path`` (PNG)."""
    fig = zwidth_figure(result)
    fig.savefig(path, dpi=110)
    return path


def zwidth_figure(result: TuningResult) -> Figure:
    """Z-width (passive K over B) with the operating points, and the points case by case.

    Every operating point shares the chosen virtual damping ``B``, so on the Z-width plane
    (left) they stack on one vertical line; the left panel draws that line as the span of the
    rendered stiffness with the stiffest point marked.  The right panel spreads them out: one
    column per case (material, thickness), the rendered stiffness at each handle angle of the
    stroke (symlog axis: the negative slopes where the spring is released show too), the
    largest of each case marked, against the passive bound at the chosen ``B`` with and
    without the tuning's safety factor.  Each case's artists carry ``gid = "material
    thickness"``.

    Parameters
    ----------
    result : TuningResult

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig = _figure((12.0, 4.6))
    ax1 = fig.add_subplot(1, 2, 1)
    ax2 = fig.add_subplot(1, 2, 2)
    _draw_zwidth_plane(ax1, result)
    _draw_operating_columns(ax2, result)
    fig.tight_layout()
    return fig


def _draw_zwidth_plane(ax: Any, result: TuningResult) -> None:
    """Passive region over (B, K), the Colgate line and the operating span at the chosen B."""
    p, dev = result.params, result.device
    T, B, fc = p.sample_time_s, virtual_damping_Nms_per_rad(p), p.velocity_cutoff_Hz
    bmax = max(4.0 * B, 2.0 * dev.damping_Nms_per_rad)
    Bs, Ks = zwidth_boundary(dev.damping_Nms_per_rad, T, fc, dev.delay_samples, bmax)
    _, K0 = zwidth_boundary(dev.damping_Nms_per_rad, T, None, 0, bmax)
    ax.fill_between(Bs, 0, Ks, color="C2", alpha=0.25,
                    label=f"passive (delay {dev.delay_samples}, cutoff {fc:g} Hz)")  # fmt: skip
    ax.plot(Bs, K0, "k--", lw=1, label="Colgate b > KT/2 + |B| (no delay)")
    allK = np.concatenate([o.K_Nm_per_rad for o in result.points])
    k_hi = float(np.max(allK))
    ax.vlines(B, max(float(np.min(allK)), 0.0), k_hi, color="C0", lw=3,
              label=f"operating points: all at B = {B:.3g} N m s/rad")  # fmt: skip
    at = result.summary.get("max_at", {})
    where = f" ({at['material']} {at['thickness_mm']:g} mm)" if "material" in at else ""
    ax.plot([B], [k_hi], "C3*", ms=11, label=f"stiffest: {k_hi:.3g} N m/rad{where}")
    ax.set_xlabel("virtual damping B (N m s/rad)")
    ax.set_ylabel("rendered stiffness K (N m/rad)")
    ax.set_title("Z-width at the handle pivot", fontsize=10)
    ax.set_ylim(0, 1.2 * max(float(np.max(Ks)), float(np.max(K0[:1])), k_hi))
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)


def _draw_operating_columns(ax: Any, result: TuningResult) -> None:
    """One column per case: rendered K over the stroke, its maximum, the passive bounds."""
    sm = result.summary
    pts = sorted(result.points, key=lambda o: (o.material, o.thickness_mm))
    mats = sorted({o.material for o in pts})
    for x, o in enumerate(pts):
        col = f"C{mats.index(o.material)}"
        gid = f"{o.material} {o.thickness_mm:g}"
        k = np.asarray(o.K_Nm_per_rad, dtype=float)
        ax.plot(np.full_like(k, float(x)), k, ".", color=col, ms=2, alpha=0.5, gid=gid,
                label=material_label(o.material) if x == 0 or o.material != pts[x - 1].material
                else None)  # fmt: skip
        ax.plot([x], [float(np.max(k))], "_", color="k", ms=9, mew=1.5, gid=f"{gid} max")
    k_pass = sm["passive_stiffness_Nm_per_rad"]
    ax.axhline(k_pass, color="C3", lw=1.2, label=f"passive bound {k_pass:.3g} N m/rad")
    k_safe = sm.get("passive_stiffness_with_margin_Nm_per_rad")
    if k_safe is not None:
        ax.axhline(k_safe, color="C3", lw=1.0, ls="--",
                   label=f"with safety {sm.get('safety_factor', 1.0):g}: "
                   f"{k_safe:.3g} N m/rad")  # fmt: skip
    ax.set_yscale("symlog", linthresh=0.1)
    k_lo = min(float(np.min(o.K_Nm_per_rad)) for o in pts)
    k_top = max(k_pass, max(float(np.max(o.K_Nm_per_rad)) for o in pts))
    ax.set_ylim(2.0 * min(k_lo, 0.0), 2.0 * k_top)
    for m in mats:
        xs = [x for x, o in enumerate(pts) if o.material == m]
        ax.text(float(np.mean(xs)), 1.01, material_label(m), fontsize=7, ha="center",
                va="bottom", transform=ax.get_xaxis_transform())  # fmt: skip
    ax.set_xticks(range(len(pts)))
    ax.set_xticklabels([f"{o.thickness_mm:g}" for o in pts], fontsize=7)
    ax.set_xlabel("case: wall thickness (mm), grouped by material")
    ax.set_ylabel("rendered K over the stroke (N m/rad)")
    ax.set_title("operating points by case (dots: handle angles; bar: max)", fontsize=10, pad=14)
    ax.grid(True, alpha=0.3, which="both")
    ax.legend(fontsize=7, loc="lower left")


def _plot_bode(result: TuningResult, path: Path) -> Path:
    """Bode plot of the rendered impedance ``Z = tau / omega`` at the stiffest point."""
    p, dev = result.params, result.device
    T, B, fc = p.sample_time_s, virtual_damping_Nms_per_rad(p), p.velocity_cutoff_Hz
    kmax = result.summary["max_rendered_K_Nm_per_rad"]
    w = np.logspace(0, math.log10(math.pi / T), 400)
    zi = np.exp(-1j * w * T)
    a = math.exp(-2 * math.pi * fc * T)
    H = zi**dev.delay_samples * (kmax + B * (1 - a) * (1 - zi) / (T * (1 - a * zi)))
    Z = H / (1j * w)
    Zc = kmax / (1j * w) + B
    fig = _figure((6.0, 5.0))
    ax1 = fig.add_subplot(2, 1, 1)
    ax2 = fig.add_subplot(2, 1, 2, sharex=ax1)
    f = w / (2 * math.pi)
    ax1.loglog(f, np.abs(Z), label="sampled (ZOH, delay, filter)")
    ax1.loglog(f, np.abs(Zc), "--", label="ideal K/s + B")
    ax1.set_ylabel("|Z| (N m s/rad)")
    ax1.set_title(f"Rendered impedance at K = {kmax:.3g} N m/rad, B = {B:.3g} N m s/rad",
                  fontsize=10)  # fmt: skip
    ax1.legend(fontsize=7)
    ax1.grid(True, which="both", alpha=0.3)
    ax2.semilogx(f, np.degrees(np.unwrap(np.angle(Z))))  # unwrapped: no jump at +-180 deg
    ax2.semilogx(f, np.degrees(np.unwrap(np.angle(Zc))), "--")
    ax2.axhline(-90, color="0.6", lw=0.8)
    ax2.axhline(90, color="0.6", lw=0.8)
    ax2.set_ylabel("phase (deg)")
    ax2.set_xlabel("frequency (Hz)")
    ax2.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path
