"""The crease band's selection for the cases of a finished 3D sweep, without running them again.

A sweep run with ``--band-companion K`` runs each case and then its companion
(:func:`grasprom.fe.bandselect.run_case_3d_selected`).  Its first half, the case's own run, is
exactly a case of the same sweep without the companion, so when such a sweep is on disk
(the shipped ``fe_data/default``) only the second half needs running:
:func:`grasprom.fe.bandselect.select_band` on the stored table.  :class:`StoredOwnRuns` is the
sweep runner that does it (``grasprom sweep --band-companion K --select-from DIR``): the cases
it writes are those of ``--band-companion K`` (same input hash, same rows), with the own run's
wall time added to the selection's and its provenance kept in ``fe_info.own_run``.

The own run is taken only if its sidecar's input hash is that of the case with
``band_companion`` 0 (:func:`grasprom.fe.bandselect.own_run_spec`): same material, geometry,
mesh and solver settings.
Its rows are the stored ones, whatever revision of the code computed them (``fe_info.own_run``
records it): they equal a fresh run's when that revision's solution path is the current one
(``fe_info.solver_rules``, absent from sidecars written before it).  The selection itself
compares equilibria of one mesh and one set of equations, which holds for any such rows.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

from grasprom.fe import datafiles as df
from grasprom.fe.bandselect import own_run_spec, select_band
from grasprom.fe.grid import SweepInputError
from grasprom.fe.model2d import CaseResult
from grasprom.fe.model3d import CaseSpec3D
from grasprom.fe.sweep import PRIOR_WALL_TIME_KEY

__all__ = ["StoredOwnRuns", "check_own_runs", "read_own_run"]

#: Sidecar keys of the own run kept in ``fe_info.own_run`` of a case selected from it.
OWN_RUN_KEYS = ("git_revision", "git_dirty", "written_at", "versions", "wall_time_s")


def read_own_run(spec: CaseSpec3D, source: str | os.PathLike[str]) -> df.LoadedCase:
    """The stored own run of ``spec`` in the sweep directory ``source``.

    Parameters
    ----------
    spec : CaseSpec3D
        The case (any ``band_companion``).
    source : str or os.PathLike
        A sweep directory holding the case run without the companion.

    Returns
    -------
    LoadedCase

    Raises
    ------
    SweepInputError
        The case is not in ``source`` or was computed there with other inputs (the message
        names the differing parameters).
    grasprom.fe.CorruptCaseError
        Its files are unreadable or inconsistent.
    """
    own = own_run_spec(spec)
    files = df.case_files(source, df.spec_stem(own))
    if not files.json.exists():
        raise SweepInputError(f"--select-from: no case {files.json.name} in {source}")
    case = df.read_case(files.json)
    differs = df.input_mismatch(case.meta, own)
    if differs is not None:
        raise SweepInputError(
            f"--select-from: {files.json} was computed with other inputs ({differs}; file != "
            "this run)"
        )
    return case


def check_own_runs(specs, source: str | os.PathLike[str]) -> None:
    """:func:`read_own_run` of every case, before anything runs.

    Parameters
    ----------
    specs : sequence of CaseSpec3D
        The sweep's cases, each with ``solver.band_companion`` >= 1.
    source : str or os.PathLike
        The sweep directory of their own runs.

    Raises
    ------
    SweepInputError
        A 2D case or one without a companion; or every case :func:`read_own_run` refuses,
        one line each.
    """
    problems = []
    for spec in specs:
        if not isinstance(spec, CaseSpec3D) or spec.solver.band_companion < 1:
            raise SweepInputError(
                "--select-from: needs --model 3d and --band-companion K >= 1 (it adds the "
                "companion's selection to stored runs; --mesh converged, the default, has 2 unless "
                "a mesh option overrides it)"
            )
        try:
            read_own_run(spec, source)
        except SweepInputError as exc:
            problems.append(str(exc))
    if problems:
        raise SweepInputError("\n".join(problems))


@dataclass(frozen=True)
class StoredOwnRuns:
    """Sweep runner (:func:`grasprom.fe.sweep.run_sweep`): a case's own run read from
    ``source``, then :func:`grasprom.fe.bandselect.select_band`.  Picklable (process pools,
    Dask).

    Attributes
    ----------
    source : str
        The sweep directory of the own runs (:func:`read_own_run`).
    solver : str
        Sparse solver of the companion and the moves.
    band : (float, float), optional
        ``(lowest, highest)`` jaw gap (mm) of the band; default ``(2 t, 4 t)``.
    """

    source: str
    solver: str = "auto"
    band: tuple[float, float] | None = None

    def __call__(self, spec: CaseSpec3D) -> CaseResult:
        """The case with the band's selection.

        Parameters
        ----------
        spec : CaseSpec3D
            The case, ``solver.band_companion`` >= 1.

        Returns
        -------
        CaseResult
            As :func:`grasprom.fe.bandselect.select_band` of the stored own run (its
            ``fe_info``, with ``own_wall_time_s`` its ``fe_info.wall_time_s``), with
            ``own_run`` (``source`` and :data:`OWN_RUN_KEYS` of its sidecar) and
            :data:`grasprom.fe.sweep.PRIOR_WALL_TIME_KEY`, the own run's wall time (s), which
            the sweep adds to this call's.

        Raises
        ------
        SweepInputError, grasprom.fe.CorruptCaseError
            As :func:`read_own_run`.
        """
        case = read_own_run(spec, self.source)
        meta = case.meta
        info: dict[str, Any] = dict(meta.get("fe_info") or {})
        outer = float(meta.get("wall_time_s") or 0.0)
        info["wall_time_s"] = float(info.get("wall_time_s") or outer)
        own = CaseResult(table=case.table, status=str(meta["status"]), info=info)
        out = select_band(spec, own, self.solver, self.band)
        kept = {k: meta.get(k) for k in OWN_RUN_KEYS}
        record = {**out.info, "own_run": {"source": str(self.source), **kept}}
        record[PRIOR_WALL_TIME_KEY] = outer
        return CaseResult(table=out.table, status=out.status, info=record)
