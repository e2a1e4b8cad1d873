"""Fit the calibration of the diagnosis' confidence on blind-benchmark results.

Reads the ``--json`` results of ``benchmarks/bench_diagnosis.py`` runs, fits the Platt map
``1 / (1 + exp(-(a + b c)))`` of the raw confidence ``c`` (``confidence_raw`` of the
``explained`` verdicts) to their observed accuracy (the exact truth set; out-of-library: always
wrong) by maximum likelihood, and prints ``(a, b)`` with the expected calibration error of every
file before (the confidences the runs stated) and after (the map applied to their raw
confidence).  Fit on one seed, check on another::

    python benchmarks/fit_confidence.py --fit ideal.json realistic.json \
        --check seed2025.json

Apply the printed pair as :data:`grasprom.gap.criteria.CONFIDENCE_PLATT`.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_diagnosis import calibration, summarise  # noqa: E402


def explained_rows(results: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """Raw confidence and correctness (1 = exact truth set) of the ``explained`` verdicts."""
    rows = [r for r in results if r["label"] == "explained" and r.get("confidence_raw") is not None]
    c = np.array([float(r["confidence_raw"]) for r in rows])
    ok = np.array(
        [
            r["kind"] in ("single", "pair") and sorted(r["predicted"]) == sorted(r["effects"])
            for r in rows
        ],
        dtype=float,
    )
    return c, ok


def fit_platt(c: np.ndarray, ok: np.ndarray) -> tuple[float, float]:
    """Maximum-likelihood ``(a, b)`` of ``P(correct) = 1 / (1 + exp(-(a + b c)))``."""

    def nll(ab: np.ndarray) -> float:
        z = ab[0] + ab[1] * c
        return float(np.sum(np.logaddexp(0.0, z) - ok * z))

    res = minimize(nll, np.array([0.0, 1.0]), method="Nelder-Mead", options={"xatol": 1e-6})
    return float(res.x[0]), float(res.x[1])


def rescored(results: list[dict], ab: tuple[float, float]) -> list[dict]:
    """The results with the confidence of ``explained`` verdicts re-mapped by ``ab`` (capped
    at 0.3 for a single trial, as :func:`grasprom.gap.verdict.calibrated`)."""
    out = []
    for r in results:
        if r["label"] == "explained" and r.get("confidence_raw") is not None:
            conf = 1.0 / (1.0 + math.exp(-(ab[0] + ab[1] * float(r["confidence_raw"]))))
            r = {**r, "confidence": conf}
        out.append(r)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--fit", nargs="+", required=True, help="benchmark --json files to fit on")
    p.add_argument("--check", nargs="*", default=[], help="files to check the map on")
    args = p.parse_args(argv)
    data = {f: json.loads(Path(f).read_text()) for f in [*args.fit, *args.check]}
    rows = [explained_rows(data[f]) for f in args.fit]
    c = np.concatenate([r[0] for r in rows])
    ok = np.concatenate([r[1] for r in rows])
    ab = fit_platt(c, ok)
    print(f"Platt (a, b) = ({ab[0]:.4f}, {ab[1]:.4f}) from {c.size} explained verdicts")
    for f, res in data.items():
        role = "fit" if f in args.fit else "check"
        before = 100 * calibration(res)["ece"]
        s = summarise(rescored(res, ab))
        neg = s["fresh_negative_conf_ge_0.5"]
        print(
            f"  {role:5s} {f}: ECE {before:.1f} points as run, "
            f"{100 * s['calibration']['ece']:.1f} with the new map; fresh shrink < 0 at "
            f"confidence >= 0.5 with the new map: {len(neg)} {neg}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
