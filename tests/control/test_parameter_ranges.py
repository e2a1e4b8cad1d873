"""One validation of the controller parameters for every command (issue 14): the ranges of
``PARAMETER_RANGES`` are enforced by ``ControllerParams`` itself, the FMU declares the same
ranges in SI (generated from them), and a bad parameter file makes simulate, tune and both
exports exit 2 with a message naming the parameter, writing nothing."""

from __future__ import annotations

import json
import math
from dataclasses import fields

import pytest

from grasprom.cli import main
from grasprom.control import ENCODER_COUNTS_RANGE, PARAMETER_RANGES, ControllerParams


def _bad_values(name: str):
    lo, hi = PARAMETER_RANGES[name]
    span = max(abs(hi), 1.0)
    bad = [lo - 0.5 * max(abs(lo), 1e-9) - 1e-12, hi + span, math.nan, math.inf, "1.0", True]
    return [v for v in bad if not (isinstance(v, float) and lo <= v <= hi)]


CASES = [(n, v) for n in PARAMETER_RANGES for v in _bad_values(n)]


def _with(name, value) -> dict:
    if name in ("prony_g", "prony_tau_s"):
        good = {"prony_g": [0.5], "prony_tau_s": [1.0]}
        good[name] = [value]
        return good
    return {name: value}


@pytest.mark.parametrize("name, value", CASES, ids=[f"{n}={v!r}" for n, v in CASES])
def test_out_of_range_parameters_are_refused(name, value):
    with pytest.raises(ValueError, match=name):
        ControllerParams(**_with(name, value))


@pytest.mark.parametrize("name", sorted(PARAMETER_RANGES))
def test_range_ends_are_accepted(name):
    lo, hi = PARAMETER_RANGES[name]
    for v in (lo, hi):
        kw = _with(name, v)
        if name == "sample_time_s":  # the cutoff must stay below Nyquist
            kw["velocity_cutoff_Hz"] = min(200.0, 0.25 / v)
        if name == "velocity_cutoff_Hz" and v > 250.0:
            kw["sample_time_s"] = 1e-5 if v < 5e4 else 1e-5  # Nyquist 5e4 Hz
            if v >= 5e4:
                continue  # above Nyquist at the fastest rate: refused by the Nyquist check
        ControllerParams(**kw)


@pytest.mark.parametrize("n", [1, 15, -4, 2.5, True, (1 << 30) + 1, "4096"])
def test_encoder_counts(n):
    with pytest.raises(ValueError, match="encoder_counts_per_rev"):
        ControllerParams(encoder_counts_per_rev=n)
    for ok in (0, ENCODER_COUNTS_RANGE[0], 4096, ENCODER_COUNTS_RANGE[1]):
        assert ControllerParams(encoder_counts_per_rev=ok).encoder_counts_per_rev == ok


@pytest.mark.parametrize("name", ["render_spring", "passivity_observer"])
@pytest.mark.parametrize("value", ["no", 0, 1, None])
def test_flags_must_be_booleans(name, value):
    with pytest.raises(ValueError, match=name):
        ControllerParams(**{name: value})


def test_every_real_parameter_has_a_range():
    real = {f.name for f in fields(ControllerParams) if f.type in ("float", "tuple[float, ...]")}
    assert real - {"thickness_mm"} <= set(PARAMETER_RANGES), real - set(PARAMETER_RANGES)


def test_fmu_declares_the_same_ranges_in_si(surrogate):
    from grasprom.export.variables import variables

    checked = 0
    for v in variables(ControllerParams(), surrogate):
        f = v.spec.params_field
        if v.causality != "parameter" or v.type != "Real" or f is None or f == "thickness_mm":
            continue
        lo, hi = PARAMETER_RANGES[f.split("[")[0]]
        assert v.min == pytest.approx(lo * v.spec.to_si, rel=1e-12), v.name
        assert v.max == pytest.approx(hi * v.spec.to_si, rel=1e-12), v.name
        checked += 1
    assert checked >= 25


BAD_FILES = [
    {"encoder_counts_per_rev": 1},
    {"tissue_scale": 1e300},
    {"backlash_deg": 1e6},
    {"velocity_cutoff_Hz": 1e-300},
    {"coupling_stiffness_N_per_mm": 1e308},
    {"render_spring": "no"},
]
COMMANDS = {
    "export-arduino": lambda p, out: ["export", "arduino", "--params", p, "--out", out],
    "export-fmu": lambda p, out: ["export", "fmu", "--params", p, "--out", out + "/c.fmu"],
    "tune": lambda p, out: ["tune", "--controller", p, "--out", out, "--no-plots"],
}


@pytest.mark.parametrize("bad", BAD_FILES, ids=[next(iter(b)) for b in BAD_FILES])
@pytest.mark.parametrize("cmd", sorted(COMMANDS))
def test_commands_refuse_a_bad_parameter_file_and_write_nothing(tmp_path, capsys, bad, cmd):
    src = tmp_path / "params.json"
    src.write_text(json.dumps(bad))
    out = tmp_path / "out"
    rc = main(COMMANDS[cmd](str(src), str(out)))
    err = capsys.readouterr().err
    assert rc == 2, err
    assert next(iter(bad)) in err and "Traceback" not in err
    assert not out.exists() or not any(out.rglob("*")), sorted(out.rglob("*"))


def test_simulate_refuses_a_bad_parameter_file(tmp_path, capsys):
    traj = tmp_path / "t.csv"
    traj.write_text("time_s,theta_deg\n0,22\n1,0\n")
    src = tmp_path / "params.json"
    src.write_text(json.dumps({"tissue_scale": 1e300}))
    out = tmp_path / "sim.csv"
    assert main(["simulate", "--trajectory", str(traj), "--controller", str(src),
                 "--out", str(out)]) == 2  # fmt: skip
    assert "tissue_scale" in capsys.readouterr().err and not out.exists()
