"""Issue 14, surrogate slice: content checks of surrogate files, FE data checked against its
sweep manifest, ``check`` with a tolerance and the FE hash, messages and file writes.

Every bad input asserts the exception type (and the CLI exit code 2), that the message names
the file and the material / curve / key / value, that the CLI prints no traceback, and that
nothing partial is left behind.
"""

from __future__ import annotations

import copy
import errno
import json
import math
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from grasprom.cli import main
from grasprom.fe import atomicio
from grasprom.fe import datafiles as df
from grasprom.fe.grid import build_grid
from grasprom.fe.model2d import MeshSpec
from grasprom.fe.sweep import run_sweep
from grasprom.surrogate import (
    CHECK_TOLERANCE,
    FEDataError,
    Surrogate,
    SurrogateFileError,
    SurrogateWriteError,
    check_passed,
    format_check,
    read_fe_cases,
)
from tests import fake_runner as fr

ROOT = Path(__file__).resolve().parents[2]
DEFAULT = ROOT / "fe_data" / "2d"
HOLDOUT = ROOT / "fe_data" / "2d_holdout"


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> tuple[Path, dict]:
    """The shipped surrogate saved once, and its parsed content."""
    p = tmp_path_factory.mktemp("good") / "s.json"
    Surrogate.build(DEFAULT).save(p)
    return p, json.loads(p.read_text())


def _cli(argv, capsys) -> tuple[int, str]:
    code = main(argv)
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    return code, err


def _curve(d, m="mr", i=0):
    return d["materials"][m]["curves"][i]


def _set(path, value):
    def mutate(d):
        *keys, last = path
        node = d
        for k in keys:
            node = node[k]
        node[last] = value(node[last]) if callable(value) else value

    return mutate


def _mat(m, key, value):
    return _set(("materials", m, key), value)


def _cv(key, value, m="mr", i=3):
    return _set(("materials", m, "curves", i, key), value)


def _rename(old, new):
    def mutate(d):
        d["materials"][new] = d["materials"].pop(old)

    return mutate


def _swap_gap_nodes(d):
    g = _curve(d, "nh", 2)["gap_mm"]
    g[1], g[2] = g[2], g[1]


BAD_FILES = [
    # (id, mutation, needles)
    ("reversed-thickness", _mat("mr", "thickness_mm", lambda t: t[::-1]), ["'mr'", "thickness"]),
    ("negated-forces", _cv("force_N", lambda f: [-v for v in f]), ["force_N[", "outside [0"]),
    ("force-1e300", _cv("force_N", lambda f: [1e300] + f[1:]), ["force_N[0] = 1e+300"]),
    ("infinite-slope", _cv("dforce_dgap_N_per_mm", lambda v: [-math.inf] + v[1:]), ["-inf"]),
    ("nan-gap", _cv("gap_mm", lambda g: g[:2] + [math.nan] + g[3:]), ["gap_mm[2] = nan"]),
    ("nan-force", _cv("force_N", lambda f: f[:1] + [math.nan] + f[2:]), ["force_N[1] = nan"]),
    ("nan-thickness", _mat("le", "thickness_mm", lambda t: [math.nan] + t[1:]), ["'le'", "nan"]),
    ("negative-diameter", _set(("diameter_mm",), -30.0), ["diameter_mm -30 mm"]),
    ("zero-diameter", _set(("diameter_mm",), 0), ["diameter_mm 0 mm"]),
    ("huge-diameter", _set(("diameter_mm",), 1e300), ["diameter_mm 1e+300"]),
    ("nan-diameter", _set(("diameter_mm",), math.nan), ["diameter_mm = nan is not finite"]),
    ("string-diameter", _set(("diameter_mm",), "30"), ["diameter_mm = '30' is not a number"]),
    ("renamed-material", _rename("mr", "steel"), ["unknown material 'steel'"]),
    ("thickness-0.01", _mat("nh", "thickness_mm", lambda t: [0.01] + t[1:]), ["0.01 mm"]),
    ("thickness-14.9", _mat("nh", "thickness_mm", lambda t: t[:-1] + [14.9]), ["14.9 mm"]),
    ("gap-not-increasing", _swap_gap_nodes, ["'nh_t1.00'", "gap axis", "not strictly"]),
    ("negative-stiffness", _cv("dforce_dgap_N_per_mm", lambda v: v[:1] + [5.0] + v[2:]), ["[1]"]),
    ("stiffness-1e300", _cv("dforce_dgap_N_per_mm", lambda v: [-1e300] + v[1:]), ["1e+300"]),
    ("negative-contact-gap", _mat("mr", "contact_gap_mm", lambda g: [-1.6] + g[1:]), ["-1.6"]),
    ("contact-gap-over-diameter", _mat("le", "contact_gap_mm", lambda g: [31.0] + g[1:]), ["31"]),
    ("gap-beyond-diameter", _cv("gap_mm", lambda g: g[:-1] + [40.0]), ["40 mm lies outside"]),
    ("negative-gap", _cv("gap_mm", lambda g: [-1.0] + g[1:]), ["-1..", "outside [0, 30]"]),
    ("stem-of-other-curve", _cv("stem", "mr_t0.80", m="mr", i=4), ["'mr_t0.80'", "stem"]),
    ("stem-of-other-material", _cv("stem", "le_t1.10", m="nh", i=3), ["'le_t1.10'", "stem"]),
    ("fe-hash-not-hex", _set(("fe_hash",), "deadbeef"), ["fe_hash 'deadbeef'"]),
    ("unequal-node-arrays", _cv("force_N", lambda f: f[:-1]), ["node arrays of lengths"]),
    ("thickness-string", _mat("mr", "thickness_mm", lambda t: ["abc"] + t[1:]), ["'abc'"]),
    ("curve-count", _mat("mr", "curves", lambda c: c[:-1]), ["one entry per thickness"]),
    ("no-materials", _set(("materials",), {}), ["materials must be a non-empty object"]),
    ("params-not-object", _set(("params",), [1, 2]), ["params must be an object"]),
    ("force-string", _cv("force_N", lambda f: ["1.0"] + f[1:]), ["force_N[0] = '1.0'"]),
    ("params-unknown-key", _set(("params", "bogus"), 1), ["inconsistent content", "bogus"]),
]


@pytest.mark.parametrize(
    ("mutation", "needles"), [b[1:] for b in BAD_FILES], ids=[b[0] for b in BAD_FILES]
)
def test_bad_surrogate_content_refused(mutation, needles, good, tmp_path, capsys):
    d = copy.deepcopy(good[1])
    mutation(d)
    bad = tmp_path / "bad_surrogate.json"
    bad.write_text(json.dumps(d))  # NaN / Infinity written as JSON extensions
    with pytest.raises(SurrogateFileError) as exc:
        Surrogate.load(bad)
    msg = str(exc.value)
    assert "bad_surrogate.json" in msg
    for needle in needles:
        assert needle in msg, (needle, msg)
    code, err = _cli(["surrogate", "check", str(bad), "--fe", str(HOLDOUT)], capsys)
    assert code == 2 and "bad_surrogate.json" in err and needles[0] in err


def test_nan_message_names_material_curve_not_finite(good, tmp_path):
    d = copy.deepcopy(good[1])
    _cv("force_N", lambda f: f[:1] + [math.nan] + f[2:], m="le", i=5)(d)
    bad = tmp_path / "nan.json"
    bad.write_text(json.dumps(d))
    with pytest.raises(SurrogateFileError) as exc:
        Surrogate.load(bad)
    msg = str(exc.value)
    assert "nan.json" in msg and "material 'le'" in msg and "curve 'le_t1.30'" in msg
    assert "not finite" in msg and "gap_mm must be finite" not in msg


def test_invalid_utf8_surrogate_names_file(good, tmp_path, capsys):
    bad = tmp_path / "latin.json"
    bad.write_bytes(good[0].read_bytes().replace(b'"mr"', b'"m\xe9"', 1))
    with pytest.raises(SurrogateFileError) as exc:
        Surrogate.load(bad)
    assert "latin.json" in str(exc.value) and "UTF-8" in str(exc.value)
    code, err = _cli(["surrogate", "check", str(bad), "--fe", str(HOLDOUT)], capsys)
    assert code == 2 and "latin.json" in err and "UTF-8" in err


def test_shipped_files_pass_and_round_trip_unchanged(good, tmp_path):
    s = Surrogate.load(good[0])
    again = s.save(tmp_path / "again.json")
    assert again.read_bytes() == good[0].read_bytes()
    Surrogate.load(again, fe_dir=DEFAULT)


# --------------------------------------------------------------------------- FE data


def _sweep(tmp_path, t="0.8:1.2:0.2", m="mr", **kw) -> Path:
    out = tmp_path / "fe"
    run_sweep(build_grid(t, m, **kw), out, workers=1, progress=False, runner=fr.fast_runner)
    return out


def _rewrite_case(directory: Path, stem: str, meta_edit=None, table_edit=None) -> None:
    """Change a case in place, keeping its CSV hash consistent (only the content is bad)."""
    jp = directory / f"{stem}.json"
    meta = json.loads(jp.read_text())
    if table_edit is not None:
        lines = (directory / f"{stem}.csv").read_text().splitlines()
        data = ("\n".join(table_edit(lines)) + "\n").encode()
        (directory / f"{stem}.csv").write_bytes(data)
        meta["csv_sha256"] = df.sha256_bytes(data)
    if meta_edit is not None:
        meta_edit(meta)
    jp.write_text(json.dumps(meta))


def _move_case(directory: Path, stem: str, new_stem: str) -> None:
    for suf in (".csv", ".json"):
        (directory / f"{stem}{suf}").rename(directory / f"{new_stem}{suf}")


def _one_row(d):
    _rewrite_case(d, "mr_t1.00", table_edit=lambda lines: lines[:2])


def _thickness(value):
    def edit(d):
        new = df.case_stem("mr", value)
        _rewrite_case(d, "mr_t1.00", meta_edit=lambda m: m.update(thickness_mm=value, stem=new))
        _move_case(d, "mr_t1.00", new)
        man = json.loads((d / "sweep.json").read_text())
        for c in man["cases"]:
            if c["stem"] == "mr_t1.00":
                c.update(stem=new, thickness_mm=value)
        (d / "sweep.json").write_text(json.dumps(man))

    return edit


def _spec_edit(key, value):
    def edit(d):
        def change(m):
            m[key] = value  # a consistent sidecar of another sweep
            m["spec"][key] = value

        _rewrite_case(d, "mr_t1.00", meta_edit=change)

    return edit


def _mesh_edit(d):
    _rewrite_case(d, "mr_t1.00", meta_edit=lambda m: m["spec"]["mesh"].update(n_layers=3))


def _mixed_without_manifest(d):
    other = d.parent / "other"
    run_sweep(
        build_grid("1.4", "mr", diameter_mm=32),
        other,
        workers=1,
        progress=False,
        runner=fr.fast_runner,
    )
    for suf in (".csv", ".json"):
        shutil.copy(other / f"mr_t1.40{suf}", d / f"mr_t1.40{suf}")
    (d / "sweep.json").unlink()


def _unlisted(d):
    man = json.loads((d / "sweep.json").read_text())
    man["cases"] = [c for c in man["cases"] if c["stem"] != "mr_t1.20"]
    (d / "sweep.json").write_text(json.dumps(man))


def _other_hash(d):
    man = json.loads((d / "sweep.json").read_text())
    man["cases"][0]["input_hash"] = "0" * 64
    (d / "sweep.json").write_text(json.dumps(man))


def _material(d):
    _rewrite_case(d, "mr_t1.00", meta_edit=lambda m: m.update(material="steel"))


def _wrong_thickness(d):
    _rewrite_case(d, "mr_t1.00", meta_edit=lambda m: m.update(thickness_mm=1.05))


def _geometry(value):
    def edit(d):
        for stem in ("mr_t0.80", "mr_t1.00", "mr_t1.20"):
            _rewrite_case(
                d,
                stem,
                meta_edit=lambda m: (
                    m.update(diameter_mm=value),
                    m["spec"].update(diameter_mm=value),
                ),
            )
        (d / "sweep.json").unlink()

    return edit


def _top_diameter(d):
    _rewrite_case(d, "mr_t1.00", meta_edit=lambda m: m.update(diameter_mm=3.0))


def _utf8_sidecar(d):
    jp = d / "mr_t1.00.json"
    jp.write_bytes(jp.read_bytes().replace(b'"complete"', b'"compl\xe8te"', 1))


def _utf8_csv(d):
    csv = d / "mr_t1.00.csv"
    data = csv.read_bytes().replace(b"gap_mm", b"gap_\xb5m", 1)  # latin-1 micro sign
    csv.write_bytes(data)
    _rewrite_case(d, "mr_t1.00", meta_edit=lambda m: m.update(csv_sha256=df.sha256_bytes(data)))


BAD_FE = [
    # (id, edit, error type, file named, needles)
    ("one-row", _one_row, FEDataError, "mr_t1.00.csv", ["1 row"]),
    ("thickness-0.01", _thickness(0.01), FEDataError, "mr_t0.01.json", ["0.01 mm"]),
    ("thickness-14.9", _thickness(14.9), FEDataError, "mr_t14.90.json", ["14.9 mm"]),
    (
        "param-vs-manifest",
        _spec_edit("force_cap_N", 50.0),
        FEDataError,
        "mr_t1.00.json",
        ["force_cap_N: 200.0 != 50.0", "sweep.json"],
    ),
    (
        "mesh-vs-manifest",
        _mesh_edit,
        FEDataError,
        "mr_t1.00.json",
        [f"mesh.n_layers: {MeshSpec().n_layers} != 3"],
    ),
    (
        "mixed-no-manifest",
        _mixed_without_manifest,
        FEDataError,
        "mr_t1.40.json",
        ["diameter_mm: 30.0 != 32.0"],
    ),
    ("not-in-manifest", _unlisted, FEDataError, "mr_t1.20.json", ["not listed"]),
    ("hash-vs-manifest", _other_hash, FEDataError, "mr_t0.80.json", ["input_hash"]),
    ("unknown-material", _material, FEDataError, "mr_t1.00.json", ["'steel'"]),
    ("thickness-vs-name", _wrong_thickness, FEDataError, "mr_t1.00.json", ["file name"]),
    ("negative-diameter", _geometry(-30.0), FEDataError, "mr_t0.80.json", ["diameter_mm = -30.0"]),
    ("diameter-vs-spec", _top_diameter, FEDataError, "mr_t1.00.json", ["disagrees with its spec"]),
    ("utf8-sidecar", _utf8_sidecar, df.CorruptCaseError, "mr_t1.00.json", ["UTF-8", "0xe8"]),
    ("utf8-csv", _utf8_csv, df.CorruptCaseError, "mr_t1.00.csv", ["UTF-8"]),
]


@pytest.mark.parametrize(
    ("edit", "exc_type", "named", "needles"), [b[1:] for b in BAD_FE], ids=[b[0] for b in BAD_FE]
)
def test_bad_fe_data_refused(edit, exc_type, named, needles, tmp_path, capsys):
    d = _sweep(tmp_path)
    edit(d)
    with pytest.raises(exc_type) as exc:
        read_fe_cases(d)
    msg = str(exc.value)
    assert named in msg
    for needle in needles:
        assert needle in msg, (needle, msg)
    out = tmp_path / "s.json"
    code, err = _cli(["surrogate", "build", "--fe", str(d), "--out", str(out)], capsys)
    assert code == 2 and named in err and needles[0] in err
    assert not out.exists() and not list(tmp_path.glob(".s.json.*"))


def test_clean_fake_sweep_builds(tmp_path):
    d = _sweep(tmp_path)
    s = Surrogate.build(d)
    assert s.thicknesses("mr") == (0.8, 1.0, 1.2)


# --------------------------------------------------------------------------- check


def test_check_passes_for_the_shipped_surrogate(good):
    res = Surrogate.load(good[0]).check(HOLDOUT)
    assert res["passed"] and check_passed(res) and res["failures"] == []
    assert res["tolerance"]["force_max_pct"] == CHECK_TOLERANCE["force_max_pct"] == 3.0
    assert res["tolerance"]["gap_max_mm"] == 0.02 and res["tolerance"]["scheme"] == "aligned"
    assert res["fe_hash"]["match"] is True and "PASSED" in format_check(res)


def test_check_fails_past_the_tolerance(good, tmp_path):
    d = copy.deepcopy(good[1])
    for md in d["materials"].values():
        for c in md["curves"]:
            c["force_N"] = [1.5 * v for v in c["force_N"]]
            c["dforce_dgap_N_per_mm"] = [1.5 * v for v in c["dforce_dgap_N_per_mm"]]
    p = tmp_path / "scaled.json"
    p.write_text(json.dumps(d))
    s = Surrogate.load(p)
    res = s.check(HOLDOUT)
    assert res["passed"] is False and not check_passed(res)
    assert any("force_max_pct" in f and "> tolerance 3 %" in f for f in res["failures"])
    assert "FAILED" in format_check(res)
    loose = s.check(HOLDOUT, tolerance={"force_max_pct": 1e6, "gap_max_mm": 1e6})
    assert check_passed(loose)


def test_check_fails_on_fe_hash_mismatch(tmp_path):
    src = tmp_path / "fe"
    src.mkdir()
    for stem in ("nh_t1.40", "nh_t1.50", "nh_t1.60", "nh_t1.70"):
        for suf in (".csv", ".json"):
            shutil.copy(DEFAULT / f"{stem}{suf}", src / f"{stem}{suf}")
    p = Surrogate.build(src).save(tmp_path / "s.json")
    with pytest.warns(UserWarning, match="outside"):
        assert check_passed(Surrogate.load(p).check(HOLDOUT))
    for suf in (".csv", ".json"):
        (src / f"nh_t1.70{suf}").unlink()  # the FE data changed since the build
    with pytest.warns(UserWarning, match=r"s\.json.*differs from its FE source"):
        s = Surrogate.load(p)
    with pytest.warns(UserWarning, match="outside"):
        res = s.check(HOLDOUT)
    assert res["fe_hash"]["match"] is False and not check_passed(res)
    assert any("fe_hash" in f and str(src) in f for f in res["failures"])
    with pytest.raises(SurrogateFileError, match="hash mismatch"):
        Surrogate.load(p, fe_dir=src)


def test_check_fails_when_nothing_is_compared(tmp_path):
    src = tmp_path / "fe"
    run_sweep(
        build_grid("3.0:3.4:0.2", "mr"), src, workers=1, progress=False, runner=fr.fast_runner
    )
    s = Surrogate.build(src)
    with pytest.warns(UserWarning, match="outside"):
        res = s.check(HOLDOUT)
    assert not check_passed(res) and "no FE point" in res["failures"][0]


# --------------------------------------------------------------------------- writing


def _enospc(*_a, **_k):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


@pytest.mark.parametrize("target", ["write", "replace"])
def test_save_full_disk_simulated(target, good, tmp_path, monkeypatch, capsys):
    s = Surrogate.load(good[0])
    out = tmp_path / "s.json"
    monkeypatch.setattr(atomicio.os, target, _enospc)
    with pytest.raises(SurrogateWriteError) as exc:
        s.save(out)
    monkeypatch.undo()
    e = exc.value
    assert isinstance(e, OSError) and isinstance(e, SurrogateFileError)
    assert e.errno == errno.ENOSPC and str(out) in str(e) and ".tmp" not in str(e)
    assert list(tmp_path.iterdir()) == []


def _mount_tiny_tmpfs(mnt: Path) -> bool:
    if not hasattr(os, "geteuid") or os.geteuid() != 0:
        return False
    r = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mnt)], capture_output=True
    )
    return r.returncode == 0


def test_cli_build_full_disk_tmpfs(tmp_path, capsys, monkeypatch):
    mnt = tmp_path / "tiny"
    mnt.mkdir()
    mounted = _mount_tiny_tmpfs(mnt)
    if not mounted:
        if os.environ.get("CI") != "true":
            pytest.skip("cannot mount a tmpfs (not root?); test_save_full_disk_simulated covers it")
        monkeypatch.setattr(atomicio.os, "write", _enospc)  # CI without mount: simulate
    try:
        out = mnt / "surrogate.json"  # ~100 kB: does not fit in 64 kB
        code, err = _cli(["surrogate", "build", "--fe", str(DEFAULT), "--out", str(out)], capsys)
        monkeypatch.undo()
        assert code == 2 and str(out) in err and "No space left on device" in err
        assert list(mnt.iterdir()) == []
    finally:
        if mounted:
            subprocess.run(["umount", str(mnt)], check=False)


def test_surrogate_file_is_0644_whatever_the_umask(good, tmp_path):
    old = os.umask(0o077)
    try:
        p = Surrogate.load(good[0]).save(tmp_path / "s.json")
    finally:
        os.umask(old)
    assert p.stat().st_mode & 0o777 == 0o644
