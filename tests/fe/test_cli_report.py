"""The ``grasprom`` command line (sweep exit codes, report) and the sweep report."""

from __future__ import annotations

import subprocess

import pandas as pd
import pytest

from grasprom.cli import main
from grasprom.fe import datafiles as df
from grasprom.fe.grid import build_grid
from grasprom.fe.report import force_at_gap, make_report, sweep_table
from grasprom.fe.sweep import run_sweep
from tests import fake_runner as fr


def _cli(python, env, *args, timeout=60):
    return subprocess.run(
        [python, "-m", "grasprom", *args], env=env, capture_output=True, text=True, timeout=timeout
    )


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--thickness", "0", "--material", "mr"], "--thickness"),
        (["--thickness", "16", "--material", "mr"], "outer radius 15"),
        (["--thickness", "1.0", "--material", "mr,steel"], "'steel'"),
        (["--thickness", "2.0:0.8:0.1", "--material", "mr"], "empty grid"),
    ],
)
def test_cli_bad_input_exit_2_subprocess(tmp_path, python, subprocess_env, args, needle):
    out = tmp_path / "out"
    p = _cli(python, subprocess_env, "sweep", *args, "--out", str(out), "--quiet")
    assert p.returncode == 2, p.stderr
    assert needle in p.stderr and "Traceback" not in p.stderr
    assert p.stderr.startswith("grasprom sweep: error:")


def test_cli_unwritable_out_and_corrupt_resume(tmp_path, python, subprocess_env):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    p = _cli(
        python,
        subprocess_env,
        "sweep",
        "--thickness",
        "1.0",
        "--material",
        "mr",
        "--out",
        str(blocker / "sub"),
    )
    assert p.returncode == 2 and str(blocker / "sub") in p.stderr and "--out" in p.stderr

    out = tmp_path / "sweep"
    run_sweep(build_grid("0.8,1.0", "mr"), out, workers=1, progress=False, runner=fr.fast_runner)
    csv = out / "mr_t1.00.csv"
    csv.write_text("garbage\n")
    # real runner, but the corrupt file is found before anything runs
    p = _cli(
        python,
        subprocess_env,
        "sweep",
        "--thickness",
        "0.8,1.0",
        "--material",
        "mr",
        "--out",
        str(out),
        "--workers",
        "1",
    )
    assert p.returncode == 2, p.stderr
    assert str(csv) in p.stderr and "Traceback" not in p.stderr
    assert csv.read_text() == "garbage\n"


def test_cli_sweep_exit_codes_in_process(tmp_path, capsys):
    args = ["sweep", "--thickness", "0.8:1.2:0.2", "--material", "mr", "--quiet", "--workers", "1"]
    assert main([*args, "--out", str(tmp_path / "ok")], runner=fr.fast_runner) == 0
    assert "3 computed" in capsys.readouterr().out
    assert main([*args, "--out", str(tmp_path / "bad")], runner=fr.failing_runner) == 1
    assert "FAILED mr_t1.00" in capsys.readouterr().out
    rc = main(
        [
            "sweep",
            "--thickness",
            "1.0",
            "--material",
            "mr",
            "--force-cap",
            "-1",
            "--out",
            str(tmp_path / "x"),
        ],
        runner=fr.fast_runner,
    )
    assert rc == 2 and "--force-cap" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:  # argparse: --workers and --scheduler exclusive
        main(
            [
                "sweep",
                "--thickness",
                "1",
                "--material",
                "mr",
                "--out",
                "x",
                "--workers",
                "2",
                "--scheduler",
                "tcp://127.0.0.1:8786",
            ]
        )
    assert exc.value.code == 2
    (tmp_path / "ok" / "mr_t0.80.csv").write_text("x")
    assert main([*args, "--out", str(tmp_path / "ok")], runner=fr.fast_runner) == 2


@pytest.fixture
def sweep_dir(tmp_path):
    out = tmp_path / "sweep"
    run_sweep(
        build_grid("0.8:1.2:0.2", "mr,le"), out, workers=1, progress=False, runner=fr.failing_runner
    )
    return out


def test_report_table_and_plot(sweep_dir, tmp_path):
    table = sweep_table(sweep_dir, gaps_mm=(20.0, 3.0, 0.5))
    assert len(table) == 6
    row = table[(table.material == "mr") & (table.thickness_mm == 1.0)].iloc[0]
    assert row.status == "failed" and row.steps == 0
    ok = table[table.status == "complete"]
    assert len(ok) == 4 and (ok.steps == 12).all() and (ok.last_gap_mm == 1.5).all()
    assert ok["force_N_at_0.5mm"].isna().all()  # never reached: no extrapolation
    assert (ok["force_N_at_3mm"] > ok["force_N_at_20mm"]).all()
    case = df.read_case(sweep_dir / "le_t1.20.json").table
    le12 = ok[(ok.material == "le") & (ok.thickness_mm == 1.2)].iloc[0]
    assert le12["max_force_N"] == case["force_N"].max()

    files = make_report(sweep_dir, tmp_path / "rep", logy=True)
    assert files.plot_png.stat().st_size > 1000
    assert files.plot_png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    saved = pd.read_csv(files.table_csv)
    assert list(saved.columns[:4]) == ["material", "thickness_mm", "status", "steps"]
    assert "failed" in files.text and "le" in files.text


def test_force_at_gap():
    assert force_at_gap([10, 5, 2], [0, 1, 4], 5) == 1.0
    assert force_at_gap([10, 5, 2], [0, 1, 4], 3.5) == pytest.approx(2.5)
    assert force_at_gap([10, 5, 2], [0, 1, 4], 1.0) != force_at_gap([10, 5, 2], [0, 1, 4], 1.0)


def test_cli_report(sweep_dir, tmp_path, capsys):
    out = tmp_path / "rep"
    assert main(["report", str(sweep_dir), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "force_N_at" in text and (out / "force_gap.png").exists()
    assert (out / "sweep_table.csv").exists()
    assert main(["report", str(tmp_path / "missing"), "--out", str(out)]) == 2
    assert "missing" in capsys.readouterr().err


def test_python_dash_m_help(python, subprocess_env):
    p = _cli(python, subprocess_env, "sweep", "--help")
    assert p.returncode == 0 and "--thickness" in p.stdout and "default 30" in p.stdout


def _runner_with_a_selection(spec):
    """A fake case whose last three rows got a companion selection: two taken, one kept."""
    res = fr.fake_result(spec)
    band = res.table.iloc[-3:]
    gaps = band.gap_mm.tolist()
    choices = [
        {"gap_mm": g, "own_force_N": 2.0 * f, "companion_force_N": f, "taken": k < 2}
        for k, (g, f) in enumerate(zip(gaps, band.force_N))
    ]
    sel = {"taken_gaps_mm": gaps[:2], "choices": choices}
    return type(res)(res.table, res.status, {**res.info, "band_selection": sel})


def test_the_report_shows_the_band_selection(tmp_path):
    """A sweep with the companion selection: ``band_rows_taken`` counts the replaced rows and
    ``band_selection.png`` is drawn; a sweep without one has NaN there and no figure."""
    sel, plain = tmp_path / "sel", tmp_path / "plain"
    grid = build_grid("1.0:1.2:0.2", "mr,le")
    run_sweep(grid, sel, workers=1, progress=False, runner=_runner_with_a_selection)
    run_sweep(grid, plain, workers=1, progress=False, runner=fr.fast_runner)
    files = make_report(sel, tmp_path / "rep")
    assert list(pd.read_csv(files.table_csv)["band_rows_taken"]) == [2, 2, 2, 2]
    assert files.band_png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    files = make_report(plain, tmp_path / "rep_plain")
    assert files.band_png is None and not (tmp_path / "rep_plain" / "band_selection.png").exists()
    assert pd.read_csv(files.table_csv)["band_rows_taken"].isna().all()
