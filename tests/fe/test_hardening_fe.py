"""Issue 14, FE-sweep slice: bad inputs and faults of the grid, the sweep and its files.

Every bad input asserts the exception type (or the CLI exit code), that the message names the
parameter / file / value, that the CLI prints no traceback, and that nothing partial is left.
The fault cases: concurrent sweeps into one directory, a killed main process, a full disk
(a small tmpfs when root, else simulated ENOSPC).
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import signal
import subprocess
import textwrap
import time
from pathlib import Path

import pytest

from grasprom.cli import main
from grasprom.fe import atomicio
from grasprom.fe import datafiles as df
from grasprom.fe.grid import MAX_CASES, SweepInputError, build_grid, parse_thickness
from grasprom.fe.model2d import ELEMENT_DESCRIPTIONS, ELEMENTS, CaseSpec, MeshSpec
from grasprom.fe.sweep import (
    LOCK_NAME,
    SweepConflictError,
    SweepWriteError,
    read_lock_record,
    run_sweep,
)
from tests import fake_runner as fr
from tests.conftest import ROOT


def _leftovers(directory: Path) -> list[str]:
    """Temporary files of the atomic writer and CSVs without a sidecar (partial cases)."""
    if not directory.is_dir():
        return []
    tmp = [p.name for p in directory.iterdir() if p.name.endswith(".tmp")]
    lone = [p.name for p in directory.glob("*.csv") if not p.with_suffix(".json").exists()]
    return sorted(tmp + lone)


def _cli(argv, capsys, runner=fr.fast_runner) -> tuple[int, str]:
    code = main(argv, runner=runner)
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    return code, err


# --------------------------------------------------------------------------- grid

GRID_BAD = [
    # (thickness, materials, kwargs, env, needles)
    ("0.8:1.0:1e-9", "mr", {}, {}, ["--thickness", "200000001", str(MAX_CASES), "GRASPROM_MAX"]),
    ("0.1:10:0.001", "mr", {}, {}, ["--thickness", "9901", "limit of 1000"]),
    (",".join(f"{0.1 + 0.01 * i:.2f}" for i in range(1001)), "mr", {}, {}, ["1001 cases"]),
    ("0.8:2.0:0.1", "mr,nh,le", {"max_cases": 20}, {}, ["13 x 3", "39 cases", "limit of 20"]),
    ("0.8:2.0:0.1", "mr", {}, {"GRASPROM_MAX_CASES": "5"}, ["13 cases", "limit of 5"]),
    ("1.0", "mr", {}, {"GRASPROM_MAX_CASES": "many"}, ["GRASPROM_MAX_CASES", "'many'"]),
    ("1.0", "mr", {"max_cases": 0}, {}, ["max_cases", "0"]),
    ("0.01", "mr", {}, {}, ["--thickness", "0.01 mm", "0.1-10 mm"]),
    ("0.0008", "mr", {}, {}, ["--thickness", "0.0008 mm", "in m"]),
    ("0.05,1.0", "mr", {}, {}, ["--thickness", "0.05 mm"]),
    ("14.9", "mr", {}, {}, ["--thickness", "14.9 mm", "um"]),
    ("12", "le", {}, {}, ["--thickness", "12 mm", "plausible"]),
    ("800", "mr", {}, {}, ["--thickness", "800"]),
    ([0.01], "mr", {}, {}, ["--thickness", "0.01 mm"]),
    ("11", "mr", {"diameter_mm": 40.0}, {}, ["--thickness", "11 mm"]),
]


@pytest.mark.parametrize(("thickness", "materials", "kwargs", "env", "needles"), GRID_BAD)
def test_bad_grid_names_parameter_and_value(
    thickness, materials, kwargs, env, needles, tmp_path, monkeypatch
):
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    out = tmp_path / "out"
    t0 = time.perf_counter()
    with pytest.raises(SweepInputError) as exc:
        build_grid(thickness, materials, out_dir=out, **kwargs)
    assert time.perf_counter() - t0 < 2.0  # refused before any work
    for needle in needles:
        assert needle in str(exc.value), (needle, str(exc.value))
    assert not out.exists()  # nothing created


@pytest.mark.parametrize(
    ("thickness", "needle"),
    [("0.8:1.0:1e-9", "limit of 1000"), ("0.01", "0.01 mm"), ("14.9", "14.9 mm")],
)
def test_bad_grid_cli_exit_2_no_traceback(thickness, needle, tmp_path, capsys):
    out = tmp_path / "out"
    code, err = _cli(
        ["sweep", "--thickness", thickness, "--material", "mr", "--out", str(out)], capsys
    )
    assert code == 2 and needle in err and "--thickness" in err
    assert not out.exists()


def test_grid_limit_can_be_raised(monkeypatch):
    assert len(parse_thickness("0.1:10:0.001", limit=10_000)) == 9901
    with pytest.raises(SweepInputError, match="1982 cases"):
        build_grid("0.1:10:0.01", "mr,le")
    monkeypatch.setenv("GRASPROM_MAX_CASES", "2000")
    assert len(build_grid("0.1:10:0.01", "mr,le")) == 1982
    assert len(build_grid("0.1:10:0.01", "mr,le", max_cases=1982)) == 1982


# --------------------------------------------------------------------------- conflicts


def _grid(t="0.8,1.0", m="mr", **kw):
    return build_grid(t, m, **kw)


def test_existing_case_other_inputs_names_key(tmp_path):
    run_sweep(_grid("1.0"), tmp_path, workers=1, progress=False, runner=fr.fast_runner)
    with pytest.raises(SweepConflictError) as exc:
        run_sweep(
            _grid("1.0", force_cap_N=50), tmp_path, workers=1, progress=False, runner=fr.fast_runner
        )
    msg = str(exc.value)
    assert "mr_t1.00.json" in msg and "force_cap_N: 200.0 != 50.0" in msg


def test_manifest_other_parameters_names_key(tmp_path):
    run_sweep(_grid("1.0"), tmp_path, workers=1, progress=False, runner=fr.fast_runner)
    for suffix in (".csv", ".json"):
        (tmp_path / f"mr_t1.00{suffix}").unlink()  # only the manifest remembers the parameters
    with pytest.raises(SweepConflictError) as exc:
        run_sweep(
            _grid("1.2", diameter_mm=25), tmp_path, workers=1, progress=False, runner=fr.fast_runner
        )
    assert "sweep.json" in str(exc.value) and "diameter_mm" in str(exc.value)
    assert not (tmp_path / "mr_t1.20.json").exists()


def test_foreign_case_without_manifest_refused(tmp_path):
    run_sweep(
        _grid("1.2", jaw_length_mm=12), tmp_path, workers=1, progress=False, runner=fr.fast_runner
    )
    (tmp_path / df.MANIFEST_NAME).unlink()
    with pytest.raises(SweepConflictError) as exc:
        run_sweep(_grid("1.0"), tmp_path, workers=1, progress=False, runner=fr.fast_runner)
    assert "mr_t1.20.json" in str(exc.value) and "jaw_length_mm" in str(exc.value)
    assert not (tmp_path / "mr_t1.00.json").exists()


def test_mixed_parameters_in_one_run_refused(tmp_path):
    specs = _grid("1.0") + _grid("1.2", force_cap_N=50)
    with pytest.raises(SweepInputError) as exc:
        run_sweep(specs, tmp_path, workers=1, progress=False, runner=fr.fast_runner)
    assert "force_cap_N" in str(exc.value) and "mr_t1.20" in str(exc.value)
    assert list(tmp_path.iterdir()) == []


HOLD_SCRIPT = """
import sys
sys.path.insert(0, {root!r})
from grasprom.fe.grid import build_grid
from grasprom.fe.sweep import run_sweep
from tests.fake_runner import slow_runner
s = run_sweep(build_grid({grid!r}, "mr"), sys.argv[1], workers=1, progress=False,
              runner=slow_runner)
print(len(s.done))
"""


@contextlib.contextmanager
def _running_sweep(tmp_path, python, env, out: Path, grid="0.8:1.4:0.2"):
    """A sweep of slow fake cases running in a subprocess, yielded once it holds the lock."""
    script = tmp_path / "hold.py"
    script.write_text(textwrap.dedent(HOLD_SCRIPT.format(root=str(ROOT), grid=grid)))
    proc = subprocess.Popen(
        [python, str(script), str(out)],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 60
        while read_lock_record(out / LOCK_NAME) is None:
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "the sweep did not take the lock in 60 s"
            time.sleep(0.02)
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate(timeout=30)


def test_concurrent_sweep_other_parameters_refused(tmp_path, python, subprocess_env, capsys):
    out = tmp_path / "shared"
    with _running_sweep(tmp_path, python, subprocess_env, out) as proc:
        with pytest.raises(SweepConflictError) as exc:
            run_sweep(
                _grid("0.8:1.4:0.2", force_cap_N=50),
                out,
                workers=1,
                progress=False,
                runner=fr.fast_runner,
            )
        msg = str(exc.value)
        assert f"pid {proc.pid}" in msg and "force_cap_N: 200.0 != 50.0" in msg
        assert "another --out" in msg
        code, err = _cli(
            [
                "sweep",
                "--thickness",
                "0.8:1.4:0.2",
                "--material",
                "mr",
                "--closed-gap",
                "2.5",
                "--out",
                str(out),
                "--workers",
                "1",
                "--quiet",
            ],
            capsys,
        )
        assert code == 2 and "closed_gap_mm" in err and str(out) in err
        assert proc.wait(timeout=60) == 0
    # only the first sweep's cases, all with its parameters
    params = df.read_manifest(out)["parameters"]
    assert params["force_cap_N"] == 200.0 and params["closed_gap_mm"] == 1.5
    for jp in df.case_json_paths(out):
        assert df.case_parameters(df.read_case(jp).meta) == params
    assert len(df.case_json_paths(out)) == 4 and not _leftovers(out)


def test_concurrent_identical_sweep_waits_and_skips(tmp_path, python, subprocess_env):
    out = tmp_path / "shared"
    with _running_sweep(tmp_path, python, subprocess_env, out) as proc:
        runner = fr.CountingRunner()
        s = run_sweep(_grid("0.8:1.4:0.2"), out, workers=1, progress=False, runner=runner)
        assert proc.wait(timeout=30) == 0
        assert runner.calls == [] and len(s.skipped) == 4 and not s.done  # nothing twice
    assert len(df.case_json_paths(out)) == 4 and not _leftovers(out)


def test_identical_sweep_wait_timeout(tmp_path, python, subprocess_env):
    out = tmp_path / "shared"
    with _running_sweep(tmp_path, python, subprocess_env, out, grid="0.8:2.0:0.1") as proc:
        with pytest.raises(SweepConflictError) as exc:
            run_sweep(
                _grid("0.8:1.0:0.2"),
                out,
                workers=1,
                progress=False,
                runner=fr.fast_runner,
                lock_timeout_s=0.3,
            )
        assert f"pid {proc.pid}" in str(exc.value) and "0.3 s" in str(exc.value)


def test_stale_lock_of_killed_sweep_is_harmless(tmp_path, python, subprocess_env):
    out = tmp_path / "shared"
    with _running_sweep(tmp_path, python, subprocess_env, out) as proc:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    assert (out / LOCK_NAME).exists() and read_lock_record(out / LOCK_NAME) is None
    s = run_sweep(
        _grid("0.8:1.4:0.2", force_cap_N=200.0),
        out,
        workers=1,
        progress=False,
        runner=fr.fast_runner,
    )
    assert s.ok and len(s.done) + len(s.skipped) == 4


# --------------------------------------------------------------------------- orphaned workers

ORPHAN_SCRIPT = """
import sys
sys.path.insert(0, {root!r})
from grasprom.fe.grid import build_grid
from grasprom.fe.sweep import run_sweep
from tests.fake_runner import slow_runner
if __name__ == "__main__":  # spawn workers import this module
    run_sweep(build_grid("0.8:3.0:0.1", "mr"), sys.argv[1], workers=2, progress=False,
              runner=slow_runner)
"""


def test_workers_exit_when_main_process_is_killed(tmp_path, python, subprocess_env):
    psutil = pytest.importorskip("psutil")
    script = tmp_path / "orphan.py"
    script.write_text(textwrap.dedent(ORPHAN_SCRIPT.format(root=str(ROOT))))
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [python, str(script), str(out)],
        env=subprocess_env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    parent = psutil.Process(proc.pid)
    children = []
    try:
        deadline = time.monotonic() + 60
        while len(df.case_json_paths(out) if out.is_dir() else []) < 2:
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.05)
        children = parent.children(recursive=True)
        cmdlines = [" ".join(c.cmdline()) for c in children]
        assert sum("spawn_main" in c for c in cmdlines) == 2, cmdlines
        assert any("resource_tracker" in c for c in cmdlines), cmdlines
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
        alive = _wait_gone(psutil, children, timeout_s=5.0)
        assert not alive, alive
    finally:
        for c in children:
            with contextlib.suppress(psutil.Error):
                c.kill()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    for jp in df.case_json_paths(out):
        df.read_case(jp)  # what finished is complete


def _wait_gone(psutil, procs, timeout_s: float) -> list[str]:
    """Descriptions of the processes still running after ``timeout_s`` (zombies count as gone:
    a container's init may not reap reparented processes)."""
    deadline = time.monotonic() + timeout_s
    while True:
        alive = []
        for p in procs:
            with contextlib.suppress(psutil.NoSuchProcess):
                if p.status() != psutil.STATUS_ZOMBIE:
                    alive.append(f"{p.pid} {' '.join(p.cmdline())}")
        if not alive or time.monotonic() > deadline:
            return alive
        time.sleep(0.05)


# --------------------------------------------------------------------------- files

UTF8_CASES = [
    ("mr_t0.80.json", b'{"schema_version": 1, "st\xffem": 1}', "mr_t0.80.json"),
    ("sweep.json", b'{"cases": [], "parameters": {"\xe9": 1}}', "sweep.json"),
]


@pytest.mark.parametrize(("name", "data", "needle"), UTF8_CASES)
def test_utf8_errors_name_the_file(name, data, needle, tmp_path):
    run_sweep(_grid(), tmp_path, workers=1, progress=False, runner=fr.fast_runner)
    (tmp_path / name).write_bytes(data)
    with pytest.raises(df.CorruptCaseError) as exc:
        run_sweep(_grid(), tmp_path, workers=1, progress=False, runner=fr.fast_runner)
    assert needle in str(exc.value) and "UTF-8" in str(exc.value)
    assert (tmp_path / name).read_bytes() == data  # left untouched


def test_utf8_error_in_csv_names_the_file(tmp_path):
    run_sweep(_grid(), tmp_path, workers=1, progress=False, runner=fr.fast_runner)
    csv = tmp_path / "mr_t1.00.csv"
    data = csv.read_bytes().replace(b"gap_mm", b"gap_\xb5m", 1)
    csv.write_bytes(data)
    meta = json.loads((tmp_path / "mr_t1.00.json").read_text())
    meta["csv_sha256"] = df.sha256_bytes(data)
    (tmp_path / "mr_t1.00.json").write_text(json.dumps(meta))
    with pytest.raises(df.CorruptCaseError) as exc:
        df.read_case(csv)
    assert "mr_t1.00.csv" in str(exc.value) and "UTF-8" in str(exc.value)
    assert "0xb5" in str(exc.value)


def test_files_are_0644_whatever_the_umask(tmp_path):
    old = os.umask(0o077)
    try:
        run_sweep(
            _grid("0.8:1.2:0.2"), tmp_path, workers=1, progress=False, runner=fr.failing_runner
        )
    finally:
        os.umask(old)
    names = [p for p in tmp_path.iterdir() if p.name != LOCK_NAME]
    assert {p.suffix for p in names} == {".csv", ".json", ".txt"}
    for p in names:
        assert p.stat().st_mode & 0o777 == 0o644, p


@pytest.mark.parametrize("element", ELEMENTS)
def test_sidecar_element_is_the_mesh_element(element, tmp_path):
    spec = CaseSpec("le", 1.0, closed_gap_mm=25.0, mesh=MeshSpec(1, 8, element=element))
    s = run_sweep([spec], tmp_path, workers=1, progress=False)
    assert s.ok
    meta = df.read_case(tmp_path / "le_t1.00.json").meta
    assert meta["mesh"]["element"] == element
    assert meta["fe_info"]["element"] == ELEMENT_DESCRIPTIONS[element]
    assert f"({element})" in meta["fe_info"]["element"]
    other = next(e for e in ELEMENTS if e != element)
    assert f"({other})" not in meta["fe_info"]["element"]


# --------------------------------------------------------------------------- full disk


def _enospc(*_a, **_k):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


@pytest.mark.parametrize("target", ["write", "fsync", "replace"])
def test_atomic_write_full_disk_simulated(target, tmp_path, monkeypatch):
    path = tmp_path / "x.json"
    path.write_bytes(b"old")
    monkeypatch.setattr(atomicio.os, target, _enospc)
    with pytest.raises(atomicio.AtomicWriteError) as exc:
        atomicio.atomic_write_bytes(path, b"new content")
    monkeypatch.undo()
    assert isinstance(exc.value, OSError) and exc.value.errno == errno.ENOSPC
    assert exc.value.filename == str(path) and str(path) in str(exc.value)
    assert path.read_bytes() == b"old" and sorted(p.name for p in tmp_path.iterdir()) == ["x.json"]


def test_case_write_full_disk_simulated_leaves_no_csv(tmp_path, monkeypatch):
    real_replace = os.replace

    def replace(src, dst):
        if str(dst).endswith(".json"):
            _enospc()
        return real_replace(src, dst)

    spec = CaseSpec("mr", 1.0)
    monkeypatch.setattr(atomicio.os, "replace", replace)
    with pytest.raises(OSError) as exc:
        df.write_case(tmp_path, spec, fr.fake_result(spec))
    monkeypatch.undo()
    assert "mr_t1.00.json" in str(exc.value) and exc.value.errno == errno.ENOSPC
    assert list(tmp_path.iterdir()) == []


def test_sweep_full_disk_simulated(tmp_path, monkeypatch, capsys):
    real_write = os.write
    calls = {"n": 0}

    def write(fd, data):
        calls["n"] += 1
        if calls["n"] > 6:  # the manifest and a few cases fit, then the disk is full
            _enospc()
        return real_write(fd, data)

    monkeypatch.setattr(atomicio.os, "write", write)
    code, err = _cli(
        [
            "sweep",
            "--thickness",
            "0.8:2.0:0.1",
            "--material",
            "mr",
            "--out",
            str(tmp_path),
            "--workers",
            "1",
            "--quiet",
        ],
        capsys,
    )
    monkeypatch.undo()
    assert code == 2 and "No space left on device" in err and str(tmp_path) in err
    assert "rerun" in err and not _leftovers(tmp_path)
    for jp in df.case_json_paths(tmp_path):
        df.read_case(jp)
    assert issubclass(SweepWriteError, OSError) and issubclass(SweepWriteError, SweepInputError)


@pytest.fixture
def tiny_tmpfs(tmp_path):
    """A 64 KiB tmpfs (root only); None where it cannot be mounted outside CI."""
    mnt = tmp_path / "tiny"
    mnt.mkdir()
    ok = False
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        r = subprocess.run(
            ["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mnt)], capture_output=True
        )
        ok = r.returncode == 0
    if not ok and os.environ.get("CI") != "true":
        pytest.skip("cannot mount a tmpfs (not root?); the simulated ENOSPC tests cover it")
    try:
        yield mnt if ok else None
    finally:
        if ok:
            subprocess.run(["umount", str(mnt)], check=False)


def test_sweep_full_disk_tmpfs(tiny_tmpfs, tmp_path, monkeypatch, capsys):
    out = tiny_tmpfs if tiny_tmpfs is not None else tmp_path / "sim"
    if tiny_tmpfs is None:  # CI without mount rights: simulate the full disk instead
        out.mkdir()
        real_write, n = os.write, {"k": 0}

        def write(fd, data):
            n["k"] += 1
            if n["k"] > 20:
                _enospc()
            return real_write(fd, data)

        monkeypatch.setattr(atomicio.os, "write", write)
    with pytest.raises(SweepWriteError) as exc:
        run_sweep(
            build_grid("0.8:3.0:0.1", "mr,le"),
            out,
            workers=1,
            progress=False,
            runner=fr.fast_runner,
        )
    monkeypatch.undo()
    assert exc.value.errno == errno.ENOSPC and str(out) in str(exc.value)
    assert not _leftovers(out)
    finished = df.case_json_paths(out)
    for jp in finished:
        df.read_case(jp)  # every case left is complete and valid
    assert len(finished) < 46


def test_valid_sweep_unchanged_and_lock_released(tmp_path):
    s = run_sweep(_grid(), tmp_path, workers=1, progress=False, runner=fr.fast_runner)
    assert s.ok and [p.name for p in df.case_json_paths(tmp_path)] == [
        "mr_t0.80.json",
        "mr_t1.00.json",
    ]
    assert df.known_stems(tmp_path) == ["mr_t0.80", "mr_t1.00"]
    assert read_lock_record(tmp_path / LOCK_NAME) is None  # released, record cleared
