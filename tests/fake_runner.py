"""Fast fake FE runners for sweep tests (module-level, hence picklable).

They return a deterministic analytic force-gap table shaped like a real case: a soft
bending regime, then a steep rise once the gap is below twice the wall thickness.
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from grasprom.fe import CaseResult, CaseSpec

FAIL_THICKNESS_MM = 1.0
"""Thickness at which :func:`failing_runner` raises."""


def fake_result(spec: CaseSpec, n_steps: int = 12) -> CaseResult:
    """Analytic stand-in for :func:`grasprom.fe.model2d.run_case` (mm, N, MPa)."""
    d, t, length = spec.diameter_mm, spec.thickness_mm, spec.jaw_length_mm
    gap = np.linspace(d, spec.closed_gap_mm, n_steps)
    disp = (d - gap) / 2.0
    stiff = {"mr": 1.0, "nh": 1.02, "le": 3.0}[spec.material]
    f_len = stiff * 0.05 * t**3 * disp / (d / 2.0) ** 2
    f_len += np.where(gap < 2 * t, stiff * 2.0 * (2 * t - gap) ** 2, 0.0)
    force = f_len * length
    table = pd.DataFrame(
        {
            "gap_mm": gap,
            "jaw_displacement_mm": disp,
            "force_N": force,
            "force_per_length_N_per_mm": f_len,
            "contact_width_mm": np.minimum(disp, d / 2.0),
            "peak_pressure_MPa": f_len / np.maximum(disp, 1e-3),
            "min_J": 1.0 - 0.01 * disp / d,
            "newton_iterations": np.full(n_steps, 3),
        }
    )
    info = {
        "steps": n_steps,
        "newton_iterations": int(3 * n_steps),
        "failures": 0,
        "last_gap_mm": float(gap[-1]),
        "dofs": 100,
        "material_constants": {"fake": True, "stiffness": stiff},
    }
    return CaseResult(table=table, status="complete", info=info)


def fast_runner(spec: CaseSpec) -> CaseResult:
    """Instant fake case."""
    return fake_result(spec)


def sleepy_runner(spec: CaseSpec) -> CaseResult:
    """Fake case taking 0.2 s."""
    time.sleep(0.2)
    return fake_result(spec)


def slow_runner(spec: CaseSpec) -> CaseResult:
    """Fake case taking 0.5 s (kill test)."""
    time.sleep(0.5)
    return fake_result(spec)


def failing_runner(spec: CaseSpec) -> CaseResult:
    """Raise for ``thickness_mm == FAIL_THICKNESS_MM``, else a fake case."""
    if abs(spec.thickness_mm - FAIL_THICKNESS_MM) < 1e-9:
        raise RuntimeError(f"fake divergence at t={spec.thickness_mm} mm")
    return fake_result(spec)


def partial_runner(spec: CaseSpec) -> CaseResult:
    """Fake case that stops early with status 'partial'."""
    r = fake_result(spec)
    return CaseResult(table=r.table.iloc[:6].reset_index(drop=True), status="partial", info=r.info)


class CountingRunner:
    """In-process runner (use with ``workers=1``) recording the stems it ran."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, float]] = []

    def __call__(self, spec: CaseSpec) -> CaseResult:
        self.calls.append((spec.material, spec.thickness_mm))
        return fake_result(spec)


def env_runner(spec: CaseSpec) -> CaseResult:
    """Fake case recording the worker's BLAS thread variables in its info."""
    import os

    r = fake_result(spec)
    names = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
    return CaseResult(r.table, r.status, {**r.info, "env": {k: os.environ.get(k) for k in names}})
