"""The driver of the main job: :func:`run_build` runs the stages in order, reports progress,
times them and turns a failure into a :class:`~grasprom.pipeline.options.StageError` after
writing a partial report."""

from __future__ import annotations

import datetime as _dt
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TextIO

from grasprom.paths import resolve_data_dir
from grasprom.pipeline.options import BuildOptions, StageError
from grasprom.pipeline.report import write_report
from grasprom.pipeline.result import BuildResult
from grasprom.pipeline.stages import STAGE_FUNCS, STAGES


def run_build(
    opts: BuildOptions,
    *,
    progress: TextIO | None = sys.stderr,
    stages: Sequence[str] = STAGES,
) -> BuildResult:
    """Run the main job; see the :mod:`grasprom.pipeline` docstring.

    Parameters
    ----------
    opts : BuildOptions
    progress : text stream or None
        Where the per-stage progress lines go (stage name, wall time); None for quiet.
    stages : sequence of str
        Stages to run (default all, in order; a later stage needs the earlier ones).

    Returns
    -------
    BuildResult

    Raises
    ------
    StageError
        A stage failed; its ``stage`` attribute names it.  Files of earlier stages are kept
        and a partial report is written (best effort).
    """
    out = Path(opts.out_dir)
    res = _start_result(opts, out)
    t_all = time.perf_counter()
    figs = out / "figures"
    todo = [s for s in STAGES if s in stages]
    for i, name in enumerate(todo, 1):
        _say(progress, f"[{i}/{len(todo)}] {name} ...")
        t0 = time.perf_counter()
        try:
            out.mkdir(parents=True, exist_ok=True)
            figs.mkdir(exist_ok=True)
            STAGE_FUNCS[name](opts, res, out, figs)
        except KeyboardInterrupt:
            raise
        except Exception as exc:  # noqa: BLE001 - every failure is reported with its stage
            _record_failure(res, opts, name, exc, t_all)
            raise StageError(name, res.error) from exc
        res.stage_times_s[name] = time.perf_counter() - t0
        _say(progress, f"[{i}/{len(todo)}] {name} done in {res.stage_times_s[name]:.1f} s")
    res.total_s = time.perf_counter() - t_all
    if "report" in todo:  # rewrite build.json with the report stage's time included
        write_report(res, opts)
    return res


def _start_result(opts: BuildOptions, out: Path) -> BuildResult:
    """Empty result of a build into ``out``: start time, resolved FE and held-out directories."""
    res = BuildResult(out_dir=out)
    res.started = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    res.fe_dir = resolve_data_dir(opts.fe_dir)
    if opts.holdout_dir is not None:
        hd = resolve_data_dir(opts.holdout_dir)
        res.holdout_dir = hd if hd.is_dir() else None
        if res.holdout_dir is None:
            res.notes.append(f"held-out FE directory {opts.holdout_dir} not found: "
                             "held-out error not computed")  # fmt: skip
    return res


def _record_failure(
    res: BuildResult, opts: BuildOptions, name: str, exc: Exception, t_all: float
) -> None:
    """Record the failure of stage ``name`` in ``res`` and write the partial report.

    Parameters
    ----------
    res : BuildResult
    opts : BuildOptions
    name : str
        The failed stage.
    exc : Exception
        Its error.
    t_all : float
        ``time.perf_counter()`` at the start of the build, s.
    """
    res.failed_stage = name
    res.error = f"{type(exc).__name__}: {exc}".strip()
    res.total_s = time.perf_counter() - t_all
    if name != "report":
        try:
            write_report(res, opts)
        except Exception:  # noqa: BLE001 - the partial report is best effort
            pass


def _say(progress: TextIO | None, msg: str) -> None:
    """Print a progress line to ``progress`` (nothing when None)."""
    if progress is not None:
        print(msg, file=progress, flush=True)
