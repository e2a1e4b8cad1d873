"""`grasprom synth` and `grasprom diagnose` through the main CLI entry point."""

import json

import pytest

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


def test_every_option_with_a_default_states_it_in_its_help():
    """Issue 16: `--help` left defaults out (simulate --thickness, tune --out...). Every
    optional option whose default is a value (not None/False) says "default" in its help, and
    the option lists do not wrap mid-word (comma lists carry spaces)."""
    import argparse

    from grasprom.cli import _build_parser, _diagnose_parser, _synth_parser

    missing = []

    def walk(p, name):
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                for n, sp in a.choices.items():
                    walk(sp, f"{name} {n}")
            elif (a.option_strings and not a.required and a.help
                  and a.default not in (None, False, "", argparse.SUPPRESS)
                  and not isinstance(a, argparse._HelpAction | argparse._VersionAction)
                  and "default" not in a.help.lower()):  # fmt: skip
                missing.append(f"{name} {a.option_strings[0]}")
            if a.help and len(max(a.help.split(), key=len, default="")) > 40:
                missing.append(f"{name} {a.dest}: a {len(a.help)}-char word wraps mid-word")

    walk(_build_parser(), "grasprom")
    walk(_diagnose_parser(), "grasprom diagnose")
    walk(_synth_parser(), "grasprom synth")
    assert not missing, missing


# (subcommand, its required arguments; "{o}" an output path that must not be created)
UNKNOWN_OPTION_ROWS = [
    ("tune", []),
    ("build", ["--out", "{o}", "--fast"]),
    ("report", []),
    ("sweep", ["--thickness", "1.4", "--material", "mr", "--out", "{o}"]),
    ("simulate", ["--trajectory", "t.csv", "--out", "{o}"]),
    ("identify", ["t.csv", "--out", "{o}"]),
    ("surrogate build", ["--fe", "fe_data/default", "--out", "{o}"]),
    ("surrogate check", ["s.json", "--fe", "fe_data/holdout"]),
    ("surrogate plot", ["s.json", "--out", "{o}"]),
    ("export fmu", ["--out", "{o}"]),
    ("export arduino", ["--out", "{o}"]),
]


@pytest.mark.parametrize("command, required", UNKNOWN_OPTION_ROWS,
                         ids=[r[0] for r in UNKNOWN_OPTION_ROWS])  # fmt: skip
def test_unknown_option_shows_the_subcommands_usage(command, required, tmp_path, capsys):
    """An unknown option on a subcommand printed the top-level usage ("usage: grasprom [-h]
    [--version] {build,...}"); it is the (nested) subcommand's usage and error, exit 2."""
    out = tmp_path / "out"
    argv = [*command.split(), *(a.replace("{o}", str(out)) for a in required), "--bogus"]
    with pytest.raises(SystemExit) as exc:
        main(argv)
    err = capsys.readouterr().err
    assert exc.value.code == 2, err
    assert err.startswith(f"usage: grasprom {command} "), err
    assert f"grasprom {command}: error: unrecognized arguments: --bogus" in err, err
    assert "{build,sweep" not in err, err
    assert not out.exists()


def test_stray_positional_is_named_with_the_subcommands_usage(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["report", "fe_data/default", "extra", "--linear"])
    err = capsys.readouterr().err
    assert exc.value.code == 2
    assert err.startswith("usage: grasprom report ")
    assert "grasprom report: error: unrecognized arguments: extra" in err
