"""Parallel, resumable sweeps of FE clamping cases over wall thickness x material.

Typical use (the grid comes from :mod:`grasprom.fe.grid`)::

    specs = build_grid("0.8:2.0:0.1", "mr,nh,le", out_dir="fe_data/mine")
    summary = run_sweep(specs, "fe_data/mine", workers=2)

Each finished case is written atomically by the parent process as soon as it completes
(see :mod:`grasprom.fe.datafiles`), so killing a sweep loses no finished case and rerunning
the same command skips them. Cases run in a local process pool, in-process
(``workers=1``) or on an existing Dask distributed cluster (``scheduler="tcp://..."``).

Units: lengths in mm, forces in N, times in s.
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import multiprocessing
import os
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from grasprom.fe import datafiles as df
from grasprom.fe.grid import SweepInputError, check_out_dir
from grasprom.fe.model2d import CaseResult, CaseSpec
from grasprom.fe.provenance import now_iso, provenance

Runner = Callable[[CaseSpec], CaseResult]


class SweepConflictError(SweepInputError):
    """The output directory holds finished cases computed from different inputs."""


# --------------------------------------------------------------------------- runner


def default_runner(spec: CaseSpec) -> CaseResult:
    """Run one case with the real FE model, :func:`grasprom.fe.model2d.run_case`.

    Module-level (picklable) so process pools and Dask workers can import it.
    """
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
    if case.meta["input_hash"] != df.input_hash(spec):
        raise SweepConflictError(
            f"--out: {files.json} was computed with different inputs "
            f"(input_hash {str(case.meta['input_hash'])[:12]}... != "
            f"{df.input_hash(spec)[:12]}...); use another --out directory"
        )
    return str(case.meta["status"])


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
) -> SweepSummary:
    """Run a grid of cases, resumably, writing each finished case as soon as it completes.

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
        Must be a module-level function (picklable) unless ``workers=1``.
    scheduler_timeout_s : float, keyword-only
        Time in s to wait for the Dask scheduler connection.

    Returns
    -------
    SweepSummary

    Raises
    ------
    SweepInputError
        Bad ``out_dir``, ``workers``, mixed parameters, or existing cases computed from
        different inputs (:class:`SweepConflictError`).
    CorruptCaseError
        If a finished case on disk fails validation; raised before anything runs and the
        file is left untouched.
    """
    t_start = time.perf_counter()
    specs = list(specs)
    stems = _check_run_inputs(specs, workers, scheduler)
    out = check_out_dir(out_dir)

    status = _disk_status(out, specs, stems)
    skipped = [stem for stem in stems if status[stem] is not None]
    todo = [i for i, stem in enumerate(stems) if status[stem] is None]
    # longest first (thin walls take the most load steps): less idle time at the end
    todo.sort(key=lambda i: (specs[i].thickness_mm, i))
    writer = _CaseWriter(out, specs, stems, status, provenance())

    bar = _progress_bar(len(specs), len(skipped), progress)
    try:
        if todo:
            _dispatch(
                workers, scheduler, runner, specs, todo, writer.handle, bar, scheduler_timeout_s
            )
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
    try:
        df.write_manifest(out, specs)
    except ValueError as exc:
        raise SweepInputError(f"--out: {exc}") from None
    return status


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
                df.write_case(
                    out, spec, outcome.result, wall_time_s=outcome.wall_time_s, prov=self.prov
                )
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
        df.write_error(out, stem, msg, outcome.traceback or "")
        self.failed.append((stem, msg))


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
    df.write_manifest(
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


def _run_pool(workers, runner, specs, todo, handle, bar) -> None:
    """Run cases in a spawn-context process pool, handling each result as it completes."""
    n = min(workers or os.cpu_count() or 1, len(todo))
    ctx = multiprocessing.get_context("spawn")
    pool = cf.ProcessPoolExecutor(max_workers=n, mp_context=ctx)
    try:
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
