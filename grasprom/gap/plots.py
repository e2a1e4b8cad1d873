"""Plots of a diagnosis (PNG, matplotlib without a display): measured vs baseline vs augmented
handle force per trial, and the residual RMS by phase before / after."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from grasprom.gap.diagnosis import Diagnosis
from grasprom.gap.prepare import PHASES, PreparedTrial
from grasprom.gap.trials import FloatArray


def _new_figure(figsize: tuple[float, float]) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig


def _plot_trial(p: PreparedTrial, fb: FloatArray, fa: FloatArray, path: Path) -> None:
    """Force (N) measured / baseline ``fb`` / augmented ``fa`` and residuals, phases shaded."""
    fig = _new_figure((8, 4.5))
    ax = fig.add_subplot(2, 1, 1)
    ax.plot(p.t, p.F, "k.", ms=1.5, label="measured")
    ax.plot(p.t, fb, "C0-", lw=1, label="baseline")
    ax.plot(p.t, fa, "C3-", lw=1, label="augmented")
    ax.set_ylabel("handle force (N)")
    ax.set_title(f"{Path(p.trial.name).name}: t = {p.thickness:g} mm, {p.material}")
    ax.legend(fontsize=7)
    ax2 = fig.add_subplot(2, 1, 2, sharex=ax)
    ax2.plot(p.t, p.F - fb, "C0-", lw=0.8, label="measured - baseline")
    ax2.plot(p.t, p.F - fa, "C3-", lw=0.8, label="measured - augmented")
    for k in range(1, len(PHASES)):
        m = p.phase == k
        if np.any(m):
            ax2.fill_between(
                p.t,
                0,
                1,
                where=m,
                color=f"C{k + 3}",
                alpha=0.15,
                transform=ax2.get_xaxis_transform(),
                label=PHASES[k],
            )
    ax2.set_xlabel("time (s)")
    ax2.set_ylabel("residual (N)")
    ax2.legend(fontsize=6, ncol=3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def _plot_by_phase(report: dict[str, Any], path: Path) -> None:
    """Residual RMS (N) by phase: baseline vs augmented (held-out), noise level dotted."""
    v = report["verdict"]
    fig = _new_figure((6, 3.5))
    ax = fig.add_subplot(1, 1, 1)
    x = np.arange(len(PHASES))
    before = [v["by_phase_before"][k] or 0.0 for k in PHASES]
    after = [v["by_phase_after"][k] or 0.0 for k in PHASES]
    ax.bar(x - 0.2, before, 0.4, label="baseline")
    ax.bar(x + 0.2, after, 0.4, label="augmented (held-out)")
    ax.axhline(report["baseline"]["noise_N"], color="k", ls=":", lw=1, label="noise")
    ax.set_xticks(x, PHASES)
    ax.set_ylabel("residual RMS (N)")
    ax.set_title(f"verdict: {v['label']} {', '.join(v['effects'])}")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def write_plots(diag: Diagnosis, out_dir: str | Path) -> list[Path]:
    """Measured vs baseline vs augmented per trial, and residual RMS by phase (PNG)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, (p, fb, fa) in enumerate(zip(diag.preps, diag.baseline_pred, diag.augmented_pred)):
        path = out / f"trial_{i + 1:02d}.png"
        _plot_trial(p, fb, fa, path)
        paths.append(path)
    path = out / "residual_by_phase.png"
    _plot_by_phase(diag.report, path)
    paths.append(path)
    return paths
