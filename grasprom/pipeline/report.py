"""The build's report: ``report.html`` (self-contained, figures embedded as base64 PNG),
``build.json`` (provenance and headline results) and the console :func:`summary`.

:func:`write_report` assembles the HTML from one section per stage; each ``_*_section``
returns the section's HTML parts (empty when its stage did not run).
"""

from __future__ import annotations

import base64
import html
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from grasprom.pipeline.buildinfo import provenance
from grasprom.pipeline.headline import FAIL, PASS, built_items, headline_rows
from grasprom.pipeline.options import BuildOptions
from grasprom.pipeline.result import BuildResult, results

if TYPE_CHECKING:
    from grasprom.control import TuningResult
    from grasprom.export import ArduinoExport
    from grasprom.pipeline.result import CosimResult

FIGURES = (
    ("fe_sweep", "FE sweep: force vs jaw gap (full stroke, log axis; zoom on the walls meeting)"),
    (
        "surrogate",
        "Surrogate (lines) over FE points (held-out cases when available): force, "
        "zoom on wall contact, stiffness",
    ),
    (
        "residuals",
        "Residuals surrogate - FE at the FE points (held-out cases when available): N over "
        "the gap, and % of the haptic scale over the haptic range with the 3 % target",
    ),
    (
        "transmission",
        "Fg/Fi vs handle angle theta: derived chain (virtual work) and Guachi et al.'s formula as "
        "printed (why they differ: the text below)",
    ),
    (
        "stiffness",
        "Rendered and raw-tissue stiffness at the handle pivot vs theta, with the passive bound",
    ),
    ("zwidth", "Z-width: passive (K, B) set and the operating points"),
    ("bode", "Rendered impedance at the stiffest point vs the ideal K/s + B"),
    (
        "transparency",
        "Transparency: rendered (solid) vs tissue (dotted) jaw force over the gap, and their "
        "ratio over the tissue force (quasi-static)",
    ),
    ("cosim", "Grasp-hold-release co-simulated through the FMU (fmpy)"),
)
"""Figure key -> caption of the figures the report embeds, in report order."""

_CAPTIONS = dict(FIGURES)

_STYLE = (
    "<title>grasprom build report</title><style>body{font-family:sans-serif;"
    "max-width:1100px;margin:auto}table{border-collapse:collapse;margin:0.5em 0}"
    "td,th{border:1px solid #bbb;padding:2px 6px;text-align:right}"
    "img{max-width:100%}pre{background:#f4f4f4;padding:6px;overflow-x:auto}"
    "pre.wrap{white-space:pre-wrap;overflow-wrap:anywhere}td.text{text-align:left}"
    ".fail{color:#b00}.pass{color:#070}</style></head><body>"
)

_ERROR_HEADER = ["scheme", "range", "material", "F rms %FS", "F max %FS", "gap rms mm",
                 "gap max mm"]  # fmt: skip


# ----------------------------------------------------------------------------------- HTML bits
def _img(path: Path, alt: str) -> str:
    """``<figure>`` with the PNG at ``path`` embedded as base64 and captioned ``alt``."""
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return (
        f'<figure><img alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'
        f"<figcaption>{html.escape(path.name)}: {html.escape(alt)}</figcaption></figure>"
    )


def _figures(figs: dict[str, Path], keys: Sequence[str]) -> list[str]:
    """Embedded figures of ``keys`` that exist in ``figs``, in that order."""
    return [_img(figs[key], _CAPTIONS[key]) for key in keys if key in figs]


def _table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """HTML table (cells escaped)."""
    th = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows
    )
    return f"<table><tr>{th}</tr>{body}</table>"


def _list(items: Sequence[str]) -> str:
    """HTML bullet list (items escaped)."""
    return "<ul>" + "".join(f"<li>{html.escape(n)}</li>" for n in items) + "</ul>"


def _fmt(v: Any, spec: str = ".3g") -> str:
    """``v`` formatted with ``spec``; ``n/a`` for None, ``str`` for non-finite floats."""
    if v is None:
        return "n/a"
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)
    return format(v, spec)


def error_rows(fig: dict[str, Any]) -> list[list[str]]:
    """Rows (scheme, range, material, F rms %, F max %, gap rms mm, gap max mm) of error figures.

    Parameters
    ----------
    fig : dict
        Output of :meth:`Surrogate.check` or :func:`grasprom.surrogate.leave_one_out`.

    Returns
    -------
    list of list of str
    """
    rows = []
    for sc, fg in fig.get("schemes", {}).items():
        for rng in ("haptic", "full"):
            for mat in sorted(fg.get(rng, {}), key=lambda k: (k == "all", k)):
                r = fg[rng][mat]
                rows.append([sc, rng, mat, _fmt(r["force_rms_pct"], ".3f"),
                             _fmt(r["force_max_pct"], ".3f"), _fmt(r["gap_rms_mm"], ".4f"),
                             _fmt(r["gap_max_mm"], ".4f")])  # fmt: skip
    return rows


# ----------------------------------------------------------------------------------- sections
def _head_section(res: BuildResult, opts: BuildOptions) -> list[str]:
    """Document head, title line and, for a failed build, the failed stage."""
    from grasprom import __version__

    parts = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'>",
        _STYLE,
        f"<h1>grasprom build report</h1><p>grasprom {html.escape(__version__)}, "
        f"{html.escape(res.started)}; operating point {html.escape(opts.material)} "
        f"{opts.thickness_mm:g} mm{' (--fast)' if opts.fast else ''}.</p>",
    ]
    if res.coverage is not None:  # issue 16: the materials and thicknesses the outputs cover
        parts.append(f"<p><b>Coverage</b>: {html.escape(res.coverage.statement())}.</p>")
    if res.failed_stage:
        parts.append(f"<p class='fail'><b>Build failed at stage '{res.failed_stage}'</b>: "
                     f"{html.escape(str(res.error))}. Sections of later stages are missing."
                     "</p>")  # fmt: skip
    return parts


def _stages_section(res: BuildResult) -> list[str]:
    """Wall time per stage (s) and the failed stage."""
    rows = [[k, f"{v:.1f}"] for k, v in res.stage_times_s.items()]
    if res.failed_stage:
        rows.append([res.failed_stage, "FAILED"])
    return ["<h2>Stages</h2>" + _table(["stage", "wall time (s)"], rows)]


def _artefacts_section(res: BuildResult) -> list[str]:
    """Artefacts written, relative to the output folder."""
    out = res.out_dir
    files = [[k, str(p.relative_to(out)) if p.is_relative_to(out) else str(p)]
             for k, p in res.files.items()]  # fmt: skip
    return ["<h2>Artefacts</h2>" + _table(["artefact", "path"], files)]


def _surrogate_section(res: BuildResult) -> list[str]:
    """FE data, surrogate figures and its held-out and leave-one-out errors."""
    s = res.surrogate
    if s is None:
        return []
    parts = ["<h2>FE data and surrogate</h2>"]
    parts.append(f"<p>FE sweep {html.escape(str(res.fe_dir))}: materials "
                 f"{', '.join(s.materials)}, {s.node_count()} surrogate nodes, scheme "
                 f"{s.scheme}.</p>")  # fmt: skip
    parts += _figures(res.figures, ("fe_sweep", "surrogate", "residuals"))
    if "holdout" in s.errors:
        parts.append(f"<h3>Held-out error ({html.escape(str(res.holdout_dir))})</h3>")
        parts.append(_table(_ERROR_HEADER, error_rows(s.errors["holdout"])))
    else:
        parts.append("<p>No held-out FE directory: only the leave-one-out error.</p>")
    parts.append("<h3>Leave-one-thickness-out error</h3>")
    parts.append(_table(_ERROR_HEADER, error_rows(s.errors.get("loo", {}))))
    parts.append("<p>F: force error at equal gap, % of full scale (haptic: 20 N, full: the "
                 "force cap) where the FE stiffness is below the steep limit; gap: gap error "
                 "at equal force where steeper.</p>")  # fmt: skip
    return parts


def _chain_section(res: BuildResult) -> list[str]:
    """The transmission figure and why Guachi et al.'s curve sits below the derived chain."""
    if "transmission" not in res.figures:
        return []
    return [
        "<h2>Kinematic chain</h2>" + _img(res.figures["transmission"], _CAPTIONS["transmission"]),
        f"<p>{html.escape(seed_explanation(_chain(res)))}</p>",
    ]


def _chain(res: BuildResult) -> Any:
    """The chain of the build's controller (the default one before the tuning)."""
    from grasprom.control import ControllerParams

    return (res.params or ControllerParams()).chain_params


def seed_explanation(chain: Any) -> str:
    """Why Guachi et al.'s ``Fg/Fi`` sits below the derived chain, with this chain's numbers.

    Parameters
    ----------
    chain : grasprom.chain.kinematics.ChainParams

    Returns
    -------
    str
        One paragraph (plain text): the ratio derived / printed formula at the end stops, the rod
        travel per radian (mm/rad) against the crank ``L1`` (mm), the crank-link angle (deg).
    """
    from grasprom.chain.kinematics import seed_comparison

    c = seed_comparison(chain)
    o, k = c["open"], c["closed"]
    return (
        f"The Guachi et al. (2020) curve is eqs (1)-(4) as printed, with this chain's m/n: it is "
        f"{o['derived_over_seed']:.1f}x below the derived chain when open ({o['seed_pct']:.1f} "
        f"vs {o['derived_pct']:.1f} %) and {k['derived_over_seed']:.1f}x when closed "
        f"({k['seed_pct']:.1f} vs {k['derived_pct']:.1f} %). Eq (2) takes the rod force as the "
        f"crank-tip force Fi L3/L1 projected with cos(phi) cos(beta), i.e. as if the rod moved "
        f"L1 = {o['crank_mm']:g} mm per radian of handle; with Table 1's lengths and eq (3)'s "
        f"layout the crank and the link stay nearly in line (angle {o['mu_deg']:.1f} deg open, "
        f"{k['mu_deg']:.1f} deg closed), so the rod moves only {o['rod_mm_per_rad']:.2f}-"
        f"{k['rod_mm_per_rad']:.2f} mm per radian and virtual work gives the rod force "
        "Fi L3 / (rod travel per radian): derived / printed = 1 / (sin(crank-link angle) "
        "cos(phi)). Not a bug: the printed formula does not conserve energy (a handle force "
        "rendered with it would create or destroy energy over a grasp), so the controller uses "
        "the derived chain; the spring terms of both agree."
    )


def _tuning_section(res: BuildResult) -> list[str]:
    """Augmented model used, chosen controller parameters, tuning report and figures."""
    if res.tuning is None:
        return []
    parts = ["<h2>Controller tuning</h2>"]
    if res.augmentation is not None:
        a = res.augmentation
        parts.append(
            f"<p>Augmented model {html.escape(a['file'])} (sha256 {a['sha256'][:12]}): "
            f"rendered {html.escape(', '.join(a['rendered']) or 'none')}; measurement-only "
            f"(not rendered) {html.escape(', '.join(a['measurement_only']) or 'none')}.</p>"
        )
    parts.append(_table(["quantity", "value"], _tuning_rows(res.tuning)))
    parts += _transparency_parts(res.tuning, res.figures)
    parts.append(f"<pre class='wrap'>{html.escape(res.tuning.report())}</pre>")
    parts += _figures(res.figures, ("zwidth", "stiffness", "bode"))
    return parts


def transparency_rows(sm: dict[str, Any]) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the transparency table of a tuning summary (one row per case).

    Parameters
    ----------
    sm : dict
        Tuning summary (``tuning.json``) with a ``transparency`` entry.

    Returns
    -------
    tuple
        ``(header, rows)``: case, rendered / tissue force at each level, largest rendered
        force (N), wall stiffness over the bound, ``K_20`` (N m/rad), ``b_needed``
        (N m s/rad), ``rate_needed`` (Hz).
    """
    tr = sm.get("transparency")
    if not tr:
        return [], []
    levels = [f"{L:g}" for L in tr["levels_N"]]
    header = ["case", *(f"{L} N" for L in levels), "max rendered (N)", "wall / bound",
              "K20 (N m/rad)", "b needed (N m s/rad)", "rate needed (Hz)"]  # fmt: skip
    rows = [[f"{c['material']} {c['thickness_mm']:g} mm",
             *(_fmt(c["ratios"][L], ".3f") for L in levels), _fmt(c["max_rendered_N"]),
             _fmt(c["wall_over_bound"]), _fmt(c["K20_Nm_per_rad"]),
             _fmt(c["b_needed_Nms_per_rad"]), _fmt(c["rate_needed_Hz"])]
            for c in tr["cases"]]  # fmt: skip
    return header, rows


def _transparency_parts(tuning: TuningResult, figs: dict[str, Path]) -> list[str]:
    """Transparency heading, table, figure and the closed-loop target of the tuning."""
    sm = tuning.summary
    header, rows = transparency_rows(sm)
    if not rows:
        return []
    tr = sm["transparency"]
    parts = [
        "<h3>Transparency</h3>",
        f"<p>{html.escape(tr['rendering'])} rendering, quasi-static: rendered / tissue jaw "
        "force at the gap where the tissue force reaches each level; wall / bound: median "
        "rendered handle stiffness where the tissue is stiffer than the passive bound, over "
        "the bound; b / rate needed: what would render the tissue exactly (passively) up to "
        f"{tr['exact_up_to_N']:g} N.</p>",
        _table(header, rows),
    ]
    parts += _figures(figs, ("transparency",))
    om = sm.get("operating_margins")
    if om:
        w = om["worst"]
        parts.append(
            f"<p>Target: {html.escape(om['target']['statement'])}: "
            f"<b>{'met' if om['meets_target'] else 'NOT met'}</b>; worst case "
            f"{html.escape(w['material'])} {w['thickness_mm']:g} mm: damping ratio "
            f"{w['damping_ratio_min']:.3g}, phase margin {w['phase_margin_min_deg']:.3g} deg "
            "with the hand.</p>"
        )
    return parts


def _tuning_rows(tuning: TuningResult) -> list[list[str]]:
    """(quantity, value) rows of the chosen controller and its passivity figures."""
    sm = tuning.summary
    c = sm["chosen"]
    bound = (
        ["stiffness limit K_lim (N m/rad), clipped rendering",
         _fmt(c["stiffness_limit_Nm_per_rad"])]
        if c.get("rendering") == "clipped"
        else ["coupling stiffness k_c (N/mm)", _fmt(c["coupling_stiffness_N_per_mm"])]
    )  # fmt: skip
    cl = sm["closed_loop_with_hand"]
    return [
        bound,
        ["virtual damping B (N m s/rad)", _fmt(c["damping_Nms_per_rad"], ".4g")],
        ["velocity cutoff (Hz)", _fmt(c["velocity_cutoff_Hz"])],
        ["largest rendered stiffness (N m/rad)", _fmt(sm["max_rendered_K_Nm_per_rad"])],
        ["passive stiffness bound (N m/rad)", _fmt(sm["passive_stiffness_Nm_per_rad"])],
        ["passivity margin b / b_required", _fmt(sm["passivity_margin"])],
        ["passive everywhere", str(sm["passive_everywhere"])],
        ["closed loop with hand: max |pole|", _fmt(cl["max_pole_mag"], ".5f")],
        [
            "closed loop with hand at the stiffest point: damping ratio, phase margin (deg)",
            f"{_fmt(cl.get('damping_ratio'))}, {_fmt(cl['phase_margin_deg'])}",
        ],
    ]


def _fmu_section(res: BuildResult) -> list[str]:
    """FMU files, FMI versions and sizes (KiB)."""
    if "fmu2" not in res.files:
        return []
    rows = [
        [res.files[k].name, v, f"{res.files[k].stat().st_size / 1024:.0f}"]
        for k, v in (("fmu2", "2.0"), ("fmu3", "3.0"))
        if k in res.files
    ]
    return ["<h2>FMU</h2>" + _table(["file", "FMI", "size (KiB)"], rows)]


def _cosim_section(res: BuildResult) -> list[str]:
    """Headline figures and the figure of the co-simulated grasp."""
    cs: CosimResult | None = res.cosim
    if cs is None:
        return []
    parts = ["<h2>Co-simulated grasp</h2>"]
    parts.append(
        "<p>The hand is the operator model of haptics: it intends a minimum-jerk closing of "
        "the handle and pushes it through the finger's stiffness and damping (HandParams), "
        "aiming at a hold force of 3 N; a pure force source would let the handle run through "
        "the soft part of the stroke and slam into the tissue.</p>"
    )
    parts.append(
        f"<p>{len(cs.data)} steps at {1 / res.params.sample_time_s:g} Hz; min handle "
        f"angle {cs.col('theta_deg').min():.2f} deg, max jaw force "
        f"{cs.col('force_jaw_N').max():.2f} N, max motor torque "
        f"{cs.col('torque_Nm').max():.3f} N m; FMU vs Python reference torque: "
        f"max |diff| {cs.max_torque_diff_Nm:.2e} N m; {cs.wall_s:.1f} s.</p>"
    )
    parts.append(f"<p>{html.escape(open_handle_explanation(res.params, cs))}</p>")
    parts.append(f"<p>{html.escape(profile_explanation())}</p>")
    st = cs.settling
    if st:
        parts.append(
            f"<p>Rendered handle force: peak {st['peak_N']:.3g} N over the settled hold "
            f"{st['settled_N']:.3g} N: overshoot {100 * st['overshoot']:.0f} % (target <= "
            f"{100 * st['target']:.0f} %: <b>{'met' if st['meets_target'] else 'NOT met'}"
            f"</b>), ringing {st['ringing_rms_N']:.2g} N rms at the end of the hold.</p>"
        )
    parts += _figures(res.figures, ("cosim",))
    return parts


def open_handle_force(params: Any) -> dict[str, float]:
    """Rendered handle force at the open stop, N: the return spring alone, from the chain.

    Parameters
    ----------
    params : ControllerParams
        Its chain (spring preload N, rate N/mm, ``L3`` mm) and ``render_spring``.

    Returns
    -------
    dict
        ``force_N`` (``F0 |du/dtheta| / L3`` at ``theta_open``; 0 without ``render_spring``),
        ``preload_N``, ``rod_mm_per_rad`` (``|du/dtheta|``), ``L3_mm``, ``theta_open_deg``.
    """
    from grasprom.chain import kinematics as kin

    ch = params.chain_params
    f = float(kin.spring_handle_force_N(ch.theta_open_deg, ch)) if params.render_spring else 0.0
    rod = kin.seed_comparison(ch)["open"]["rod_mm_per_rad"]
    return {"force_N": f, "preload_N": ch.spring_preload_N, "rod_mm_per_rad": rod,
            "L3_mm": ch.L3_mm, "theta_open_deg": ch.theta_open_deg}  # fmt: skip


def open_handle_explanation(params: Any, cs: CosimResult) -> str:
    """Why the rendered handle force is not zero with the handle open (the return spring)."""
    o = open_handle_force(params)
    at_open = cs.col("theta_deg") >= o["theta_open_deg"] - 1e-9
    seen = cs.col("force_handle_N")[at_open]
    measured = f"{seen[0]:.2f} N" if seen.size else "n/a"
    if o["force_N"] == 0.0:
        return (f"With the handle open the rendered handle force is {measured}: the return "
                "spring is not rendered (render_spring off).")  # fmt: skip
    return (
        f"With the handle at its open stop (theta = {o['theta_open_deg']:g} deg: before the "
        f"hand closes it and after it lets go) the rendered handle force is "
        f"{o['force_N']:.2f} N (co-simulated: {measured}): the rendered return spring of the "
        f"instrument, its preload F0 = {o['preload_N']:g} N on the rod reflected to the grip "
        f"by virtual work, F0 |du/dtheta| / L3 = {o['preload_N']:g} N x "
        f"{o['rod_mm_per_rad']:.2f} mm/rad / {o['L3_mm']:g} mm = {o['force_N']:.2f} N. The "
        "hand has to exceed it before the handle moves, and it returns the handle to the open "
        "stop on release."
    )


def profile_explanation() -> str:
    """The grasp profile of the co-simulation, what ``--fast`` changes, and the example."""
    from grasprom.pipeline.cosim import FAST_REST_S, GRASP_PROFILE_S

    ramp, hold, release, rest = GRASP_PROFILE_S
    return (
        f"Grasp profile: ramp {ramp:g} s, hold {hold:g} s, release {release:g} s, rest "
        f"{rest:g} s; --fast only shortens the rest to {FAST_REST_S:g} s (the handle is back at "
        "its open stop before the release ends), so the figures above are the same with and "
        "without --fast. examples/fmu_cosim.py runs this co-simulation (same tuning, device, "
        "hand and profile, FMI 2 or 3) and prints the same figures."
    )


def _arduino_section(res: BuildResult) -> list[str]:
    """Arduino budget: measured flash, RAM, cycles and errors against the budgets; notes."""
    a = res.arduino
    if a is None:
        return []
    parts = [
        "<h2>Arduino budget (ATmega328P)</h2>"
        + _table(["figure", "measured", "budget"], _arduino_rows(a))
    ]
    if a.notes:
        parts.append(_list(a.notes))
    return parts


def _arduino_rows(a: ArduinoExport) -> list[list[Any]]:
    """(figure, measured, budget) rows of an Arduino export."""
    from grasprom.export import CYCLE_BUDGET, ERROR_BUDGET, FLASH_BUDGET_B, RAM_BUDGET_B

    return [
        ["flash tables + core (B)", _fmt(a.flash_B, "d"), FLASH_BUDGET_B],
        ["RAM static + step stack (B)", _fmt(a.ram_B, "d"), RAM_BUDGET_B],
        ["cycles per step, max", _fmt(a.cycles_max, "d"), CYCLE_BUDGET],
        [
            f"handle-force error (% of the rendered range {_fmt(a.rendered_max_N, '.3g')} N)",
            _fmt(a.error_handle_pct_rendered, ".3f"),
            f"{100 * ERROR_BUDGET:g}",
        ],
        ["handle-force error (% of motor FS)", _fmt(a.error_handle_pct_fs, ".3f"), ""],
        ["jaw-force error (% of jaw FS)", _fmt(a.error_jaw_pct_fs, ".3f"), ""],
        ["tables (B)", a.table_bytes, ""],
        ["grid nodes", ", ".join(f"{k} {v}" for k, v in a.grid_nodes.items()), ""],
    ]


def _notes_section(res: BuildResult) -> list[str]:
    """Notes of the build (warnings of the stages)."""
    if not res.notes:
        return []
    return ["<h2>Notes</h2>" + _list(res.notes)]


# ----------------------------------------------------------------------------------- writers
def write_report(res: BuildResult, opts: BuildOptions) -> Path:
    """Write ``report.html`` (figures embedded as base64 PNG) and ``build.json``.

    Works on a partial build: sections of the stages that did not run are left out and the
    failed stage is named at the top.

    Parameters
    ----------
    res : BuildResult
    opts : BuildOptions

    Returns
    -------
    Path
        The HTML report.
    """
    prov = provenance(res, opts)
    parts = [
        *_head_section(res, opts),
        *_headline_section(res),
        *_surrogate_section(res),
        *_chain_section(res),
        *_tuning_section(res),
        *_fmu_section(res),
        *_cosim_section(res),
        *_arduino_section(res),
        *_notes_section(res),
        *_stages_section(res),
        *_artefacts_section(res),
        "<h2>Provenance</h2><pre>" + html.escape(json.dumps(prov, indent=2)) + "</pre>",
        "</body></html>",
    ]
    path = res.out_dir / "report.html"
    path.write_text("\n".join(parts))
    res.files["report"] = path
    write_build_json(res, prov)
    return path


def write_build_json(res: BuildResult, prov: dict[str, Any]) -> Path:
    """Write ``build.json``: provenance, headline :func:`results`, figure and file paths.

    Parameters
    ----------
    res : BuildResult
    prov : dict
        Output of :func:`~grasprom.pipeline.buildinfo.provenance`.

    Returns
    -------
    Path
    """
    out = res.out_dir
    path = out / "build.json"
    path.write_text(json.dumps(
        {"format": "grasprom-build", "format_version": 1, "provenance": prov,
         "results": results(res), "headline": headline_rows(res),
         "figures": {k: str(p.relative_to(out)) for k, p in res.figures.items()},
         "files": {k: str(p.relative_to(out)) for k, p in res.files.items()}},
        indent=2, default=str))  # fmt: skip
    res.files["build_json"] = path
    return path


def summary(res: BuildResult) -> str:
    """One paragraph on a finished build: artefacts and headline figures."""
    lines = [f"grasprom build: {res.total_s:.1f} s -> {res.out_dir}"]
    lines += [f"  {x}" for x in headline(res)]
    for key in ("surrogate", "controller", "fmu2", "fmu3", "arduino", "report"):
        if key in res.files:
            lines.append(f"  {key:10s} {res.files[key]}")
    return "\n".join(lines)


def _headline_section(res: BuildResult) -> list[str]:
    """The results first: what was built, then :func:`headline_rows` with PASS / FAIL."""
    items = built_items(res)
    rows = headline_rows(res)
    if not items and not rows:
        return []
    parts = ["<h2>Results at a glance</h2>"]
    if items:
        parts.append("<p>Built:</p>" + _list(items))
    if rows:
        parts.append(_headline_table(rows))
        n = {v: sum(r["verdict"] == v for r in rows) for v in (PASS, FAIL)}
        parts.append(f"<p>{n[PASS]} of {len(rows)} targets met, {n[FAIL]} missed"
                     f"{'' if n[PASS] + n[FAIL] == len(rows) else '; n/a: not measured'}"
                     ". Each target is the project's own constant, named in the last column."
                     "</p>")  # fmt: skip
    return parts


def _headline_table(rows: Sequence[dict[str, Any]]) -> str:
    """HTML of the headline rows: figure, measured, target, verdict (coloured), source."""
    head = "".join(f"<th>{h}</th>" for h in ("figure", "measured", "target", "verdict",
                                               "target stated in"))  # fmt: skip
    body = []
    for r in rows:
        cls = {PASS: "pass", FAIL: "fail"}.get(r["verdict"], "")
        unit = f" {r['unit']}" if r["unit"] else ""
        val = "not measured" if r["value"] is None else f"{_fmt(r['value'], '.4g')}{unit}"
        body.append(
            f"<tr><td class='text'>{html.escape(r['figure'])}</td><td>{html.escape(val)}</td>"
            f"<td>{html.escape(r['sense'])} {r['limit']:g}{html.escape(unit)}</td>"
            f"<td class='{cls}'><b>{r['verdict']}</b></td>"
            f"<td class='text'>{html.escape(r['source'])}</td></tr>"
        )
    return f"<table class='headline'><tr>{head}</tr>{''.join(body)}</table>"


def headline(res: BuildResult) -> list[str]:
    """The headline figures of a build, one sentence each (units stated): surrogate error,
    controller and passivity, closed loop, augmentation, Arduino budget, co-simulation."""
    lines: list[str] = []
    if res.surrogate is not None:
        err = res.surrogate.errors.get("holdout", {}).get("schemes", {}).get(res.surrogate.scheme)
        if err:
            h = err["haptic"]["all"]
            f_max, g_max = _fmt(h["force_max_pct"], ".2f"), _fmt(h["gap_max_mm"], ".3f")
            lines.append(f"surrogate: held-out haptic force error {f_max} % of the force scale "
                         f"(max), gap error {g_max} mm (max, where steeper)")  # fmt: skip
    if res.tuning is not None:
        sm = res.tuning.summary
        c = sm["chosen"]
        bound = (f"K_lim = {c['stiffness_limit_Nm_per_rad']:g} N m/rad (clipped)"
                 if c.get("rendering") == "clipped"
                 else f"k_c = {c['coupling_stiffness_N_per_mm']:g} N/mm")  # fmt: skip
        lines.append(f"controller: {bound}, passivity margin {sm['passivity_margin']:.3g}")
        om = sm.get("operating_margins")
        if om:
            lines.append(f"closed loop with the hand: worst damping ratio "
                         f"{om['worst']['damping_ratio_min']:.3g} (target "
                         f"{om['target']['damping_ratio_min']:g}: "
                         f"{'met' if om['meets_target'] else 'NOT met'})")  # fmt: skip
    if res.augmentation is not None:
        lines.append(f"augmented model {res.augmentation['file']}: rendered "
                     f"{', '.join(res.augmentation['rendered']) or 'none'}")  # fmt: skip
    if res.arduino is not None:
        a = res.arduino
        if a.flash_B is None and a.cycles_max is None and a.error_handle_pct_rendered is None:
            why = "; ".join(a.notes) or "no toolchain run"
            lines.append(f"arduino: package written, budget not measured ({why})")
        else:
            lines.append(f"arduino: flash {_fmt(a.flash_B, 'd')} B, RAM {_fmt(a.ram_B, 'd')} B, "
                         f"cycles {_fmt(a.cycles_max, 'd')}, handle-force error "
                         f"{_fmt(a.error_handle_pct_rendered, '.3f')} % of the rendered "
                         "range")  # fmt: skip
    if res.cosim is not None:
        lines.append(
            f"co-simulation: max jaw force {res.cosim.col('force_jaw_N').max():.2f} N,"
            f" FMU vs Python torque {res.cosim.max_torque_diff_Nm:.1e} N m"
            + (
                f", handle-force overshoot {100 * res.cosim.settling['overshoot']:.0f} %"
                if res.cosim.settling
                else ""
            )
        )
    return lines
