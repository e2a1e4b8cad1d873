"""Outputs of a diagnosis: the readable summary of the report and the files ``report.json``,
``augmented_model.json`` (and the plots of :mod:`~grasprom.gap.plots`)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from grasprom.gap.augmented import save_augmented
from grasprom.gap.diagnosis import Diagnosis
from grasprom.gap.plots import write_plots
from grasprom.gap.prepare import PHASES


def _explained_param_lines(report: dict[str, Any]) -> list[str]:
    """``effect.param = value +- uncertainty unit`` of the explaining effect set."""
    v = report["verdict"]
    lines = []
    for r in report["effects"] + report["pairs"]:
        if r["effects"] == v["effects"]:
            ps = r["params"] if len(v["effects"]) > 1 else {v["effects"][0]: r["params"]}
            us = r["uncertainty"] if len(v["effects"]) > 1 else {v["effects"][0]: r["uncertainty"]}
            un = r["units"] if len(v["effects"]) > 1 else {v["effects"][0]: r["units"]}
            for e in ps:
                for k, val in ps[e].items():
                    u = us[e].get(k)
                    lines.append(
                        f"  {e}.{k} = {val:.4g} +- {u if u is None else format(u, '.2g')} "
                        f"{un[e][k]}"
                    )
    return lines


def _shrink_lines(v: dict[str, Any]) -> list[str]:
    """The held-out shrink of the best candidate set per phase, with its bootstrap interval."""
    rows = v.get("shrink_by_phase") or []
    if not rows:
        return []
    who = " + ".join(v["best_candidate"]) or "-"
    lines = [
        "",
        f"held-out shrink of {who} (90 % bootstrap interval over trials; < 0: worse)",
        f"{'phase':<12}{'share':>7}{'rms before':>12}{'after N':>9}{'shrink':>9}{'interval':>17}",
    ]

    def known(x: Any) -> bool:  # NaN is null in the JSON report
        return x is not None and x == x

    for r in rows:
        ci = f"[{r['low']:+.2f}, {r['high']:+.2f}]" if known(r["low"]) else ""
        sh = f"{r['shrink']:+.2f}" if known(r["shrink"]) else "n/a"
        lines.append(
            f"{r['phase']:<12}{r['share_of_gap']:7.2f}{r['rms_before_N']:12.3f}"
            f"{r['rms_after_N']:9.3f}{sh:>9}{ci:>17}"
        )
    return lines


def format_summary(report: dict[str, Any]) -> str:
    """Readable summary of a diagnosis report."""
    b = report["baseline"]
    v = report["verdict"]
    w = report["where"]
    lines = [
        f"trials: {len(report['trials'])}, analysis samples: {b['n_samples']}",
        f"baseline RMS {b['rms_N']:.3f} N (bias {b['bias_N']:+.3f} N), noise {b['noise_N']:.3f} N, "
        f"systematic ratio {b['systematic_ratio']:.3g} -> "
        f"{'significant' if b['significant'] else 'within noise'}",
        "",
        f"{'phase':<12}{'rms N':>9}{'bias N':>9}{'share':>8}{'n':>7}",
    ]
    for k in PHASES:
        s = b["by_phase"][k]
        if s["n"]:
            lines.append(f"{k:<12}{s['rms_N']:9.3f}{s['bias_N']:+9.3f}{s['share']:8.2f}{s['n']:7d}")
    if b.get("by_block"):
        lines.append("")
        for k, s in b["by_block"].items():
            lines.append(f"block {k:<10} rms {s['rms_N']:.3f} N  share {s['share']:.2f}")
    lines += ["", f"where: phase {w['phase']}, block {w['block']} ({w['block_source']})", ""]
    lines.append(f"{'candidate':<42}{'held-out rms N':>15}{'shrink':>8}{'score':>8}")
    for r in report["effects"] + report["pairs"]:
        lines.append(
            f"{r['name']:<42}{r['heldout_rms_N']:15.3f}{r['shrink']:8.2f}{r['score']:8.2f}"
        )
    lines += [
        "",
        f"VERDICT: {v['label']}"
        + (f" ({', '.join(v['effects'])})" if v["effects"] else "")
        + f", confidence {v['confidence']:.2f}",
        f"  held-out RMS {v['heldout_rms_before_N']:.3f} N -> {v['heldout_rms_after_N']:.3f} N "
        f"(shrink {100 * v['shrink']:.0f} %)",
        f"  {v['message']}",
    ]
    if v["label"] == "explained":
        lines += _explained_param_lines(report)
    lines += _shrink_lines(v)
    if v["label"] == "not_diagnosable":
        lines.append("  no augmented model is written")
    for wmsg in report["warnings"]:
        lines.append(f"warning: {wmsg}")
    return "\n".join(lines)


def write_outputs(diag: Diagnosis, out_dir: str | Path, plots: bool = True) -> dict[str, Path]:
    """Write ``report.json``, ``augmented_model.json`` and (optionally) the plots.

    With the verdict ``not_diagnosable`` there is no augmented model: none is written and one
    left in ``out_dir`` by an earlier run is removed (it would not belong to this report).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rep = dict(diag.report)
    aug_path = out / "augmented_model.json"
    rep["augmented_model"] = None if diag.augmented is None else aug_path.name
    (out / "report.json").write_text(json.dumps(rep, indent=2))
    paths = {"report": out / "report.json"}
    if diag.augmented is None:
        aug_path.unlink(missing_ok=True)
    else:
        paths["augmented"] = save_augmented(diag.augmented, aug_path)
    if plots:
        for p in write_plots(diag, out):
            paths[p.stem] = p
    return paths
