"""`grasprom synth` and `grasprom diagnose` through the main CLI entry point."""

import json

from grasprom.cli import main


def test_synth_then_diagnose_through_the_cli(tmp_path, capsys):
    trials = tmp_path / "trials"
    assert main(["synth", "--out", str(trials), "--effect", "mechanism_friction", "--seed", "3",
                 "--trials", "4"]) == 0  # fmt: skip
    csvs = sorted(str(p) for p in trials.glob("trial_*.csv"))
    assert len(csvs) == 4
    out = tmp_path / "diag"
    assert main(["diagnose", *csvs, "--out", str(out), "--no-plots"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["verdict"]["label"] == "explained"
    assert "mechanism_friction" in report["verdict"]["effects"]
    assert "VERDICT" in capsys.readouterr().out


def test_diagnose_bad_input_exit_code(tmp_path, capsys):
    bad = tmp_path / "t.csv"
    bad.write_text("time_s,theta_deg\n0,1\n")
    assert main(["diagnose", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "t.csv" in capsys.readouterr().err
