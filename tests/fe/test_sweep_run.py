"""Running sweeps: resume, corruption/conflict on resume, failures, pool, kill-and-resume."""

from __future__ import annotations

import json
import signal
import subprocess
import textwrap
import time
from pathlib import Path

import pandas as pd
import pytest

from grasprom.fe import datafiles as df
from grasprom.fe.grid import SweepInputError, build_grid
from grasprom.fe.sweep import SweepConflictError, run_sweep
from tests import fake_runner as fr


def _snapshot(directory: Path, stems) -> dict[str, tuple[str, int]]:
    out = {}
    for stem in stems:
        for suffix in (".csv", ".json"):
            p = directory / f"{stem}{suffix}"
            out[p.name] = (df.sha256_file(p), p.stat().st_mtime_ns)
    return out


def test_run_and_resume_skips_finished(tmp_path):
    specs = build_grid("0.8:1.2:0.2", "mr,le")
    first = fr.CountingRunner()
    s1 = run_sweep(specs[:3], tmp_path, workers=1, progress=False, runner=first)
    assert len(first.calls) == 3 and s1.ok and len(s1.done) == 3 and not s1.skipped
    before = _snapshot(tmp_path, s1.done)

    second = fr.CountingRunner()
    s2 = run_sweep(specs, tmp_path, workers=1, progress=True, runner=second)
    assert second.calls == [("le", 0.8), ("le", 1.0), ("le", 1.2)]
    assert s2.skipped == s1.done and s2.done == ("le_t0.80", "le_t1.00", "le_t1.20")
    assert _snapshot(tmp_path, s1.done) == before  # finished files untouched

    third = fr.CountingRunner()
    s3 = run_sweep(specs, tmp_path, workers=1, progress=False, runner=third)
    assert third.calls == [] and len(s3.skipped) == 6 and s3.total == 6
    man = df.read_manifest(tmp_path)
    assert len(man["cases"]) == 6 and man["last_run"]["skipped"] == list(s3.skipped)
    assert "partial" in s3.format() or "0 partial" in s3.format()


def test_corrupt_case_on_resume_is_reported_not_deleted(tmp_path):
    specs = build_grid("0.8,1.0", "mr")
    run_sweep(specs, tmp_path, workers=1, progress=False, runner=fr.fast_runner)
    csv = tmp_path / "mr_t0.80.csv"
    damaged = csv.read_bytes()[:-30]
    csv.write_bytes(damaged)
    runner = fr.CountingRunner()
    with pytest.raises(df.CorruptCaseError) as exc:
        run_sweep(specs, tmp_path, workers=1, progress=False, runner=runner)
    assert str(csv) in str(exc.value)
    assert runner.calls == []  # validation happens before anything runs
    assert csv.read_bytes() == damaged and (tmp_path / "mr_t0.80.json").exists()

    (tmp_path / "mr_t1.00.json").write_text("{ not json")
    csv.unlink()
    with pytest.raises(df.CorruptCaseError, match="mr_t0.80.csv|mr_t1.00.json"):
        run_sweep(specs, tmp_path, workers=1, progress=False, runner=runner)
    assert (tmp_path / "mr_t1.00.json").read_text() == "{ not json"


def test_different_inputs_in_same_out_dir_refused(tmp_path):
    run_sweep(build_grid("1.0", "mr"), tmp_path, workers=1, progress=False, runner=fr.fast_runner)
    before = _snapshot(tmp_path, ["mr_t1.00"])
    with pytest.raises(SweepConflictError, match="another --out"):
        run_sweep(
            build_grid("1.0", "mr", force_cap_N=50),
            tmp_path,
            workers=1,
            progress=False,
            runner=fr.fast_runner,
        )
    with pytest.raises(SweepInputError, match="another --out"):  # via the manifest
        run_sweep(
            build_grid("1.2", "mr", force_cap_N=50),
            tmp_path,
            workers=1,
            progress=False,
            runner=fr.fast_runner,
        )
    assert _snapshot(tmp_path, ["mr_t1.00"]) == before


def test_failing_case_recorded_others_finish(tmp_path):
    specs = build_grid("0.8:1.2:0.2", "mr")
    s = run_sweep(specs, tmp_path, workers=2, progress=False, runner=fr.failing_runner)
    assert not s.ok
    assert s.done == ("mr_t0.80", "mr_t1.20")
    assert [stem for stem, _ in s.failed] == ["mr_t1.00"]
    assert "fake divergence" in s.failed[0][1]
    err = (tmp_path / "mr_t1.00.error.txt").read_text()
    assert "RuntimeError: fake divergence" in err and "Traceback" in err
    assert not (tmp_path / "mr_t1.00.json").exists()
    assert "FAILED mr_t1.00" in s.format()
    # rerun with a working runner: only the failed case runs, its error file is cleared
    runner = fr.CountingRunner()
    s2 = run_sweep(specs, tmp_path, workers=1, progress=False, runner=runner)
    assert runner.calls == [("mr", 1.0)] and s2.ok
    assert not (tmp_path / "mr_t1.00.error.txt").exists()


def test_partial_cases_listed(tmp_path):
    s = run_sweep(
        build_grid("0.8,1.0", "nh"), tmp_path, workers=1, progress=False, runner=fr.partial_runner
    )
    assert s.ok and s.partial == ("nh_t0.80", "nh_t1.00")
    assert df.read_case(tmp_path / "nh_t0.80.json").meta["status"] == "partial"


def test_pool_equals_in_process(tmp_path):
    specs = build_grid("0.8:1.4:0.2", "mr,le")
    a = run_sweep(specs, tmp_path / "serial", workers=1, progress=False, runner=fr.fast_runner)
    b = run_sweep(specs, tmp_path / "pool", workers=2, progress=False, runner=fr.sleepy_runner)
    assert a.ok and b.ok and len(b.done) == 8
    pd.testing.assert_frame_equal(
        df.load_sweep(tmp_path / "serial"), df.load_sweep(tmp_path / "pool")
    )


def test_bad_run_arguments(tmp_path):
    specs = build_grid("1.0", "mr")
    with pytest.raises(SweepInputError, match="--workers"):
        run_sweep(specs, tmp_path, workers=0, runner=fr.fast_runner)
    with pytest.raises(SweepInputError, match="exclusive"):
        run_sweep(specs, tmp_path, workers=2, scheduler="tcp://127.0.0.1:1", runner=fr.fast_runner)
    with pytest.raises(SweepInputError, match="empty"):
        run_sweep([], tmp_path, runner=fr.fast_runner)


KILL_SCRIPT = """
import json, sys
sys.path.insert(0, {root!r})
from grasprom.fe.grid import build_grid
from grasprom.fe.sweep import run_sweep
from tests.fake_runner import slow_runner
specs = build_grid("0.8:1.8:0.2", "mr")
s = run_sweep(specs, sys.argv[1], workers=1, progress=False, runner=slow_runner)
print(json.dumps({{"done": s.done, "skipped": s.skipped, "failed": s.failed}}))
"""


def test_kill_and_resume_loses_nothing(tmp_path, python, subprocess_env):
    from tests.conftest import ROOT

    script = tmp_path / "run.py"
    script.write_text(textwrap.dedent(KILL_SCRIPT.format(root=str(ROOT))))
    out = tmp_path / "killed"
    proc = subprocess.Popen(
        [python, str(script), str(out)],
        env=subprocess_env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    deadline = time.monotonic() + 60
    try:
        while len(df.case_json_paths(out) if out.is_dir() else []) < 2:
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "sweep did not produce 2 cases in 60 s"
            time.sleep(0.02)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.communicate(timeout=30)
    finished = [p.stem for p in df.case_json_paths(out)]
    assert 2 <= len(finished) < 6
    before = _snapshot(out, finished)
    for stem in finished:
        df.read_case(out / f"{stem}.json")  # every sidecar present is a valid case

    rerun = subprocess.run(
        [python, str(script), str(out)],
        env=subprocess_env,
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    result = json.loads(rerun.stdout.strip().splitlines()[-1])
    assert sorted(result["skipped"]) == sorted(finished)
    assert not result["failed"]
    assert len(df.case_json_paths(out)) == 6
    assert _snapshot(out, finished) == before  # earlier finished files unchanged

    clean = tmp_path / "clean"
    run_sweep(
        build_grid("0.8:1.8:0.2", "mr"), clean, workers=1, progress=False, runner=fr.fast_runner
    )
    pd.testing.assert_frame_equal(df.load_sweep(out), df.load_sweep(clean))
    for p in df.case_json_paths(clean):
        a = json.loads(p.read_text())
        b = json.loads((out / p.name).read_text())
        assert (a["csv_sha256"], a["input_hash"]) == (b["csv_sha256"], b["input_hash"])


def test_pool_workers_run_single_threaded_blas(tmp_path, monkeypatch):
    """Two workers with a BLAS pool per core each would oversubscribe the machine; a variable
    the user set wins, and the parent's environment is left as it was."""
    import os

    for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.delenv(k, raising=False)
    monkeypatch.setenv("MKL_NUM_THREADS", "3")
    s = run_sweep(build_grid("0.8,1.0", "mr"), tmp_path, workers=2, progress=False,
                  runner=fr.env_runner)  # fmt: skip
    assert s.ok
    env = df.read_case(tmp_path / "mr_t0.80.json").meta["fe_info"]["env"]
    assert env == {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "3"}
    assert "OMP_NUM_THREADS" not in os.environ and os.environ["MKL_NUM_THREADS"] == "3"
