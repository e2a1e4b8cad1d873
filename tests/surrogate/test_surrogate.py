"""Tests of the tabulated force surrogate (grasprom.surrogate)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from grasprom.cli import main
from grasprom.fe import datafiles
from grasprom.surrogate import (
    SCHEMES,
    BuildParams,
    Surrogate,
    SurrogateFileError,
    clamp_thickness,
    error_figures,
    fe_dir_hash,
    read_fe_cases,
)

ROOT = Path(__file__).resolve().parents[2]
DEFAULT = ROOT / "fe_data" / "2d"
HOLDOUT = ROOT / "fe_data" / "2d_holdout"
MATERIALS = ("mr", "nh", "le")

# targets of issue 3 (held-out FE, haptic range)
TARGET_FORCE_RMS_PCT = 1.0
TARGET_FORCE_MAX_PCT = 3.0
TARGET_GAP_MM = 0.02


@pytest.fixture(scope="module")
def cases():
    return read_fe_cases(DEFAULT)[0]


@pytest.fixture(scope="module")
def sur(cases) -> Surrogate:
    return Surrogate.from_cases(cases, BuildParams(tol=0.005), source=str(DEFAULT))


@pytest.fixture(scope="module")
def holdout_figures(sur):
    hold = read_fe_cases(HOLDOUT)[0]
    return {sc: error_figures(sur.with_scheme(sc), hold) for sc in SCHEMES}


# --------------------------------------------------------------------------- accuracy


def test_public_import():
    from grasprom import Surrogate as S

    assert S is Surrogate


def test_holdout_accuracy_meets_targets(holdout_figures):
    fig = holdout_figures["aligned"]
    for mat in (*MATERIALS, "all"):
        r = fig["haptic"][mat]
        assert r["n_force"] > 100 and r["n_gap"] > 10
        assert r["force_rms_pct"] <= TARGET_FORCE_RMS_PCT, (mat, r)
        assert r["force_max_pct"] <= TARGET_FORCE_MAX_PCT, (mat, r)
        assert r["gap_max_mm"] <= TARGET_GAP_MM, (mat, r)
        full = fig["full"][mat]
        assert full["force_max_pct"] <= TARGET_FORCE_MAX_PCT, (mat, full)
        assert full["gap_max_mm"] <= TARGET_GAP_MM, (mat, full)


def test_holdout_accuracy_on_the_shipped_3d_sweep():
    """The surrogate built on the default 3D sweep (fe_data/default: the converged cross-section,
    0.2 mm thickness spacing) against its held-out FE cases at t = 1.5 mm (fe_data/holdout,
    independent FE runs): within the targets in every material (figures in
    docs/surrogate.md); the naive scheme misses them (mr max 118 %, gap 0.17 mm)."""
    sur = Surrogate.build(ROOT / "fe_data" / "default", params=BuildParams(tol=0.005))
    hold = read_fe_cases(ROOT / "fe_data" / "holdout")[0]
    assert {c.material for c in hold} == set(MATERIALS)
    fig = {sc: error_figures(sur.with_scheme(sc), hold) for sc in SCHEMES}
    for mat in (*MATERIALS, "all"):
        r = fig["aligned"]["haptic"][mat]
        assert r["n_force"] > 40
        assert r["force_rms_pct"] <= TARGET_FORCE_RMS_PCT, (mat, r)
        assert r["force_max_pct"] <= TARGET_FORCE_MAX_PCT, (mat, r)
    assert fig["aligned"]["haptic"]["mr"]["gap_max_mm"] <= TARGET_GAP_MM
    naive = fig["naive"]["haptic"]["mr"]
    assert naive["force_max_pct"] > TARGET_FORCE_MAX_PCT and naive["gap_max_mm"] > TARGET_GAP_MM


def test_aligned_beats_naive(holdout_figures):
    al, nv = holdout_figures["aligned"], holdout_figures["naive"]
    for mat in (*MATERIALS, "all"):
        a, n = al["haptic"][mat], nv["haptic"][mat]
        assert a["force_rms_pct"] < 0.2 * n["force_rms_pct"]
        assert a["gap_max_mm"] < 0.5 * n["gap_max_mm"]
    # the naive scheme misses the targets: the wall-contact staircase
    assert nv["haptic"]["all"]["gap_max_mm"] > TARGET_GAP_MM


def test_leave_one_out_reported(sur, cases):
    from grasprom.surrogate import leave_one_out

    loo = leave_one_out(sur, [c for c in cases if c.material == "mr"])["schemes"]
    a, n = loo["aligned"]["haptic"]["mr"], loo["naive"]["haptic"]["mr"]
    assert a["force_rms_pct"] < n["force_rms_pct"] and a["gap_max_mm"] < n["gap_max_mm"]
    assert a["force_max_pct"] < TARGET_FORCE_MAX_PCT  # measured 0.37 %, gap max 0.023 mm


def test_node_tolerance_and_counts(cases):
    small = Surrogate.from_cases(cases, BuildParams(tol=0.02))
    fine = Surrogate.from_cases(cases, BuildParams(tol=0.005))
    assert small.node_count() < fine.node_count() < sum(len(c.gap_mm) for c in cases)
    for m in MATERIALS:
        assert fine.errors["fit"][m]["max_fit_error"] <= 0.005
        for c in fine.curves(m):
            assert c.gap_mm[-1] == 30.0 and c.force_N[-1] == 0.0


# --------------------------------------------------------------------------- properties

_mat = st.sampled_from(MATERIALS)
_scheme = st.sampled_from(SCHEMES)
_t = st.floats(0.8, 2.0)
_g = st.floats(0.5, 29.999999)


@settings(max_examples=150, deadline=None)
@given(m=_mat, sc=_scheme, t=_t, g1=_g, g2=_g)
def test_monotone_nonnegative(sur, m, sc, t, g1, g2):
    s = sur.with_scheme(sc) if sc != sur.scheme else sur
    lo, hi = min(g1, g2), max(g1, g2)
    f_lo, f_hi = s.force_scalar(lo, t, m), s.force_scalar(hi, t, m)
    assert f_lo >= f_hi >= 0.0
    assert s.stiffness_scalar(lo, t, m) >= 0.0


@settings(max_examples=150, deadline=None)
@given(m=_mat, t=_t, g=_g)
def test_stiffness_continuous(sur, m, t, g):
    d = 1e-9
    k0 = sur.stiffness_scalar(g, t, m)
    k1 = sur.stiffness_scalar(g + d, t, m)
    assert abs(k1 - k0) <= 1e-3 * (1.0 + abs(k0))
    f0, f1 = sur.force_scalar(g, t, m), sur.force_scalar(g + d, t, m)
    assert abs(f0 - f1) <= (abs(k0) + 1.0) * 2 * d + 1e-12


def test_stiffness_continuous_at_every_node(sur):
    for m in MATERIALS:
        for c in sur.curves(m):
            for x in c.gap_mm[1:-1]:
                kl = sur.stiffness_scalar(x - 1e-10, c.thickness_mm, m)
                kr = sur.stiffness_scalar(x, c.thickness_mm, m)
                assert abs(kl - kr) <= 1e-3 * (1.0 + abs(kr))


def test_reproduces_every_node_exactly(sur, cases):
    for c in cases:
        curve = next(k for k in sur.curves(c.material) if k.thickness_mm == c.thickness_mm)
        x = np.array(curve.gap_mm)
        f = sur.force(x, c.thickness_mm, c.material)
        assert np.array_equal(f, np.array(curve.force_N))
        # nodes are FE points: the FE values themselves
        fe = dict(zip(c.gap_mm.tolist(), c.force_N.tolist()))
        assert all(fe[g] == y for g, y in zip(curve.gap_mm, curve.force_N))
        for g, y in zip(curve.gap_mm, curve.force_N):
            assert sur.force_scalar(g, c.thickness_mm, c.material) == y


@settings(max_examples=60, deadline=None)
@given(m=_mat, sc=_scheme, seed=st.integers(0, 2**31 - 1))
def test_scalar_equals_vectorised(sur, m, sc, seed):
    s = sur.with_scheme(sc)
    rng = np.random.default_rng(seed)
    g = rng.uniform(0.0, 32.0, 64)
    t = rng.uniform(0.8, 2.0, 64)
    t[:8] = s.thicknesses(m)[:8]  # grid thicknesses too
    f, flag = s.force(g, t, m, return_flag=True)
    k = s.stiffness(g, t, m)
    for i in range(g.size):
        fs, ks, fl = s.evaluate_scalar(g[i], t[i], m)
        assert fs == pytest.approx(f[i], rel=1e-12, abs=1e-12)
        assert ks == pytest.approx(k[i], rel=1e-12, abs=1e-12)
        assert fl == flag[i]


def test_broadcasting(sur):
    g = np.linspace(1.5, 31, 7)[:, None]
    t = np.array([0.8, 1.25, 2.0])[None, :]
    f = sur.force(g, t, "mr")
    assert f.shape == (7, 3)
    assert np.allclose(f[:, 1], sur.force(g[:, 0], 1.25, "mr"))
    assert sur.force(10.0, 1.0, "mr").shape == ()


# --------------------------------------------------------------------------- out of range


def test_out_of_range_behaviour(sur):
    for m in MATERIALS:
        assert np.all(sur.force([30.0, 30.5, 100.0], 1.3, m) == 0.0)
        assert np.all(sur.stiffness([30.0, 31.0], 1.3, m) == 0.0)
        c = sur.curves(m)[0]  # t = 0.8
        x0, y0 = c.gap_mm[0], c.force_N[0]
        k0 = -c.dforce_dgap_N_per_mm[0]
        f, flag = sur.force([x0, x0 - 0.1, x0 - 0.5], c.thickness_mm, m, return_flag=True)
        assert list(flag) == [False, True, True]
        assert f[1] == pytest.approx(y0 + 0.1 * k0) and f[2] == pytest.approx(y0 + 0.5 * k0)
        assert np.all(np.diff(f) > 0)
        assert sur.stiffness(x0 - 0.3, c.thickness_mm, m) == pytest.approx(k0)
        assert not sur.in_range(x0 - 0.3, c.thickness_mm, m)
        assert sur.evaluate_scalar(x0 - 0.3, c.thickness_mm, m)[2] is True
        with pytest.raises(ValueError, match="thickness_mm"):
            sur.force(10.0, 0.7, m)
        with pytest.raises(ValueError, match="thickness_mm"):
            sur.force_scalar(10.0, 2.1, m)
    assert clamp_thickness(sur, 0.5, "mr") == (0.8, True)
    assert clamp_thickness(sur, 2.5, "le") == (2.0, True)
    assert clamp_thickness(sur, 1.3, "nh") == (1.3, False)
    with pytest.raises(ValueError, match="finite"):
        sur.force(np.nan, 1.0, "mr")


def test_unknown_material(sur):
    with pytest.raises(ValueError, match="unknown material 'xx'"):
        sur.force(10.0, 1.0, "xx")
    with pytest.raises(ValueError, match="unknown material"):
        sur.force_scalar(10.0, 1.0, "steel")


# --------------------------------------------------------------------------- files


def test_save_load_round_trip(sur, tmp_path):
    p = sur.save(tmp_path / "s.json")
    s2 = Surrogate.load(p, fe_dir=DEFAULT)
    g = np.linspace(0.5, 31, 501)
    for m in MATERIALS:
        for t in (0.8, 0.93, 1.5, 2.0):
            assert np.array_equal(s2.force(g, t, m), sur.force(g, t, m))
            assert np.array_equal(s2.stiffness(g, t, m), sur.stiffness(g, t, m))
    d = json.loads(p.read_text())
    assert d["format_version"] == 1 and d["fe_hash"] == fe_dir_hash(DEFAULT)
    assert d["scheme"]["thickness"] == "aligned" and "fit" in d["errors"]


def test_bad_surrogate_files(sur, tmp_path):
    p = sur.save(tmp_path / "s.json")
    d = json.loads(p.read_text())
    bad = tmp_path / "old.json"
    bad.write_text(json.dumps({**d, "format_version": 99}))
    with pytest.raises(SurrogateFileError, match=r"old\.json.*format_version 99"):
        Surrogate.load(bad)
    miss = tmp_path / "miss.json"
    miss.write_text(json.dumps({k: v for k, v in d.items() if k != "fe_hash"}))
    with pytest.raises(SurrogateFileError, match=r"miss\.json.*missing keys \['fe_hash'\]"):
        Surrogate.load(miss)
    junk = tmp_path / "junk.json"
    junk.write_text("{not json")
    with pytest.raises(SurrogateFileError, match="junk.json"):
        Surrogate.load(junk)
    with pytest.raises(SurrogateFileError, match="not found"):
        Surrogate.load(tmp_path / "nope.json")


def _copy_cases(dst: Path, stems) -> Path:
    dst.mkdir()
    for stem in stems:
        for suf in (".csv", ".json"):
            shutil.copy(DEFAULT / f"{stem}{suf}", dst / f"{stem}{suf}")
    return dst


def test_partial_case_warned_and_hash_mismatch(tmp_path):
    d = _copy_cases(tmp_path / "fe", ["mr_t0.80", "mr_t0.90", "mr_t1.00"])
    j = d / "mr_t0.90.json"
    meta = json.loads(j.read_text())
    meta["status"] = "partial"
    j.write_text(json.dumps(meta))
    with pytest.warns(UserWarning, match="mr_t0.90"):
        s = Surrogate.build(d)
    assert s.thicknesses("mr") == (0.8, 1.0)
    p = s.save(tmp_path / "s.json")
    Surrogate.load(p, fe_dir=d)
    with pytest.raises(SurrogateFileError, match=r"s\.json.*hash mismatch"):
        Surrogate.load(p, fe_dir=DEFAULT)


def test_nan_in_csv_names_file(tmp_path):
    d = _copy_cases(tmp_path / "fe", ["le_t1.00", "le_t1.10"])
    csv = d / "le_t1.10.csv"
    lines = csv.read_text().splitlines()
    cells = lines[5].split(",")
    cells[2] = "nan"
    lines[5] = ",".join(cells)
    data = ("\n".join(lines) + "\n").encode()
    csv.write_bytes(data)
    j = d / "le_t1.10.json"
    meta = json.loads(j.read_text())
    meta["csv_sha256"] = datafiles.sha256_bytes(data)
    j.write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"le_t1\.10\.csv.*NaN"):
        Surrogate.build(d)


# --------------------------------------------------------------------------- CLI


def test_cli_build_check_plot(tmp_path, capsys):
    d = _copy_cases(tmp_path / "fe", ["nh_t1.40", "nh_t1.50", "nh_t1.60"])
    out = tmp_path / "s.json"
    assert main(["surrogate", "build", "--fe", str(d), "--out", str(out), "--tol", "0.01"]) == 0
    assert "leave-one-thickness-out" in capsys.readouterr().out
    assert main(["surrogate", "check", str(out), "--fe", str(HOLDOUT)]) == 0
    text = capsys.readouterr().out
    assert "aligned" in text and "naive" in text and "F rms %" in text
    png = tmp_path / "p.png"
    assert main(["surrogate", "plot", str(out), "--fe", str(HOLDOUT), "--out", str(png)]) == 0
    assert png.stat().st_size > 10_000
    bad = tmp_path / "bad.json"
    bad.write_text("[]")
    assert main(["surrogate", "check", str(bad), "--fe", str(HOLDOUT)]) == 2
    assert "bad.json" in capsys.readouterr().err


# --------------------------------------------------------------------------- residual plot


def test_residual_plot_is_surrogate_minus_fe(sur, tmp_path):
    """Issue 16 item 6: the residual figure plots surrogate - FE at the FE points of the
    held-out cases; recomputed here from the raw CSVs (gap_mm, force_N columns) and the
    surrogate's force, independently of read_fe_cases and surrogate_residuals."""
    import re

    from grasprom.surrogate import plot_residuals, read_fe_cases, surrogate_residuals
    from grasprom.surrogate.plots import residual_figure

    png = plot_residuals(sur, tmp_path / "figs" / "res.png", HOLDOUT)
    assert png.stat().st_size > 10_000
    fig = residual_figure(sur, surrogate_residuals(sur, read_fe_cases(HOLDOUT)[0]), "t")
    lines = {ln.get_gid(): ln for ax in fig.axes for ln in ax.get_lines() if ln.get_gid()}
    csvs = sorted(HOLDOUT.glob("*.csv"))
    assert len(csvs) >= 3
    for csv in csvs:
        m = re.fullmatch(r"(mr|nh|le)_t(\d+\.\d+)", csv.stem)
        assert m, csv.name
        mat, t = m.group(1), float(m.group(2))
        tab = np.genfromtxt(csv, delimiter=",", names=True)
        g, f = tab["gap_mm"], tab["force_N"]
        want = np.array([sur.force_scalar(x, t, mat) for x in g]) - f
        line = lines[f"{csv.stem} N"]
        np.testing.assert_allclose(line.get_xdata(), g, rtol=0, atol=0)
        np.testing.assert_allclose(line.get_ydata(), want, rtol=1e-9, atol=1e-9)
        # the % panel: the same residual over the 20 N haptic scale, at non-steep points
        pct = lines[f"{csv.stem} %"]
        on = np.isin(g, pct.get_xdata())
        np.testing.assert_allclose(pct.get_ydata(), 100.0 * want[on] / 20.0, atol=1e-7)
        assert 0 < on.sum() < g.size  # the haptic range, not the whole stroke
