"""Residual statistics of the report: RMS, bias and share of the total sum of squares, overall
and grouped by a per-sample label (phase, direction)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from grasprom.gap.trials import FloatArray


def residual_stats(r: FloatArray, total_ss: float) -> dict[str, float]:
    """``rms_N`` (N), ``bias_N`` (N), ``share`` of ``total_ss`` (N^2) and ``n`` of residuals."""
    if r.size == 0:
        return {"rms_N": None, "bias_N": None, "share": 0.0, "n": 0}  # type: ignore[dict-item]
    ss = float(r @ r)
    return {
        "rms_N": float(math.sqrt(ss / r.size)),
        "bias_N": float(r.mean()),
        "share": float(ss / total_ss) if total_ss > 0 else 0.0,
        "n": int(r.size),
    }


def stats_by_label(
    res: Sequence[FloatArray], labels: Sequence[NDArray[np.int_]], names: Sequence[str]
) -> dict[str, dict[str, float]]:
    """:func:`residual_stats` per label value ``k`` (named ``names[k]``) over all trials."""
    r = np.concatenate(res)
    lab = np.concatenate(labels)
    tot = float(r @ r)
    return {name: residual_stats(r[lab == k], tot) for k, name in enumerate(names)}


def rms(res: Sequence[FloatArray]) -> float:
    """RMS (N) of the residuals of all trials."""
    r = np.concatenate(res)
    return float(math.sqrt(r @ r / r.size))
