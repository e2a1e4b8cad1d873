"""Parallel, resumable sweeps of FE clamping cases over wall thickness x material.

Typical use::

    specs = build_grid("0.8:2.0:0.1", "mr,nh,le", out_dir="fe_data/mine")
    summary = run_sweep(specs, "fe_data/mine", workers=2)

Each finished case is written atomically by the parent process as soon as it completes
(see :mod:`grasprom.datafiles`), so killing a sweep loses no finished case and rerunning
the same command skips them. Cases run in a local process pool, in-process
(``workers=1``) or on an existing Dask distributed cluster (``scheduler="tcp://..."``).

Units: lengths in mm, forces in N, times in s.
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import math
import multiprocessing
import os
import tempfile
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any

from grasprom.fe import datafiles as df
from grasprom.fe.materials import MATERIAL_NAMES
from grasprom.fe.model2d import CaseResult, CaseSpec, MeshSpec

KNOWN_MATERIALS = MATERIAL_NAMES
"""Material keys: Mooney-Rivlin, neo-Hookean, large-strain linear elastic."""

_THICKNESS_DECIMALS = 6

Runner = Callable[[CaseSpec], CaseResult]


class SweepInputError(ValueError):
    """Bad sweep input (grid, parameters, output directory); the message names the culprit."""


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
class _Outcome:
    """What a worker sends back for one case."""

    index: int
    result: CaseResult | None
    wall_time_s: float
    error: str | None = None
    traceback: str | None = None


def execute_case(runner: Runner, index: int, spec: CaseSpec) -> _Outcome:
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
    _Outcome
        The result and its wall time in s, or the error message and formatted traceback.
    """
    t0 = time.perf_counter()
    try:
        result = runner(spec)
    except Exception as exc:  # noqa: BLE001 - a failing case must not stop the sweep
        return _Outcome(
            index=index,
            result=None,
            wall_time_s=time.perf_counter() - t0,
            error=f"{type(exc).__name__}: {exc}",
            traceback=traceback.format_exc(),
        )
    return _Outcome(index=index, result=result, wall_time_s=time.perf_counter() - t0)


# --------------------------------------------------------------------------- parsing


def _unique(items: Iterable[Any]) -> list[Any]:
    seen: set[Any] = set()
    out = []
    for x in items:
        if x not in seen:
            seen.add(x)
            out.append(x)
    return out


def _dec(text: str, what: str) -> Decimal:
    try:
        d = Decimal(text.strip())
    except InvalidOperation:
        raise SweepInputError(
            f"--thickness: cannot parse {what} {text.strip()!r} as a number"
        ) from None
    if not d.is_finite():
        raise SweepInputError(f"--thickness: {what} {text.strip()!r} is not finite")
    return d


def parse_thickness(text: str) -> list[float]:
    """Parse a ``--thickness`` value into wall thicknesses in mm.

    Parameters
    ----------
    text : str
        ``"start:stop:step"`` (inclusive of ``stop`` when it lies on the grid),
        a comma list ``"0.8,1.0"`` or a single value ``"1.2"``; all in mm.

    Returns
    -------
    list of float
        Thicknesses in mm, rounded to 6 decimals (no float drift: ``"0.8:2.0:0.1"`` gives
        exactly the 13 values 0.8, 0.9, ..., 2.0), duplicates removed.

    Raises
    ------
    SweepInputError
        On malformed text, a non-positive step, ``stop < start`` or an empty result.
    """
    text = str(text).strip()
    if not text:
        raise SweepInputError("--thickness: empty value (give e.g. 0.8:2.0:0.1, 0.8,1.0 or 1.2)")
    if ":" in text:
        parts = text.split(":")
        if len(parts) != 3:
            raise SweepInputError(
                f"--thickness: range {text!r} must be start:stop:step (e.g. 0.8:2.0:0.1)"
            )
        start, stop, step = (_dec(p, w) for p, w in zip(parts, ("start", "stop", "step")))
        if step <= 0:
            raise SweepInputError(f"--thickness: step must be > 0 in {text!r}")
        if stop < start:
            raise SweepInputError(
                f"--thickness: empty grid, stop {stop} < start {start} in {text!r}"
            )
        n = int((stop - start) / step)  # exact decimal arithmetic: floor
        values = [float(round(start + i * step, _THICKNESS_DECIMALS)) for i in range(n + 1)]
    else:
        items = [p for p in text.split(",") if p.strip()]
        if not items:
            raise SweepInputError(f"--thickness: empty grid in {text!r}")
        values = [float(round(_dec(p, "value"), _THICKNESS_DECIMALS)) for p in items]
    return _unique(values)


def parse_materials(text: str | Iterable[str]) -> list[str]:
    """Parse a ``--material`` value such as ``"mr,nh,le"``.

    Parameters
    ----------
    text : str or iterable of str
        Comma-separated material keys (case-insensitive) or a list of them.

    Returns
    -------
    list of str
        Lower-case keys in given order, duplicates removed.

    Raises
    ------
    SweepInputError
        If empty or if a key is not one of :data:`KNOWN_MATERIALS` (the message lists them).
    """
    items = text.split(",") if isinstance(text, str) else list(text)
    mats = _unique(str(m).strip().lower() for m in items if str(m).strip())
    if not mats:
        raise SweepInputError(
            f"--material: empty list; valid materials: {', '.join(KNOWN_MATERIALS)}"
        )
    bad = [m for m in mats if m not in KNOWN_MATERIALS]
    if bad:
        raise SweepInputError(
            f"--material: unknown material {', '.join(map(repr, bad))}; "
            f"valid materials: {', '.join(KNOWN_MATERIALS)}"
        )
    return mats


# --------------------------------------------------------------------------- grid


def spec_defaults() -> dict[str, Any]:
    """Default values of the scalar :class:`~grasprom.fe.model2d.CaseSpec` and
    :class:`~grasprom.fe.model2d.MeshSpec` fields (the single source of CLI defaults).

    Returns
    -------
    dict
        E.g. ``{"diameter_mm": 30.0, ..., "n_layers": 2, "n_circ": 48}``.
    """
    out: dict[str, Any] = {}
    for cls in (CaseSpec, MeshSpec):
        for f in dataclasses.fields(cls):
            if f.default is not dataclasses.MISSING:
                out[f.name] = f.default
    return out


def check_out_dir(out_dir: str | os.PathLike[str]) -> Path:
    """Create ``out_dir`` if needed and check that files can be written in it.

    Returns
    -------
    pathlib.Path
        The directory.

    Raises
    ------
    SweepInputError
        Naming the directory, if it cannot be created or written.
    """
    d = Path(out_dir)
    if d.exists() and not d.is_dir():
        raise SweepInputError(f"--out: {d} exists and is not a directory")
    try:
        d.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=d, prefix=".write-probe.", suffix=".tmp")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise SweepInputError(
            f"--out: output directory {d} is not writable ({exc.strerror or exc})"
        ) from None
    return d


def _positive(name: str, value: float | None) -> None:
    if value is None:
        return
    try:
        ok = math.isfinite(float(value)) and float(value) > 0
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise SweepInputError(f"{name}: must be a positive number, got {value!r}")


def build_grid(
    thickness: str | Iterable[float],
    materials: str | Iterable[str],
    *,
    diameter_mm: float | None = None,
    jaw_length_mm: float | None = None,
    closed_gap_mm: float | None = None,
    force_cap_N: float | None = None,
    n_layers: int | None = None,
    n_circ: int | None = None,
    out_dir: str | os.PathLike[str] | None = None,
) -> list[CaseSpec]:
    """Build and validate the thickness x material grid of cases.

    Parameters
    ----------
    thickness : str or iterable of float
        Wall thicknesses in mm, or a ``--thickness`` string (see :func:`parse_thickness`).
    materials : str or iterable of str
        Material keys or a ``--material`` string (see :func:`parse_materials`).
    diameter_mm, jaw_length_mm, closed_gap_mm : float, optional
        Outer tube diameter, jaw length along the tube axis (out-of-plane depth) and
        closed jaw gap, in mm; None takes the :class:`~grasprom.fe.model2d.CaseSpec` default.
    force_cap_N : float, optional
        Jaw force in N at which a case stops; None takes the default.
    n_layers, n_circ : int, optional
        Mesh divisions through the wall / along the quarter circumference; None takes the
        :class:`~grasprom.fe.model2d.MeshSpec` default.
    out_dir : str or os.PathLike, optional
        If given, created if needed and checked for writability.

    Returns
    -------
    list of CaseSpec
        Ordered by material, then thickness.

    Raises
    ------
    SweepInputError
        With a message naming the offending option (``--thickness``, ``--material``,
        ``--diameter``, ``--jaw-length``, ``--closed-gap``, ``--force-cap``, ``--n-layers``,
        ``--n-circ``, ``--out``) and value.
    """
    t_list = (
        parse_thickness(thickness)
        if isinstance(thickness, str)
        else _unique(round(float(t), _THICKNESS_DECIMALS) for t in thickness)
    )
    mats = parse_materials(materials)
    if not t_list:
        raise SweepInputError("--thickness: empty grid")
    for name, v in (
        ("--diameter", diameter_mm),
        ("--jaw-length", jaw_length_mm),
        ("--closed-gap", closed_gap_mm),
        ("--force-cap", force_cap_N),
    ):
        _positive(name, v)
    for name, v in (("--n-layers", n_layers), ("--n-circ", n_circ)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 1):
            raise SweepInputError(f"{name}: must be a positive integer, got {v!r}")

    kw = {
        k: float(v)
        for k, v in (
            ("diameter_mm", diameter_mm),
            ("jaw_length_mm", jaw_length_mm),
            ("closed_gap_mm", closed_gap_mm),
            ("force_cap_N", force_cap_N),
        )
        if v is not None
    }
    mesh_kw = {k: v for k, v in (("n_layers", n_layers), ("n_circ", n_circ)) if v is not None}
    defaults = spec_defaults()
    diameter = kw.get("diameter_mm", defaults["diameter_mm"])
    radius = diameter / 2.0
    closed_gap = kw.get("closed_gap_mm", defaults["closed_gap_mm"])
    if closed_gap >= diameter:
        raise SweepInputError(
            f"--closed-gap: {closed_gap:g} mm must be smaller than the tube diameter "
            f"{diameter:g} mm"
        )
    for t in t_list:
        if not math.isfinite(t) or t <= 0:
            raise SweepInputError(f"--thickness: wall thickness must be > 0 mm, got {t:g}")
        if t >= radius:
            raise SweepInputError(
                f"--thickness: wall thickness {t:g} mm must be smaller than the outer radius "
                f"{radius:g} mm (diameter {diameter:g} mm)"
            )
    mesh = MeshSpec(**mesh_kw)
    specs = [CaseSpec(material=m, thickness_mm=t, mesh=mesh, **kw) for m in mats for t in t_list]
    stems = [df.spec_stem(s) for s in specs]
    if len(set(stems)) != len(stems):
        raise SweepInputError(
            "--thickness: values closer than 0.01 mm map to the same case file name"
        )
    if out_dir is not None:
        check_out_dir(out_dir)
    return specs


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
    out = check_out_dir(out_dir)

    # Validate everything on disk before computing anything.
    status: dict[str, str | None] = {
        stem: _existing_status(out, s) for stem, s in zip(stems, specs)
    }
    try:
        df.write_manifest(out, specs)
    except ValueError as exc:
        raise SweepInputError(f"--out: {exc}") from None

    skipped = [stem for stem in stems if status[stem] is not None]
    todo = [i for i, stem in enumerate(stems) if status[stem] is None]
    # longest first (thin walls take the most load steps): less idle time at the end
    todo.sort(key=lambda i: (specs[i].thickness_mm, i))
    prov = df.provenance()
    done: list[str] = []
    failed: list[tuple[str, str]] = []

    def handle(outcome: _Outcome) -> None:
        spec = specs[outcome.index]
        stem = stems[outcome.index]
        if outcome.result is not None:
            try:
                df.write_case(out, spec, outcome.result, wall_time_s=outcome.wall_time_s, prov=prov)
            except ValueError as exc:
                outcome = dataclasses.replace(
                    outcome,
                    result=None,
                    error=f"invalid result: {exc}",
                    traceback=traceback.format_exc(),
                )
            else:
                status[stem] = outcome.result.status
                done.append(stem)
                err = out / f"{stem}{df.ERROR_SUFFIX}"
                if err.exists():  # stale record of an earlier failure
                    err.unlink()
                return
        msg = outcome.error or "unknown error"
        df.write_error(out, stem, msg, outcome.traceback or "")
        failed.append((stem, msg))

    bar = _progress_bar(len(specs), len(skipped), progress)
    try:
        if todo:
            if scheduler is not None:
                _run_dask(scheduler, runner, specs, todo, handle, bar, scheduler_timeout_s)
            elif workers == 1:
                for i in todo:
                    handle(execute_case(runner, i, specs[i]))
                    bar.update(1)
            else:
                _run_pool(workers, runner, specs, todo, handle, bar)
    finally:
        bar.close()

    order = {s: k for k, s in enumerate(stems)}
    summary = SweepSummary(
        out_dir=out,
        total=len(specs),
        done=tuple(sorted(done, key=order.__getitem__)),
        skipped=tuple(skipped),
        failed=tuple(sorted(failed, key=lambda f: order[f[0]])),
        partial=tuple(s for s in stems if status[s] == "partial"),
        wall_time_s=time.perf_counter() - t_start,
    )
    df.write_manifest(
        out,
        specs,
        last_run={
            "finished": df.now_iso(),
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
    return summary


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


def _collect(fut, index: int) -> _Outcome:
    """The outcome of a finished future; a lost worker becomes a failed case."""
    try:
        return fut.result()
    except Exception as exc:  # noqa: BLE001 - e.g. a worker process died or lost the task
        return _Outcome(
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
