"""Benchmarks of the 3D clamping model (grasprom.fe.model3d): prints figures, asserts nothing.

Sections (run all, or name some on the command line)::

    python benchmarks/bench_fe3d.py default       # default case: wall time, dofs, 3D/2D ratio
    python benchmarks/bench_fe3d.py solver        # default case, SuperLU (baseline) vs PARDISO
    python benchmarks/bench_fe3d.py cases         # t 0.8/1.4/2.0 x mr/le, stick and frictionless
    python benchmarks/bench_fe3d.py cases --materials mr --thickness 0.8 --json out.json
    python benchmarks/bench_fe3d.py contact       # stick vs frictionless at fixed gaps
    python benchmarks/bench_fe3d.py laws          # frictionless, coulomb 0.1/0.3/1, stick to gap 5
    python benchmarks/bench_fe3d.py crease        # crease band: default vs small steps, dense
    python benchmarks/bench_fe3d.py length        # tube-length convergence (L, 2L)
    python benchmarks/bench_fe3d.py free          # axial divisions beyond the jaw: 9/6/5/4
    python benchmarks/bench_fe3d.py mesh          # mesh convergence at fixed gaps
    python benchmarks/bench_fe3d.py meshband      # crease band and wall contact vs a fine mesh
    python benchmarks/bench_fe3d.py meshtube      # five cross-sections on the 240 mm tube (~1 h)
    python benchmarks/bench_fe3d.py layers        # four and five layers through the wall (~3 h)
    python benchmarks/bench_fe3d.py planestrain   # plane-strain 3D vs the 2D model, full stroke
    python benchmarks/bench_fe3d.py element       # crease band in plane strain: beta, cross-section
    python benchmarks/bench_fe3d.py shell         # small-deflection stiffness vs shell theory
    python benchmarks/bench_fe3d.py assembly      # assembly: blocked vs one pass vs plain einsum
    python benchmarks/bench_fe3d.py ccx           # against CalculiX, frictionless, 3 meshes (~1 h)
    python benchmarks/bench_fe3d.py wallsmeet     # 4 x 36, 240 mm: contact predicted or not (~1.5h)
    python benchmarks/bench_fe3d.py activeset     # 4 x 36, 240 mm: active-set tolerance (~40 min)
    python benchmarks/bench_fe3d.py activeset --closed-gap 12   # its bending part (~4 min)
    python benchmarks/bench_fe3d.py reuse         # 4 x 36, 240 mm: predictor factor reuse, bending
    python benchmarks/bench_fe3d.py reuse --closed-gap 1.5      # the whole stroke (~30 min)
    python benchmarks/bench_fe3d.py band          # 4 x 48 vs 4 x 36, 240 mm: crease band (~35 min)
    python benchmarks/bench_fe3d.py commonbranch  # band states moved between the meshes (~1.5 h)
    python benchmarks/bench_fe3d.py crossmesh     # le 1.0: default vs zoned, band states swapped
    python benchmarks/bench_fe3d.py bandselect    # le 1.0: 4 x 36 vs 4 x 48, each with a companion
    python benchmarks/bench_fe3d.py moves         # zoned states moved to 4 x 36: one set-up or each
    python benchmarks/bench_fe3d.py stall         # 4 x 36: budgeted solves stop when rising
    python benchmarks/bench_fe3d.py factors       # 4 x 36 sweep case: where factorisations go
    python benchmarks/bench_fe3d.py factors --far-coarsening 2   # the same, 2 x 18 beyond the jaw
    python benchmarks/bench_fe3d.py forwardstall  # sweep case mr 0.8: forward stall rule (~1 h)
    python benchmarks/bench_fe3d.py transition    # sweep case, far zone 2 x 18 vs 4 x 36 (~25 min)
    python benchmarks/bench_fe3d.py transition --closed-gap 12   # its bending part (~5 min)
    python benchmarks/bench_fe3d.py factorreuse   # zoned nh 2.0: GMRES, older factor (~25 min)
    python benchmarks/bench_fe3d.py factorreuse --materials mr --thickness 0.8  # slowest case

Forces in N, gaps in mm.  t = 1.4 mm, Mooney-Rivlin, unless stated.  Timings are wall-clock on
whatever machine runs this (noisy when shared), on one core: the numerical libraries get one
thread each unless the caller sets ``OMP_NUM_THREADS`` / ``OPENBLAS_NUM_THREADS`` /
``MKL_NUM_THREADS`` (PARDISO is on one thread anyway; OpenBLAS's default of one per core gave
no gain on the 3D model, 46 s against 42 s for the stick-anchor test, and made two runs side by
side 2-3x slower).
"""

from __future__ import annotations

from grasprom.threads import default_blas_threads

default_blas_threads(1)  # before numpy loads OpenBLAS: one core per run

import json
import sys
import time
from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from grasprom.fe.datafiles import own_wall_time_s
from grasprom.fe.mesh3d import MeshSpec3D
from grasprom.fe.model2d import CaseSpec, MeshSpec, SolverSettings, run_case
from grasprom.fe.model3d import CaseSpec3D, run_case_3d, semi_membrane_jaw_stiffness

T = 1.4
#: bending (20, 10), approach (5), walls meeting (2 t = 2.8), compaction (2.7, 2.6); the
#: 200 N force cap is reached near gap 2.4 mm
GAPS = (20.0, 10.0, 5.0, 2.9, 2.7, 2.6)
FINE = MeshSpec3D(n_layers=3, n_circ=16, n_jaw=6, n_free=8, grading=2.0)
#: the fold-resolving cross-section of the full-tube studies (docs/fe-model.md)
FOLD_MESH = MeshSpec3D(n_circ=24, grading=8.0)


def _with_gaps(spec: CaseSpec3D, gaps=GAPS) -> CaseSpec3D:
    return replace(spec, solver=replace(spec.solver, land_on_gaps_mm=tuple(gaps)))


def _force_at(table, gaps=GAPS, col: str = "force_N") -> dict:
    out = {}
    for g in gaps:
        sel = np.isclose(table["gap_mm"], g)
        out[g] = float(table.loc[sel, col].iloc[0]) if sel.any() else float("nan")
    return out


def _run(spec: CaseSpec3D, label: str, solver: str = "auto", progress=None):
    t0 = time.perf_counter()
    res = run_case_3d(spec, solver=solver, progress=progress)
    i = res.info
    print(
        f"[{label}] {res.status} ({i['status_reason']}): dofs {i['dofs']}, steps {i['steps']}, "
        f"newton {i['newton_iterations']}, failures {i['failures']}, "
        f"wall {time.perf_counter() - t0:.1f} s, last gap {i['last_gap_mm']:.3f} mm",
        flush=True,
    )
    return res


def _print_row(label: str, values: dict, fmt: str = "{:9.4f}") -> None:
    print(f"  {label:<28}" + " ".join(fmt.format(v) for v in values.values()), flush=True)


def _header(gaps=GAPS) -> None:
    print(f"  {'gap (mm)':<28}" + " ".join(f"{g:9.2f}" for g in gaps))


def _base(**kw) -> CaseSpec3D:
    return _with_gaps(CaseSpec3D("mr", T, **kw))


def bench_default() -> dict:
    """Default case (stick, free ends) and its ratio to the 2D strip x jaw length."""
    spec = _base()
    r3 = _run(spec, "3D default stick")
    s2 = CaseSpec("mr", T, solver=SolverSettings(land_on_gaps_mm=GAPS))
    r2 = run_case(s2)
    f3, f2 = _force_at(r3.table), _force_at(r2.table)
    _header()
    _print_row("3D force_N", f3)
    _print_row("2D force_N (x jaw length)", f2)
    _print_row("3D / 2D", {g: f3[g] / f2[g] for g in GAPS}, "{:9.3f}")
    _print_row("3D peak pressure MPa", _force_at(r3.table, col="peak_pressure_MPa"))
    _print_row("3D contact length mm", _force_at(r3.table, col="contact_length_mm"))
    return {"3d": f3, "2d": f2, "info": {k: r3.info[k] for k in ("dofs", "steps", "wall_time_s")}}


def bench_solver() -> dict:
    """Default case with each linear solver: SuperLU (the baseline) vs MKL PARDISO."""
    res, wall = {}, {}
    for name in ("superlu", "pardiso"):
        t0 = time.perf_counter()
        res[name] = _run(_base(), f"default case, {name}", solver=name)
        wall[name] = time.perf_counter() - t0
    fa, fb = (_force_at(res[k].table) for k in ("superlu", "pardiso"))
    _header()
    _print_row("SuperLU force_N", fa)
    _print_row("PARDISO force_N", fb)
    _print_row("PARDISO / SuperLU - 1", {g: fb[g] / fa[g] - 1 for g in GAPS}, "{:9.1e}")
    print(
        f"  wall time: SuperLU {wall['superlu']:.1f} s, PARDISO {wall['pardiso']:.1f} s, "
        f"speed-up {wall['superlu'] / wall['pardiso']:.2f} (round-off can change the step "
        "cuts, so the steps may differ)",
        flush=True,
    )
    return {
        "wall_s": wall,
        "speedup": wall["superlu"] / wall["pardiso"],
        "force_N": {"superlu": fa, "pardiso": fb},
        "newton": {k: r.info["newton_iterations"] for k, r in res.items()},
    }


def bench_contact() -> dict:
    """Stick vs frictionless at the default mesh; tangential share of the stick reaction."""
    rs = _run(_base(contact="stick"), "stick")
    rf = _run(_base(contact="frictionless"), "frictionless")
    fs, ff = _force_at(rs.table), _force_at(rf.table)
    _header()
    _print_row("stick force_N", fs)
    _print_row("frictionless force_N", ff)
    _print_row("stick / frictionless - 1", {g: fs[g] / ff[g] - 1 for g in GAPS}, "{:9.4f}")
    _print_row("stick tangential share", _force_at(rs.table, col="tangential_share"))
    r2 = run_case(CaseSpec("mr", T, solver=SolverSettings(land_on_gaps_mm=GAPS)))
    f2 = _force_at(r2.table)
    _print_row("2D force_N (x jaw length)", f2)
    _print_row("stick / 2D", {g: fs[g] / f2[g] for g in GAPS}, "{:9.3f}")
    _print_row("frictionless / 2D", {g: ff[g] / f2[g] for g in GAPS}, "{:9.3f}")
    return {"stick": fs, "frictionless": ff, "2d": f2}


def _dense_band(table, grid: np.ndarray) -> np.ndarray:
    """Force (N) of ``table`` at the gaps ``grid`` (mm), log-interpolated between its steps."""
    logf = np.log(np.maximum(table["force_N"].to_numpy(), 1e-12))
    return np.exp(np.interp(-grid, -table["gap_mm"].to_numpy(), logf))


def bench_crease(tube_length: float = 60.0) -> dict:
    """Crease band (2t..4t) of the 3D stick case: default steps vs small steps, dense, with and
    without the crease placed by energy (mr, t = 1.4, the default cross-section, 60 mm tube)."""
    base = CaseSpec3D("mr", T, tube_length_mm=tube_length, closed_gap_mm=2.6)
    base = replace(base, mesh=replace(base.mesh, n_free=3))
    small = {"dh_max_mm": 0.25, "max_rel_force_step": 0.1}
    grid = np.linspace(2 * T, 4 * T, 400)  # the crease band, gap 2t..4t
    out, curves = {}, {}
    for maxwell in (False, True):
        for label, kw in (("default steps", {}), ("small steps", small)):
            solver = replace(base.solver, maxwell_crease=maxwell, **kw)
            r = _run(replace(base, solver=solver), f"maxwell={maxwell} {label}")
            curves[(maxwell, label)] = _dense_band(r.table, grid)
            out[f"maxwell={maxwell} {label} wall_s"] = r.info["wall_time_s"]
        rel = curves[(maxwell, "default steps")] / curves[(maxwell, "small steps")] - 1
        k = int(np.argmax(np.abs(rel)))
        key = f"maxwell={maxwell}"
        out[key] = {
            "max": float(np.abs(rel).max()),
            "at_gap_mm": float(grid[k]),
            "median": float(np.median(np.abs(rel))),
            "share_beyond_3pct": float((np.abs(rel) > 0.03).mean()),
        }
        print(f"  {key}: default / small steps - 1 over gaps {grid[0]:.2f}-{grid[-1]:.2f} mm: "
              f"max {out[key]['max']:.1%} at {grid[k]:.2f} mm, median {out[key]['median']:.1%}, "
              f"beyond 3 %: {out[key]['share_beyond_3pct']:.0%}", flush=True)  # fmt: skip
    return out


def bench_laws(closed_gap: float = 5.0) -> dict:
    """Contact laws in 3D (mr, t = 1.4, default mesh) to gap 5 mm: force, share, cost."""
    gaps = (20.0, 10.0, 5.0)
    laws = [("frictionless", 0.0), ("coulomb", 0.1), ("coulomb", 0.3), ("coulomb", 1.0)]
    out = {}
    for contact, mu in [*laws, ("stick", 0.0)]:
        spec = CaseSpec3D("mr", T, contact=contact, friction=mu, closed_gap_mm=closed_gap)
        r = _run(_with_gaps(spec, gaps), f"{contact} {mu:g}")
        f = _force_at(r.table, gaps)
        out[f"{contact} {mu:g}"] = {
            **{f"F@{g:g}": f[g] for g in gaps},
            "max_share": float(r.table["tangential_share"].max()),
            "steps": r.info["steps"],
            "newton": r.info["newton_iterations"],
            "wall_s": r.info["wall_time_s"],
        }
    print("  " + " | ".join(["law", *next(iter(out.values()))]))
    for k, v in out.items():
        print("  " + " | ".join([k, *(f"{x:.4g}" for x in v.values())]), flush=True)
    return out


CASE_GAPS = (20.0, 10.0, 5.0)
"""Gaps (mm) of the per-case 3D / 2D table: bending (20, 10) and approach (5)."""


def _shipped_case(mat: str, t: float, fe_dir: str = "fe_data/default"):
    """The shipped 3D case (stick): its table and sidecar (``None`` if not there)."""
    import pandas as pd

    from grasprom.fe.datafiles import case_files, case_stem

    files = case_files(fe_dir, case_stem(mat, t))
    if not files.json.exists():
        return None
    return pd.read_csv(files.csv), json.loads(files.json.read_text())


def _case_row(table, info: dict, f2: dict) -> dict:
    f3 = _force_at(table, CASE_GAPS) if info.get("landed", True) else {}
    gaps = np.asarray(table["gap_mm"])
    force = np.asarray(table["force_N"])
    if not f3:  # shipped tables do not land on the gaps: interpolate in log force
        f3 = {
            g: float(np.exp(np.interp(-g, -gaps, np.log(np.maximum(force, 1e-12)))))
            for g in CASE_GAPS
        }
    return {
        "wall_s": own_wall_time_s(info),
        "dofs": info["dofs"],
        "steps": info["steps"],
        "newton": info["newton_iterations"],
        "newton_per_step": info["newton_iterations"] / max(info["steps"], 1),
        "last_gap_mm": info["last_gap_mm"],
        "last_force_N": float(force[-1]),
        **{f"3d/2d@{g:g}": f3[g] / f2[g] for g in CASE_GAPS},
    }


def bench_cases(thicknesses=(0.8, 1.4, 2.0), materials=("mr", "le")) -> dict:
    """Full strokes, t 0.8/1.4/2.0 x mr/le, stick (shipped) and frictionless: cost, 3D/2D.

    The stick cases are the shipped ones (``fe_data/default``, their sidecars' wall time, run
    while the sweep shared the machine); the frictionless ones run here.
    """
    rows = {}
    for mat in materials:
        for t in thicknesses:
            r2 = run_case(CaseSpec(mat, t, solver=SolverSettings(land_on_gaps_mm=CASE_GAPS)))
            f2 = _force_at(r2.table, CASE_GAPS)
            shipped = _shipped_case(mat, t)
            if shipped is not None:
                table, meta = shipped
                rows[(mat, t, "stick")] = _case_row(table, {**meta["fe_info"], "landed": False}, f2)
            r = _run(
                _with_gaps(CaseSpec3D(mat, t, contact="frictionless"), CASE_GAPS), f"{mat} t={t}"
            )
            rows[(mat, t, "frictionless")] = _case_row(r.table, r.info, f2)
    cols = list(next(iter(rows.values())))
    print("  " + " | ".join(["case", *cols]))
    for k, v in rows.items():
        cells = [f"{x:.3f}" if isinstance(x, float) else str(x) for x in v.values()]
        print("  " + " | ".join([f"{k[0]} {k[1]} {k[2]}", *cells]), flush=True)
    for mat in materials:
        for t in thicknesses:
            if (mat, t, "stick") not in rows:
                continue
            s, f = rows[(mat, t, "stick")], rows[(mat, t, "frictionless")]
            ratio = {g: s[f"3d/2d@{g:g}"] / f[f"3d/2d@{g:g}"] - 1 for g in CASE_GAPS}
            _print_row(f"{mat} {t} stick/frictionless-1", ratio, "{:9.4f}")
    return {f"{k[0]}_{k[1]}_{k[2]}": v for k, v in rows.items()}


def bench_length(lengths=(60.0, 120.0, 240.0)) -> dict:  # n_free: 3, 6, 9 (default mesh 9)
    """Tube-length convergence of the force at fixed gaps (free ends and seed ends)."""
    out = {}
    for ends, L in [("free", L) for L in lengths] + [("seed", L) for L in lengths[1:]]:
        base = CaseSpec3D("mr", T)
        n_free = base.mesh.n_free + int(round(3 * np.log2(L / base.tube_length_mm)))
        mesh = replace(base.mesh, n_free=max(2, n_free))
        r = _run(_base(tube_length_mm=L, ends=ends, mesh=mesh), f"L={L:g} ends={ends}")
        out[(ends, L)] = _force_at(r.table)
    _header()
    for k, v in out.items():
        _print_row(f"{k[0]} L={k[1]:g}", v)
    for ends in ("free", "seed"):
        for a, b in zip(lengths[:-1], lengths[1:]):
            if (ends, a) not in out:
                continue
            rel = {g: out[(ends, b)][g] / out[(ends, a)][g] - 1 for g in GAPS}
            _print_row(f"{ends} F(L={b:g})/F(L={a:g})-1", rel, "{:9.4f}")
    return {f"{k[0]}_{k[1]:g}": v for k, v in out.items()}


#: gaps of the axial study beyond the jaw: bending, the crease band, the walls meeting
FREE_GAPS = (20.0, 10.0, 6.0, 5.0, 4.0, 3.5, 3.0, 2.9, 2.8, 2.7, 2.6, 2.5)


def bench_free(n_free=(9, 6, 5, 4)) -> dict:
    """Axial divisions beyond the jaw on the 240 mm tube (default cross-section, 9 the default):
    force at fixed gaps relative to the first, wall time (about 4 min)."""
    out, walls = {}, {}
    for n in n_free:
        spec = _base()
        spec = _with_gaps(replace(spec, mesh=replace(spec.mesh, n_free=n)), FREE_GAPS)
        t0 = time.perf_counter()
        r = _run(spec, f"n_free={n}")
        walls[n] = time.perf_counter() - t0
        out[n] = _force_at(r.table, FREE_GAPS)
    _header(FREE_GAPS)
    ref = out[n_free[0]]
    _print_row(f"n_free={n_free[0]} (N)", ref)
    for n in n_free[1:]:
        rel = {g: 100.0 * (out[n][g] / ref[g] - 1.0) for g in FREE_GAPS}
        _print_row(f"n_free={n} (%), {walls[n] / walls[n_free[0]]:.2f} x time", rel, "{:9.2f}")
    return {"forces_N": out, "wall_s": walls}


def bench_mesh() -> dict:
    """Mesh convergence: default vs a mesh refined in every direction."""
    rd = _run(_base(), "default mesh")
    rf = _run(_base(mesh=FINE), "fine mesh")
    fd, ff = _force_at(rd.table), _force_at(rf.table)
    _header()
    _print_row("default", fd)
    _print_row("fine", ff)
    _print_row("default / fine - 1", {g: fd[g] / ff[g] - 1 for g in GAPS}, "{:9.4f}")
    return {"default": fd, "fine": ff}


BAND_GAPS = (10.0, 6.0, 5.0, 4.5, 4.0, 3.5, 3.0, 2.9, 2.8, 2.75, 2.7, 2.65, 2.6, 2.5)
RISE_FORCES = (5.0, 10.0, 20.0, 50.0, 100.0)


def _gap_at_force(table, forces=RISE_FORCES, below: float = 3.2) -> dict:
    """Gap (mm) at which the wall-contact rise (gaps < ``below``) reaches each force (N)."""
    t = table[table["gap_mm"] < below].sort_values("force_N")
    return {f: float(np.interp(f, t["force_N"], t["gap_mm"])) for f in forces}


def bench_meshband(tube_length: float = 60.0) -> dict:
    """Crease band and walls meeting (mr, t = 1.4, stick, 60 mm tube) on meshes against a fine
    reference (2 x 24 x (8 + 3), small steps): force at fixed gaps, gap at equal force."""
    small = {"dh_max_mm": 0.25, "max_rel_force_step": 0.1}
    variants = {  # label: (mesh changes, solver changes)
        "reference 2x24x8, small steps": ({"n_circ": 24, "n_jaw": 8}, small),
        "default 2x12x4": ({}, {}),
        "default, small steps": ({}, small),
        "2x12x4 graded 6:1": ({"grading": 6.0}, {}),
        "2x16x6 graded 6:1": ({"n_circ": 16, "n_jaw": 6, "grading": 6.0}, {}),
    }
    tables, out = {}, {}
    for label, (mk, sk) in variants.items():
        spec = CaseSpec3D("mr", T, tube_length_mm=tube_length, closed_gap_mm=2.45)
        spec = replace(spec, mesh=replace(spec.mesh, n_free=3, **mk))
        spec = replace(spec, solver=replace(spec.solver, land_on_gaps_mm=BAND_GAPS, **sk))
        r = _run(spec, label)
        tables[label] = r.table
        out[label] = {"force_N": _force_at(r.table, BAND_GAPS), "info": r.info}
    ref_label = next(iter(variants))
    ref = out[ref_label]["force_N"]
    _header(BAND_GAPS)
    for label, v in out.items():
        _print_row(label, v["force_N"], "{:9.3f}")
    for label, v in out.items():
        rel = {g: v["force_N"][g] / ref[g] - 1 for g in BAND_GAPS}
        _print_row(f"{label[:20]} / ref - 1", rel, "{:+9.3f}")
        v["rel_to_reference"] = rel
    gref = _gap_at_force(tables[ref_label])
    print("  gap at equal force on the wall-contact rise, minus the reference's (um):")
    print(f"  {'force (N)':<28}" + " ".join(f"{f:9.0f}" for f in RISE_FORCES))
    for label in out:
        g = _gap_at_force(tables[label])
        dg = {f: 1000.0 * (g[f] - gref[f]) for f in RISE_FORCES}
        _print_row(label, dg, "{:+9.1f}")
        out[label]["gap_shift_um"] = dg
    return {k: {kk: vv for kk, vv in v.items() if kk != "info"} for k, v in out.items()}


#: the five cross-sections of the 240 mm tube study (docs/fe-model.md), reference first
TUBE_MESHES = {
    "3 x 24, layers 3:1 (reference)": {"n_layers": 3, "n_circ": 24, "grading": 8.0,
                                       "radial_grading": 3.0},
    "default 2 x 12 graded 2:1": {},
    "2 x 24 graded 8:1": {"n_circ": 24, "grading": 8.0},
    "2 x 36 graded 8:1": {"n_circ": 36, "grading": 8.0},
    "3 x 36, layers 3:1": {"n_layers": 3, "n_circ": 36, "grading": 8.0, "radial_grading": 3.0},
}  # fmt: skip
#: bending, the approach, the crease band (2 t .. 4 t) and the compaction, for t = 1.4 mm
TUBE_GAPS = (20.0, 10.0, 5.6, 4.9, 4.2, 3.5, 3.2, 3.0, 2.9, 2.7, 2.6)


def _compare_meshes(base: CaseSpec3D, meshes: dict, gaps, forces=()) -> dict:
    """Run ``base`` with each mesh change of ``meshes`` (the reference first), landing on
    ``gaps``; print the forces (N) and each mesh's ratio to the reference - 1, and the gaps (mm)
    at which each mesh reaches ``forces`` (N)."""
    out = {}
    for label, mk in meshes.items():
        spec = _with_gaps(replace(base, mesh=replace(base.mesh, **mk)), gaps)
        r = _run(spec, label)
        out[label] = {"force_N": _force_at(r.table, gaps), "dofs": r.info["dofs"]}
        out[label] |= {"newton": r.info["newton_iterations"], "wall_s": r.info["wall_time_s"]}
        out[label]["gap_at_force_mm"] = _gap_at_force(r.table, forces) if forces else {}
    ref = next(iter(out.values()))["force_N"]
    _header(gaps)
    for label, v in out.items():
        _print_row(label[:28], v["force_N"], "{:9.3f}")
    for label, v in out.items():
        v["rel_to_reference"] = {g: v["force_N"][g] / ref[g] - 1 for g in gaps}
        _print_row(f"{label[:20]} / ref - 1", v["rel_to_reference"], "{:+9.3f}")
    if forces:
        print(f"  {'gap (mm) at force (N)':<28}" + " ".join(f"{f:9.1f}" for f in forces))
        for label, v in out.items():
            _print_row(label[:28], v["gap_at_force_mm"], "{:9.3f}")
    return out


def bench_meshtube(meshes=TUBE_MESHES, gaps=TUBE_GAPS, tube_length: float | None = None) -> dict:
    """Cross-sections on the default 240 mm tube (mr, t = 1.4, stick; about an hour)."""
    base = _base() if tube_length is None else _base(tube_length_mm=tube_length)
    return _compare_meshes(base, meshes, gaps)


#: gaps of the through-the-wall study: bending, the crease band (2t..4t), the walls' knee and
#: the compaction rise, for t = 1.4 mm
LAYER_GAPS = (10.0, 6.0, 5.0, 4.5, 4.0, 3.5, 3.0, 2.9, 2.8, 2.7, 2.6, 2.5)
#: forces (N) at which the through-the-wall study compares the gaps (the steep walls meeting)
LAYER_FORCES = (3.5, 5.0, 10.0, 20.0, 50.0)
#: cross-sections with four and five layers through the wall (graded 8:1 toward the side
#: fold), the reference first, three axial refinements and the default's for comparison
LAYER_MESHES = {
    "4 x 48 (reference)": {"n_layers": 4, "n_circ": 48, "grading": 8.0},
    "4 x 24": {"n_layers": 4, "n_circ": 24, "grading": 8.0},
    "4 x 36": {"n_layers": 4, "n_circ": 36, "grading": 8.0},
    "4 x 64": {"n_layers": 4, "n_circ": 64, "grading": 8.0},
    "5 x 36": {"n_layers": 5, "n_circ": 36, "grading": 8.0},
    "4 x 36, 6 axial": {"n_layers": 4, "n_circ": 36, "grading": 8.0, "n_jaw": 6},
    "4 x 36, 8 axial": {"n_layers": 4, "n_circ": 36, "grading": 8.0, "n_jaw": 8},
    "4 x 36, 12 axial": {"n_layers": 4, "n_circ": 36, "grading": 8.0, "n_jaw": 12},
    "default 2 x 12 graded 2:1": {},
}  # fmt: skip


def bench_layers(
    meshes=LAYER_MESHES, gaps=LAYER_GAPS, tube_length: float = 60.0, forces=LAYER_FORCES
) -> dict:
    """Crease band with four and five layers through the wall (mr, t = 1.4, stick, 60 mm tube,
    4 axial divisions over the jaw unless stated; about 3 h): force at fixed gaps against
    4 x 48, and the gap at equal force."""
    base = CaseSpec3D("mr", T, tube_length_mm=tube_length)
    base = replace(base, mesh=replace(base.mesh, n_free=3))
    return _compare_meshes(base, meshes, gaps, forces)


#: tube length (mm) of the plane-strain slices; their jaw is 2 mm longer (flat over the tube)
PLANE_STRAIN_L = 2.0


def _plane_strain_3d(mesh: MeshSpec3D, gaps, label: str) -> dict:
    """3D in plane strain (u_z = 0, frictionless) to gap 2.8 mm: force per length (N/mm)."""
    L = PLANE_STRAIN_L
    spec = CaseSpec3D("mr", T, jaw_length_mm=L + 2.0, tube_length_mm=L, plane_strain=True,
                      contact="frictionless", closed_gap_mm=2.8, mesh=mesh)  # fmt: skip
    r3 = _run(_with_gaps(spec, gaps), label)
    return {g: v / L for g, v in _force_at(r3.table, gaps).items()}


def _plane_strain_2d(mesh: MeshSpec, gaps) -> dict:
    """The 2D model (frictionless) to gap 2.8 mm: force per length (N/mm)."""
    s2 = CaseSpec("mr", T, closed_gap_mm=2.8, mesh=mesh)
    r2 = run_case(replace(s2, solver=SolverSettings(land_on_gaps_mm=gaps)))
    return _force_at(r2.table, gaps, "force_per_length_N_per_mm")


def bench_planestrain(nc: int = 32) -> dict:
    """Plane-strain 3D (u_z = 0, jaw as long as the tube) vs the 2D model, full stroke."""
    gaps = (20.0, 10.0, 6.0, 4.0, 3.2, 2.9)
    mesh = MeshSpec3D(n_layers=2, n_circ=nc, n_jaw=1, n_free=0, grading=1.0)
    f3 = _plane_strain_3d(mesh, gaps, f"plane-strain 3D (2 x {nc})")
    res2 = {(nl, n): _plane_strain_2d(MeshSpec(n_layers=nl, n_circ=n), gaps)
            for nl, n in ((2, nc), (4, 2 * nc))}  # fmt: skip
    _header(gaps)
    _print_row("3D N/mm", f3)
    for k, v in res2.items():
        _print_row(f"2D {k} N/mm", v)
        _print_row(f"3D / 2D {k} - 1", {g: f3[g] / v[g] - 1 for g in gaps}, "{:9.4f}")
    return {"3d": f3, **{f"2d_{k}": v for k, v in res2.items()}}


#: crease band at t = 1.4 (2t..4t) with the bending point 10 and the walls meeting 2t + 0.05
ELEMENT_GAPS = (10.0, 6.0, 5.5, 5.0, 4.5, 4.0, 3.5, 3.2, 3.0, 2.9, 2.85)
#: (label, n_layers, n_circ, grading, radial_grading, beta): the spurious instability of the
#: mixed element (beta 0, 0.01) and the cross-sections, coarse to the 2x refinement
ELEMENT_CASES = (
    ("4x24 g8 beta 0", 4, 24, 8.0, 1.0, 0.0),
    ("4x24 g8 beta 0.01", 4, 24, 8.0, 1.0, 0.01),
    ("4x24 g8 beta 0.02", 4, 24, 8.0, 1.0, 0.02),
    ("4x24 g8 beta 0.05 (the test's)", 4, 24, 8.0, 1.0, 0.05),
    ("2x12 g2 beta 0", 2, 12, 2.0, 1.0, 0.0),
    ("2x12 g2 beta 0.05", 2, 12, 2.0, 1.0, 0.05),
    ("2x24 g8 beta 0.05", 2, 24, 8.0, 1.0, 0.05),
    ("3x24 g8 rg3 beta 0.05", 3, 24, 8.0, 3.0, 0.05),
    ("4x48 g8.35 beta 0.02", 4, 48, 8.35, 1.0, 0.02),
    # the full tube's converged cross-section, its refinement, and a beta that holds the fold
    ("4x36 g8 beta 0.05", 4, 36, 8.0, 1.0, 0.05),
    ("4x64 g8 beta 0.05", 4, 64, 8.0, 1.0, 0.05),
    ("4x36 g8 beta 0.2", 4, 36, 8.0, 1.0, 0.2),
)


def bench_element() -> dict:
    """Crease band in plane strain (frictionless, mr t = 1.4): 3D Q2/P1 vs the 2D model."""
    gaps = ELEMENT_GAPS
    ref = {}
    for label, mesh in (("2D default", MeshSpec()), ("2D refined", MeshSpec().refined(2))):
        t0 = time.perf_counter()
        ref[label] = _plane_strain_2d(mesh.for_wall(15.0 - T, T), gaps)
        print(f"[{label}] {time.perf_counter() - t0:.0f} s", flush=True)
    base = ref["2D default"]
    rel = {"2D refined": {g: ref["2D refined"][g] / base[g] - 1 for g in gaps}}
    for label, nl, nc, g8, rg, beta in ELEMENT_CASES:
        mesh = MeshSpec3D(n_layers=nl, n_circ=nc, n_jaw=1, n_free=0, grading=g8,
                          radial_grading=rg, beta=beta)  # fmt: skip
        f3 = _plane_strain_3d(mesh, gaps, label)
        rel[label] = {g: f3[g] / base[g] - 1 for g in gaps}
    print("force per length / 2D default - 1, in %:")
    _header(gaps)
    for label, v in rel.items():
        _print_row(label, {g: 100 * x for g, x in v.items()}, "{:+9.1f}")
    return {"2d_N_per_mm": base, "rel": rel}


def bench_shell() -> dict:
    """Small-deflection jaw stiffness of a long tube vs semi-membrane shell theory."""
    d = 0.02
    out = {}
    for t in (0.8, 1.4):
        mesh = replace(CaseSpec3D("le", t).mesh, n_free=9)
        spec = CaseSpec3D(
            "le",
            t,
            tube_length_mm=240.0,
            contact="frictionless",
            closed_gap_mm=30.0 - 2 * d,
            mesh=mesh,
        )
        spec = replace(spec, solver=replace(spec.solver, dh_initial_mm=d))
        r = _run(spec, f"small deflection t={t}")
        k_fe = float(r.table["force_N"].iloc[-1]) / d
        m = spec.make_material()
        Rm = 0.5 * (spec.diameter_mm - t)
        k_sm = semi_membrane_jaw_stiffness(Rm, t, m.E, m.nu, spec.flat_half_length_mm)
        D = m.E * t**3 / (12 * (1 - m.nu**2))
        # 2D ring: diameter change 2 d = (pi/4 - 2/pi) F R^3 / D per unit length, x jaw length
        k_ring = 2 * D / ((np.pi / 4 - 2 / np.pi) * Rm**3) * spec.jaw_length_mm
        print(
            f"  t={t}: FE {k_fe:.4f} N/mm, semi-membrane {k_sm:.4f} N/mm "
            f"(FE/SM {k_fe / k_sm:.3f}), 2D ring x jaw length {k_ring:.4f} N/mm",
            flush=True,
        )
        out[t] = {"fe": k_fe, "semi_membrane": k_sm, "ring_x_jaw": k_ring}
    return out


def _time(fn, repeat: int = 5) -> float:
    """Best wall time (s) of ``repeat`` calls after one warm-up."""
    fn()
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _assembly_times(label: str, mesh: MeshSpec3D) -> dict:
    """Wall times (s) of one assembly on ``mesh`` and of the plain einsum baseline."""
    from grasprom.fe.hyperelastic3d import stress_and_tangent
    from grasprom.fe.model3d import assemble, build_disc, kinematics

    spec = replace(_base(), mesh=mesh)
    disc, mat = build_disc(spec), spec.make_material()
    u = 1e-3 * np.random.default_rng(0).standard_normal(disc.ndof)
    F = kinematics(disc, u)
    p = np.zeros(F.shape[:2])
    _, A, _, _ = stress_and_tangent(mat, F, p)
    G, dx = disc.grads, disc.dx
    t_full = _time(lambda: assemble(disc, mat, u))
    t_one = _time(lambda: assemble(disc, mat, u, block=G.shape[0]))  # one pass, no blocks
    t_f = _time(lambda: assemble(disc, mat, u, tangent=False))
    t_pt = _time(lambda: stress_and_tangent(mat, F, p))
    # the baseline: the element matrices alone, by one optimised einsum of their definition
    path = "eqaj,eqijkl,eqbl,eq->eaibk"
    t_plain = _time(lambda: np.einsum(path, G, A, G, dx, optimize="greedy"), 2)
    print(
        f"  {label}: {disc.ndof} dofs, {G.shape[0]} elements; assemble f+K {t_full:.3f} s "
        f"(f only {t_f:.3f} s, pointwise A {t_pt:.3f} s); in one pass over all elements "
        f"{t_one:.3f} s = {t_one / t_full:.2f} x the blocked assembly; the element matrices "
        f"alone by plain einsum {t_plain:.3f} s = {t_plain / t_full:.1f} x",
        flush=True,
    )
    return {
        "dofs": disc.ndof,
        "assemble_s": t_full,
        "one_pass_s": t_one,
        "force_only_s": t_f,
        "pointwise_tangent_s": t_pt,
        "plain_einsum_element_matrices_s": t_plain,
    }


def _constraint_times(label: str, mesh: MeshSpec3D) -> dict:
    """Wall times (s) of constraining a tangent and of a Levenberg-shifted PARDISO solve, each
    against the way it was done before (a mask over all entries; ``K + s * identity``, which
    drops the stored zeros, so PARDISO redid its analysis for the shifted matrix and again
    for the next plain one)."""
    import scipy.sparse as sp

    from grasprom.fe import model3d
    from grasprom.fe.linsolve import PardisoLDLT, shifted

    spec = replace(_base(), mesh=mesh)
    st = model3d._setup(spec, "auto")
    d = st.disc
    K = model3d.assemble(d, st.material, np.zeros(d.ndof))[1]
    fixed = st.base_fixed | (np.random.default_rng(1).random(d.ndof) < 0.05)

    def masked():
        keep = ~(fixed[d.rows] | fixed[d.cols])
        data = K.data * keep
        data[d.diag_pos[fixed]] = 1.0
        return sp.csr_matrix((data, d.indices, d.indptr), shape=K.shape)

    t_new = _time(lambda: model3d._constrained(st, K, fixed, False))
    t_old = _time(masked)
    Kc = model3d._constrained(st, K, fixed, False)
    r = np.where(fixed, 0.0, 1.0)
    shift = 1e-3 * float(abs(Kc.diagonal()).mean())
    solve = PardisoLDLT()
    solve(Kc, r)  # analysed once

    def shifted_then_plain(Ks):
        solve(Ks, r)
        solve(Kc, r)

    t_keep = _time(lambda: shifted_then_plain(shifted(Kc, shift)))
    a_keep = solve.analyses
    t_drop = _time(lambda: shifted_then_plain(Kc + shift * sp.identity(d.ndof, format="csr")))
    a_drop = solve.analyses - a_keep
    plain, matched = PardisoLDLT(matching=False), PardisoLDLT()
    plain(Kc, r), matched(Kc, r)  # analysed
    t_plain = _time(lambda: plain(Kc, r))
    t_match = _time(lambda: matched(Kc, r))
    print(
        f"  {label}: factor + solve {t_match:.3f} s (without scaling and matching "
        f"{t_plain:.3f} s, {t_plain / t_match:.2f} x)",
        flush=True,
    )
    print(
        f"  {label}: constrain {t_new * 1e3:.1f} ms (mask over all entries {t_old * 1e3:.1f} ms, "
        f"{t_old / t_new:.2f} x); a shifted solve and the next plain one {t_keep:.2f} s with "
        f"the pattern kept, {t_drop:.2f} s with K + s I ({t_drop / t_keep:.2f} x; PARDISO "
        f"analyses {a_keep} and {a_drop})",
        flush=True,
    )
    return {
        "constrain_s": t_new,
        "constrain_mask_s": t_old,
        "shift_s": t_keep,
        "shift_drop_s": t_drop,
        "factor_s": t_match,
        "factor_without_matching_s": t_plain,
    }


def bench_assembly() -> dict:
    """Tangent assembly: the batched kernels against a plain einsum baseline; default case.
    Constraining and the Levenberg shift against their earlier forms."""
    meshes = (
        ("default 2 x 12", MeshSpec3D()),
        ("2 x 24 g8", FOLD_MESH),
        ("4 x 36 g8", MeshSpec3D(n_layers=4, n_circ=36, grading=8.0)),
    )
    out = {label: _assembly_times(label, mesh) for label, mesh in meshes}
    for label, mesh in meshes:
        out[label].update(_constraint_times(label, mesh))
    res = _run(_base(), "default case")
    out["default_case_s"] = res.info["wall_time_s"]
    out["newton_iterations"] = res.info["newton_iterations"]
    return out


#: three of the mesh study's cross-sections (``TUBE_MESHES``), coarsest first
CCX_MESHES = {
    k: TUBE_MESHES[k]
    for k in ("default 2 x 12 graded 2:1", "2 x 24 graded 8:1", "3 x 24, layers 3:1 (reference)")
}


def bench_ccx(meshes=CCX_MESHES, gaps=TUBE_GAPS, workdir: str | None = None) -> dict:
    """Against CalculiX (a second code) on the 240 mm tube: mr, t = 1.4, frictionless (~1 h).

    Needs ``ccx`` (``apt-get install calculix-ccx``).  CalculiX's Newton has no path control
    through a crease, so it may stop in the crease band; its last converged gap is printed.
    """
    import tempfile

    from grasprom.fe.ccx import run_ccx

    out = {}
    for label, mk in meshes.items():
        spec = _with_gaps(replace(_base(contact="frictionless"), mesh=MeshSpec3D(**mk)), gaps)
        ours = _force_at(_run(spec, label).table, gaps)
        with tempfile.TemporaryDirectory(dir=workdir) as tmp:
            res = run_ccx(spec, tmp, min(gaps))
        tb = res.table.iloc[::-1]
        ref = {g: float(np.interp(g, tb.gap_mm, tb.force_N)) for g in gaps}
        ref = {g: (v if g >= tb.gap_mm.min() - 1e-9 else float("nan")) for g, v in ref.items()}
        print(
            f"[ccx {label}] completed {res.completed}, last gap {tb.gap_mm.min():.3f} mm, "
            f"{len(tb)} increments, wall {res.wall_time_s:.0f} s, {res.deck.n_tube_nodes} nodes",
            flush=True,
        )
        out[label] = {"ours": ours, "ccx": ref, "ccx_completed": res.completed}
        out[label]["ccx_wall_s"] = res.wall_time_s
    _header(gaps)
    for label, v in out.items():
        _print_row(f"{label[:20]} ours", v["ours"], "{:9.3f}")
        _print_row(f"{label[:20]} ccx", v["ccx"], "{:9.3f}")
        v["ours_over_ccx"] = {g: v["ours"][g] / v["ccx"][g] - 1 for g in gaps}
        _print_row(f"{label[:20]} ours/ccx-1", v["ours_over_ccx"], "{:+9.3f}")
    return out


class _OutOfTime(Exception):
    pass


def bench_wallsmeet(switch_gap: float = 3.5, budget_factor: float = 2.0) -> dict:
    """The walls meeting on a converged cross-section (4 x 36 graded 8:1, the default 240 mm
    tube, mr, t = 1.4, stick): with predicted contact below gap ``switch_gap`` (mm;
    ``SolverSettings.predict_contact_below_mm``, off before, through the crease) against the
    case as shipped (off), given ``budget_factor`` times the first run's time after the switch;
    prints the time to the switch and after it, and the gap (mm) each run reached (~1.5 h)."""
    base = _base()
    spec = _with_gaps(replace(base, mesh=replace(base.mesh, **LAYER_MESHES["4 x 36"])), LAYER_GAPS)
    out = {}
    for label, below in (("predicted contact", switch_gap), ("node by node (as shipped)", 0.0)):
        run = replace(spec, solver=replace(spec.solver, predict_contact_below_mm=below))
        t0, state = time.perf_counter(), {"gap": np.inf, "force": np.nan, "t_switch": None}
        budget = budget_factor * out["predicted contact"]["after_s"] if out else np.inf

        def progress(gap, force, t0=t0, state=state, budget=budget):
            state |= {"gap": gap, "force": force}
            if state["t_switch"] is None and gap < switch_gap:
                state["t_switch"] = time.perf_counter() - t0
            if (
                state["t_switch"] is not None
                and time.perf_counter() - t0 - state["t_switch"] > budget
            ):
                raise _OutOfTime

        try:
            r = run_case_3d(run, progress=progress)
            done = f"{r.status}, {r.info['newton_iterations']} Newton iterations"
            done += f", {r.info['failures']} failed steps"
        except _OutOfTime:
            done = "stopped: out of time"
        wall = time.perf_counter() - t0
        t_sw = state["t_switch"] if state["t_switch"] is not None else wall
        out[label] = {"to_switch_s": t_sw, "after_s": wall - t_sw, "gap_mm": state["gap"]}
        out[label] |= {"force_N": state["force"], "end": done}
        print(
            f"  {label:<26} to gap {switch_gap} mm {t_sw:6.0f} s, after {wall - t_sw:6.0f} s:"
            f" gap {state['gap']:.4f} mm, F {state['force']:.3f} N ({done})",
            flush=True,
        )
    return out


#: ``model3d.ACTIVE_SET_RTOL`` before it was raised (the baseline of :func:`bench_activeset`)
ACTIVE_SET_RTOL_BEFORE = 1e-4


def _converged_case(closed_gap: float) -> tuple[CaseSpec3D, tuple[float, ...]]:
    """The converged cross-section's case (4 x 36 graded 8:1, six axial divisions beyond the
    jaw, 240 mm tube, mr, t = 1.4, stick, contact predicted below gap 3.5 mm) to
    ``closed_gap`` (mm), landing on the gaps it returns (a short stroke ends on its closed
    gap)."""
    base = _base(closed_gap_mm=closed_gap)
    spec = replace(base, mesh=replace(base.mesh, **LAYER_MESHES["4 x 36"], n_free=6))
    gaps = tuple(g for g in (20.0, 15.0) + LAYER_GAPS if g > closed_gap)
    gaps += (closed_gap,) if closed_gap > 2.5 else ()
    spec = replace(spec, solver=replace(spec.solver, predict_contact_below_mm=3.5))
    return _with_gaps(spec, gaps), gaps


def _before_and_current(spec: CaseSpec3D, name: str, before, label, current=None) -> dict:
    """Run ``spec`` with the module constant ``model3d.<name>`` set to ``before``, then to
    ``current`` (default: its value now), and restore it: ``{"before"|"current": (value,
    result, wall_s)}``; ``label(value)`` names each run."""
    from grasprom.fe import model3d

    kept = getattr(model3d, name)
    current = kept if current is None else current
    out = {}
    for key, value in (("before", before), ("current", current)):
        setattr(model3d, name, value)
        try:
            t0 = time.perf_counter()
            r = _run(spec, label(value))
            out[key] = (value, r, time.perf_counter() - t0)
        finally:
            setattr(model3d, name, kept)
    return out


def bench_activeset(closed_gap: float = 1.5) -> dict:
    """Active-set passes solved to 1e-4 of the force scale (before) against the current
    ``model3d.ACTIVE_SET_RTOL``, on the converged cross-section (4 x 36 graded 8:1, six axial
    divisions beyond the jaw, 240 mm tube, mr, t = 1.4, stick, contact predicted below gap
    3.5 mm) from first touch to ``closed_gap`` (mm) or the force cap: wall time, steps, Newton
    iterations and the force at fixed gaps of each, the ratios and the force differences
    (~40 min for the full stroke; ``closed_gap=12`` gives the bending part in ~4 min)."""
    spec, gaps = _converged_case(closed_gap)
    runs = _before_and_current(
        spec, "ACTIVE_SET_RTOL", ACTIVE_SET_RTOL_BEFORE, lambda v: f"ACTIVE_SET_RTOL {v:g}"
    )
    out = {}
    _header(gaps)
    for label, (rtol, r, wall) in runs.items():
        force = _force_at(r.table, gaps)
        _print_row(f"{label} {rtol:g} (N)", force)
        out[label] = {"rtol": rtol, "wall_s": wall, "steps": r.info["steps"]}
        out[label] |= {"newton": r.info["newton_iterations"], "force_N": force}
    b, c = out["before"], out["current"]
    diff = {g: 100.0 * (c["force_N"][g] / b["force_N"][g] - 1.0) for g in gaps}
    _print_row("current vs before (%)", diff, "{:+9.2f}")
    out["ratio"] = {"wall": b["wall_s"] / c["wall_s"], "newton": b["newton"] / c["newton"]}
    print(
        f"  before/current: wall {out['ratio']['wall']:.2f} x, Newton iterations"
        f" {out['ratio']['newton']:.2f} x",
        flush=True,
    )
    return out


def bench_reuse(closed_gap: float = 12.0) -> dict:
    """The tangent predictor solving with the last Newton factor
    (``model3d.PREDICTOR_REUSES_FACTOR``) against factoring its own tangent (before), on the
    converged cross-section (4 x 36 graded 8:1, six axial divisions beyond the jaw, 240 mm
    tube, mr, t = 1.4, stick) from first touch to ``closed_gap`` (mm; default 12, the bending
    part, ~4 min for both; 1.5 runs to the force cap with contact predicted below gap 3.5 mm,
    ~30 min): wall time, factorisations, Newton iterations, forces at fixed gaps, ratios."""
    spec, gaps = _converged_case(closed_gap)
    runs = _before_and_current(  # "current": the reuse on (off by default)
        spec,
        "PREDICTOR_REUSES_FACTOR",
        False,
        lambda v: f"predictor reuses the Newton factor: {v}",
        current=True,
    )
    out = {}
    _header(gaps)
    for label, (_, r, wall) in runs.items():
        force = _force_at(r.table, gaps)
        _print_row(f"{label} (N)", force)
        out[label] = {"wall_s": wall, "steps": r.info["steps"], "force_N": force}
        out[label] |= {k: r.info[k] for k in ("newton_iterations", "factorizations")}
    b, c = out["before"], out["current"]
    _print_row("current vs before (%)", {g: 100.0 * (c["force_N"][g] / b["force_N"][g] - 1.0)
                                          for g in gaps}, "{:+9.4f}")  # fmt: skip
    out["ratio"] = {k: b[k] / c[k] for k in ("wall_s", "factorizations", "newton_iterations")}
    print(
        f"  before/current: wall {out['ratio']['wall_s']:.2f} x, factorisations "
        f"{b['factorizations']} / {c['factorizations']} = {out['ratio']['factorizations']:.2f} x,"
        f" Newton iterations {b['newton_iterations']} / {c['newton_iterations']}",
        flush=True,
    )
    return out


def bench_stall() -> dict:
    """Budgeted solves that stop once their residual keeps rising (``model3d.STALL_RISES``)
    against spending the whole budget (before), on the band study's 4 x 36 case (``band``):
    wall time, factorisations, and whether the tables are equal (~30 min)."""
    base, _ = _converged_case(2.8)
    spec = _with_gaps(replace(base, mesh=replace(base.mesh, **BAND_MESHES["4 x 36"])), BAND_GAPS)
    runs = _before_and_current(spec, "STALL_RISES", None, lambda v: f"STALL_RISES {v}")
    return _compare_runs(runs, ("steps", "newton_iterations", "factorizations"))


def _compare_runs(runs: dict, keys: tuple[str, ...]) -> dict:
    """Summary of :func:`_before_and_current`'s runs: the ``keys`` of each run's info, wall
    time, the before/current ratios and whether the tables are equal (printed too)."""
    out = {}
    for label, (_, r, wall) in runs.items():
        out[label] = {k: r.info[k] for k in keys} | {"wall_s": wall}
    b, c = out["before"], out["current"]
    same = runs["before"][1].table.equals(runs["current"][1].table)
    out["ratio"] = {k: b[k] / c[k] for k in ("wall_s", "factorizations")}
    out["tables_equal"] = same
    extra = "".join(f", {k} {b[k]} / {c[k]}" for k in keys if k not in ("factorizations",))
    print(
        f"  before/current: wall {b['wall_s']:.0f} / {c['wall_s']:.0f} s = "
        f"{out['ratio']['wall_s']:.2f} x, factorisations {b['factorizations']} / "
        f"{c['factorizations']}{extra}; tables equal: {same}",
        flush=True,
    )
    return out


def _sweep_case(
    material: str = "mr", thickness: float = 1.4, mesh: str | None = None
) -> CaseSpec3D:
    """The case ``grasprom sweep --model 3d [--mesh MESH]`` runs (its defaults, built the way it
    builds them: the mesh and solver settings of ``fe_data/default``, whose sidecars record the
    same spec; ``mesh="zoned"``: those of ``fe_data/3d_zoned``): 4 x 36 graded 8:1 (zoned: 2 x
    18 beyond the jaw zone), six axial divisions beyond the jaw, 240 mm tube, stick, contact
    predicted below gap 2.5 t, to the force cap, no landing gaps; the case's own run
    (``band_companion`` 0: the sweep's default adds the companion and the band selection,
    :mod:`grasprom.fe.bandselect`)."""
    from grasprom.fe import build_grid
    from grasprom.fe.grid3d import Model3DOptions, to_3d

    opts = Model3DOptions(mesh=mesh, band_companion=0)
    return to_3d(build_grid(f"{thickness:g}", material), opts, {})[0]


def bench_factor_reuse(material: str = "nh", thickness: float = 2.0) -> dict:
    """Newton solves with GMRES preconditioned by the last factorisation
    (``model3d.FACTOR_REUSE``) against a factorisation each (before), on the zoned sweep's case
    (``--mesh zoned``; nh 2.0 mm by default): wall time, factorisations, reuses, GMRES and
    Newton iterations; the largest force difference above the crease band (g > 4 t) and in it,
    and the gap at 20, 50 and 100 N (~25 min for both runs at nh 2.0 mm)."""
    spec = _sweep_case(material, thickness, mesh="zoned")
    runs = _before_and_current(spec, "FACTOR_REUSE", False, lambda v: f"factor reuse {v}")
    keys = ("steps", "newton_iterations", "factorizations", "factor_reuses", "krylov_iterations")
    out = _compare_runs(runs, keys)
    b, c = (runs[k][1].table for k in ("before", "current"))
    grid = np.linspace(max(b["gap_mm"].min(), c["gap_mm"].min()), 8.0 * thickness, 800)
    fb, fc = (np.interp(grid, x["gap_mm"][::-1], x["force_N"][::-1]) for x in (b, c))
    rel = np.abs(fc / np.maximum(fb, 1e-12) - 1.0)
    above, band = grid > 4.0 * thickness, (grid >= 2.0 * thickness) & (grid <= 4.0 * thickness)
    out["max_rel_force_diff"] = {
        "above_band": float(rel[above].max()),
        "band": float(rel[band].max()),
    }
    rise = (20.0, 50.0, 100.0)
    out["gap_at_force_mm"] = {
        k: _gap_at_force(runs[k][1].table, rise, 2.0 * thickness) for k in ("before", "current")
    }
    print(
        f"  force difference current vs before: above the band (g > 4 t) "
        f"{out['max_rel_force_diff']['above_band']:.1e}, in the band (2t..4t) "
        f"{100 * out['max_rel_force_diff']['band']:.2f} %; gap at 20/50/100 N (mm): "
        + "; ".join(
            f"{k} " + ", ".join(f"{v:.4f}" for v in out["gap_at_force_mm"][k].values())
            for k in ("before", "current")
        ),
        flush=True,
    )
    return out


def bench_forward_stall(thickness: float = 0.8) -> dict:
    """Forward steps whose solve stops once its residual keeps rising
    (``model3d.FORWARD_STALL_RISES``) against running to ``max_newton`` (before), on the
    sweep's case of mr at ``thickness`` (mm; 0.8: six failed steps in the shipped run): wall
    time, factorisations, failed steps, whether the tables are equal (~1 h at 0.8 mm)."""
    spec = _sweep_case("mr", thickness)
    runs = _before_and_current(spec, "FORWARD_STALL_RISES", None, lambda v: f"forward stall {v}")
    return _compare_runs(runs, ("steps", "newton_iterations", "factorizations", "failures"))


class _AttributedSolver:
    """A :func:`grasprom.fe.linsolve.make_solver` solver that logs every factorisation (each
    call; ``resolve`` reuses the factor) with its wall time and where it came from, read off
    the call stack: the phase (``forward`` step, ``crease`` placement, ``relax``) and the kind
    (``predictor``, ``newton`` direction, ``shift``: a Levenberg-shifted retry)."""

    def __init__(self, inner) -> None:
        self.inner = inner
        self.log: list[list] = []  # [phase, kind, seconds, failed]

    @property
    def factorizations(self) -> int:
        return self.inner.factorizations

    @property
    def name(self) -> str:
        from grasprom.fe.linsolve import solver_name

        return solver_name(self.inner)

    def resolve(self, rhs):
        return self.inner.resolve(rhs)

    def __call__(self, K, rhs):
        names, shift = [], 0.0
        f = sys._getframe(1)
        while f is not None:
            names.append(f.f_code.co_name)
            if f.f_code.co_name == "shifted_descent":
                shift = f.f_locals.get("shift", 0.0)
            f = f.f_back
        phase = (
            "crease" if "_crease_onset" in names else "relax" if "_relax" in names else "forward"
        )
        kind = "predictor" if "_predict" in names else "shift" if shift else "newton"
        t0 = time.perf_counter()
        try:
            return self.inner(K, rhs)
        finally:
            self.log.append([phase, kind, time.perf_counter() - t0, False])


def bench_factors(closed_gap: float = 1.5, far_coarsening: int = 1) -> dict:
    """Where the factorisations of the converged sweep's case go (4 x 36 graded 8:1, six axial
    divisions beyond the jaw, 240 mm tube, mr, t = 1.4, stick, contact predicted below 2.5 t,
    no landing gaps: the case ``grasprom sweep`` runs; ~15 min): count and seconds by phase
    (forward steps, crease placement, relaxation) and kind (predictor, Newton direction,
    Levenberg shift), those spent in solves that failed, and the assembly's share; then the
    wall time by region of the stroke (:func:`_regions`).  ``far_coarsening``: the mesh's
    (``--far-coarsening``; 1, the shipped mesh)."""
    from grasprom.fe import model3d

    spec = replace(_sweep_case("mr", T), closed_gap_mm=closed_gap)
    spec = replace(spec, mesh=replace(spec.mesh, far_coarsening=far_coarsening))
    solvers: list[_AttributedSolver] = []
    make, solve_step, assemble = model3d.make_solver, model3d._solve_step, model3d.assemble
    crease_onset = model3d._crease_onset
    assembly = {"calls": 0, "tangents": 0, "s": 0.0}
    steps: list[list] = []  # [gap (mm), wall time at its end (s), crease placement in it (s)]
    placing = [0.0]

    def placed(*args, **kw):
        t0 = time.perf_counter()
        try:
            return crease_onset(*args, **kw)
        finally:
            placing[0] += time.perf_counter() - t0

    def progress(gap, force):
        steps.append([gap, time.perf_counter(), placing[0]])
        placing[0] = 0.0

    def attributed(name: str = "auto"):
        solvers.append(_AttributedSolver(make(name)))
        return solvers[-1]

    def marked(*args, **kw):  # the factorisations of a solve that raises count as failed
        st = args[0]
        start = len(st.solver.log)
        try:
            return solve_step(*args, **kw)
        except Exception:
            for entry in st.solver.log[start:]:
                entry[3] = True
            raise

    def timed(disc, material, u, tangent=True, block=0):
        t0 = time.perf_counter()
        try:
            return assemble(disc, material, u, tangent, block)
        finally:
            assembly["calls"] += 1
            assembly["tangents"] += bool(tangent)
            assembly["s"] += time.perf_counter() - t0

    model3d.make_solver, model3d._solve_step, model3d.assemble = attributed, marked, timed
    model3d._crease_onset = placed
    try:
        t0 = time.perf_counter()
        label = "the sweep's 4 x 36 case" + (
            f", far_coarsening {far_coarsening}" if far_coarsening != 1 else ""
        )
        r = _run(spec, f"{label}, factorisations attributed", progress=progress)
        wall = time.perf_counter() - t0
    finally:
        model3d.make_solver, model3d._solve_step, model3d.assemble = make, solve_step, assemble
        model3d._crease_onset = crease_onset
    log = solvers[0].log
    out: dict = {"wall_s": wall, "newton_iterations": r.info["newton_iterations"]}
    out |= {"steps": r.info["steps"], "factorizations": len(log), "assembly": assembly}
    print(f"  {'phase':8s} {'kind':10s} {'count':>6s} {'s':>7s} {'failed':>7s} {'failed s':>9s}")
    for phase in ("forward", "crease", "relax"):
        for kind in ("predictor", "newton", "shift"):
            sel = [e for e in log if e[0] == phase and e[1] == kind]
            bad = [e for e in sel if e[3]]
            row = {"count": len(sel), "s": sum(e[2] for e in sel)}
            row |= {"failed": len(bad), "failed_s": sum(e[2] for e in bad)}
            out[f"{phase}/{kind}"] = row
            print(
                f"  {phase:8s} {kind:10s} {row['count']:6d} {row['s']:7.1f} {row['failed']:7d}"
                f" {row['failed_s']:9.1f}",
                flush=True,
            )
    fact_s = sum(e[2] for e in log)
    print(
        f"  total: {len(log)} factorisations ({fact_s:.0f} s), {assembly['calls']} assemblies "
        f"({assembly['tangents']} with the tangent, {assembly['s']:.0f} s), "
        f"{r.info['newton_iterations']} Newton iterations, {r.info['steps']} steps, "
        f"{wall:.0f} s wall",
        flush=True,
    )
    per_fact = fact_s / max(len(log), 1)
    per_asm = assembly["s"] / max(assembly["calls"], 1)
    print(
        f"  the machine today: {per_fact:.3f} s a factorisation, {per_asm:.3f} s an assembly "
        "(wall times of other days compare through these; the counts do not change)",
        flush=True,
    )
    out |= {"s_per_factorization": per_fact, "s_per_assembly": per_asm}
    out["regions"] = _regions(steps, t0, spec.thickness_mm)
    return out


def _regions(steps: list[list], t0: float, t: float) -> dict:
    """Wall time (s) and steps by region of the stroke, from ``[gap, end time, placement s]``
    per converged forward step (the placement's time is split off its step): bending (gap
    above 4 t), the crease band (2 t to 4 t), the crease placements in it, and compaction (the
    walls meet at gap 2 t; ``t`` the wall thickness, mm).  Printed as a table."""
    labels = {
        "bending": f"bending (gap > 4 t = {4 * t:g} mm)",
        "band": f"crease band ({2 * t:g}-{4 * t:g} mm)",
        "placements": "crease placements (Maxwell)",
        "compaction": f"compaction (gap <= 2 t = {2 * t:g} mm)",
    }
    out = {k: {"steps": 0, "s": 0.0} for k in labels}
    last = t0
    for gap, end, placement in steps:
        region = "bending" if gap > 4 * t else "band" if gap > 2 * t else "compaction"
        out[region]["steps"] += 1
        out[region]["s"] += end - last - placement
        if placement > 0:
            out["placements"]["steps"] += 1
            out["placements"]["s"] += placement
        last = end
    total = sum(v["s"] for v in out.values())
    print(f"  {'region':34s} {'steps':>6s} {'s':>7s} {'share':>6s}")
    for k, v in out.items():
        share = v["s"] / total if total > 0 else 0.0
        print(f"  {labels[k]:34s} {v['steps']:6d} {v['s']:7.1f} {100 * share:5.1f} %", flush=True)
    return out


#: gaps (mm) of the 3D band study: bending, the crease band 2t..4t (t = 1.4 mm) and the walls
#: meeting at 2t
BAND_GAPS = (20.0, 10.0, 6.0, 5.5, 5.0, 4.8, 4.5, 4.3, 4.0, 3.8, 3.5, 3.2, 3.0, 2.9, 2.8)
#: cross-sections of the 3D band study on the converged case, the reference first
BAND_MESHES = {
    "4 x 48": {"n_layers": 4, "n_circ": 48, "grading": 8.0},
    "4 x 36": {"n_layers": 4, "n_circ": 36, "grading": 8.0},
}


def bench_band(meshes=BAND_MESHES, gaps=BAND_GAPS) -> dict:
    """Crease band of the converged case (240 mm tube, six axial divisions beyond the jaw, mr,
    t = 1.4, stick, contact predicted below gap 3.5 mm) on 4 x 48 and 4 x 36 to gap 2.8 mm:
    force at fixed gaps, dense over the band 2t..4t (400 gaps, log-interpolated between the
    steps), strain energy, cost (~35 min)."""
    base, _ = _converged_case(2.8)
    grid = np.linspace(2 * T + 0.02, 4 * T, 400)
    out, dense = {}, {}
    for label, mk in meshes.items():
        spec = _with_gaps(replace(base, mesh=replace(base.mesh, **mk)), gaps)
        r = _run(spec, label)
        tb = r.table
        dense[label] = _dense_band(tb, grid)
        out[label] = {"force_N": _force_at(tb, gaps), "dofs": r.info["dofs"]}
        out[label] |= {k: r.info[k] for k in ("steps", "newton_iterations", "factorizations")}
        out[label] |= {"wall_s": r.info["wall_time_s"]}
        out[label]["energy_2t_mJ"] = float(tb["strain_energy_mJ"].iloc[-1])
    ref = next(iter(meshes))
    _header(gaps)
    for label, v in out.items():
        _print_row(label, v["force_N"], "{:9.3f}")
    for label, v in out.items():
        rel = {g: 100.0 * (v["force_N"][g] / out[ref]["force_N"][g] - 1.0) for g in gaps}
        _print_row(f"{label} / {ref} - 1 (%)", rel, "{:+9.2f}")
        d = dense[label] / dense[ref] - 1.0
        k = int(np.argmax(np.abs(d)))
        v["band"] = {"max": float(np.abs(d).max()), "at_gap_mm": float(grid[k])}
        v["band"] |= {
            "median": float(np.median(np.abs(d))),
            "beyond_3pct": float((abs(d) > 0.03).mean()),
        }
        e = 100.0 * (v["energy_2t_mJ"] / out[ref]["energy_2t_mJ"] - 1.0)
        print(
            f"  {label}: {v['dofs']} dofs, {v['steps']} steps, {v['newton_iterations']} Newton, "
            f"{v['factorizations']} factorisations, {v['wall_s']:.0f} s; energy at 2t "
            f"{v['energy_2t_mJ']:.3f} mJ ({e:+.2f} %); dense band vs {ref}: max "
            f"{v['band']['max']:.1%} at gap {v['band']['at_gap_mm']:.2f} mm, median "
            f"{v['band']['median']:.2%}, beyond 3 %: {v['band']['beyond_3pct']:.0%}",
            flush=True,
        )
    return out


def _band_runs(specs: dict, band) -> dict:
    """Run each of ``specs`` (label -> spec) keeping the table's state (``on_row``'s last call)
    at each of the ``band`` gaps (mm): ``{label: (spec, table, {gap: u})}``."""
    runs = {}
    for label, spec in specs.items():
        states = {}

        def keep(disc, u, gap, force, states=states):
            states[round(gap, 6)] = u.copy()

        r = run_case_3d(spec, on_row=keep)
        placed = [round(c["placed_gap_mm"], 3) for c in r.info["creases"]]
        print(f"[{label}] {r.info['newton_iterations']} Newton, {r.info['wall_time_s']:.0f} s, "
              f"creases placed at gaps {placed} mm")  # fmt: skip
        kept = {g: states[round(g, 6)] for g in band if round(g, 6) in states}
        runs[label] = (spec, r.table, kept)
    return runs


def _moved(spec_from, u, spec_to, gap: float):
    """``spec_from``'s state ``u`` moved to ``spec_to``'s mesh and solved at ``gap`` (mm):
    ``(force N, strain energy mJ, Newton iterations)``, NaN where that fails."""
    from grasprom.fe.model3d import equilibrium_from
    from grasprom.fe.transfer3d import transfer_displacement

    try:
        eq = equilibrium_from(spec_to, transfer_displacement(spec_from, u, spec_to), gap)
    except RuntimeError as exc:
        print(f"  gap {gap}: {exc}", flush=True)
        return np.nan, np.nan, 0
    return eq.force_N, eq.strain_energy_mJ, eq.newton_iterations


def _lower_on(own: tuple, moved: tuple) -> tuple:
    """The lower-energy of a mesh's own ``(force, energy)`` and a moved state's."""
    return moved[:2] if moved[1] < own[1] else own


#: the table columns of a state's force (N) and strain energy (mJ)
_FE = ("force_N", "strain_energy_mJ")


def _swap_band(runs: dict, band) -> dict:
    """Each band state of the two ``runs`` (:func:`_band_runs`, the reference first) moved to
    the other mesh and solved there; per gap the own and moved ``(force N, energy mJ[, Newton
    iterations])`` and, in %, the other run's force against the reference's: own and on each
    mesh's lower-energy state."""
    (la, (sa, ta, ua)), (lb, (sb, tb, ub)) = runs.items()
    out = {}
    print(f"  gap | {la}: own F, E | {lb}: own F, E | {lb}'s on {la}: F, E (its) | {la}'s on "
          f"{lb}: F, E (its) | own apart | lower-energy apart")  # fmt: skip
    for g in band:
        if g not in ua or g not in ub:
            continue
        own_a, own_b = (tuple(_force_at(t, (g,), c)[g] for c in _FE) for t in (ta, tb))
        b_on_a, a_on_b = _moved(sb, ub[g], sa, g), _moved(sa, ua[g], sb, g)
        low_a, low_b = _lower_on(own_a, b_on_a), _lower_on(own_b, a_on_b)
        own_rel = 100.0 * (own_b[0] / own_a[0] - 1.0)
        low_rel = 100.0 * (low_b[0] / low_a[0] - 1.0)
        out[g] = {"own": (own_a, own_b), "moved": (b_on_a, a_on_b)}
        out[g] |= {"own_apart_pct": own_rel, "lower_apart_pct": low_rel}
        print(
            f"  {g:4.2f} | {own_a[0]:.4f} {own_a[1]:.4f} | {own_b[0]:.4f} {own_b[1]:.4f} | "
            f"{b_on_a[0]:.4f} {b_on_a[1]:.4f} ({b_on_a[2]}) | {a_on_b[0]:.4f} {a_on_b[1]:.4f} "
            f"({a_on_b[2]}) | {own_rel:+.2f} % | {low_rel:+.2f} %",
            flush=True,
        )
    return out


def bench_commonbranch(meshes=BAND_MESHES, gaps=BAND_GAPS) -> dict:
    """Crease band of the converged case on 4 x 48 and 4 x 36 (as ``band``), each band state
    moved to the other mesh and solved there (``grasprom.fe.transfer3d``,
    ``model3d.equilibrium_from``): the force on a common start (discretisation error), which
    state holds less energy on each mesh, and the two meshes' forces on the lower one
    (~1.5 h)."""
    base, _ = _converged_case(2.8)
    band = [g for g in gaps if 2 * T - 1e-9 <= g <= 4 * T + 1e-9]
    specs = {
        label: _with_gaps(replace(base, mesh=replace(base.mesh, **mk)), gaps)
        for label, mk in meshes.items()
    }
    return _swap_band(_band_runs(specs, band), band)


def bench_crossmesh(material: str = "le", thickness: float = 1.0) -> dict:
    """A sweep case on the default mesh and the zoned one (the same jaw zone, the far zone
    halved), both landing on the band gaps 4t, 3.8t, ..., 2t and stopping below 2t; each band
    state moved to the other mesh and solved there: the force on a common start (the far
    zone's discretisation), which state holds less energy on each mesh, and the two meshes'
    forces on their lower-energy states (~25 min for le 1.0 mm)."""
    band = [round(thickness * k / 10, 6) for k in range(40, 19, -2)]
    specs = {}
    for mesh in ("default", "zoned"):
        spec = _sweep_case(material, thickness, None if mesh == "default" else "zoned")
        solver = replace(spec.solver, land_on_gaps_mm=band)
        specs[mesh] = replace(spec, closed_gap_mm=2 * thickness - 0.05, solver=solver)
    return _swap_band(_band_runs(specs, band), band)


def _own_forces(table, selection: dict):
    """The run's own forces (N): ``table`` with each row that the companion's state replaced
    given back its own force (``fe_info.band_selection``'s choices)."""
    own = table.copy()
    for c in selection["choices"]:
        if c["taken"]:
            at = np.isclose(own["gap_mm"], c["gap_mm"], rtol=0.0, atol=1e-9)
            own.loc[at, "force_N"] = c["own_force_N"]
    return own


def _print_choices(selection: dict) -> None:
    """One line per band gap of ``fe_info.band_selection``: own, companion and moved state."""
    print("  gap | own F, E | companion F | moved F, E (Newton) | taken", flush=True)
    for c in selection["choices"]:
        mf, me = (np.nan if c[k] is None else c[k] for k in ("moved_force_N", "moved_energy_mJ"))
        print(f"  {c['gap_mm']:.4f} | {c['own_force_N']:.4f} {c['own_energy_mJ']:.4f} | "
              f"{c['companion_force_N']:.4f} | {mf:.4f} {me:.4f} ({c['newton_iterations']}) | "
              f"{c['taken']} {c['error']}", flush=True)  # fmt: skip


def bench_bandselect(
    material: str = "le", thickness: float = 1.0, n_circ: tuple[int, int] = (36, 48)
) -> dict:
    """The sweep's case with a companion run (``--band-companion 2``) on the default mesh (4 x
    36) and on its refinement (4 x 48; ``n_circ``), both to just below the crease band: per
    run the companion's choices, then the two meshes apart over the band (2t..4t, dense: 400
    gaps, log-interpolated between rows) with their own rows and with the selected ones
    (~1.5 h for le 1.0 mm alone)."""
    from grasprom.fe.bandselect import run_case_3d_selected

    t = thickness
    grid = np.linspace(2 * t, 4 * t, 400)
    out: dict = {}
    for nc in n_circ:
        spec = _sweep_case(material, t)
        solver = replace(spec.solver, band_companion=2)
        spec = replace(spec, mesh=replace(spec.mesh, n_circ=nc), solver=solver)
        r = run_case_3d_selected(replace(spec, closed_gap_mm=2 * t - 0.05))
        sel, info = r.info["band_selection"], r.info
        label = f"{spec.mesh.n_layers} x {nc}"
        placed = [round(c["placed_gap_mm"], 3) for c in info["creases"]]
        print(f"[{label}] own run {info['own_wall_time_s']:.0f} s, creases at {placed} mm; "
              f"companion and moves {sel['wall_time_s']:.0f} s, creases at "
              f"{sel['crease_gaps_mm']} mm", flush=True)  # fmt: skip
        _print_choices(sel)
        own = _own_forces(r.table, sel)
        out[label] = {"own": _dense_band(own, grid), "selected": _dense_band(r.table, grid)}
        out[label] |= {"selection": sel, "own_wall_s": info["own_wall_time_s"]}
    ref, other = (out[k] for k in list(out)[:2])
    for kind in ("own", "selected"):
        d = np.abs(other[kind] / ref[kind] - 1.0)
        k = int(np.argmax(d))
        stats = {"max": float(d.max()), "at_gap_mm": float(grid[k])}
        stats |= {"median": float(np.median(d)), "mean": float(d.mean())}
        stats["beyond_3pct"] = float((d > 0.03).mean())
        out[kind + "_apart"] = stats
        print(f"  {list(out)[1]} vs {list(out)[0]}, {kind} rows: max {stats['max']:.1%} at gap "
              f"{stats['at_gap_mm']:.2f} mm, median {stats['median']:.2%}, mean "
              f"{stats['mean']:.2%}, beyond 3 %: {stats['beyond_3pct']:.0%}",
              flush=True)  # fmt: skip
    for v in (ref, other):
        v["own"], v["selected"] = v["own"].tolist(), v["selected"].tolist()
    return out


#: gaps (mm) of the moves benchmark: bending, where the two meshes' runs are one branch
MOVE_GAPS = (26.0, 24.0, 22.0, 20.0, 18.0, 16.0)


def bench_moves(closed_gap: float = 16.0) -> dict:
    """The band selection's moves on the sweep's mesh (4 x 36, 240 mm; mr 1.4): the zoned
    companion's states at ``MOVE_GAPS`` moved to it and solved at their gaps, with one
    ``EquilibriumSolver`` kept over the moves against ``equilibrium_from``'s fresh set-up each
    (the baseline: the selection before), after one untimed warm-up solve (~5 min)."""
    from grasprom.fe.model3d import EquilibriumSolver, equilibrium_from
    from grasprom.fe.transfer3d import transfer_matrix

    spec = _sweep_case("mr", 1.4)
    comp = _sweep_case("mr", 1.4, mesh="zoned")
    comp = replace(comp, closed_gap_mm=closed_gap, solver=replace(comp.solver,
                   land_on_gaps_mm=MOVE_GAPS))  # fmt: skip
    states: dict = {}

    def keep(disc, u, gap, force):
        if any(abs(gap - g) < 1e-9 for g in MOVE_GAPS):
            states[round(gap, 6)] = u.copy()

    t0 = time.perf_counter()
    run_case_3d(comp, on_row=keep)
    P = transfer_matrix(comp, spec)
    moves = [(np.asarray(P @ states[g].reshape(-1, 3)).ravel(), g) for g in MOVE_GAPS]
    print(f"  zoned companion to {closed_gap} mm: {time.perf_counter() - t0:.0f} s", flush=True)
    equilibrium_from(spec, *moves[0])  # warm-up: caches, the PARDISO library
    out: dict = {"moves": len(moves)}
    t0 = time.perf_counter()
    fresh = [equilibrium_from(spec, u, g) for u, g in moves]
    out["fresh_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    kept = EquilibriumSolver(spec)
    reused = [kept.solve(u, g) for u, g in moves]
    out["kept_s"] = time.perf_counter() - t0
    out["newton"] = [e.newton_iterations for e in reused]
    out["bitwise_equal"] = all(np.array_equal(a.u, b.u) for a, b in zip(reused, fresh))
    print(f"  {len(moves)} moves, Newton {out['newton']}: fresh set-up each (baseline) "
          f"{out['fresh_s']:.1f} s, one kept solver {out['kept_s']:.1f} s -> "
          f"{out['fresh_s'] / out['kept_s']:.2f}x; states equal to the bit: "
          f"{out['bitwise_equal']}", flush=True)  # fmt: skip
    return out


#: gaps of the zoned mesh's comparison: bending, the crease band, the walls meeting, compaction
ZONE_GAPS = (25.0, 20.0, 15.0, 10.0, 8.0, 6.0, 5.0, 4.5, 4.0, 3.5, 3.0, 2.9, 2.8, 2.7, 2.6, 2.5)


def _unit_costs(spec: CaseSpec3D, repeat: int = 3) -> tuple[int, float, float]:
    """DOFs, seconds per factorisation (the ``"auto"`` solver: PARDISO if installed) and per
    tangent assembly of the undeformed tube's tangent (this machine, now; the mean of
    ``repeat`` after a warm-up)."""
    from grasprom.fe.linsolve import make_solver
    from grasprom.fe.model3d import assemble, build_disc

    disc = build_disc(spec)
    mat = spec.make_material()
    u = np.zeros(disc.ndof)
    assemble(disc, mat, u)
    t0 = time.perf_counter()
    for _ in range(repeat):
        K = assemble(disc, mat, u)[1]
    t_asm = (time.perf_counter() - t0) / repeat
    K = K + 1e-3 * abs(K.diagonal()).mean() * sp.identity(disc.ndof, format="csr")
    rhs = np.ones(disc.ndof)
    solve = make_solver("auto")
    solve(K, rhs)  # the analysis, once
    t0 = time.perf_counter()
    for _ in range(repeat):
        solve(K, rhs)
    return disc.ndof, (time.perf_counter() - t0) / repeat, t_asm


def bench_transition(closed_gap: float = 1.5) -> dict:
    """The sweep's case (mr, t = 1.4, 4 x 36 graded 8:1, 240 mm tube, stick) on one cross-section
    along the tube (the shipped mesh) and with the cross-section halved beyond the jaw zone
    (``MeshSpec3D.far_coarsening`` = 2: 2 x 18 beyond z = 7 mm): DOFs, the cost of a
    factorisation and of an assembly, wall time, counts; the force at fixed gaps (interpolated
    on each run's own path, no landing gaps: the sweep's path) and the gap at equal force
    (~25 min, the two runs one after the other)."""
    base = replace(_sweep_case("mr", T), closed_gap_mm=closed_gap)
    specs = {"one cross-section": base}
    specs["far_coarsening 2"] = replace(base, mesh=replace(base.mesh, far_coarsening=2))
    out = {}
    for label, spec in specs.items():
        ndof, t_fac, t_asm = _unit_costs(spec)
        t0 = time.perf_counter()
        r = _run(spec, label)
        wall = time.perf_counter() - t0
        i = r.info
        tab = r.table.sort_values("gap_mm")
        g, f = tab["gap_mm"].to_numpy(), tab["force_N"].to_numpy()
        rise = _gap_at_force(r.table) if f.max() >= RISE_FORCES[0] else {}
        out[label] = {
            "dofs": ndof,
            "factorisation_s": t_fac,
            "assembly_s": t_asm,
            "wall_s": wall,
            "steps": i["steps"],
            "newton": i["newton_iterations"],
            "factorisations": i["factorizations"],
            "force_N": {gg: float(np.interp(gg, g, f, np.nan, np.nan)) for gg in ZONE_GAPS},
            "gap_at_force_mm": {ff: rise[ff] if f.max() >= ff else None for ff in RISE_FORCES},
        }
    a, b = out["one cross-section"], out["far_coarsening 2"]
    print(f"  {'':<22}{'one cross-section':>20}{'far_coarsening 2':>20}{'ratio':>9}")
    for key, fmt in (("dofs", "{:20d}"), ("factorisation_s", "{:20.3f}"),
                     ("assembly_s", "{:20.3f}"), ("wall_s", "{:20.1f}"),
                     ("steps", "{:20d}"), ("newton", "{:20d}"),
                     ("factorisations", "{:20d}")):  # fmt: skip
        print(f"  {key:<22}" + fmt.format(a[key]) + fmt.format(b[key]) + f"{b[key] / a[key]:9.2f}")
    print(f"  {'s per factorisation':<22}{a['wall_s'] / a['factorisations']:20.3f}"
          f"{b['wall_s'] / b['factorisations']:20.3f}")  # fmt: skip
    _header(ZONE_GAPS)
    _print_row("one cross-section (N)", a["force_N"])
    rel = {gg: 100.0 * (b["force_N"][gg] / a["force_N"][gg] - 1.0) for gg in ZONE_GAPS}
    _print_row("far_coarsening 2 (%)", rel, "{:9.2f}")
    for ff in RISE_FORCES:
        ga, gb = a["gap_at_force_mm"][ff], b["gap_at_force_mm"][ff]
        if ga is not None and gb is not None:
            print(f"  gap at {ff:5.0f} N: {ga:.4f} / {gb:.4f} mm, {1000 * (gb - ga):+.1f} um")
    return out


SECTIONS = {
    "shell": bench_shell,
    "default": bench_default,
    "solver": bench_solver,
    "cases": bench_cases,
    "contact": bench_contact,
    "laws": bench_laws,
    "crease": bench_crease,
    "length": bench_length,
    "free": bench_free,
    "mesh": bench_mesh,
    "meshband": bench_meshband,
    "planestrain": bench_planestrain,
    "element": bench_element,
    "assembly": bench_assembly,
    "meshtube": bench_meshtube,
    "layers": bench_layers,
    "ccx": bench_ccx,
    "wallsmeet": bench_wallsmeet,
    "activeset": bench_activeset,
    "reuse": bench_reuse,
    "band": bench_band,
    "commonbranch": bench_commonbranch,
    "crossmesh": bench_crossmesh,
    "bandselect": bench_bandselect,
    "moves": bench_moves,
    "stall": bench_stall,
    "forwardstall": bench_forward_stall,
    "factorreuse": bench_factor_reuse,
    "factors": bench_factors,
    "transition": bench_transition,
}


def main(argv: list[str]) -> None:
    import argparse

    ap = argparse.ArgumentParser(
        description="Benchmarks of the 3D clamping model; prints figures, asserts nothing.",
        epilog="sections: " + ", ".join(SECTIONS),
    )
    ap.add_argument("sections", nargs="*", help="sections to run (default: all)")
    ap.add_argument(
        "--materials",
        default=None,
        help="'cases' section: materials (default mr,le); 'factorreuse' (default nh there) and "
        "'crossmesh' and 'bandselect' (default le): the first of them",
    )
    ap.add_argument(
        "--thickness",
        default=None,
        help="'cases' section: wall thicknesses in mm (default 0.8,1.4,2.0); 'forwardstall' and "
        "'factorreuse' (default 2.0 there), 'crossmesh' and 'bandselect' (default 1.0): the "
        "first of them",
    )
    ap.add_argument(
        "--closed-gap",
        type=float,
        default=None,
        help="'activeset', 'reuse', 'factors' and 'transition' sections: end of the stroke in "
        "mm (default 1.5, to the force cap; 12, the bending part, for 'reuse')",
    )
    ap.add_argument(
        "--far-coarsening",
        type=int,
        default=1,
        help="'factors' section: MeshSpec3D.far_coarsening of the case (default 1, the shipped "
        "mesh; 2 halves the cross-section beyond the jaw zone)",
    )
    ap.add_argument("--json", help="write the figures as JSON here")
    args = ap.parse_args(argv)
    unknown = [n for n in args.sections if n not in SECTIONS]
    if unknown:
        ap.error(f"unknown section(s) {', '.join(unknown)}; valid: {', '.join(SECTIONS)}")
    results = {}
    for name in args.sections or list(SECTIONS):
        print(f"== {name}: {SECTIONS[name].__doc__.splitlines()[0]}", flush=True)
        if name == "cases":
            mats = tuple((args.materials or "mr,le").split(","))
            ts = tuple(float(x) for x in (args.thickness or "0.8,1.4,2.0").split(","))
            results[name] = bench_cases(ts, mats)
        elif name == "activeset":
            results[name] = bench_activeset(args.closed_gap or 1.5)
        elif name == "reuse":
            results[name] = bench_reuse(args.closed_gap or 12.0)
        elif name == "factors":
            results[name] = bench_factors(args.closed_gap or 1.5, args.far_coarsening)
        elif name == "transition":
            results[name] = bench_transition(args.closed_gap or 1.5)
        elif name == "forwardstall":
            results[name] = bench_forward_stall(float((args.thickness or "0.8").split(",")[0]))
        elif name == "crossmesh":
            mat = (args.materials or "le").split(",")[0]
            results[name] = bench_crossmesh(mat, float((args.thickness or "1.0").split(",")[0]))
        elif name == "bandselect":
            mat = (args.materials or "le").split(",")[0]
            results[name] = bench_bandselect(mat, float((args.thickness or "1.0").split(",")[0]))
        elif name == "factorreuse":
            mat = (args.materials or "nh").split(",")[0]
            t = float((args.thickness or "2.0").split(",")[0])
            results[name] = bench_factor_reuse(mat, t)
        else:
            results[name] = SECTIONS[name]()
    text = json.dumps(results, default=str)
    if args.json:
        with open(args.json, "w") as fh:
            fh.write(text)
    print(text[:2000])


if __name__ == "__main__":
    main(sys.argv[1:])
