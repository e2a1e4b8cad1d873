"""Parallel, resumable sweeps of FE clamping cases over wall thickness x material.

Typical use (the grid comes from :mod:`grasprom.fe.grid`)::

    specs = build_grid("0.8:2.0:0.1", "mr,nh,le", out_dir="fe_data/mine")
    summary = run_sweep(specs, "fe_data/mine", workers=2)

Each finished case is written atomically by the parent process as soon as it completes
(see :mod:`grasprom.fe.datafiles`), so killing a sweep loses no finished case and rerunning
the same command skips them. Cases run in a local process pool, in-process
(``workers=1``) or on an existing Dask distributed cluster (``scheduler="tcp://..."``).

A run holds an exclusive lock on ``<out>/.sweep.lock`` (:func:`sweep_lock`): a concurrent sweep
into the same directory with other parameters is refused (:class:`SweepConflictError`), one
with the same parameters waits for the first to finish and then skips every case it finished
(so no case is computed twice). Pool workers exit when the main process dies (a watchdog
thread and, on Linux, ``PR_SET_PDEATHSIG``), so killing it leaves no process behind.

Units: lengths in mm, forces in N, times in s.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import dataclasses
import json
import math
import multiprocessing
import os
import signal
import socket
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from grasprom.fe import datafiles as df
from grasprom.fe.atomicio import AtomicWriteError
from grasprom.fe.grid import SweepInputError, check_out_dir
from grasprom.fe.model2d import CaseResult, CaseSpec
from grasprom.fe.provenance import now_iso, provenance
from grasprom.threads import BLAS_THREAD_VARS, default_blas_threads

Runner = Callable[[CaseSpec], CaseResult]


class SweepConflictError(SweepInputError):
    """The output directory holds finished cases computed from different inputs, or another
    sweep with different parameters is writing into it right now."""


class SweepWriteError(AtomicWriteError, SweepInputError):
    """A case, error record or manifest could not be written (e.g. the disk is full).

    An :class:`OSError` (``filename`` is the file) and a :class:`SweepInputError` (the CLI
    reports it as a usage error, exit code 2). Nothing partial is left behind; finished
    cases are kept and a rerun resumes.
    """

    def __str__(self) -> str:
        return (
            f"--out: cannot write {self.filename}: {self.strerror} (nothing partial was left; "
            "finished cases are kept: free space and rerun the same command to resume)"
        )


LOCK_NAME = ".sweep.lock"
"""Lock file of a sweep directory (see :func:`sweep_lock`); it stays after the run."""

LOCK_POLL_S = 0.1
"""Poll interval in s while waiting for the lock of a sweep directory."""

WATCHDOG_POLL_S = 0.2
"""Interval in s at which a pool worker checks that the sweep's main process is alive."""


# --------------------------------------------------------------------------- lock


@contextlib.contextmanager
def sweep_lock(
    out_dir: str | os.PathLike[str],
    parameters: dict[str, Any],
    *,
    timeout_s: float | None = None,
    notify: Callable[[str], None] | None = None,
) -> Iterator[Path]:
    """Hold the exclusive lock of a sweep directory for the duration of a run.

    An exclusive :func:`fcntl.flock` on ``<out_dir>/.sweep.lock`` (released by the kernel
    when the process dies, so a stale lock file of a killed sweep is harmless). The holder
    records its pid, host and sweep parameters in the file. A second sweep into the same
    directory

    * with other parameters refuses at once (:class:`SweepConflictError` naming the running
      sweep's pid and the first differing parameters);
    * with the same parameters waits until the first one finishes (then it skips every case
      the first one finished, see :func:`run_sweep`), so no case is computed twice.

    Parameters
    ----------
    out_dir : str or os.PathLike
        The sweep directory (must exist).
    parameters : dict
        This run's shared parameters (:func:`grasprom.fe.datafiles.sweep_parameters`).
    timeout_s : float, optional
        Longest wait in s for a sweep with the same parameters; None waits as long as it
        runs.
    notify : callable, optional
        Called once with a message when this run has to wait.

    Yields
    ------
    pathlib.Path
        The lock file.

    Raises
    ------
    SweepConflictError
        Another sweep with other parameters holds the lock, or the wait timed out.
    SweepInputError
        The lock file cannot be created or locked.
    """
    import fcntl

    path = Path(out_dir) / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
    except OSError as exc:
        raise SweepInputError(
            f"--out: cannot create the lock file {path} ({exc.strerror or exc})"
        ) from None
    try:
        _wait_for_lock(fcntl, fd, path, parameters, timeout_s, notify)
        try:
            _write_lock_record(fd, parameters)
            yield path
        finally:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, 0)  # the lock file stays (see LOCK_NAME), its record goes
    finally:
        os.close(fd)  # releases the flock


def _wait_for_lock(fcntl, fd, path, parameters, timeout_s, notify) -> None:
    """Take the flock on ``fd``, waiting while a sweep with the same parameters holds it."""
    deadline = None if timeout_s is None else time.monotonic() + float(timeout_s)
    told = False
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return
        except BlockingIOError:
            pass
        except OSError as exc:
            raise SweepInputError(
                f"--out: cannot lock {path} ({exc.strerror or exc}); is the directory on a "
                "file system without locks?"
            ) from None
        holder = read_lock_record(path)
        who = f"pid {holder['pid']} on {holder['host']}" if holder else "another process"
        if holder is not None:
            diffs = df.parameter_differences(holder["parameters"], parameters)
            if diffs:
                raise SweepConflictError(
                    f"--out: {path.parent} is being written right now by another sweep ({who}) "
                    f"with different parameters ({df.format_differences(diffs)}; running != "
                    "this run); use another --out directory or wait for it to finish"
                )
        if not told and notify is not None:
            notify(
                f"waiting for the sweep already running in {path.parent} ({who}); the cases "
                "it finishes will be skipped"
            )
            told = True
        if deadline is not None and time.monotonic() > deadline:
            raise SweepConflictError(
                f"--out: {path.parent} is still locked by {who} after {timeout_s:g} s "
                f"(lock file {path})"
            )
        time.sleep(LOCK_POLL_S)


def _write_lock_record(fd: int, parameters: dict[str, Any]) -> None:
    record = {
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "started": now_iso(),
        "parameters": parameters,
    }
    data = json.dumps(record, default=str).encode()
    os.ftruncate(fd, 0)
    os.pwrite(fd, data, 0)


def read_lock_record(path: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The record of the sweep holding a lock file (pid, host, started, parameters).

    Returns
    -------
    dict or None
        None if the file is empty, unreadable, or names a dead process on this host (the
        record of a killed sweep, or the holder has not written its record yet).
    """
    try:
        rec = json.loads(Path(path).read_bytes().decode("utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(rec, dict) or not isinstance(rec.get("parameters"), dict):
        return None
    if not isinstance(rec.get("pid"), int) or not isinstance(rec.get("host"), str):
        return None
    if rec["host"] == socket.gethostname():
        try:
            os.kill(rec["pid"], 0)
        except ProcessLookupError:
            return None
        except PermissionError:
            pass
    return rec


# --------------------------------------------------------------------------- workers


def _set_parent_death_signal() -> None:
    """Linux: have the kernel SIGKILL this process when its parent dies (no-op elsewhere)."""
    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):
        pass  # the watchdog thread still covers it


def _watch_parent(parent_pid: int) -> None:
    while True:
        if os.getppid() != parent_pid:
            os._exit(1)
        time.sleep(WATCHDOG_POLL_S)


def _worker_init(parent_pid: int) -> None:
    """Initializer of the pool workers: exit as soon as the sweep's main process dies.

    ``PR_SET_PDEATHSIG`` on Linux, and everywhere a daemon thread polling
    :func:`os.getppid` against ``parent_pid`` every :data:`WATCHDOG_POLL_S` s; without it,
    killing only the main process leaves the workers (and through them multiprocessing's
    resource tracker) blocked forever.
    """
    _set_parent_death_signal()
    if os.getppid() != parent_pid:  # the parent died before the signal was armed
        os._exit(1)
    threading.Thread(
        target=_watch_parent, args=(parent_pid,), name="grasprom-parent-watchdog", daemon=True
    ).start()


# --------------------------------------------------------------------------- runner


def default_runner(spec: CaseSpec) -> CaseResult:
    """Run one case with the real FE model: :func:`grasprom.fe.model2d.run_case`, or
    :func:`grasprom.fe.bandselect.run_case_3d_selected` for a ``CaseSpec3D`` (the plain
    :func:`grasprom.fe.model3d.run_case_3d` unless ``solver.band_companion`` asks for a
    companion run).

    Module-level (picklable) so process pools and Dask workers can import it.
    """
    if df.model_keys(spec)["model"] == "3d":
        from grasprom.fe.bandselect import run_case_3d_selected
        from grasprom.fe.snapshots3d import SectionRecorder

        rec = SectionRecorder()
        res = run_case_3d_selected(spec, on_step=rec)
        return CaseResult(res.table, res.status, {**res.info, "sections": rec.result()})
    from grasprom.fe.model2d import run_case

    return run_case(spec)


@dataclass(frozen=True)
class CaseOutcome:
    """What a worker sends back for one case."""

    index: int
    result: CaseResult | None
    wall_time_s: float
    error: str | None = None
    traceback: str | None = None


def execute_case(runner: Runner, index: int, spec: CaseSpec) -> CaseOutcome:
    """Run ``runner(spec)`` in a worker, timing it and capturing any exception.

    Parameters
    ----------
    runner : callable
        ``runner(spec) -> CaseResult``; module-level so it pickles by reference.
    index : int
        Position of the case in the sweep (returned unchanged).
    spec : CaseSpec
        The case.

    Returns
    -------
    CaseOutcome
        The result and its wall time in s, or the error message and formatted traceback.
    """
    t0 = time.perf_counter()
    try:
        result = runner(spec)
    except Exception as exc:  # noqa: BLE001 - a failing case must not stop the sweep
        return CaseOutcome(
            index=index,
            result=None,
            wall_time_s=time.perf_counter() - t0,
            error=f"{type(exc).__name__}: {exc}",
            traceback=traceback.format_exc(),
        )
    return CaseOutcome(index=index, result=result, wall_time_s=time.perf_counter() - t0)


# --------------------------------------------------------------------------- running


@dataclass(frozen=True)
class SweepSummary:
    """Outcome of :func:`run_sweep`.

    Attributes
    ----------
    out_dir : pathlib.Path
        Sweep directory.
    total : int
        Cases in the grid.
    done : tuple of str
        Stems computed and written by this run.
    skipped : tuple of str
        Stems already finished on disk (same inputs), not recomputed.
    failed : tuple of (str, str)
        ``(stem, error message)`` of cases that raised; see ``<stem>.error.txt``.
    partial : tuple of str
        Stems (done or skipped) whose status is ``"partial"`` (closed gap not reached).
    wall_time_s : float
        Wall time of the run in s.
    """

    out_dir: Path
    total: int
    done: tuple[str, ...]
    skipped: tuple[str, ...]
    failed: tuple[tuple[str, str], ...]
    partial: tuple[str, ...]
    wall_time_s: float

    @property
    def ok(self) -> bool:
        """True if no case failed."""
        return not self.failed

    def format(self) -> str:
        """Human-readable multi-line summary."""
        lines = [
            f"sweep {self.out_dir}: {self.total} cases, {len(self.done)} computed, "
            f"{len(self.skipped)} skipped (already finished), {len(self.failed)} failed, "
            f"{len(self.partial)} partial; {self.wall_time_s:.1f} s"
        ]
        if self.partial:
            lines.append("partial (closed gap / force cap not reached): " + ", ".join(self.partial))
        for stem, msg in self.failed:
            lines.append(f"FAILED {stem}: {msg} (see {self.out_dir / (stem + df.ERROR_SUFFIX)})")
        return "\n".join(lines)


def _existing_status(out_dir: Path, spec: CaseSpec) -> str | None:
    """Status of a finished case on disk, None if not finished.

    Raises CorruptCaseError or SweepConflictError (never deletes anything).
    """
    files = df.case_files(out_dir, df.spec_stem(spec))
    if not files.json.exists():
        return None
    case = df.read_case(files.json)
    differs = df.input_mismatch(case.meta, spec)
    if differs is not None:
        raise SweepConflictError(
            f"--out: {files.json} was computed with different inputs ({differs}; file != this "
            "run); use another --out directory"
        )
    return str(case.meta["status"])


def _check_foreign_cases(out_dir: Path, stems: Sequence[str], params: dict[str, Any]) -> None:
    """SweepConflictError if a sidecar outside this grid records other sweep parameters."""
    own = set(stems)
    for jp in df.case_json_paths(out_dir):
        if jp.stem in own:
            continue  # read in full by _existing_status
        meta = df.read_json_file(jp)
        theirs = df.case_parameters(meta) if isinstance(meta, dict) else None
        if theirs is None:
            continue
        diffs = df.parameter_differences(theirs, params)
        if diffs:
            raise SweepConflictError(
                f"--out: {jp} was computed with other sweep parameters "
                f"({df.format_differences(diffs)}; file != this run); use another --out "
                "directory"
            )


def _progress_bar(total: int, initial: int, enabled: bool):
    from tqdm.auto import tqdm

    return tqdm(
        total=total,
        initial=initial,
        disable=not enabled,
        unit="case",
        desc="FE sweep",
        dynamic_ncols=True,
    )


def run_sweep(
    specs: Sequence[CaseSpec],
    out_dir: str | os.PathLike[str],
    workers: int | None = None,
    scheduler: str | None = None,
    progress: bool = True,
    *,
    runner: Runner = default_runner,
    scheduler_timeout_s: float = 30.0,
    lock_timeout_s: float | None = None,
) -> SweepSummary:
    """Run a grid of cases, resumably, writing each finished case as soon as it completes.

    The run holds the lock of ``out_dir`` (:func:`sweep_lock`): a concurrent sweep with other
    parameters is refused, one with the same parameters waits and then skips what this one
    finished. Pool workers exit when this process dies.

    Parameters
    ----------
    specs : sequence of CaseSpec
        Cases, e.g. from :func:`build_grid`; all must share the non-grid parameters.
    out_dir : str or os.PathLike
        Sweep directory; created if needed.
    workers : int, optional
        Local process-pool size (default ``os.cpu_count()``); ``1`` runs in-process.
    scheduler : str, optional
        Address of an existing Dask distributed scheduler (e.g. ``"tcp://127.0.0.1:8786"``);
        exclusive with ``workers``. Workers must be able to import grasprom and ``runner``.
    progress : bool
        Show a tqdm progress bar (cases done / total, ETA) on stderr.
    runner : callable, keyword-only
        ``runner(spec) -> CaseResult``; default :func:`default_runner` (the real FE model).
        Must pickle (a module-level function or an instance of a module-level class) unless
        ``workers=1``.  A result's ``info[PRIOR_WALL_TIME_KEY]`` (s) is added to the case's
        wall time (:func:`split_prior_time`).
    scheduler_timeout_s : float, keyword-only
        Time in s to wait for the Dask scheduler connection.
    lock_timeout_s : float, keyword-only, optional
        Longest wait in s for another sweep with the same parameters running in ``out_dir``
        (None: as long as it runs).

    Returns
    -------
    SweepSummary

    Raises
    ------
    SweepInputError
        Bad ``out_dir``, ``workers``, mixed parameters, existing cases computed from
        different inputs or a concurrent sweep with other parameters
        (:class:`SweepConflictError`), or a write that failed, e.g. on a full disk
        (:class:`SweepWriteError`, also an :class:`OSError`).
    CorruptCaseError
        If a finished case on disk fails validation; raised before anything runs and the
        file is left untouched.
    """
    t_start = time.perf_counter()
    specs = list(specs)
    stems = _check_run_inputs(specs, workers, scheduler)
    out = check_out_dir(out_dir)
    params = df.sweep_parameters(specs[0])
    with sweep_lock(out, params, timeout_s=lock_timeout_s, notify=_notifier(progress)):
        return _run_locked(
            out, specs, stems, workers, scheduler, progress, runner, scheduler_timeout_s, t_start
        )


def _notifier(progress: bool) -> Callable[[str], None] | None:
    """Print lock-wait messages on stderr when the progress display is on."""
    if not progress:
        return None
    return lambda msg: print(f"grasprom sweep: {msg}", file=sys.stderr, flush=True)


def _run_locked(out, specs, stems, workers, scheduler, progress, runner, timeout_s, t_start):
    """The body of :func:`run_sweep`, run while holding the lock of ``out``."""
    status = _disk_status(out, specs, stems)
    skipped = [stem for stem in stems if status[stem] is not None]
    todo = [i for i, stem in enumerate(stems) if status[stem] is None]
    # longest first (thin walls take the most load steps): less idle time at the end
    todo.sort(key=lambda i: (specs[i].thickness_mm, i))
    writer = _CaseWriter(out, specs, stems, status, provenance())

    bar = _progress_bar(len(specs), len(skipped), progress)
    try:
        if todo:
            _dispatch(workers, scheduler, runner, specs, todo, writer.handle, bar, timeout_s)
    finally:
        bar.close()

    order = {s: k for k, s in enumerate(stems)}
    summary = SweepSummary(
        out_dir=out,
        total=len(specs),
        done=tuple(sorted(writer.done, key=order.__getitem__)),
        skipped=tuple(skipped),
        failed=tuple(sorted(writer.failed, key=lambda f: order[f[0]])),
        partial=tuple(s for s in stems if status[s] == "partial"),
        wall_time_s=time.perf_counter() - t_start,
    )
    _record_run(out, specs, summary, workers, scheduler)
    return summary


def _disk_status(out: Path, specs: list[CaseSpec], stems: list[str]) -> dict[str, str | None]:
    """Status of every case on disk (None: not finished), then the manifest updated.

    Validates everything on disk before anything is computed (CorruptCaseError,
    SweepConflictError, SweepInputError for parameters that differ from the manifest's).
    """
    status: dict[str, str | None] = {
        stem: _existing_status(out, s) for stem, s in zip(stems, specs)
    }
    _check_foreign_cases(out, stems, df.sweep_parameters(specs[0]))
    _write_manifest(out, specs)
    return status


def _write_manifest(out: Path, specs: Sequence[CaseSpec], **kw: Any) -> None:
    """:func:`~grasprom.fe.datafiles.write_manifest` with its errors as sweep errors."""
    try:
        df.write_manifest(out, specs, **kw)
    except AtomicWriteError as exc:
        raise SweepWriteError(exc.errno, exc.strerror, exc.filename) from None
    except ValueError as exc:
        raise SweepConflictError(f"--out: {exc}") from None


def _check_run_inputs(
    specs: list[CaseSpec], workers: int | None, scheduler: str | None
) -> list[str]:
    """Stems of the cases, after checking the grid and the worker options (SweepInputError)."""
    if not specs:
        raise SweepInputError("--thickness/--material: empty grid, nothing to run")
    if workers is not None and scheduler is not None:
        raise SweepInputError("--workers and --scheduler are exclusive")
    if workers is not None and (
        isinstance(workers, bool) or int(workers) != workers or workers < 1
    ):
        raise SweepInputError(f"--workers: must be a positive integer, got {workers!r}")
    stems = [df.spec_stem(s) for s in specs]
    if len(set(stems)) != len(stems):
        raise SweepInputError("duplicate cases in the grid (same material and thickness)")
    first = df.sweep_parameters(specs[0])
    for s in specs[1:]:
        diffs = df.parameter_differences(first, df.sweep_parameters(s))
        if diffs:
            raise SweepInputError(
                f"cases of one sweep must share their parameters; {stems[0]} and "
                f"{df.spec_stem(s)} differ in {df.format_differences(diffs)}"
            )
    return stems


@dataclass
class _CaseWriter:
    """Writes each outcome as it arrives: the case files, or the error record of a failure.

    ``status`` (stem -> status on disk) is updated in place; ``done`` and ``failed`` collect
    the stems written and the ``(stem, message)`` of the failures, in arrival order.
    """

    out: Path
    specs: Sequence[CaseSpec]
    stems: Sequence[str]
    status: dict[str, str | None]
    prov: dict
    done: list[str] = field(default_factory=list)
    failed: list[tuple[str, str]] = field(default_factory=list)

    def handle(self, outcome: CaseOutcome) -> None:
        """Write one outcome (a result that fails validation becomes a failed case)."""
        spec = self.specs[outcome.index]
        stem = self.stems[outcome.index]
        out = self.out
        if outcome.result is not None:
            try:
                result, prior = split_prior_time(outcome.result)
                wall = outcome.wall_time_s + prior
                df.write_case(out, spec, result, wall_time_s=wall, prov=self.prov)
            except AtomicWriteError as exc:
                raise SweepWriteError(exc.errno, exc.strerror, exc.filename) from None
            except ValueError as exc:
                outcome = dataclasses.replace(
                    outcome,
                    result=None,
                    error=f"invalid result: {exc}",
                    traceback=traceback.format_exc(),
                )
            else:
                self.status[stem] = outcome.result.status
                self.done.append(stem)
                err = out / f"{stem}{df.ERROR_SUFFIX}"
                if err.exists():  # stale record of an earlier failure
                    err.unlink()
                return
        msg = outcome.error or "unknown error"
        try:
            df.write_error(out, stem, msg, outcome.traceback or "")
        except AtomicWriteError as exc:
            raise SweepWriteError(exc.errno, exc.strerror, exc.filename) from None
        self.failed.append((stem, msg))


#: ``CaseResult.info`` key of a runner that continued earlier work (e.g.
#: :class:`grasprom.fe.reselect.StoredOwnRuns`): the seconds that work took, added to the
#: runner's own in the case's ``wall_time_s``; not written to the sidecar.
PRIOR_WALL_TIME_KEY = "prior_wall_time_s"


def split_prior_time(result: CaseResult) -> tuple[CaseResult, float]:
    """``result`` without :data:`PRIOR_WALL_TIME_KEY`, and its value (s; 0 if absent).

    Raises
    ------
    ValueError
        The value is not a finite number >= 0.
    """
    info = dict(result.info or {})
    raw = info.pop(PRIOR_WALL_TIME_KEY, 0.0)
    try:
        prior = float(raw)
    except (TypeError, ValueError):
        prior = math.nan
    if not (math.isfinite(prior) and prior >= 0):
        raise ValueError(f"{PRIOR_WALL_TIME_KEY}={raw!r}: must be seconds >= 0")
    return CaseResult(table=result.table, status=result.status, info=info), prior


def _dispatch(workers, scheduler, runner, specs, todo, handle, bar, timeout_s) -> None:
    """Run the cases ``todo`` on Dask, in-process (``workers == 1``) or in a process pool."""
    if scheduler is not None:
        _run_dask(scheduler, runner, specs, todo, handle, bar, timeout_s)
    elif workers == 1:
        for i in todo:
            handle(execute_case(runner, i, specs[i]))
            bar.update(1)
    else:
        _run_pool(workers, runner, specs, todo, handle, bar)


def _record_run(
    out: Path,
    specs: Sequence[CaseSpec],
    summary: SweepSummary,
    workers: int | None,
    scheduler: str | None,
) -> None:
    """Record the run's summary as ``last_run`` in the sweep manifest."""
    _write_manifest(
        out,
        specs,
        last_run={
            "finished": now_iso(),
            "workers": workers,
            "scheduler": scheduler,
            "total": summary.total,
            "done": list(summary.done),
            "skipped": list(summary.skipped),
            "failed": [s for s, _ in summary.failed],
            "partial": list(summary.partial),
            "wall_time_s": round(summary.wall_time_s, 3),
        },
    )


@contextlib.contextmanager
def _worker_blas_threads(n: int | None):
    """Environment of the pool workers spawned inside: ``n`` BLAS threads each (None: as is).

    Several workers with a BLAS thread per core each oversubscribe the machine (measured: two
    3D cases on two cores ran at 60 % of a core each).  Variables the user set are kept; the
    parent's environment is restored on exit.
    """
    saved = {k: os.environ.get(k) for k in BLAS_THREAD_VARS}
    if n is not None:
        default_blas_threads(n)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _run_pool(workers, runner, specs, todo, handle, bar) -> None:
    """Run cases in a spawn-context process pool, handling each result as it completes."""
    n = min(workers or os.cpu_count() or 1, len(todo))
    ctx = multiprocessing.get_context("spawn")
    pool = cf.ProcessPoolExecutor(
        max_workers=n, mp_context=ctx, initializer=_worker_init, initargs=(os.getpid(),)
    )
    try:
        with _worker_blas_threads(1 if n > 1 else None):  # the workers spawn on submit
            futs = {pool.submit(execute_case, runner, i, specs[i]): i for i in todo}
        for fut in cf.as_completed(futs):
            i = futs[fut]
            outcome = _collect(fut, i)
            handle(outcome)
            bar.update(1)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _collect(fut, index: int) -> CaseOutcome:
    """The outcome of a finished future; a lost worker becomes a failed case."""
    try:
        return fut.result()
    except Exception as exc:  # noqa: BLE001 - e.g. a worker process died or lost the task
        return CaseOutcome(
            index=index,
            result=None,
            wall_time_s=float("nan"),
            error=f"{type(exc).__name__}: {exc}",
            traceback=traceback.format_exc(),
        )


def _run_dask(scheduler, runner, specs, todo, handle, bar, timeout_s) -> None:
    """Run cases on an existing Dask distributed cluster."""
    try:
        from dask.distributed import Client, as_completed
    except ImportError:
        raise SweepInputError(
            "--scheduler needs dask.distributed: pip install 'grasprom[dask]' "
            "(or pip install 'dask[distributed]')"
        ) from None
    try:
        client = Client(scheduler, timeout=f"{timeout_s}s")
    except OSError as exc:
        raise SweepInputError(
            f"--scheduler: cannot connect to the Dask scheduler at {scheduler} ({exc})"
        ) from None
    try:
        futs = client.map(
            execute_case,
            [runner] * len(todo),
            todo,
            [specs[i] for i in todo],
            pure=False,
            key=[f"grasprom-{df.spec_stem(specs[i])}-{os.getpid()}-{time.time_ns()}" for i in todo],
        )
        index = {f.key: i for f, i in zip(futs, todo)}
        for fut in as_completed(futs):
            i = index[fut.key]
            outcome = _collect(fut, i)
            handle(outcome)
            bar.update(1)
    finally:
        client.close()
