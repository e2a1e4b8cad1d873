"""Blind benchmark of the sim-to-real gap diagnosis (issue 7).

Random cases over every library effect alone, every pair, null cases (noise only) and an effect
outside the library (motor cogging ripple): 116 cases by default (the first 102 as before the
``sensor_drift`` candidate, then its 6 singles and 8 pairs, :data:`ADDED_EFFECTS`).  Each
case: :func:`grasprom.gap.synth.synth_case` makes ``--trials`` "real" trials with the effect
identities withheld; :func:`grasprom.gap.diagnosis.diagnose` sees only the trial tables and
sidecars.  Prints the
confusion matrix, top-1 accuracy, median
held-out shrink, null -> none rate, the verdicts on out-of-library cases and the block
attribution of single-effect cases (``where.block`` vs the block of the truth effect,
:data:`grasprom.gap.EFFECTS`), with its 3 x 3 confusion matrix.

``--gap-channel`` gives every trial the measured jaw gap ``gap_mm`` as well
(``synth_case(gap_channel=True)``: kinematic gap after the truth play + truth jaw deflection +
5-10 um rms noise from its own random stream, so every other value of every case is the same as
without it); the block analysis then splits gap and force law from the measured gap instead of
fitting candidates to the jaw channel.

``--acquisition`` records the trials as :data:`ACQUISITIONS` says; ``2khz`` synthesises them at
2 kHz (``synth_case(rate_hz=2000)``: the same truth and trial conditions as at 1 kHz, sensor
noise independent at every sample) -- until this version it interpolated the 1 kHz trials,
whose added midpoints carry no noise of their own (the diagnosis' noise estimate, the median
absolute second difference, then collapsed and every null case read as a significant gap).

Usage::

    python benchmarks/bench_diagnosis.py [--seed 2024] [--per-effect 6] [--null 14] \
        [--ool 12] [--trials 4] [--workers 2] [--gap-channel] [--json results.json] \
        [--acquisition ideal|coarse|jitter|500hz|2khz|realistic] [--tremor DEG] [--fe DIR]

About 5-7 minutes with ``--workers 1`` for the default 116 cases (280-360 s measured for
``ideal`` and ``realistic`` since the interval likelihood of the encoder quantum, which
evaluates every model at both ends of the resting levels; 103-108 s before).
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import sys
import time
import warnings
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from grasprom.gap import LIBRARY_EFFECTS, OUT_OF_LIBRARY_EFFECTS  # noqa: E402

_SURROGATES: dict = {}  # per FE sweep directory, built once per process


def _surrogate(fe: str | None = None):
    """The surrogate the cases are synthesised and diagnosed with: built from the FE sweep
    ``fe`` (default the shipped ``fe_data/default``)."""
    path = Path(fe) if fe else ROOT / "fe_data" / "default"
    if path not in _SURROGATES:
        from grasprom.surrogate import Surrogate

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            _SURROGATES[path] = Surrogate.build(path)
    return _SURROGATES[path]


ADDED_EFFECTS = ("sensor_drift",)
"""Library effects added after the benchmark's first 102-case version: their cases (singles,
then the pairs with every earlier effect) come after all the others, so that the earlier cases
keep their seeds and stay comparable with earlier figures."""


def case_list(seed: int, per_effect: int, n_null: int, n_ool: int) -> list[dict]:
    """The benchmark cases: effects (truth), seed and kind (see :data:`ADDED_EFFECTS`)."""
    cases = []
    k = 0
    first = [e for e in LIBRARY_EFFECTS if e not in ADDED_EFFECTS]
    for e in first:
        for _ in range(per_effect):
            cases.append({"effects": [e], "kind": "single"})
    for a, b in itertools.combinations(first, 2):
        cases.append({"effects": [a, b], "kind": "pair"})
    for _ in range(n_null):
        cases.append({"effects": [], "kind": "null"})
    for i in range(n_ool):
        cases.append(
            {
                "effects": [OUT_OF_LIBRARY_EFFECTS[i % len(OUT_OF_LIBRARY_EFFECTS)]],
                "kind": "out_of_library",
            }
        )
    added = [e for e in LIBRARY_EFFECTS if e in ADDED_EFFECTS]
    for e in added:
        cases += [{"effects": [e], "kind": "single"} for _ in range(per_effect)]
        earlier = LIBRARY_EFFECTS[: LIBRARY_EFFECTS.index(e)]
        cases += [{"effects": [a, e], "kind": "pair"} for a in earlier]
    for c in cases:
        c["seed"] = seed * 1000 + k
        k += 1
    return cases


ACQUISITIONS = ("ideal", "coarse", "jitter", "500hz", "2khz", "realistic")
"""Acquisition conditions of the synthetic trials (``--acquisition``): ``ideal`` the 1 kHz
trials as synthesised, ``coarse`` a 0.1 deg angle encoder, ``jitter`` time stamps jittered by
+-30 % of the sample period, ``500hz`` every second sample of the 1 kHz trial (a slower
acquisition), ``2khz`` trials synthesised at 2 kHz (:data:`SYNTH_RATE_HZ`: same truth and
conditions, sensor noise independent at every sample; no interpolation), ``realistic`` coarse
+ jitter + 500 Hz."""

SYNTH_RATE_HZ = {"2khz": 2000.0}
"""Sample rate (Hz) the trials of an acquisition mode are synthesised at (1000 Hz if absent)."""


def synth_rate_hz(mode: str) -> float:
    """Sample rate (Hz) at which :func:`run_case` synthesises the trials of acquisition ``mode``."""
    return SYNTH_RATE_HZ.get(mode, 1000.0)


def acquire(df, mode: str, rng: np.random.Generator):
    """A synthetic trial (synthesised at :func:`synth_rate_hz` of ``mode``) as an acquisition
    ``mode`` would record it (see :data:`ACQUISITIONS`)."""
    if mode == "ideal":
        return df
    t = df["time_s"].to_numpy()
    dt = float(np.median(np.diff(t)))
    if abs(dt * synth_rate_hz(mode) - 1.0) > 1e-3:
        raise ValueError(
            f"acquisition {mode!r} takes a trial synthesised at {synth_rate_hz(mode):g} Hz, "
            f"got one at {1.0 / dt:g} Hz"
        )
    if mode in ("500hz", "realistic"):
        df = df.iloc[:: max(int(round(0.002 / dt)), 1)].reset_index(drop=True)
    if mode in ("coarse", "realistic"):
        df = df.assign(theta_deg=np.round(df["theta_deg"].to_numpy() / 0.1) * 0.1)
    if mode in ("jitter", "realistic"):
        tt = df["time_s"].to_numpy()
        step = float(np.median(np.diff(tt)))
        df = df.assign(time_s=tt + rng.uniform(-0.3, 0.3, tt.size) * step)
    return df


def run_case(case: dict, n_trials: int = 4, gap_channel: bool = False,
             acquisition: str = "ideal", tremor_deg: float = 0.0) -> dict:  # fmt: skip
    """Synthesise and diagnose one case; returns truth, verdict and timing.

    ``gap_channel`` adds the measured jaw gap ``gap_mm`` to the synthetic trials;
    ``acquisition`` sets their sample rate (:func:`synth_rate_hz`) and records them as
    :func:`acquire` says, the fresh trial too; ``tremor_deg`` adds hand tremor (deg RMS,
    6-12 Hz) to the handle angle.
    """
    from grasprom.chain import kinematics as kin
    from grasprom.gap import diagnose, synth_case, validate_trial

    s = _surrogate(case.get("fe"))
    chain = kin.ChainParams()
    t0 = time.perf_counter()
    # one trial more than diagnosed: the fresh trial of fresh_trial_shrink (the first
    # n_trials are the same with or without it: the trials draw from their streams in turn)
    sc = synth_case(
        case["effects"],
        seed=case["seed"],
        surrogate=s,
        n_trials=n_trials + 1,
        gap_channel=gap_channel,
        tremor_deg=tremor_deg,
        rate_hz=synth_rate_hz(acquisition),
    )
    *seen, unseen = sc.trials
    rng = np.random.default_rng(case["seed"] + 17)
    trials = [
        validate_trial(
            acquire(t.data, acquisition, rng), t.sidecar, f"case{case['seed']}_{i}", chain, s
        )  # fmt: skip
        for i, t in enumerate(seen)
    ]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = diagnose(trials, s, chain)
    v = d.report["verdict"]
    fresh, fresh_g, fresh_u = (
        _fresh_shrinks(unseen, case["seed"], acquisition, d.augmented, case.get("fe"))
        if v["label"] == "explained" and d.augmented is not None
        else (None, None, None)
    )
    return {
        **case,
        **({"gap_channel": True} if gap_channel else {}),
        "truth_params": sc.truth["effects"],
        "label": v["label"],
        "predicted": v["effects"],
        "best_candidate": v["best_candidate"],
        "confidence": v["confidence"],
        "confidence_raw": v.get("confidence_raw"),
        "message": v["message"],
        "shrink_by_phase": v.get("shrink_by_phase"),
        "shrink": v["shrink"],
        "shrink_rms": v["shrink_rms"],
        "explained_share": v["explained_share"],
        "systematic_ratio": d.report["baseline"]["systematic_ratio"],
        "rms_before_N": v["heldout_rms_before_N"],
        "rms_after_N": v["heldout_rms_after_N"],
        "where": d.report["where"],
        "by_block": d.report["baseline"]["by_block"],
        "fresh_shrink": fresh,
        "fresh_shrink_gaussian": fresh_g,
        "fresh_shrink_unfloored": fresh_u,
        "seconds": time.perf_counter() - t0,
    }


def fresh_trial_shrink(unseen, seed: int, acquisition: str, augmented: dict) -> float:
    """Independently measured shrink: the augmented model against the baseline on one more
    trial of the same truth (``unseen``, the synthetic trial after the diagnosed ones of the
    case ``seed``, synthesised at the same rate and recorded with the same ``acquisition``),
    weighted as the diagnosis weighs its samples (:mod:`grasprom.gap.likelihood`):
    ``1 - sqrt(max(S_aug, 0) / S_base)``, ``S`` the systematic chi2 ``sum z^2 - sum E[z^2]``
    on the analysis grid, where the angle rests in
    an encoder level the residual counted beyond the force range of both models over the level
    (``AugmentedModel.handle_force_N`` at the level's ends), elsewhere ``r / sigma``; the models
    see the angle reconstructed between the encoder counts (as the diagnosis): < 0 when the
    augmented model predicts the new trial worse than the baseline.

    The baseline's ``S`` is floored at the significance level ``SIGNIFICANT_RHO x N`` (N
    samples; as the diagnosis' :func:`grasprom.gap.verdict.gap_left`: below it a gap is not told
    from the noise), and the shrink is NaN when neither model leaves a significant gap on the
    fresh trial: there is then nothing to shrink, and a ratio of two noise-level figures (39
    against 245 on a trial of 565 samples) would read as a large negative shrink.  It is
    negative when the augmented model leaves a significant gap larger than the baseline's.  The
    unfloored figure is kept as ``fresh_shrink_unfloored``.  See
    :func:`fresh_trial_shrink_gaussian` for the figure of earlier versions."""
    return _fresh_shrinks(unseen, seed, acquisition, augmented)[0]


def fresh_trial_shrink_gaussian(unseen, seed: int, acquisition: str, augmented: dict) -> float:
    """:func:`fresh_trial_shrink` as measured before the interval likelihood: the models at the
    recorded angle, every residual weighted by the Gaussian sigma (sensor noise, the angle
    quantum through the local stiffness, 1 % of the force) with ``S = chi2 - N``.  At rests the
    level's centre is then taken for the true angle: half a count of a 0.1 deg encoder is tens
    of N on the wall-contact rise."""
    return _fresh_shrinks(unseen, seed, acquisition, augmented)[1]


def _fresh_shrinks(
    unseen, seed: int, acquisition: str, augmented: dict, fe: str | None = None
) -> tuple[float, float, float]:
    """(interval-likelihood floored at the significance level, Gaussian, interval-likelihood
    unfloored) fresh-trial shrink of :func:`fresh_trial_shrink` (surrogate of the FE sweep
    ``fe``, default ``fe_data/default``)."""
    from grasprom.chain import kinematics as kin
    from grasprom.gap import AugmentedModel, validate_trial
    from grasprom.gap.criteria import SIGNIFICANT_RHO
    from grasprom.gap.likelihood import interval_z
    from grasprom.gap.prepare import prepare_trial

    s = _surrogate(fe)
    chain = kin.ChainParams()
    rng = np.random.default_rng(seed + 29)
    data = acquire(unseen.data, acquisition, rng)
    tr = validate_trial(data, unseen.sidecar, "fresh", chain, s)
    effects = {e["name"]: dict(e["params"]) for e in augmented["effects"]}
    p = prepare_trial(tr, s, chain)
    idx = np.searchsorted(tr.time_s, p.t)
    lo, hi = kin.theta_range_deg(chain)

    def forces(model, theta):
        return model.handle_force_N(tr.time_s, theta, tr.thickness_mm, tr.material, s)[idx]

    out = []
    aug, base = AugmentedModel(effects, chain), AugmentedModel({}, chain)
    hw = p.raw_rest_halfwidth_deg
    ends = [np.clip(p.raw_theta + k * hw, lo, hi) for k in (-1.0, 1.0)]
    s_int = []
    for m in (base, aug):
        c = forces(m, p.raw_theta)
        z = interval_z(p.F, c, (forces(m, ends[0]), forces(m, ends[1])), p.sigma_fit)
        s_int.append(float(z @ z - np.sum(p.null)))
    s_gau = []
    for m in (base, aug):
        r = (p.F - forces(m, tr.theta_deg)) / p.sigma
        s_gau.append(float(r @ r) - p.F.size)
    for s_b, s_a in (s_int, s_gau):
        out.append(float("nan") if s_b <= 0 else 1.0 - float(np.sqrt(max(s_a, 0.0) / s_b)))
    floor = SIGNIFICANT_RHO * p.F.size
    s_b, s_a = s_int
    floored = (
        float("nan")
        if max(s_b, s_a) <= floor
        else 1.0 - float(np.sqrt(max(s_a, 0.0) / max(s_b, floor)))
    )
    return floored, out[1], out[0]


def _fresh_summary(results: list[dict], key: str = "fresh_shrink", prefix: str = "fresh") -> dict:
    """Median / worst of the independently measured shrink (``key`` of the results) and its
    negative, confident cases (summary keys ``prefix_...``)."""
    fr = [r for r in results if r.get(key) is not None and np.isfinite(r[key])]
    vals = [r[key] for r in fr]
    neg = [
        f"{'+'.join(r['effects']) or 'null'} -> {'+'.join(r['predicted'])} "
        f"(conf {r['confidence']:.2f}, fresh shrink {r[key]:.2f})"
        for r in fr
        if r[key] < 0 and r["confidence"] >= 0.5
    ]
    return {
        f"{prefix}_n": len(vals),
        f"{prefix}_median": float(np.median(vals)) if vals else float("nan"),
        f"{prefix}_worst": float(np.min(vals)) if vals else float("nan"),
        f"{prefix}_negative_conf_ge_0.5": neg,
    }


def _pred_key(r: dict) -> str:
    if r["label"] != "explained":
        return r["label"]
    return "+".join(r["predicted"])


def truth_block(r: dict) -> str | None:
    """Block of the chain of a single-effect case's truth effect (None for other cases)."""
    from grasprom.gap import EFFECTS

    if r["kind"] != "single":
        return None
    return EFFECTS[r["effects"][0]].block


def _truth_blocks(r: dict) -> set[str]:
    from grasprom.gap import EFFECTS

    return {EFFECTS[e].block for e in r["effects"]}


def block_confusion(results: list[dict]) -> dict[str, Counter]:
    """``{truth block: Counter(where.block)}`` over the single-effect cases."""
    out: dict[str, Counter] = {}
    for r in results:
        tb = truth_block(r)
        if tb is not None:
            out.setdefault(tb, Counter())[r["where"]["block"]] += 1
    return out


CONF_BINS = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0001)
"""Confidence bins of the reliability table."""


def calibration(results: list[dict]) -> dict:
    """Reliability of the stated confidence of ``explained`` verdicts: per bin the count, mean
    confidence and observed accuracy (exact truth set; out-of-library: always wrong), and the
    expected calibration error (count-weighted |confidence - accuracy|)."""
    rows, ece, n_all = [], 0.0, 0
    expl = [r for r in results if r["label"] == "explained"]
    for lo, hi in zip(CONF_BINS[:-1], CONF_BINS[1:]):
        rs = [r for r in expl if lo <= r["confidence"] < hi]
        if not rs:
            rows.append({"bin": [lo, min(hi, 1.0)], "n": 0})
            continue
        ok = [r["kind"] in ("single", "pair") and sorted(r["predicted"]) == sorted(r["effects"])
              for r in rs]  # fmt: skip
        acc = float(np.mean(ok))
        conf = float(np.mean([r["confidence"] for r in rs]))
        rows.append({"bin": [lo, min(hi, 1.0)], "n": len(rs), "confidence": conf,
                     "accuracy": acc})  # fmt: skip
        ece += len(rs) * abs(conf - acc)
        n_all += len(rs)
    return {"bins": rows, "ece": ece / n_all if n_all else float("nan")}


def summarise(results: list[dict]) -> dict:
    """Headline figures of a list of :func:`run_case` results."""
    lib = [r for r in results if r["kind"] in ("single", "pair")]
    exact = [
        sorted(r["predicted"]) == sorted(r["effects"]) and r["label"] == "explained" for r in lib
    ]
    first_ok = [r["label"] == "explained" and r["predicted"][0] in r["effects"] for r in lib]
    singles = [r for r in results if r["kind"] == "single"]
    pairs = [r for r in results if r["kind"] == "pair"]
    nulls = [r for r in results if r["kind"] == "null"]
    ool = [r for r in results if r["kind"] == "out_of_library"]
    shr = [r["shrink"] for r in lib]
    return {
        "n_cases": len(results),
        "top1_exact": float(np.mean(exact)) if lib else float("nan"),
        "top1_singles": float(
            np.mean(
                [
                    sorted(r["predicted"]) == r["effects"] and r["label"] == "explained"
                    for r in singles
                ]
            )
        )
        if singles
        else float("nan"),
        "pairs_exact": float(
            np.mean([sorted(r["predicted"]) == sorted(r["effects"]) for r in pairs])
        )
        if pairs
        else float("nan"),
        "top1_first_effect_in_truth": float(np.mean(first_ok)) if lib else float("nan"),
        "median_shrink": float(np.median(shr)) if shr else float("nan"),
        **_fresh_summary(results),
        **_fresh_summary(results, "fresh_shrink_gaussian", "fresh_gaussian"),
        **_fresh_summary(results, "fresh_shrink_unfloored", "fresh_unfloored"),
        "median_shrink_rms": float(np.median([r["shrink_rms"] for r in lib])) if lib else None,
        "null_to_none": float(np.mean([r["label"] == "none" for r in nulls]))
        if nulls
        else float("nan"),
        "ool_labels": dict(Counter(r["label"] for r in ool)),
        "ool_explained_conf_ge_0.8": int(
            sum(r["label"] == "explained" and r["confidence"] >= 0.8 for r in ool)
        ),
        "block_accuracy_singles": float(
            np.mean([r["where"]["block"] == truth_block(r) for r in singles])
        )
        if singles
        else float("nan"),
        "block_accuracy_by_block": {
            b: c[b] / sum(c.values()) for b, c in block_confusion(results).items()
        },
        "pairs_block_in_truth": float(
            np.mean([r["where"]["block"] in _truth_blocks(r) for r in pairs])
        )
        if pairs
        else float("nan"),
        "ool_blocks": dict(Counter(r["where"]["block"] for r in ool)),
        "mean_seconds": float(np.mean([r["seconds"] for r in results])),
        "calibration": calibration(results),
    }


def print_report(results: list[dict]) -> None:
    truths = list(LIBRARY_EFFECTS) + ["null"] + list(OUT_OF_LIBRARY_EFFECTS)
    cols = list(LIBRARY_EFFECTS) + ["pair", "none", "unexplained"]
    short = {e: e[:9] for e in cols}
    print("Confusion matrix (single effects, null and out-of-library cases; rows = truth)")
    print(f"{'truth':<24}" + "".join(f"{short[c]:>10}" for c in cols))
    for t in truths:
        rs = [r for r in results if (r["effects"] == [t]) or (t == "null" and not r["effects"])]
        if not rs:
            continue
        cnt = Counter()
        for r in rs:
            k = _pred_key(r)
            cnt["pair" if "+" in k else k] += 1
        print(f"{t:<24}" + "".join(f"{cnt.get(c, 0):>10d}" for c in cols))
    pairs = [r for r in results if r["kind"] == "pair"]
    if pairs:
        print("\nPairs (truth -> verdict)")
        for r in pairs:
            ok = "OK " if sorted(r["predicted"]) == sorted(r["effects"]) else "-- "
            print(
                f"  {ok}{'+'.join(r['effects']):<48} -> {r['label']} {'+'.join(r['predicted'])}"
                f" (conf {r['confidence']:.2f}, shrink {r['shrink']:.2f})"
            )
    ool = [r for r in results if r["kind"] == "out_of_library"]
    if ool:
        print("\nOut-of-library cases (motor cogging ripple)")
        for r in ool:
            print(
                f"  seed {r['seed']}: {r['label']} {'+'.join(r['predicted'])} conf "
                f"{r['confidence']:.2f} (best candidate {'+'.join(r['best_candidate'])} explains"
                f" {100 * max(r['explained_share'], 0):.0f} %)"
            )
    conf = block_confusion(results)
    if conf:
        from grasprom.gap import BLOCKS

        bcols = list(BLOCKS) + ["unknown"]
        print(
            "\nBlock attribution (single effects; rows = block of the truth effect, "
            "columns = where.block)"
        )
        print(f"{'truth block':<24}" + "".join(f"{c:>10}" for c in bcols))
        for b in BLOCKS:
            c = conf.get(b, Counter())
            print(f"{b:<24}" + "".join(f"{c.get(k, 0):>10d}" for k in bcols))
        print("  per effect (where.block counts):")
        for e in LIBRARY_EFFECTS:
            c = Counter(
                r["where"]["block"]
                for r in results
                if r["kind"] == "single" and r["effects"] == [e]
            )
            print(f"    {e:<24} " + ", ".join(f"{k} {n}" for k, n in sorted(c.items())))
    s = summarise(results)
    print("\nReliability of the stated confidence (explained verdicts; accuracy = exact truth set)")
    print(f"  {'confidence':<12}{'n':>5}{'stated':>9}{'observed':>10}")
    for b in s["calibration"]["bins"]:
        lo, hi = b["bin"]
        if b["n"]:
            print(f"  {lo:.1f}-{hi:.1f}    {b['n']:5d}{b['confidence']:9.2f}{b['accuracy']:10.2f}")
        else:
            print(f"  {lo:.1f}-{hi:.1f}    {0:5d}")
    print(f"  expected calibration error: {100 * s['calibration']['ece']:.1f} points")
    print("\nSummary")
    print(f"  cases: {s['n_cases']}, mean {s['mean_seconds']:.1f} s per case")
    print(
        f"  top-1 accuracy (verdict = exact truth set, singles + pairs): "
        f"{100 * s['top1_exact']:.1f} %  [singles {100 * s['top1_singles']:.1f} %, "
        f"pairs {100 * s['pairs_exact']:.1f} %; first named effect in truth "
        f"{100 * s['top1_first_effect_in_truth']:.1f} %]"
    )
    print(
        f"  median held-out shrink of the systematic gap: {100 * s['median_shrink']:.1f} % "
        f"(of the total RMS incl. noise: {100 * s['median_shrink_rms']:.1f} %)"
    )
    print(
        f"  independently measured shrink on a fresh trial (explained verdicts, "
        f"n = {s['fresh_n']}): median {100 * s['fresh_median']:.1f} %, worst "
        f"{100 * s['fresh_worst']:.1f} %; negative with confidence >= 0.5: "
        f"{len(s['fresh_negative_conf_ge_0.5'])} {s['fresh_negative_conf_ge_0.5']}"
    )
    print(
        f"    unfloored (a fresh trial without a significant gap counted too): median "
        f"{100 * s['fresh_unfloored_median']:.1f} %, worst "
        f"{100 * s['fresh_unfloored_worst']:.1f} %; negative with confidence >= 0.5: "
        f"{len(s['fresh_unfloored_negative_conf_ge_0.5'])}"
    )
    print(
        f"    weighted as before the interval likelihood (Gaussian quantum, recorded angle): "
        f"median {100 * s['fresh_gaussian_median']:.1f} %, worst "
        f"{100 * s['fresh_gaussian_worst']:.1f} %; negative with confidence >= 0.5: "
        f"{len(s['fresh_gaussian_negative_conf_ge_0.5'])}"
    )
    print(f"  null -> none: {100 * s['null_to_none']:.1f} %")
    print(
        f"  out-of-library verdicts: {s['ool_labels']}; explained with confidence >= 0.8: "
        f"{s['ool_explained_conf_ge_0.8']}"
    )
    print(
        f"  block accuracy (single effects, where.block = block of the truth effect): "
        f"{100 * s['block_accuracy_singles']:.1f} %  ["
        + ", ".join(f"{b} {100 * a:.0f} %" for b, a in s["block_accuracy_by_block"].items())
        + f"]; pairs: block of one of the two effects {100 * s['pairs_block_in_truth']:.1f} %;"
        f" out-of-library (cogging, in the drive): {s['ool_blocks']}"
    )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seed", type=int, default=2024)
    p.add_argument("--per-effect", type=int, default=6)
    p.add_argument("--null", type=int, default=14)
    p.add_argument("--ool", type=int, default=12)
    p.add_argument("--trials", type=int, default=4)
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    p.add_argument(
        "--gap-channel",
        action="store_true",
        help="trials carry a measured jaw gap gap_mm (laser sensor, 5-10 um rms)",
    )
    p.add_argument("--json", default=None, help="write all case results here")
    p.add_argument("--acquisition", choices=ACQUISITIONS, default="ideal",
                   help="how the synthetic trials are recorded (default ideal)")  # fmt: skip
    p.add_argument("--tremor", type=float, default=0.0, metavar="DEG",
                   help="hand tremor on the angle, deg RMS in 6-12 Hz (default 0)")  # fmt: skip
    p.add_argument("--fe", default=None, metavar="DIR",
                   help="FE sweep of the surrogate (default fe_data/default)")  # fmt: skip
    args = p.parse_args(argv)
    cases = case_list(args.seed, args.per_effect, args.null, args.ool)
    if args.fe:
        cases = [{**c, "fe": args.fe} for c in cases]
    t0 = time.perf_counter()
    if args.workers > 1:
        with ProcessPoolExecutor(args.workers) as ex:
            results = list(
                ex.map(
                    run_case,
                    cases,
                    [args.trials] * len(cases),
                    [args.gap_channel] * len(cases),
                    [args.acquisition] * len(cases),
                    [args.tremor] * len(cases),
                    chunksize=2,
                )
            )
    else:
        results = [
            run_case(c, args.trials, args.gap_channel, args.acquisition, args.tremor) for c in cases
        ]
    if args.gap_channel:
        print("Trials with the measured jaw gap gap_mm (--gap-channel)\n")
    print(
        f"Acquisition: {args.acquisition}, {args.trials} trials per case, tremor "
        f"{args.tremor:g} deg RMS, seed {args.seed}\n"
    )
    print_report(results)
    print(f"  wall time {time.perf_counter() - t0:.0f} s with {args.workers} worker(s)")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
